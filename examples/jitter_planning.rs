//! The control loop's timing while a client plans Cartesian moves back to back.
//!
//! `cargo run --release --example jitter_planning [SECONDS]` — runs the daemon core at 500 Hz
//! on the virtual bus twice: once with no client, once with a client thread sending
//! `move_pose` requests as fast as they are answered (each plans ≈ 200 IK solves; while a
//! move runs the new one is refused, after planning). Prints wake-up jitter and cycle compute
//! time (p50 / p99 / max, µs) from `status` for both. BENCHMARKS.md quotes its output.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use pa10::daemon::api::handle;
use pa10::daemon::config::Config;
use pa10::daemon::runtime::Daemon;
use serde_json::{Value, json};

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let text = std::fs::read_to_string(base.join("sim.yaml")).expect("config/sim.yaml");
    println!(
        "| client | requests | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | overruns |"
    );
    println!("|---|---|---|---|---|");
    for planning in [false, true] {
        let sock = std::env::temp_dir().join(format!("pa10-jitter-{}.sock", std::process::id()));
        let t = text.replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", sock.display()),
        );
        let cfg = Config::parse(&t, "bench")
            .expect("config")
            .validate(&base)
            .expect("valid");
        let d = Daemon::start(&cfg).expect("daemon");
        let stop = Arc::new(AtomicBool::new(false));
        let count = Arc::new(AtomicU64::new(0));
        let client = planning.then(|| {
            let shared = d.shared.clone();
            let (stop, count) = (stop.clone(), count.clone());
            std::thread::spawn(move || {
                let poses = [[0.55, -0.12, 0.30], [0.60, 0.12, 0.40]];
                let mut k = 0;
                while !stop.load(Ordering::Relaxed) {
                    let p = poses[k % 2];
                    let r = handle(
                        &shared,
                        &json!({"cmd": "move_pose", "position": p, "quaternion": [0.0, 1.0, 0.0, 0.0]})
                            .to_string(),
                    );
                    assert!(r.get("ok").is_some(), "{r}");
                    count.fetch_add(1, Ordering::Relaxed);
                    k += 1;
                }
            })
        });
        std::thread::sleep(Duration::from_secs_f64(secs));
        stop.store(true, Ordering::Relaxed);
        if let Some(c) = client {
            c.join().expect("client thread");
        }
        let st: Value = handle(&d.shared, r#"{"cmd":"status"}"#)["status"].clone();
        let c = &st["cycle"];
        let f = |v: &Value| {
            format!(
                "{:.0} / {:.0} / {:.0}",
                v[0].as_f64().unwrap_or(0.0),
                v[1].as_f64().unwrap_or(0.0),
                v[2].as_f64().unwrap_or(0.0)
            )
        };
        println!(
            "| {} | {} | {} | {} | {} |",
            if planning {
                "move_pose back to back"
            } else {
                "none"
            },
            count.load(Ordering::Relaxed),
            f(&c["jitter_us"]),
            f(&c["compute_us"]),
            c["overruns"],
        );
    }
}
