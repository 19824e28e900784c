//! `pa10 plan`: a calibration campaign designed for the model to be identified — the pose list
//! `pa10 collect run` takes, chosen I- (or D-) optimally among reachable candidates in the instrument's
//! volume, with the accuracy it predicts beside the paper's 27 poses (`pa10::calib::plan`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail, ensure};
use clap::Args;
use pa10::calib::collect::{PoseTarget, poses_csv};
use pa10::calib::plan::{
    Information, PlanNoise, check_loads, check_noise, design_log_det, design_model, exchange,
    greedy_order, information, predicted_error, prior, workspace_weight,
};
use pa10::model::{Frame, Model};
use pa10::sim::experiment::{grid_poses, random_pose};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::Serialize;

use crate::model_cmds::ModelArg;

/// Arguments of `pa10 plan`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct PlanArgs {
    #[command(flatten)]
    model: ModelArg,
    /// The instrument's measuring volume for the tool point: XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (m,
    /// robot base frame). Negative first values: `--box=-0.7,…`.
    #[arg(
        long = "box",
        value_delimiter = ',',
        required_unless_present = "sphere",
        conflicts_with = "sphere"
    )]
    volume: Vec<f64>,
    /// Or a spherical measuring volume: CX,CY,CZ,RADIUS (m, robot base frame; a laser
    /// tracker's or a camera's working volume).
    #[arg(long, value_delimiter = ',')]
    sphere: Vec<f64>,
    /// The volume is given in the instrument's frame, which sits here in the robot base frame
    /// (a rough `base_from_instrument`: X Y Z in m, QW QX QY QZ; a tape measure's worth).
    #[arg(long, num_args = 7, value_names = ["X", "Y", "Z", "QW", "QX", "QY", "QZ"])]
    instrument_frame: Option<Vec<f64>>,
    /// Write the "how many configurations" curve as a plot (SVG).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Configurations to measure (each at every load).
    #[arg(long, default_value_t = 12)]
    configs: usize,
    /// Loads hung at the tool at each configuration, N, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0,22,44")]
    loads: Vec<f64>,
    /// Flange → tool: X Y Z (m) QW QX QY QZ (unit quaternion), as `pa10 tool` takes it.
    #[arg(long, num_args = 7, value_names = ["X", "Y", "Z", "QW", "QX", "QY", "QZ"])]
    tool: Option<Vec<f64>>,
    /// Candidate orientations: `any` (uniform joint angles whose tool point is in the box:
    /// every orientation the arm can take there) or `down` (the tool pointing down within
    /// ±0.3 rad tilts and ±0.6 rad of turn, as the paper's grid).
    #[arg(long, value_enum, default_value_t = Orientations::Any)]
    orientations: Orientations,
    /// The design criterion: `i` (I-optimal: the smallest predicted position variance averaged
    /// over the volume) or `d` (D-optimal: the largest `log det` of the information).
    #[arg(long, value_enum, default_value_t = Criterion::I)]
    criterion: Criterion,
    /// Candidate configurations to choose from.
    #[arg(long, default_value_t = 1500)]
    candidates: usize,
    /// Keep every joint at least this far inside its limits, rad.
    #[arg(long, default_value_t = 0.1)]
    joint_margin: f64,
    /// A table plane: every joint origin and the tool stay above this height (m, base frame).
    #[arg(long, value_name = "Z")]
    table_z: Option<f64>,
    /// Instrument samples per configuration and load.
    #[arg(long, default_value_t = 10)]
    repeats: usize,
    /// Seed of the candidates.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where to write the pose list (`config_id,load_n,q1..q6`, link-side rad).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
}

/// The design criterion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Criterion {
    /// I-optimal: the mean predicted position variance over the volume, smallest.
    I,
    /// D-optimal: `log det` of the information, largest.
    D,
}

/// Which tool orientations the candidates take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Orientations {
    /// Any the arm can take with the tool point in the box.
    Any,
    /// Pointing down within ±0.3 rad tilts.
    Down,
}

/// One design's figures.
#[derive(Debug, Serialize)]
struct Figures {
    configs: usize,
    /// `log det M` (prior included), and per parameter (36 columns).
    log_det: f64,
    log_det_per_param: f64,
    /// Predicted mean position error after calibration at the validation configurations
    /// (0/45/90 N), mm, and the resolver floor there.
    predicted_mm: f64,
    floor_mm: f64,
}

#[derive(Debug, Serialize)]
struct Outcome {
    planned: Figures,
    /// The paper's 27 poses (3 × 3 × 3 grid) at the same loads (absent when out of reach).
    paper: Option<Figures>,
    /// Why the paper's poses could not be compared, if so.
    paper_unreachable: Option<String>,
    /// Predicted mean error (mm) of the best design of each size: "how many do I need?"
    curve: Vec<(usize, f64)>,
    candidates: usize,
    criterion: &'static str,
    validation_configs: usize,
    out: String,
}

const VALIDATION_LOADS: [f64; 3] = [0.0, 45.0, 90.0];

/// The design sizes of the "how many" curve.
const CURVE_SIZES: [usize; 9] = [4, 6, 8, 10, 12, 16, 20, 27, 36];

/// `pa10 plan`.
pub fn run(a: &PlanArgs) -> Result<()> {
    let spin = crate::progress::spinner("planning: sampling candidate configurations", a.json);
    let r = plan(a, &spin);
    spin.finish_and_clear();
    r
}

fn plan(a: &PlanArgs, spin: &indicatif::ProgressBar) -> Result<()> {
    // the volume: a box or a sphere, in the base frame or (with --instrument-frame) in the
    // instrument's; candidates are sampled in its bounding box in the base frame and kept inside
    let inst = a
        .instrument_frame
        .as_deref()
        .map(|t| crate::model_cmds::pose_arg("--instrument-frame", t))
        .transpose()?;
    let to_base = |p: nalgebra::Point3<f64>| inst.map_or(p, |f| f * p);
    let (vol_box, ball) = if a.sphere.is_empty() {
        let b = <[f64; 6]>::try_from(a.volume.as_slice())
            .map_err(|_| anyhow::anyhow!("--box takes six values, got {}", a.volume.len()))?;
        ensure!(
            b.iter().all(|v| v.is_finite()) && b[0] < b[3] && b[1] < b[4] && b[2] < b[5],
            "--box: XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX in metres with each minimum below its maximum, got {:?}",
            a.volume
        );
        (Some(b), None)
    } else {
        let [cx, cy, cz, r] = <[f64; 4]>::try_from(a.sphere.as_slice()).map_err(|_| {
            anyhow::anyhow!(
                "--sphere takes CX,CY,CZ,RADIUS (4 values), got {}",
                a.sphere.len()
            )
        })?;
        ensure!(
            [cx, cy, cz, r].iter().all(|v| v.is_finite()) && r > 0.0,
            "--sphere: a finite centre and a positive radius in metres, got {:?}",
            a.sphere
        );
        (None, Some((nalgebra::Point3::new(cx, cy, cz), r)))
    };
    // the bounding box in the base frame: of the box's corners, or of the sphere
    let corners: Vec<nalgebra::Point3<f64>> = match (vol_box, ball) {
        (Some(b), _) => (0..8)
            .map(|k| {
                let pick = |bit: usize, lo: f64, hi: f64| if k & bit == 0 { lo } else { hi };
                to_base(nalgebra::Point3::new(
                    pick(1, b[0], b[3]),
                    pick(2, b[1], b[4]),
                    pick(4, b[2], b[5]),
                ))
            })
            .collect(),
        (None, Some((c, r))) => {
            let c = to_base(c);
            vec![
                c - nalgebra::Vector3::repeat(r),
                c + nalgebra::Vector3::repeat(r),
            ]
        }
        (None, None) => bail!("--box or --sphere: the instrument's measuring volume"),
    };
    let lo = corners
        .iter()
        .fold(nalgebra::Vector3::repeat(f64::INFINITY), |m, p| {
            m.inf(&p.coords)
        });
    let hi = corners
        .iter()
        .fold(nalgebra::Vector3::repeat(f64::NEG_INFINITY), |m, p| {
            m.sup(&p.coords)
        });
    let bounds = [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z];
    let [x0, y0, z0, x1, y1, z1] = bounds;
    ensure!(
        (1..=200).contains(&a.configs),
        "--configs: 1…200, got {}",
        a.configs
    );
    ensure!(
        (a.configs..=20_000).contains(&a.candidates),
        "--candidates: --configs ({})…20000, got {}",
        a.configs,
        a.candidates
    );
    ensure!(
        a.joint_margin.is_finite() && (0.0..=0.5).contains(&a.joint_margin),
        "--joint-margin: 0…0.5 rad, got {}",
        a.joint_margin
    );
    ensure!(
        a.table_z.is_none_or(|z| z.is_finite()),
        "--table-z: a finite height in metres"
    );
    check_loads(&a.loads)?;
    let noise = PlanNoise {
        repeats: a.repeats,
        ..PlanNoise::default()
    };
    check_noise(&noise)?;
    let tool = crate::model_cmds::tool_arg(a.tool.as_deref())?;
    let model = design_model(&a.model.load()?.with_tool(&tool)?)?;

    // Candidates: `any` — joint angles uniform within the limits less the margin, kept when
    // the tool point is in the box; `down` — tool points uniform in the box, pointing down
    // within ±0.3 rad tilts and ±0.6 rad of turn (the campaigns' family), solved nearest a
    // reference facing the point.
    let mut rng = Pcg64::seed_from_u64(a.seed);
    let mut cands: Vec<[f64; 6]> = Vec::with_capacity(a.candidates);
    let mut tries = 0usize;
    let budget = match a.orientations {
        Orientations::Any => 2000 * a.candidates,
        Orientations::Down => 50 * a.candidates,
    };
    let lim = *model.limits();
    // a base-frame point inside the volume (tested in the volume's own frame)
    let inside = |p: &nalgebra::Vector3<f64>| {
        let v = inst.map_or(nalgebra::Point3::from(*p), |f| {
            f.inverse() * nalgebra::Point3::from(*p)
        });
        vol_box.is_none_or(|b| {
            (b[0]..=b[3]).contains(&v.x)
                && (b[1]..=b[4]).contains(&v.y)
                && (b[2]..=b[5]).contains(&v.z)
        }) && ball.is_none_or(|(c, r)| (v - c).norm() <= r)
    };
    while cands.len() < a.candidates {
        tries += 1;
        if tries > budget {
            bail!(
                "only {} of {} candidates are reachable in the volume {:?} (orientations {:?}, joint margin {} rad{}): widen it or ask for fewer",
                cands.len(),
                a.candidates,
                if a.sphere.is_empty() {
                    &a.volume
                } else {
                    &a.sphere
                },
                a.orientations,
                a.joint_margin,
                a.table_z
                    .map(|z| format!(", above z = {z} m"))
                    .unwrap_or_default()
            );
        }
        let q = match a.orientations {
            Orientations::Down => {
                let t = random_pose(&mut rng, [x0, y0, z0], [x1, y1, z1]);
                if inside(&t.translation.vector) {
                    reachable(&model, &t, a.joint_margin, a.table_z)
                } else {
                    None
                }
            }
            Orientations::Any => {
                use rand::RngExt;
                let q: [f64; 6] = std::array::from_fn(|j| {
                    rng.random_range(
                        (lim.lower[j] + a.joint_margin)..(lim.upper[j] - a.joint_margin),
                    )
                });
                let p = model.fk(&q).translation.vector;
                (inside(&p) && above(&model, &q, a.table_z)).then_some(q)
            }
        };
        cands.extend(q);
    }
    let infos: Vec<Information> = cands
        .par_iter()
        .map(|q| information(&model, q, &a.loads, &noise))
        .collect();
    // where the arm will work: every fourth candidate stands for the volume in the
    // I-criterion; the prediction is made at others (every fourth from the second), not chosen
    let work: Vec<[f64; 6]> = cands.iter().step_by(4).take(150).copied().collect();
    let w = workspace_weight(&model, &work, &VALIDATION_LOADS);
    let crit = match a.criterion {
        Criterion::I => pa10::calib::plan::Criterion::I(&w),
        Criterion::D => pa10::calib::plan::Criterion::D,
    };
    // one greedy pass serves the design and every size of the curve (greedy is
    // prefix-stable); each then has its own exchange passes
    let sizes: Vec<usize> = CURVE_SIZES
        .into_iter()
        .filter(|&n| n <= cands.len())
        .collect();
    let order = greedy_order(
        &infos,
        sizes.iter().copied().fold(a.configs, usize::max),
        &crit,
    )?;
    let choose = |n: usize, passes: usize| exchange(&infos, &order[..n], passes, &crit);
    spin.set_message(format!(
        "planning: choosing {} of {} candidates (exchange)",
        a.configs,
        cands.len()
    ));
    let design = choose(a.configs, 10)?;
    let val: Vec<[f64; 6]> = (1..cands.len())
        .step_by(4)
        .filter(|i| !design.chosen.contains(i))
        .take(60)
        .map(|i| cands[i])
        .collect();
    let figures = |m: &Information, n: usize| -> Result<Figures> {
        let (e, floor) = predicted_error(&model, m, &val, &VALIDATION_LOADS, &noise)?;
        let ld = pa10::calib::plan::log_det(m);
        Ok(Figures {
            configs: n,
            log_det: ld,
            log_det_per_param: ld / pa10::calib::plan::DESIGN_COLS as f64,
            predicted_mm: e * 1e3,
            floor_mm: floor * 1e3,
        })
    };
    let sum = |ids: &[usize]| ids.iter().fold(prior(), |m, &i| m + infos[i]);
    let planned = figures(&sum(&design.chosen), a.configs)?;

    // the paper's 27 poses, solved as the demo solves them (nearest the previous one); with
    // some tools some are out of reach, and the comparison says so
    let mut reference = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
    let mut paper_infos = Vec::new();
    let mut paper_unreachable = None;
    for (id, target) in grid_poses() {
        match model.ik_nearest(&target, &reference) {
            Ok(q) => {
                reference = q;
                paper_infos.push(information(&model, &q, &a.loads, &noise));
            }
            Err(e) => {
                paper_unreachable = Some(format!(
                    "the paper's pose {id} is out of reach with this tool: {e}"
                ));
                break;
            }
        }
    }
    let paper = match paper_unreachable {
        None => {
            let paper_m = paper_infos.iter().fold(prior(), |m, i| m + i);
            debug_assert!(
                (pa10::calib::plan::log_det(&paper_m) - design_log_det(&paper_infos)).abs() < 1e-9
            );
            Some(figures(&paper_m, paper_infos.len())?)
        }
        Some(_) => None,
    };

    spin.set_message("planning: the how-many curve");
    let mut curve = Vec::new();
    for n in sizes {
        let d = choose(n, 1)?;
        curve.push((n, figures(&sum(&d.chosen), n)?.predicted_mm));
    }

    if let Some(p) = &a.plot {
        let floor = planned.floor_mm;
        pa10::plot::series(
            p,
            "pa10 plan: predicted mean position error after calibration",
            "configurations",
            "mm",
            &[
                (
                    "planned".to_string(),
                    curve.iter().map(|&(n, e)| (n as f64, e)).collect(),
                ),
                (
                    "resolver floor".to_string(),
                    curve.iter().map(|&(n, _)| (n as f64, floor)).collect(),
                ),
            ],
        )?;
    }
    let targets: Vec<PoseTarget> = design
        .chosen
        .iter()
        .enumerate()
        .flat_map(|(k, &i)| {
            let q = cands[i];
            a.loads.iter().map(move |&load_n| PoseTarget {
                config_id: format!("p{:02}", k + 1),
                load_n,
                q,
            })
        })
        .collect();
    std::fs::write(&a.out, poses_csv(&targets))
        .with_context(|| format!("writing {}", a.out.display()))?;
    let out = Outcome {
        planned,
        paper,
        paper_unreachable,
        curve,
        candidates: cands.len(),
        criterion: match a.criterion {
            Criterion::I => "I",
            Criterion::D => "D",
        },
        validation_configs: val.len(),
        out: a.out.display().to_string(),
    };
    if a.json {
        println!("{}", serde_json::to_string(&out)?);
    } else {
        print(&out);
    }
    Ok(())
}

/// The link angles that put `model`'s tool at `target`, nearest a reference facing it, when
/// every joint is `margin` inside its limits and (with a table) every joint origin and the
/// tool are above `table_z`.
fn reachable(model: &Model, target: &Frame, margin: f64, table_z: Option<f64>) -> Option<[f64; 6]> {
    let p = target.translation.vector;
    let reference = [p.y.atan2(p.x), 0.3, 1.6, 0.0, 1.1, 0.0];
    let q = model.ik_nearest(target, &reference).ok()?;
    let lim = model.limits();
    if (0..6).any(|j| q[j] < lim.lower[j] + margin || q[j] > lim.upper[j] - margin) {
        return None;
    }
    above(model, &q, table_z).then_some(q)
}

/// Whether every joint origin and the tool are above the table (always, without one).
fn above(model: &Model, q: &[f64; 6], table_z: Option<f64>) -> bool {
    let Some(z) = table_z else {
        return true;
    };
    let frames = model.frames(q);
    frames.iter().skip(1).all(|f| f.translation.z > z) && model.fk(q).translation.z > z
}

fn print(o: &Outcome) {
    println!(
        "pa10 plan: {} configurations chosen {}-optimally among {} reachable candidates; pose list in {}",
        o.planned.configs, o.criterion, o.candidates, o.out
    );
    println!();
    println!(
        "| design | configurations | log det M (per parameter) | predicted mean error after calibration [mm] | resolver floor [mm] |"
    );
    println!("|---|---|---|---|---|");
    let rows = std::iter::once(("planned", &o.planned))
        .chain(o.paper.as_ref().map(|p| ("the paper's 27 poses", p)));
    for (name, f) in rows {
        println!(
            "| {name} | {} | {:.1} ({:.2}) | {:.3} | {:.3} |",
            f.configs, f.log_det, f.log_det_per_param, f.predicted_mm, f.floor_mm
        );
    }
    if let Some(why) = &o.paper_unreachable {
        println!("| the paper's 27 poses | — | {why} | | |");
    }
    println!(
        "\nPredicted at {} other reachable configurations × 0/45/90 N (linearised: the parameters' covariance from the design, the resolvers' floor added).",
        o.validation_configs
    );
    println!("\nHow many configurations: the best design of each size");
    println!("| configurations | predicted mean error [mm] |");
    println!("|---|---|");
    for (n, e) in &o.curve {
        println!("| {n} | {e:.3} |");
    }
}
