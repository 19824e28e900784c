//! Control-cycle timing of the daemon on the virtual bus with the simulated controller.
//!
//! `cargo run --release --example daemon_cycle [SECONDS]` — runs the daemon core at 500 Hz and
//! at the highest rate the 90 % bus budget allows, moving the arm back and forth, and prints
//! the cycle statistics `status` reports (wake-up jitter and cycle compute time, p50/p99/max).
//! BENCHMARKS.md quotes its output.

use std::time::Duration;

use pa10::daemon::api::handle;
use serde_json::{Value, json};

mod common;

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let max_rate = (0.9 * 1e6 / pa10::can::protocol::cycle_bits_worst() as f64).floor();
    println!(
        "| rate | cycles | overruns | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | bus load |"
    );
    println!("|---|---|---|---|---|---|");
    for rate in [500.0, max_rate] {
        let cfg = common::sim_config(rate, "cycle");
        let (_arm, d) = common::start(&cfg);
        let a = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
        let b = [0.3, 0.6, 1.3, 0.4, 0.8, 0.5];
        let end = std::time::Instant::now() + Duration::from_secs_f64(secs);
        let mut k = 0;
        while std::time::Instant::now() < end {
            let q = if k % 2 == 0 { b } else { a };
            let r = handle(&d.core, &json!({"cmd": "move_joints", "q": q}).to_string());
            let dur = r["duration_s"].as_f64().unwrap_or(0.5);
            std::thread::sleep(Duration::from_secs_f64(dur + 0.1));
            k += 1;
        }
        let st: Value = handle(&d.core, r#"{"cmd":"status"}"#)["status"].clone();
        let c = &st["cycle"];
        let f = common::triple;
        println!(
            "| {rate} Hz | {} | {} | {} | {} | {:.1} % |",
            c["cycles"],
            c["overruns"],
            f(&c["jitter_us"]),
            f(&c["compute_us"]),
            c["bus_load_pct"].as_f64().unwrap_or(0.0)
        );
        if st["state"] != "holding" {
            println!("(ended in {}: {})", st["state"], st["fault"]);
        }
    }
}
