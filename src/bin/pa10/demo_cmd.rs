//! `pa10 demo`: the whole story on a simulated PA10, no hardware. Runs the daemon core with
//! the simulated servo controller (a hidden true robot) in simulated time, gathers the paper's calibration set through the daemon's API and the CAN
//! protocol (the simulator's ground truth plays the CMM), calibrates, loads the models into
//! the running daemon and commands novel poses under loads up to 90 N, judged by the truth.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pa10::calib::dataset::{Dataset, Effort, Meta, Row};
use pa10::calib::fit::{CalibOptions, calibrate, fit_base_only, settled_model_torques};
use pa10::calib::identify::SweepPlan;
use pa10::daemon::api::sweep;
use pa10::daemon::config::{Config, Settings, TorqueSource};

use pa10::daemon::wire::ApiRequest;
use pa10::model::{Frame, Model, NOMINAL_YAML, pose_error, pose_parts};
use pa10::sim::experiment::{CampaignSpec, grid_poses, random_pose, sidecar};
use pa10::sim::rig::Lockstep;
use rand::SeedableRng;
use rand_pcg::Pcg64;
use serde::Serialize;

use crate::client_cmd::{Api, AsSession, Simulated, checked};
use crate::collect_cmd::{TOOL_STILL_MAX_S, move_wait, sample, wait_still, wait_tool_still};

/// Arguments of `pa10 demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Seed of the hidden true robot, the validation poses and every noise (with `--config`:
    /// its `sim.seed` unless given).
    #[arg(long)]
    seed: Option<u64>,
    /// Run on this configuration's simulated arm instead of the built-in one: its `sim`
    /// section (the hidden truth, `sim.plant`: e.g. `config/sim-mujoco.yaml`, MuJoCo with
    /// sticking drives), its loop and limits as written. With `torque_source: estimated` or
    /// `model` the lab's path runs: `pa10 identify`'s tour through the daemon first, the
    /// identified model loaded, calibration on its torques (`--model-torques`).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Samples per calibration pose and load.
    #[arg(long, default_value_t = 2)]
    repeats: usize,
    /// Novel validation poses.
    #[arg(long, default_value_t = 4)]
    validation_poses: usize,
    /// A short run (8 calibration poses, 2 validation poses), for smoke tests.
    #[arg(long)]
    quick: bool,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Write the gathered dataset, the models and plots (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
}

/// Errors of one model at one load.
#[derive(Debug, Clone, Serialize)]
struct Cell {
    load_n: f64,
    mean_mm: f64,
    peak_mm: f64,
    mean_orient_deg: f64,
}

#[derive(Debug, Serialize)]
struct Outcome {
    seed: u64,
    /// The configuration the arm ran on (`--config`), or the built-in one.
    config: String,
    /// `pa10 identify`'s tour ran first (the configuration's torque source needs a model's
    /// bodies): its constant-speed samples.
    identified_samples: Option<usize>,
    calibration_rows: usize,
    calibration_poses: usize,
    validation_poses: usize,
    /// model name → per-load errors
    models: Vec<(String, Vec<Cell>)>,
    /// Monte Carlo resolver floor per load: mean position error, mm
    floor_mm: Vec<(f64, f64)>,
    elapsed_s: f64,
}

const CAL_LOADS: [f64; 3] = [0.0, 22.0, 44.0];
const VAL_LOADS: [f64; 3] = [0.0, 45.0, 90.0];
/// Least and most wait after a move or a load change before sampling (until the resolvers
/// are still).
const SETTLE_MIN: Duration = Duration::from_millis(80);
const SETTLE_MAX: Duration = Duration::from_millis(400);

fn config_text(dir: &Path, seed: u64) -> String {
    include_str!("../../../config/sim.yaml")
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", dir.join("api.sock").display()),
        )
        .replace("  seed: 1", &format!("  seed: {seed}"))
        // up to the PA10's rated joint speeds (S1, S2 57°/s, E1 114°/s, wrist 360°/s) and
        // brisk accelerations, so that the 27 poses take well under a minute
        .replace(
            "speed: [0.5, 0.5, 1.0, 2.0, 2.0, 2.0]",
            "speed: [1.0, 1.0, 2.0, 4.0, 4.0, 4.0]",
        )
        .replace(
            "acceleration: [1.0, 1.0, 2.0, 4.0, 4.0, 4.0]",
            "acceleration: [6.0, 6.0, 10.0, 16.0, 16.0, 16.0]",
        )
        // margins for a busy machine (the demo shares it with whatever else runs)
        .replace("following_error: 0.01", "following_error: 0.05")
        .replace("feedback_timeout_ms: 20", "feedback_timeout_ms: 100")
        .replace("log_level: info", "log_level: warn")
}

/// Waits for the resolvers ([`wait_still`]) and then, as the instrument does, for the tool
/// ([`wait_tool_still`], at most `tool_max` s).
fn settle(api: &mut Simulated, tool_max: f64) -> Result<()> {
    wait_still(api, SETTLE_MIN, SETTLE_MAX)?;
    wait_tool_still(api, tool_max);
    Ok(())
}

/// Hangs `n` newtons on the simulated arm and tells the daemon.
fn set_load(api: &mut Simulated, n: f64) -> Result<()> {
    api.hang_weight(n)?;
    crate::collect_cmd::set_payload(api, n)
}

/// `pa10 demo`.
pub fn run(a: &DemoArgs) -> Result<()> {
    anyhow::ensure!(
        (1..=20).contains(&a.repeats),
        "--repeats must be 1…20, got {}",
        a.repeats
    );
    anyhow::ensure!(
        (1..=30).contains(&a.validation_poses),
        "--validation-poses must be 1…30, got {}",
        a.validation_poses
    );
    let t0 = Instant::now();
    let dir = std::env::temp_dir().join(format!("pa10-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = demo(a, &dir, t0);
    std::fs::remove_dir_all(&dir).ok();
    result
}

/// The settings the demo runs on, and its seed: `--config`'s (models loaded from `dir`,
/// the seed given or its `sim.seed`), or the built-in simulation written into `dir`.
fn settings(a: &DemoArgs, dir: &Path) -> Result<(Settings, u64)> {
    let Some(path) = &a.config else {
        let seed = a.seed.unwrap_or(1);
        std::fs::write(dir.join("model-nominal.yaml"), NOMINAL_YAML)?;
        let cfg_path = dir.join("pa10d.yaml");
        std::fs::write(&cfg_path, config_text(dir, seed))?;
        return Ok((Config::load(&cfg_path)?, seed));
    };
    let mut s = Config::load(path)?;
    let Some(sim) = s.sim.as_mut() else {
        anyhow::bail!(
            "--config {}: no simulated arm (the demo needs `bus.backend: virtual` and a `sim` section)",
            path.display()
        );
    };
    if let Some(seed) = a.seed {
        sim.seed = seed;
    }
    let seed = sim.seed;
    // the demo writes its models into its own folder and loads them from there
    s.api.model_dir = dir.to_path_buf();
    Ok((s, seed))
}

fn demo(a: &DemoArgs, dir: &Path, t0: Instant) -> Result<()> {
    let (loaded, seed) = settings(a, dir)?;
    let kt = loaded.control.torque_constants;
    let tool = CampaignSpec::default().tool;
    let nominal = loaded.model.with_tool(&tool)?;
    // a torque source built on the model's bodies wants them identified first (the lab's path)
    // the built-in in-process arm is still when its resolvers are
    let tool_max = if a.config.is_some() {
        TOOL_STILL_MAX_S
    } else {
        0.0
    };
    let identify_first = matches!(
        loaded.control.torque_source,
        TorqueSource::Estimated | TorqueSource::Model
    );

    // Snake through the grid (consecutive poses one grid step apart) so moves stay short.
    let mut all = grid_poses();
    all.sort_by_key(|(id, _)| {
        let d: Vec<usize> = id[1..].chars().map(|c| c as usize - '0' as usize).collect();
        let j = if d[0] % 2 == 1 { 2 - d[1] } else { d[1] };
        let k = if (d[0] * 3 + j) % 2 == 1 {
            2 - d[2]
        } else {
            d[2]
        };
        (d[0], j, k)
    });
    let cal_poses: Vec<(String, Frame)> = if a.quick {
        all.into_iter()
            .filter(|(id, _)| !id[1..].contains('1'))
            .collect()
    } else {
        all
    };
    let n_val = if a.quick { 2 } else { a.validation_poses };
    let steps = (cal_poses.len() * CAL_LOADS.len() + 3 * n_val * VAL_LOADS.len()) as u64;
    let bar = if a.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(steps)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed:>3} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("starting pa10d on the simulated PA10");
    // The daemon's core and the simulated arm in simulated time: deterministic, and as fast
    // as the machine computes (the real-time daemon is `pa10d`; tests/vcan runs it on a kernel).
    let mut api = Simulated(Lockstep::from_config(&loaded)?);
    api.0
        .run_until_ready(5.0)
        .map_err(|e| anyhow::anyhow!("the simulated servo controller: {e}"))?;
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xde70);
    let truth = api.0.servo.truth().clone();
    let cmm = |api: &Simulated, rng: &mut Pcg64| -> Frame {
        truth.observe_pose(&api.0.servo.true_tool_pose(), rng)
    };

    // 0. On the lab's path, gravity and friction from the arm's own motion first.
    let (base, identified_samples) = if identify_first {
        bar.set_message("identifying gravity and friction (pa10 identify's tour)");
        let plan = SweepPlan {
            waypoints: if a.quick { 6 } else { 10 },
            seed,
            ..SweepPlan::default()
        };
        let run = sweep::identify_through(
            &mut AsSession(&mut api),
            &nominal,
            &kt,
            &plan,
            &sweep::DEFAULT_SPEEDS,
        )
        .context("identification")?;
        let path = dir.join("identified.yaml");
        run.model.save(&path)?;
        checked(
            &mut api,
            ApiRequest::LoadModel {
                path: path.display().to_string(),
            },
        )?;
        (run.model, Some(run.samples.len()))
    } else {
        (nominal.clone(), None)
    };

    // 1. Gather the calibration set through the daemon.
    let mut data = Dataset::default();
    let mut reference = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0]; // the simulator's home
    for (n, (id, target)) in cal_poses.iter().enumerate() {
        // The joint solution nearest the previous configuration: no wrist flips.
        let q = nominal
            .ik_nearest(target, &reference)
            .map_err(|e| anyhow::anyhow!("pose {id}: {e}"))?;
        reference = q;
        bar.set_message(format!("calibration pose {id}"));
        move_wait(&mut api, ApiRequest::MoveJoints { q })
            .with_context(|| format!("calibration pose {id}"))?;
        // Loads up at one pose, down at the next: one load change fewer per pose.
        let loads: Vec<f64> = if n % 2 == 0 {
            CAL_LOADS.to_vec()
        } else {
            CAL_LOADS.iter().rev().copied().collect()
        };
        for load in loads {
            set_load(&mut api, load)?;
            settle(&mut api, tool_max)?;
            for _ in 0..a.repeats {
                let (q_motor, current) = sample(&mut api)?;
                data.rows.push(Row {
                    config_id: id.clone(),
                    load_n: load,
                    q: q_motor,
                    effort: Effort::Current(current),
                    pose: cmm(&api, &mut rng),
                    direction: [0; 6],
                    temperature_c: None,
                    line: 0,
                });
                api.pause(Duration::from_millis(10));
            }
            bar.inc(1);
        }
    }
    data.meta = Some(Meta {
        inner_configs: Some(
            cal_poses
                .iter()
                .map(|(id, _)| id.clone())
                .filter(|id| !id[1..].contains('1'))
                .collect(),
        ),
        ..sidecar(
            format!("simulator ground truth (pa10 demo, seed {seed})"),
            &tool,
            &truth.noise,
        )
    });
    let t_gather = t0.elapsed().as_secs_f64();
    // 2. Calibrate: full model, linear stiffness only, and the nominal model placed — on the
    //    lab's path from the identified model and on its torques.
    bar.set_message("calibrating");
    let opts = CalibOptions {
        torque_constants: Some(kt),
        starts: 2,
        seed,
        ..Default::default()
    };
    let fitted = if identify_first {
        settled_model_torques(&base, &data, None, &opts)?.0
    } else {
        data.clone()
    };
    let full = calibrate(&base, &fitted, None, &opts, &|_| {})?.model;
    let linear = calibrate(
        &base,
        &fitted,
        None,
        &CalibOptions {
            linear_only: true,
            ..opts.clone()
        },
        &|_| {},
    )?
    .model;
    let placed = fit_base_only(&base, &fitted, None, &opts)?;

    let t_calib = t0.elapsed().as_secs_f64();
    // 3. Validation: novel poses (instrument frame), every model loaded into the daemon.
    let mut targets: Vec<Frame> = Vec::new();
    while targets.len() < n_val {
        let t = random_pose(&mut rng, [0.40, -0.25, -0.10], [0.75, 0.25, 0.30]);
        let p = t.translation.vector;
        let reference = [p.y.atan2(p.x), 0.3, 1.6, 0.0, 1.2, 0.0];
        if nominal.ik_nearest(&t, &reference).is_ok() {
            targets.push(placed.base_from_instrument().inverse() * t);
        }
    }
    let truth_base = *truth.model.base_from_instrument();
    let named: [(&str, &Model); 3] = [
        ("nominal", &placed),
        ("linear stiffness", &linear),
        ("full model", &full),
    ];
    let mut paths = Vec::new();
    for (name, m) in &named {
        let path = dir.join(format!("{}.yaml", name.replace(' ', "-")));
        m.save(&path)?;
        paths.push(path);
    }
    // errs[model][load] = (position mm, orientation deg) per pose
    let mut errs = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    // the link configurations the full model commanded (for the floor)
    let mut val_q: Vec<[f64; 6]> = Vec::new();
    for (k, target) in targets.iter().enumerate() {
        // At each pose every model in turn (a short move between them).
        for (mi, (name, m)) in named.iter().enumerate() {
            let path = paths[mi].display().to_string();
            checked(&mut api, ApiRequest::LoadModel { path })?;
            let (p, q) = pose_parts(&(m.base_from_instrument() * target));
            bar.set_message(format!("validation pose {} with the {name}", k + 1));
            move_wait(
                &mut api,
                ApiRequest::MovePose {
                    position: p,
                    quaternion: q,
                },
            )
            .with_context(|| format!("validation pose {} with the {name}", k + 1))?;
            if mi == named.len() - 1 {
                val_q.push(crate::client_cmd::status_of(&mut api)?.setpoint);
            }
            // Loads up for one model, down for the next.
            let order: Vec<usize> = if mi % 2 == 0 {
                vec![0, 1, 2]
            } else {
                vec![2, 1, 0]
            };
            for l in order {
                let load = VAL_LOADS[l];
                set_load(&mut api, load)?;
                settle(&mut api, tool_max)?;
                let got = truth_base.inverse() * api.0.servo.true_tool_pose();
                let e = pose_error(target, &got);
                errs[mi][l].push((
                    e.fixed_rows::<3>(0).norm() * 1e3,
                    e.fixed_rows::<3>(3).norm().to_degrees(),
                ));
                bar.inc(1);
            }
        }
    }
    let models: Vec<(String, Vec<Cell>)> = named
        .iter()
        .zip(&errs)
        .map(|((name, _), per_load)| {
            let cells = VAL_LOADS
                .iter()
                .zip(per_load)
                .map(|(&load_n, v)| Cell {
                    load_n,
                    mean_mm: v.iter().map(|e| e.0).sum::<f64>() / v.len() as f64,
                    peak_mm: v.iter().map(|e| e.0).fold(0.0, f64::max),
                    mean_orient_deg: v.iter().map(|e| e.1).sum::<f64>() / v.len() as f64,
                })
                .collect();
            (name.to_string(), cells)
        })
        .collect();
    set_load(&mut api, 0.0)?;
    let t_val = t0.elapsed().as_secs_f64();
    tracing::debug!(t_gather, t_calib, t_val, "demo phases (s since start)");
    if std::env::var_os("PA10_DEMO_TIMING").is_some() {
        eprintln!(
            "gathered at {t_gather:.1} s, calibrated at {t_calib:.1} s, validated at {t_val:.1} s"
        );
    }
    bar.finish_and_clear();

    // 4. The Monte Carlo floor at the validation configurations: resolver errors alone
    //    (σ per joint), seeded draws through the accuracy module's FK kernel.
    let floor = mc_floor_mm(&full, &val_q, truth.noise.resolver_rad, seed);
    let floor_mm: Vec<(f64, f64)> = VAL_LOADS.iter().map(|&l| (l, floor)).collect();

    let out = Outcome {
        seed,
        config: a
            .config
            .as_ref()
            .map_or_else(|| "built-in".to_string(), |p| p.display().to_string()),
        identified_samples,
        calibration_rows: data.rows.len(),
        calibration_poses: cal_poses.len(),
        validation_poses: targets.len(),
        models,
        floor_mm,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    if let Some(r) = &a.report {
        report(r, &data, &placed, &linear, &full, &out)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&out)?);
    } else {
        print(&out);
    }
    Ok(())
}

/// Mean position error (mm) that resolver errors of `sigma` rad (1σ, every joint) alone cause
/// at the configurations `qs`: 20 000 seeded draws per configuration.
fn mc_floor_mm(model: &Model, qs: &[[f64; 6]], sigma: f64, seed: u64) -> f64 {
    pa10::accuracy::floor_at(model, qs, sigma, 20_000, seed ^ 0xf100) * 1e3
}

fn report(
    dir: &Path,
    data: &Dataset,
    placed: &Model,
    linear: &Model,
    full: &Model,
    out: &Outcome,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    data.save(dir.join("cal.csv"))?;
    placed.save(dir.join("nominal-placed.yaml"))?;
    linear.save(dir.join("linear.yaml"))?;
    full.save(dir.join("calibrated.yaml"))?;
    std::fs::write(dir.join("demo.json"), serde_json::to_string_pretty(out)?)?;
    let series: Vec<(String, Vec<(f64, f64)>)> = out
        .models
        .iter()
        .map(|(n, cells)| {
            (
                n.clone(),
                cells.iter().map(|c| (c.load_n, c.mean_mm)).collect(),
            )
        })
        .chain(std::iter::once((
            "Monte Carlo floor".to_string(),
            out.floor_mm.clone(),
        )))
        .collect();
    pa10::plot::series(
        &dir.join("validation.svg"),
        "pa10 demo: mean position error on novel poses, through the daemon",
        "load (N)",
        "mean position error (mm)",
        &series,
    )?;
    Ok(())
}

fn print(o: &Outcome) {
    println!(
        "pa10 demo (seed {}): {} calibration rows ({} poses × 0/22/44 N) gathered through pa10d, \
         {} novel validation poses × 0/45/90 N, {:.0} s",
        o.seed, o.calibration_rows, o.calibration_poses, o.validation_poses, o.elapsed_s
    );
    println!();
    print!("{:>9}", "load [N]");
    for (n, _) in &o.models {
        print!("  {n:>27}");
    }
    println!("  {:>14}", "MC floor");
    print!("{:>9}", "");
    for _ in &o.models {
        print!("  {:>27}", "mean / peak mm, mean deg");
    }
    println!("  {:>14}", "mean mm");
    for (l, (load, floor)) in o.floor_mm.iter().enumerate() {
        print!("{load:>9.0}");
        for (_, cells) in &o.models {
            let c = &cells[l];
            print!(
                "  {:>9.3} / {:>6.3}, {:>6.4}",
                c.mean_mm, c.peak_mm, c.mean_orient_deg
            );
        }
        println!("  {floor:>14.3}");
    }
    println!(
        "\nErrors are the simulator's ground truth: where the tool really went vs where it was sent."
    );
}
