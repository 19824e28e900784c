//! `pa10 accuracy`: the resolver-uncertainty bound (Monte Carlo and linearised).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{Quaternion, UnitQuaternion};
use pa10::accuracy::{self, ARCMIN, McConfig, Region};

use crate::model_cmds::ModelArg;

/// Arguments of `pa10 accuracy`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct AccuracyArgs {
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

fn config(a: &AccuracyArgs) -> Result<McConfig> {
    let sigma: [f64; 6] = match a.sigma_arcmin.as_slice() {
        [s] => [*s * ARCMIN; 6],
        s if s.len() == 6 => std::array::from_fn(|j| s[j] * ARCMIN),
        s => bail!("--sigma-arcmin takes one value or six, got {}", s.len()),
    };
    let [x0, x1, y0, y1] = a.region.as_slice() else {
        bail!(
            "--region takes XMIN,XMAX,YMIN,YMAX (4 values), got {}",
            a.region.len()
        );
    };
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
            x: (*x0, *x1),
            y: (*y0, *y1),
        },
        seed: a.seed,
    })
}

/// `pa10 accuracy`.
pub fn accuracy(a: &AccuracyArgs) -> Result<()> {
    let model = a.model.load()?;
    let cfg = config(a)?;
    let total = (cfg.planes.len() * cfg.points) as u64;
    let bar = ProgressBar::new(total).with_style(
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
