//! A client streaming `servo` setpoints at 500 Hz over the real socket to the real-time
//! daemon on the simulated arm (control thread SCHED_FIFO where permitted), against a quiet
//! run: the loop's wake-up jitter and compute time with and without the stream, how many
//! setpoints arrived, and how closely the setpoint followed the streamed target.
//!
//! `cargo run --release --example servo_stream [SECONDS]` — BENCHMARKS.md quotes it.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use serde_json::json;

mod common;

fn main() {
    let (secs, fifo, dir) = common::setup("servo-stream", 5.0);
    println!(
        "| run | s | setpoints sent / refused | max lag after 1 s [mrad] | cycles | overruns | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | ended |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for streaming in [false, true] {
        let mut cfg = common::sim_config(500.0, if streaming { "stream" } else { "still" });
        let path = dir.join(if streaming {
            "stream.sock"
        } else {
            "still.sock"
        });
        let served = common::Served::start(&mut cfg, fifo, &path);
        let (mut sent, mut refused, mut lag) = (0usize, 0usize, 0.0f64);
        let t0 = Instant::now();
        if streaming {
            let mut s = UnixStream::connect(&path).expect("connect");
            let mut r = BufReader::new(s.try_clone().expect("clone"));
            let home = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
            let mut next = t0;
            while t0.elapsed().as_secs_f64() < secs {
                // a 0.2 Hz sine of 0.2 rad on joints 1 and 6: ≤ 0.25 rad/s
                let t = t0.elapsed().as_secs_f64();
                let mut q = home;
                let w = 2.0 * std::f64::consts::PI * 0.2;
                q[0] += 0.2 * (w * t).sin();
                q[5] += 0.2 * (w * t).sin();
                let line = json!({"cmd": "servo", "positions": q}).to_string();
                s.write_all(format!("{line}\n").as_bytes()).expect("send");
                let mut answer = String::new();
                r.read_line(&mut answer).expect("answer");
                sent += 1;
                if !answer.contains("\"ok\":true") {
                    refused += 1;
                }
                // after the start-up catch-up (the target starts at 0.25 rad/s from rest)
                if sent % 50 == 0 && t > 1.0 {
                    let st = served.status();
                    let sp: [f64; 6] = serde_json::from_value(st["setpoint"].clone()).expect("six");
                    lag = lag.max((sp[0] - q[0]).abs().max((sp[5] - q[5]).abs()));
                }
                next += Duration::from_millis(2);
                if let Some(d) = next.checked_duration_since(Instant::now()) {
                    std::thread::sleep(d);
                }
            }
        } else {
            std::thread::sleep(Duration::from_secs_f64(secs));
        }
        let seconds = t0.elapsed().as_secs_f64();
        let st = served.status();
        served.stop();
        let c = &st["cycle"];
        println!(
            "| {} | {seconds:.1} | {sent} / {refused} | {:.2} | {} | {} | {} | {} | {} |",
            if streaming {
                "servo at 500 Hz"
            } else {
                "holding"
            },
            lag * 1e3,
            c["cycles"],
            c["overruns"],
            common::triple(&c["jitter_us"]),
            common::triple(&c["compute_us"]),
            st["state"]
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
