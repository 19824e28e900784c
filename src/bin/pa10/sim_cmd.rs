//! `pa10 sim …`: the simulated servo controller on a CAN interface (with fault injection and
//! a candump log), replaying and decoding candump logs, and the seed paper's measurement
//! campaign on a hidden simulated robot (`pa10 sim measure`; `pa10 sim discovery` lives with
//! `discover_cmd`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use pa10::sim::experiment::{CampaignSpec, paper_campaign};

/// `pa10 sim …`: without a subcommand, run the simulated servo controller on a CAN interface.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SimArgs {
    #[command(subcommand)]
    cmd: Option<SimCmd>,
    #[command(flatten)]
    run: SimRunArgs,
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
pub struct SimRunArgs {
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
    /// Speak CAN FD (one FEEDBACK_FD frame a cycle; COMMAND_FD or COMMAND taken) on an FD
    /// interface (MTU 72), as the daemon does with `bus.fd: true`.
    #[arg(long)]
    fd: bool,
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
    /// Open the interface for CAN FD (needed when the log holds FD frames).
    #[arg(long)]
    fd: bool,
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

/// The frame format `--fd` asks for.
fn framing_of(fd: bool) -> pa10::can::Framing {
    if fd {
        pa10::can::Framing::Fd
    } else {
        pa10::can::Framing::Classic
    }
}

/// Opens a SocketCAN interface (Linux only), for CAN FD frames too with [`Framing::Fd`](pa10::can::Framing::Fd).
#[cfg(target_os = "linux")]
fn open_can(
    iface: &str,
    framing: pa10::can::Framing,
) -> Result<pa10::can::socketcan_bus::SocketCanBus> {
    pa10::can::socketcan_bus::SocketCanBus::open_with(iface, framing).with_context(|| {
        format!("opening CAN interface {iface} (is it up? `ip link set up {iface}`)")
    })
}

#[cfg(not(target_os = "linux"))]
fn open_can(iface: &str, _framing: pa10::can::Framing) -> Result<pa10::can::VirtualEndpoint> {
    anyhow::bail!("{iface}: SocketCAN needs Linux")
}

fn run_sim(a: &SimRunArgs) -> Result<()> {
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
    let framing = framing_of(a.fd);
    let cfg = ServoConfig::speaking(framing);
    let mut servo_sim = ServoSim::new(truth, cfg, home, a.seed);
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
        let bus = open_can(iface, framing)?;
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
        let mut bus = open_can(&a.can, framing_of(a.fd))?;
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
