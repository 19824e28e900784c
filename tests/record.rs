//! Recording every cycle: through the daemon's API in simulated time, read back by our reader
//! and (in CI, `PA10_PYTHON_MCAP=1`) by the Python `mcap` package; a slow and a failing disk
//! drop and count records while the loop keeps going.

use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use pa10::daemon::config::Config;
use pa10::model::Model;
use pa10::record::{OpenSink, RecordConfig, Recorder, Sink, read};
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

fn temp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pa10-record-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The daemon in simulated time, recording into `dir`.
fn lockstep(dir: &Path) -> Lockstep {
    lockstep_into(dir, dir)
}

/// The daemon in simulated time, its configuration in `dir`, recording into `records`.
fn lockstep_into(dir: &Path, records: &Path) -> Lockstep {
    let cfg = crate::daemon::config(dir, &Model::nominal());
    let text = std::fs::read_to_string(&cfg).unwrap();
    let text = text.replace(
        "  dir: /tmp/pa10d-recordings",
        &format!("  dir: {}\n  max_file_mb: 0.05", records.display()),
    );
    assert!(text.contains("max_file_mb: 0.05"));
    std::fs::write(&cfg, text).unwrap();
    let loaded = Config::load(&cfg).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    ls.run_until_ready(1.0).unwrap();
    ls.run_for(0.1);
    ls
}

fn recording(ls: &Lockstep) -> Value {
    ls.call_json(&json!({"cmd": "status"}))["status"]["recording"].clone()
}

/// Waits (real time, ≤ 10 s) until the writer closed its last file.
fn finished(ls: &Lockstep) -> Value {
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        let r = recording(ls);
        if r["finished"] == true || Instant::now() > end {
            return r;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn every_cycle_is_recorded_and_read_back_with_its_events() {
    let dir = temp("cycles");
    let mut ls = lockstep(&dir);
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "run1", "duration_s": 2.0}));
    assert_eq!(r["ok"], true, "{r}");
    let path = PathBuf::from(r["path"].as_str().unwrap());
    assert_eq!(path, dir.join("run1.mcap"));
    let mv = json!({"cmd": "move_joints", "q": [0.1, 0.45, 1.55, 0.0, 1.1, -0.1]});
    assert_eq!(ls.call_json(&mv)["ok"], true);
    ls.run_for(3.0);
    let st = finished(&ls);
    assert_eq!(st["active"], false, "{st}");
    assert_eq!(st["dropped_queue"], 0, "{st}");
    assert_eq!(st["dropped_write"], 0, "{st}");
    assert!(
        st["files"].as_u64().unwrap() >= 2,
        "rotated at 0.05 MiB: {st}"
    );
    // every file of the recording, in order
    let files = pa10::record::files_of(&path);
    assert_eq!(files.len() as u64, st["files"].as_u64().unwrap());
    let mut cycles = Vec::new();
    let mut events = Vec::new();
    for f in &files {
        cycles.extend(read::cycles(f).unwrap());
        events.extend(read::events(f).unwrap());
    }
    // 2.0 s at 500 Hz: 1000 cycles (0.5 %)
    let n = cycles.len() as f64;
    assert!((n - 1000.0).abs() <= 5.0, "{n} cycles");
    assert!(
        cycles
            .windows(2)
            .all(|w| w[1].stamp_s > w[0].stamp_s && w[1].cycle == w[0].cycle + 1)
    );
    assert!(cycles.iter().any(|c| c.activity == 1), "the move is in it");
    assert!(
        cycles
            .iter()
            .filter(|c| c.activity == 1)
            .any(|c| c.speeds.iter().any(|v| v.abs() > 0.01))
    );
    assert!(cycles.iter().all(|c| c.feedback));
    let kinds: Vec<(String, String)> = events
        .iter()
        .map(|e| (e.kind.to_string(), e.text.to_string()))
        .collect();
    for want in [
        ("recording", "started"),
        ("command", "move"),
        ("state", "moving"),
        ("state", "holding"),
        ("recording", "duration reached"),
    ] {
        assert!(
            kinds.iter().any(|(k, t)| k == want.0 && t == want.1),
            "{want:?} in {kinds:?}"
        );
    }
    let info = read::info(&files[0]).unwrap();
    assert!(info.channels["/pa10/cycle"] > 0);
    assert_eq!(
        info.recorder.get("dropped_queue").map(String::as_str),
        None,
        "only the last file carries the counts"
    );
    let last = read::info(files.last().unwrap()).unwrap();
    assert_eq!(last.recorder["dropped_queue"], "0");
    assert_eq!(info.truncated, None);
    // a file cut short (as by a crash) is read up to the damage
    let cut = dir.join("cut.mcap");
    let bytes = std::fs::read(&files[0]).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let partial = read::info(&cut).unwrap();
    assert!(partial.truncated.is_some(), "{partial:?}");
    assert!(partial.channels["/pa10/cycle"] > 0);
    assert!(partial.channels["/pa10/cycle"] < info.channels["/pa10/cycle"]);
    // the CSV export
    let out = dir.join("csv");
    let [c, e] = read::export_csv(&files[0], &out).unwrap();
    let text = std::fs::read_to_string(c).unwrap();
    assert!(text.starts_with("stamp_s,cycle,activity,feedback,q_motor1"));
    assert_eq!(
        text.lines().count() as u64,
        info.channels["/pa10/cycle"] + 1
    );
    assert!(
        std::fs::read_to_string(e)
            .unwrap()
            .contains("recording,\"started\"")
    );
    // a reader we did not write
    if std::env::var("PA10_PYTHON_MCAP").is_ok_and(|v| v == "1") {
        let mut total = 0u64;
        for f in &files {
            let o = std::process::Command::new("python3")
                .arg(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/tests/record/check_mcap.py"
                ))
                .arg(f)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let v: Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(v["monotonic"], true, "{v}");
            assert_eq!(
                v["schemas"]["/pa10/cycle"],
                json!(["pa10.Cycle", "jsonschema"]),
                "{v}"
            );
            assert_eq!(
                v["schemas"]["/pa10/event"],
                json!(["pa10.Event", "jsonschema"]),
                "{v}"
            );
            total += v["counts"]["/pa10/cycle"].as_u64().unwrap();
        }
        assert_eq!(total, cycles.len() as u64);
        eprintln!("python mcap: {total} cycles in {} files", files.len());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn recording_names_stay_inside_the_folder_and_one_runs_at_a_time() {
    let dir = temp("names");
    let mut ls = lockstep(&dir);
    for bad in ["../x", "/etc/passwd", "a/b", ".hidden", ""] {
        let r = ls.call_json(&json!({"cmd": "record_start", "file": bad}));
        assert!(
            r["error"].as_str().unwrap().contains("plain file name"),
            "{bad}: {r}"
        );
    }
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "x", "duration_s": -1.0}));
    assert!(r["error"].as_str().unwrap().contains("duration_s"), "{r}");
    assert_eq!(
        ls.call_json(&json!({"cmd": "record_start", "file": "x"}))["ok"],
        true
    );
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "y"}));
    assert!(
        r["error"].as_str().unwrap().contains("record_stop first"),
        "{r}"
    );
    ls.run_for(0.2);
    assert_eq!(ls.call_json(&json!({"cmd": "record_stop"}))["ok"], true);
    finished(&ls);
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "x"}));
    assert!(r["error"].as_str().unwrap().contains("exists"), "{r}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A disk that takes `delay` per write, or fails once `limit` bytes were written.
struct Disk {
    delay: Duration,
    limit: u64,
    pos: u64,
}

impl Write for Disk {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        std::thread::sleep(self.delay);
        if self.pos + b.len() as u64 > self.limit {
            return Err(std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                "no space left on device",
            ));
        }
        self.pos += b.len() as u64;
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Disk {
    fn seek(&mut self, p: SeekFrom) -> std::io::Result<u64> {
        if let SeekFrom::Start(n) = p {
            self.pos = n;
        }
        Ok(self.pos)
    }
}

fn disk(delay: Duration, limit: u64) -> OpenSink {
    Box::new(move |i| {
        Ok((
            Box::new(Disk {
                delay,
                limit,
                pos: 0,
            }) as Box<dyn Sink>,
            PathBuf::from(format!("disk-{i}")),
        ))
    })
}

/// Runs the daemon for `seconds` of simulated time recording into `open`; the status.
fn record_into(open: OpenSink, queue: usize, seconds: f64) -> (Value, Value) {
    let dir = temp(&format!("disk{queue}"));
    let mut ls = lockstep(&dir);
    let cfg = RecordConfig {
        queue,
        max_file_mb: 1.0,
        ..RecordConfig::default()
    };
    let tap = Recorder::start_with(&cfg, open, None, PathBuf::from("disk-0")).unwrap();
    let stats = tap.stats.clone();
    pa10::daemon::runtime::lock(&ls.core)
        .submit(pa10::daemon::core::Command::Record(Box::new(tap)))
        .unwrap();
    let mv = json!({"cmd": "move_joints", "q": [0.1, 0.45, 1.55, 0.0, 1.1, -0.1]});
    assert_eq!(ls.call_json(&mv)["ok"], true);
    let t0 = Instant::now();
    ls.run_for(seconds);
    let wall = t0.elapsed();
    assert!(
        wall < Duration::from_secs(5),
        "the core never waited for the writer: {wall:?}"
    );
    let st = ls.call_json(&json!({"cmd": "status"}))["status"].clone();
    assert_eq!(ls.call_json(&json!({"cmd": "record_stop"}))["ok"], true);
    let end = Instant::now() + Duration::from_secs(20);
    while !stats.finished.load(Ordering::SeqCst) && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(10));
    }
    let after = ls.call_json(&json!({"cmd": "status"}))["status"].clone();
    std::fs::remove_dir_all(&dir).unwrap();
    (st, after)
}

#[test]
fn a_slow_disk_drops_and_counts_records_and_the_loop_keeps_its_cycles() {
    // 20 ms per write, a 200-record queue, 4 s of cycles (2000 + events) pushed in well under a second
    let (st, after) = record_into(disk(Duration::from_millis(20), u64::MAX), 200, 4.0);
    assert_eq!(st["state"], "holding", "{st}");
    assert_eq!(st["link"]["incomplete"], 0);
    let r = &after["recording"];
    let dropped = r["dropped_queue"].as_u64().unwrap();
    let written = r["written"].as_u64().unwrap();
    assert!(dropped > 1000, "{r}");
    assert!(
        written + dropped >= 2000,
        "every record is written or counted: {r}"
    );
    assert_eq!(r["dropped_write"], 0, "{r}");
}

#[test]
fn a_full_disk_is_reported_once_and_the_loop_keeps_going() {
    let (st, after) = record_into(disk(Duration::ZERO, 20_000), 5000, 4.0);
    assert_eq!(st["state"], "holding", "{st}");
    let r = &after["recording"];
    assert!(
        r["error"]
            .as_str()
            .is_some_and(|e| e.contains("no space left")),
        "{r}"
    );
    assert!(r["dropped_write"].as_u64().unwrap() > 0, "{r}");
    assert!(r["written"].as_u64().unwrap() > 0, "{r}");
}

#[test]
fn still_phases_are_cut_from_a_recording() {
    let dir = temp("still");
    let mut ls = lockstep(&dir);
    assert_eq!(
        ls.call_json(&json!({"cmd": "record_start", "file": "still"}))["ok"],
        true
    );
    let targets = [
        [0.1, 0.45, 1.55, 0.0, 1.1, -0.1],
        [0.0, 0.4, 1.6, 0.0, 1.1, 0.0],
    ];
    for q in targets {
        assert_eq!(
            ls.call_json(&json!({"cmd": "move_joints", "q": q}))["ok"],
            true
        );
        assert!(ls.run_while_not(
            10.0,
            |l| l.call_json(&json!({"cmd": "status"}))["status"]["state"] == "holding"
        ));
        ls.run_for(1.0);
    }
    assert_eq!(ls.call_json(&json!({"cmd": "record_stop"}))["ok"], true);
    let st = finished(&ls);
    let mut cycles = Vec::new();
    for f in pa10::record::files_of(Path::new(st["path"].as_str().unwrap())) {
        cycles.extend(read::cycles(&f).unwrap());
    }
    let phases = read::still_phases(&cycles, 0.5, 0.2, 0.01);
    assert_eq!(phases.len(), 2, "at rest after each move: {phases:?}");
    for (p, q) in phases.iter().zip(targets) {
        assert_eq!(p.setpoint, q);
        // resolver means near the setpoint (the nominal model has no springs)
        assert!((0..6).all(|j| (p.q_motor[j] - q[j]).abs() < 2e-3), "{p:?}");
        assert!(p.cycles > 300);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A `record.dir` that does not exist yet (the simulated configuration's on a fresh machine) is
/// created, with the recorder's mode, when the first recording starts; one that cannot be
/// created is refused with the key and the reason, and nothing is started.
#[test]
fn a_missing_record_dir_is_created_and_an_impossible_one_refused() {
    use std::os::unix::fs::PermissionsExt;
    let root = temp("mkdir");
    let dir = root.join("not").join("yet");
    let mut ls = lockstep_into(&root, &dir);
    assert!(!dir.exists());
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "first", "duration_s": 0.2}));
    assert_eq!(r["ok"], true, "{r}");
    ls.run_for(0.5);
    assert_eq!(finished(&ls)["active"], false);
    assert!(dir.join("first.mcap").is_file());
    let mode = std::fs::metadata(&dir).unwrap().permissions().mode() & 0o777;
    assert_eq!(
        mode & !0o022,
        pa10::record::RECORD_DIR_MODE & !0o022,
        "{mode:o}"
    );
    // a folder under a plain file cannot be made
    let file = root.join("plain");
    std::fs::write(&file, b"x").unwrap();
    let ls = lockstep_into(&root, &file.join("sub"));
    let r = ls.call_json(&json!({"cmd": "record_start", "file": "second"}));
    assert_eq!(r["ok"], false, "{r}");
    let e = r["error"].to_string();
    assert!(e.contains("record.dir could not be created"), "{e}");
    assert_ne!(recording(&ls)["active"], true, "nothing started");
    std::fs::remove_dir_all(&root).unwrap();
}
