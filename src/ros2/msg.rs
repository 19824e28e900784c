//! The ROS 2 messages the bridge speaks, field by field in the order of their IDL (CDR has
//! no field names: the order *is* the type): builtin_interfaces, std_msgs, sensor_msgs,
//! trajectory_msgs, geometry_msgs, control_msgs' FollowJointTrajectory, std_srvs' Trigger,
//! diagnostic_msgs. Plain data; units as in ROS (radians, seconds).

use serde::{Deserialize, Serialize};

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
pub struct JointStateMsg {
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
