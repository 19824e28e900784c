//! `pa10 accuracy`: the resolver-uncertainty bound (Monte Carlo and linearised); `pa10 accuracy
//! map`: a calibrated model's predicted tool position uncertainty over a plane.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use indicatif::ProgressStyle;
use nalgebra::{Quaternion, UnitQuaternion};
use pa10::accuracy::{self, ARCMIN, McConfig, Region};

use crate::model_cmds::ModelArg;

/// Arguments of `pa10 accuracy` (without a subcommand: the resolver bound).
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true, args_conflicts_with_subcommands = true)]
pub struct AccuracyArgs {
    #[command(subcommand)]
    sub: Option<AccuracySub>,
    #[command(flatten)]
    model: ModelArg,
    /// Plane heights of the tool point, m (base frame), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.3,0.4,0.5,0.6,0.7")]
    planes: Vec<f64>,
    /// Points per plane, chosen uniformly over the plane's reachable part.
    #[arg(long, default_value_t = 200)]
    points: usize,
    /// Monte Carlo draws per point.
    #[arg(long, default_value_t = 100_000)]
    draws: usize,
    /// Resolver standard deviation, arcmin: one value for every joint or six.
    #[arg(long, value_delimiter = ',', default_value = "0.64")]
    sigma_arcmin: Vec<f64>,
    /// Tool point offset along the flange z axis, m (the paper's ball sat 0.3–0.4 m out).
    #[arg(long, default_value_t = 0.35)]
    tool_offset: f64,
    /// Tool orientation in the base frame as a unit quaternion W,X,Y,Z (default: pointing down).
    #[arg(long, value_delimiter = ',', value_name = "W,X,Y,Z")]
    tool_quaternion: Option<Vec<f64>>,
    /// Region of each plane, m: XMIN,XMAX,YMIN,YMAX.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "XMIN,XMAX,YMIN,YMAX",
        default_value = "-1.2,1.2,-1.2,1.2"
    )]
    region: Vec<f64>,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Worker threads (default: all cores); results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Write per-point results to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Write one SVG per plane (per-point mean error over the plane) into this directory.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// `pa10 accuracy` subcommands.
#[derive(Debug, Subcommand)]
pub enum AccuracySub {
    /// A calibrated model's predicted 1σ tool position uncertainty (its covariance ⊕ the
    /// resolver floor) over a horizontal plane, tool pointing down: CSV and an SVG map.
    Map(MapArgs),
}

/// Arguments of `pa10 accuracy map`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct MapArgs {
    /// A calibrated model (with the `uncertainty:` section `pa10 calibrate` writes).
    #[arg(long, value_name = "FILE")]
    model: PathBuf,
    /// Height of the plane of the tool point, m (base frame).
    #[arg(long)]
    z: f64,
    /// Region of the plane, m: XMIN,XMAX,YMIN,YMAX.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "XMIN,XMAX,YMIN,YMAX",
        default_value = "0.3,0.9,-0.4,0.4"
    )]
    region: Vec<f64>,
    /// Grid step, m.
    #[arg(long, default_value_t = 0.05)]
    step: f64,
    /// Load hung at the tool, N.
    #[arg(long, default_value_t = 0.0)]
    load: f64,
    /// Tool point offset along the flange z axis, m.
    #[arg(long, default_value_t = 0.35)]
    tool_offset: f64,
    /// Write the map (SVG) here.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Write the points (`x,y,z,sigma_mm`) to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
}

/// `--region XMIN,XMAX,YMIN,YMAX` (m): exactly four numbers.
fn region(v: &[f64]) -> Result<[f64; 4]> {
    <[f64; 4]>::try_from(v).map_err(|_| {
        anyhow::anyhow!(
            "--region takes XMIN,XMAX,YMIN,YMAX (4 values), got {}",
            v.len()
        )
    })
}

fn map(a: &MapArgs) -> Result<()> {
    let [x0, x1, y0, y1] = region(&a.region)?;
    anyhow::ensure!(
        [x0, x1, y0, y1, a.z].iter().all(|v| v.is_finite()) && x0 < x1 && y0 < y1,
        "--region: finite XMIN < XMAX, YMIN < YMAX in metres, and a finite --z"
    );
    anyhow::ensure!(
        a.step.is_finite()
            && a.step >= 0.005
            && ((x1 - x0) / a.step + 1.0) * ((y1 - y0) / a.step + 1.0) <= 40_000.0,
        "--step: at least 5 mm and at most 40 000 grid points, got {} m",
        a.step
    );
    anyhow::ensure!(
        a.load.is_finite() && (0.0..=500.0).contains(&a.load),
        "--load: 0…500 N, got {}",
        a.load
    );
    anyhow::ensure!(
        a.tool_offset.is_finite() && a.tool_offset.abs() < 2.0,
        "--tool-offset: |offset| < 2 m"
    );
    let tool = pa10::model::frame_from_pose([0.0, 0.0, a.tool_offset], [1.0, 0.0, 0.0, 0.0]);
    let model = pa10::model::Model::load(&a.model)
        .with_context(|| format!("loading model {}", a.model.display()))?
        .with_tool(&tool)?;
    if model.data().uncertainty.is_none() {
        bail!(
            "{} has no `uncertainty:` section: a model `pa10 calibrate` wrote has one (a nominal model has no covariance to map)",
            a.model.display()
        );
    }
    let down = accuracy::pointing_down().to_rotation_matrix();
    let load = pa10::model::ExternalLoad::hung(a.load, &model.gravity());
    let mut points = Vec::new();
    let nx = ((x1 - x0) / a.step).floor() as usize;
    let ny = ((y1 - y0) / a.step).floor() as usize;
    for i in 0..=nx {
        for k in 0..=ny {
            let (x, y) = (x0 + i as f64 * a.step, y0 + k as f64 * a.step);
            let t = pa10::model::Frame::from_parts(nalgebra::Translation3::new(x, y, a.z), down);
            let reference = [y.atan2(x), 0.3, 1.6, 0.0, 1.1, 0.0];
            let Ok(q) = model.ik_nearest(&t, &reference) else {
                continue;
            };
            let tau = model.static_torques(&q, &load);
            if let Some(s) = model.position_uncertainty(&q, &tau) {
                points.push((x, y, s * 1e3));
            }
        }
    }
    if points.is_empty() {
        bail!(
            "no point of the region is reachable at z = {} m with the tool pointing down",
            a.z
        );
    }
    pa10::plot::scatter_heat(
        &a.out,
        &format!(
            "predicted 1σ tool position uncertainty, z = {} m, {} N",
            a.z, a.load
        ),
        &points,
        "mm",
    )?;
    if let Some(p) = &a.csv {
        let mut text = String::from("x,y,z,sigma_mm\n");
        for (x, y, s) in &points {
            text.push_str(&format!("{x},{y},{},{s}\n", a.z));
        }
        std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?;
    }
    let mut v: Vec<f64> = points.iter().map(|p| p.2).collect();
    v.sort_by(f64::total_cmp);
    println!(
        "{} reachable points: predicted 1σ {:.3} mm (min) / {:.3} mm (median) / {:.3} mm (max); map in {}",
        v.len(),
        v[0],
        v[v.len() / 2],
        v[v.len() - 1],
        a.out.display()
    );
    Ok(())
}

fn config(a: &AccuracyArgs) -> Result<McConfig> {
    let sigma: [f64; 6] = match a.sigma_arcmin.as_slice() {
        [s] => [*s * ARCMIN; 6],
        s if s.len() == 6 => std::array::from_fn(|j| s[j] * ARCMIN),
        s => bail!("--sigma-arcmin takes one value or six, got {}", s.len()),
    };
    let [x0, x1, y0, y1] = region(&a.region)?;
    let tool_orientation = match &a.tool_quaternion {
        None => accuracy::pointing_down(),
        Some(v) => {
            let [w, x, y, z] = v.as_slice() else {
                bail!(
                    "--tool-quaternion takes W,X,Y,Z (4 values), got {}",
                    v.len()
                )
            };
            let q = Quaternion::new(*w, *x, *y, *z);
            if !(q.norm() - 1.0).abs().le(&1e-3) {
                bail!(
                    "--tool-quaternion must be a unit quaternion; its norm is {}",
                    q.norm()
                );
            }
            UnitQuaternion::from_quaternion(q)
        }
    };
    Ok(McConfig {
        sigma,
        planes: a.planes.clone(),
        points: a.points,
        draws: a.draws,
        tool_offset: a.tool_offset,
        tool_orientation,
        region: Region {
            x: (x0, x1),
            y: (y0, y1),
        },
        seed: a.seed,
    })
}

/// `pa10 accuracy`.
pub fn accuracy(a: &AccuracyArgs) -> Result<()> {
    if let Some(AccuracySub::Map(m)) = &a.sub {
        return map(m);
    }
    let model = a.model.load()?;
    let cfg = config(a)?;
    let total = (cfg.planes.len() * cfg.points) as u64;
    let bar = crate::progress::bar(total, "points", a.json).with_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} points ({eta} left)",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let pool = {
        let mut b = rayon::ThreadPoolBuilder::new();
        if let Some(n) = a.threads {
            if n == 0 {
                bail!("--threads must be ≥ 1");
            }
            b = b.num_threads(n);
        }
        b.build().context("starting worker threads")?
    };
    let started = std::time::Instant::now();
    let planes = pool.install(|| accuracy::run(&model, &cfg, &|done| bar.set_position(done)))?;
    bar.finish_and_clear();
    let elapsed = started.elapsed().as_secs_f64();

    if let Some(path) = &a.csv {
        write_csv(path, &planes).with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(dir) = &a.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for p in &planes {
            let pts: Vec<(f64, f64, f64)> = p
                .points
                .iter()
                .map(|r| (r.position[0], r.position[1], r.mc.mean_mm))
                .collect();
            let file = dir.join(format!("accuracy-z{:.3}.svg", p.z));
            let title = format!("resolver bound, mean error per point, z = {:.3} m", p.z);
            pa10::plot::scatter_heat(&file, &title, &pts, "mm")?;
        }
    }
    if a.json {
        let planes_json: Vec<_> = planes
            .iter()
            .map(|p| {
                serde_json::json!({
                    "z": p.z, "points": p.points.len(),
                    "mean_mm": p.mc.mean_mm, "sd_mm": p.mc.sd_mm, "median_mm": p.mc.median_mm,
                    "p95_mm": p.mc.p95_mm, "p99_mm": p.mc.p99_mm, "max_mm": p.mc.max_mm,
                    "linearised_mean_mm": p.linearised_mean_mm, "linearised_sd_mm": p.linearised_sd_mm,
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({
                "planes": planes_json,
                "sigma_rad": cfg.sigma, "draws": cfg.draws, "tool_offset_m": cfg.tool_offset,
                "seed": cfg.seed, "elapsed_s": elapsed,
            })
        );
    } else {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "resolver bound: σ = {:?} arcmin, {} points × {} draws per plane, tool {:.3} m, seed {} ({:.2} s)",
            cfg.sigma.map(|s| (s / ARCMIN * 1e4).round() / 1e4),
            cfg.points,
            cfg.draws,
            cfg.tool_offset,
            cfg.seed,
            elapsed
        )?;
        writeln!(
            out,
            "  z [m]   mean ± sd [mm]     median    p95      p99      max    | linearised mean ± sd [mm]  MC/lin"
        )?;
        for p in &planes {
            writeln!(
                out,
                "  {:5.3}   {:.4} ± {:.4}   {:.4}   {:.4}   {:.4}   {:.4} | {:.4} ± {:.4}          {:.4}",
                p.z,
                p.mc.mean_mm,
                p.mc.sd_mm,
                p.mc.median_mm,
                p.mc.p95_mm,
                p.mc.p99_mm,
                p.mc.max_mm,
                p.linearised_mean_mm,
                p.linearised_sd_mm,
                p.mc.mean_mm / p.linearised_mean_mm
            )?;
        }
        writeln!(
            out,
            "  seed paper (Lightcap et al. 2008), z = 0.5 m: 0.197 ± 0.096 mm"
        )?;
    }
    Ok(())
}

fn write_csv(path: &std::path::Path, planes: &[accuracy::PlaneResult]) -> Result<()> {
    let mut w = csv::Writer::from_path(path)?;
    w.write_record([
        "z_m",
        "point",
        "x_m",
        "y_m",
        "q1",
        "q2",
        "q3",
        "q4",
        "q5",
        "q6",
        "mean_mm",
        "sd_mm",
        "median_mm",
        "p95_mm",
        "p99_mm",
        "max_mm",
        "linearised_mean_mm",
        "linearised_sd_mm",
    ])?;
    for p in planes {
        for (i, r) in p.points.iter().enumerate() {
            let mut rec = vec![
                p.z.to_string(),
                i.to_string(),
                r.position[0].to_string(),
                r.position[1].to_string(),
            ];
            rec.extend(r.q.iter().map(|v| v.to_string()));
            rec.extend(
                [
                    r.mc.mean_mm,
                    r.mc.sd_mm,
                    r.mc.median_mm,
                    r.mc.p95_mm,
                    r.mc.p99_mm,
                    r.mc.max_mm,
                    r.linearised_mean_mm,
                    r.linearised_sd_mm,
                ]
                .iter()
                .map(|v| v.to_string()),
            );
            w.write_record(&rec)?;
        }
    }
    w.flush()?;
    Ok(())
}
