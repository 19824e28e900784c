//! Motion planning, off the control cycle: synchronised joint moves and straight-line tool
//! moves (`moves.rs`), timed joint trajectories as a planner sends them (`trajectory.rs`) and
//! timed tool-pose waypoints turned into joint trajectories (`cartesian.rs`). Plain functions
//! of the model, the limits ([`Limits`]) and the setpoint a plan starts from; no clock, no
//! lock: the API plans outside the core's lock and hands the result over, and the loop only
//! samples what was planned.

mod cartesian;
mod moves;
mod trajectory;

pub use super::vocab::{Limits, Setpoint};
pub use cartesian::{CartesianPoint, MAX_WAYPOINTS, cartesian_waypoints};
pub use moves::{Move, MoveError, Profile, interpolate};
pub use trajectory::{MAX_POINTS, Trajectory, TrajectoryError, TrajectoryPoint, TrajectorySample};
