//! Tracking at the loop rates the bus allows: classic CAN at 500 Hz against CAN FD (1 Mbit/s
//! arbitration, 5 Mbit/s data) at 1 kHz and 2 kHz, judged by the simulator's true link angles.
//!
//! The daemon's unchanged core runs the simulated arm in simulated time (`Lockstep`) with the
//! wire modelled: every frame waits for the bus, takes its exact time at the arbitration and
//! data bit rates and reaches the other side 20 µs after its last bit. The daemon holds the
//! model calibrated on the seed's paper campaign (so that what is left is the loop, not the
//! model). For each bus:
//! 1. `docs/motion.md`'s six-point trajectory at 0 and 90 N: true link − desired, every cycle;
//! 2. a servo stream at the loop's own rate (a 0.2 Hz sine on four joints, one setpoint a
//!    cycle) at 0 and 90 N: true link − the streamed target, after the first second;
//! 3. the wire's measured load beside the configured worst case.
//!
//! `cargo run --release --example fd_tracking [-- --seed N]` — BENCHMARKS.md and
//! `docs/motion.md` quote it.

use std::path::Path;

use pa10::calib::fit::{CalibOptions, calibrate};
use pa10::daemon::config::{Config, Settings};
use pa10::model::Model;
use pa10::sim::experiment::{CampaignSpec, paper_campaign};
use pa10::sim::rig::Lockstep;
use serde_json::json;

#[path = "common/six_points.rs"]
mod motion_path;
use motion_path::six_points;
#[path = "common/tracking.rs"]
mod tracking;

/// From a frame's last bit to the receiver acting on it, s.
const WIRE_LATENCY_S: f64 = 20e-6;
/// The stream's sine amplitudes about HOME, rad.
const AMP: [f64; 6] = [0.2, 0.1, -0.1, 0.0, 0.2, 0.0];

fn main() {
    let seed: u64 = std::env::args()
        .skip_while(|a| a != "--seed")
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let dir = std::env::temp_dir().join(format!("pa10-fd-tracking-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let camp = paper_campaign(&CampaignSpec {
        seed,
        repeats: 3,
        ..Default::default()
    })
    .expect("campaign");
    let model = calibrate(
        &Model::nominal(),
        &camp.cal,
        Some(&camp.lines),
        &CalibOptions::default(),
        &|_| {},
    )
    .expect("calibration")
    .model;
    model.save(dir.join("model.yaml")).expect("model");
    println!("seed {seed}: the daemon holds the model calibrated on the seed's paper campaign");
    println!();
    println!(
        "| bus | rate | load | six-point RMS / peak [mrad] | stream RMS / peak [mrad] | wire load worst / measured |"
    );
    println!("|---|---|---|---|---|---|");
    for (fd, rate) in [(None, 500.0), (Some(5e6), 1000.0), (Some(5e6), 2000.0)] {
        let settings = settings(&dir, seed, rate, fd);
        for load in [0.0, 90.0] {
            let mut ls = rig(&settings, load);
            let ok = |_: &Lockstep| Ok::<(), String>(());
            let (rms, peak, ended) =
                tracking::trajectory(&mut ls, &six_points(), 1.0 / rate, 20.0, ok)
                    .expect("the six points");
            assert_eq!(ended, "succeeded");
            let mut ls2 = rig(&settings, load);
            let (s_rms, s_peak) =
                tracking::sine_stream(&mut ls2, 1.0 / rate, 4.0, AMP, ok).expect("the stream");
            println!(
                "| {} | {rate} Hz | {load} N | {rms:.3} / {peak:.3} | {s_rms:.3} / {s_peak:.3} | {:.1} % / {:.1} % |",
                settings.bus.timing().describe(),
                settings.bus_load * 100.0,
                ls.wire_load().unwrap_or(0.0) * 100.0
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `config/sim.yaml` with the calibrated model in `dir`, the seed's arm, `rate_hz` and, with
/// `fd`, CAN FD at that data bit rate.
fn settings(dir: &Path, seed: u64, rate_hz: f64, fd: Option<f64>) -> Settings {
    let bus = match fd {
        Some(d) => format!("  bitrate: 1000000\n  fd: true\n  data_bitrate: {d}"),
        None => "  bitrate: 1000000".to_string(),
    };
    let text = include_str!("../config/sim.yaml")
        .replace("  bitrate: 1000000          # bit/s", &bus)
        .replace("rate_hz: 500 ", &format!("rate_hz: {rate_hz} "))
        .replace("model: model-nominal.yaml", "model: model.yaml")
        .replace("  seed: 1", &format!("  seed: {seed}"))
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", dir.join("api.sock").display()),
        );
    let path = dir.join(format!("pa10d-{rate_hz}.yaml"));
    std::fs::write(&path, text).expect("config");
    Config::load(&path).expect("valid configuration")
}

/// The daemon on the simulated arm at `load_n` (N), the wire modelled, holding and settled.
fn rig(settings: &Settings, load_n: f64) -> Lockstep {
    let mut ls = Lockstep::from_config(settings)
        .expect("simulated arm")
        .with_wire(settings.bus.timing(), WIRE_LATENCY_S);
    ls.run_until_ready(1.0).expect("ready");
    ls.servo.set_load(load_n);
    let r = ls.call_json(&json!({"cmd": "set_payload", "newtons": load_n}));
    assert_eq!(r["ok"], true, "{r}");
    ls.run_for(1.0); // the measured torques settle
    ls
}
