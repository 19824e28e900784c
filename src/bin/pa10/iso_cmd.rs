//! `pa10 iso9283 plan|report`: ISO 9283 pose accuracy and repeatability — the standard's five
//! poses in a test cube as a pose list `pa10 collect run` drives the daemon through, and AP/RP
//! per pose from the instrument's measurements (`pa10::accuracy::iso9283`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result, bail, ensure};
use clap::{Args, Subcommand};
use pa10::accuracy::iso9283::{Cube, PoseFigures, figures, test_poses};
use pa10::calib::collect::{PoseTarget, parse_instrument, parse_poses, poses_csv};
use pa10::model::Frame;
use serde::Serialize;

use crate::model_cmds::ModelArg;

/// `pa10 iso9283 …`
#[derive(Debug, Subcommand)]
pub enum IsoCmd {
    /// The test poses P1…P5 of a cube, every cycle, as a pose list (`config_id,load_n,q1..q6`).
    Plan(IsoPlanArgs),
    /// AP and RP per pose from the instrument's measurements of a planned test, and a verdict.
    Report(IsoReportArgs),
}

/// Arguments of `pa10 iso9283 plan`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct IsoPlanArgs {
    #[command(flatten)]
    model: ModelArg,
    /// The test cube: CX,CY,CZ (its centre, m, base frame),SIDE (m).
    #[arg(long, value_delimiter = ',', required = true)]
    cube: Vec<f64>,
    /// Flange → tool: X Y Z (m) QW QX QY QZ; default 0.35 m along the flange axis.
    #[arg(long, num_args = 7, value_names = ["X", "Y", "Z", "QW", "QX", "QY", "QZ"])]
    tool: Option<Vec<f64>>,
    /// Cycles (the standard: 30).
    #[arg(long, default_value_t = 30)]
    cycles: usize,
    /// Load hung at the tool during the test, N.
    #[arg(long, default_value_t = 0.0)]
    load: f64,
    /// Where to write the pose list.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Arguments of `pa10 iso9283 report`.
#[derive(Debug, Args)]
pub struct IsoReportArgs {
    /// The model the test was planned with (its tool and base frame: the commanded poses are
    /// its forward kinematics of the pose list, the measurements are mapped by its base frame).
    #[command(flatten)]
    model: ModelArg,
    /// The planned pose list (`pa10 iso9283 plan --out`).
    #[arg(long, value_name = "FILE")]
    poses: PathBuf,
    /// The instrument's measurements (`config_id,load_n,x,y,z,qw,qx,qy,qz`, instrument frame).
    #[arg(long, value_name = "FILE")]
    measured: PathBuf,
    /// Pass/fail limits: AP_MM,RP_MM (position accuracy and repeatability, mm).
    #[arg(long, value_delimiter = ',')]
    limits: Option<Vec<f64>>,
    /// Write a plot of AP and RP per pose (SVG).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// `pa10 iso9283 …`.
pub fn run(c: &IsoCmd) -> Result<()> {
    match c {
        IsoCmd::Plan(a) => plan(a),
        IsoCmd::Report(a) => report(a),
    }
}

fn plan(a: &IsoPlanArgs) -> Result<()> {
    let [cx, cy, cz, side] = <[f64; 4]>::try_from(a.cube.as_slice()).map_err(|_| {
        anyhow::anyhow!(
            "--cube takes CX,CY,CZ,SIDE (4 values), got {}",
            a.cube.len()
        )
    })?;
    ensure!(
        (2..=100).contains(&a.cycles),
        "--cycles: 2…100 (the standard: 30), got {}",
        a.cycles
    );
    ensure!(
        a.load.is_finite() && (0.0..=500.0).contains(&a.load),
        "--load: 0…500 N, got {}",
        a.load
    );
    let tool = crate::model_cmds::tool_arg(a.tool.as_deref())?;
    let model = a.model.load()?.with_tool(&tool)?;
    let cube = Cube {
        centre: [cx, cy, cz],
        side,
    };
    let down = pa10::accuracy::pointing_down().to_rotation_matrix();
    let poses = test_poses(&cube, &down)?;
    let mut reference = [cy.atan2(cx), 0.3, 1.6, 0.0, 1.1, 0.0];
    let mut qs = Vec::new();
    for (k, p) in poses.iter().enumerate() {
        let q = model.ik_nearest(p, &reference).map_err(|e| {
            anyhow::anyhow!(
                "P{} at {:?} m is not reachable with the tool pointing down: {e} (move or shrink the cube)",
                k + 1,
                p.translation.vector.as_slice()
            )
        })?;
        reference = q;
        qs.push(q);
    }
    let targets: Vec<PoseTarget> = (0..a.cycles)
        .flat_map(|_| {
            qs.iter().enumerate().map(|(k, q)| PoseTarget {
                config_id: format!("P{}", k + 1),
                load_n: a.load,
                q: *q,
            })
        })
        .collect();
    std::fs::write(&a.out, poses_csv(&targets))
        .with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "ISO 9283 test: P1…P5 in the cube centred at {:?} m, side {side} m, × {} cycles at {} N → {} ({} rows)",
        cube.centre,
        a.cycles,
        a.load,
        a.out.display(),
        targets.len()
    );
    Ok(())
}

#[derive(Debug, Serialize)]
struct Line {
    pose: String,
    #[serde(flatten)]
    figures: PoseFigures,
    pass: Option<bool>,
}

fn report(a: &IsoReportArgs) -> Result<()> {
    let model = a.model.load()?;
    let read = |p: &PathBuf| {
        std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))
    };
    let origin = |p: &PathBuf| p.display().to_string();
    let plan = parse_poses(&read(&a.poses)?, &origin(&a.poses))?;
    let meas = parse_instrument(&read(&a.measured)?, &origin(&a.measured))?;
    let limits = match &a.limits {
        None => None,
        Some(v) => {
            let [ap, rp] = <[f64; 2]>::try_from(v.as_slice()).map_err(|_| {
                anyhow::anyhow!("--limits takes AP_MM,RP_MM, got {} values", v.len())
            })?;
            ensure!(
                ap > 0.0 && rp > 0.0 && ap.is_finite() && rp.is_finite(),
                "--limits: positive millimetres, got {ap},{rp}"
            );
            Some((ap * 1e-3, rp * 1e-3))
        }
    };
    let mut commanded: BTreeMap<String, Frame> = BTreeMap::new();
    for t in &plan {
        commanded
            .entry(t.config_id.clone())
            .or_insert_with(|| model.fk(&t.q));
    }
    let mut attained: BTreeMap<String, Vec<Frame>> = BTreeMap::new();
    for m in &meas {
        if !commanded.contains_key(&m.config_id) {
            bail!(
                "{}: pose `{}` is not in the plan {}",
                a.measured.display(),
                m.config_id,
                a.poses.display()
            );
        }
        attained
            .entry(m.config_id.clone())
            .or_default()
            .push(*model.base_from_instrument() * m.pose);
    }
    let mut lines = Vec::new();
    for (id, c) in &commanded {
        let got = attained.get(id).map(Vec::as_slice).unwrap_or_default();
        let f = figures(c, got).with_context(|| format!("pose {id}"))?;
        let pass = limits.map(|(ap, rp)| f.ap_p <= ap && f.rp_l <= rp);
        lines.push(Line {
            pose: id.clone(),
            figures: f,
            pass,
        });
    }
    let verdict = limits.map(|_| lines.iter().all(|l| l.pass == Some(true)));
    if let Some(p) = &a.plot {
        let series = |name: &str, f: fn(&PoseFigures) -> f64| {
            (
                name.to_string(),
                lines
                    .iter()
                    .enumerate()
                    .map(|(k, l)| ((k + 1) as f64, f(&l.figures) * 1e3))
                    .collect::<Vec<_>>(),
            )
        };
        pa10::plot::series(
            p,
            "ISO 9283: pose accuracy and repeatability",
            "pose (P1…P5)",
            "mm",
            &[series("AP_P", |f| f.ap_p), series("RP_l", |f| f.rp_l)],
        )?;
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({"poses": lines, "pass": verdict, "limits_mm": limits.map(|(a, r)| [a * 1e3, r * 1e3])})
        );
        return Ok(());
    }
    println!(
        "| pose | n | AP_P [mm] | AP_x / AP_y / AP_z [mm] | AP_a / AP_b / AP_c [mrad] | RP_l [mm] | RP_a / RP_b / RP_c [± mrad] | verdict |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for l in &lines {
        let f = &l.figures;
        let mm = |v: f64| v * 1e3;
        println!(
            "| {} | {} | {:.3} | {:.3} / {:.3} / {:.3} | {:.3} / {:.3} / {:.3} | {:.3} | {:.3} / {:.3} / {:.3} | {} |",
            l.pose,
            f.n,
            mm(f.ap_p),
            mm(f.ap_xyz[0]),
            mm(f.ap_xyz[1]),
            mm(f.ap_xyz[2]),
            mm(f.ap_abc[0]),
            mm(f.ap_abc[1]),
            mm(f.ap_abc[2]),
            mm(f.rp_l),
            mm(f.rp_abc[0]),
            mm(f.rp_abc[1]),
            mm(f.rp_abc[2]),
            match l.pass {
                Some(true) => "pass",
                Some(false) => "FAIL",
                None => "-",
            }
        );
    }
    match (verdict, limits) {
        (Some(v), Some((ap, rp))) => println!(
            "\n{}: AP within {} mm and RP within {} mm at {} poses",
            if v { "PASS" } else { "FAIL" },
            ap * 1e3,
            rp * 1e3,
            if v { "all" } else { "not all" }
        ),
        _ => println!("\n(no --limits: no verdict)"),
    }
    Ok(())
}
