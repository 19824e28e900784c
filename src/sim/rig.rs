//! The simulated PA10 wired to the daemon, two ways:
//!
//! - [`SimulatedArm`]: the simulated servo controller on a [`VirtualBus`], running in real
//!   time on its own runtime; `pa10d` (virtual backend), the demo and the real-time examples
//!   hand its [`SimulatedArm::host`] endpoint to [`Daemon::start`](crate::daemon::runtime::Daemon::start).
//! - [`Lockstep`]: the daemon's sans-IO [`Core`] and the sans-IO [`ServoSim`] exchanging
//!   frames in *simulated* time, one thread, deterministic: the daemon tests run through it
//!   in parallel and in a fraction of real time.
//!
//! Both draw the hidden true robot the same way ([`truth_from_config`]); the daemon never
//! reads it.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::mujoco::{MujocoError, MujocoOptions, MujocoPlant};
use super::plant::{ModelPlant, Plant, PlantKind};
use super::servo::{self, ServoConfig, ServoSim, SharedServo};
use super::{SimNoise, TrueRobot};
use crate::can::protocol::CanFrame;
use crate::can::{VirtualBus, VirtualConfig, VirtualEndpoint};
use crate::daemon::config::{Settings, SimConfig};
use crate::daemon::core::Core;
use crate::daemon::runtime::lock;
use crate::daemon::wire::{ApiRequest, Reply};
use crate::model::{Model, ModelError, frame_from_pose};
use serde::Deserialize as _;

/// Where the simulated arm's motors start, rad.
pub const HOME: [f64; 6] = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];

/// The tool of a drawn truth: a 0.35 m tooling-ball holder along the flange axis.
pub fn default_tool() -> crate::model::Frame {
    frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0])
}

/// Why the simulated arm could not be built.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RigError {
    /// The `sim.truth` model file.
    #[error("sim.truth: {0}")]
    Truth(#[from] ModelError),
    /// The simulator's runtime.
    #[error("simulator runtime: {0}")]
    Runtime(#[from] std::io::Error),
    /// The `sim.plant` process (`kind: mujoco`).
    #[error("sim.plant: {0} (MuJoCo's plant needs `pip install mujoco`)")]
    Plant(#[from] MujocoError),
}

/// The hidden true robot of a validated `sim` section ([`Settings::sim`]): the `truth` model
/// file (its path resolved by validation) or one drawn from `seed` around the nominal model
/// with [`default_tool`].
pub fn truth_from_config(sim: &SimConfig) -> Result<TrueRobot, RigError> {
    let noise = SimNoise::default();
    Ok(match &sim.truth {
        Some(p) => TrueRobot::from_model(Model::load(p)?, noise, sim.seed),
        None => TrueRobot::draw(sim.seed, &Model::nominal(), &default_tool(), noise)?,
    })
}

/// The truth and seed validated daemon settings ask for (their `sim` section, its truth file
/// resolved, or the defaults).
pub fn truth_for(settings: &Settings) -> Result<(TrueRobot, u64), RigError> {
    let sim = settings.sim.clone().unwrap_or_default();
    Ok((truth_from_config(&sim)?, sim.seed))
}

/// The physics a validated `sim` section asks for (`sim.plant`), for `truth`'s arm with its
/// motors at rest at `q0` (rad): the in-process [`ModelPlant`] of the truth model, or the
/// plant process (MuJoCo's by default) with the truth's tool point.
pub fn plant_from_config(
    sim: &SimConfig,
    truth: &TrueRobot,
    cfg: &ServoConfig,
    q0: [f64; 6],
) -> Result<Box<dyn Plant>, RigError> {
    Ok(match sim.plant.kind {
        PlantKind::Model => Box::new(ModelPlant::new(truth.model.clone(), cfg.tau_s, q0)),
        PlantKind::Mujoco => {
            let t = truth.model.tool().translation.vector;
            let opts = MujocoOptions::from_config(&sim.plant, sim.seed, [t.x, t.y, t.z], q0);
            Box::new(MujocoPlant::start(&opts)?)
        }
    })
}

/// The simulated servo controller validated daemon settings describe (their `sim` section:
/// truth, seed, plant), its motors at [`HOME`], speaking the bus's framing.
pub fn servo_for(settings: &Settings) -> Result<ServoSim, RigError> {
    let sim = settings.sim.clone().unwrap_or_default();
    let truth = truth_from_config(&sim)?;
    let cfg = ServoConfig::speaking(settings.bus.timing().framing);
    let plant = plant_from_config(&sim, &truth, &cfg, HOME)?;
    Ok(ServoSim::with_plant(truth, cfg, plant, sim.seed))
}

/// The simulated controller running in real time on a virtual bus.
pub struct SimulatedArm {
    servo: SharedServo,
    bus: VirtualBus,
    stop: tokio::sync::watch::Sender<bool>,
    _rt: tokio::runtime::Runtime,
}

impl SimulatedArm {
    /// Starts the controller of `truth` at [`HOME`] (noise seeded by `seed`), ticking every
    /// millisecond.
    pub fn start(truth: TrueRobot, seed: u64) -> Result<Self, RigError> {
        Self::start_with_priority(truth, seed, None)
    }

    /// [`SimulatedArm::start`], its thread under SCHED_FIFO at `priority` when given and
    /// permitted (a real controller is its own hardware: a loaded host must not slow it).
    pub fn start_with_priority(
        truth: TrueRobot,
        seed: u64,
        priority: Option<u8>,
    ) -> Result<Self, RigError> {
        Self::start_on(truth, seed, priority, crate::can::BusTiming::classic(1e6))
    }

    /// [`SimulatedArm::start_with_priority`] on a virtual bus of `timing` (classic or CAN FD;
    /// the controller speaks its framing).
    pub fn start_on(
        truth: TrueRobot,
        seed: u64,
        priority: Option<u8>,
        timing: crate::can::BusTiming,
    ) -> Result<Self, RigError> {
        let cfg = ServoConfig::speaking(timing.framing);
        Self::start_servo(ServoSim::new(truth, cfg, HOME, seed), priority, timing)
    }

    /// `servo` running in real time on a virtual bus of `timing`, its thread under
    /// SCHED_FIFO at `priority` when given and permitted.
    pub fn start_servo(
        servo: ServoSim,
        priority: Option<u8>,
        timing: crate::can::BusTiming,
    ) -> Result<Self, RigError> {
        let bus = VirtualBus::new(VirtualConfig {
            timing,
            ..VirtualConfig::default()
        });
        let servo = Arc::new(Mutex::new(servo));
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("pa10-sim")
            .on_thread_start(move || {
                #[cfg(target_os = "linux")]
                if let Some(p) = priority
                    && let Err(e) = crate::daemon::realtime::set_fifo(p)
                {
                    tracing::warn!(priority = p, error = %e, "simulator thread: SCHED_FIFO not permitted");
                }
            })
            .enable_all()
            .build()?;
        let (stop, rx) = tokio::sync::watch::channel(false);
        rt.spawn(servo::run(
            bus.endpoint(false),
            servo.clone(),
            Duration::from_millis(1),
            rx,
            |_, _| {},
        ));
        Ok(Self {
            servo,
            bus,
            stop,
            _rt: rt,
        })
    }

    /// The arm validated daemon settings describe (their `sim` section: truth, seed, plant).
    pub fn from_config(settings: &Settings) -> Result<Self, RigError> {
        Self::start_servo(servo_for(settings)?, None, settings.bus.timing())
    }

    /// A new endpoint on the arm's bus, for the host (the daemon).
    pub fn host(&self) -> VirtualEndpoint {
        self.bus.endpoint(false)
    }

    /// The bus's traffic so far (frames, exact bits, wire time).
    pub fn bus_stats(&self) -> crate::can::virtual_bus::BusStats {
        self.bus.stats()
    }

    /// The simulated controller: ground truth and fault injection.
    pub fn servo(&self) -> &SharedServo {
        &self.servo
    }

    /// The virtual bus: more endpoints, statistics, bus-off.
    pub fn bus(&self) -> &VirtualBus {
        &self.bus
    }
}

impl Drop for SimulatedArm {
    fn drop(&mut self) {
        let _ = self.stop.send(true);
    }
}

/// The daemon core and the simulated controller in simulated time (see the module
/// documentation). Frames take [`Lockstep::LATENCY_S`] each way; the plant ticks every
/// millisecond; the core is woken exactly at its deadlines.
pub struct Lockstep {
    /// The daemon core, behind the same mutex the API handler takes.
    pub core: Arc<crate::daemon::runtime::SharedCore>,
    /// The simulated controller (ground truth, fault injection).
    pub servo: ServoSim,
    now: f64,
    next_tick: f64,
    to_servo: VecDeque<(f64, CanFrame)>,
    to_host: VecDeque<(f64, CanFrame)>,
    out: Vec<CanFrame>,
    wire: Option<Wire>,
}

/// When a frame sent at `now` (s) arrives at the other side, s: after [`Lockstep::LATENCY_S`],
/// or through the modelled `wire`.
fn arrival(wire: &mut Option<Wire>, now: f64, f: &CanFrame) -> f64 {
    match wire {
        None => now + Lockstep::LATENCY_S,
        Some(w) => {
            let t = w.timing.frame_time_s(f);
            let end = now.max(w.free_at) + t;
            w.free_at = end;
            w.busy_s += t;
            end + w.latency_s
        }
    }
}

/// The shared wire of a [`Lockstep`] run with wire timing ([`Lockstep::with_wire`]): frames
/// are sent one after another, each taking its exact time at the bus's bit rates, and reach
/// the other side `latency_s` after their end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wire {
    /// Framing and bit rates.
    pub timing: crate::can::BusTiming,
    /// From a frame's last bit to the receiver acting on it (interrupt, driver, code), s.
    pub latency_s: f64,
    /// When the wire is next free, s.
    free_at: f64,
    /// Time it was busy, s.
    busy_s: f64,
}

impl Lockstep {
    /// One-way latency of a frame, s.
    pub const LATENCY_S: f64 = 100e-6;
    /// Plant tick, s.
    pub const TICK_S: f64 = 1e-3;

    /// Starts `core`'s session with `servo` at simulated time 0.
    pub fn new(mut core: Core, servo: ServoSim) -> Self {
        core.start(0.0);
        Self {
            core: crate::daemon::runtime::share(core),
            servo,
            now: 0.0,
            next_tick: 0.0,
            to_servo: VecDeque::new(),
            to_host: VecDeque::new(),
            out: Vec::with_capacity(16),
            wire: None,
        }
    }

    /// Models the bus: every frame waits for the wire, takes its exact time on it at
    /// `timing`'s rates (classic, or FD's two phases) and arrives `latency_s` after its last
    /// bit, instead of a fixed [`Lockstep::LATENCY_S`].
    pub fn with_wire(mut self, timing: crate::can::BusTiming, latency_s: f64) -> Self {
        self.wire = Some(Wire {
            timing,
            latency_s,
            free_at: 0.0,
            busy_s: 0.0,
        });
        self
    }

    /// The share of the simulated time the modelled wire was busy (0…1), `None` without
    /// [`Lockstep::with_wire`].
    pub fn wire_load(&self) -> Option<f64> {
        self.wire
            .map(|w| w.busy_s / self.now.max(f64::MIN_POSITIVE))
    }

    /// The daemon validated settings describe with the simulated arm of their `sim` section
    /// at [`HOME`].
    pub fn from_config(settings: &Settings) -> Result<Self, RigError> {
        Ok(Self::new(Core::from_config(settings), servo_for(settings)?))
    }

    /// Simulated time, s.
    pub fn now(&self) -> f64 {
        self.now
    }

    /// Delivers `frame` to the daemon now, as a rogue node on the bus would.
    pub fn inject(&mut self, frame: CanFrame) {
        self.to_host.push_back((self.now, frame));
    }

    /// Runs for `seconds` of simulated time.
    pub fn run_for(&mut self, seconds: f64) {
        let end = self.now + seconds;
        self.run_until(end);
    }

    /// Runs until `pred` holds (checked every simulated millisecond) or `timeout_s` passed;
    /// whether it held.
    pub fn run_while_not(&mut self, timeout_s: f64, mut pred: impl FnMut(&Self) -> bool) -> bool {
        let end = self.now + timeout_s;
        while self.now < end {
            if pred(self) {
                return true;
            }
            self.run_until((self.now + 1e-3).min(end));
        }
        pred(self)
    }

    /// Runs until the servo controller is in control mode (the daemon ready for moves), at
    /// most `timeout_s` of simulated time; the start-up failure otherwise.
    pub fn run_until_ready(&mut self, timeout_s: f64) -> Result<(), String> {
        self.run_while_not(timeout_s, |l| {
            let c = lock(&l.core);
            c.is_ready() || c.startup_failure().is_some()
        });
        let c = lock(&self.core);
        match (c.is_ready(), c.startup_failure()) {
            (true, _) => Ok(()),
            (false, Some(e)) => Err(e.to_string()),
            (false, None) => Err(format!("not in control mode within {timeout_s} s")),
        }
    }

    /// Runs until simulated time `end` (s).
    pub fn run_until(&mut self, end: f64) {
        loop {
            let t_core = lock(&self.core).poll_timeout().unwrap_or(f64::INFINITY);
            let t_host = self.to_host.front().map_or(f64::INFINITY, |f| f.0);
            let t_servo = self.to_servo.front().map_or(f64::INFINITY, |f| f.0);
            let t = t_core.min(t_host).min(t_servo).min(self.next_tick);
            if t > end {
                self.now = end;
                return;
            }
            self.now = self.now.max(t);
            let now = self.now;
            if t_host <= t {
                if let Some((_, f)) = self.to_host.pop_front() {
                    lock(&self.core).handle_frame(&f, now);
                }
            } else if t_servo <= t {
                if let Some((_, f)) = self.to_servo.pop_front() {
                    self.servo.handle(now, &f, &mut self.out);
                }
            } else if self.next_tick <= t {
                self.servo.tick(now, &mut self.out);
                self.next_tick += Self::TICK_S;
            } else {
                lock(&self.core).handle_timeout(now);
            }
            for f in self.out.drain(..) {
                self.to_host
                    .push_back((arrival(&mut self.wire, now, &f), f));
            }
            let mut core = lock(&self.core);
            while let Some(f) = core.poll_transmit() {
                self.to_servo
                    .push_back((arrival(&mut self.wire, now, &f), f));
            }
        }
    }

    /// One API request, answered by the daemon's request handler.
    pub fn call(&self, request: ApiRequest) -> Reply {
        crate::daemon::api::handle(&self.core, request)
    }

    /// One API request in its wire form (a JSON value), answered in the reply's wire form:
    /// what a client of the socket sends and reads, for tests that check the JSON itself. A
    /// value that is not a request is answered with the socket's `bad request` refusal.
    pub fn call_json(&self, request: &serde_json::Value) -> serde_json::Value {
        let reply = match ApiRequest::deserialize(request) {
            Ok(r) => self.call(r),
            Err(e) => Reply::Refused(format!("bad request: {e}")),
        };
        serde_json::to_value(reply).unwrap_or_default()
    }
}

/// The rig as a client sees the daemon: requests answered by the core, pauses run the
/// simulation (`pa10 identify --simulate`, the judges).
impl crate::daemon::api::sweep::Session for Lockstep {
    fn send(&mut self, req: ApiRequest) -> Result<Reply, String> {
        Ok(self.call(req))
    }
    fn pause(&mut self, seconds: f64) {
        self.run_for(seconds);
    }
    fn clock_s(&self) -> f64 {
        self.now()
    }
}
