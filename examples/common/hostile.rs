//! The hostile-client suite's requests, shared by the simulated-time test (`tests/hostile.rs`)
//! and the real-time example (`examples/hostile.rs`): every class of malformed request the
//! `[harden]` issue found, each with what its refusal must say, and one hostile client.
#![allow(dead_code)] // each includer uses its part

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;

use serde_json::Value;

/// One request line (raw bytes) and its answer; `None` when the server closed.
pub fn ask(s: &mut UnixStream, line: &[u8]) -> Option<Value> {
    // a write may fail when the server has already answered and closed (the overlong line:
    // it stops reading at the limit); the answer is still there to read
    let sent = s.write_all(line).and_then(|()| s.write_all(b"\n"));
    let mut answer = String::new();
    BufReader::new(s.try_clone().ok()?)
        .read_line(&mut answer)
        .ok()?;
    if answer.is_empty() && sent.is_err() {
        return None;
    }
    serde_json::from_str(&answer).ok()
}

/// Every class of malformed request, each with what its refusal must say (alternatives split
/// by `|`: a move is refused as out of limits, or as busy while the good client's move runs,
/// or — in real time on a host that stalls — as faulted; the fault itself is the mover's to
/// report).
pub fn requests(dir: &Path) -> Vec<(Vec<u8>, &'static str)> {
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
            "joint 2|in progress|faulted",
        ),
        (
            br#"{"cmd":"move_pose","position":[0.5,0,0.5],"quaternion":[1,1,0,0]}"#.to_vec(),
            "unit",
        ),
        (
            br#"{"cmd":"move_pose","position":[3,0,0.5],"quaternion":[0,1,0,0]}"#.to_vec(),
            "path|in progress|faulted",
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
    std::fs::write(dir.join("secret.yaml"), "root:x:0:0:root:/root:/bin/bash\n")
        .expect("a file in the temp dir");
    v
}

pub fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4)
}

/// One hostile client: `rounds` rounds of every class of `requests`, then a line too long.
/// Panics on an answer that is not a precise refusal (or echoes, or leaks); returns how many
/// were refused.
pub fn hammer(path: &Path, requests: &[(Vec<u8>, &'static str)], rounds: usize) -> usize {
    let mut refused = 0usize;
    let mut s = UnixStream::connect(path).expect("connect");
    for _ in 0..rounds {
        for (line, why) in requests {
            let a = ask(&mut s, line).unwrap_or_else(|| panic!("no answer"));
            assert_eq!(a["ok"], false, "{a}");
            let e = a["error"].as_str().expect("an error text");
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
    let a = ask(&mut s, &vec![b'{'; 70_000]).expect("an answer to the long line");
    assert!(
        a["error"].as_str().is_some_and(|e| e.contains("65536")),
        "{a}"
    );
    refused + 1
}

/// The well-behaved client: moves the arm back and forth between two joint targets while
/// `more(moves_so_far)` says so; every move must be accepted and land exactly (its setpoint).
/// Returns the moves landed, or the arm's fault (the caller judges it).
pub fn mover(path: &Path, more: impl Fn(usize) -> bool) -> Result<usize, String> {
    let mut s = UnixStream::connect(path).expect("connect");
    let targets = [
        [0.2, 0.5, 1.4, 0.1, 1.0, 0.2],
        [0.0, 0.4, 1.6, 0.0, 1.1, 0.0],
    ];
    let mut moves = 0;
    while more(moves) {
        let q = targets[moves % 2];
        let line = serde_json::json!({"cmd": "move_joints", "q": q}).to_string();
        let a = ask(&mut s, line.as_bytes()).expect("an answer");
        if a["ok"] != true {
            // a move refused because the arm had faulted is the fault, for the caller to judge
            let e = a["error"].as_str().unwrap_or_default();
            if e.starts_with("faulted") {
                return Err(format!("the arm faulted after {moves} moves: {e}"));
            }
            panic!("a good move refused: {a}");
        }
        loop {
            let st = ask(&mut s, br#"{"cmd":"status"}"#).expect("an answer")["status"].clone();
            if st["state"] == "fault" {
                return Err(format!(
                    "the arm faulted after {moves} moves: {}",
                    st["fault"]
                ));
            }
            if st["state"] == "holding" {
                let sp: Vec<f64> = serde_json::from_value(st["setpoint"].clone()).expect("six");
                assert!((0..6).all(|j| (sp[j] - q[j]).abs() < 1e-9), "{sp:?}");
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        moves += 1;
    }
    Ok(moves)
}
