//! `pa10 sim measure` and `pa10 calibrate`.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::ProgressBar;
use pa10::calib::dataset::Dataset;
use pa10::calib::fit::{CalibOptions, Weighting, row_residual};
use pa10::calib::report::{self, ByLoad, Report};
use pa10::sim::experiment::{CampaignSpec, paper_campaign};

use crate::model_cmds::ModelArg;

/// `pa10 sim …`: without a subcommand, run the simulated servo controller on a CAN interface.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SimArgs {
    #[command(subcommand)]
    cmd: Option<SimCmd>,
    #[command(flatten)]
    run: RunArgs,
}

/// `pa10 sim` subcommands.
#[derive(Debug, Subcommand)]
pub enum SimCmd {
    /// Generate the seed paper's measurement campaign on a hidden simulated robot.
    Measure(MeasureArgs),
    /// Generate a discovery campaign on a hidden robot with an effect the model lacks.
    Discovery(crate::discover_cmd::SimDiscoveryArgs),
    /// Replay a candump log onto a CAN interface with its original timing.
    Replay(ReplayArgs),
    /// Decode a candump log with the codec: one JSON list of {"id", "signals"} (DBC names, SI).
    Decode {
        /// The candump log.
        file: PathBuf,
    },
}

/// Running the simulated controller.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// SocketCAN interface to serve (e.g. `vcan0`, `can0`).
    #[arg(long, value_name = "IFACE")]
    can: Option<String>,
    /// The hidden true robot (a model YAML, e.g. `pa10 sim measure`'s truth.yaml); drawn from
    /// `--seed` when absent.
    #[arg(long, value_name = "FILE")]
    truth: Option<PathBuf>,
    /// Seed of the drawn truth and of the sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Log all traffic in candump format to this file.
    #[arg(long, value_name = "FILE")]
    log: Option<PathBuf>,
    /// Fault injection: this axis (1…6) never answers.
    #[arg(long, value_name = "AXIS", value_parser = clap::value_parser!(u8).range(1..=6))]
    mute_axis: Option<u8>,
    /// Fault injection: current-sensor offset, `AXIS=AMPS` (repeatable).
    #[arg(long, value_name = "AXIS=AMPS", allow_negative_numbers = true)]
    current_offset: Vec<String>,
    /// Fault injection: one resolver glitch of `AXIS=COUNTS` on the first feedback.
    #[arg(long, value_name = "AXIS=COUNTS", allow_negative_numbers = true)]
    resolver_glitch: Option<String>,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    duration: Option<f64>,
}

/// Arguments of `pa10 sim measure`.
#[derive(Debug, Args)]
pub struct MeasureArgs {
    /// Seed of the hidden truth and of every measurement.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory: cal.csv, lines.csv, val.csv (with sidecars) and truth.yaml.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Repeats per calibration configuration and load.
    #[arg(long, default_value_t = 10)]
    repeats: usize,
}

/// Arguments of `pa10 sim replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// SocketCAN interface to send on.
    #[arg(long, value_name = "IFACE")]
    can: String,
    /// The candump log.
    file: PathBuf,
}

/// `pa10 sim …`.
pub fn sim(a: &SimArgs) -> Result<()> {
    match &a.cmd {
        Some(SimCmd::Measure(m)) => measure(m),
        Some(SimCmd::Discovery(d)) => crate::discover_cmd::sim(d),
        Some(SimCmd::Replay(r)) => replay(r),
        Some(SimCmd::Decode { file }) => decode_log(file),
        None => run_sim(&a.run),
    }
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Opens a SocketCAN interface (Linux only).
#[cfg(target_os = "linux")]
fn open_can(iface: &str) -> Result<pa10::can::socketcan_bus::SocketCanBus> {
    pa10::can::socketcan_bus::SocketCanBus::open(iface).with_context(|| {
        format!("opening CAN interface {iface} (is it up? `ip link set up {iface}`)")
    })
}

#[cfg(not(target_os = "linux"))]
fn open_can(iface: &str) -> Result<pa10::can::VirtualEndpoint> {
    anyhow::bail!("{iface}: SocketCAN needs Linux")
}

fn run_sim(a: &RunArgs) -> Result<()> {
    use pa10::sim::servo::{self, ServoConfig, ServoSim};
    let Some(iface) = a.can.as_deref() else {
        anyhow::bail!("`pa10 sim` needs --can IFACE (or a subcommand: measure, replay)");
    };
    if let Some(d) = a.duration
        && !(d.is_finite() && d > 0.0)
    {
        anyhow::bail!("--duration must be > 0 s, got {d}");
    }
    let noise = pa10::sim::SimNoise::default();
    let truth = match &a.truth {
        Some(p) => pa10::sim::TrueRobot::from_model(
            pa10::model::Model::load(p)
                .with_context(|| format!("loading truth {}", p.display()))?,
            noise,
            a.seed,
        ),
        None => {
            let tool = pa10::model::frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0]);
            pa10::sim::TrueRobot::draw(a.seed, &pa10::model::Model::nominal(), &tool, noise)?
        }
    };
    let home = [0.0, 0.5, 1.2, 0.0, 0.9, 0.0];
    let mut servo_sim = ServoSim::new(truth, ServoConfig::default(), home, a.seed);
    servo_sim.injected.mute_axis = a.mute_axis;
    for spec in &a.current_offset {
        let (axis, amps) = axis_value(spec, "--current-offset")?;
        servo_sim.injected.current_offset_a[axis - 1] = amps;
    }
    if let Some(spec) = &a.resolver_glitch {
        let (axis, counts) = axis_value(spec, "--resolver-glitch")?;
        servo_sim.injected.resolver_glitch = Some((axis as u8, counts as i32));
    }
    let sim = std::sync::Arc::new(std::sync::Mutex::new(servo_sim));
    let mut logger = match &a.log {
        Some(p) => Some(pa10::can::candump::Logger::new(
            std::io::BufWriter::new(
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?,
            ),
            iface,
        )),
        None => None,
    };
    let rt = runtime()?;
    rt.block_on(async {
        let bus = open_can(iface)?;
        let (tx, rx) = tokio::sync::watch::channel(false);
        let duration = a.duration;
        tokio::spawn(async move {
            match duration {
                Some(d) => tokio::time::sleep(std::time::Duration::from_secs_f64(d)).await,
                None => {
                    let _ = tokio::signal::ctrl_c().await;
                }
            }
            let _ = tx.send(true);
        });
        eprintln!("pa10 sim: simulated PA10 servo controller on {iface} (Ctrl-C stops)");
        let wall0 = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0);
        servo::run(bus, sim, std::time::Duration::from_millis(1), rx, |t, f| {
            if let Some(l) = logger.as_mut() {
                let _ = l.log(wall0 + t, f);
            }
        })
        .await
        .with_context(|| format!("serving {iface}"))?;
        if let Some(l) = logger.as_mut() {
            l.flush()?;
        }
        anyhow::Ok(())
    })
}

/// Parses `AXIS=VALUE` with AXIS in 1…6.
fn axis_value(spec: &str, flag: &str) -> Result<(usize, f64)> {
    let parsed = spec.split_once('=').and_then(|(a, v)| {
        Some((
            a.trim().parse::<usize>().ok()?,
            v.trim().parse::<f64>().ok()?,
        ))
    });
    match parsed {
        Some((a, v)) if (1..=6).contains(&a) && v.is_finite() => Ok((a, v)),
        _ => {
            anyhow::bail!("{flag} takes AXIS=VALUE with AXIS 1…6 and a finite value, got `{spec}`")
        }
    }
}

/// `{"id": …, "signals": {name: value}}`: what the cantools check compares.
fn signals_json(id: u16, m: &pa10::can::Message) -> serde_json::Value {
    let signals: serde_json::Map<String, serde_json::Value> = pa10::can::signals::signals(m)
        .into_iter()
        .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
        .collect();
    serde_json::json!({ "id": id, "signals": signals })
}

fn decode_log(file: &Path) -> Result<()> {
    let records = pa10::can::candump::read_log(file)?;
    let mut out = Vec::with_capacity(records.len());
    for (k, r) in records.iter().enumerate() {
        let m = pa10::can::protocol::decode(&r.frame)
            .with_context(|| format!("{}: frame {}", file.display(), k + 1))?;
        out.push(signals_json(r.frame.id(), &m));
    }
    println!("{}", serde_json::Value::Array(out));
    Ok(())
}

fn replay(a: &ReplayArgs) -> Result<()> {
    let entries = pa10::can::candump::read_log(&a.file)?;
    let rt = runtime()?;
    let n = rt.block_on(async {
        let mut bus = open_can(&a.can)?;
        pa10::can::candump::replay(&mut bus, &entries)
            .await
            .with_context(|| format!("sending on {}", a.can))
    })?;
    eprintln!("replayed {n} frames on {}", a.can);
    Ok(())
}

/// `pa10 sim measure`.
fn measure(a: &MeasureArgs) -> Result<()> {
    let spec = CampaignSpec {
        seed: a.seed,
        repeats: a.repeats,
        ..Default::default()
    };
    let camp = paper_campaign(&spec)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    camp.cal.save(a.out.join("cal.csv"))?;
    camp.lines.save(a.out.join("lines.csv"))?;
    camp.val.save(a.out.join("val.csv"))?;
    let truth = format!(
        "# HIDDEN TRUTH of the simulated robot (pa10 sim measure --seed {}).\n# The calibration never reads this file; compare against it afterwards.\n{}",
        a.seed,
        camp.truth.model.to_yaml()
    );
    std::fs::write(a.out.join("truth.yaml"), truth).with_context(|| "writing truth.yaml")?;
    println!(
        "wrote {}: cal.csv ({} rows), lines.csv ({} rows), val.csv ({} rows), their .meta.yaml sidecars, truth.yaml (hidden truth)",
        a.out.display(),
        camp.cal.rows.len(),
        camp.lines.rows.len(),
        camp.val.rows.len()
    );
    Ok(())
}

/// Row weighting choice on the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum WeightingArg {
    /// From the noise the data show: reading noise, repeatable error, instrument and
    /// torque noise estimated from the repeats (default).
    Measured,
    /// Generalised least squares assuming a repeatable resolver error of the sidecar's σ.
    Gls,
    /// The paper's cost exactly.
    Paper,
}

/// Arguments of `pa10 calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Calibration dataset (CSV; a `.meta.yaml` sidecar beside it is read).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Straight-line moves along the robot's x and y axes (ids x0…, y0…) for the base-frame
    /// seed; without it the seed is a point fit.
    #[arg(long, value_name = "FILE")]
    base_seed: Option<PathBuf>,
    /// Validation dataset: configurations and loads outside the calibration set.
    #[arg(long, value_name = "FILE")]
    validate: Option<PathBuf>,
    /// Where to write the calibrated model (YAML).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Fit linear stiffness only (Kcub = 0).
    #[arg(long)]
    linear_only: bool,
    /// The paper's regularisation weight ε (it used 1.6e-4; see docs/calibration.md).
    #[arg(long, default_value_t = 0.0)]
    epsilon: f64,
    /// Row weighting.
    #[arg(long, value_enum, default_value = "measured")]
    weighting: WeightingArg,
    /// Number of starts (multi-start).
    #[arg(long, default_value_t = 4)]
    starts: usize,
    /// Seed of the random starts.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Inner-level configurations: `all` (every unloaded one) or a comma-separated id list;
    /// default: the sidecar's, else every unloaded one with the measured weighting and 8
    /// spread-out ones with the others.
    #[arg(long, value_name = "all|ID,…")]
    inner_configs: Option<String>,
    /// Motor current → joint torque constants, N·m/A, six comma-separated (for `i1..i6` data).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    torque_constants: Option<Vec<f64>>,
    /// Write residual plots (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
}

/// Loads a dataset (and its sidecar), naming the file in errors.
pub(crate) fn load(p: &Path) -> Result<Dataset> {
    Dataset::load(p).with_context(|| format!("loading {}", p.display()))
}

/// `--torque-constants` as six values, N·m/A.
pub(crate) fn torque_constants(v: &Option<Vec<f64>>) -> Result<Option<[f64; 6]>> {
    v.as_ref()
        .map(|v| {
            <[f64; 6]>::try_from(v.as_slice()).map_err(|_| {
                anyhow::anyhow!("--torque-constants takes six values, got {}", v.len())
            })
        })
        .transpose()
}

/// `pa10 calibrate`.
pub fn calibrate(a: &CalibrateArgs) -> Result<()> {
    let model = a.model.load()?;
    let data = load(&a.data)?;
    let lines = a.base_seed.as_deref().map(load).transpose()?;
    let val = a.validate.as_deref().map(load).transpose()?;
    let inner_configs = match a.inner_configs.as_deref() {
        None => None,
        Some("all") => {
            let mut ids: Vec<String> = data
                .rows
                .iter()
                .filter(|r| r.load_n == 0.0)
                .map(|r| r.config_id.clone())
                .collect();
            ids.dedup();
            ids.sort();
            ids.dedup();
            Some(ids)
        }
        Some(list) => Some(list.split(',').map(|s| s.trim().to_string()).collect()),
    };
    let torque_constants = torque_constants(&a.torque_constants)?;
    let opts = CalibOptions {
        epsilon: a.epsilon,
        linear_only: a.linear_only,
        starts: a.starts,
        seed: a.seed,
        inner_configs,
        torque_constants,
        weighting: match a.weighting {
            WeightingArg::Measured => Weighting::Measured,
            WeightingArg::Gls => Weighting::Gls,
            WeightingArg::Paper => Weighting::Paper,
        },
        ..Default::default()
    };
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bar = ProgressBar::new(opts.starts as u64).with_message("starts");
    let outcome = report::run(&model, &data, lines.as_ref(), val.as_ref(), &opts, &|n| {
        bar.set_position(n as u64)
    })?;
    bar.finish_and_clear();
    outcome
        .result
        .model
        .save(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    if let Some(dir) = &a.report {
        plots(dir, &outcome, &data, val.as_ref(), opts.r_max)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&outcome.report)?);
    } else {
        print_report(&outcome.report, &a.out)?;
    }
    Ok(())
}

fn sorted(m: &ByLoad) -> Vec<&pa10::calib::fit::ErrorSummary> {
    let mut v: Vec<_> = m.values().collect();
    v.sort_by(|a, b| a.load_n.total_cmp(&b.load_n));
    v
}

fn print_report(r: &Report, out: &Path) -> Result<()> {
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "calibration: {} rows, {} configurations, {} starts, weighting {:?}, ε = {}{} ({:.2} s)",
        r.rows,
        r.configurations,
        r.start_costs.len(),
        r.weighting,
        r.epsilon,
        if r.linear_only {
            ", linear stiffness only"
        } else {
            ""
        },
        r.elapsed_s
    )?;
    if let Some(n) = &r.noise {
        writeln!(o, "{}", n.summary())?;
        if let Some(a) = &n.assumption {
            writeln!(o, "  assumed: {a}")?;
        }
        writeln!(
            o,
            "  weights: {}",
            if n.structure.shares_offsets() {
                "GLS with the repeatable error the configuration means show"
            } else {
                "per row (no repeatable error shows between configurations)"
            }
        )?;
    }
    writeln!(
        o,
        "\ncalibration set      before (nominal)                 after"
    )?;
    writeln!(
        o,
        "  load [N]  rows   mean / peak [mm]  orient [deg]   mean / peak [mm]  orient [deg]"
    )?;
    for (b, a) in sorted(&r.before).iter().zip(sorted(&r.after)) {
        writeln!(
            o,
            "  {:8.1}  {:4}   {:6.3} / {:6.3}   {:8.4}       {:6.3} / {:6.3}   {:8.4}",
            b.load_n,
            b.rows,
            b.mean_mm,
            b.peak_mm,
            b.mean_orient_deg,
            a.mean_mm,
            a.peak_mm,
            a.mean_orient_deg
        )?;
    }
    if let Some(v) = &r.validation {
        writeln!(
            o,
            "\nvalidation set       nominal            linear stiffness    full model          resolver floor"
        )?;
        writeln!(
            o,
            "  load [N]  rows   mean / peak [mm]   mean / peak [mm]    mean / peak [mm]    mean [mm]"
        )?;
        for ((b, l), a) in sorted(&v.before)
            .iter()
            .zip(sorted(&v.linear))
            .zip(sorted(&v.after))
        {
            let floor = v
                .floor_mm
                .get(&format!("{}", a.load_n))
                .copied()
                .unwrap_or(f64::NAN);
            writeln!(
                o,
                "  {:8.1}  {:4}   {:6.3} / {:6.3}    {:6.3} / {:6.3}     {:6.3} / {:6.3}     {:6.3}",
                b.load_n,
                b.rows,
                b.mean_mm,
                b.peak_mm,
                l.mean_mm,
                l.peak_mm,
                a.mean_mm,
                a.peak_mm,
                floor
            )?;
        }
    }
    writeln!(o, "\nidentified parameters (± standard error)")?;
    for p in &r.params {
        let (scale, unit) = match p.unit.as_str() {
            "m" => (1e3, "mm"),
            "rad" => (1e3, "mrad"),
            u => (1.0, u),
        };
        match p.std_error {
            Some(se) => writeln!(
                o,
                "  {:8} {:+12.5e} ± {:10.3e} {unit}",
                p.name,
                p.value * scale,
                se * scale
            )?,
            None => writeln!(
                o,
                "  {:8} {:+12.5e}   (fixed)    {unit}",
                p.name,
                p.value * scale
            )?,
        }
    }
    let sv = &r.singular_values;
    writeln!(
        o,
        "\nidentification Jacobian (scaled): {} singular values, largest {:.3e}, smallest {:.3e}; {} structurally null; condition number of the rest {:.3e}",
        sv.len(),
        sv.first().copied().unwrap_or(0.0),
        sv.last().copied().unwrap_or(0.0),
        r.null_directions,
        r.condition_number
    )?;
    if !r.weak.is_empty() {
        writeln!(
            o,
            "warning: {} parameter combination(s) cannot be identified from this data; they were held near nominal/seed:",
            r.weak.len()
        )?;
        for w in &r.weak {
            let names: Vec<String> = w
                .params
                .iter()
                .map(|(n, l)| format!("{n} ({l:+.2})"))
                .collect();
            writeln!(
                o,
                "  std error {:7.2} (tolerances / log-units): {}",
                w.std_error,
                names.join(", ")
            )?;
        }
    }
    writeln!(o, "\nwrote {}", out.display())?;
    Ok(())
}

fn plots(
    dir: &Path,
    outcome: &report::Outcome,
    data: &Dataset,
    val: Option<&Dataset>,
    r_max: f64,
) -> Result<()> {
    let per_config = |model: &pa10::model::Model, d: &Dataset| -> Vec<(String, Vec<(f64, f64)>)> {
        let mut ids: Vec<&str> = Vec::new();
        let mut series: Vec<(String, Vec<(f64, f64)>)> = d
            .loads()
            .iter()
            .map(|l| (format!("{l} N"), Vec::new()))
            .collect();
        for r in &d.rows {
            let k = ids
                .iter()
                .position(|i| *i == r.config_id)
                .unwrap_or_else(|| {
                    ids.push(&r.config_id);
                    ids.len() - 1
                });
            let tau = match r.effort {
                pa10::calib::dataset::Effort::Torque(t) => t,
                pa10::calib::dataset::Effort::Current(_) => [0.0; 6],
            };
            let e = row_residual(model, &r.q, &tau, &r.pose, r_max)
                .fixed_rows::<3>(0)
                .norm()
                * r_max
                * 1e3;
            if let Some(s) = d.loads().iter().position(|l| *l == r.load_n) {
                series[s].1.push((k as f64, e));
            }
        }
        series
    };
    for (name, title, model, d) in [
        (
            "residuals-before.svg",
            "position error before calibration (nominal model), per configuration",
            &outcome.before_model,
            Some(data),
        ),
        (
            "residuals-after.svg",
            "position error after calibration, per configuration",
            &outcome.result.model,
            Some(data),
        ),
        (
            "validation-after.svg",
            "validation: position error of the calibrated model, per configuration",
            &outcome.result.model,
            val,
        ),
    ] {
        if let Some(d) = d {
            pa10::plot::series(
                &dir.join(name),
                title,
                "configuration (order of appearance)",
                "position error [mm]",
                &per_config(model, d),
            )?;
        }
    }
    Ok(())
}
