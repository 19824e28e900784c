//! What clients hand the core and read back: the typed [`Command`]s (with the [`PlanBasis`]
//! a move was planned from), who sent them ([`ClientId`]) (the [`Status`](crate::daemon::wire::Status) snapshot is the wire's).

use std::sync::Arc;

use crate::daemon::control::{Stream, Tolerances};
use crate::daemon::plan::{Limits, Move, TrajectoryPoint};
use crate::model::Model;
use crate::record::RecordTap;

/// What a move was planned from: the model, the link setpoint and the limits, taken under the
/// lock, used outside it. A [`Command::Start`] is refused when the setpoint or the model has
/// changed since.
#[derive(Debug, Clone)]
pub struct PlanBasis {
    /// The model in use.
    pub model: Arc<Model>,
    /// The link-side setpoint the move starts from, rad.
    pub from: [f64; 6],
    /// The limits in force (the model's position limits, the loop's speed and
    /// acceleration limits).
    pub limits: Limits,
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
    LoadModel {
        /// The model.
        model: Arc<Model>,
        /// The file it was read from, for `status.model`.
        file: String,
    },
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
            Command::LoadModel { .. } => "load_model",
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
