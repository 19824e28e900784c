//! What clients hand the core and read back: the typed [`Command`]s (with the [`PlanBasis`]
//! a move was planned from), who sent them ([`ClientId`]) and the [`Status`] snapshot.

use std::sync::Arc;

use serde::Serialize;

use crate::daemon::control::{Stream, Tolerances, TrajectoryStatus};
use crate::daemon::link::LinkCounters;
use crate::daemon::motion::Move;
use crate::daemon::stats::CycleStats;
use crate::daemon::trajectory::TrajectoryPoint;
use crate::model::Model;
use crate::record::{RecordTap, RecordingStatus};

/// What a move was planned from: the model, the link setpoint and the limits, taken under the
/// lock, used outside it. A [`Command::Start`] is refused when the setpoint or the model has
/// changed since.
#[derive(Debug, Clone)]
pub struct PlanBasis {
    /// The model in use.
    pub model: Arc<Model>,
    /// The link-side setpoint the move starts from, rad.
    pub from: [f64; 6],
    /// Speed limits, rad/s.
    pub speed: [f64; 6],
    /// Acceleration limits, rad/s².
    pub acceleration: [f64; 6],
}

/// A client's command.
#[derive(Debug)]
pub enum Command {
    /// Start a move planned from `basis`.
    Start {
        /// The planned move.
        mv: Box<Move>,
        /// What it was planned from.
        basis: PlanBasis,
    },
    /// Controlled stop.
    Stop,
    /// Immediate servo stop, brakes on; a fault until reset.
    Estop,
    /// Clear a fault; bring the controller back to control mode when it left it.
    Reset,
    /// The payload: weight, N, and centre of mass in the tool frame, m.
    SetPayload {
        /// Weight, N.
        newtons: f64,
        /// Centre of mass in the tool frame, m.
        com: [f64; 3],
    },
    /// A new tool transform (flange → tool): compensation and Cartesian commands use it.
    SetTool(Box<crate::model::Frame>),
    /// Replace the model between moves (parsed by the caller).
    LoadModel(Arc<Model>),
    /// Bring the arm to rest, stop the servo and close the link.
    Shutdown,
    /// Follow a timed trajectory from the current setpoint (replacing what runs).
    FollowTrajectory {
        /// The waypoints.
        points: Vec<TrajectoryPoint>,
        /// Its tolerances.
        tolerances: Tolerances,
        /// What the points were planned from (a Cartesian trajectory's IK): refused as
        /// stale if the setpoint or the model changed since. `None`: from whatever runs.
        basis: Option<PlanBasis>,
    },
    /// Slow running and future trajectories and streams, 0 < f ≤ 1.
    SetSpeedScaling(f64),
    /// A streamed servo target or jog velocity.
    Stream(Stream),
    /// Take the motion lease for the submitting client.
    Acquire,
    /// Give the motion lease back.
    Release,
    /// The submitting client's connection closed: its lease ends (stopping what it moved).
    Disconnected,
    /// Start recording every cycle into this tap (see `record`).
    Record(Box<RecordTap>),
    /// Stop recording (the writer closes the file).
    RecordStop,
}

impl Command {
    /// The command's name, as the API spells it (recordings log it).
    pub fn name(&self) -> &'static str {
        match self {
            Command::Start { .. } => "move",
            Command::Stop => "stop",
            Command::Estop => "estop",
            Command::Reset => "reset",
            Command::SetPayload { .. } => "set_payload",
            Command::SetTool(_) => "set_tool",
            Command::LoadModel(_) => "load_model",
            Command::Shutdown => "shutdown",
            Command::FollowTrajectory { .. } => "follow_trajectory",
            Command::SetSpeedScaling(_) => "set_speed_scaling",
            Command::Stream(Stream::Servo(_)) => "servo",
            Command::Stream(_) => "jog",
            Command::Acquire => "acquire",
            Command::Release => "release",
            Command::Disconnected => "disconnected",
            Command::Record(_) => "record_start",
            Command::RecordStop => "record_stop",
        }
    }
}

/// Who submits a command: a connection's id, or [`LOCAL`] for in-process callers.
pub type ClientId = u64;

/// The in-process caller (the daemon itself, tests, examples).
pub const LOCAL: ClientId = 0;

/// What `status` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Status {
    /// starting, holding, moving, stopping, fault, closed.
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
    /// The daemon's clock, s since it started (the last cycle or event it saw).
    pub time_s: f64,
    /// Joint torque estimate the compensation used last cycle, N·m.
    pub tau: [f64; 6],
    /// Tool position of the setpoint, m (base frame).
    pub tool_position: [f64; 3],
    /// Tool orientation of the setpoint, quaternion w, x, y, z.
    pub tool_quaternion: [f64; 4],
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
    pub stream_end: Option<&'static str>,
    /// Whether a client holds the motion lease.
    pub leased: bool,
    /// The recording in progress, or the last one.
    pub recording: Option<RecordingStatus>,
}
