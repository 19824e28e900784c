//! One control cycle, sans IO: joint state in, speed commands out.
//!
//! `feedback → torque estimate → compensation → position loop → speed commands`, with the
//! safety checks of every cycle. [`Controller::step`] takes the time and the cycle's
//! feedback as arguments and never reads a clock or a socket, so the whole loop is tested
//! without either; the daemon's control thread only moves frames. No allocation per cycle.
//!
//! - **Torques** ([`estimate`]): `measured` (the motor currents × torque constants through a
//!   first-order low-pass: every load, and every bias of the currents — friction, the
//!   rotor's acceleration torque, a sticking drive's held torque); `model` (the model's
//!   gravity plus the configured payload at the link setpoint: noise-free, exact only when
//!   the model's bodies and the payload are right, which `pa10 identify` sees to);
//!   `blended` (`model` plus a correction learnt from the currents at rest, frozen in
//!   motion); `estimated` (`model` plus a correction learnt only from joints at constant
//!   speed with the identified friction removed, frozen at rest and accelerating).
//! - **Compensation**: the motor target that puts the *link* at the setpoint,
//!   `q_motor = q_link + δ(τ) + e(q_motor) + (b/2)·dir` ([`Model::compensate`]: springs,
//!   and the transmission error, eccentricity and backlash `pa10 discover` may add; `dir` is
//!   the direction each joint last moved in).
//! - **Position loop**: `speed = q̇_setpoint + K·(q_motor_target − q_motor_measured)`,
//!   clamped to the speed limits.
//! - **Safety**: stale feedback, following error beyond the limit, a joint outside its
//!   limits, or a controller fault → [`Fault`]; the loop then commands zero speed until
//!   `reset`.

use std::sync::Arc;

use super::plan::{Move, MoveError, Setpoint, Trajectory, TrajectoryPoint};
use super::vocab::Limits;

use crate::model::{ExternalLoad, Model, NO_DIRECTION, Torques};
use crate::record::Mode;

pub use super::vocab::JointState;
pub use estimate::{ESTIMATE_MAX_ACCEL, ESTIMATE_MIN_SPEED, EstimateInputs, TorqueEstimator};
pub use params::*;

mod cycle;
pub mod estimate;
mod glide;
pub mod hold;
mod params;
mod stream;

pub use glide::GLIDE_S;

/// Corner frequency of the motor speed estimate (resolver differences) the holding loop's
/// damping uses, Hz: one resolver count a cycle (7.7 µrad at 500 Hz, 3.8 mrad/s) is a
/// quarter of that after the filter.
pub const MOTOR_SPEED_HZ: f64 = 50.0;

/// The sans-IO controller.
#[derive(Debug, Clone)]
pub struct Controller {
    model: Arc<Model>,
    p: LoopParams,
    setpoint: Setpoint,
    activity: Activity,
    /// Step 3's state: the measured torques' filter or the learnt correction.
    estimator: TorqueEstimator,
    /// Direction each joint last moved in (−1, 0, +1): the side its backlash is taken up on.
    direction: [f64; 6],
    last_feedback_s: f64,
    /// Consecutive cycles without complete feedback.
    missed: u32,
    last_state: Option<JointState>,
    /// Motor speeds from the resolvers, low-passed at [`MOTOR_SPEED_HZ`], rad/s.
    motor_speed: [f64; 6],
    /// Speed scaling in force (ramping toward `scaling_target`), 0 < f ≤ 1.
    scaling: f64,
    scaling_target: f64,
    trajectory: TrajectoryStatus,
    /// Why the last stream ended, for `status`.
    stream_end: Option<&'static str>,
    /// What the last cycle computed (before the first: the motors where they are).
    out: CycleOutput,
    /// Step 4c: a newly loaded model's target reached smoothly.
    glide: glide::Glide,
    /// Step 5's holding band and in-position state (`hold.rs`).
    hold: hold::HoldBand,
}

/// What one cycle computed (for recordings): torques used, motor target, speeds sent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CycleOutput {
    /// Torque estimate, N·m.
    pub tau: [f64; 6],
    /// Motor target, rad.
    pub target: [f64; 6],
    /// Speed commands, rad/s.
    pub speeds: [f64; 6],
}

impl Controller {
    /// A controller holding the arm where `first` says it is. The position limits of
    /// `p.limits` are taken from `model` (the model file is their home).
    pub fn new(model: impl Into<Arc<Model>>, mut p: LoopParams, first: &JointState) -> Self {
        let model = model.into();
        p.limits.lower = model.limits().lower;
        p.limits.upper = model.limits().upper;
        let load = ExternalLoad::hung_at(p.payload_n, &model.gravity(), &p.payload_com);
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
            estimator: TorqueEstimator::default(),
            direction: [0.0; 6],
            last_feedback_s: first.stamp_s,
            missed: 0,
            last_state: Some(*first),
            motor_speed: [0.0; 6],
            scaling: 1.0,
            scaling_target: 1.0,
            trajectory: TrajectoryStatus::default(),
            stream_end: None,
            out: CycleOutput {
                target: first.q_motor,
                ..CycleOutput::default()
            },
            glide: glide::Glide::default(),
            hold: hold::HoldBand::default(),
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
            Activity::Holding => Ok(()),
            _ => Err(CommandError::Busy),
        }
    }

    /// Starts `mv` at `now_s`; refused while faulted or already moving.
    pub fn start_move(&mut self, mv: impl Into<Box<Move>>, now_s: f64) -> Result<(), CommandError> {
        match &self.activity {
            Activity::Faulted(f) => Err(CommandError::Faulted(f.clone())),
            Activity::Holding => {
                self.activity = Activity::Moving {
                    mv: mv.into(),
                    start_s: now_s,
                };
                Ok(())
            }
            _ => Err(CommandError::Busy),
        }
    }

    /// The loop parameters.
    pub fn params(&self) -> &LoopParams {
        &self.p
    }

    /// Position, speed and acceleration limits in force (the position limits are the
    /// model's).
    pub fn limits(&self) -> &Limits {
        &self.p.limits
    }

    /// Starts following `points` from the current setpoint (replacing a running trajectory,
    /// move or stream without a jump in position or velocity); the whole trajectory is
    /// checked first at the speed scaling in force. Returns its id.
    pub fn start_trajectory(
        &mut self,
        points: &[TrajectoryPoint],
        tol: Tolerances,
    ) -> Result<u64, CommandError> {
        match &self.activity {
            Activity::Faulted(f) => return Err(CommandError::Faulted(f.clone())),
            Activity::Stopping { .. } => return Err(CommandError::Busy),
            _ => {}
        }
        let scaling = self.scaling.max(self.scaling_target);
        let traj = Trajectory::plan(&self.setpoint, points, &self.p.limits, scaling)?;
        self.end_trajectory(TrajectoryState::Preempted, TrajectoryResult::Preempted);
        self.trajectory = TrajectoryStatus {
            id: self.trajectory.id + 1,
            state: TrajectoryState::Executing,
            result: TrajectoryResult::Running,
            desired: self.setpoint.q,
            actual: self.trajectory.actual,
            error: [0.0; 6],
            progress: 0.0,
        };
        self.activity = Activity::Following {
            traj: Box::new(traj),
            tau: 0.0,
            tol,
            ended_s: None,
        };
        Ok(self.trajectory.id)
    }

    /// The latest trajectory's state.
    pub fn trajectory(&self) -> &TrajectoryStatus {
        &self.trajectory
    }

    /// The speed scaling in force and the one asked for, 0 < f ≤ 1.
    pub fn speed_scaling(&self) -> (f64, f64) {
        (self.scaling, self.scaling_target)
    }

    /// Why the last servo or jog stream ended, if it did.
    pub fn stream_end(&self) -> Option<&'static str> {
        self.stream_end
    }

    /// Slows (or speeds up again) running and future trajectories: the scaling ramps to
    /// `fraction` over at most [`SCALING_RAMP_S`]. Refused if what remains of the running
    /// trajectory would exceed a limit at the faster scaling.
    pub fn set_speed_scaling(&mut self, fraction: f64) -> Result<(), CommandError> {
        if !(fraction.is_finite() && fraction > 0.0 && fraction <= 1.0) {
            return Err(CommandError::Scaling(fraction));
        }
        if let Activity::Following { traj, tau, .. } = &self.activity
            && fraction > self.scaling
        {
            traj.check_from(*tau, &self.p.limits, fraction)?;
        }
        self.scaling_target = fraction;
        Ok(())
    }

    /// Replaces the model between moves (hot reload); refused while moving, and when a
    /// configured speed limit exceeds the new model's joint velocity limit. Its position
    /// limits replace the old model's. The motors glide to the new model's target over
    /// [`GLIDE_S`] (`glide.rs`) instead of stepping there.
    pub fn load_model(&mut self, model: impl Into<Arc<Model>>) -> Result<(), CommandError> {
        if matches!(
            self.activity,
            Activity::Moving { .. } | Activity::Stopping { .. }
        ) {
            return Err(CommandError::ModelDuringMove);
        }
        let model = model.into();
        let ml = model.limits();
        if let Some(j) = (0..6).find(|&j| self.p.limits.speed[j] > ml.velocity[j]) {
            return Err(CommandError::Invalid(format!(
                "the model's joint {} velocity limit {} rad/s is below the configured speed limit {} rad/s",
                j + 1,
                ml.velocity[j],
                self.p.limits.speed[j]
            )));
        }
        self.p.limits.lower = ml.lower;
        self.p.limits.upper = ml.upper;
        self.model = model;
        self.glide.start();
        Ok(())
    }

    /// Sets the payload: its weight, N (0…500), and its centre of mass in the tool frame,
    /// m (within 1 m of the tool origin). Used by the compensation (model torques) at once.
    pub fn set_payload(&mut self, newtons: f64, com: [f64; 3]) -> Result<(), CommandError> {
        check_payload(newtons, &com)?;
        self.p.payload_n = newtons;
        self.p.payload_com = com;
        Ok(())
    }

    /// The payload as a load on the model.
    fn load(&self) -> ExternalLoad {
        ExternalLoad::hung_at(self.p.payload_n, &self.model.gravity(), &self.p.payload_com)
    }

    /// The payload's centre of mass in the tool frame, m.
    pub fn payload_com(&self) -> [f64; 3] {
        self.p.payload_com
    }

    /// Payload hung at the tool, N.
    pub fn payload_n(&self) -> f64 {
        self.p.payload_n
    }

    /// Takes `state` as the truth after the servo was restarted: hold where the arm is and
    /// clear any fault.
    pub fn resync(&mut self, state: &JointState) {
        self.last_state = Some(*state);
        self.motor_speed = [0.0; 6];
        self.last_feedback_s = state.stamp_s;
        self.missed = 0;
        self.activity = Activity::Faulted(Fault::Controller);
        self.reset();
    }

    /// Clears a fault: hold where the arm is now.
    pub fn reset(&mut self) {
        if let (Activity::Faulted(_), Some(s)) = (&self.activity, self.last_state) {
            let load = self.load();
            self.setpoint = Setpoint {
                q: self
                    .model
                    .link_from_motor(&s.q_motor, Torques::Gravity(&load), &self.direction)
                    .map(|c| c.q_link)
                    .unwrap_or(s.q_motor),
                qd: [0.0; 6],
            };
            self.activity = Activity::Holding;
            // from where the motors are to the compensation's target, without a step
            self.out.target = s.q_motor;
            self.glide.start();
        }
    }

    /// A controlled stop: the setpoint decelerates to rest within the acceleration limits,
    /// every joint reaching zero speed at the same instant. No effect unless moving.
    pub fn stop(&mut self) {
        self.end_trajectory(TrajectoryState::Aborted, TrajectoryResult::Stopped);
        if matches!(
            self.activity,
            Activity::Moving { .. } | Activity::Following { .. } | Activity::Streaming { .. }
        ) {
            let qd = self.setpoint.qd;
            let t = (0..6)
                .map(|j| qd[j].abs() / self.p.limits.acceleration[j])
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
        let state = match self.take_feedback(now_s, fb) {
            Ok(Some(state)) => state,
            Ok(None) => return [0.0; 6],
            Err(f) => return self.fault(f),
        };
        if let Err(f) = self.advance_setpoint(now_s) {
            return self.fault(f);
        }
        let tau = self.torque_estimate(&state);
        self.note_directions();
        let target = match self.compensated_target(&tau) {
            Ok(t) => self.glide.apply(&t, &self.out.target, self.p.period_s),
            Err(f) => return self.fault(f),
        };
        let (model, setpoint) = (&self.model, &self.setpoint.q);
        let mut jacobian = None;
        self.hold.update(
            self.p.period_s,
            matches!(self.activity, Activity::Holding),
            self.p.hold_deadband,
            &target,
            &state.q_motor,
            &self.motor_speed,
            |j| {
                let jac = jacobian.get_or_insert_with(|| model.jacobian(setpoint));
                jac.fixed_view::<3, 1>(0, j).norm()
            },
        );
        let (speeds, link) = match self.position_loop(&state, &target) {
            Ok(v) => v,
            Err(f) => return self.fault(f),
        };
        self.out = CycleOutput {
            tau,
            target,
            speeds,
        };
        self.track(&link, now_s);
        speeds
    }

    /// Whether the arm is in position: holding, every motor still and within its holding
    /// band of the compensated target ([`hold`]).
    pub fn in_position(&self) -> bool {
        self.hold.in_position()
    }

    /// What the last cycle computed.
    pub fn output(&self) -> &CycleOutput {
        &self.out
    }

    /// What the loop is doing, as the recording's one mode table has it.
    pub fn mode(&self) -> Mode {
        match self.activity {
            Activity::Holding => Mode::Holding,
            Activity::Moving { .. } => Mode::Moving,
            Activity::Following { .. } => Mode::Following,
            Activity::Streaming { .. } => Mode::Streaming,
            Activity::Stopping { .. } => Mode::Stopping,
            Activity::Faulted(_) => Mode::Faulted,
        }
    }

    /// The trajectory's bookkeeping after a cycle: desired vs the link estimate, the path
    /// tolerance while executing, the goal tolerance at the end.
    fn track(&mut self, actual: &[f64; 6], now_s: f64) {
        let t = &mut self.trajectory;
        t.actual = *actual;
        if t.state != TrajectoryState::Executing {
            return;
        }
        t.desired = self.setpoint.q;
        for j in 0..6 {
            t.error[j] = t.desired[j] - actual[j];
        }
        let Activity::Following { tol, ended_s, .. } = &self.activity else {
            return;
        };
        let beyond = |lim: &[f64; 6]| (0..6).any(|j| lim[j] > 0.0 && t.error[j].abs() > lim[j]);
        let (off_path, off_goal) = (beyond(&tol.path), beyond(&tol.goal));
        let late = ended_s.map(|end| now_s - end > tol.goal_time_s);
        match late {
            None if off_path => {
                self.stop();
                self.trajectory.state = TrajectoryState::Aborted;
                self.trajectory.result = TrajectoryResult::PathToleranceViolated;
            }
            None => {}
            Some(_) if !off_goal => {
                t.state = TrajectoryState::Succeeded;
                t.result = TrajectoryResult::Succeeded;
                self.activity = Activity::Holding;
            }
            Some(true) => {
                t.state = TrajectoryState::Aborted;
                t.result = TrajectoryResult::GoalToleranceViolated;
                self.activity = Activity::Holding;
            }
            Some(false) => {}
        }
    }

    /// Stops the arm for a fault found outside the cycle (the link, a client's emergency
    /// stop): zero speed until [`Controller::reset`]. An earlier fault is kept.
    pub fn halt(&mut self, f: Fault) {
        if !matches!(self.activity, Activity::Faulted(_)) {
            self.end_trajectory(TrajectoryState::Aborted, TrajectoryResult::Fault);
            self.activity = Activity::Faulted(f);
        }
    }

    fn fault(&mut self, f: Fault) -> [f64; 6] {
        self.end_trajectory(TrajectoryState::Aborted, TrajectoryResult::Fault);
        self.activity = Activity::Faulted(f);
        [0.0; 6]
    }
}
