//! The loop's cost and timing with recording on vs off: the real-time daemon on the
//! simulated arm (control thread SCHED_FIFO where permitted) moving back and forth, once
//! without and once while recording every cycle to MCAP (zstd) in a temporary folder, at
//! 500 Hz on classic CAN and at 1 kHz on CAN FD (1/5 Mbit/s).
//!
//! `cargo run --release --example record_cycle [SECONDS]` — prints cycles, overruns, wake-up
//! jitter and compute time (p50 / p99 / max, µs), what the recorder wrote and dropped, and
//! the disk rate (file size over the recorded time, kB/s).
//! BENCHMARKS.md quotes it.

use std::time::Duration;

use pa10::daemon::api::handle;
use pa10::daemon::wire::{ApiRequest, Reply};

mod common;

fn main() {
    let (secs, fifo, dir) = common::setup("record-cycle", 10.0);
    println!(
        "| loop | recording | cycles | overruns | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | written / dropped | file [kB] | disk [kB/s] |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for ((fd, rate), record) in [(None, 500.0), (Some(5e6), 1000.0)]
        .into_iter()
        .flat_map(|r| [(r, false), (r, true)])
    {
        let tag = format!("{}{rate}", if record { "rec" } else { "norec" });
        let mut cfg = common::sim_config_on(rate, &tag, fd);
        cfg.record.dir = dir.clone();
        let path = dir.join(format!("{tag}.sock"));
        let served = common::Served::start(&mut cfg, fifo, &path);
        let core = served.daemon.core.clone();
        if record {
            let start = ApiRequest::RecordStart {
                file: Some(format!("bench-{rate}")),
                duration_s: None,
            };
            let r = handle(&core, start);
            assert!(matches!(r, Reply::Ok(_)), "{r:?}");
        }
        let t0 = std::time::Instant::now();
        common::back_and_forth(&core, secs);
        let recorded_s = t0.elapsed().as_secs_f64();
        let st = served.status();
        let _ = handle(&core, ApiRequest::RecordStop {});
        std::thread::sleep(Duration::from_millis(500));
        let rec = common::status_json(&core)["recording"].clone();
        served.stop();
        let c = &st["cycle"];
        println!(
            "| {rate} Hz {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            if fd.is_some() { "FD" } else { "classic" },
            if record { "on (zstd)" } else { "off" },
            c["cycles"],
            c["overruns"],
            common::triple(&c["jitter_us"]),
            common::triple(&c["compute_us"]),
            if record {
                format!(
                    "{} / {}",
                    rec["written"],
                    rec["dropped_queue"].as_u64().unwrap_or(0)
                        + rec["dropped_write"].as_u64().unwrap_or(0)
                )
            } else {
                "—".into()
            },
            if record {
                format!("{:.0}", rec["bytes"].as_f64().unwrap_or(0.0) / 1e3)
            } else {
                "—".into()
            },
            if record {
                format!(
                    "{:.0}",
                    rec["bytes"].as_f64().unwrap_or(0.0) / 1e3 / recorded_s
                )
            } else {
                "—".into()
            },
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
