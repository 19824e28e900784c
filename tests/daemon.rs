//! End to end: the daemon core with the simulated controller (a hidden true robot), driven
//! through the client API; positions are judged by the simulator's ground truth.
//!
//! These run in *simulated* time ([`Lockstep`]): the daemon's sans-IO core and the sans-IO
//! servo simulator exchange frames on one thread, deterministic and in parallel with other
//! tests. One test runs the real `pa10d` binary in real time on its socket.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pa10::daemon::config::Config;
use pa10::daemon::wire::State;
use pa10::model::{Frame, Model, pose_parts};
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

const SEED: u64 = 3;

use crate::common::{busy_lock as busy, realtime_lock as serial};

/// The real socket server on `core`, at `path`, with at most `max_clients`: its runtime, its
/// health counters, the stop switch and the task (wait for it after `stop`).
pub(crate) struct Server {
    pub rt: tokio::runtime::Runtime,
    pub health: std::sync::Arc<pa10::daemon::api::ApiHealth>,
    pub stop: tokio::sync::watch::Sender<bool>,
    pub task: tokio::task::JoinHandle<std::io::Result<()>>,
}

impl Server {
    /// Starts serving and waits (≤ 5 s) until the socket exists.
    pub(crate) fn start(
        core: std::sync::Arc<pa10::daemon::runtime::SharedCore>,
        path: &Path,
        max_clients: usize,
    ) -> Self {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let (stop, stop_rx) = tokio::sync::watch::channel(false);
        let health = std::sync::Arc::new(pa10::daemon::api::ApiHealth::default());
        let (p, h) = (path.to_path_buf(), health.clone());
        let task = rt.spawn(async move {
            pa10::daemon::api::serve(&p, 0o600, max_clients, core, h, stop_rx).await
        });
        let end = Instant::now() + Duration::from_secs(5);
        while !path.exists() && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(5));
        }
        Self {
            rt,
            health,
            stop,
            task,
        }
    }

    /// Stops serving; the server's own result.
    pub(crate) fn stop(self) {
        self.stop.send(true).unwrap();
        self.rt.block_on(self.task).unwrap().unwrap();
    }
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pa10-daemon-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A sim.yaml variant in `dir` using `model` and a socket inside `dir`.
pub(crate) fn config(dir: &Path, model: &Model) -> PathBuf {
    model.save(dir.join("model.yaml")).unwrap();
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml"))
        .unwrap()
        .replace("model: model-nominal.yaml", "model: model.yaml")
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", dir.join("api.sock").display()),
        )
        .replace("  seed: 1", &format!("  seed: {SEED}"));
    let p = dir.join("pa10d.yaml");
    std::fs::write(&p, text).unwrap();
    p
}

/// The daemon of `model` on the simulated arm of seed [`SEED`], connected (simulated time).
fn lockstep(tag: &str, model: &Model) -> Lockstep {
    let dir = temp_dir(tag);
    let loaded = Config::load(&config(&dir, model)).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    assert!(
        ls.run_while_not(
            1.0,
            |l| l.call_json(&json!({"cmd": "status"}))["status"]["state"] == "holding"
        ),
        "{}",
        ls.call_json(&json!({"cmd": "status"}))
    );
    ls
}

fn status(ls: &Lockstep) -> Value {
    ls.call_json(&json!({"cmd": "status"}))["status"].clone()
}

/// Runs until the daemon holds (or faults), at most `timeout_s` of simulated time.
fn wait_holding(ls: &mut Lockstep, timeout_s: f64) -> Value {
    ls.run_while_not(timeout_s, |l| {
        let st = status(l);
        st["state"] == "holding" || st["state"] == "fault"
    });
    status(ls)
}

/// Sends `reset` and runs until the daemon holds again (at most 2 s of simulated time).
fn reset_until_holding(ls: &mut Lockstep) {
    assert_eq!(ls.call_json(&json!({"cmd": "reset"}))["ok"], true);
    assert!(
        ls.run_while_not(2.0, |l| status(l)["state"] == "holding"),
        "{}",
        status(ls)
    );
}

/// Tool targets in the instrument frame, inside the calibrated volume.
fn targets(truth_base: &Frame) -> Vec<Frame> {
    let down = nalgebra::UnitQuaternion::from_axis_angle(
        &nalgebra::Vector3::x_axis(),
        std::f64::consts::PI,
    );
    [[0.55, -0.12, 0.05], [0.62, 0.12, 0.18]]
        .iter()
        .map(|p| {
            truth_base.inverse()
                * Frame::from_parts(
                    nalgebra::Translation3::new(p[0], p[1], p[2]),
                    down.to_rotation_matrix(),
                )
        })
        .collect()
}

/// Mean error (mm) of the daemon running `model` at `load_n`, judged by ground truth.
/// Mean position error (mm, judged by the simulator's truth) of `model` in the daemon over the
/// test targets at `load_n`, and the mean predicted 1σ the daemon's status reported there.
fn drive(model: &Model, load_n: f64) -> (f64, Option<f64>) {
    let mut ls = lockstep(&format!("drive{}", load_n as u32), model);
    ls.servo.set_load(load_n);
    assert_eq!(
        ls.call_json(&json!({"cmd": "set_payload", "newtons": load_n}))["ok"],
        true
    );
    let truth_base = *ls.servo.truth().model.base_from_instrument();
    let (mut sum, mut sigma) = (0.0, Some(0.0));
    let ts = targets(&truth_base);
    for target_inst in &ts {
        let target = model.base_from_instrument() * target_inst;
        let (p, q) = pose_parts(&target);
        let r = ls.call_json(&json!({"cmd": "move_pose", "position": p, "quaternion": q}));
        assert_eq!(r["ok"], true, "{r}");
        let st = wait_holding(&mut ls, 10.0);
        assert_eq!(st["state"], "holding", "{st}");
        ls.run_for(0.3); // settle
        let got = truth_base.inverse() * ls.servo.true_tool_pose();
        sum += (got.translation.vector - target_inst.translation.vector).norm() * 1e3;
        let s = status(&ls)["position_sigma_mm"].as_f64();
        sigma = sigma.zip(s).map(|(a, b)| a + b);
    }
    let n = ts.len() as f64;
    (sum / n, sigma.map(|s| s / n))
}

#[test]
fn move_pose_through_the_daemon_lands_near_the_floor_where_the_nominal_model_misses() {
    let _busy = busy();
    let (_, calibrated, nominal) = crate::common::calibrated_and_nominal(SEED);
    let ((cal0, sigma0), (cal90, sigma90), (nom90, nom_sigma)) = (
        drive(&calibrated, 0.0),
        drive(&calibrated, 90.0),
        drive(&nominal, 90.0),
    );
    eprintln!(
        "daemon, calibrated: {cal0:.3} mm at 0 N, {cal90:.3} mm at 90 N; nominal: {nom90:.3} mm at 90 N; predicted 1σ {sigma0:?} / {sigma90:?} mm"
    );
    // the status says how accurate the arm is here: a calibrated model's 1σ (3-D rms) is of
    // the order of what it achieves; a nominal model has no covariance to say it from
    for (s, e) in [(sigma0, cal0), (sigma90, cal90)] {
        let s = s.expect("position_sigma_mm with a calibrated model");
        assert!(
            s > 0.5 * e && s < 4.0 * e && s < 1.0,
            "predicted {s} mm vs achieved {e} mm"
        );
    }
    assert_eq!(nom_sigma, None);
    assert!(
        cal0 < 0.45 && cal90 < 0.45,
        "calibrated {cal0} / {cal90} mm"
    );
    assert!(nom90 > 4.0 * cal90, "nominal {nom90} mm");
}

#[test]
fn bad_requests_are_refused_and_change_nothing_and_estop_needs_reset() {
    let _busy = busy();
    let tool = pa10::model::frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0]);
    let mut ls = lockstep("bad", &Model::nominal().with_tool(&tool).unwrap());
    ls.run_for(0.1);
    let before = status(&ls)["setpoint"].clone();
    for (req, msg) in [
        (json!("{not json"), "bad request"),
        (json!({"cmd": "fly"}), "bad request"),
        (
            json!({"cmd": "move_joints", "q": [0.0, 2.5, 0.0, 0.0, 0.0, 0.0]}),
            "joint 2",
        ),
        (
            json!({"cmd": "move_joints", "q": [0.0, 0.0]}),
            "bad request",
        ),
        (
            json!({"cmd": "move_pose", "position": [3.0, 0.0, 0.5], "quaternion": [0.0, 1.0, 0.0, 0.0]}),
            "path",
        ),
        (
            json!({"cmd": "move_pose", "position": [0.5, 0.0, 0.5], "quaternion": [1.0, 1.0, 0.0, 0.0]}),
            "unit",
        ),
        (json!({"cmd": "set_payload", "newtons": -5.0}), "payload"),
        (
            json!({"cmd": "load_model", "path": "/nonexistent.yaml"}),
            "nonexistent",
        ),
        // unknown fields are refused on every command, unit ones included
        (json!({"cmd": "estop", "why": 1}), "unknown field `why`"),
        (json!({"cmd": "stop", "speed": 0}), "unknown field `speed`"),
        (json!({"cmd": "reset", "all": true}), "unknown field `all`"),
        (json!({"cmd": "status", "x": 1}), "unknown field `x`"),
        // an unknown command is named, but never echoed at length
        (json!({"cmd": "x".repeat(100_000)}), "bad request"),
    ] {
        let line = if let Value::String(s) = &req {
            s.clone()
        } else {
            req.to_string()
        };
        // the socket's path: the line parsed (or refused), then handled
        let r = match pa10::daemon::api::parse(&line) {
            Ok(request) => pa10::daemon::api::handle(&ls.core, request),
            Err(refusal) => refusal,
        };
        let r = serde_json::to_value(r).unwrap();
        assert_eq!(r["ok"], false, "{req}: {r}");
        assert!(
            r.to_string().len() < 1000,
            "an answer echoes at most a few hundred bytes"
        );
        assert!(r["error"].as_str().unwrap().contains(msg), "{req}: {r}");
    }
    let after = status(&ls);
    assert_eq!(after["state"], "holding");
    assert_eq!(after["setpoint"], before);
    // a move cannot start while another runs
    let far = json!({"cmd": "move_joints", "q": [0.3, 0.4, 1.6, 0.0, 1.1, 0.0]});
    assert_eq!(ls.call_json(&far)["ok"], true);
    ls.run_for(0.05);
    let r = ls.call_json(&json!({"cmd": "move_joints", "q": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0]}));
    assert!(r["error"].as_str().unwrap().contains("in progress"), "{r}");
    assert_eq!(wait_holding(&mut ls, 5.0)["state"], "holding");
    // estop: the servo stops, the daemon reports a fault, moves are refused until reset
    assert_eq!(ls.call_json(&json!({"cmd": "estop"}))["ok"], true);
    ls.run_for(0.1);
    let st = status(&ls);
    assert_eq!(st["state"], "fault", "{st}");
    assert_eq!(st["servo"], "Stopped", "{st}");
    assert!(
        st["fault"].as_str().unwrap().contains("emergency stop"),
        "{st}"
    );
    let again = json!({"cmd": "move_joints", "q": [0.1, 0.4, 1.6, 0.0, 1.1, 0.0]});
    let r = ls.call_json(&again);
    assert!(r["error"].as_str().unwrap().contains("reset"), "{r}");
    assert_eq!(ls.call_json(&json!({"cmd": "reset"}))["ok"], true);
    // the link re-runs the start-up handshake; the state says so until it is done
    assert_eq!(status(&ls)["state"], "starting");
    assert!(ls.run_while_not(2.0, |l| status(l)["state"] == "holding"));
    let st = status(&ls);
    assert_eq!(st["servo"], "Control", "{st}");
    assert_eq!(ls.call_json(&again)["ok"], true);
    assert_eq!(wait_holding(&mut ls, 5.0)["state"], "holding");
}

#[test]
fn the_feedback_timeout_stops_the_arm_when_the_controller_goes_silent() {
    let _busy = busy();
    let mut ls = lockstep("silent", &Model::nominal());
    ls.run_for(0.05);
    // one axis stops answering: no cycle completes
    ls.servo.injected.mute_axis = Some(1);
    ls.run_for(0.1);
    let st = status(&ls);
    assert_eq!(st["state"], "fault", "{st}");
    assert!(
        st["fault"].as_str().unwrap().contains("stale feedback"),
        "{st}"
    );
    assert!(st["link"]["incomplete"].as_u64().unwrap() > 5);
    // the daemon sent a controlled STOP: the controller stops instead of waiting for its
    // watchdog
    ls.run_for(0.5);
    assert_eq!(status(&ls)["servo"], "Stopped", "{}", status(&ls));
    // the axis answers again: reset brings the arm back under control
    ls.servo.injected.mute_axis = None;
    reset_until_holding(&mut ls);
}

#[test]
fn a_silent_controller_fails_the_start_with_a_precise_error() {
    let _busy = busy();
    let dir = temp_dir("mute");
    let loaded = Config::load(&config(&dir, &Model::nominal())).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    // every axis muted: the handshake succeeds, the first feedback never completes
    ls.servo.injected.mute_axis = Some(4);
    ls.run_for(1.0);
    let r = ls.call_json(&json!({"cmd": "move_joints", "q": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]}));
    assert!(
        r["error"]
            .as_str()
            .unwrap()
            .contains("no complete feedback"),
        "{r}"
    );
    let st = status(&ls);
    assert_eq!(st["state"], "fault", "{st}");
    // reset retries the start once the controller answers
    ls.servo.injected.mute_axis = None;
    reset_until_holding(&mut ls);
}

#[test]
fn a_bus_off_is_a_link_fault_that_stops_the_arm() {
    let _busy = busy();
    let mut ls = lockstep("busoff", &Model::nominal());
    ls.run_for(0.05);
    ls.core
        .lock()
        .handle_bus(Ok(pa10::can::BusEvent::BusOff), ls.now());
    ls.run_for(0.05);
    let st = status(&ls);
    assert_eq!(st["state"], "fault", "{st}");
    assert!(st["fault"].as_str().unwrap().contains("bus off"), "{st}");
}

/// A child process killed if the test fails before it exits.
struct Reaped(std::process::Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A paused control thread (here: the core's lock held for 30 ms, as a host stall would) finds
/// the cycle's feedback queued when it wakes: it takes all of it before judging the window, so
/// neither an incomplete cycle nor a stale-feedback fault is blamed on the controller.
#[test]
#[ignore = "wall-clock threads: .ci/run runs it alone, after the runs that share the cores"]
fn a_paused_control_thread_is_not_a_silent_controller() {
    let _serial = serial();
    // Wall-clock threads on a shared host: the simulated controller itself may be delayed by
    // other work (CI runs the judges beside the tests). A second attempt is allowed for the
    // incomplete-cycle count only; the old code failed every attempt (7 of 10 pauses cost a
    // cycle and the first one a stale-feedback fault).
    for attempt in 0..2 {
        let dir = temp_dir("pause");
        let loaded = Config::load(&config(&dir, &Model::nominal())).unwrap();
        let arm = pa10::sim::rig::SimulatedArm::from_config(&loaded).unwrap();
        let d = pa10::daemon::runtime::Daemon::start(&loaded, arm.host()).unwrap();
        let before = pa10::daemon::runtime::lock(&d.core).status();
        for _ in 0..10 {
            {
                let _paused = pa10::daemon::runtime::lock(&d.core);
                std::thread::sleep(Duration::from_millis(30));
            }
            std::thread::sleep(Duration::from_millis(60));
        }
        let after = pa10::daemon::runtime::lock(&d.core).status();
        drop(d);
        drop(arm);
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(after.state, State::Holding, "{:?}", after.fault);
        // the pauses happened (most of them delay a cycle past its period)
        assert!(
            after.cycle.overruns >= before.cycle.overruns + 5,
            "{after:?}"
        );
        // and the control thread measured those waits for the lock (status.cycle.lock_wait_us)
        assert!(
            after.cycle.lock_waits >= before.cycle.lock_waits + 5,
            "{after:?}"
        );
        assert!(after.cycle.lock_wait_us[2] >= 20_000.0, "{after:?}");
        // the pauses cost no cycle (a shared host may still delay the simulated controller
        // itself once or twice)
        let incomplete = after.link.incomplete - before.link.incomplete;
        if incomplete <= 2 {
            return;
        }
        assert!(
            attempt == 0,
            "{incomplete} incomplete cycles, twice: {after:?}"
        );
    }
}

/// Pins the calling thread to `cpu`.
fn pin_to(cpu: usize) {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes inside it, and
    // sched_setaffinity(0, …) reads it for the calling thread only.
    #[allow(unsafe_code)]
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        assert_eq!(
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set),
            0,
            "sched_setaffinity: {}",
            std::io::Error::last_os_error()
        );
    }
}

/// The first CPU this process may run on.
fn first_cpu() -> usize {
    // SAFETY: as in `pin_to`; sched_getaffinity fills the set for the calling thread.
    #[allow(unsafe_code)]
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
        (0..libc::CPU_SETSIZE as usize)
            .find(|&c| libc::CPU_ISSET(c, &set))
            .unwrap_or(0)
    }
}

/// Spins (keeps the CPU) for `d` of wall time.
fn spin(d: Duration) {
    let end = Instant::now() + d;
    while Instant::now() < end {
        std::hint::spin_loop();
    }
}

/// The priority inversion that a `std::sync::Mutex` allows, on one CPU: a client thread at
/// normal priority holds the core's lock; the SCHED_FIFO 80 control thread asks for it; a
/// busy real-time thread of middle priority (FIFO 50) becomes runnable. With a plain mutex the
/// middle thread keeps the holder — and so the control thread — off the CPU for as long as it
/// spins (400 ms here; a 20 ms feedback window is lost after 10 cycles). The core's lock
/// inherits priority: the holder runs at 80 until it lets go, so the control thread waits only
/// for the holder's own 100 ms. Needs SCHED_FIFO (root or CAP_SYS_NICE); without it the test
/// says so and passes, unless `PA10_REQUIRE_FIFO` is set (CI sets it).
#[test]
fn a_client_holding_the_core_lock_runs_at_the_control_threads_priority() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let _serial = serial();
    let permitted = std::thread::spawn(|| pa10::daemon::realtime::set_fifo(10).is_ok())
        .join()
        .unwrap();
    if !permitted {
        assert!(
            std::env::var_os("PA10_REQUIRE_FIFO").is_none(),
            "SCHED_FIFO is not permitted here and PA10_REQUIRE_FIFO is set"
        );
        eprintln!("skipped: SCHED_FIFO not permitted");
        return;
    }
    let dir = temp_dir("inversion");
    let loaded = Config::load(&config(&dir, &Model::nominal())).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let core = pa10::daemon::runtime::share(pa10::daemon::core::Core::from_config(&loaded));
    let cpu = first_cpu();
    let (held, asking) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicBool::new(false)),
    );
    let client = {
        let (core, held) = (core.clone(), held.clone());
        std::thread::spawn(move || {
            pin_to(cpu);
            let _g = pa10::daemon::runtime::lock(&core);
            held.store(true, Ordering::SeqCst);
            spin(Duration::from_millis(100));
        })
    };
    while !held.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(1));
    }
    let control = {
        let (core, asking) = (core.clone(), asking.clone());
        std::thread::spawn(move || {
            pin_to(cpu);
            pa10::daemon::realtime::set_fifo(80).unwrap();
            asking.store(true, Ordering::SeqCst);
            let t = Instant::now();
            drop(pa10::daemon::runtime::lock(&core));
            t.elapsed()
        })
    };
    while !asking.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(Duration::from_millis(5));
    let middle = std::thread::spawn(move || {
        pin_to(cpu);
        pa10::daemon::realtime::set_fifo(50).unwrap();
        spin(Duration::from_millis(400));
    });
    let waited = control.join().unwrap();
    client.join().unwrap();
    middle.join().unwrap();
    eprintln!("the control thread waited {waited:?} for the lock");
    assert!(
        waited < Duration::from_millis(250),
        "the control thread waited {waited:?} behind a preempted client"
    );
}

/// Out of file descriptors (EMFILE, here forced by `ulimit -n`): the `pa10d` binary says so
/// once, keeps its loop, and serves clients again as soon as descriptors are free.
#[test]
fn the_daemon_binary_keeps_accepting_after_running_out_of_file_descriptors() {
    use std::io::{BufRead, Write};
    let _serial = serial();
    let dir = temp_dir("emfile");
    let cfg = config(&dir, &Model::nominal());
    let text = std::fs::read_to_string(&cfg)
        .unwrap()
        .replace("feedback_timeout_ms: 20", "feedback_timeout_ms: 100")
        .replace("  model_dir: .", "  model_dir: .\n  max_clients: 1000");
    std::fs::write(&cfg, text).unwrap();
    let log = dir.join("pa10d.log");
    let _child = Reaped(
        std::process::Command::new("sh")
            .args(["-c", "ulimit -n 40 && exec \"$0\" --config \"$1\""])
            .arg(env!("CARGO_BIN_EXE_pa10d"))
            .arg(&cfg)
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap(),
    );
    let sock = dir.join("api.sock");
    let end = Instant::now() + Duration::from_secs(10);
    while !sock.exists() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
    // one status round trip, or None when no answer comes within `wait`
    let ask = |s: &mut std::os::unix::net::UnixStream, wait: Duration| -> Option<Value> {
        s.set_read_timeout(Some(wait)).unwrap();
        s.write_all(b"{\"cmd\":\"status\"}\n").ok()?;
        let mut line = String::new();
        std::io::BufReader::new(s.try_clone().unwrap())
            .read_line(&mut line)
            .ok()?;
        serde_json::from_str(&line).ok()
    };
    // idle clients until the daemon has no descriptor left for the next one
    let mut clients = Vec::new();
    let mut starved = false;
    for _ in 0..200 {
        let mut s = std::os::unix::net::UnixStream::connect(&sock).unwrap();
        let answered = ask(&mut s, Duration::from_millis(500)).is_some();
        clients.push(s);
        if !answered {
            starved = true;
            break;
        }
    }
    assert!(starved, "40 descriptors never ran out");
    let held = clients.len();
    drop(clients);
    // descriptors free again: a new client is served within the back-off (≤ 1 s) and the
    // arm never stopped holding
    let mut s = std::os::unix::net::UnixStream::connect(&sock).unwrap();
    let v = ask(&mut s, Duration::from_secs(5)).expect("served again after EMFILE");
    assert_eq!(v["status"]["state"], "holding", "{v}");
    // pa10d logs through a non-blocking writer: its lines reach the file a moment later
    let end = Instant::now() + Duration::from_secs(5);
    let mut text = std::fs::read_to_string(&log).unwrap();
    while !text.contains("accepting clients again") && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
        text = std::fs::read_to_string(&log).unwrap();
    }
    assert_eq!(
        text.matches("accepting a client failed").count(),
        1,
        "logged once for {held} clients: {text}"
    );
    assert!(text.contains("accepting clients again"), "{text}");
}

/// Starts the `pa10d` binary on the simulated arm with its configuration in `dir` (sim.yaml
/// with real-time margins for a shared test machine, then `edit`); waits (≤ 10 s) for its
/// socket.
/// The `pa10` client run with `args` against the daemon on `sock`.
fn pa10_on(sock: &Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_pa10"))
        .args(args)
        .env("PA10D_SOCKET", sock)
        .output()
        .unwrap()
}

fn spawn_pa10d(dir: &Path, edit: impl FnOnce(String) -> String) -> (Reaped, PathBuf) {
    let cfg = config(dir, &Model::nominal());
    let text = crate::common::ci_tolerances(&std::fs::read_to_string(&cfg).unwrap())
        .replace("feedback_timeout_ms: 20", "feedback_timeout_ms: 100");
    std::fs::write(&cfg, edit(text)).unwrap();
    let child = Reaped(
        std::process::Command::new(env!("CARGO_BIN_EXE_pa10d"))
            .args(["--config", cfg.to_str().unwrap()])
            // not piped: an unread pipe fills up and blocks the daemon's logging
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let sock = dir.join("api.sock");
    let end = Instant::now() + Duration::from_secs(10);
    while !sock.exists() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
    (child, sock)
}

/// A recording cut by `kill -9` of the `pa10d` binary: `pa10 record recover` rewrites what
/// reached the disk as a whole MCAP file that our reader and (in CI, `PA10_PYTHON_MCAP=1`) the
/// Python `mcap` package read in full; the crash loses at most a chunk and the queue.
#[test]
fn a_recording_cut_by_kill_9_is_recovered_whole() {
    let _serial = serial();
    let dir = temp_dir("crash");
    let (mut child, sock) = spawn_pa10d(&dir, |text| {
        text.replace(
            "  dir: /tmp/pa10d-recordings\n  autostart: false",
            &format!("  dir: {}\n  autostart: false", dir.display()),
        )
    });
    let pa10 = |args: &[&str]| pa10_on(&sock, args);
    let o = pa10(&["record", "start", "--out", "crash"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::thread::sleep(Duration::from_secs(3));
    let st: Value = serde_json::from_slice(&pa10(&["status", "--json"]).stdout).unwrap();
    let written = st["status"]["recording"]["written"].as_u64().unwrap();
    child.0.kill().unwrap(); // SIGKILL: no summary, no footer, the last chunk unwritten
    child.0.wait().unwrap();
    let cut = dir.join("crash.mcap");
    let whole = dir.join("recovered.mcap");
    let o = pa10(&[
        "record",
        "recover",
        cut.to_str().unwrap(),
        whole.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    let recovered = r["channels"]["/pa10/cycle"].as_u64().unwrap();
    let cycles = pa10::record::read::cycles(&whole).unwrap();
    assert_eq!(cycles.len() as u64, recovered);
    assert!(
        pa10::record::read::info(&whole)
            .unwrap()
            .truncated
            .is_none()
    );
    // at 500 Hz for 3 s: the crash lost at most a chunk (and the queue) of what was written
    let lost = written.saturating_sub(recovered);
    eprintln!(
        "kill -9: {written} cycles written by the status before the kill, {recovered} recovered"
    );
    assert!(recovered > 500, "{r}");
    // CHUNK_BYTES of ~830-byte cycles is ~160 cycles; the 8 KiB file buffer a fraction of one
    assert!(lost < 400, "{written} written, {recovered} recovered");
    // refused: an output that exists is not overwritten
    let again = pa10(&[
        "record",
        "recover",
        cut.to_str().unwrap(),
        whole.to_str().unwrap(),
    ]);
    assert!(!again.status.success());
    assert_eq!(
        pa10::record::read::cycles(&whole).unwrap().len() as u64,
        recovered
    );
    if std::env::var("PA10_PYTHON_MCAP").is_ok_and(|v| v == "1") {
        let o = std::process::Command::new("python3")
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/record/check_mcap.py"
            ))
            .arg(&whole)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["counts"]["/pa10/cycle"].as_u64(), Some(recovered), "{v}");
        assert_eq!(v["monotonic"], true, "{v}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The Python client (`clients/python`, installed by CI: `PA10_PYTHON_CLIENT=1`) against the
/// `pa10d` binary on the simulated arm: moves, a refusal's words, a trajectory, the lease, a
/// servo stream and its deadline, jog, speed scaling, subscribe.
#[test]
fn the_python_client_drives_the_daemon_binary() {
    if std::env::var("PA10_PYTHON_CLIENT").is_ok_and(|v| v == "1") {
        let _serial = serial();
        let dir = temp_dir("python");
        let (_child, sock) = spawn_pa10d(&dir, |t| t);
        let out = python(
            "clients/python/tests/against_daemon.py",
            &[sock.to_str().unwrap()],
            &[],
        );
        assert!(out.contains("all checks passed"), "{out}");
        std::fs::remove_dir_all(&dir).unwrap();
    } else {
        eprintln!("skipped: set PA10_PYTHON_CLIENT=1 with clients/python installed (CI does)");
    }
}

/// Runs `python3 SCRIPT ARGS…` (SCRIPT relative to the package) with `env` added; its stdout,
/// once it exited 0 (else both outputs in the panic).
fn python(script: &str, args: &[&str], env: &[(&str, &str)]) -> String {
    let o = std::process::Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join(script))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{script}: {out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

/// `pa10-ros2` (feature `ros2`) next to the `pa10d` binary on the simulated arm, read by
/// Eclipse Cyclone DDS from Python with the ROS 2 types declared there (CI installs
/// `cyclonedds`): `/joint_states` at ≥ 80 Hz, names, the link estimate `pa10 status` shows,
/// the torque estimate as effort. A domain of its own; loopback only.
#[cfg(feature = "ros2")]
#[test]
fn ros2_joint_states_reach_a_dds_implementation_we_did_not_write() {
    let _serial = serial();
    let dir = temp_dir("ros2");
    let (_daemon, sock) = spawn_pa10d(&dir, |t| t);
    let domain = (100 + std::process::id() % 100).to_string();
    let _bridge = ros2_bridge(&sock, &domain, "enhanced");
    // the arm holds: what pa10 status says is what /joint_states must carry
    let o = pa10_on(&sock, &["status", "--json"]);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let q: Vec<String> = v["status"]["trajectory"]["actual"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.to_string())
        .collect();
    let out = python(
        "tests/ros2/check_joint_states.py",
        &[&q.join(",")],
        &[("ROS_DOMAIN_ID", &domain)],
    );
    let r: Value = serde_json::from_str(&out).unwrap();
    eprintln!("ros2: {r}");
    assert!(r["rate_hz"].as_f64().unwrap() >= 80.0, "{r}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `pa10-ros2` on the daemon at `sock`, in DDS domain `domain`, with service `mapping`.
#[cfg(feature = "ros2")]
fn ros2_bridge(sock: &Path, domain: &str, mapping: &str) -> Reaped {
    Reaped(
        std::process::Command::new(env!("CARGO_BIN_EXE_pa10-ros2"))
            .env("PA10D_SOCKET", sock)
            .env("ROS_DOMAIN_ID", domain)
            .env("PA10_ROS2_SERVICE_MAPPING", mapping)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    )
}

/// The FollowJointTrajectory action, the Trigger services and /diagnostics of `pa10-ros2`,
/// driven by Eclipse Cyclone DDS from Python through the raw DDS topics a ROS 2 action is made
/// of (`tests/ros2/follow_trajectory.py`, the ROS 2 IDL types declared there), under both
/// service mappings (rmw_cyclonedds' request header, and the enhanced mapping of rmw_fastrtps):
/// a goal in another joint order with its start state at t = 0 succeeds and the arm arrives
/// (checked on pa10d's socket); unknown joints end INVALID_JOINTS with the name; a goal pa10d
/// refuses ends INVALID_GOAL with pa10d's words; a cancel stops the arm short of its goal
/// (CANCELED); a newer goal replaces a running one (CANCELED, then SUCCEEDED); `~/stop`
/// answers success; `/diagnostics` names the loop's state.
#[cfg(feature = "ros2")]
#[test]
fn ros2_follow_joint_trajectory_through_a_dds_implementation_we_did_not_write() {
    let _serial = serial();
    for (k, mapping) in ["cyclone", "enhanced"].into_iter().enumerate() {
        let dir = temp_dir(&format!("ros2-fjt-{mapping}"));
        let (_daemon, sock) = spawn_pa10d(&dir, |t| t);
        let domain = (10 + 2 * (std::process::id() % 40) + k as u32).to_string();
        let _bridge = ros2_bridge(&sock, &domain, mapping);
        let out = python(
            "tests/ros2/follow_trajectory.py",
            &[mapping],
            &[
                ("PA10D_SOCKET", sock.to_str().unwrap()),
                ("ROS_DOMAIN_ID", &domain),
            ],
        );
        let r: Value = serde_json::from_str(&out).unwrap();
        eprintln!("ros2 {mapping}: {r}");
        assert!(r["goal_succeeded"]["worst_error_rad"].as_f64().unwrap() < 0.005);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// The one real-time end-to-end test: the `pa10d` binary on its socket with the simulated arm.
#[test]
fn the_daemon_binary_serves_its_socket_and_stops_on_sigterm() {
    let _serial = serial();
    let dir = temp_dir("bin");
    let (mut child, sock) = spawn_pa10d(&dir, |text| {
        // every cycle recorded from the start (record.autostart), into the test's folder
        let t = text.replace(
            "  dir: /tmp/pa10d-recordings\n  autostart: false",
            &format!("  dir: {}\n  autostart: true", dir.display()),
        );
        assert!(t.contains("autostart: true"));
        t
    });
    let cfg = dir.join("pa10d.yaml");
    use std::io::{BufRead, Write};
    let mut s = std::os::unix::net::UnixStream::connect(&sock).unwrap();
    s.write_all(b"{\"cmd\":\"status\"}\n").unwrap();
    let mut line = String::new();
    std::io::BufReader::new(s.try_clone().unwrap())
        .read_line(&mut line)
        .unwrap();
    let v: Value = serde_json::from_str(&line).unwrap();
    assert_eq!(v["ok"], true);
    assert_eq!(v["status"]["servo"], "Control");
    // a second daemon on the same configuration refuses to start and names the first
    let second = std::process::Command::new(env!("CARGO_BIN_EXE_pa10d"))
        .args(["--config", cfg.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(second.status.code(), Some(1));
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(
        err.contains(&format!("another pa10d (pid {},", child.0.id())),
        "{err}"
    );
    assert!(sock.exists(), "the first daemon's socket is untouched");
    // the pa10 client wraps every call
    let pa10 = |args: &[&str]| pa10_on(&sock, args);
    let o = pa10(&["status", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["status"]["state"], "holding");
    let o = pa10(&[
        "move", "joints", "--wait", "0.1", "0.45", "1.55", "0", "1.1", "-0.1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        String::from_utf8_lossy(&o.stdout).starts_with("pa10d holding, in position · "),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let o = pa10(&["status", "--json"]);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let sp: Vec<f64> = v["status"]["setpoint"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        (sp[0] - 0.1).abs() < 1e-9 && (sp[5] + 0.1).abs() < 1e-9,
        "{sp:?}"
    );
    let o = pa10(&["payload", "--", "-5"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .contains("pa10d refused: payload must be within 0…500 N"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = pa10(&["move", "pose", "3", "0", "0.5", "0", "1", "0", "0"]);
    assert_eq!(o.status.code(), Some(1));
    // the motion commands of docs/motion.md
    for args in [
        &["payload", "--mass", "2", "--com", "0.1", "0", "0.05"][..],
        &["payload", "0"],
        &["tool", "0", "0", "0", "1", "0", "0", "0"],
        &["speed", "0.8"],
        &["jog", "6", "0.1", "--for", "0.2"],
    ] {
        let o = pa10(args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let o = pa10(&["speed", "1.5"]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("speed scaling must be within (0, 1]"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let traj = dir.join("path.csv");
    std::fs::write(
        &traj,
        "time_from_start,q1,q2,q3,q4,q5,q6\n0.8,0.1,0.46,1.54,0,1.1,-0.1\n1.6,0.1,0.45,1.55,0,1.1,-0.1\n",
    )
    .unwrap();
    let o = pa10(&["trajectory", traj.to_str().unwrap(), "--wait"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("succeeded"));
    let o = pa10(&["speed", "1"]);
    assert!(o.status.success());
    // pa10 servo: setpoints from stdin, then silence: the daemon stops the arm by itself
    let mut servo = std::process::Command::new(env!("CARGO_BIN_EXE_pa10"))
        .arg("servo")
        .env("PA10D_SOCKET", &sock)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut stdin = servo.stdin.take().unwrap();
        for k in 0..50 {
            let q6 = -0.1 + 0.0004 * k as f64;
            writeln!(stdin, "0.1 0.45 1.55 0 1.1 {q6}").unwrap();
            std::thread::sleep(Duration::from_millis(4));
        }
    }
    let out = servo.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("50 setpoints sent"));
    let end = Instant::now() + Duration::from_secs(5);
    let st = loop {
        let o = pa10(&["status", "--json"]);
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        if v["status"]["state"] == "holding" || Instant::now() > end {
            break v;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(st["status"]["state"], "holding", "{st}");
    assert!(
        st["status"]["stream_end"]
            .as_str()
            .is_some_and(|e| e.contains("servo.deadline_ms")),
        "{st}"
    );
    // pa10 collect drives it through a pose list and records resolver angles and currents …
    let poses = dir.join("poses.csv");
    std::fs::write(
        &poses,
        "config_id,load_n,q1,q2,q3,q4,q5,q6\na,0,0.0,0.4,1.6,0,1.1,0\nb,0,0.2,0.5,1.5,0.1,1.0,0\n",
    )
    .unwrap();
    let robot = dir.join("robot.csv");
    let o = pa10(&[
        "collect",
        "run",
        "--poses",
        poses.to_str().unwrap(),
        "--out",
        robot.to_str().unwrap(),
        "--samples",
        "2",
        "--settle-ms",
        "100",
        "--yes",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let samples =
        pa10::calib::collect::parse_robot(&std::fs::read_to_string(&robot).unwrap(), "r").unwrap();
    assert_eq!(samples.len(), 4);
    assert!((samples[2].q[0] - 0.2).abs() < 1e-3, "{:?}", samples[2]);
    assert!(
        samples[0].current[1].abs() > 0.1,
        "gravity on J2 draws current"
    );
    // … and merges them with the instrument's measurements by pose id.
    let inst = dir.join("inst.csv");
    std::fs::write(
        &inst,
        "config_id,load_n,x,y,z,qw,qx,qy,qz\n\
         a,0,0.6,0,0.4,0,1,0,0\na,0,0.6,0,0.4,0,1,0,0\nb,0,0.5,0.1,0.3,0,1,0,0\nb,0,0.5,0.1,0.3,0,1,0,0\n",
    )
    .unwrap();
    let cal = dir.join("cal.csv");
    let o = pa10(&[
        "collect",
        "merge",
        "--robot",
        robot.to_str().unwrap(),
        "--instrument",
        inst.to_str().unwrap(),
        "--out",
        cal.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        pa10::calib::dataset::Dataset::load(&cal)
            .unwrap()
            .rows
            .len(),
        4
    );
    assert!(pa10(&["stop"]).status.success());
    #[cfg(unix)]
    {
        let pid = child.0.id() as i32;
        // SIGTERM through the shell's kill: no libc dependency in the tests
        std::process::Command::new("kill")
            .args(["-TERM", &pid.to_string()])
            .status()
            .unwrap();
    }
    let status = child.0.wait().unwrap();
    assert!(status.success(), "{status:?}");
    assert!(!sock.exists(), "socket removed on exit");
    // the recording the daemon made of all this, closed on exit, read back through the CLI
    let first = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            p.file_name().is_some_and(|n| {
                n.to_string_lossy().starts_with("pa10d-") && !n.to_string_lossy().contains("-0")
            })
        })
        .expect("an autostarted recording");
    let files = pa10::record::files_of(&first);
    let o = pa10(&[
        "record",
        "info",
        "--json",
        files.last().unwrap().to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let info: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(info["recorder"]["dropped_queue"], "0", "{info}");
    let o = pa10(&[
        "record",
        "export",
        files[0].to_str().unwrap(),
        "--csv",
        dir.join("csv").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let events = std::fs::read_to_string(dir.join("csv/events.csv")).unwrap();
    assert!(events.contains("command,\"move\""), "{events}");
    // the campaign cut again from the recording: a sample per still phase at a listed pose
    let robot2 = dir.join("robot2.csv");
    let mut args = vec!["collect", "from-recording"];
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    args.extend(names.iter().map(String::as_str));
    args.extend([
        "--poses",
        poses.to_str().unwrap(),
        "--out",
        robot2.to_str().unwrap(),
        "--min-still",
        "0.1",
        "--settle",
        "0.05",
    ]);
    let o = pa10(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cut = pa10::calib::collect::parse_robot(&std::fs::read_to_string(&robot2).unwrap(), "r2")
        .unwrap();
    assert!(
        cut.iter().any(|r| r.config_id == "a") && cut.iter().any(|r| r.config_id == "b"),
        "{cut:?}"
    );
    let b = cut.iter().find(|r| r.config_id == "b").unwrap();
    assert!((b.q[0] - 0.2).abs() < 1e-3, "{b:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_storm_of_malformed_frames_does_not_crash_the_daemon() {
    let _busy = busy();
    use rand::{RngExt, SeedableRng};
    let mut ls = lockstep("storm", &Model::nominal());
    // a rogue node: 20 000 random frames (ids, lengths, payloads), 200 per millisecond
    let mut rng = rand_pcg::Pcg64::seed_from_u64(0xbad);
    for k in 0..20_000u32 {
        let id = rng.random_range(0..0x800u16);
        let n = rng.random_range(0..=8usize);
        let data: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        ls.inject(pa10::can::CanFrame::new(id, &data).unwrap());
        if k % 200 == 0 {
            ls.run_for(1e-3);
        }
    }
    ls.run_for(0.1);
    let st = status(&ls);
    assert!(st["link"]["malformed"].as_u64().unwrap() > 1000, "{st}");
    // still alive and answering; whatever the rogue frames did is a named state, not a crash
    assert!(st["state"] == "holding" || st["state"] == "fault", "{st}");
    if st["state"] == "fault" {
        assert_eq!(ls.call_json(&json!({"cmd": "reset"}))["ok"], true);
    }
}

#[test]
fn the_demo_gathers_through_the_daemon_calibrates_and_beats_the_nominal_model() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_pa10"))
        .args(["demo", "--quick", "--json", "--seed", "2"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["calibration_rows"], 8 * 3 * 2);
    let models = v["models"].as_array().unwrap();
    let at90 = |m: usize| models[m][1][2]["mean_mm"].as_f64().unwrap();
    assert_eq!(models[2][0], "full model");
    // 8 poses are a thin calibration set: the full model must still beat the nominal one
    // at 90 N by a wide margin (the full run does 0.3 mm vs 3.7 mm).
    assert!(
        at90(2) < 0.5 * at90(0),
        "full {} vs nominal {}",
        at90(2),
        at90(0)
    );
}

/// `pa10 demo --config`: a configuration on `torque_source: estimated` runs the lab's path
/// (identification through the daemon first, calibration on the identified model's torques);
/// a configuration without a simulated arm is refused with the reason.
#[test]
fn the_demo_runs_the_labs_path_on_a_configured_arm() {
    let dir = std::env::temp_dir().join(format!("pa10-demo-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let root = env!("CARGO_MANIFEST_DIR");
    let text = std::fs::read_to_string(format!("{root}/config/sim.yaml")).unwrap();
    let estimated = text.replace("torque_source: measured", "torque_source: estimated");
    assert_ne!(estimated, text, "config/sim.yaml names its torque source");
    std::fs::write(dir.join("sim.yaml"), estimated).unwrap();
    std::fs::copy(
        format!("{root}/config/model-nominal.yaml"),
        dir.join("model-nominal.yaml"),
    )
    .unwrap();
    let demo = |config: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_pa10"))
            .args([
                "demo", "--quick", "--json", "--seed", "2", "--config", config,
            ])
            .output()
            .unwrap()
    };
    let o = demo(dir.join("sim.yaml").to_str().unwrap());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["identified_samples"].as_u64().unwrap() > 300, "{v}");
    assert_eq!(v["seed"], 2);
    let models = v["models"].as_array().unwrap();
    let at90 = |m: usize| models[m][1][2]["mean_mm"].as_f64().unwrap();
    assert!(
        at90(2) < 0.5 * at90(0),
        "full {} vs nominal {}",
        at90(2),
        at90(0)
    );
    // the hardware's bus, no simulated arm
    let cut = text
        .find("\nsim:")
        .expect("config/sim.yaml has a sim section");
    let hardware = text[..cut].replace("backend: virtual", "backend: socketcan\n  interface: can0");
    std::fs::write(dir.join("hw.yaml"), hardware).unwrap();
    let refused = demo(dir.join("hw.yaml").to_str().unwrap());
    assert!(!refused.status.success());
    let e = String::from_utf8_lossy(&refused.stderr);
    assert!(e.contains("no simulated arm"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_move_planned_from_a_setpoint_or_model_that_changed_is_refused() {
    use pa10::daemon::control::CommandError;
    use pa10::daemon::core::Command;
    use pa10::daemon::plan::Move;
    let _busy = busy();
    let mut ls = lockstep("stale", &Model::nominal());
    let plan = |ls: &Lockstep, q: [f64; 6]| {
        let basis = ls.core.lock().plan_basis().unwrap();
        let mv = Move::joints(basis.from, q, &basis.limits).unwrap();
        (Box::new(mv), basis)
    };
    let a = [0.1, 0.4, 1.6, 0.0, 1.1, 0.0];
    // planned, then another client's move runs to completion: the setpoint moved
    let (mv, basis) = plan(&ls, a);
    assert_eq!(
        ls.call_json(&json!({"cmd": "move_joints", "q": [0.0, 0.5, 1.6, 0.0, 1.1, 0.0]}))["ok"],
        true
    );
    assert_eq!(wait_holding(&mut ls, 5.0)["state"], "holding");
    let r = ls.core.lock().submit(Command::Start { mv, basis });
    assert_eq!(r, Err(CommandError::Stale));
    // planned, then the model was replaced: refused too
    let (mv, basis) = plan(&ls, a);
    let model = std::sync::Arc::new(Model::nominal());
    let file = "nominal".into();
    ls.core
        .lock()
        .submit(Command::LoadModel { model, file })
        .unwrap();
    let r = ls.core.lock().submit(Command::Start { mv, basis });
    assert_eq!(r, Err(CommandError::Stale));
    // planned from what is current: accepted
    let (mv, basis) = plan(&ls, a);
    assert_eq!(ls.core.lock().submit(Command::Start { mv, basis }), Ok(()));
    assert_eq!(wait_holding(&mut ls, 5.0)["state"], "holding");
    // a basis is refused outright while a move runs
    assert_eq!(
        ls.call_json(&json!({"cmd": "move_joints", "q": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0]}))["ok"],
        true
    );
    ls.run_for(0.01);
    assert!(matches!(
        ls.core.lock().plan_basis(),
        Err(CommandError::Busy)
    ));
}

/// The socket server itself, with a plain `std` client: line limits and non-UTF-8 input.
#[test]
fn the_socket_refuses_overlong_and_non_utf8_lines_and_extra_clients_with_an_answer() {
    use std::io::{BufRead, BufReader, Read, Write};
    let _busy = busy();
    let ls = lockstep("sock", &Model::nominal());
    let dir = temp_dir("sock-api");
    let path = dir.join("api.sock");
    let server = Server::start(ls.core.clone(), &path, 2);
    let health = server.health.clone();
    let answer = |s: &mut std::os::unix::net::UnixStream| -> Value {
        let mut line = String::new();
        BufReader::new(s.try_clone().unwrap())
            .read_line(&mut line)
            .unwrap();
        serde_json::from_str(&line).unwrap()
    };
    // not UTF-8: an answer, and the connection stays usable
    let mut s = std::os::unix::net::UnixStream::connect(&path).unwrap();
    s.write_all(b"\xff\xfe{}\n").unwrap();
    let a = answer(&mut s);
    assert!(a["error"].as_str().unwrap().contains("not UTF-8"), "{a}");
    s.write_all(b"{\"cmd\":\"status\"}\n").unwrap();
    assert_eq!(answer(&mut s)["ok"], true);
    // api.max_clients = 2: a third client is told why and closed; a freed place is reused
    let mut s2 = std::os::unix::net::UnixStream::connect(&path).unwrap();
    s2.write_all(b"{\"cmd\":\"status\"}\n").unwrap();
    assert_eq!(answer(&mut s2)["ok"], true);
    let mut s3 = std::os::unix::net::UnixStream::connect(&path).unwrap();
    let a = answer(&mut s3);
    assert!(
        a["error"].as_str().unwrap().contains("too many clients (2"),
        "{a}"
    );
    assert_eq!(
        health
            .refused_clients
            .load(std::sync::atomic::Ordering::Relaxed),
        1
    );
    drop(s2);
    let end = Instant::now() + Duration::from_secs(5);
    while health.clients.load(std::sync::atomic::Ordering::Relaxed) > 1 && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut s4 = std::os::unix::net::UnixStream::connect(&path).unwrap();
    s4.write_all(b"{\"cmd\":\"status\"}\n").unwrap();
    assert_eq!(answer(&mut s4)["ok"], true);
    // 100 kB without a newline: refused with a reason, then closed
    // (written from another thread: the server may close before all of it is sent)
    let mut w = s.try_clone().unwrap();
    let writer = std::thread::spawn(move || {
        let _ = w.write_all(&vec![b'x'; 100_000]);
    });
    let a = answer(&mut s);
    writer.join().unwrap();
    assert!(a["error"].as_str().unwrap().contains("65536 bytes"), "{a}");
    let mut rest = Vec::new();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    // closed after the refusal (a reset when the rest of the line was still unread)
    match s.read_to_end(&mut rest) {
        Ok(n) => assert_eq!(n, 0),
        Err(e) => assert_eq!(e.kind(), std::io::ErrorKind::ConnectionReset),
    }
    server.stop();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn load_model_reads_only_regular_files_inside_the_model_dir_and_never_echoes_them() {
    let _busy = busy();
    let dir = temp_dir("models");
    let loaded = Config::load(&config(&dir, &Model::nominal())).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    ls.run_until_ready(1.0).unwrap();
    let load = |ls: &Lockstep, p: &str| ls.call_json(&json!({"cmd": "load_model", "path": p}));
    let secret = "root:x:0:0:root:/root:/bin/bash";
    std::fs::write(dir.join("passwd.yaml"), format!("{secret}\n")).unwrap();
    std::fs::write(dir.join("big.yaml"), vec![b'#'; 2 << 20]).unwrap();
    std::os::unix::fs::symlink("/etc/hostname", dir.join("out.yaml")).unwrap();
    let fifo = dir.join("fifo.yaml");
    let have_fifo = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    let mut cases = vec![
        ("/etc/passwd".to_string(), "outside the model directory"),
        (
            "../../../etc/passwd".to_string(),
            "outside the model directory",
        ),
        ("out.yaml".to_string(), "outside the model directory"),
        // no probing: a missing file outside is refused as outside, not as missing
        (
            "/nonexistent-pa10-probe/x.yaml".to_string(),
            "outside the model directory",
        ),
        (
            "../nonexistent-pa10-probe".to_string(),
            "outside the model directory",
        ),
        ("passwd.yaml".to_string(), "passwd.yaml"),
        ("big.yaml".to_string(), "more than the 1048576"),
        ("missing.yaml".to_string(), "missing.yaml"),
    ];
    if have_fifo {
        cases.push(("fifo.yaml".to_string(), "not a regular file"));
    }
    for (path, why) in &cases {
        let r = load(&ls, path);
        assert_eq!(r["ok"], false, "{path}: {r}");
        let e = r["error"].as_str().unwrap();
        assert!(e.contains(why), "{path}: {e}");
        assert!(
            !(why.contains("outside") && e.contains("os error")),
            "{path}: the file system was asked: {e}"
        );
        assert!(
            !e.contains("root:x") && !e.contains("/bin/bash"),
            "{path}: leaks {e}"
        );
        // the status keeps it, in the same words
        let last = &status(&ls)["last_refusal"];
        assert_eq!(last["request"], "load_model", "{last}");
        assert_eq!(last["error"], e, "{last}");
    }
    // the model next to the configuration loads, by a relative or an absolute path
    ls.run_for(0.1);
    assert_eq!(load(&ls, "model.yaml")["ok"], true);
    let abs = dir.join("model.yaml");
    assert_eq!(load(&ls, abs.to_str().unwrap())["ok"], true);
    let st = status(&ls);
    assert_eq!(st["state"], "holding");
    let m = &st["model"];
    assert_eq!(m["file"], abs.to_str().unwrap(), "{m}");
    assert_eq!(m["kind"], "nominal", "{m}");
    assert!(m["since_s"].as_f64().unwrap() > 0.0, "{m}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_second_daemon_cannot_take_a_live_socket() {
    let dir = temp_dir("claim");
    let sock = dir.join("api.sock");
    let first = pa10::daemon::api::SocketLock::claim(&sock).unwrap();
    let e = pa10::daemon::api::SocketLock::claim(&sock).unwrap_err();
    assert!(
        e.contains(&format!("pid {}", std::process::id())) && e.contains("another pa10d"),
        "{e}"
    );
    drop(first);
    // released with its owner: the next claim succeeds
    assert!(pa10::daemon::api::SocketLock::claim(&sock).is_ok());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_controller_fault_is_reported_with_the_controllers_own_words() {
    let _busy = busy();
    let mut ls = lockstep("ctlfault", &Model::nominal());
    // the controller's clock jumps 100 ms ahead with no command in it: its watchdog trips
    let mut out = Vec::new();
    let t = ls.now() + 0.1;
    ls.servo.tick(t, &mut out);
    for f in out {
        ls.inject(f);
    }
    ls.run_for(0.05);
    let st = status(&ls);
    assert_eq!(st["state"], "fault", "{st}");
    let f = st["fault"].as_str().unwrap();
    assert!(
        f.contains("servo controller reports a fault") && f.contains("Watchdog"),
        "{f}"
    );
}
