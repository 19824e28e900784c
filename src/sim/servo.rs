//! The simulated PA10 servo controller: a sans-IO state machine and plant that speaks the
//! pa10 CAN protocol (`docs/protocol.md`), and a thin async task that runs it on any
//! [`CanBus`].
//!
//! [`ServoSim`] takes frames and the current time and returns frames; it never reads a
//! clock. The physics is a [`Plant`]: by default the in-process [`ModelPlant`] (a first-order
//! speed loop, the link at the motor angle minus the true spring deflection under the true
//! gravity and hung load of the [`TrueRobot`]), or any other, e.g. MuJoCo's
//! ([`super::mujoco::MujocoPlant`]). The controller's own parts stay here: the resolver reads
//! the plant's motor angle with the truth's repeatable error, noise and quantisation; motor
//! currents are the plant's motor torques over the torque constants, with noise. The command watchdog, brakes and faults behave as the protocol's state machine
//! says. [`ServoSim::observe_tool`] is the ground truth — the instrument — and is never
//! reachable over the bus.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::TrueRobot;
use super::plant::{Drive, ModelPlant, Plant};
use crate::can::bus::{BusError, BusEvent, CanBus};
use crate::can::protocol::{
    self, AxisCommand, CanFrame, ErrorCode, FaultCode, Feedback, Framing, Message, Request,
    ServoState, angle_counts, current_counts, mode, status,
};
use crate::model::Frame as Pose;

/// Simulated motor current → link torque constants, N·m/A (the real ones are not published).
pub const SIM_TORQUE_CONSTANTS: [f64; 6] = [15.0, 30.0, 15.0, 5.0, 5.0, 2.0];

/// Servo parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoConfig {
    /// Velocity-loop time constant, s.
    pub tau_s: f64,
    /// Speed limits, rad/s.
    pub speed_limit: [f64; 6],
    /// Current limits, A.
    pub current_limit_a: [f64; 6],
    /// Torque constants, N·m/A.
    pub torque_constants: [f64; 6],
    /// Resolver noise, counts (1σ), added before quantisation.
    pub resolver_noise_counts: f64,
    /// Current noise, A (1σ).
    pub current_noise_a: f64,
    /// Default command watchdog, s.
    pub watchdog_s: f64,
    /// STATE heartbeat period, s.
    pub heartbeat_s: f64,
    /// Deceleration of a controlled stop, rad/s².
    pub stop_decel: f64,
    /// The feedback's format: six FEEDBACK frames or one FEEDBACK_FD per SYNC. Commands are
    /// taken in either format.
    pub framing: Framing,
}

impl Default for ServoConfig {
    fn default() -> Self {
        Self {
            tau_s: 0.005,
            speed_limit: [
                1.0,
                1.0,
                2.0,
                std::f64::consts::TAU,
                std::f64::consts::TAU,
                std::f64::consts::TAU,
            ],
            current_limit_a: [30.0; 6],
            torque_constants: SIM_TORQUE_CONSTANTS,
            resolver_noise_counts: 0.5,
            current_noise_a: 0.005,
            watchdog_s: 0.05,
            heartbeat_s: 0.1,
            stop_decel: 2.0,
            framing: Framing::Classic,
        }
    }
}

impl ServoConfig {
    /// The default parameters, sending feedback in `framing`'s format.
    pub fn speaking(framing: Framing) -> Self {
        Self {
            framing,
            ..Self::default()
        }
    }
}

/// Faults to inject (from configuration or tests).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Injected {
    /// This axis (1…6) stops answering: no FEEDBACK frames.
    pub mute_axis: Option<u8>,
    /// Current-sensor offsets, A.
    pub current_offset_a: [f64; 6],
    /// One-shot resolver glitch: (axis 1…6, counts) added to the next FEEDBACK of that axis.
    pub resolver_glitch: Option<(u8, i32)>,
}

/// The simulated servo controller.
#[derive(Debug)]
pub struct ServoSim {
    truth: TrueRobot,
    cfg: ServoConfig,
    /// Fault injection.
    pub injected: Injected,
    state: ServoState,
    fault: FaultCode,
    stopping: bool,
    /// When a controlled stop closes the brakes even if a motor still creeps, s.
    stop_deadline_s: f64,
    now: f64,
    plant: Box<dyn Plant>,
    target: [f64; 6],
    pending: [Option<AxisCommand>; 6],
    applied_cycle: u16,
    last_command_s: f64,
    watchdog_s: f64,
    last_heartbeat_s: f64,
    deadman: bool,
    rng: Pcg64,
}

/// Motor speed below which a controlled stop is complete and the brakes close, rad/s: a
/// drive's standstill threshold. A plant with dynamics (a rotor on a ringing spring, MuJoCo's)
/// never reaches exactly zero; 1 mrad/s for the last few ms of a stop moves a motor by µrad.
const STOPPED_SPEED: f64 = 1e-3;

fn gauss(rng: &mut Pcg64) -> f64 {
    StandardNormal.sample(rng)
}

impl ServoSim {
    /// A controller for `truth` whose motors start at angles `q0` (rad), at time 0, STOPPED;
    /// the physics the in-process [`ModelPlant`] of the truth model.
    pub fn new(truth: TrueRobot, cfg: ServoConfig, q0: [f64; 6], seed: u64) -> Self {
        let plant = ModelPlant::new(truth.model.clone(), cfg.tau_s, q0);
        Self::with_plant(truth, cfg, Box::new(plant), seed)
    }

    /// A controller for `truth`'s sensors and instrument driving `plant` (its motors where the
    /// plant has them), at time 0, STOPPED.
    pub fn with_plant(
        truth: TrueRobot,
        cfg: ServoConfig,
        plant: Box<dyn Plant>,
        seed: u64,
    ) -> Self {
        let watchdog_s = cfg.watchdog_s;
        Self {
            truth,
            cfg,
            injected: Injected::default(),
            state: ServoState::Stopped,
            fault: FaultCode::None,
            stopping: false,
            stop_deadline_s: 0.0,
            now: 0.0,
            plant,
            target: [0.0; 6],
            pending: [None; 6],
            applied_cycle: 0,
            last_command_s: 0.0,
            watchdog_s,
            last_heartbeat_s: 0.0,
            deadman: false,
            rng: Pcg64::seed_from_u64(seed),
        }
    }

    /// Current state.
    pub fn state(&self) -> ServoState {
        self.state
    }
    /// Current fault.
    pub fn fault(&self) -> FaultCode {
        self.fault
    }
    /// True motor angles, rad.
    pub fn motor_angles(&self) -> [f64; 6] {
        self.plant.motor_angles()
    }
    /// Hangs `newtons` at the tool (the weight rack).
    pub fn set_load(&mut self, newtons: f64) {
        self.plant.set_load(newtons.max(0.0));
    }
    /// The physics.
    pub fn plant(&self) -> &dyn Plant {
        self.plant.as_ref()
    }
    /// The hidden truth.
    pub fn truth(&self) -> &TrueRobot {
        &self.truth
    }

    /// True link angles and the torques the motor currents carry (rad, N·m), from the plant.
    pub fn link_state(&self) -> ([f64; 6], [f64; 6]) {
        self.plant.link_state()
    }

    /// **Ground truth** (the instrument): the tool's pose in the instrument frame, with the
    /// instrument's noise. Never reachable over the bus.
    pub fn observe_tool(&mut self) -> Pose {
        let pose = self.plant.tool_pose();
        self.truth.observe_pose(&pose, &mut self.rng)
    }

    /// The exact tool pose in the robot base frame (for end-to-end checks).
    pub fn true_tool_pose(&self) -> Pose {
        self.plant.tool_pose()
    }

    fn enter_fault(
        &mut self,
        fault: FaultCode,
        code: ErrorCode,
        axis: u8,
        detail: i32,
        out: &mut Vec<CanFrame>,
    ) {
        self.state = ServoState::Fault;
        self.fault = fault;
        self.target = [0.0; 6];
        self.stopping = false;
        self.push(Message::Error { code, axis, detail }, out);
        self.push_state(out);
    }

    /// A controlled stop: the speeds ramp down at `stop_decel`; the brakes close when the
    /// motors are still or, at the latest, 0.5 s after the ramp from the fastest motor's speed
    /// would have ended (a plant that rings or hunts at rest never reaches exact standstill).
    fn begin_stop(&mut self) {
        if !self.stopping {
            let fastest = self
                .plant
                .motor_speeds()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            self.stop_deadline_s = self.now + fastest / self.cfg.stop_decel + 0.5;
        }
        self.stopping = true;
    }

    fn push(&self, m: Message, out: &mut Vec<CanFrame>) {
        if let Ok(f) = protocol::encode(&m) {
            out.push(f);
        }
    }

    fn push_state(&self, out: &mut Vec<CanFrame>) {
        self.push(
            Message::State {
                state: self.state,
                fault: self.fault,
                cycle: self.applied_cycle,
            },
            out,
        );
    }

    /// Advances the plant to `now` (s) and runs the watchdog and heartbeat.
    pub fn tick(&mut self, now: f64, out: &mut Vec<CanFrame>) {
        if now <= self.now {
            return;
        }
        let servo = matches!(self.state, ServoState::BrakeRelease | ServoState::Control);
        let drive = Drive {
            speed: if self.stopping || !servo {
                [0.0; 6]
            } else {
                self.target
            },
            engaged: servo,
            stop_decel: self.stopping.then_some(self.cfg.stop_decel),
            speed_limit: self.cfg.speed_limit,
        };
        let mut t = self.now;
        while t < now {
            let dt = (now - t).min(1e-3);
            self.plant.advance(dt, &drive);
            t += dt;
        }
        self.now = now;
        let still = self
            .plant
            .motor_speeds()
            .iter()
            .all(|v| v.abs() < STOPPED_SPEED);
        if self.stopping && (still || now >= self.stop_deadline_s) {
            self.stopping = false;
            self.state = ServoState::Stopped;
            self.target = [0.0; 6];
            self.push_state(out);
        }
        let motor = self.plant.motor_angles();
        let lim = self.truth.model.limits();
        if servo
            && let Some(j) = (0..6).find(|&j| motor[j] < lim.lower[j] || motor[j] > lim.upper[j])
        {
            let detail = angle_counts(motor[j]).unwrap_or(0);
            self.enter_fault(FaultCode::Limit, ErrorCode::Limit, j as u8 + 1, detail, out);
        }
        if self.state == ServoState::Control
            && !self.stopping
            && now - self.last_command_s > self.watchdog_s
        {
            let ms = ((now - self.last_command_s) * 1e3) as i32;
            self.enter_fault(FaultCode::Watchdog, ErrorCode::Watchdog, 0, ms, out);
        }
        if now - self.last_heartbeat_s >= self.cfg.heartbeat_s {
            self.last_heartbeat_s = now;
            self.push_state(out);
        }
    }

    /// Handles one received frame at time `now` (s); frames to send go to `out`.
    pub fn handle(&mut self, now: f64, frame: &CanFrame, out: &mut Vec<CanFrame>) {
        self.tick(now, out);
        let Ok(msg) = protocol::decode(frame) else {
            return;
        };
        match msg {
            Message::Control {
                request,
                watchdog_ms,
            } => {
                if watchdog_ms > 0 {
                    self.watchdog_s = watchdog_ms as f64 * 1e-3;
                }
                self.request(request, out)
            }
            Message::Sync { cycle } => self.feedback(cycle, out),
            Message::Command(c) => self.command(c, out),
            Message::CommandFd(cmds) if self.state == ServoState::Control && !self.stopping => {
                self.pending = [None; 6];
                self.apply(cmds, out);
            }
            _ => {}
        }
    }

    fn request(&mut self, r: Request, out: &mut Vec<CanFrame>) {
        use ServoState::{BrakeRelease, Control, Stopped};
        let ok = match (r, self.state) {
            (Request::ReleaseBrakes, Stopped) => {
                self.state = BrakeRelease;
                self.target = [0.0; 6];
                true
            }
            (Request::StartControl, BrakeRelease) => {
                self.state = Control;
                self.last_command_s = self.now;
                self.pending = [None; 6];
                true
            }
            (Request::Stop, BrakeRelease | Control) => {
                self.begin_stop();
                true
            }
            (Request::Estop, _) => {
                self.state = Stopped;
                self.stopping = false;
                self.target = [0.0; 6];
                true
            }
            (Request::ResetFault, ServoState::Fault) => {
                self.state = Stopped;
                self.fault = FaultCode::None;
                true
            }
            _ => false,
        };
        if ok {
            if self.fault == FaultCode::Rejected {
                self.fault = FaultCode::None;
            }
            self.push_state(out);
        } else {
            let prev = self.fault;
            self.fault = FaultCode::Rejected;
            self.push(
                Message::Error {
                    code: ErrorCode::Rejected,
                    axis: 0,
                    detail: r as i32,
                },
                out,
            );
            self.push_state(out);
            if prev != FaultCode::None {
                self.fault = prev;
            }
        }
    }

    fn command(&mut self, c: AxisCommand, out: &mut Vec<CanFrame>) {
        if self.state != ServoState::Control || self.stopping {
            return;
        }
        self.pending[c.axis as usize - 1] = Some(c);
        let cycle = c.cycle;
        if self
            .pending
            .iter()
            .all(|p| p.is_some_and(|p| p.cycle == cycle))
        {
            let cmds: [AxisCommand; 6] = std::array::from_fn(|j| self.pending[j].unwrap_or(c));
            self.pending = [None; 6];
            self.apply(cmds, out);
        }
    }

    /// A complete command set of one cycle (six COMMAND frames, or one COMMAND_FD).
    fn apply(&mut self, cmds: [AxisCommand; 6], out: &mut Vec<CanFrame>) {
        let cycle = cmds[0].cycle;
        self.last_command_s = self.now;
        self.applied_cycle = (self.applied_cycle & 0xFF00) | cycle as u16;
        self.deadman = cmds.iter().any(|c| c.mode & mode::DEADMAN != 0);
        if cmds.iter().any(|c| c.mode & mode::TORQUE != 0) {
            self.push(
                Message::Error {
                    code: ErrorCode::Rejected,
                    axis: 0,
                    detail: 0,
                },
                out,
            );
            self.begin_stop();
            return;
        }
        if cmds
            .iter()
            .any(|c| c.mode & mode::SERVO == 0 || c.mode & mode::BRAKE != 0)
        {
            self.begin_stop();
            return;
        }
        for (j, c) in cmds.iter().enumerate() {
            self.target[j] = c.speed_rad_s();
        }
    }

    fn feedback(&mut self, cycle: u16, out: &mut Vec<CanFrame>) {
        // a partial command set of an earlier cycle is discarded
        self.pending = [None; 6];
        self.applied_cycle = (cycle & 0xFF00) | (self.applied_cycle & 0xFF);
        let (_, tau) = self.plant.link_state();
        let motor = self.plant.motor_angles();
        let servo_on = matches!(self.state, ServoState::BrakeRelease | ServoState::Control);
        let mut st = if servo_on {
            status::SERVO_ON
        } else {
            status::BRAKE_ON
        };
        if self.state == ServoState::Fault {
            st |= status::FAULT;
            if self.fault == FaultCode::Watchdog {
                st |= status::WATCHDOG;
            }
            if self.fault == FaultCode::Limit {
                st |= status::LIMIT;
            }
        }
        if self.deadman {
            st |= status::DEADMAN;
        }
        let mut set = [None; 6];
        for (j, slot) in set.iter_mut().enumerate() {
            let axis = j as u8 + 1;
            if self.injected.mute_axis == Some(axis) {
                continue;
            }
            let reading = self.truth.resolver_reading(j, motor[j]);
            let mut counts = angle_counts(reading).unwrap_or(0);
            counts = counts.saturating_add(
                (self.cfg.resolver_noise_counts * gauss(&mut self.rng)).round() as i32,
            );
            if let Some((a, glitch)) = self.injected.resolver_glitch
                && a == axis
            {
                counts = counts.saturating_add(glitch);
                self.injected.resolver_glitch = None;
            }
            let current = (tau[j] / self.cfg.torque_constants[j]
                + self.injected.current_offset_a[j]
                + self.cfg.current_noise_a * gauss(&mut self.rng))
            .clamp(-self.cfg.current_limit_a[j], self.cfg.current_limit_a[j]);
            *slot = Some(Feedback {
                axis,
                angle: counts,
                current: current_counts(current),
                status: st,
                cycle: cycle as u8,
            });
        }
        match self.cfg.framing {
            Framing::Classic => {
                for fb in set.into_iter().flatten() {
                    self.push(Message::Feedback(fb), out);
                }
            }
            // one frame for all six axes: an axis that does not answer withholds it
            Framing::Fd => {
                if let [Some(a), Some(b), Some(c), Some(d), Some(e), Some(f)] = set {
                    self.push(Message::FeedbackFd([a, b, c, d, e, f]), out);
                }
            }
        }
    }
}

/// A running simulated controller shared between its bus task and the ground-truth handle.
pub type SharedServo = Arc<Mutex<ServoSim>>;

/// Runs `sim` on `bus` until `stop` resolves: frames in → [`ServoSim::handle`], frames out →
/// the bus; the plant ticks at least every `tick`. Time is tokio's clock (pausable in tests).
/// Each frame sent or received is passed to `log` with its time (s).
pub async fn run<B: CanBus>(
    mut bus: B,
    sim: SharedServo,
    tick: Duration,
    mut stop: tokio::sync::watch::Receiver<bool>,
    mut log: impl FnMut(f64, &CanFrame) + Send,
) -> Result<(), BusError> {
    let t0 = tokio::time::Instant::now();
    let mut out = Vec::with_capacity(16);
    loop {
        if *stop.borrow() {
            return Ok(());
        }
        let ev = tokio::select! {
            ev = bus.recv(tick) => ev,
            _ = stop.changed() => return Ok(()),
        };
        let now = t0.elapsed().as_secs_f64();
        {
            let mut s = sim.lock().unwrap_or_else(|p| p.into_inner());
            match ev {
                Ok(BusEvent::Frame(f)) => {
                    log(now, &f);
                    s.handle(now, &f, &mut out);
                }
                // Bus-off silences the host: the command watchdog then stops the arm, as on
                // the real controller.
                Ok(BusEvent::BusOff | BusEvent::ErrorFrame { .. }) | Err(BusError::Timeout) => {
                    s.tick(now, &mut out)
                }
                Err(e) => return Err(e),
            }
        }
        for f in out.drain(..) {
            log(now, &f);
            match bus.send(f).await {
                Ok(()) | Err(BusError::BusOff) => {}
                Err(e) => return Err(e),
            }
        }
    }
}
