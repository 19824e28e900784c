//! One control cycle, sans IO: joint state in, speed commands out.
//!
//! `feedback → torque estimate → compensation → position loop → speed commands`, with the
//! safety checks of every cycle. [`Controller::step`] takes the time and the cycle's
//! feedback as arguments and never reads a clock or a socket, so the whole loop is tested
//! without either; the daemon's control thread only moves frames. No allocation per cycle.
//!
//! - **Torques**: [`TorqueSource::Measured`] (the default) uses the motor currents × torque
//!   constants through a first-order low-pass: it sees every load, tooling and unknown
//!   payloads included, which matters because calibration identifies the springs from
//!   measured torques but never the masses; [`TorqueSource::Model`] uses the model's gravity
//!   plus the configured payload at the link setpoint (noise-free, exact only when the
//!   model's bodies and the payload are right).
//! - **Compensation**: the motor target that puts the *link* at the setpoint,
//!   `q_motor = q_link + δ(τ) + e(q_motor) + (b/2)·dir` ([`Model::compensate`]: springs,
//!   and the transmission error, eccentricity and backlash `pa10 discover` may add; `dir` is
//!   the direction each joint last moved in).
//! - **Position loop**: `speed = q̇_setpoint + K·(q_motor_target − q_motor_measured)`,
//!   clamped to the speed limits.
//! - **Safety**: stale feedback, following error beyond the limit, a joint outside its
//!   limits, or a controller fault → [`Fault`]; the loop then commands zero speed until
//!   `reset`.

use super::config::TorqueSource;
use super::motion::{Move, MoveError, Setpoint};
use std::sync::Arc;

use super::link::LinkError;
use crate::model::{ExternalLoad, Model, NO_DIRECTION, Torques};

/// The joint state of one cycle, as decoded from the six FEEDBACK frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    /// Resolver (motor-side) angles, rad.
    pub q_motor: [f64; 6],
    /// Motor currents, A.
    pub current: [f64; 6],
    /// When it was sampled (the SYNC time), s.
    pub stamp_s: f64,
    /// The controller reported a fault on some axis.
    pub controller_fault: bool,
}

/// Why the loop stopped the arm.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Fault {
    /// No complete feedback in as many consecutive cycles as the timeout spans. Cycles the
    /// loop itself did not run (the host paused it) do not count: only the controller's
    /// silence while the loop was listening does.
    #[error(
        "stale feedback: none in {missed_cycles} consecutive cycles ({listened_ms:.1} ms of listening, limit {limit_ms:.1} ms; the last is {age_ms:.1} ms old)"
    )]
    StaleFeedback {
        /// Consecutive cycles without complete feedback.
        missed_cycles: u32,
        /// Those cycles' length, ms.
        listened_ms: f64,
        /// Age of the last feedback, ms (includes any pause of the host).
        age_ms: f64,
        /// Timeout, ms.
        limit_ms: f64,
    },
    /// The motor lags its target by more than the limit.
    #[error("following error on joint {joint}: {error:.4} rad (limit {limit:.4} rad)")]
    FollowingError {
        /// 1…6.
        joint: usize,
        /// |target − measured|, rad.
        error: f64,
        /// Limit, rad.
        limit: f64,
    },
    /// A joint left its limits.
    #[error("joint {joint} at {value:.4} rad is outside its limits")]
    JointLimit {
        /// 1…6.
        joint: usize,
        /// Link angle estimate, rad.
        value: f64,
    },
    /// The servo controller reported a fault.
    #[error("the servo controller reports a fault")]
    Controller,
    /// A setpoint could not be computed (the model refused the path mid-move).
    #[error("setpoint: {0}")]
    Setpoint(MoveError),
    /// The servo link failed (bus, silent controller, refused request).
    #[error("servo link: {0}")]
    Link(LinkError),
    /// A client asked for an emergency stop.
    #[error("emergency stop requested by a client")]
    EmergencyStop,
}

/// Why a command was refused; a refused command changes nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandError {
    /// The daemon is faulted.
    #[error("faulted ({0}); send reset first")]
    Faulted(Fault),
    /// A move or a controlled stop is in progress.
    #[error("a move is in progress; stop it first")]
    Busy,
    /// The servo controller is not (yet, or again) in control mode.
    #[error("not ready: {0}")]
    NotReady(String),
    /// The move was planned from a setpoint or model that has changed since.
    #[error("the setpoint or the model changed while the move was planned; send it again")]
    Stale,
    /// The move cannot be planned.
    #[error("{0}")]
    Plan(#[from] MoveError),
    /// A payload outside 0…500 N.
    #[error("payload must be within 0…500 N, got {0}")]
    Payload(f64),
    /// The model cannot change during a move.
    #[error("cannot change the model during a move")]
    ModelDuringMove,
    /// A model file that does not load.
    #[error("model: {0}")]
    Model(String),
    /// The daemon is shutting down.
    #[error("shutting down")]
    ShuttingDown,
}

/// What the loop is doing.
#[derive(Debug, Clone, PartialEq)]
pub enum Activity {
    /// Holding the last setpoint.
    Holding,
    /// Following a move that started at `start_s`.
    Moving {
        /// The move (boxed: planned once per move, not per cycle).
        mv: Box<Move>,
        /// Start time, s.
        start_s: f64,
    },
    /// Decelerating to rest (a controlled stop), all joints together.
    Stopping {
        /// Per-joint deceleration, rad/s².
        decel: [f64; 6],
    },
    /// Stopped by a fault; zero speed until reset.
    Faulted(Fault),
}

/// Loop parameters (from the daemon configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct LoopParams {
    /// Cycle period, s.
    pub period_s: f64,
    /// Position gain, 1/s.
    pub gain: f64,
    /// Torque source.
    pub torque_source: TorqueSource,
    /// Low-pass cut-off for measured torques, Hz.
    pub filter_hz: f64,
    /// Torque constants, N·m/A.
    pub torque_constants: [f64; 6],
    /// Payload hung at the tool, N.
    pub payload_n: f64,
    /// Speed limits, rad/s.
    pub speed: [f64; 6],
    /// Acceleration limits (controlled stops), rad/s².
    pub acceleration: [f64; 6],
    /// Following-error limit, rad.
    pub following_error: f64,
    /// Feedback timeout, s.
    pub feedback_timeout_s: f64,
}

/// The sans-IO controller.
#[derive(Debug, Clone)]
pub struct Controller {
    model: Arc<Model>,
    p: LoopParams,
    setpoint: Setpoint,
    activity: Activity,
    tau_filtered: [f64; 6],
    /// Direction each joint last moved in (−1, 0, +1): the side its backlash is taken up on.
    direction: [f64; 6],
    last_feedback_s: f64,
    /// Consecutive cycles without complete feedback.
    missed: u32,
    last_state: Option<JointState>,
}

impl Controller {
    /// A controller holding the arm where `first` says it is.
    pub fn new(model: impl Into<Arc<Model>>, p: LoopParams, first: &JointState) -> Self {
        let model = model.into();
        let load = ExternalLoad::hung(p.payload_n, &model.gravity());
        let q_link = model
            .link_from_motor(&first.q_motor, Torques::Gravity(&load), &NO_DIRECTION)
            .map(|c| c.q_link)
            .unwrap_or(first.q_motor);
        Self {
            model,
            p,
            setpoint: Setpoint {
                q: q_link,
                qd: [0.0; 6],
            },
            activity: Activity::Holding,
            tau_filtered: [0.0; 6],
            direction: [0.0; 6],
            last_feedback_s: first.stamp_s,
            missed: 0,
            last_state: Some(*first),
        }
    }

    /// What the loop is doing.
    pub fn activity(&self) -> &Activity {
        &self.activity
    }
    /// The current link-side setpoint.
    pub fn setpoint(&self) -> &Setpoint {
        &self.setpoint
    }
    /// The model in use.
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// The model in use, shared (planning takes it outside the control lock).
    pub fn model_arc(&self) -> &Arc<Model> {
        &self.model
    }

    /// Whether a new move may start now: holding, not faulted.
    pub fn ready_for_move(&self) -> Result<(), CommandError> {
        match &self.activity {
            Activity::Faulted(f) => Err(CommandError::Faulted(f.clone())),
            Activity::Moving { .. } | Activity::Stopping { .. } => Err(CommandError::Busy),
            Activity::Holding => Ok(()),
        }
    }

    /// Starts `mv` at `now_s`; refused while faulted or already moving.
    pub fn start_move(&mut self, mv: impl Into<Box<Move>>, now_s: f64) -> Result<(), CommandError> {
        match &self.activity {
            Activity::Faulted(f) => Err(CommandError::Faulted(f.clone())),
            Activity::Moving { .. } | Activity::Stopping { .. } => Err(CommandError::Busy),
            Activity::Holding => {
                self.activity = Activity::Moving {
                    mv: mv.into(),
                    start_s: now_s,
                };
                Ok(())
            }
        }
    }

    /// Replaces the model between moves (hot reload); refused while moving.
    pub fn load_model(&mut self, model: impl Into<Arc<Model>>) -> Result<(), CommandError> {
        if matches!(
            self.activity,
            Activity::Moving { .. } | Activity::Stopping { .. }
        ) {
            return Err(CommandError::ModelDuringMove);
        }
        self.model = model.into();
        Ok(())
    }

    /// Sets the payload hung at the tool, N.
    pub fn set_payload(&mut self, newtons: f64) -> Result<(), CommandError> {
        if !(newtons.is_finite() && (0.0..=500.0).contains(&newtons)) {
            return Err(CommandError::Payload(newtons));
        }
        self.p.payload_n = newtons;
        Ok(())
    }

    /// Move limits in use: speed (rad/s) and acceleration (rad/s²).
    pub fn limits(&self) -> ([f64; 6], [f64; 6]) {
        (self.p.speed, self.p.acceleration)
    }

    /// Payload hung at the tool, N.
    pub fn payload_n(&self) -> f64 {
        self.p.payload_n
    }

    /// Takes `state` as the truth after the servo was restarted: hold where the arm is and
    /// clear any fault.
    pub fn resync(&mut self, state: &JointState) {
        self.last_state = Some(*state);
        self.last_feedback_s = state.stamp_s;
        self.missed = 0;
        self.activity = Activity::Faulted(Fault::Controller);
        self.reset();
    }

    /// Clears a fault: hold where the arm is now.
    pub fn reset(&mut self) {
        if let (Activity::Faulted(_), Some(s)) = (&self.activity, self.last_state) {
            let load = ExternalLoad::hung(self.p.payload_n, &self.model.gravity());
            self.setpoint = Setpoint {
                q: self
                    .model
                    .link_from_motor(&s.q_motor, Torques::Gravity(&load), &self.direction)
                    .map(|c| c.q_link)
                    .unwrap_or(s.q_motor),
                qd: [0.0; 6],
            };
            self.activity = Activity::Holding;
        }
    }

    /// A controlled stop: the setpoint decelerates to rest within the acceleration limits,
    /// every joint reaching zero speed at the same instant. No effect unless moving.
    pub fn stop(&mut self) {
        if matches!(self.activity, Activity::Moving { .. }) {
            let qd = self.setpoint.qd;
            let t = (0..6)
                .map(|j| qd[j].abs() / self.p.acceleration[j])
                .fold(0.0, f64::max);
            if t <= 0.0 {
                self.activity = Activity::Holding;
                return;
            }
            self.activity = Activity::Stopping {
                decel: std::array::from_fn(|j| qd[j].abs() / t),
            };
        }
    }

    /// One cycle at `now_s`: `fb` is this cycle's complete feedback, `None` when it did not
    /// arrive. Returns the six speed commands (rad/s); zero when faulted.
    pub fn step(&mut self, now_s: f64, fb: Option<&JointState>) -> [f64; 6] {
        match fb {
            Some(f) => {
                self.last_feedback_s = f.stamp_s;
                self.last_state = Some(*f);
                self.missed = 0;
            }
            None => self.missed = self.missed.saturating_add(1),
        }
        if matches!(self.activity, Activity::Faulted(_)) {
            return [0.0; 6];
        }
        // the controller's silence is judged in cycles the loop ran and listened through: a
        // host pause of the loop itself is not evidence against the controller (its own
        // watchdog, `limits.controller_watchdog_ms`, judges the loop)
        let listened = f64::from(self.missed) * self.p.period_s;
        if listened > self.p.feedback_timeout_s + 1e-9 {
            return self.fault(Fault::StaleFeedback {
                missed_cycles: self.missed,
                listened_ms: listened * 1e3,
                age_ms: (now_s - self.last_feedback_s) * 1e3,
                limit_ms: self.p.feedback_timeout_s * 1e3,
            });
        }
        let Some(state) = self.last_state else {
            return [0.0; 6];
        };
        if state.controller_fault {
            return self.fault(Fault::Controller);
        }
        // setpoint
        if let Activity::Moving { mv, start_s } = &self.activity {
            let t = now_s - start_s;
            match mv.sample(&self.model, t, &self.setpoint.q) {
                Ok(sp) => self.setpoint = sp,
                Err(e) => return self.fault(Fault::Setpoint(e)),
            }
            if t >= mv.duration() {
                self.setpoint.qd = [0.0; 6];
                self.activity = Activity::Holding;
            }
        }
        if let Activity::Stopping { decel } = self.activity {
            let dt = self.p.period_s;
            let mut moving = false;
            for j in 0..6 {
                let v = self.setpoint.qd[j];
                let nv = if v > 0.0 {
                    (v - decel[j] * dt).max(0.0)
                } else {
                    (v + decel[j] * dt).min(0.0)
                };
                self.setpoint.q[j] += 0.5 * (v + nv) * dt;
                self.setpoint.qd[j] = nv;
                moving |= nv != 0.0;
            }
            if !moving {
                self.activity = Activity::Holding;
            }
        }
        // torques
        let load = ExternalLoad::hung(self.p.payload_n, &self.model.gravity());
        let tau = match self.p.torque_source {
            TorqueSource::Model => self.model.static_torques(&self.setpoint.q, &load),
            TorqueSource::Measured => {
                let alpha =
                    1.0 - (-std::f64::consts::TAU * self.p.filter_hz * self.p.period_s).exp();
                for j in 0..6 {
                    let m = state.current[j] * self.p.torque_constants[j];
                    self.tau_filtered[j] += alpha * (m - self.tau_filtered[j]);
                }
                self.tau_filtered
            }
        };
        for (d, v) in self.direction.iter_mut().zip(&self.setpoint.qd) {
            if *v != 0.0 {
                *d = v.signum();
            }
        }
        let target =
            match self
                .model
                .compensate(&self.setpoint.q, Torques::Given(&tau), &self.direction)
            {
                Ok(c) => c.q_motor,
                Err(_) => {
                    return self.fault(Fault::Setpoint(MoveError::NonFinite("compensated target")));
                }
            };
        let lim = self.model.limits();
        let mut out = [0.0; 6];
        for j in 0..6 {
            let e = target[j] - state.q_motor[j];
            if e.abs() > self.p.following_error {
                return self.fault(Fault::FollowingError {
                    joint: j + 1,
                    error: e.abs(),
                    limit: self.p.following_error,
                });
            }
            let link = state.q_motor[j] - (target[j] - self.setpoint.q[j]);
            if link < lim.lower[j] - 1e-3 || link > lim.upper[j] + 1e-3 {
                return self.fault(Fault::JointLimit {
                    joint: j + 1,
                    value: link,
                });
            }
            out[j] =
                (self.setpoint.qd[j] + self.p.gain * e).clamp(-self.p.speed[j], self.p.speed[j]);
        }
        out
    }

    /// Stops the arm for a fault found outside the cycle (the link, a client's emergency
    /// stop): zero speed until [`Controller::reset`]. An earlier fault is kept.
    pub fn halt(&mut self, f: Fault) {
        if !matches!(self.activity, Activity::Faulted(_)) {
            self.activity = Activity::Faulted(f);
        }
    }

    fn fault(&mut self, f: Fault) -> [f64; 6] {
        self.activity = Activity::Faulted(f);
        [0.0; 6]
    }
}
