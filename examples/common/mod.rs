//! What the real-time daemon examples share: starting the daemon on the simulated arm from
//! `config/sim.yaml`, and printing `status` percentiles.

use pa10::daemon::config::{Config, Loaded};
use pa10::daemon::runtime::Daemon;
use pa10::sim::rig::SimulatedArm;
use serde_json::Value;

/// `config/sim.yaml` at `rate_hz`, with a private socket path.
pub fn sim_config(rate_hz: f64, tag: &str) -> Loaded {
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let text = std::fs::read_to_string(base.join("sim.yaml")).expect("config/sim.yaml");
    let sock = std::env::temp_dir().join(format!("pa10-{tag}-{}.sock", std::process::id()));
    let t = text
        .replace("rate_hz: 500", &format!("rate_hz: {rate_hz}"))
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", sock.display()),
        );
    Config::parse(&t, tag)
        .expect("config")
        .validate(&base)
        .expect("valid")
}

/// The real-time daemon on the simulated arm of `cfg` (drop the daemon first).
#[allow(dead_code)] // each example compiles this module; not every one starts this way
pub fn start(cfg: &Loaded) -> (SimulatedArm, Daemon) {
    let arm = SimulatedArm::from_config(cfg).expect("simulated arm");
    let d = Daemon::start(cfg, arm.host()).expect("daemon");
    (arm, d)
}

/// `p50 / p99 / max` of a status triple, µs.
pub fn triple(v: &Value) -> String {
    format!(
        "{:.0} / {:.0} / {:.0}",
        v[0].as_f64().unwrap_or(0.0),
        v[1].as_f64().unwrap_or(0.0),
        v[2].as_f64().unwrap_or(0.0)
    )
}
