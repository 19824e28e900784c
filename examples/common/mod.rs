//! What the real-time daemon examples share: starting the daemon on the simulated arm from
//! `config/sim.yaml`, and printing `status` percentiles.

use pa10::daemon::config::{Config, Settings};
use pa10::daemon::runtime::Daemon;
use pa10::sim::rig::SimulatedArm;
use serde_json::Value;

/// `config/sim.yaml` at `rate_hz`, with a private socket path.
#[allow(dead_code)] // not every example runs on classic CAN alone
pub fn sim_config(rate_hz: f64, tag: &str) -> Settings {
    sim_config_on(rate_hz, tag, None)
}

/// [`sim_config`] on CAN FD with a `data_bitrate` (bit/s) data phase when given.
pub fn sim_config_on(rate_hz: f64, tag: &str, fd_data_bitrate: Option<f64>) -> Settings {
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let text = std::fs::read_to_string(base.join("sim.yaml")).expect("config/sim.yaml");
    let sock = std::env::temp_dir().join(format!("pa10-{tag}-{}.sock", std::process::id()));
    let bus = match fd_data_bitrate {
        Some(d) => format!("bus:\n  fd: true\n  data_bitrate: {d}\n"),
        None => "bus:\n".to_string(),
    };
    let t = text
        .replace("bus:\n", &bus)
        .replace("rate_hz: 500", &format!("rate_hz: {rate_hz}"))
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", sock.display()),
        );
    Config::parse(&t, tag)
        .expect("config")
        .validate(&base)
        .expect("valid")
}

/// The real-time daemon on the simulated arm of `cfg` (drop the daemon first).
#[allow(dead_code)] // each example compiles this module; not every one starts this way
pub fn start(cfg: &Settings) -> (SimulatedArm, Daemon) {
    let arm = SimulatedArm::from_config(cfg).expect("simulated arm");
    let d = Daemon::start(cfg, arm.host()).expect("daemon");
    (arm, d)
}

/// `p50 / p99 / max` of a status triple, µs.
pub fn triple(v: &Value) -> String {
    format!(
        "{:.0} / {:.0} / {:.0}",
        v[0].as_f64().unwrap_or(0.0),
        v[1].as_f64().unwrap_or(0.0),
        v[2].as_f64().unwrap_or(0.0)
    )
}

/// The real-time daemon on the simulated arm of `cfg` (control thread SCHED_FIFO 80 and the
/// simulated controller 81 when `fifo`) with its socket server at `path`.
#[allow(dead_code)] // not every example serves a socket
pub struct Served {
    /// The daemon.
    pub daemon: Daemon,
    arm: SimulatedArm,
    rt: tokio::runtime::Runtime,
    stop: tokio::sync::watch::Sender<bool>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
}

#[allow(dead_code)]
impl Served {
    /// Starts both and waits for the socket.
    pub fn start(cfg: &mut Settings, fifo: bool, path: &std::path::Path) -> Self {
        cfg.realtime.sched_fifo_priority = fifo.then_some(80);
        let (truth, seed) = pa10::sim::rig::truth_for(cfg).expect("truth");
        let arm =
            SimulatedArm::start_on(truth, seed, fifo.then_some(81), cfg.bus.timing()).expect("arm");
        let daemon = Daemon::start(cfg, arm.host()).expect("daemon");
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .expect("runtime");
        let (stop, stop_rx) = tokio::sync::watch::channel(false);
        let task = {
            let (p, core) = (path.to_path_buf(), daemon.core.clone());
            let health = std::sync::Arc::new(pa10::daemon::api::ApiHealth::default());
            rt.spawn(
                async move { pa10::daemon::api::serve(&p, 0o600, 64, core, health, stop_rx).await },
            )
        };
        while !path.exists() {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        Self {
            daemon,
            arm,
            rt,
            stop,
            task,
        }
    }

    /// The daemon's status now.
    pub fn status(&self) -> Value {
        status_json(&self.daemon.core)
    }

    /// Stops serving, the daemon (the arm at rest first) and the simulated arm.
    pub fn stop(self) {
        let _ = self.stop.send(true);
        let _ = self.rt.block_on(self.task);
        drop(self.daemon);
        drop(self.arm);
    }
}

/// The status of `core` in its wire form (a JSON value), for the examples' tables.
pub fn status_json(core: &pa10::daemon::runtime::SharedCore) -> Value {
    serde_json::to_value(pa10::daemon::api::status_reply(core)).unwrap_or_default()["status"]
        .clone()
}

/// The examples' shared start: SECONDS from the first numeric argument (or `default_s`),
/// whether SCHED_FIFO is permitted here (probed on a throw-away thread, printed), and a
/// fresh temporary folder for `tag`.
#[allow(dead_code)]
pub fn setup(tag: &str, default_s: f64) -> (f64, bool, std::path::PathBuf) {
    let secs = std::env::args()
        .skip(1)
        .find_map(|s| s.parse().ok())
        .unwrap_or(default_s);
    let fifo = std::thread::spawn(|| pa10::daemon::realtime::set_fifo(80).is_ok())
        .join()
        .expect("probe thread");
    let dir = std::env::temp_dir().join(format!("pa10-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    println!(
        "control thread: {}",
        if fifo {
            "SCHED_FIFO 80"
        } else {
            "normal priority (SCHED_FIFO not permitted)"
        }
    );
    (secs, fifo, dir)
}

/// Moves the arm of `core` back and forth between two joint targets for `secs` (real
/// time), each move awaited; the moves made.
#[allow(dead_code)]
pub fn back_and_forth(core: &pa10::daemon::runtime::SharedCore, secs: f64) -> usize {
    let a = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
    let b = [0.3, 0.6, 1.3, 0.4, 0.8, 0.5];
    let end = std::time::Instant::now() + std::time::Duration::from_secs_f64(secs);
    let mut k = 0;
    while std::time::Instant::now() < end {
        let q = if k % 2 == 0 { b } else { a };
        let r = pa10::daemon::api::handle(core, pa10::daemon::wire::ApiRequest::MoveJoints { q });
        let dur = match r {
            pa10::daemon::wire::Reply::Ok(pa10::daemon::wire::Answer::Moving { duration_s }) => {
                duration_s
            }
            _ => 0.5,
        };
        std::thread::sleep(std::time::Duration::from_secs_f64(dur + 0.1));
        k += 1;
    }
    k
}

/// Above this p99 of its own wake-up lateness the host is not fit for a 500 Hz loop, ms.
#[allow(dead_code)]
pub const HOST_UNFIT_P99_MS: f64 = 1.0;
/// A single stall of the host longer than this can cost the loop its feedback window, ms.
#[allow(dead_code)]
pub const HOST_UNFIT_MAX_MS: f64 = 20.0;

/// The host's own stalls while a run goes on: a thread at SCHED_FIFO 90 (above the control
/// thread's 80 and the simulated controller's 81) that sleeps 1 ms at a time and records how
/// late it wakes. No thread of the daemon can delay it; what delays it is the host (the VM's
/// vCPUs paused, the kernel busy writing back a build). A fault in a run where the host itself
/// was unfit is the host's, not the daemon's: the `--check` gates judge a fault only on a host
/// that was fit ([`HostStalls::unfit`]).
#[allow(dead_code)]
pub struct HostWatch {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<[f64; 3]>,
}

/// What a [`HostWatch`] saw: its wake-up lateness p50 / p99 / max, µs.
#[allow(dead_code)]
#[derive(Clone, Copy, Debug)]
pub struct HostStalls(pub [f64; 3]);

#[allow(dead_code)]
impl HostWatch {
    /// Starts watching (SCHED_FIFO 90 when `fifo`).
    pub fn start(fifo: bool) -> Self {
        use std::sync::atomic::Ordering;
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            if fifo {
                let _ = pa10::daemon::realtime::set_fifo(90);
            }
            let mut h = pa10::daemon::timing::Histogram::default();
            let period = std::time::Duration::from_millis(1);
            while !s.load(Ordering::Relaxed) {
                let due = std::time::Instant::now() + period;
                std::thread::sleep(period);
                h.record(due.elapsed().as_secs_f64() * 1e6);
            }
            h.summary()
        });
        Self { stop, thread }
    }

    /// Stops watching.
    pub fn finish(self) -> HostStalls {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        HostStalls(self.thread.join().unwrap_or([f64::INFINITY; 3]))
    }
}

#[allow(dead_code)]
impl HostStalls {
    /// Whether the host itself was unfit for the loop (its p99 lateness above
    /// [`HOST_UNFIT_P99_MS`] or one stall above [`HOST_UNFIT_MAX_MS`]).
    pub fn unfit(&self) -> bool {
        self.0[1] > HOST_UNFIT_P99_MS * 1e3 || self.0[2] > HOST_UNFIT_MAX_MS * 1e3
    }

    /// `p99 / max` in µs, for a table.
    pub fn cell(&self) -> String {
        format!("{:.0} / {:.0}", self.0[1], self.0[2])
    }
}
