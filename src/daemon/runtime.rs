//! The daemon's moving parts: the control thread (absolute-deadline cycle on its own thread,
//! the bus driven through a private current-thread runtime), the shared state the client API
//! reads and writes, cycle statistics, and the in-process simulated backend.
//!
//! The control thread owns the bus; the API never touches it. Requests reach the loop through
//! the [`Shared`] state under a mutex held for microseconds on either side.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use serde::Serialize;

use super::config::{Backend, Loaded};
use super::control::{Activity, Controller, JointState, LoopParams};
use super::link::{CycleAssembler, LinkCounters, command_frames};
use crate::can::bus::{BusError, BusEvent, CanBus};
use crate::can::protocol::{self, Message, Request, ServoState};
use crate::can::{VirtualBus, VirtualConfig};
use crate::model::Model;
use crate::sim::servo::{self, ServoConfig, ServoSim, SharedServo};
use crate::sim::{SimNoise, TrueRobot};

/// Why the daemon could not start or stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DaemonError {
    /// The bus could not be opened or failed.
    #[error("bus: {0}")]
    Bus(#[from] BusError),
    /// The servo controller did not reach control mode.
    #[error("servo controller: {0}")]
    Controller(String),
    /// Something else at start-up.
    #[error("{0}")]
    Startup(String),
}

/// Histogram of durations in microseconds (fixed buckets, no allocation per sample).
#[derive(Debug, Clone)]
pub struct Histogram {
    buckets: [u64; 1000],
    overflow: u64,
    max_us: f64,
    n: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            buckets: [0; 1000],
            overflow: 0,
            max_us: 0.0,
            n: 0,
        }
    }
}

impl Histogram {
    /// Buckets of 10 µs up to 10 ms.
    const W: f64 = 10.0;
    /// Records `us` microseconds.
    pub fn record(&mut self, us: f64) {
        let i = (us.max(0.0) / Self::W) as usize;
        match self.buckets.get_mut(i) {
            Some(b) => *b += 1,
            None => self.overflow += 1,
        }
        self.max_us = self.max_us.max(us);
        self.n += 1;
    }
    /// The `p` quantile (0…1), µs, to the bucket's upper edge.
    pub fn quantile(&self, p: f64) -> f64 {
        let k = (p * self.n as f64).ceil() as u64;
        let mut c = 0;
        for (i, b) in self.buckets.iter().enumerate() {
            c += b;
            if c >= k.max(1) {
                return (i as f64 + 1.0) * Self::W;
            }
        }
        self.max_us
    }
}

/// Cycle statistics for `status`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct CycleStats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles that started later than one period after their deadline.
    pub overruns: u64,
    /// Wake-up lateness, p50 / p99 / max, µs.
    pub jitter_us: [f64; 3],
    /// Compute time of a cycle (receive → commands sent), p50 / p99 / max, µs.
    pub compute_us: [f64; 3],
    /// Worst-case bus load of the configured rate, %.
    pub bus_load_pct: f64,
}

/// What `status` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Status {
    /// starting, holding, moving, stopping, fault.
    pub state: String,
    /// The fault, when there is one.
    pub fault: Option<String>,
    /// The servo controller's last reported state.
    pub servo: Option<String>,
    /// Link-side setpoint, rad.
    pub setpoint: [f64; 6],
    /// Resolver angles, rad.
    pub q_motor: [f64; 6],
    /// Motor currents, A (the last cycle's).
    pub current: [f64; 6],
    /// Tool position of the setpoint, m (base frame).
    pub tool_position: [f64; 3],
    /// Tool orientation of the setpoint, quaternion w, x, y, z.
    pub tool_quaternion: [f64; 4],
    /// Payload, N.
    pub payload_n: f64,
    /// Link counters.
    pub link: LinkCounters,
    /// Cycle statistics.
    pub cycle: CycleStats,
}

/// State shared between the control thread and the API.
pub struct Shared {
    /// The controller (None until the servo reached control mode).
    pub ctl: Option<Controller>,
    /// A start-up or link fault outside the controller.
    pub fault: Option<String>,
    /// The servo controller's last state.
    pub servo: Option<ServoState>,
    /// Last joint state.
    pub last: Option<JointState>,
    /// Link counters.
    pub link: LinkCounters,
    /// Statistics.
    pub stats: CycleStats,
    /// ESTOP requested by a client, to be sent by the control thread.
    pub estop: bool,
    /// Re-run the start-up handshake (after a reset).
    pub restart: bool,
    /// Seconds since the daemon started (the loop's clock).
    pub now_s: f64,
    /// Cycle rate, Hz.
    pub rate_hz: f64,
}

impl Shared {
    /// The status snapshot.
    pub fn status(&self) -> Status {
        let (state, fault, setpoint, tool, payload) = match &self.ctl {
            None => (
                "starting".to_string(),
                self.fault.clone(),
                [0.0; 6],
                None,
                0.0,
            ),
            Some(c) => {
                let (s, f) = match c.activity() {
                    Activity::Holding => ("holding", None),
                    Activity::Moving { .. } => ("moving", None),
                    Activity::Stopping { .. } => ("stopping", None),
                    Activity::Faulted(f) => ("fault", Some(f.to_string())),
                };
                let f = f.or_else(|| self.fault.clone());
                let state = if f.is_some() { "fault" } else { s };
                (
                    state.to_string(),
                    f,
                    c.setpoint().q,
                    Some(c.model().fk(&c.setpoint().q)),
                    c.payload_n(),
                )
            }
        };
        let (p, q) = tool
            .map(|t| crate::model::pose_parts(&t))
            .unwrap_or(([0.0; 3], [1.0, 0.0, 0.0, 0.0]));
        Status {
            state,
            fault,
            servo: self.servo.map(|s| format!("{s:?}")),
            setpoint,
            q_motor: self.last.map(|s| s.q_motor).unwrap_or([0.0; 6]),
            current: self.last.map(|s| s.current).unwrap_or([0.0; 6]),
            tool_position: p,
            tool_quaternion: q,
            payload_n: payload,
            link: self.link,
            cycle: self.stats,
        }
    }
}

/// Locks, recovering from a poisoned mutex (a panicked holder must not stop the arm's
/// supervision).
pub fn lock(m: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A running daemon core.
pub struct Daemon {
    /// Shared state (the API's handle).
    pub shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// The simulated controller (virtual backend only): ground truth for tests and demos.
    pub sim: Option<SharedServo>,
    /// The virtual bus (virtual backend only): for fault injection.
    pub bus: Option<VirtualBus>,
    sim_stop: Option<tokio::sync::watch::Sender<bool>>,
    _sim_rt: Option<tokio::runtime::Runtime>,
}

impl Daemon {
    /// Starts the control thread on the configured backend and waits until the servo
    /// controller is in control mode (or fails).
    pub fn start(loaded: &Loaded) -> Result<Self, DaemonError> {
        let c = &loaded.config;
        let params = LoopParams {
            period_s: 1.0 / c.control.rate_hz,
            gain: c.control.position_gain,
            torque_source: c.control.torque_source,
            filter_hz: c.control.current_filter_hz,
            torque_constants: c.torque_constants,
            payload_n: c.payload_n,
            speed: c.limits.speed,
            acceleration: c.limits.acceleration,
            following_error: c.limits.following_error,
            feedback_timeout_s: c.limits.feedback_timeout_ms * 1e-3,
        };
        let shared = Arc::new(Mutex::new(Shared {
            ctl: None,
            fault: None,
            servo: None,
            last: None,
            link: LinkCounters::default(),
            stats: CycleStats {
                bus_load_pct: loaded.bus_load * 100.0,
                ..Default::default()
            },
            estop: false,
            restart: false,
            now_s: 0.0,
            rate_hz: c.control.rate_hz,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let model = loaded.model.clone();
        let prio = c.control.realtime.sched_fifo_priority;
        if c.control.realtime.mlockall {
            match super::realtime::lock_memory() {
                Ok(()) => tracing::info!("memory locked (mlockall)"),
                Err(e) => tracing::warn!(error = %e, "mlockall not permitted; memory may page"),
            }
        }
        let (thread, sim, vbus, sim_stop, sim_rt) = match c.bus.backend {
            Backend::Virtual => {
                let bus = VirtualBus::new(VirtualConfig::default());
                let sim_cfg = c.sim.clone().unwrap_or_default();
                let noise = SimNoise::default();
                let tool = crate::model::frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0]);
                let truth = match &sim_cfg.truth {
                    Some(p) => {
                        let base = loaded
                            .model_path
                            .parent()
                            .unwrap_or(std::path::Path::new("."));
                        let m = Model::load(base.join(p))
                            .map_err(|e| DaemonError::Startup(format!("sim.truth: {e}")))?;
                        TrueRobot::from_model(m, noise, sim_cfg.seed)
                    }
                    None => TrueRobot::draw(sim_cfg.seed, &Model::nominal(), &tool, noise)
                        .map_err(|e| DaemonError::Startup(e.to_string()))?,
                };
                let home = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
                let servo_sim = Arc::new(Mutex::new(ServoSim::new(
                    truth,
                    ServoConfig::default(),
                    home,
                    sim_cfg.seed,
                )));
                let rt = tokio::runtime::Builder::new_multi_thread()
                    .worker_threads(1)
                    .enable_all()
                    .build()
                    .map_err(|e| DaemonError::Startup(format!("simulator runtime: {e}")))?;
                let (tx, rx) = tokio::sync::watch::channel(false);
                rt.spawn(servo::run(
                    bus.endpoint(false),
                    servo_sim.clone(),
                    Duration::from_millis(1),
                    rx,
                    |_, _| {},
                ));
                let ep = bus.endpoint(false);
                let th = spawn_control(
                    move || Ok(ep),
                    model,
                    params,
                    shared.clone(),
                    stop.clone(),
                    ready_tx,
                    c.limits.feedback_timeout_ms,
                    prio,
                )?;
                (th, Some(servo_sim), Some(bus), Some(tx), Some(rt))
            }
            Backend::Socketcan => {
                #[cfg(target_os = "linux")]
                {
                    let iface = c.bus.interface.clone().unwrap_or_default();
                    let th = spawn_control(
                        move || crate::can::socketcan_bus::SocketCanBus::open(&iface),
                        model,
                        params,
                        shared.clone(),
                        stop.clone(),
                        ready_tx,
                        c.limits.feedback_timeout_ms,
                        prio,
                    )?;
                    (th, None, None, None, None)
                }
                #[cfg(not(target_os = "linux"))]
                return Err(DaemonError::Startup("SocketCAN needs Linux".into()));
            }
        };
        let mut d = Daemon {
            shared,
            stop,
            thread: Some(thread),
            sim,
            bus: vbus,
            sim_stop,
            _sim_rt: sim_rt,
        };
        match ready_rx.recv_timeout(Duration::from_secs(5)) {
            Ok(Ok(())) => Ok(d),
            Ok(Err(e)) => {
                d.shutdown();
                Err(DaemonError::Controller(e))
            }
            Err(_) => {
                d.shutdown();
                Err(DaemonError::Controller("no answer within 5 s".into()))
            }
        }
    }

    /// Brings the arm to rest, stops the servo (brakes on) and joins the control thread.
    pub fn shutdown(&mut self) {
        if let Some(c) = lock(&self.shared).ctl.as_mut() {
            c.stop();
        }
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Some(tx) = self.sim_stop.take() {
            let _ = tx.send(true);
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.shutdown();
    }
}

#[allow(clippy::too_many_arguments)]
fn spawn_control<B: CanBus + 'static, F: FnOnce() -> Result<B, BusError> + Send + 'static>(
    open_bus: F,
    model: Model,
    params: LoopParams,
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
    watchdog_ms: f64,
    rt_priority: Option<u8>,
) -> Result<std::thread::JoinHandle<()>, DaemonError> {
    std::thread::Builder::new()
        .name("pa10d-control".into())
        .spawn(move || {
            control_loop(
                open_bus,
                model,
                params,
                shared,
                stop,
                ready,
                watchdog_ms,
                rt_priority,
            )
        })
        .map_err(|e| DaemonError::Startup(format!("control thread: {e}")))
}

/// Sends `r` and waits, up to `timeout`, for a STATE that shows the request took effect
/// (heartbeats showing the old state are skipped; a REJECTED answer is an error).
fn request<B: CanBus>(
    rt: &tokio::runtime::Runtime,
    bus: &mut B,
    r: Request,
    watchdog_ms: u8,
    timeout: Duration,
) -> Result<ServoState, String> {
    let expected = match r {
        Request::ReleaseBrakes => ServoState::BrakeRelease,
        Request::StartControl => ServoState::Control,
        Request::Stop | Request::Estop | Request::ResetFault => ServoState::Stopped,
    };
    let f = protocol::encode(&Message::Control {
        request: r,
        watchdog_ms,
    })
    .map_err(|e| e.to_string())?;
    rt.block_on(bus.send(f)).map_err(|e| e.to_string())?;
    let end = Instant::now() + timeout;
    let mut last = None;
    while Instant::now() < end {
        match rt.block_on(bus.recv(end.saturating_duration_since(Instant::now()))) {
            Ok(BusEvent::Frame(f)) => match protocol::decode(&f) {
                Ok(Message::State { state, .. }) if state == expected => return Ok(state),
                Ok(Message::Error {
                    code: protocol::ErrorCode::Rejected,
                    ..
                }) => {
                    return Err(format!("{r:?} refused by the controller (state {last:?})"));
                }
                Ok(Message::State { state, .. }) => last = Some(state),
                _ => {}
            },
            Ok(BusEvent::BusOff) => return Err("bus off".into()),
            Ok(BusEvent::ErrorFrame { .. }) | Err(BusError::Timeout) => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    Err(format!(
        "no STATE {expected:?} after {r:?} (last seen {last:?})"
    ))
}

/// RELEASE_BRAKES, START_CONTROL; returns the first complete feedback.
fn handshake<B: CanBus>(
    rt: &tokio::runtime::Runtime,
    bus: &mut B,
    watchdog_ms: u8,
    asm: &mut CycleAssembler,
    t0: Instant,
) -> Result<JointState, String> {
    // First hear the controller (its STATE heartbeat): a request sent before it listens is
    // lost, as on any CAN bus.
    let end = Instant::now() + Duration::from_secs(3);
    loop {
        if Instant::now() >= end {
            return Err("the controller is silent (no STATE heartbeat within 3 s)".into());
        }
        if let Ok(BusEvent::Frame(f)) =
            rt.block_on(bus.recv(end.saturating_duration_since(Instant::now())))
            && let Ok(Message::State { .. }) = protocol::decode(&f)
        {
            break;
        }
    }
    let wait = Duration::from_millis(500);
    request(rt, bus, Request::ReleaseBrakes, watchdog_ms, wait)?;
    request(rt, bus, Request::StartControl, watchdog_ms, wait)?;
    for cycle in 1..=20u16 {
        let sync = asm.begin(cycle, t0.elapsed().as_secs_f64());
        rt.block_on(bus.send(sync)).map_err(|e| e.to_string())?;
        let end = Instant::now() + Duration::from_millis(5);
        while !asm.complete() && Instant::now() < end {
            if let Ok(BusEvent::Frame(f)) =
                rt.block_on(bus.recv(end.saturating_duration_since(Instant::now())))
            {
                asm.accept(&f);
            }
        }
        if let Some(js) = asm.finish() {
            // answer with zero speed so the controller's watchdog stays fed
            for f in command_frames(cycle, &[0.0; 6]) {
                rt.block_on(bus.send(f)).map_err(|e| e.to_string())?;
            }
            return Ok(js);
        }
    }
    Err("no complete feedback after START_CONTROL".into())
}

#[allow(clippy::too_many_arguments)]
fn control_loop<B: CanBus, F: FnOnce() -> Result<B, BusError>>(
    open_bus: F,
    model: Model,
    params: LoopParams,
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
    watchdog_ms: f64,
    rt_priority: Option<u8>,
) {
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            let _ = ready.send(Err(format!("control runtime: {e}")));
            return;
        }
    };
    // The bus is opened here, inside this thread's runtime: a SocketCAN socket registers with
    // the reactor of the runtime it is created in, and this runtime drives it.
    let mut bus = {
        let _guard = rt.enter();
        match open_bus() {
            Ok(b) => b,
            Err(e) => {
                lock(&shared).fault = Some(e.to_string());
                let _ = ready.send(Err(format!("opening the bus: {e}")));
                return;
            }
        }
    };
    if let Some(prio) = rt_priority {
        match super::realtime::set_fifo(prio) {
            Ok(()) => tracing::info!(priority = prio, "control thread runs SCHED_FIFO"),
            Err(e) => {
                tracing::warn!(priority = prio, error = %e, "SCHED_FIFO not permitted; running at normal priority")
            }
        }
    }
    let t0 = Instant::now();
    let period = Duration::from_secs_f64(params.period_s);
    let wd = (watchdog_ms.round() as u8).max(1);
    let mut asm = CycleAssembler::default();
    let first = match handshake(&rt, &mut bus, wd, &mut asm, t0) {
        Ok(js) => js,
        Err(e) => {
            lock(&shared).fault = Some(e.clone());
            let _ = ready.send(Err(e));
            return;
        }
    };
    {
        let mut s = lock(&shared);
        s.ctl = Some(Controller::new(model, params.clone(), &first));
        s.servo = Some(ServoState::Control);
        s.last = Some(first);
    }
    let _ = ready.send(Ok(()));
    let (mut jitter, mut compute) = (Histogram::default(), Histogram::default());
    let mut cycle: u16 = 20;
    let mut deadline = Instant::now() + period;
    let mut stop_sent = false;
    let mut last_warning = Instant::now();
    let mut fault_logged = false;
    let mut stopping_for_exit = false;
    loop {
        let now = Instant::now();
        if now < deadline {
            std::thread::sleep(deadline - now);
        }
        let woke = Instant::now();
        let late = woke.saturating_duration_since(deadline);
        jitter.record(late.as_secs_f64() * 1e6);
        let overrun = late > period;
        deadline += period;
        if overrun {
            deadline = woke + period; // do not try to catch up a burst of missed cycles
        }
        cycle = cycle.wrapping_add(1);
        let now_s = t0.elapsed().as_secs_f64();
        let sync = asm.begin(cycle, now_s);
        let mut bus_fault = None;
        if let Err(e) = rt.block_on(bus.send(sync)) {
            bus_fault = Some(e.to_string());
        }
        let recv_end = woke + period.mul_f64(0.6);
        while bus_fault.is_none() && !asm.complete() {
            let left = recv_end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            match rt.block_on(bus.recv(left)) {
                Ok(BusEvent::Frame(f)) => {
                    asm.accept(&f);
                }
                Ok(BusEvent::BusOff) => bus_fault = Some("bus off".into()),
                Ok(BusEvent::ErrorFrame { .. }) => asm.counters.malformed += 1,
                Err(BusError::Timeout) => break,
                Err(e) => bus_fault = Some(e.to_string()),
            }
        }
        let js = asm.finish();
        let exiting = stop.load(Ordering::SeqCst);
        let (speeds, estop, faulted, restart, still) = {
            let mut s = lock(&shared);
            s.now_s = now_s;
            s.link = asm.counters;
            if let Some(st) = asm.servo_state.take() {
                s.servo = Some(st);
            }
            if let Some(j) = js {
                s.last = Some(j);
            }
            if let Some(f) = bus_fault.take() {
                s.fault = Some(f);
            }
            if exiting && !stopping_for_exit {
                stopping_for_exit = true;
                if let Some(c) = s.ctl.as_mut() {
                    c.stop();
                }
            }
            let estop = std::mem::take(&mut s.estop);
            let restart = std::mem::take(&mut s.restart);
            let link_fault = s.fault.is_some();
            let (speeds, faulted, still) = match s.ctl.as_mut() {
                Some(c) => {
                    let sp = c.step(now_s, js.as_ref());
                    let f = matches!(c.activity(), Activity::Faulted(_)) || link_fault;
                    let still = matches!(c.activity(), Activity::Holding | Activity::Faulted(_));
                    (if f { [0.0; 6] } else { sp }, f, still)
                }
                None => ([0.0; 6], true, true),
            };
            (speeds, estop, faulted, restart, still)
        };
        if estop {
            let r = request(&rt, &mut bus, Request::Estop, 0, Duration::from_millis(20));
            let mut s = lock(&shared);
            s.fault = Some("emergency stop requested by a client".into());
            if let Ok(st) = r {
                s.servo = Some(st);
            }
            stop_sent = true;
        } else if faulted && !stop_sent {
            // a controlled stop of the servo; the brakes follow
            if let Ok(st) = request(&rt, &mut bus, Request::Stop, 0, Duration::from_millis(20)) {
                lock(&shared).servo = Some(st);
            }
            stop_sent = true;
        } else if !faulted {
            for f in command_frames(cycle, &speeds) {
                if let Err(e) = rt.block_on(bus.send(f)) {
                    lock(&shared).fault = Some(e.to_string());
                    break;
                }
            }
        }
        if restart {
            // after a reset: bring the controller back to control mode
            if lock(&shared).servo == Some(ServoState::Fault) {
                let _ = request(
                    &rt,
                    &mut bus,
                    Request::ResetFault,
                    0,
                    Duration::from_millis(20),
                );
            }
            match handshake(&rt, &mut bus, wd, &mut asm, t0) {
                Ok(js) => {
                    let mut s = lock(&shared);
                    s.fault = None;
                    s.servo = Some(ServoState::Control);
                    s.last = Some(js);
                    if let Some(c) = s.ctl.as_mut() {
                        c.resync(&js);
                    }
                    stop_sent = false;
                }
                Err(e) => lock(&shared).fault = Some(format!("restart: {e}")),
            }
            deadline = Instant::now() + period;
        }
        if overrun && woke.duration_since(last_warning) > Duration::from_secs(1) {
            // rate-limited: at most one warning a second from the loop
            last_warning = woke;
            tracing::warn!(late_us = late.as_micros() as u64, "control cycle overrun");
        }
        if faulted && !fault_logged {
            fault_logged = true;
            tracing::error!(status = ?lock(&shared).status().fault, "fault: the arm is stopped until reset");
        }
        if !faulted {
            fault_logged = false;
        }
        compute.record(woke.elapsed().as_secs_f64() * 1e6);
        {
            let mut s = lock(&shared);
            s.stats.cycles += 1;
            s.stats.overruns += overrun as u64;
            s.stats.jitter_us = [jitter.quantile(0.5), jitter.quantile(0.99), jitter.max_us];
            s.stats.compute_us = [
                compute.quantile(0.5),
                compute.quantile(0.99),
                compute.max_us,
            ];
        }
        if exiting && (still || faulted) {
            let _ = request(&rt, &mut bus, Request::Stop, 0, Duration::from_millis(50));
            return;
        }
    }
}
