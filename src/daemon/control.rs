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

use super::motion::{Move, MoveError, Setpoint};
use super::trajectory::{JointLimits, Trajectory, TrajectoryError, TrajectoryPoint};
use super::vocab::TorqueSource;
use std::sync::Arc;

use super::link::LinkError;
use crate::model::{ExternalLoad, Model, NO_DIRECTION, Torques};

pub use super::vocab::JointState;

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
    /// The trajectory cannot be followed.
    #[error("trajectory refused: {0}")]
    Trajectory(#[from] TrajectoryError),
    /// A speed scaling outside (0, 1].
    #[error("speed scaling must be within (0, 1], got {0}")]
    Scaling(f64),
    /// An argument that is not finite or beyond a limit.
    #[error("{0}")]
    Invalid(String),
    /// Another connection holds the motion lease.
    #[error(
        "another client holds the motion lease (acquire); only status, subscribe, stop and estop are allowed"
    )]
    Leased,
}

/// Checks a payload: weight within 0…500 N, centre of mass finite and within 1 m of the
/// tool origin.
pub fn check_payload(newtons: f64, com: &[f64; 3]) -> Result<(), CommandError> {
    if !(newtons.is_finite() && (0.0..=500.0).contains(&newtons)) {
        return Err(CommandError::Payload(newtons));
    }
    if !com.iter().all(|c| c.is_finite()) || com.iter().map(|c| c * c).sum::<f64>() > 1.0 {
        return Err(CommandError::Invalid(format!(
            "payload centre of mass {com:?} m must be finite and within 1 m of the tool origin"
        )));
    }
    Ok(())
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
    /// Following a timed trajectory.
    Following {
        /// The trajectory (boxed: planned once, not per cycle).
        traj: Box<Trajectory>,
        /// Trajectory time reached, s.
        tau: f64,
        /// Its tolerances.
        tol: Tolerances,
        /// When trajectory time reached the end, s (the goal time tolerance runs from here).
        ended_s: Option<f64>,
    },
    /// Moving toward streamed setpoints (`servo`) or at streamed velocities (`jog`).
    Streaming {
        /// What the stream asks for.
        stream: Stream,
        /// When the last command of the stream came, s.
        last_s: f64,
        /// The servo target's own velocity, from its last two setpoints (rad/s; fed
        /// forward so a moving target is followed without the lag a stop-at-target
        /// profile would have).
        target_v: [f64; 6],
    },
    /// Decelerating to rest (a controlled stop), all joints together.
    Stopping {
        /// Per-joint deceleration, rad/s².
        decel: [f64; 6],
    },
    /// Stopped by a fault; zero speed until reset.
    Faulted(Fault),
}

/// What a stream asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stream {
    /// Move toward these link positions, rad, within the speed and acceleration limits.
    Servo([f64; 6]),
    /// Move at these link velocities, rad/s (ramped by the acceleration limits).
    Jog([f64; 6]),
    /// Move the tool at this twist: linear velocity of the tool origin (m/s) then angular
    /// velocity (rad/s), in the base frame or (`tool_frame`) the tool's own axes.
    Twist {
        /// vx, vy, vz (m/s), wx, wy, wz (rad/s).
        twist: [f64; 6],
        /// Whether the twist is expressed in the tool frame.
        tool_frame: bool,
    },
}

/// Largest linear speed of a tool-twist jog, m/s.
pub const MAX_TWIST_LINEAR: f64 = 0.25;
/// Largest angular speed of a tool-twist jog, rad/s.
pub const MAX_TWIST_ANGULAR: f64 = 0.5;

/// A trajectory's tolerances, per joint (0: not checked), as in `FollowJointTrajectory`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Largest |desired − actual| link position while executing, rad.
    pub path: [f64; 6],
    /// Largest |desired − actual| link position at the end, rad.
    pub goal: [f64; 6],
    /// How long after the trajectory's end the goal may still be reached, s.
    pub goal_time_s: f64,
}

impl Default for Tolerances {
    /// Path unchecked; goal 5 mrad per joint within 1 s.
    fn default() -> Self {
        Self {
            path: [0.0; 6],
            goal: [0.005; 6],
            goal_time_s: 1.0,
        }
    }
}

/// A trajectory's state, for `status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrajectoryState {
    /// None started yet.
    #[default]
    Idle,
    /// Being followed.
    Executing,
    /// Reached its goal within the tolerances.
    Succeeded,
    /// Stopped before its goal (see the result).
    Aborted,
    /// Replaced by a newer one, or by a move or a stream.
    Preempted,
}

/// The latest trajectory, for `status`: `desired` is the setpoint, `actual` the link estimate
/// (resolver angle minus the modelled deflection), `error` = desired − actual (rad).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct TrajectoryStatus {
    /// Its id (from 1; 0 before the first).
    pub id: u64,
    /// Its state.
    pub state: TrajectoryState,
    /// Why it ended: `""` while executing, `succeeded`, `path_tolerance_violated`,
    /// `goal_tolerance_violated`, `preempted`, `stopped`, `fault`.
    pub result: &'static str,
    /// Desired link positions, rad.
    pub desired: [f64; 6],
    /// Estimated link positions, rad.
    pub actual: [f64; 6],
    /// desired − actual, rad.
    pub error: [f64; 6],
    /// Trajectory time reached / duration, 0…1.
    pub progress: f64,
}

/// How long a speed-scaling change takes from 0 to 1, s (it ramps, so velocities do not jump).
pub const SCALING_RAMP_S: f64 = 0.5;

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
    /// The payload's centre of mass in the tool frame, m.
    pub payload_com: [f64; 3],
    /// Speed limits, rad/s.
    pub speed: [f64; 6],
    /// Acceleration limits (controlled stops), rad/s².
    pub acceleration: [f64; 6],
    /// Following-error limit, rad.
    pub following_error: f64,
    /// Feedback timeout, s.
    pub feedback_timeout_s: f64,
    /// A servo or jog stream stops the arm when no command came for this long, s.
    pub stream_deadline_s: f64,
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
    /// Speed scaling in force (ramping toward `scaling_target`), 0 < f ≤ 1.
    scaling: f64,
    scaling_target: f64,
    trajectory: TrajectoryStatus,
    /// Why the last stream ended, for `status`.
    stream_end: Option<&'static str>,
    /// What the last cycle computed.
    out: CycleOutput,
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
    /// A controller holding the arm where `first` says it is.
    pub fn new(model: impl Into<Arc<Model>>, p: LoopParams, first: &JointState) -> Self {
        let model = model.into();
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
            tau_filtered: [0.0; 6],
            direction: [0.0; 6],
            last_feedback_s: first.stamp_s,
            missed: 0,
            last_state: Some(*first),
            scaling: 1.0,
            scaling_target: 1.0,
            trajectory: TrajectoryStatus::default(),
            stream_end: None,
            out: CycleOutput::default(),
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

    /// Position, speed and acceleration limits in force.
    pub fn joint_limits(&self) -> JointLimits {
        let lim = self.model.limits();
        JointLimits {
            lower: lim.lower,
            upper: lim.upper,
            speed: self.p.speed,
            acceleration: self.p.acceleration,
        }
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
        let traj = Trajectory::plan(&self.setpoint, points, &self.joint_limits(), scaling)?;
        self.end_trajectory(TrajectoryState::Preempted, "preempted");
        self.trajectory = TrajectoryStatus {
            id: self.trajectory.id + 1,
            state: TrajectoryState::Executing,
            result: "",
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
            traj.check_from(*tau, &self.joint_limits(), fraction)?;
        }
        self.scaling_target = fraction;
        Ok(())
    }

    /// A streamed command at `now_s`: a servo target (link positions, rad, inside the
    /// limits) or jog velocities (rad/s, within the speed limits). Starts the stream from
    /// holding or continues one; refused during a move, a trajectory or a stop.
    pub fn stream(&mut self, stream: Stream, now_s: f64) -> Result<(), CommandError> {
        let lim = self.joint_limits();
        if let Stream::Twist { twist, .. } = &stream {
            let n = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let (lin, ang) = (n(&twist[..3]), n(&twist[3..]));
            if !(lin.is_finite() && ang.is_finite())
                || lin > MAX_TWIST_LINEAR
                || ang > MAX_TWIST_ANGULAR
            {
                return Err(CommandError::Invalid(format!(
                    "tool twist: {lin:.4} m/s and {ang:.4} rad/s must be finite and within {MAX_TWIST_LINEAR} m/s and {MAX_TWIST_ANGULAR} rad/s"
                )));
            }
        }
        let (v, what) = match &stream {
            Stream::Servo(q) => (q, "servo position"),
            Stream::Jog(v) => (v, "jog velocity"),
            Stream::Twist { .. } => (&[0.0; 6], "tool twist"),
        };
        for j in 0..6 {
            if !v[j].is_finite() {
                return Err(CommandError::Invalid(format!(
                    "{what} of joint {} is not finite",
                    j + 1
                )));
            }
            let bad = match stream {
                Stream::Servo(_) => v[j] < lim.lower[j] || v[j] > lim.upper[j],
                Stream::Jog(_) => v[j].abs() > lim.speed[j],
                Stream::Twist { .. } => false,
            };
            if bad {
                return Err(CommandError::Invalid(match stream {
                    Stream::Servo(_) => format!(
                        "{what} of joint {}: {:.4} rad is outside [{:.4}, {:.4}] rad",
                        j + 1,
                        v[j],
                        lim.lower[j],
                        lim.upper[j]
                    ),
                    Stream::Jog(_) | Stream::Twist { .. } => format!(
                        "{what} of joint {}: {:.4} rad/s is beyond the {:.4} rad/s limit",
                        j + 1,
                        v[j],
                        lim.speed[j]
                    ),
                }));
            }
        }
        let target_v = match (&self.activity, stream) {
            (
                Activity::Streaming {
                    stream: Stream::Servo(old),
                    last_s,
                    ..
                },
                Stream::Servo(new),
            ) if now_s > *last_s => std::array::from_fn(|j| {
                ((new[j] - old[j]) / (now_s - last_s)).clamp(-lim.speed[j], lim.speed[j])
            }),
            _ => [0.0; 6],
        };
        match &self.activity {
            Activity::Faulted(f) => Err(CommandError::Faulted(f.clone())),
            Activity::Holding | Activity::Streaming { .. } => {
                self.stream_end = None;
                self.activity = Activity::Streaming {
                    stream,
                    last_s: now_s,
                    target_v,
                };
                Ok(())
            }
            _ => Err(CommandError::Busy),
        }
    }

    /// Joint velocities (rad/s) that move the tool at `twist` from the current setpoint, by
    /// the model's Jacobian (numerical, 7 forward kinematics, no allocation); scaled down as a
    /// whole (direction kept) to the speed limits × scaling. `None` near a singularity,
    /// where that would need more than ten times a joint's speed limit.
    fn twist_to_joints(&self, twist: &[f64; 6], tool_frame: bool) -> Option<[f64; 6]> {
        use nalgebra::{Matrix6, Vector3, Vector6};
        let q = self.setpoint.q;
        let f0 = self.model.fk(&q);
        let h = 1e-7;
        let mut jac = Matrix6::zeros();
        for j in 0..6 {
            let mut qh = q;
            qh[j] += h;
            let f1 = self.model.fk(&qh);
            let dp = (f1.translation.vector - f0.translation.vector) / h;
            let dr = (f1.rotation * f0.rotation.inverse()).scaled_axis() / h;
            for r in 0..3 {
                jac[(r, j)] = dp[r];
                jac[(r + 3, j)] = dr[r];
            }
        }
        let (mut v, mut w) = (
            Vector3::new(twist[0], twist[1], twist[2]),
            Vector3::new(twist[3], twist[4], twist[5]),
        );
        if tool_frame {
            v = f0.rotation * v;
            w = f0.rotation * w;
        }
        let qd = jac
            .lu()
            .solve(&Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z))?;
        let lim = self.joint_limits();
        let mut scale = 1.0f64;
        for j in 0..6 {
            let vmax = lim.speed[j] * self.scaling;
            if !qd[j].is_finite() || qd[j].abs() > 10.0 * lim.speed[j] {
                return None;
            }
            if qd[j].abs() > vmax {
                scale = scale.min(vmax / qd[j].abs());
            }
        }
        Some(std::array::from_fn(|j| qd[j] * scale))
    }

    /// Marks the running trajectory as ended (no effect on any other activity).
    fn end_trajectory(&mut self, state: TrajectoryState, result: &'static str) {
        if self.trajectory.state == TrajectoryState::Executing {
            self.trajectory.state = state;
            self.trajectory.result = result;
        }
    }

    /// One cycle of a stream: toward the servo target or at the jog velocity, each joint
    /// within its speed (× scaling) and acceleration limits and braking before its range
    /// ends. No allocation.
    fn stream_step(&mut self, stream: Stream, target_v: &[f64; 6]) {
        let dt = self.p.period_s;
        let lim = self.joint_limits();
        let stream = match stream {
            Stream::Twist { twist, tool_frame } => match self.twist_to_joints(&twist, tool_frame) {
                Some(v) => Stream::Jog(v),
                None => {
                    self.stream_end = Some(
                        "jog: the tool twist needs joint speeds beyond the limits here (near a singularity); stopped",
                    );
                    self.stop();
                    return;
                }
            },
            s => s,
        };
        for j in 0..6 {
            let (q, v) = (self.setpoint.q[j], self.setpoint.qd[j]);
            let (vmax, a) = (lim.speed[j] * self.scaling, lim.acceleration[j]);
            let want = match stream {
                Stream::Servo(target) => {
                    let e = target[j] - q;
                    // the target's own speed, plus the fastest approach from which the
                    // target can still be reached at rest
                    let approach =
                        e.signum() * vmax.min((2.0 * a * e.abs()).sqrt()).min(e.abs() / dt);
                    (target_v[j] * self.scaling + approach).clamp(-vmax, vmax)
                }
                // (a twist was turned into joint velocities above)
                Stream::Jog(vel) | Stream::Twist { twist: vel, .. } => {
                    let w = vel[j].clamp(-vmax, vmax);
                    // brake before the range ends
                    let room = if w > 0.0 {
                        lim.upper[j] - q
                    } else {
                        q - lim.lower[j]
                    };
                    w.signum() * w.abs().min((2.0 * a * room.max(0.0)).sqrt())
                }
            };
            let nv = v + (want - v).clamp(-a * dt, a * dt);
            self.setpoint.q[j] = q + 0.5 * (v + nv) * dt;
            self.setpoint.qd[j] = nv;
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
        }
    }

    /// A controlled stop: the setpoint decelerates to rest within the acceleration limits,
    /// every joint reaching zero speed at the same instant. No effect unless moving.
    pub fn stop(&mut self) {
        self.end_trajectory(TrajectoryState::Aborted, "stopped");
        if matches!(
            self.activity,
            Activity::Moving { .. } | Activity::Following { .. } | Activity::Streaming { .. }
        ) {
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
        // the speed scaling ramps toward what was asked
        let ramp = self.p.period_s / SCALING_RAMP_S;
        self.scaling += (self.scaling_target - self.scaling).clamp(-ramp, ramp);
        if let Activity::Following {
            traj, tau, ended_s, ..
        } = &mut self.activity
        {
            *tau = (*tau + self.scaling * self.p.period_s).min(traj.duration());
            let s = traj.sample(*tau);
            self.setpoint.q = s.q;
            for j in 0..6 {
                self.setpoint.qd[j] = if *tau < traj.duration() {
                    self.scaling * s.qd[j]
                } else {
                    0.0
                };
            }
            self.trajectory.progress = *tau / traj.duration();
            if *tau >= traj.duration() && ended_s.is_none() {
                *ended_s = Some(now_s);
            }
        }
        if let Activity::Streaming {
            stream,
            last_s,
            target_v,
        } = self.activity
        {
            if now_s - last_s > self.p.stream_deadline_s {
                self.stream_end = Some(match stream {
                    Stream::Servo(_) => "servo: no setpoint within servo.deadline_ms; stopped",
                    Stream::Jog(_) | Stream::Twist { .. } => {
                        "jog: no command within servo.deadline_ms; stopped"
                    }
                });
                self.stop();
            } else {
                self.stream_step(stream, &target_v);
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
        let load = self.load();
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
        let mut actual = [0.0; 6];
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
            actual[j] = link;
        }
        self.out = CycleOutput {
            tau,
            target,
            speeds: out,
        };
        self.track(&actual, now_s);
        out
    }

    /// What the last cycle computed.
    pub fn output(&self) -> &CycleOutput {
        &self.out
    }

    /// The activity as a small code (recordings): 0 holding, 1 moving, 2 following,
    /// 3 streaming, 4 stopping, 5 faulted.
    pub fn activity_code(&self) -> u8 {
        match self.activity {
            Activity::Holding => 0,
            Activity::Moving { .. } => 1,
            Activity::Following { .. } => 2,
            Activity::Streaming { .. } => 3,
            Activity::Stopping { .. } => 4,
            Activity::Faulted(_) => 5,
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
                self.trajectory.result = "path_tolerance_violated";
            }
            None => {}
            Some(_) if !off_goal => {
                t.state = TrajectoryState::Succeeded;
                t.result = "succeeded";
                self.activity = Activity::Holding;
            }
            Some(true) => {
                t.state = TrajectoryState::Aborted;
                t.result = "goal_tolerance_violated";
                self.activity = Activity::Holding;
            }
            Some(false) => {}
        }
    }

    /// Stops the arm for a fault found outside the cycle (the link, a client's emergency
    /// stop): zero speed until [`Controller::reset`]. An earlier fault is kept.
    pub fn halt(&mut self, f: Fault) {
        if !matches!(self.activity, Activity::Faulted(_)) {
            self.end_trajectory(TrajectoryState::Aborted, "fault");
            self.activity = Activity::Faulted(f);
        }
    }

    fn fault(&mut self, f: Fault) -> [f64; 6] {
        self.end_trajectory(TrajectoryState::Aborted, "fault");
        self.activity = Activity::Faulted(f);
        [0.0; 6]
    }
}
