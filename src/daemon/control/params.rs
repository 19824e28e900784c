//! The loop's vocabulary: why it stopped the arm ([`Fault`]), why it refused a command
//! ([`CommandError`]), what it is doing ([`Activity`], [`TrajectoryStatus`]), what a client
//! streams ([`Stream`]) and the parameters it runs with ([`LoopParams`], [`Tolerances`]).

use schemars::JsonSchema;

use crate::daemon::link::LinkError;
use crate::daemon::plan::{Move, MoveError, Trajectory, TrajectoryError};
use crate::daemon::vocab::{Limits, TorqueSource};

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
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, JsonSchema,
)]
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

/// Why a trajectory ended, for `status` (`""` while it has not).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum TrajectoryResult {
    /// Not ended (executing, or none started): `""` on the wire.
    #[default]
    #[serde(rename = "")]
    Running,
    /// Reached its goal within the tolerances.
    Succeeded,
    /// A joint left its path tolerance; the arm stopped.
    PathToleranceViolated,
    /// The goal was not reached within the goal time tolerance.
    GoalToleranceViolated,
    /// Replaced by a newer trajectory, a move or a stream.
    Preempted,
    /// Ended by a stop request.
    Stopped,
    /// Ended by a fault.
    Fault,
}

/// The latest trajectory, for `status`: `desired` is the setpoint, `actual` the link estimate
/// (resolver angle minus the modelled deflection), `error` = desired − actual (rad).
#[derive(
    Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize, JsonSchema,
)]
pub struct TrajectoryStatus {
    /// Its id (from 1; 0 before the first).
    pub id: u64,
    /// Its state.
    pub state: TrajectoryState,
    /// Why it ended.
    pub result: TrajectoryResult,
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
    /// Holding, motor-angle errors below this get no position correction, rad (0: off).
    pub hold_deadband: f64,
    /// Holding, this × the resolvers' motor speed is taken off the speed command
    /// (dimensionless; 0: off).
    pub hold_damping: f64,
    /// The shoulder's (J2's) inertia up to which the position gain applies in full, kg·m²
    /// (`None`: the gain does not depend on the inertia; [`LoopParams::loop_gain`]).
    pub gain_inertia_kgm2: Option<f64>,
    /// Torque constants, N·m/A.
    pub torque_constants: [f64; 6],
    /// Payload hung at the tool, N.
    pub payload_n: f64,
    /// The payload's centre of mass in the tool frame, m.
    pub payload_com: [f64; 3],
    /// Position (the model's), speed and acceleration limits.
    pub limits: Limits,
    /// Following-error limit, rad.
    pub following_error: f64,
    /// Feedback timeout, s.
    pub feedback_timeout_s: f64,
    /// A servo or jog stream stops the arm when no command came for this long, s.
    pub stream_deadline_s: f64,
}

impl LoopParams {
    /// The position gain in force (1/s) when the shoulder's drive moves `shoulder_kgm2`
    /// (kg·m², [`Model::link_inertia`](crate::model::Model::link_inertia)'s J2):
    /// `gain × min(1, gain_inertia_kgm2 / shoulder_kgm2)`, or `gain` unscheduled. The drive's
    /// speed loop slows in proportion to the inertia it moves; the position loop around it
    /// slows with it, keeping the cascade's margin (docs/daemon.md).
    pub fn loop_gain(&self, shoulder_kgm2: f64) -> f64 {
        match self.gain_inertia_kgm2 {
            Some(limit) if shoulder_kgm2 > limit => self.gain * limit / shoulder_kgm2,
            _ => self.gain,
        }
    }
}

/// Loop parameters for the unit tests of the loop and the core: 500 Hz, gain 20, measured
/// torques through a 20 Hz filter with 10 N·m/A constants, the nominal model's position
/// limits, 1 rad/s and 2 rad/s² on every joint, a 0.01 rad following-error limit, 20 ms
/// feedback timeout, 0.1 s stream deadline.
#[cfg(test)]
pub(crate) fn test_params() -> LoopParams {
    let m = crate::model::Model::nominal();
    LoopParams {
        period_s: 0.002,
        gain: 20.0,
        torque_source: TorqueSource::Measured,
        filter_hz: 20.0,
        hold_deadband: 0.0,
        hold_damping: 0.0,
        gain_inertia_kgm2: None,
        torque_constants: [10.0; 6],
        payload_n: 0.0,
        payload_com: [0.0; 3],
        limits: Limits {
            lower: m.limits().lower,
            upper: m.limits().upper,
            speed: [1.0; 6],
            acceleration: [2.0; 6],
            min_ramp_s: 0.0,
        },
        following_error: 0.01,
        feedback_timeout_s: 0.02,
        stream_deadline_s: 0.1,
    }
}
