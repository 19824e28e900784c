//! The client protocol's one vocabulary (`docs/api.md`): [`ApiRequest`] (what a client
//! sends), [`Reply`] (what the daemon answers, [`Answer`] or a refusal) and the [`Status`]
//! snapshot with its [`State`]. Every type both serialises and parses, so `pa10d`, the `pa10`
//! CLI, the ROS 2 bridge and the tests speak it through the same code; [`schema`] is the JSON
//! Schema generated from these types, published as `docs/api.schema.json`.
//!
//! A request and its reply, as a client sends and reads them:
//!
//! ```
//! use pa10::daemon::wire::{Answer, ApiRequest, Reply};
//!
//! let req: ApiRequest = serde_json::from_str(r#"{"cmd":"move_joints","q":[0,0.5,1.5,0,1,0]}"#)?;
//! assert_eq!(req, ApiRequest::MoveJoints { q: [0.0, 0.5, 1.5, 0.0, 1.0, 0.0] });
//! let reply: Reply = serde_json::from_str(r#"{"ok":true,"duration_s":1.25}"#)?;
//! assert_eq!(reply, Reply::Ok(Answer::Moving { duration_s: 1.25 }));
//! let refusal: Reply = serde_json::from_str(r#"{"ok":false,"error":"joint 2 out of range"}"#)?;
//! assert_eq!(refusal.into_result().unwrap_err().to_string(), "joint 2 out of range");
//! # Ok::<(), serde_json::Error>(())
//! ```

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::daemon::control::TrajectoryStatus;
use crate::daemon::link::LinkCounters;
use crate::daemon::plan::{CartesianPoint, TrajectoryPoint};
use crate::daemon::timing::CycleStats;
use crate::record::{Mode, RecordingStatus};

/// A client request: one JSON object a line, `cmd` naming it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum ApiRequest {
    /// The daemon's state.
    Status {},
    /// A joint move to `q` (link angles, rad).
    MoveJoints {
        /// Target, rad.
        q: [f64; 6],
    },
    /// A straight-line tool move to a pose (base frame, m, quaternion w, x, y, z).
    MovePose {
        /// Position, m.
        position: [f64; 3],
        /// Unit quaternion w, x, y, z.
        quaternion: [f64; 4],
    },
    /// Controlled stop.
    Stop {},
    /// Immediate servo stop and brakes.
    Estop {},
    /// Clears a fault.
    Reset {},
    /// Sets the payload: its weight (`newtons`, or `mass_kg` under the model's gravity) and
    /// its centre of mass in the tool frame (`com`, m; default the tool origin).
    SetPayload {
        /// Weight, N.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        newtons: Option<f64>,
        /// Mass, kg.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        mass_kg: Option<f64>,
        /// Centre of mass in the tool frame, m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        com: Option<[f64; 3]>,
    },
    /// Sets the tool transform (flange → tool): translation, m, and a unit quaternion
    /// w, x, y, z. Compensation and Cartesian commands use it at once.
    SetTool {
        /// Translation, m.
        translation: [f64; 3],
        /// Unit quaternion w, x, y, z.
        quaternion: [f64; 4],
    },
    /// Hot-reloads a model file between moves.
    LoadModel {
        /// Path of the model YAML.
        path: String,
    },
    /// Streams `status` at `rate_hz` until the client disconnects.
    Subscribe {
        /// Hz (0.1…100).
        #[schemars(range(min = 0.1, max = 100.0))]
        rate_hz: f64,
    },
    /// Follows a timed joint trajectory (link side), replacing what runs.
    FollowTrajectory {
        /// Waypoints.
        points: Vec<TrajectoryPoint>,
        /// Per-joint path tolerance, rad (0: unchecked; default unchecked).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path_tolerance: Option<[f64; 6]>,
        /// Per-joint goal tolerance, rad (0: unchecked; default 0.005).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        goal_tolerance: Option<[f64; 6]>,
        /// Time after the end the goal may still be reached, s (default 1).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        goal_time_tolerance: Option<f64>,
    },
    /// Follows tool-pose waypoints, straight lines between them (from holding).
    FollowCartesian {
        /// Waypoints.
        points: Vec<CartesianPoint>,
        /// Per-joint path tolerance, rad (0: unchecked; default unchecked).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path_tolerance: Option<[f64; 6]>,
        /// Per-joint goal tolerance, rad (0: unchecked; default 0.005).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        goal_tolerance: Option<[f64; 6]>,
        /// Time after the end the goal may still be reached, s (default 1).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        goal_time_tolerance: Option<f64>,
    },
    /// A streamed setpoint: link positions (rad), or a tool pose.
    Servo {
        /// Link positions, rad.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        positions: Option<[f64; 6]>,
        /// Tool position, m (base frame), with `quaternion`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position: Option<[f64; 3]>,
        /// Tool orientation, unit quaternion w, x, y, z.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        quaternion: Option<[f64; 4]>,
    },
    /// Streamed joint velocities, rad/s.
    Jog {
        /// Link velocities, rad/s.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        joint_velocities: Option<[f64; 6]>,
        /// A tool twist: vx, vy, vz (m/s), wx, wy, wz (rad/s).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tool_twist: Option<[f64; 6]>,
        /// The twist's frame: `base` (default) or `tool`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        frame: Option<String>,
    },
    /// Slows running and future trajectories and streams, 0 < f ≤ 1.
    SetSpeedScaling {
        /// The fraction of full speed.
        #[schemars(range(max = 1.0))]
        fraction: f64,
    },
    /// Starts recording every cycle to an MCAP file inside `record.dir`.
    RecordStart {
        /// A plain file name (default `pa10d-<unix time>.mcap`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        file: Option<String>,
        /// Stop after this long, s (default: until `record_stop`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration_s: Option<f64>,
    },
    /// Stops recording.
    RecordStop {},
    /// Takes the motion lease for this connection.
    Acquire {},
    /// Gives the motion lease back.
    Release {},
}

impl ApiRequest {
    /// Every request's `cmd`, in declaration order.
    pub const NAMES: [&'static str; 19] = [
        "status",
        "move_joints",
        "move_pose",
        "stop",
        "estop",
        "reset",
        "set_payload",
        "set_tool",
        "load_model",
        "subscribe",
        "follow_trajectory",
        "follow_cartesian",
        "servo",
        "jog",
        "set_speed_scaling",
        "record_start",
        "record_stop",
        "acquire",
        "release",
    ];

    /// This request's `cmd`.
    pub const fn name(&self) -> &'static str {
        match self {
            ApiRequest::Status { .. } => "status",
            ApiRequest::MoveJoints { .. } => "move_joints",
            ApiRequest::MovePose { .. } => "move_pose",
            ApiRequest::Stop { .. } => "stop",
            ApiRequest::Estop { .. } => "estop",
            ApiRequest::Reset { .. } => "reset",
            ApiRequest::SetPayload { .. } => "set_payload",
            ApiRequest::SetTool { .. } => "set_tool",
            ApiRequest::LoadModel { .. } => "load_model",
            ApiRequest::Subscribe { .. } => "subscribe",
            ApiRequest::FollowTrajectory { .. } => "follow_trajectory",
            ApiRequest::FollowCartesian { .. } => "follow_cartesian",
            ApiRequest::Servo { .. } => "servo",
            ApiRequest::Jog { .. } => "jog",
            ApiRequest::SetSpeedScaling { .. } => "set_speed_scaling",
            ApiRequest::RecordStart { .. } => "record_start",
            ApiRequest::RecordStop { .. } => "record_stop",
            ApiRequest::Acquire { .. } => "acquire",
            ApiRequest::Release { .. } => "release",
        }
    }

    /// The `cmd` a line that did not parse names, when it is one of [`ApiRequest::NAMES`]
    /// (so that a refusal is logged under its request); `""` otherwise.
    pub fn name_in(line: &str) -> &'static str {
        #[derive(Deserialize)]
        struct Cmd<'a> {
            #[serde(borrow)]
            cmd: std::borrow::Cow<'a, str>,
        }
        serde_json::from_str::<Cmd>(line)
            .ok()
            .and_then(|c| Self::NAMES.iter().find(|n| **n == c.cmd).copied())
            .unwrap_or("")
    }
}

/// What the daemon is doing, as `status.state` says it: the loop's [`Mode`], or that it is not
/// (yet, or any more) in control.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum State {
    /// The session with the servo controller is being brought up (or restarted).
    Starting,
    /// Holding the setpoint.
    Holding,
    /// Running a planned move.
    Moving,
    /// Following a timed trajectory.
    Following,
    /// Following a servo, jog or twist stream.
    Streaming,
    /// Decelerating to rest.
    Stopping,
    /// Stopped by a fault (or the start failed); commands zero until `reset`.
    Fault,
    /// The link is closed (shut down).
    Closed,
}

impl From<Mode> for State {
    fn from(m: Mode) -> Self {
        match m {
            Mode::Holding => State::Holding,
            Mode::Moving => State::Moving,
            Mode::Following => State::Following,
            Mode::Streaming => State::Streaming,
            Mode::Stopping => State::Stopping,
            Mode::Faulted => State::Fault,
        }
    }
}

impl State {
    /// The name on the wire (`holding`, `fault`, …).
    pub const fn name(self) -> &'static str {
        match self {
            State::Starting => "starting",
            State::Holding => "holding",
            State::Moving => "moving",
            State::Following => "following",
            State::Streaming => "streaming",
            State::Stopping => "stopping",
            State::Fault => "fault",
            State::Closed => "closed",
        }
    }
}

impl std::fmt::Display for State {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What `status` reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Status {
    /// What the daemon is doing.
    pub state: State,
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
    /// The daemon's clock, s since it started (the last cycle or event it saw).
    pub time_s: f64,
    /// Joint torque estimate the compensation used last cycle, N·m.
    pub tau: [f64; 6],
    /// Tool position of the setpoint, m (base frame).
    pub tool_position: [f64; 3],
    /// Tool orientation of the setpoint, quaternion w, x, y, z.
    pub tool_quaternion: [f64; 4],
    /// How accurate the arm is here: the tool position's predicted 1σ uncertainty at the
    /// setpoint (3-D rms), mm — the calibration's parameter covariance ⊕ the resolvers' floor;
    /// absent for a model without one (nominal).
    #[serde(default)]
    pub position_sigma_mm: Option<f64>,
    /// Payload, N.
    pub payload_n: f64,
    /// The payload's centre of mass in the tool frame, m.
    pub payload_com: [f64; 3],
    /// Link counters.
    pub link: LinkCounters,
    /// Cycle statistics.
    pub cycle: CycleStats,
    /// The latest trajectory.
    pub trajectory: TrajectoryStatus,
    /// Speed scaling in force, 0 < f ≤ 1 (it ramps toward what was asked).
    pub speed_scaling: f64,
    /// Why the last servo or jog stream ended (a missed deadline), if it did.
    pub stream_end: Option<String>,
    /// Whether a client holds the motion lease.
    pub leased: bool,
    /// The recording in progress, or the last one.
    pub recording: Option<RecordingStatus>,
    /// The model the compensation uses.
    #[serde(default)]
    pub model: Option<ModelStatus>,
    /// The last request the daemon refused (any client), in its words.
    #[serde(default)]
    pub last_refusal: Option<RefusalStatus>,
    /// In position: holding, every motor still and within its holding band of the
    /// compensated target (`control.hold_deadband`, widened where a sticking drive hunted;
    /// docs/daemon.md). What a client waits for before it measures.
    #[serde(default)]
    pub in_position: bool,
}

/// What a model holds, from its contents.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// The nominal table: no identified departures, no covariance.
    Nominal,
    /// `pa10 calibrate`'s: identified departures (and their covariance).
    Calibrated,
    /// A calibrated model that `pa10 discover` extended with named effects.
    Extended,
}

impl ModelKind {
    /// Its name, as the wire spells it.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Nominal => "nominal",
            ModelKind::Calibrated => "calibrated",
            ModelKind::Extended => "extended",
        }
    }
}

/// The model in force (`status.model`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ModelStatus {
    /// The file it was read from: the configuration's `model:` or the last `load_model`'s
    /// path, as the daemon resolved it.
    pub file: String,
    /// What it holds.
    pub kind: ModelKind,
    /// The joints (1…6) it gives a spring.
    pub springs: Vec<u8>,
    /// The joints (1…6) whose friction it holds (`pa10 identify`).
    pub friction: Vec<u8>,
    /// The effects `pa10 discover` added, `name[Jn]`.
    pub discovered: Vec<String>,
    /// When it came into force, s on the daemon's clock (as `time_s`).
    pub since_s: f64,
}

/// A refused request (`status.last_refusal`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RefusalStatus {
    /// The request's `cmd` (empty when the line was not a request).
    pub request: String,
    /// The refusal's words, as the client read them.
    pub error: String,
    /// When, s on the daemon's clock (as `time_s`).
    pub time_s: f64,
}

/// What an accepted request answers.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// Accepted; nothing to report (`{"ok":true}`).
    Done,
    /// `status` and each `subscribe` sample.
    Status(Box<Status>),
    /// `move_joints`, `move_pose`: the planned move's duration, s.
    Moving {
        /// s.
        duration_s: f64,
    },
    /// `follow_trajectory`, `follow_cartesian`: the trajectory's id (`status.trajectory.id`).
    Following {
        /// From 1.
        id: u64,
    },
    /// `record_start`: the recording's first file.
    Recording {
        /// Its path on the daemon's machine.
        path: String,
    },
}

/// The daemon's answer to one request: accepted, or refused with the reason (which changed
/// nothing). On the wire `{"ok":true, …}` or `{"ok":false,"error":"…"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(into = "ReplyWire", try_from = "ReplyWire")]
pub enum Reply {
    /// Accepted.
    Ok(Answer),
    /// Refused, with the daemon's words.
    Refused(String),
}

/// A refusal's words, as an error.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

impl Reply {
    /// The answer, or the refusal as an error.
    pub fn into_result(self) -> Result<Answer, Refused> {
        match self {
            Reply::Ok(a) => Ok(a),
            Reply::Refused(e) => Err(Refused(e)),
        }
    }

    /// The status this reply carries, if it does.
    pub fn status(&self) -> Option<&Status> {
        match self {
            Reply::Ok(Answer::Status(s)) => Some(s),
            _ => None,
        }
    }
}

impl From<Answer> for Reply {
    fn from(a: Answer) -> Self {
        Reply::Ok(a)
    }
}

/// The wire form of a [`Reply`]: `ok`, then the one field its answer has.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
struct ReplyWire {
    /// Whether the request was accepted.
    ok: bool,
    /// Why it was refused (with `ok: false` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    /// The status (`status`, `subscribe`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    status: Option<Box<Status>>,
    /// The planned move's duration, s (`move_joints`, `move_pose`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    duration_s: Option<f64>,
    /// The trajectory's id (`follow_trajectory`, `follow_cartesian`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    id: Option<u64>,
    /// The recording's first file (`record_start`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    path: Option<String>,
}

impl From<Reply> for ReplyWire {
    fn from(r: Reply) -> Self {
        let ok = ReplyWire {
            ok: true,
            ..Default::default()
        };
        match r {
            Reply::Refused(e) => ReplyWire {
                error: Some(e),
                ..Default::default()
            },
            Reply::Ok(Answer::Done) => ok,
            Reply::Ok(Answer::Status(s)) => ReplyWire {
                status: Some(s),
                ..ok
            },
            Reply::Ok(Answer::Moving { duration_s }) => ReplyWire {
                duration_s: Some(duration_s),
                ..ok
            },
            Reply::Ok(Answer::Following { id }) => ReplyWire { id: Some(id), ..ok },
            Reply::Ok(Answer::Recording { path }) => ReplyWire {
                path: Some(path),
                ..ok
            },
        }
    }
}

impl TryFrom<ReplyWire> for Reply {
    type Error = String;

    fn try_from(w: ReplyWire) -> Result<Self, String> {
        Ok(match w {
            ReplyWire {
                ok: false,
                error: Some(e),
                status: None,
                duration_s: None,
                id: None,
                path: None,
            } => Reply::Refused(e),
            ReplyWire {
                ok: true,
                error: None,
                status,
                duration_s,
                id,
                path,
            } => match (status, duration_s, id, path) {
                (None, None, None, None) => Reply::Ok(Answer::Done),
                (Some(s), None, None, None) => Reply::Ok(Answer::Status(s)),
                (None, Some(duration_s), None, None) => Reply::Ok(Answer::Moving { duration_s }),
                (None, None, Some(id), None) => Reply::Ok(Answer::Following { id }),
                (None, None, None, Some(path)) => Reply::Ok(Answer::Recording { path }),
                _ => {
                    return Err(
                        "a reply carries at most one of status, duration_s, id, path".into(),
                    );
                }
            },
            ReplyWire { ok: false, .. } => {
                return Err("a refusal (ok: false) carries an error and nothing else".into());
            }
            ReplyWire { ok: true, .. } => return Err("an accepted reply carries no error".into()),
        })
    }
}

/// The protocol's JSON Schema (draft 2020-12): `request` and `reply` under `$defs`, the
/// document itself accepting either. `docs/api.schema.json` is this, pretty-printed; a test
/// keeps the two equal (`pa10 api-schema` prints it).
pub fn schema() -> serde_json::Value {
    let mut generator = schemars::generate::SchemaSettings::draft2020_12().into_generator();
    let request = generator.subschema_for::<ApiRequest>();
    let reply = generator.subschema_for::<Reply>();
    let mut doc = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "pa10d client protocol",
        "description": "One JSON object a line over pa10d's Unix socket: a request (`cmd`), then its reply (`ok`). Generated from pa10::daemon::wire; see docs/api.md.",
        "oneOf": [request, reply],
    });
    doc["$defs"] = serde_json::Value::Object(generator.take_definitions(true));
    doc
}

#[cfg(test)]
mod tests;
