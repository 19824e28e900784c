//! The pure core of the `pa10-ros2` bridge: the ROS 2 messages it speaks, declared field by
//! field in the order of their IDL (CDR has no field names, so the order *is* the type), and the
//! translations between them and `pa10d`'s JSON — a `FollowJointTrajectory` goal into a
//! `follow_trajectory` request (or the result code and words that refuse it), the daemon's
//! trajectory status into the action's feedback and result, its status into
//! `diagnostic_msgs/DiagnosticArray`. No DDS, no sockets, no clock: the binary
//! (`src/bin/pa10-ros2.rs`, feature `ros2`) passes the time in.
//!
//! Units as in ROS: radians, seconds; `builtin_interfaces` times and durations as whole
//! seconds plus nanoseconds.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::daemon::api::MAX_LINE_BYTES;
use crate::daemon::control::Tolerances;
use crate::daemon::trajectory::MAX_POINTS;

/// The joint names of the arm, J1…J6, as `/joint_states` and the URDF carry them.
pub use crate::model::urdf::JOINT_NAMES;

/// How far (rad, every joint) a first point at `time_from_start` 0 may be from the arm's
/// current setpoint to be taken as the start state MoveIt sends (and dropped).
pub const START_STATE_TOLERANCE: f64 = 0.01;

/// How far in the future a goal's `header.stamp` may lie and still start now, s (clocks of
/// two hosts differ by that much; a later start is not supported).
pub const STAMP_SLACK_S: f64 = 0.5;

/// The p99 wake-up jitter above which `/diagnostics` warns, µs (a quarter of the 500 Hz
/// period).
pub const JITTER_WARN_US: f64 = 500.0;

/// builtin_interfaces/Time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds since the epoch.
    pub sec: i32,
    /// Nanoseconds, 0…999 999 999.
    pub nanosec: u32,
}

impl Time {
    /// `t` seconds since the epoch.
    pub fn from_secs(t: f64) -> Self {
        let sec = t.floor();
        Self {
            sec: sec as i32,
            nanosec: (((t - sec) * 1e9) as u32).min(999_999_999),
        }
    }

    /// Seconds since the epoch.
    pub fn secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

/// builtin_interfaces/Duration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, 0…999 999 999.
    pub nanosec: u32,
}

impl Duration {
    /// The duration in seconds, or why it is not one (nanoseconds ≥ 1 s).
    pub fn secs(&self) -> Result<f64, String> {
        if self.nanosec >= 1_000_000_000 {
            return Err(format!("nanosec {} is not below 10⁹", self.nanosec));
        }
        Ok(self.sec as f64 + self.nanosec as f64 * 1e-9)
    }

    /// `s` seconds (≥ 0).
    pub fn from_secs(s: f64) -> Self {
        let t = Time::from_secs(s.max(0.0));
        Self {
            sec: t.sec,
            nanosec: t.nanosec,
        }
    }
}

/// std_msgs/Header.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When (wall clock).
    pub stamp: Time,
    /// The frame.
    pub frame_id: String,
}

/// sensor_msgs/JointState.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Velocities, rad/s.
    pub velocity: Vec<f64>,
    /// Efforts, N·m.
    pub effort: Vec<f64>,
}

/// trajectory_msgs/JointTrajectoryPoint.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    /// Positions, rad.
    pub positions: Vec<f64>,
    /// Velocities, rad/s (empty or one per joint).
    pub velocities: Vec<f64>,
    /// Accelerations, rad/s² (empty or one per joint).
    pub accelerations: Vec<f64>,
    /// Efforts, N·m (not supported: must be empty).
    pub effort: Vec<f64>,
    /// When, from the trajectory's start.
    pub time_from_start: Duration,
}

/// trajectory_msgs/JointTrajectory.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// `stamp`: when it starts (zero: now).
    pub header: Header,
    /// The joints the points' entries belong to, in their order.
    pub joint_names: Vec<String>,
    /// The points.
    pub points: Vec<JointTrajectoryPoint>,
}

/// geometry_msgs/Vector3.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// geometry_msgs/Quaternion.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// geometry_msgs/Transform.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Transform {
    /// m.
    pub translation: Vector3,
    /// Unit quaternion.
    pub rotation: Quaternion,
}

/// geometry_msgs/Twist.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    /// m/s.
    pub linear: Vector3,
    /// rad/s.
    pub angular: Vector3,
}

/// trajectory_msgs/MultiDOFJointTrajectoryPoint.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MultiDofJointTrajectoryPoint {
    /// Poses.
    pub transforms: Vec<Transform>,
    /// Velocities.
    pub velocities: Vec<Twist>,
    /// Accelerations.
    pub accelerations: Vec<Twist>,
    /// When, from the start.
    pub time_from_start: Duration,
}

/// trajectory_msgs/MultiDOFJointTrajectory (the PA10 has none: must be empty).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MultiDofJointTrajectory {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Points.
    pub points: Vec<MultiDofJointTrajectoryPoint>,
}

/// control_msgs/JointTolerance: 0 = the server's default, −1 = unchecked.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTolerance {
    /// The joint.
    pub name: String,
    /// rad.
    pub position: f64,
    /// rad/s (not supported: 0 or −1).
    pub velocity: f64,
    /// rad/s² (not supported: 0 or −1).
    pub acceleration: f64,
}

/// control_msgs/JointComponentTolerance (for multi-DOF joints; not supported: must be empty).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointComponentTolerance {
    /// The joint.
    pub joint_name: String,
    /// X_AXIS = 1 … TRANSLATION = 5, ROTATION = 6.
    pub component: u16,
    /// Position tolerance.
    pub position: f64,
    /// Velocity tolerance.
    pub velocity: f64,
    /// Acceleration tolerance.
    pub acceleration: f64,
}

/// control_msgs/action/FollowJointTrajectory goal (ROS 2 Humble and later).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryGoal {
    /// The trajectory.
    pub trajectory: JointTrajectory,
    /// Multi-DOF joints (none on the PA10).
    pub multi_dof_trajectory: MultiDofJointTrajectory,
    /// Tolerances while executing.
    pub path_tolerance: Vec<JointTolerance>,
    /// Multi-DOF path tolerances.
    pub component_path_tolerance: Vec<JointComponentTolerance>,
    /// Tolerances at the end.
    pub goal_tolerance: Vec<JointTolerance>,
    /// Multi-DOF goal tolerances.
    pub component_goal_tolerance: Vec<JointComponentTolerance>,
    /// How long after the end the goal may still be reached (zero: the default, 1 s).
    pub goal_time_tolerance: Duration,
}

/// control_msgs/action/FollowJointTrajectory result codes.
pub mod code {
    /// Reached within the tolerances (also a cancelled goal's code).
    pub const SUCCESSFUL: i32 = 0;
    /// Not a goal this arm can follow (the words say why); also a goal ended early.
    pub const INVALID_GOAL: i32 = -1;
    /// Joint names not the arm's six.
    pub const INVALID_JOINTS: i32 = -2;
    /// The trajectory ended before it arrived.
    pub const OLD_HEADER_TIMESTAMP: i32 = -3;
    /// A path tolerance was exceeded (the arm stopped).
    pub const PATH_TOLERANCE_VIOLATED: i32 = -4;
    /// Not within the goal tolerance in time.
    pub const GOAL_TOLERANCE_VIOLATED: i32 = -5;
}

/// control_msgs/action/FollowJointTrajectory result.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryResult {
    /// One of [`code`].
    pub error_code: i32,
    /// Why, in words.
    pub error_string: String,
}

/// control_msgs/action/FollowJointTrajectory feedback.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryFeedback {
    /// Stamp.
    pub header: Header,
    /// The arm's joints.
    pub joint_names: Vec<String>,
    /// The setpoint.
    pub desired: JointTrajectoryPoint,
    /// The link estimate.
    pub actual: JointTrajectoryPoint,
    /// desired − actual.
    pub error: JointTrajectoryPoint,
    /// Empty.
    pub multi_dof_joint_names: Vec<String>,
    /// Empty.
    pub multi_dof_desired: MultiDofJointTrajectoryPoint,
    /// Empty.
    pub multi_dof_actual: MultiDofJointTrajectoryPoint,
    /// Empty.
    pub multi_dof_error: MultiDofJointTrajectoryPoint,
}

/// std_srvs/Trigger request (an empty IDL struct carries one placeholder octet).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// Always 0.
    pub structure_needs_at_least_one_member: u8,
}

/// std_srvs/Trigger response.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TriggerResponse {
    /// Whether the daemon did it.
    pub success: bool,
    /// The daemon's words.
    pub message: String,
}

/// diagnostic_msgs/KeyValue.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// diagnostic_msgs/DiagnosticStatus levels.
pub mod level {
    /// All well.
    pub const OK: u8 = 0;
    /// Working, but look.
    pub const WARN: u8 = 1;
    /// Faulted.
    pub const ERROR: u8 = 2;
    /// No news.
    pub const STALE: u8 = 3;
}

/// diagnostic_msgs/DiagnosticStatus.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// One of [`level`].
    pub level: u8,
    /// What is reported on.
    pub name: String,
    /// In words.
    pub message: String,
    /// Which hardware.
    pub hardware_id: String,
    /// The numbers.
    pub values: Vec<KeyValue>,
}

/// diagnostic_msgs/DiagnosticArray.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One entry per reported thing.
    pub status: Vec<DiagnosticStatus>,
}

/// Why a goal cannot be followed: its result code and words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct GoalRefusal {
    /// One of [`code`].
    pub code: i32,
    /// Why.
    pub message: String,
}

fn refuse<T>(code: i32, message: impl Into<String>) -> Result<T, GoalRefusal> {
    Err(GoalRefusal {
        code,
        message: message.into(),
    })
}

/// The arm's joint index of each of `names` (a permutation of [`JOINT_NAMES`]), or why not.
fn joint_order(names: &[String]) -> Result<[usize; 6], GoalRefusal> {
    if names.len() != 6 {
        return refuse(
            code::INVALID_JOINTS,
            format!(
                "the trajectory names {} joints; the arm has six: {}",
                names.len(),
                JOINT_NAMES.join(", ")
            ),
        );
    }
    let mut order = [0; 6];
    let mut seen = [false; 6];
    for (k, n) in names.iter().enumerate() {
        let Some(j) = JOINT_NAMES.iter().position(|m| m == n) else {
            return refuse(
                code::INVALID_JOINTS,
                format!(
                    "unknown joint {n:?}: the arm's joints are {}",
                    JOINT_NAMES.join(", ")
                ),
            );
        };
        if seen[j] {
            return refuse(code::INVALID_JOINTS, format!("joint {n:?} named twice"));
        }
        seen[j] = true;
        order[k] = j;
    }
    Ok(order)
}

/// `v` (entries in the goal's joint order) in the arm's order; `what` names it in a refusal.
fn reorder(v: &[f64], order: &[usize; 6], what: &str) -> Result<[f64; 6], GoalRefusal> {
    if v.len() != 6 {
        return refuse(
            code::INVALID_GOAL,
            format!("{what}: {} values for 6 joints", v.len()),
        );
    }
    let mut out = [0.0; 6];
    for (k, &j) in order.iter().enumerate() {
        if !v[k].is_finite() {
            return refuse(
                code::INVALID_GOAL,
                format!(
                    "{what}: {} is not a finite number ({})",
                    JOINT_NAMES[j], v[k]
                ),
            );
        }
        out[j] = nano(v[k]);
    }
    Ok(out)
}

/// `x` to 1e-9 (rad, rad/s, rad/s², s — far below the resolvers' 0.19 mrad): the shortest
/// decimal of such a number has ≤ 12 digits, where an arbitrary double needs 17, so a request
/// line carries ≈ 40 % more points.
fn nano(x: f64) -> f64 {
    (x * 1e9).round() / 1e9
}

/// Per-joint position tolerances, rad, in the arm's order: 0 (unspecified) → `default`,
/// −1 → 0 (unchecked, as the daemon reads 0).
fn tolerances(
    list: &[JointTolerance],
    default: &[f64; 6],
    what: &str,
) -> Result<[f64; 6], GoalRefusal> {
    let mut out = *default;
    for t in list {
        let Some(j) = JOINT_NAMES.iter().position(|m| *m == t.name) else {
            return refuse(
                code::INVALID_JOINTS,
                format!("{what}: unknown joint {:?}", t.name),
            );
        };
        for (v, kind) in [(t.velocity, "velocity"), (t.acceleration, "acceleration")] {
            if v != 0.0 && v != -1.0 {
                return refuse(
                    code::INVALID_GOAL,
                    format!(
                        "{what} of {}: {kind} tolerances are not supported (0 or -1)",
                        t.name
                    ),
                );
            }
        }
        out[j] = match t.position {
            0.0 => default[j],
            -1.0 => 0.0,
            p if p.is_finite() && p > 0.0 => p,
            p => {
                return refuse(
                    code::INVALID_GOAL,
                    format!(
                        "{what} of {}: {p} rad is not a tolerance (> 0, 0 or -1)",
                        t.name
                    ),
                );
            }
        };
    }
    Ok(out)
}

/// The `follow_trajectory` request of `goal`, or why it cannot be followed. `now` is the wall
/// clock (for `header.stamp`); `current` the arm's link setpoint, rad (a first point at time 0
/// within [`START_STATE_TOLERANCE`] of it is the start state and is dropped).
pub fn goal_request(
    goal: &FollowJointTrajectoryGoal,
    now: Time,
    current: &[f64; 6],
) -> Result<Value, GoalRefusal> {
    let m = &goal.multi_dof_trajectory;
    if !m.joint_names.is_empty() || !m.points.is_empty() {
        return refuse(
            code::INVALID_JOINTS,
            "multi-DOF joints are not supported: the arm has six revolute joints",
        );
    }
    if !goal.component_path_tolerance.is_empty() || !goal.component_goal_tolerance.is_empty() {
        return refuse(
            code::INVALID_GOAL,
            "component tolerances (of multi-DOF joints) are not supported",
        );
    }
    let t = &goal.trajectory;
    let order = joint_order(&t.joint_names)?;
    if t.points.is_empty() {
        return refuse(code::INVALID_GOAL, "the trajectory has no points");
    }
    if t.points.len() > MAX_POINTS {
        // judged before any point is translated: a million points cost nothing but this
        return refuse(
            code::INVALID_GOAL,
            format!(
                "{} points: pa10d follows at most {MAX_POINTS}",
                t.points.len()
            ),
        );
    }
    let times = t
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            p.time_from_start.secs().or_else(|e| {
                refuse(
                    code::INVALID_GOAL,
                    format!("point {i}: time_from_start: {e}"),
                )
            })
        })
        .collect::<Result<Vec<f64>, _>>()?;
    let end = times.last().copied().unwrap_or(0.0);
    if t.header.stamp != Time::default() {
        let start = t.header.stamp.secs();
        if start + end < now.secs() {
            return refuse(
                code::OLD_HEADER_TIMESTAMP,
                format!(
                    "the trajectory ended {:.3} s ago (header.stamp {:.3} s + {end:.3} s)",
                    now.secs() - start - end,
                    start
                ),
            );
        }
        if start > now.secs() + STAMP_SLACK_S {
            return refuse(
                code::INVALID_GOAL,
                format!(
                    "header.stamp is {:.3} s in the future: a delayed start is not supported (zero: now)",
                    start - now.secs()
                ),
            );
        }
    }
    let mut points = Vec::with_capacity(t.points.len());
    for (i, (p, &tp)) in t.points.iter().zip(&times).enumerate() {
        if !p.effort.is_empty() {
            return refuse(
                code::INVALID_GOAL,
                format!("point {i}: effort is not supported (position control)"),
            );
        }
        let q = reorder(&p.positions, &order, &format!("point {i} positions"))?;
        if i == 0 && tp == 0.0 {
            // the start state MoveIt puts first: it must be where the arm is
            if let Some(j) = (0..6).find(|&j| (q[j] - current[j]).abs() > START_STATE_TOLERANCE) {
                return refuse(
                    code::INVALID_GOAL,
                    format!(
                        "point 0 at time 0 is {:.4} rad from the arm on {} (it must be the current state, within {START_STATE_TOLERANCE} rad)",
                        (q[j] - current[j]).abs(),
                        JOINT_NAMES[j]
                    ),
                );
            }
            continue;
        }
        let mut point = json!({ "positions": q, "time_from_start": nano(tp) });
        if !p.velocities.is_empty() {
            point["velocities"] = json!(reorder(
                &p.velocities,
                &order,
                &format!("point {i} velocities")
            )?);
        }
        if !p.accelerations.is_empty() {
            point["accelerations"] = json!(reorder(
                &p.accelerations,
                &order,
                &format!("point {i} accelerations")
            )?);
        }
        points.push(point);
    }
    if points.is_empty() {
        return refuse(
            code::INVALID_GOAL,
            "the trajectory has only its start state (a point at time 0)",
        );
    }
    let d = Tolerances::default();
    let path = tolerances(&goal.path_tolerance, &d.path, "path_tolerance")?;
    let goal_tol = tolerances(&goal.goal_tolerance, &d.goal, "goal_tolerance")?;
    let goal_time = match goal.goal_time_tolerance.secs() {
        Ok(0.0) => d.goal_time_s,
        Ok(s) if s > 0.0 => s,
        Ok(s) => return refuse(code::INVALID_GOAL, format!("goal_time_tolerance {s} s < 0")),
        Err(e) => return refuse(code::INVALID_GOAL, format!("goal_time_tolerance: {e}")),
    };
    let n = points.len();
    let req = json!({
        "cmd": "follow_trajectory",
        "points": points,
        "path_tolerance": path,
        "goal_tolerance": goal_tol,
        "goal_time_tolerance": goal_time,
    });
    let bytes = req.to_string().len() + 1;
    if bytes > MAX_LINE_BYTES {
        return refuse(
            code::INVALID_GOAL,
            format!(
                "{n} points make a {bytes}-byte request; pa10d takes {MAX_LINE_BYTES} bytes a line (about {} points like these): send fewer points",
                n * MAX_LINE_BYTES / bytes
            ),
        );
    }
    Ok(req)
}

/// The daemon's latest trajectory, as `status.trajectory` carries it.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
pub struct TrajectoryReport {
    /// Its id (the `id` `follow_trajectory` answered).
    pub id: u64,
    /// `idle | executing | succeeded | aborted | preempted`.
    pub state: String,
    /// Why it ended.
    pub result: String,
    /// Setpoint, rad.
    pub desired: [f64; 6],
    /// Link estimate, rad.
    pub actual: [f64; 6],
    /// desired − actual, rad.
    pub error: [f64; 6],
    /// 0…1.
    pub progress: f64,
}

/// How a goal ended, as `action_msgs/GoalStatus` says it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// SUCCEEDED.
    Succeeded,
    /// ABORTED.
    Aborted,
    /// CANCELED.
    Canceled,
}

/// How the goal whose trajectory is `t` ended, with its result — `None` while it executes.
/// `canceling`: the client asked to cancel it (a stop then is the cancel's, not a failure).
/// `fault`: the daemon's fault text, if any.
pub fn goal_result(
    t: &TrajectoryReport,
    canceling: bool,
    fault: Option<&str>,
) -> Option<(Ending, FollowJointTrajectoryResult)> {
    let worst = |e: &[f64; 6]| {
        (0..6)
            .max_by(|&a, &b| e[a].abs().total_cmp(&e[b].abs()))
            .map_or((0, 0.0), |j| (j, e[j]))
    };
    let r = |code, s: String| FollowJointTrajectoryResult {
        error_code: code,
        error_string: s,
    };
    let (j, e) = worst(&t.error);
    Some(match (t.state.as_str(), t.result.as_str()) {
        ("executing", _) | ("idle", _) => return None,
        ("succeeded", _) => (Ending::Succeeded, r(code::SUCCESSFUL, String::new())),
        (_, "path_tolerance_violated") => (
            Ending::Aborted,
            r(
                code::PATH_TOLERANCE_VIOLATED,
                format!(
                    "path tolerance violated on {}: error {e:.5} rad; the arm stopped",
                    JOINT_NAMES[j]
                ),
            ),
        ),
        (_, "goal_tolerance_violated") => (
            Ending::Aborted,
            r(
                code::GOAL_TOLERANCE_VIOLATED,
                format!(
                    "goal tolerance violated on {}: error {e:.5} rad after the goal time tolerance",
                    JOINT_NAMES[j]
                ),
            ),
        ),
        (_, "stopped") if canceling => (Ending::Canceled, r(code::SUCCESSFUL, String::new())),
        ("preempted", _) => (
            Ending::Canceled,
            r(
                code::INVALID_GOAL,
                "replaced by a newer trajectory, move or stream".into(),
            ),
        ),
        (_, "fault") => (
            Ending::Aborted,
            r(
                code::INVALID_GOAL,
                format!("the arm faulted: {}", fault.unwrap_or("(no fault text)")),
            ),
        ),
        (_, "stopped") => (
            Ending::Aborted,
            r(
                code::INVALID_GOAL,
                "stopped by a stop request to pa10d".into(),
            ),
        ),
        (s, why) => (
            Ending::Aborted,
            r(code::INVALID_GOAL, format!("ended {s}: {why}")),
        ),
    })
}

fn point(q: &[f64; 6]) -> JointTrajectoryPoint {
    JointTrajectoryPoint {
        positions: q.to_vec(),
        ..Default::default()
    }
}

/// The action's feedback for trajectory `t` at wall-clock `now`.
pub fn feedback(t: &TrajectoryReport, now: Time) -> FollowJointTrajectoryFeedback {
    FollowJointTrajectoryFeedback {
        header: Header {
            stamp: now,
            frame_id: String::new(),
        },
        joint_names: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
        desired: point(&t.desired),
        actual: point(&t.actual),
        error: point(&t.error),
        ..Default::default()
    }
}

/// What `/diagnostics` reports about the daemon, from its `status` (JSON) at wall-clock
/// `now`: level ERROR on a fault, WARN while not in control (starting, closed) or when the
/// loop's p99 wake-up jitter exceeds [`JITTER_WARN_US`], OK otherwise; the loop's, link's and
/// bus's numbers as key/values.
pub fn diagnostics(status: &Value, now: Time) -> DiagnosticArray {
    let state = status["state"].as_str().unwrap_or("unknown");
    let fault = status["fault"].as_str();
    let c = &status["cycle"];
    let p99 = c["jitter_us"][1].as_f64().unwrap_or(0.0);
    let (level, message) = match (fault, state) {
        (Some(f), _) => (level::ERROR, format!("fault: {f}")),
        (None, "starting" | "closed" | "unknown") => (level::WARN, state.to_string()),
        (None, _) if p99 > JITTER_WARN_US => (
            level::WARN,
            format!("{state}; p99 wake-up jitter {p99:.0} µs"),
        ),
        (None, _) => (level::OK, state.to_string()),
    };
    let triple = |v: &Value| {
        format!(
            "{:.0} / {:.0} / {:.0}",
            v[0].as_f64().unwrap_or(0.0),
            v[1].as_f64().unwrap_or(0.0),
            v[2].as_f64().unwrap_or(0.0)
        )
    };
    let text = |v: &Value| match v {
        Value::String(s) => s.clone(),
        Value::Null => String::new(),
        v => v.to_string(),
    };
    let l = &status["link"];
    let values = [
        ("state", text(&status["state"])),
        ("fault", text(&status["fault"])),
        ("servo", text(&status["servo"])),
        ("cycles", text(&c["cycles"])),
        ("overruns", text(&c["overruns"])),
        ("jitter p50 / p99 / max [us]", triple(&c["jitter_us"])),
        ("compute p50 / p99 / max [us]", triple(&c["compute_us"])),
        ("bus load [%]", text(&c["bus_load_pct"])),
        ("incomplete feedback cycles", text(&l["incomplete"])),
        ("host pauses", text(&l["paused"])),
        ("stale frames", text(&l["stale"])),
        ("malformed frames", text(&l["malformed"])),
        ("controller errors", text(&l["controller_errors"])),
        ("speed scaling", text(&status["speed_scaling"])),
        ("leased", text(&status["leased"])),
    ]
    .into_iter()
    .map(|(k, v)| KeyValue {
        key: k.into(),
        value: v,
    })
    .collect();
    DiagnosticArray {
        header: Header {
            stamp: now,
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level,
            name: "pa10d: control loop".into(),
            message,
            hardware_id: "pa10-6ce".into(),
            values,
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(order: [usize; 6]) -> Vec<String> {
        order.iter().map(|&j| JOINT_NAMES[j].to_string()).collect()
    }

    fn goal(order: [usize; 6], pts: &[([f64; 6], f64)]) -> FollowJointTrajectoryGoal {
        FollowJointTrajectoryGoal {
            trajectory: JointTrajectory {
                joint_names: names(order),
                points: pts
                    .iter()
                    .map(|(q, t)| JointTrajectoryPoint {
                        positions: order.iter().map(|&j| q[j]).collect(),
                        time_from_start: Duration::from_secs(*t),
                        ..Default::default()
                    })
                    .collect(),
                ..Default::default()
            },
            ..Default::default()
        }
    }

    const NOW: Time = Time {
        sec: 1_800_000_000,
        nanosec: 0,
    };
    const Q0: [f64; 6] = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
    const Q1: [f64; 6] = [0.1, 0.5, 1.5, 0.1, 1.0, 0.2];

    #[test]
    fn a_moveit_goal_in_any_joint_order_becomes_the_arms_order_without_its_start_state() {
        let order = [3, 1, 5, 0, 2, 4];
        let g = goal(order, &[(Q0, 0.0), (Q1, 2.0)]);
        let r = goal_request(&g, NOW, &Q0).unwrap();
        assert_eq!(r["cmd"], "follow_trajectory");
        assert_eq!(r["points"].as_array().unwrap().len(), 1);
        let q: [f64; 6] = serde_json::from_value(r["points"][0]["positions"].clone()).unwrap();
        assert_eq!(q, Q1);
        assert_eq!(r["points"][0]["time_from_start"], 2.0);
        assert_eq!(r["goal_tolerance"], json!([0.005f64; 6].to_vec()));
        assert_eq!(r["path_tolerance"], json!([0.0f64; 6].to_vec()));
        assert_eq!(r["goal_time_tolerance"], 1.0);
    }

    #[test]
    fn tolerances_by_name_with_zero_default_and_minus_one_unchecked() {
        let mut g = goal([0, 1, 2, 3, 4, 5], &[(Q1, 1.5)]);
        let tol = |name: &str, p: f64| JointTolerance {
            name: name.into(),
            position: p,
            ..Default::default()
        };
        g.path_tolerance = vec![tol("pa10_joint_3", 0.05)];
        g.goal_tolerance = vec![tol("pa10_joint_2", -1.0), tol("pa10_joint_6", 0.0)];
        g.goal_time_tolerance = Duration {
            sec: 2,
            nanosec: 500_000_000,
        };
        let r = goal_request(&g, NOW, &Q0).unwrap();
        assert_eq!(r["path_tolerance"], json!([0.0, 0.0, 0.05, 0.0, 0.0, 0.0]));
        assert_eq!(
            r["goal_tolerance"],
            json!([0.005, 0.0, 0.005, 0.005, 0.005, 0.005])
        );
        assert_eq!(r["goal_time_tolerance"], 2.5);
    }

    #[test]
    fn refusals_carry_the_code_and_name_what_is_wrong() {
        let ok = goal([0, 1, 2, 3, 4, 5], &[(Q1, 1.0)]);
        let check = |g: FollowJointTrajectoryGoal, code: i32, words: &str| {
            let e = goal_request(&g, NOW, &Q0).unwrap_err();
            assert_eq!(e.code, code, "{e}");
            assert!(e.message.contains(words), "{e}");
        };
        let mut g = ok.clone();
        g.trajectory.joint_names[4] = "elbow".into();
        check(g, code::INVALID_JOINTS, "unknown joint \"elbow\"");
        let mut g = ok.clone();
        g.trajectory.joint_names[4] = "pa10_joint_1".into();
        check(g, code::INVALID_JOINTS, "named twice");
        let mut g = ok.clone();
        g.trajectory.joint_names.pop();
        check(g, code::INVALID_JOINTS, "names 5 joints");
        let mut g = ok.clone();
        g.trajectory.points.clear();
        check(g, code::INVALID_GOAL, "no points");
        let mut g = ok.clone();
        g.trajectory.points[0].positions[2] = f64::NAN;
        check(g, code::INVALID_GOAL, "pa10_joint_3 is not a finite number");
        let mut g = ok.clone();
        g.trajectory.points[0].velocities = vec![0.0; 5];
        check(g, code::INVALID_GOAL, "point 0 velocities: 5 values");
        let mut g = ok.clone();
        g.trajectory.points[0].effort = vec![0.0; 6];
        check(g, code::INVALID_GOAL, "effort is not supported");
        let mut g = ok.clone();
        g.trajectory.points[0].time_from_start.nanosec = 1_000_000_000;
        check(g, code::INVALID_GOAL, "point 0: time_from_start");
        let mut g = ok.clone();
        g.multi_dof_trajectory.joint_names = vec!["base".into()];
        check(g, code::INVALID_JOINTS, "multi-DOF");
        let mut g = ok.clone();
        g.component_goal_tolerance = vec![JointComponentTolerance::default()];
        check(g, code::INVALID_GOAL, "component tolerances");
        let mut g = ok.clone();
        g.path_tolerance = vec![JointTolerance {
            name: "pa10_joint_1".into(),
            velocity: 0.1,
            ..Default::default()
        }];
        check(
            g,
            code::INVALID_GOAL,
            "velocity tolerances are not supported",
        );
        let mut g = ok.clone();
        g.goal_tolerance = vec![JointTolerance {
            name: "wrist".into(),
            ..Default::default()
        }];
        check(g, code::INVALID_JOINTS, "goal_tolerance: unknown joint");
        // a start state that is not where the arm is
        let g = goal([0, 1, 2, 3, 4, 5], &[(Q1, 0.0), (Q0, 1.0)]);
        check(
            g,
            code::INVALID_GOAL,
            "point 0 at time 0 is 0.1000 rad from the arm on pa10_joint_1",
        );
        // only a start state
        let g = goal([0, 1, 2, 3, 4, 5], &[(Q0, 0.0)]);
        check(g, code::INVALID_GOAL, "only its start state");
        // stamps: over already, or a delayed start
        let mut g = ok.clone();
        g.trajectory.header.stamp = Time {
            sec: NOW.sec - 10,
            nanosec: 0,
        };
        check(g, code::OLD_HEADER_TIMESTAMP, "ended 9.000 s ago");
        let mut g = ok.clone();
        g.trajectory.header.stamp = Time {
            sec: NOW.sec + 3,
            nanosec: 0,
        };
        check(g, code::INVALID_GOAL, "in the future");
        // a stamp of now (within the slack) starts now
        let mut g = ok;
        g.trajectory.header.stamp = NOW;
        assert!(goal_request(&g, NOW, &Q0).is_ok());
    }

    fn report(state: &str, result: &str) -> TrajectoryReport {
        TrajectoryReport {
            id: 3,
            state: state.into(),
            result: result.into(),
            error: [0.0, -0.02, 0.001, 0.0, 0.0, 0.0],
            ..Default::default()
        }
    }

    #[test]
    fn every_ending_has_its_status_and_code() {
        assert_eq!(goal_result(&report("executing", ""), false, None), None);
        let cases = [
            (
                "succeeded",
                "succeeded",
                false,
                Ending::Succeeded,
                code::SUCCESSFUL,
            ),
            (
                "aborted",
                "path_tolerance_violated",
                false,
                Ending::Aborted,
                code::PATH_TOLERANCE_VIOLATED,
            ),
            (
                "aborted",
                "goal_tolerance_violated",
                false,
                Ending::Aborted,
                code::GOAL_TOLERANCE_VIOLATED,
            ),
            (
                "aborted",
                "stopped",
                true,
                Ending::Canceled,
                code::SUCCESSFUL,
            ),
            (
                "aborted",
                "stopped",
                false,
                Ending::Aborted,
                code::INVALID_GOAL,
            ),
            (
                "preempted",
                "preempted",
                false,
                Ending::Canceled,
                code::INVALID_GOAL,
            ),
            (
                "aborted",
                "fault",
                false,
                Ending::Aborted,
                code::INVALID_GOAL,
            ),
        ];
        for (state, why, canceling, ending, c) in cases {
            let (e, r) = goal_result(&report(state, why), canceling, Some("watchdog")).unwrap();
            assert_eq!((e, r.error_code), (ending, c), "{state}/{why}");
        }
        let (_, r) =
            goal_result(&report("aborted", "path_tolerance_violated"), false, None).unwrap();
        assert!(
            r.error_string.contains("pa10_joint_2: error -0.02000 rad"),
            "{r:?}"
        );
        let (_, r) = goal_result(&report("aborted", "fault"), false, Some("watchdog")).unwrap();
        assert!(r.error_string.contains("watchdog"), "{r:?}");
    }

    #[test]
    fn diagnostics_rate_the_daemon() {
        let st = json!({"state":"holding","fault":null,"cycle":{"cycles":10,"jitter_us":[50,100,300]},"link":{}});
        let d = diagnostics(&st, NOW);
        assert_eq!(d.status[0].level, level::OK);
        assert!(
            d.status[0]
                .values
                .iter()
                .any(|kv| kv.key == "cycles" && kv.value == "10")
        );
        let st = json!({"state":"fault","fault":"servo controller: watchdog","cycle":{},"link":{}});
        let d = diagnostics(&st, NOW);
        assert_eq!(d.status[0].level, level::ERROR);
        assert!(d.status[0].message.contains("watchdog"));
        let st =
            json!({"state":"holding","fault":null,"cycle":{"jitter_us":[50,900,3000]},"link":{}});
        assert_eq!(diagnostics(&st, NOW).status[0].level, level::WARN);
        let st = json!({"state":"starting","fault":null,"cycle":{},"link":{}});
        assert_eq!(diagnostics(&st, NOW).status[0].level, level::WARN);
    }

    #[test]
    fn a_goal_too_long_for_one_request_line_is_refused_by_its_size() {
        // a MoveIt-like plan: positions, velocities and accelerations on every point
        let plan = |n: usize| {
            let mut g = goal(
                [0, 1, 2, 3, 4, 5],
                &(1..=n)
                    .map(|i| {
                        let s = i as f64 / n as f64;
                        (
                            std::array::from_fn(|j| Q0[j] + 0.3 * s + 1e-7 / 3.0),
                            0.01 * i as f64,
                        )
                    })
                    .collect::<Vec<_>>(),
            );
            for p in &mut g.trajectory.points {
                p.velocities = vec![0.123_456_789_123; 6];
                p.accelerations = vec![-0.987_654_321_987; 6];
            }
            g
        };
        let r = goal_request(&plan(200), NOW, &Q0).unwrap();
        assert!(r.to_string().len() < MAX_LINE_BYTES);
        // sent to 1e-9
        assert_eq!(r["points"][0]["velocities"][0], 0.123_456_789);
        let e = goal_request(&plan(MAX_POINTS + 1), NOW, &Q0).unwrap_err();
        assert_eq!(e.code, code::INVALID_GOAL);
        assert!(
            e.message
                .contains("2001 points: pa10d follows at most 2000"),
            "{e}"
        );
        let e = goal_request(&plan(2000), NOW, &Q0).unwrap_err();
        assert_eq!(e.code, code::INVALID_GOAL);
        assert!(e.message.contains("2000 points make a"), "{e}");
        assert!(e.message.contains("send fewer points"), "{e}");
        eprintln!("{e}");
    }

    #[test]
    fn times_and_durations_round_trip() {
        let t = Time::from_secs(1_800_000_000.25);
        assert_eq!((t.sec, t.nanosec), (1_800_000_000, 250_000_000));
        assert!((Duration::from_secs(2.5).secs().unwrap() - 2.5).abs() < 1e-12);
    }
}

/// The messages ros2-client carries in its services and actions (feature `ros2`).
#[cfg(feature = "ros2")]
mod dds {
    use super::*;
    impl ros2_client::Message for FollowJointTrajectoryGoal {}
    impl ros2_client::Message for FollowJointTrajectoryResult {}
    impl ros2_client::Message for FollowJointTrajectoryFeedback {}
    impl ros2_client::Message for TriggerRequest {}
    impl ros2_client::Message for TriggerResponse {}
}
