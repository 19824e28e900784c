//! Motion: synchronised joint-space moves and straight-line Cartesian moves, each following
//! one smooth time-scaling `s(t)` from 0 to 1 with bounded acceleration and jerk.
//!
//! The profile ramps its acceleration up and down as a raised cosine (so acceleration is
//! continuous and jerk bounded), cruises, and decelerates symmetrically; it becomes a
//! two-ramp (no cruise) profile when the move is short. A joint move scales the profile by
//! each joint's displacement, so every joint starts and ends together and none exceeds its
//! speed or acceleration limit. A Cartesian move interpolates position linearly and
//! orientation by slerp, solves the IK on the (calibrated) model at every setpoint near the
//! previous one, and is refused when the path leaves the workspace, crosses a singularity or
//! a branch change, or cannot be timed within the joint limits. Pure functions, no clock.
//! Cartesian *trajectories* (timed tool waypoints) are `cartesian.rs`'s.

use nalgebra::UnitQuaternion;

use crate::daemon::vocab::{Limits, Setpoint};
use crate::model::{Frame, IkError, Model};

/// A smooth time-scaling `s(t)`: 0 → 1 with peak rate `v` (1/s) and peak acceleration `a`
/// (1/s²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    v: f64,
    ta: f64,
    tc: f64,
}

impl Profile {
    /// The fastest profile with rate ≤ `v_max` and acceleration ≤ `a_max` (both > 0) whose
    /// ramps last at least `min_ramp_s` (s, ≥ 0).
    pub fn new(v_max: f64, a_max: f64, min_ramp_s: f64) -> Self {
        // raised-cosine ramp: peak acceleration = 2·v/ta; distance of one ramp = v·ta/2
        let mut v = v_max;
        let mut ta = 2.0 * v / a_max;
        if v * ta > 1.0 {
            // no room to cruise: two ramps cover the unit distance
            v = (a_max / 2.0).sqrt();
            ta = 2.0 * v / a_max;
        }
        if ta < min_ramp_s {
            // slower ramps (a lower acceleration), and a lower rate if they leave no cruise
            ta = min_ramp_s;
            v = v.min(1.0 / ta);
        }
        let tc = ((1.0 - v * ta) / v).max(0.0);
        Self { v, ta, tc }
    }

    /// Total duration, s.
    pub fn duration(&self) -> f64 {
        2.0 * self.ta + self.tc
    }

    /// `(s, ds/dt, d²s/dt²)` at time `t` (s); clamped to the ends outside `[0, duration]`.
    pub fn sample(&self, t: f64) -> (f64, f64, f64) {
        use std::f64::consts::PI;
        let (v, ta, tc) = (self.v, self.ta, self.tc);
        let ramp = |t: f64| {
            // s, ṡ, s̈ of the accelerating ramp at t ∈ [0, ta]
            let w = 2.0 * PI / ta;
            let s = v * (t * t / (2.0 * ta) + ta * ((w * t).cos() - 1.0) / (4.0 * PI * PI));
            let sd = v * (t / ta - (w * t).sin() / (2.0 * PI));
            let sdd = v / ta * (1.0 - (w * t).cos());
            (s, sd, sdd)
        };
        let total = self.duration();
        if t <= 0.0 {
            (0.0, 0.0, 0.0)
        } else if t < ta {
            ramp(t)
        } else if t < ta + tc {
            (v * ta / 2.0 + v * (t - ta), v, 0.0)
        } else if t < total {
            let (s, sd, sdd) = ramp(total - t);
            (1.0 - s, sd, -sdd)
        } else {
            (1.0, 0.0, 0.0)
        }
    }
}

/// Why a move was refused. The robot is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MoveError {
    /// A target joint is outside its limits.
    #[error("joint {joint}: target {value:.4} rad is outside [{lower:.4}, {upper:.4}] rad")]
    JointLimit {
        /// 1…6.
        joint: usize,
        /// Target, rad.
        value: f64,
        /// Lower limit, rad.
        lower: f64,
        /// Upper limit, rad.
        upper: f64,
    },
    /// A number is not finite.
    #[error("{0} is not finite")]
    NonFinite(&'static str),
    /// The Cartesian path cannot be followed.
    #[error("at {percent:.0} % of the path: {reason}")]
    Path {
        /// Where along the path, %.
        percent: f64,
        /// What went wrong.
        reason: String,
    },
    /// A Cartesian waypoint cannot be reached along its straight line.
    #[error("waypoint {point}, {percent:.0} % of the way from the previous one: {reason}")]
    Waypoint {
        /// The waypoint, numbered from 0 as sent.
        point: usize,
        /// Where along its segment, %.
        percent: f64,
        /// What went wrong.
        reason: String,
    },
    /// The IK has no solution for the target.
    #[error("target pose: {0}")]
    Ik(#[from] IkError),
}

/// Points checked along a Cartesian path.
const PATH_SAMPLES: usize = 200;
/// Largest joint change between two path samples before it counts as a branch jump, rad.
const BRANCH_JUMP: f64 = 0.1;

/// The joints that put the tool at `pose`, nearest to `q` (the previous sample of a path):
/// refused (with the reason) when there are none, when the joints would jump more than a
/// branch change allows, or when they leave their limits.
pub(super) fn ik_step(
    model: &Model,
    lim: &Limits,
    pose: &Frame,
    q: &[f64; 6],
) -> Result<[f64; 6], String> {
    let next = model.ik_nearest(pose, q).map_err(|e| e.to_string())?;
    let jump = (0..6).map(|j| (next[j] - q[j]).abs()).fold(0.0, f64::max);
    if jump > BRANCH_JUMP {
        return Err(format!(
            "the joints would jump {jump:.3} rad (a singularity or a branch change on the way)"
        ));
    }
    check_limits(lim, &next).map_err(|e| e.to_string())?;
    Ok(next)
}

/// A planned move.
#[derive(Debug, Clone, PartialEq)]
pub enum Move {
    /// Straight line in joint space.
    Joints {
        /// Start, rad.
        from: [f64; 6],
        /// Goal, rad.
        to: [f64; 6],
        /// Timing.
        profile: Profile,
    },
    /// Straight line of the tool in Cartesian space.
    Cartesian {
        /// Start pose (base frame).
        from: Frame,
        /// Goal pose.
        to: Frame,
        /// Link angles at the start (the IK branch to follow), rad.
        q_start: [f64; 6],
        /// Timing.
        profile: Profile,
    },
}

fn check_limits(lim: &Limits, q: &[f64; 6]) -> Result<(), MoveError> {
    match lim.violation(q) {
        None => Ok(()),
        Some((_, v)) if !v.is_finite() => Err(MoveError::NonFinite("target joint angle")),
        Some((joint, value)) => Err(MoveError::JointLimit {
            joint,
            value,
            lower: lim.lower[joint - 1],
            upper: lim.upper[joint - 1],
        }),
    }
}

/// Profile rate/acceleration so that a path with joint derivatives up to `dq_ds` (rad per
/// unit s) and `d2q_ds2` respects `v_max` and `a_max` (rad/s, rad/s²).
fn timing(dq_ds: &[f64; 6], d2q_ds2: &[f64; 6], lim: &Limits) -> Profile {
    let (v_max, a_max) = (&lim.speed, &lim.acceleration);
    let mut v = f64::INFINITY;
    let mut a = f64::INFINITY;
    for j in 0..6 {
        if dq_ds[j] > 1e-12 {
            v = v.min(v_max[j] / dq_ds[j]);
            a = a.min(a_max[j] / dq_ds[j]);
        }
        if d2q_ds2[j] > 1e-12 {
            // q̈ = q'·s̈ + q''·ṡ²: keep the curvature term within half the limit
            v = v.min((0.5 * a_max[j] / d2q_ds2[j]).sqrt());
        }
    }
    if !v.is_finite() {
        v = 1.0;
        a = 1.0;
    }
    // leave half the acceleration budget for the curvature term
    Profile::new(v, 0.5 * a.min(1e6), lim.min_ramp_s)
}

impl Move {
    /// A synchronised joint move from `from` to `to` (rad) within `lim`.
    pub fn joints(from: [f64; 6], to: [f64; 6], lim: &Limits) -> Result<Self, MoveError> {
        if from.iter().any(|x| !x.is_finite()) {
            return Err(MoveError::NonFinite("start joint angle"));
        }
        check_limits(lim, &to)?;
        let d: [f64; 6] = std::array::from_fn(|j| (to[j] - from[j]).abs());
        Ok(Move::Joints {
            from,
            to,
            profile: timing(&d, &[0.0; 6], lim),
        })
    }

    /// A straight-line tool move from the pose at `q_start` to `to`, validated along the whole
    /// path (reachability, limits, no branch change) and timed within `lim`.
    pub fn cartesian(
        model: &Model,
        q_start: [f64; 6],
        to: Frame,
        lim: &Limits,
    ) -> Result<Self, MoveError> {
        if q_start.iter().any(|x| !x.is_finite()) {
            return Err(MoveError::NonFinite("start joint angle"));
        }
        if !to.translation.vector.iter().all(|x| x.is_finite()) {
            return Err(MoveError::NonFinite("target position"));
        }
        let from = model.fk(&q_start);
        let mut q = q_start;
        let mut path = Vec::with_capacity(PATH_SAMPLES + 1);
        path.push(q);
        for k in 1..=PATH_SAMPLES {
            let s = k as f64 / PATH_SAMPLES as f64;
            let pose = interpolate(&from, &to, s);
            q = ik_step(model, lim, &pose, &q).map_err(|reason| MoveError::Path {
                percent: 100.0 * s,
                reason,
            })?;
            path.push(q);
        }
        let h = 1.0 / PATH_SAMPLES as f64;
        let mut d1 = [0.0f64; 6];
        let mut d2 = [0.0f64; 6];
        for k in 0..PATH_SAMPLES {
            for j in 0..6 {
                d1[j] = d1[j].max((path[k + 1][j] - path[k][j]).abs() / h);
                if k > 0 {
                    d2[j] = d2[j]
                        .max((path[k + 1][j] - 2.0 * path[k][j] + path[k - 1][j]).abs() / (h * h));
                }
            }
        }
        Ok(Move::Cartesian {
            from,
            to,
            q_start,
            profile: timing(&d1, &d2, lim),
        })
    }

    /// Duration, s.
    pub fn duration(&self) -> f64 {
        match self {
            Move::Joints { profile, .. } | Move::Cartesian { profile, .. } => profile.duration(),
        }
    }

    /// The setpoint at time `t` (s) from the move's start; `q_prev` is the previous setpoint
    /// (the IK branch to stay on for Cartesian moves).
    pub fn sample(&self, model: &Model, t: f64, q_prev: &[f64; 6]) -> Result<Setpoint, MoveError> {
        match self {
            Move::Joints { from, to, profile } => {
                let (s, sd, _) = profile.sample(t);
                Ok(Setpoint {
                    q: std::array::from_fn(|j| from[j] + s * (to[j] - from[j])),
                    qd: std::array::from_fn(|j| sd * (to[j] - from[j])),
                })
            }
            Move::Cartesian {
                from, to, profile, ..
            } => {
                let (s, sd, _) = profile.sample(t);
                let pose = interpolate(from, to, s);
                let q = model
                    .ik_nearest(&pose, q_prev)
                    .map_err(|e| MoveError::Path {
                        percent: 100.0 * s,
                        reason: e.to_string(),
                    })?;
                // joint speed from the tool twist through the Jacobian
                let twist = crate::model::pose_error(to, from) * sd;
                let qd = model
                    .jacobian(&q)
                    .lu()
                    .solve(&twist)
                    .map(|v| std::array::from_fn(|j| v[j]))
                    .unwrap_or([0.0; 6]);
                Ok(Setpoint { q, qd })
            }
        }
    }
}

/// Pose at fraction `s` of the straight line from `a` to `b` (linear position, slerp).
pub fn interpolate(a: &Frame, b: &Frame, s: f64) -> Frame {
    let qa = UnitQuaternion::from_rotation_matrix(&a.rotation);
    let qb = UnitQuaternion::from_rotation_matrix(&b.rotation);
    let r = qa.slerp(&qb, s).to_rotation_matrix();
    let p = a.translation.vector * (1.0 - s) + b.translation.vector * s;
    Frame::from_parts(nalgebra::Translation3::from(p), r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nominal model's position limits with these speed and acceleration limits.
    fn limits(speed: [f64; 6], acceleration: [f64; 6]) -> Limits {
        let m = Model::nominal();
        Limits {
            lower: m.limits().lower,
            upper: m.limits().upper,
            speed,
            acceleration,
            min_ramp_s: 0.0,
        }
    }

    #[test]
    fn the_profile_is_smooth_bounded_and_reaches_one() {
        for (v, a) in [(1.0, 2.0), (0.2, 5.0), (5.0, 0.5)] {
            let p = Profile::new(v, a, 0.0);
            let n = 20_000;
            let dt = p.duration() / n as f64;
            let (mut vmax, mut amax, mut prev_a) = (0.0f64, 0.0f64, 0.0f64);
            for k in 0..=n {
                let (_, sd, sdd) = p.sample(k as f64 * dt);
                vmax = vmax.max(sd);
                amax = amax.max(sdd.abs());
                // continuous acceleration: no jumps between samples
                assert!((sdd - prev_a).abs() < 1e-2 * a.max(1.0), "jump at {k}");
                prev_a = sdd;
            }
            assert!(
                vmax <= v * (1.0 + 1e-9) && amax <= a * (1.0 + 1e-6),
                "{v} {a}: {vmax} {amax}"
            );
            assert!((p.sample(p.duration()).0 - 1.0).abs() < 1e-12);
            // s integrates ṡ
            let mid = p.duration() * 0.37;
            let num: f64 = (0..10_000)
                .map(|k| p.sample((k as f64 + 0.5) * mid / 10_000.0).1)
                .sum::<f64>()
                * mid
                / 10_000.0;
            assert!((num - p.sample(mid).0).abs() < 1e-6);
        }
    }

    #[test]
    fn a_minimum_ramp_slows_short_moves_only() {
        // a short move: without a minimum its ramps would last sqrt(2/a) = 0.063 s
        let p = Profile::new(50.0, 500.0, 0.4);
        assert!((p.duration() - 0.8).abs() < 1e-12, "{}", p.duration());
        assert!((p.sample(p.duration()).0 - 1.0).abs() < 1e-12);
        let peak = (0..=1000)
            .map(|k| p.sample(k as f64 * 0.8e-3).2.abs())
            .fold(0.0, f64::max);
        assert!(
            peak <= 500.0 && (peak - 2.0 / 0.4 / 0.4).abs() < 1e-3,
            "{peak}"
        );
        // a cruise with ramps shorter than the minimum: the ramps stretch, the rate stays
        let p = Profile::new(0.5, 10.0, 0.4);
        assert_eq!(p.ta, 0.4);
        assert_eq!(p.v, 0.5);
        assert!((p.sample(p.duration()).0 - 1.0).abs() < 1e-12);
        // long ramps already: unchanged
        assert_eq!(Profile::new(0.5, 1.0, 0.4), Profile::new(0.5, 1.0, 0.0));
        // through the limits: a 1 mrad joint move takes at least two ramps
        let m = Model::nominal();
        let mut lim = limits([0.5; 6], [1.0; 6]);
        let from = [0.0, 0.3, 1.2, 0.0, 0.8, 0.0];
        let mut to = from;
        to[1] += 1e-3;
        let quick = Move::joints(from, to, &lim).unwrap().duration();
        lim.min_ramp_s = 0.5;
        let mv = Move::joints(from, to, &lim).unwrap();
        assert!(
            quick < 0.2 && (mv.duration() - 1.0).abs() < 1e-12,
            "{quick}"
        );
        let end = mv.sample(&m, mv.duration(), &from).unwrap();
        assert!((end.q[1] - to[1]).abs() < 1e-15);
    }

    #[test]
    fn joint_moves_are_synchronised_and_within_limits() {
        let m = Model::nominal();
        let from = [0.0, 0.3, 1.2, 0.0, 0.8, 0.0];
        let to = [0.5, 0.1, 1.5, -0.4, 1.0, 1.0];
        let vmax = [0.5, 0.5, 1.0, 2.0, 2.0, 2.0];
        let lim = limits(vmax, [1.0, 1.0, 2.0, 4.0, 4.0, 4.0]);
        let mv = Move::joints(from, to, &lim).unwrap();
        let dt = mv.duration() / 2000.0;
        let mut prev = from;
        for k in 0..=2000 {
            let sp = mv.sample(&m, k as f64 * dt, &prev).unwrap();
            for j in 0..6 {
                assert!(sp.qd[j].abs() <= vmax[j] * (1.0 + 1e-9));
            }
            prev = sp.q;
        }
        assert_eq!(prev, to);
        let e = Move::joints(from, [0.0, 2.0, 1.0, 0.0, 0.0, 0.0], &lim).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("joint 2: target 2.0000 rad is outside"),
            "{e}"
        );
        assert!(Move::joints(from, [f64::NAN; 6], &lim).is_err());
    }

    #[test]
    fn cartesian_moves_follow_a_straight_line_and_refuse_impossible_paths() {
        let m = Model::nominal();
        let q0 = [0.2, 0.4, 1.3, 0.1, 0.9, 0.2];
        let start = m.fk(&q0);
        let goal = Frame::from_parts(
            nalgebra::Translation3::from(
                start.translation.vector + nalgebra::Vector3::new(0.1, -0.15, 0.05),
            ),
            start.rotation,
        );
        let vmax = [0.5, 0.5, 1.0, 2.0, 2.0, 2.0];
        let lim = limits(vmax, [1.0, 1.0, 2.0, 4.0, 4.0, 4.0]);
        let mv = Move::cartesian(&m, q0, goal, &lim).unwrap();
        let mut q = q0;
        let n = 400;
        for k in 0..=n {
            let t = mv.duration() * k as f64 / n as f64;
            let sp = mv.sample(&m, t, &q).unwrap();
            q = sp.q;
            let p = m.fk(&q).translation.vector;
            // on the segment
            let d = goal.translation.vector - start.translation.vector;
            let along = (p - start.translation.vector).dot(&d) / d.norm_squared();
            let off = (p - start.translation.vector - d * along).norm();
            assert!(off < 1e-9, "{k}: {off} m off the line");
            for j in 0..6 {
                assert!(
                    sp.qd[j].abs() <= vmax[j] * 1.05,
                    "joint {} speed {}",
                    j + 1,
                    sp.qd[j]
                );
            }
        }
        assert!(crate::model::pose_error(&m.fk(&q), &goal).norm() < 1e-9);
        // out of reach
        let far = Frame::from_parts(nalgebra::Translation3::new(1.5, 0.0, 0.3), start.rotation);
        let e = Move::cartesian(&m, q0, far, &lim).unwrap_err();
        assert!(matches!(e, MoveError::Path { .. }), "{e}");
        // through the upright singularity (wrist centre over the J1 axis)
        let over = Frame::from_parts(
            nalgebra::Translation3::new(
                -start.translation.x,
                -start.translation.y,
                start.translation.z,
            ),
            start.rotation,
        );
        assert!(Move::cartesian(&m, q0, over, &lim).is_err());
    }
}
