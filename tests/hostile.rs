//! The hostile-client suite: thousands of malformed requests of every class the `[harden]`
//! issue found, sent over the real socket server while a well-behaved client keeps moving the
//! arm. The daemon core and the simulated controller run in simulated time on this thread
//! (`Lockstep`); the clients are plain `std` sockets on their own threads.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pa10::daemon::config::Config;
use pa10::model::Model;
use pa10::sim::rig::Lockstep;
use serde_json::json;

#[path = "../examples/common/hostile.rs"]
mod suite;

/// Rounds of every class per hostile client (four clients).
const ROUNDS: usize = 250;

#[test]
fn thousands_of_hostile_requests_change_nothing_while_a_good_client_moves_the_arm() {
    let _busy = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let loaded = Config::load(&crate::daemon::config(&dir, &Model::nominal())).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    ls.run_until_ready(1.0).unwrap();
    let path = dir.join("api.sock");
    let server = crate::daemon::Server::start(ls.core.clone(), &path, 64);
    let rss0 = suite::rss_kib();
    let requests = Arc::new(suite::requests(&dir));
    let done = Arc::new(AtomicBool::new(false));
    // four hostile clients, 250 rounds of every class each: ≥ 1000 of every class
    let hostile: Vec<_> = (0..4)
        .map(|_| {
            let (path, requests) = (path.clone(), requests.clone());
            std::thread::spawn(move || suite::hammer(&path, &requests, ROUNDS))
        })
        .collect();
    // the well-behaved client: back and forth, each move must land
    let good = {
        let (path, done) = (path.clone(), done.clone());
        std::thread::spawn(move || {
            let moves = suite::mover(&path, |m| m < 6);
            done.store(true, Ordering::SeqCst);
            moves
        })
    };
    // simulated time runs on this thread until the good client is done (at most 120 s of it)
    while !done.load(Ordering::SeqCst) && ls.now() < 120.0 {
        ls.run_for(0.01);
        std::thread::sleep(Duration::from_micros(200));
    }
    let refused: usize = hostile.into_iter().map(|t| t.join().unwrap()).sum();
    let moves = good.join().unwrap().expect("no fault in simulated time");
    assert_eq!(moves, 6);
    assert_eq!(refused, 4 * (ROUNDS * requests.len() + 1));
    const { assert!(4 * ROUNDS >= 1000) };
    let st = ls.call_json(&json!({"cmd": "status"}))["status"].clone();
    assert_eq!(st["state"], "holding", "{st}");
    assert_eq!(st["link"]["incomplete"], 0, "{st}");
    let grown = suite::rss_kib().saturating_sub(rss0);
    assert!(grown < 64 * 1024, "memory grew by {grown} KiB");
    eprintln!(
        "hostile: {refused} refused, {moves} good moves landed, {:.1} s simulated, RSS +{grown} KiB",
        ls.now()
    );
    server.stop();
    std::fs::remove_dir_all(&dir).unwrap();
}
