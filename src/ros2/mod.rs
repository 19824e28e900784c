//! The pure core of the `pa10-ros2` bridge: the ROS 2 messages it speaks, declared field by
//! field in the order of their IDL (CDR has no field names, so the order *is* the type), and the
//! translations between them and `pa10d`'s protocol types ([`crate::daemon::wire`]) — a
//! `FollowJointTrajectory` goal into a `follow_trajectory` request (or the result code and
//! words that refuse it), the daemon's trajectory status into the action's feedback and
//! result, its status into `diagnostic_msgs/DiagnosticArray`. No DDS, no sockets, no clock: the binary
//! (`src/bin/pa10-ros2.rs`, feature `ros2`) passes the time in.
//!
//! Units as in ROS: radians, seconds; `builtin_interfaces` times and durations as whole
//! seconds plus nanoseconds.

use crate::daemon::api::MAX_LINE_BYTES;
use crate::daemon::control::{Tolerances, TrajectoryResult, TrajectoryState, TrajectoryStatus};
use crate::daemon::plan::{MAX_POINTS, TrajectoryPoint};
use crate::daemon::wire::{ApiRequest, State, Status};

pub use msg::*;

mod msg;

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
) -> Result<ApiRequest, GoalRefusal> {
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
        let optional = |v: &[f64], what: &str| {
            (!v.is_empty())
                .then(|| reorder(v, &order, &format!("point {i} {what}")))
                .transpose()
        };
        points.push(TrajectoryPoint {
            positions: q,
            velocities: optional(&p.velocities, "velocities")?,
            accelerations: optional(&p.accelerations, "accelerations")?,
            time_from_start: nano(tp),
        });
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
    let req = ApiRequest::FollowTrajectory {
        points,
        path_tolerance: Some(path),
        goal_tolerance: Some(goal_tol),
        goal_time_tolerance: Some(goal_time),
    };
    // the request's line on the socket, newline included
    let bytes = serde_json::to_vec(&req).map_or(usize::MAX, |v| v.len() + 1);
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
    t: &TrajectoryStatus,
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
    use TrajectoryResult as R;
    use TrajectoryState as S;
    Some(match (t.state, t.result) {
        (S::Executing | S::Idle, _) => return None,
        (S::Succeeded, _) => (Ending::Succeeded, r(code::SUCCESSFUL, String::new())),
        (_, R::PathToleranceViolated) => (
            Ending::Aborted,
            r(
                code::PATH_TOLERANCE_VIOLATED,
                format!(
                    "path tolerance violated on {}: error {e:.5} rad; the arm stopped",
                    JOINT_NAMES[j]
                ),
            ),
        ),
        (_, R::GoalToleranceViolated) => (
            Ending::Aborted,
            r(
                code::GOAL_TOLERANCE_VIOLATED,
                format!(
                    "goal tolerance violated on {}: error {e:.5} rad after the goal time tolerance",
                    JOINT_NAMES[j]
                ),
            ),
        ),
        (_, R::Stopped) if canceling => (Ending::Canceled, r(code::SUCCESSFUL, String::new())),
        (S::Preempted, _) => (
            Ending::Canceled,
            r(
                code::INVALID_GOAL,
                "replaced by a newer trajectory, move or stream".into(),
            ),
        ),
        (_, R::Fault) => (
            Ending::Aborted,
            r(
                code::INVALID_GOAL,
                format!("the arm faulted: {}", fault.unwrap_or("(no fault text)")),
            ),
        ),
        (_, R::Stopped) => (
            Ending::Aborted,
            r(
                code::INVALID_GOAL,
                "stopped by a stop request to pa10d".into(),
            ),
        ),
        (s, why) => (
            Ending::Aborted,
            r(code::INVALID_GOAL, format!("ended {s:?}: {why:?}")),
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
pub fn feedback(t: &TrajectoryStatus, now: Time) -> FollowJointTrajectoryFeedback {
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

/// What `/diagnostics` reports about the daemon, from its [`Status`] at wall-clock
/// `now`: level ERROR on a fault, WARN while not in control (starting, closed) or when the
/// loop's p99 wake-up jitter exceeds [`JITTER_WARN_US`], OK otherwise; the loop's, link's and
/// bus's numbers as key/values.
pub fn diagnostics(status: &Status, now: Time) -> DiagnosticArray {
    let state = status.state;
    let c = &status.cycle;
    let p99 = c.jitter_us[1];
    let (level, message) = match (&status.fault, state) {
        (Some(f), _) => (level::ERROR, format!("fault: {f}")),
        (None, State::Starting | State::Closed) => (level::WARN, state.to_string()),
        (None, _) if p99 > JITTER_WARN_US => (
            level::WARN,
            format!("{state}; p99 wake-up jitter {p99:.0} µs"),
        ),
        (None, _) => (level::OK, state.to_string()),
    };
    let triple = |v: &[f64; 3]| format!("{:.0} / {:.0} / {:.0}", v[0], v[1], v[2]);
    let l = &status.link;
    let values = [
        ("state", state.to_string()),
        ("fault", status.fault.clone().unwrap_or_default()),
        ("servo", status.servo.clone().unwrap_or_default()),
        ("cycles", c.cycles.to_string()),
        ("overruns", c.overruns.to_string()),
        ("jitter p50 / p99 / max [us]", triple(&c.jitter_us)),
        ("compute p50 / p99 / max [us]", triple(&c.compute_us)),
        ("bus load [%]", c.bus_load_pct.to_string()),
        ("incomplete feedback cycles", l.incomplete.to_string()),
        ("host pauses", l.paused.to_string()),
        ("stale frames", l.stale.to_string()),
        ("malformed frames", l.malformed.to_string()),
        ("controller errors", l.controller_errors.to_string()),
        ("speed scaling", status.speed_scaling.to_string()),
        ("leased", status.leased.to_string()),
        ("in position", status.in_position.to_string()),
        (
            "model",
            status
                .model
                .as_ref()
                .map(|m| format!("{} {}", m.kind.name(), m.file))
                .unwrap_or_default(),
        ),
        (
            "last refusal",
            status
                .last_refusal
                .as_ref()
                .map(|r| format!("{} at {:.1} s: {}", r.request, r.time_s, r.error))
                .unwrap_or_default(),
        ),
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
mod tests;

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
