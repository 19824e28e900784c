//! The control loop's timing while a client plans Cartesian moves back to back.
//!
//! `cargo run --release --example jitter_planning [SECONDS]` — runs the daemon core at 500 Hz
//! on the virtual bus twice: once with no client, once with a client thread sending
//! `move_pose` requests back to back between two poses 0.2 mm apart (each request plans a
//! straight line, ≈ 200 IK solves, ≈ 1 ms; the moves are short, so most requests plan and
//! start a move, and one refused because a move still runs is sent again 1 ms later; the
//! client sleeps 1 ms after every answer so that it takes about half of one core). Prints
//! the number of moves planned and started, wake-up jitter and cycle compute time
//! (p50 / p99 / max, µs) from `status`. BENCHMARKS.md quotes its output.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use pa10::daemon::api::handle;
use pa10::daemon::runtime::lock;
use pa10::daemon::wire::{ApiRequest, Reply};
use serde_json::Value;

mod common;

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    println!(
        "| client | moves planned and started | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | overruns | state at the end |"
    );
    println!("|---|---|---|---|---|---|");
    for planning in [false, true] {
        let cfg = common::sim_config(500.0, "jitter");
        let (_arm, d) = common::start(&cfg);
        let stop = Arc::new(AtomicBool::new(false));
        let count = Arc::new(AtomicU64::new(0));
        let client = planning.then(|| {
            let shared = d.core.clone();
            let (stop, count) = (stop.clone(), count.clone());
            std::thread::spawn(move || {
                // the setpoint's own tool pose and one 0.2 mm away along x
                let st = lock(&shared).status();
                let (p0, quaternion) = (st.tool_position, st.tool_quaternion);
                let poses = [[p0[0], p0[1], p0[2]], [p0[0] + 2e-4, p0[1], p0[2]]];
                let mut k = 1;
                while !stop.load(Ordering::Relaxed) {
                    let p = poses[k % 2];
                    let request = ApiRequest::MovePose {
                        position: p,
                        quaternion,
                    };
                    match handle(&shared, request) {
                        Reply::Ok(_) => {
                            count.fetch_add(1, Ordering::Relaxed);
                            k += 1;
                        }
                        Reply::Refused(e) if e.contains("in progress") => {}
                        Reply::Refused(e) => {
                            eprintln!("client stops: {e}");
                            return;
                        }
                    }
                    // about half a core: the host keeps one for the loop and the simulator
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
        });
        std::thread::sleep(Duration::from_secs_f64(secs));
        stop.store(true, Ordering::Relaxed);
        if let Some(c) = client {
            c.join().expect("client thread");
        }
        let st: Value = common::status_json(&d.core);
        let c = &st["cycle"];
        let f = common::triple;
        println!(
            "| {} | {} | {} | {} | {} | {} |",
            if planning {
                "move_pose back to back"
            } else {
                "none"
            },
            count.load(Ordering::Relaxed),
            f(&c["jitter_us"]),
            f(&c["compute_us"]),
            c["overruns"],
            match st["fault"].as_str() {
                Some(f) => format!("{}: {f}", st["state"]),
                None => st["state"].to_string(),
            },
        );
    }
}
