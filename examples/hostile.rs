//! The hostile-client suite in real time: the daemon on the simulated arm (control thread under
//! SCHED_FIFO where the host permits it), its real socket server, and a well-behaved client
//! moving the arm back and forth — once alone, once while four hostile clients send ≥ 1000
//! malformed requests of every class (`common/hostile.rs`). Prints the loop's timing of both
//! runs, the refusals, the moves landed and the memory grown.
//!
//! `cargo run --release --example hostile [SECONDS] [--check]` — with `--check` (CI runs it
//! so) it exits 1 if the arm faulted, or, under SCHED_FIFO, if the hostile run's p99 wake-up
//! jitter exceeds the quiet run's by more than max(2×, +1 ms) twice in a row (once may be
//! the VM's own noise; both runs are measured again) — on a host that was itself fit: a
//! SCHED_FIFO 90 watcher (`common::HostWatch`) measures the host's own stalls, and a run in
//! which the host stalled every thread (its p99 > 1 ms or one stall > 20 ms) is reported,
//! not judged. Every refusal is checked for
//! precision in both modes (a vague or leaking answer panics). BENCHMARKS.md quotes it.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;
#[path = "common/hostile.rs"]
mod suite;

/// Rounds of every class per hostile client (four clients: ≥ 1000 of every class).
const ROUNDS: usize = 250;

struct Run {
    status: Value,
    moves: usize,
    refused: usize,
    seconds: f64,
    rss_grown_kib: u64,
    host: common::HostStalls,
}

fn run(secs: f64, fifo: bool, hostile: bool, dir: &Path) -> Run {
    let mut cfg = common::sim_config(500.0, if hostile { "hostile" } else { "quiet" });
    // load_model's confinement is judged in the run's own folder (its secret.yaml included)
    cfg.api.model_dir = dir.to_path_buf();
    let path = dir.join(if hostile {
        "hostile.sock"
    } else {
        "quiet.sock"
    });
    let host = common::HostWatch::start(fifo);
    let served = common::Served::start(&mut cfg, fifo, &path);
    let rss0 = suite::rss_kib();
    let t0 = Instant::now();
    let requests = Arc::new(suite::requests(dir));
    let busy = Arc::new(AtomicBool::new(hostile));
    let clients: Vec<_> = (0..if hostile { 4 } else { 0 })
        .map(|_| {
            let (path, requests) = (path.clone(), requests.clone());
            std::thread::spawn(move || suite::hammer(&path, &requests, ROUNDS))
        })
        .collect();
    let (moves, fault) = {
        let busy = busy.clone();
        let end = t0 + Duration::from_secs_f64(secs);
        // moves go on for the duration and while the hostile clients are still at it
        let watcher = {
            let clients_done = busy.clone();
            move |_| Instant::now() < end || clients_done.load(Ordering::SeqCst)
        };
        let mover = {
            let path = path.clone();
            std::thread::spawn(move || suite::mover(&path, watcher))
        };
        let refused: usize = clients
            .into_iter()
            .map(|c| {
                c.join()
                    .expect("a hostile client panicked: an imprecise answer")
            })
            .sum();
        busy.store(false, Ordering::SeqCst);
        match mover.join().expect("the good client panicked") {
            Ok(n) => ((n, refused), None),
            Err(fault) => ((0, refused), Some(fault)),
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    let status = served.status();
    let rss_grown_kib = suite::rss_kib().saturating_sub(rss0);
    served.stop();
    let host = host.finish();
    if let Some(f) = fault {
        eprintln!("hostile: {f}");
    }
    Run {
        status,
        moves: moves.0,
        refused: moves.1,
        seconds,
        rss_grown_kib,
        host,
    }
}

/// One quiet and one hostile run: the faults, and the jitter rise when p99 under hostile
/// clients exceeds max(2×, +1 ms) of the quiet run's under SCHED_FIFO — each judged only when
/// the host itself was fit during the run (`common::HostWatch`): a fault or a rise while the
/// host stalled every thread is printed and not blamed on the daemon.
fn attempt(secs: f64, fifo: bool, dir: &std::path::Path) -> (Vec<String>, Option<String>) {
    println!(
        "| run | s | refused | good moves | cycles | overruns | incomplete / paused | jitter p50 / p99 / max [µs] | compute p50 / p99 / max [µs] | loop waited for a client: n, p99 / max [µs] | host's own stalls p99 / max [µs] | RSS + [KiB] | ended |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut p99 = [0.0; 2];
    let mut unfit = false;
    let mut faults = Vec::new();
    for (k, hostile) in [false, true].into_iter().enumerate() {
        let r = run(secs, fifo, hostile, dir);
        let (st, c) = (&r.status, &r.status["cycle"]);
        p99[k] = c["jitter_us"][1].as_f64().unwrap_or(f64::INFINITY);
        unfit |= r.host.unfit();
        if !st["fault"].is_null() && r.host.unfit() {
            println!(
                "(the {} run faulted while the host itself stalled: reported, not judged)",
                if hostile { "hostile" } else { "quiet" }
            );
        } else if !st["fault"].is_null() {
            faults.push(format!(
                "the {} run faulted: {}",
                if hostile { "hostile" } else { "quiet" },
                st["fault"]
            ));
        }
        println!(
            "| {} | {:.1} | {} | {} | {} | {} | {} / {} | {} | {} | {}, {:.0} / {:.0} | {} | {} | {} |",
            if hostile {
                "4 hostile clients"
            } else {
                "quiet"
            },
            r.seconds,
            r.refused,
            r.moves,
            c["cycles"],
            c["overruns"],
            st["link"]["incomplete"],
            st["link"]["paused"],
            common::triple(&c["jitter_us"]),
            common::triple(&c["compute_us"]),
            c["lock_waits"],
            c["lock_wait_us"][1].as_f64().unwrap_or(0.0),
            c["lock_wait_us"][2].as_f64().unwrap_or(0.0),
            r.host.cell(),
            r.rss_grown_kib,
            st["state"]
        );
    }
    let allowed = (2.0 * p99[0]).max(p99[0] + 1000.0);
    println!(
        "p99 jitter: quiet {:.0} µs, hostile {:.0} µs (allowed under SCHED_FIFO: {allowed:.0} µs)",
        p99[0], p99[1]
    );
    if unfit {
        println!("(the host itself stalled in a run: the jitter comparison is not judged)");
    }
    let jitter = (fifo && !unfit && p99[1] > allowed).then(|| {
        format!(
            "p99 jitter {:.0} µs under hostile clients > {allowed:.0} µs",
            p99[1]
        )
    });
    (faults, jitter)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let check = args.iter().any(|a| a == "--check");
    let (secs, fifo, dir) = common::setup("hostile-example", 5.0);
    let (mut faults, mut jitter) = attempt(secs, fifo, &dir);
    if check && faults.is_empty() && jitter.is_some() {
        // a jitter rise once may be the VM's own noise (it pauses every thread now and then);
        // a real one repeats: measure both runs again, and judge the second pair
        println!("the p99 rose once; measuring both runs again");
        (faults, jitter) = attempt(secs, fifo, &dir);
    }
    let _ = std::fs::remove_dir_all(&dir);
    let failed: Vec<String> = faults.into_iter().chain(jitter).collect();
    if check && !failed.is_empty() {
        for f in &failed {
            eprintln!("hostile: {f}");
        }
        std::process::exit(1);
    }
}
