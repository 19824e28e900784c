//! Cartesian trajectories (`follow_cartesian`): timed tool-pose waypoints turned into a joint
//! trajectory — a straight line of the tool between consecutive waypoints (position linear,
//! orientation by slerp) under a rest-to-rest quintic time scaling, solved by IK nearest to the
//! previous sample and checked against the limits. The joint trajectory is then planned and
//! checked like any other (`trajectory.rs`). Pure functions, no clock.

use super::moves::{MoveError, ik_step, interpolate};
use super::trajectory::{MAX_POINTS, TrajectoryPoint};
use crate::daemon::vocab::Limits;
use crate::model::Model;

/// A tool-pose waypoint of `follow_cartesian` (base frame).
#[derive(
    Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct CartesianPoint {
    /// Tool position, m.
    pub position: [f64; 3],
    /// Tool orientation, unit quaternion w, x, y, z.
    pub quaternion: [f64; 4],
    /// Time of this waypoint from the start, s (at speed scaling 1).
    pub time_from_start: f64,
}

/// At most this many Cartesian waypoints.
pub const MAX_WAYPOINTS: usize = 200;
/// Largest spacing of the joint samples of a Cartesian trajectory, s.
const CARTESIAN_SAMPLE_S: f64 = 0.02;

/// Joint waypoints for tool-pose `waypoints` from the link angles `q_start` (the tool's pose
/// there is the start): between consecutive waypoints the tool moves on a straight line
/// (position linear, orientation by slerp) under a smooth rest-to-rest time scaling
/// (quintic: at rest at every waypoint), sampled at most every 20 ms and solved by IK
/// nearest to the previous sample. The result is a joint trajectory for
/// [`super::Trajectory::plan`], whose checks (speed, acceleration) still apply.
pub fn cartesian_waypoints(
    model: &Model,
    lim: &Limits,
    q_start: [f64; 6],
    waypoints: &[CartesianPoint],
) -> Result<Vec<TrajectoryPoint>, MoveError> {
    if waypoints.is_empty() || waypoints.len() > MAX_WAYPOINTS {
        return Err(MoveError::Waypoint {
            point: waypoints.len(),
            percent: 0.0,
            reason: format!("a Cartesian trajectory needs 1…{MAX_WAYPOINTS} waypoints"),
        });
    }
    let total = waypoints[waypoints.len() - 1].time_from_start;
    let step = CARTESIAN_SAMPLE_S.max(total / (MAX_POINTS as f64 - 10.0));
    let mut from = model.fk(&q_start);
    let (mut q, mut t0) = (q_start, 0.0);
    let mut out = Vec::new();
    for (i, w) in waypoints.iter().enumerate() {
        let bad = |reason: String| MoveError::Waypoint {
            point: i,
            percent: 100.0,
            reason,
        };
        let n = w.quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !w
            .position
            .iter()
            .chain(&w.quaternion)
            .all(|v| v.is_finite())
            || (n - 1.0).abs() > 1e-3
        {
            return Err(bad(format!(
                "position must be finite (m) and quaternion a unit [w, x, y, z] (norm {n})"
            )));
        }
        if !(w.time_from_start.is_finite() && w.time_from_start > t0) {
            return Err(bad(format!(
                "time_from_start {} s must be greater than {t0} s",
                w.time_from_start
            )));
        }
        let to = crate::model::frame_from_pose(w.position, w.quaternion);
        let h = w.time_from_start - t0;
        let k_max = (h / step).ceil().max(1.0) as usize;
        for k in 1..=k_max {
            let u = k as f64 / k_max as f64;
            let s = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
            q = ik_step(model, lim, &interpolate(&from, &to, s), &q).map_err(|reason| {
                MoveError::Waypoint {
                    point: i,
                    percent: 100.0 * u,
                    reason,
                }
            })?;
            out.push(TrajectoryPoint {
                positions: q,
                velocities: None,
                accelerations: None,
                time_from_start: t0 + u * h,
            });
        }
        from = to;
        t0 = w.time_from_start;
    }
    Ok(out)
}
