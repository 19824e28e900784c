//! The hostile-client suite: thousands of malformed requests of every class the `[harden]`
//! issue found, sent over the real socket server while a well-behaved client keeps moving the
//! arm. The daemon core and the simulated controller run in simulated time on this thread
//! (`Lockstep`); the clients are plain `std` sockets on their own threads.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pa10::daemon::config::Config;
use pa10::model::Model;
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

/// One request line (raw bytes) and its answer; `None` when the server closed.
fn ask(s: &mut UnixStream, line: &[u8]) -> Option<Value> {
    s.write_all(line).ok()?;
    s.write_all(b"\n").ok()?;
    let mut answer = String::new();
    BufReader::new(s.try_clone().ok()?)
        .read_line(&mut answer)
        .ok()?;
    serde_json::from_str(&answer).ok()
}

/// Every class of malformed request, each with what its refusal must say (alternatives split
/// by `|`: a move is refused as out of limits, or as busy while the good client's move runs).
fn hostile_requests(dir: &Path) -> Vec<(Vec<u8>, &'static str)> {
    let mut v: Vec<(Vec<u8>, &'static str)> = vec![
        (b"{not json".to_vec(), "bad request"),
        (b"".to_vec(), "bad request"),
        (br#"{"cmd":"fly"}"#.to_vec(), "bad request"),
        (br#"{"cmd":"estop","why":1}"#.to_vec(), "unknown field"),
        (br#"{"cmd":"stop","speed":0}"#.to_vec(), "unknown field"),
        (br#"{"cmd":"reset","now":true}"#.to_vec(), "unknown field"),
        (
            br#"{"cmd":"move_joints","q":[0,0,0]}"#.to_vec(),
            "bad request",
        ),
        (
            br#"{"cmd":"move_joints","q":["a",0,0,0,0,0]}"#.to_vec(),
            "bad request",
        ),
        (
            br#"{"cmd":"move_joints","q":[NaN,0,0,0,0,0]}"#.to_vec(),
            "bad request",
        ),
        (
            br#"{"cmd":"move_joints","q":[1e400,0,0,0,0,0]}"#.to_vec(),
            "bad request",
        ),
        (
            br#"{"cmd":"move_joints","q":[0,2.5,0,0,0,0]}"#.to_vec(),
            "joint 2|in progress",
        ),
        (
            br#"{"cmd":"move_pose","position":[0.5,0,0.5],"quaternion":[1,1,0,0]}"#.to_vec(),
            "unit",
        ),
        (
            br#"{"cmd":"move_pose","position":[3,0,0.5],"quaternion":[0,1,0,0]}"#.to_vec(),
            "path|in progress",
        ),
        (br#"{"cmd":"set_payload","newtons":-5}"#.to_vec(), "payload"),
        (
            br#"{"cmd":"set_payload","newtons":1e9}"#.to_vec(),
            "payload",
        ),
        (br#"{"cmd":"subscribe","rate_hz":1e6}"#.to_vec(), "rate_hz"),
        (
            br#"{"cmd":"load_model","path":"/etc/passwd"}"#.to_vec(),
            "outside",
        ),
        (
            br#"{"cmd":"load_model","path":"../../etc/passwd"}"#.to_vec(),
            "outside",
        ),
        (
            br#"{"cmd":"load_model","path":"secret.yaml"}"#.to_vec(),
            "secret.yaml",
        ),
        (b"\xff\xfe\xfd".to_vec(), "not UTF-8"),
    ];
    let long_cmd = format!(r#"{{"cmd":"{}"}}"#, "x".repeat(50_000));
    v.push((long_cmd.into_bytes(), "bad request"));
    std::fs::write(dir.join("secret.yaml"), "root:x:0:0:root:/root:/bin/bash\n").unwrap();
    v
}

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4)
}

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
    let rss0 = rss_kib();
    let requests = Arc::new(hostile_requests(&dir));
    let done = Arc::new(AtomicBool::new(false));
    // four hostile clients, 60 rounds of every class each: 4 × 60 × 21 = 5040 requests
    let hostile: Vec<_> = (0..4)
        .map(|_| {
            let (path, requests) = (path.clone(), requests.clone());
            std::thread::spawn(move || {
                let mut refused = 0usize;
                let mut s = UnixStream::connect(&path).unwrap();
                for _ in 0..60 {
                    for (line, why) in requests.iter() {
                        let a = ask(&mut s, line).unwrap_or_else(|| panic!("no answer"));
                        assert_eq!(a["ok"], false, "{a}");
                        let e = a["error"].as_str().unwrap();
                        assert!(
                            why.split('|').any(|w| e.contains(w)),
                            "{}: {e}",
                            String::from_utf8_lossy(line)
                        );
                        assert!(!e.contains("root:x"), "leaks: {e}");
                        assert!(
                            a.to_string().len() < 1000,
                            "echoes: {} bytes",
                            a.to_string().len()
                        );
                        refused += 1;
                    }
                }
                // and one line too long: refused, then closed
                let a = ask(&mut s, &vec![b'{'; 70_000]).unwrap();
                assert!(a["error"].as_str().unwrap().contains("65536"), "{a}");
                refused + 1
            })
        })
        .collect();
    // the well-behaved client: back and forth, each move must land
    let good = {
        let (path, done) = (path.clone(), done.clone());
        std::thread::spawn(move || {
            let mut s = UnixStream::connect(&path).unwrap();
            let targets = [
                [0.2, 0.5, 1.4, 0.1, 1.0, 0.2],
                [0.0, 0.4, 1.6, 0.0, 1.1, 0.0],
            ];
            let mut moves = 0;
            for k in 0..6 {
                let q = targets[k % 2];
                let a = ask(
                    &mut s,
                    json!({"cmd": "move_joints", "q": q}).to_string().as_bytes(),
                )
                .unwrap();
                assert_eq!(a["ok"], true, "{a}");
                loop {
                    let st = ask(&mut s, br#"{"cmd":"status"}"#).unwrap()["status"].clone();
                    assert_ne!(st["state"], "fault", "{st}");
                    if st["state"] == "holding" {
                        let sp: Vec<f64> = serde_json::from_value(st["setpoint"].clone()).unwrap();
                        assert!((0..6).all(|j| (sp[j] - q[j]).abs() < 1e-9), "{sp:?}");
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                moves += 1;
            }
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
    let moves = good.join().unwrap();
    assert_eq!(moves, 6);
    assert!(refused >= 5000, "{refused}");
    let st = ls.call(&json!({"cmd": "status"}))["status"].clone();
    assert_eq!(st["state"], "holding", "{st}");
    assert_eq!(st["link"]["incomplete"], 0, "{st}");
    let grown = rss_kib().saturating_sub(rss0);
    assert!(grown < 64 * 1024, "memory grew by {grown} KiB");
    eprintln!(
        "hostile: {refused} refused, {moves} good moves landed, {:.1} s simulated, RSS +{grown} KiB",
        ls.now()
    );
    server.stop();
    std::fs::remove_dir_all(&dir).unwrap();
}
