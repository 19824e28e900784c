//! Control-cycle timing of the daemon on the virtual bus with the simulated controller, on
//! classic CAN and on CAN FD.
//!
//! `cargo run --release --example daemon_cycle [SECONDS]` — runs the real-time daemon at 500 Hz
//! and at the highest rate the 90 % budget of a 1 Mbit/s classic bus allows, then on CAN FD
//! (1 Mbit/s arbitration, 5 Mbit/s data) at 1 kHz and 2 kHz, moving the arm back and forth,
//! and prints the cycle statistics `status` reports (wake-up jitter and cycle compute time,
//! p50/p99/max), the configured worst-case bus load and the load the virtual bus measured
//! (exact bits of the frames sent, each phase at its rate). BENCHMARKS.md quotes its output.

use pa10::can::BusTiming;
use serde_json::Value;

mod common;

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let classic_max = BusTiming::classic(1e6).max_rate_hz(0.9).floor();
    println!(
        "| bus | rate | cycles | overruns | incomplete | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | bus load worst / measured |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (fd, rate) in [
        (None, 500.0),
        (None, classic_max),
        (Some(5e6), 1000.0),
        (Some(5e6), 2000.0),
    ] {
        let cfg = common::sim_config_on(rate, "cycle", fd);
        let (arm, d) = common::start(&cfg);
        let t0 = std::time::Instant::now();
        let wire0 = arm.bus_stats().wire_s;
        common::back_and_forth(&d.core, secs);
        let measured = (arm.bus_stats().wire_s - wire0) / t0.elapsed().as_secs_f64();
        let st: Value = common::status_json(&d.core);
        let c = &st["cycle"];
        let f = common::triple;
        println!(
            "| {} | {rate} Hz | {} | {} | {} | {} | {} | {:.1} % / {:.1} % |",
            cfg.bus.timing().describe(),
            c["cycles"],
            c["overruns"],
            st["link"]["incomplete"],
            f(&c["jitter_us"]),
            f(&c["compute_us"]),
            c["bus_load_pct"].as_f64().unwrap_or(0.0),
            measured * 100.0
        );
        if st["state"] != "holding" {
            println!("(ended in {}: {})", st["state"], st["fault"]);
        }
    }
}
