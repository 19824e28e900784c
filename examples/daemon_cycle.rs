//! Control-cycle timing of the daemon on the virtual bus with the simulated controller.
//!
//! `cargo run --release --example daemon_cycle [SECONDS]` — runs the daemon core at 500 Hz and
//! at the highest rate the 90 % bus budget allows, moving the arm back and forth, and prints
//! the cycle statistics `status` reports (wake-up jitter and cycle compute time, p50/p99/max).
//! BENCHMARKS.md quotes its output.

use serde_json::Value;

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
        common::back_and_forth(&d.core, secs);
        let st: Value = common::status_json(&d.core);
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
