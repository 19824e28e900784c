//! Timed joint trajectories as a planner sends them (MoveIt's `FollowJointTrajectory`,
//! ros2_control's joint_trajectory_controller): waypoints of link-side joint positions with
//! optional velocities and accelerations at given times from the start, interpolated the way
//! that controller does it, checked whole before they start. Pure functions, no clock.
//!
//! Interpolation per segment: a quintic where every point carries accelerations (and
//! velocities), a cubic Hermite where every point carries velocities, otherwise a clamped cubic
//! spline through the positions (C², its interior velocities solved from the positions, the
//! end at rest). The first segment starts from the current setpoint — its position and speed,
//! so a trajectory that replaces a running one continues it without a jump in position or
//! velocity (the acceleration may step, within the limits). Every segment is a quintic
//! polynomial (a cubic has zero top coefficients), sampled in trajectory time τ; the daemon
//! advances τ by the speed scaling times the wall period, so the velocities it commands are
//! `scaling · dq/dτ` and the accelerations `scaling² · d²q/dτ²`.

use crate::daemon::vocab::{Limits, Setpoint};

/// At most this many points in one trajectory (the request line limit allows ≈ 600 anyway).
pub const MAX_POINTS: usize = 2000;
/// Samples per segment of the feasibility check (besides its ends).
const CHECK_SAMPLES: usize = 16;
/// Numerical slack of the limit checks (relative).
const SLACK: f64 = 1e-9;

/// One waypoint (link side).
#[derive(
    Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryPoint {
    /// Joint positions, rad.
    pub positions: [f64; 6],
    /// Joint velocities, rad/s (all points or none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocities: Option<[f64; 6]>,
    /// Joint accelerations, rad/s² (all points or none; only with velocities).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accelerations: Option<[f64; 6]>,
    /// Time of this point from the trajectory's start, s (at speed scaling 1).
    pub time_from_start: f64,
}

/// Why a trajectory was refused; the points are numbered from 0 as sent, joints 1…6.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrajectoryError {
    /// No points, or too many.
    #[error("a trajectory needs 1…{MAX_POINTS} points, got {0}")]
    Count(usize),
    /// A number is NaN or infinite.
    #[error("point {point}: {field} is not finite")]
    NonFinite {
        /// Point index.
        point: usize,
        /// Which field.
        field: &'static str,
    },
    /// Times must start after 0 and increase.
    #[error("point {point}: time_from_start {time:.6} s must be greater than {after:.6} s")]
    Time {
        /// Point index.
        point: usize,
        /// Its time, s.
        time: f64,
        /// The previous point's time (0 for the first), s.
        after: f64,
    },
    /// Some points carry a field and others do not.
    #[error("point {point}: {field} must be given on every point or on none")]
    Mixed {
        /// The first point that differs.
        point: usize,
        /// Which field.
        field: &'static str,
    },
    /// The path leaves a joint's range.
    #[error(
        "point {point}, joint {joint}: {value:.4} rad is outside [{lower:.4}, {upper:.4}] rad{}",
        if *between { " (between this point and the previous one)" } else { "" }
    )]
    Position {
        /// The segment's end point.
        point: usize,
        /// 1…6.
        joint: usize,
        /// The position, rad.
        value: f64,
        /// Lower limit, rad.
        lower: f64,
        /// Upper limit, rad.
        upper: f64,
        /// Whether the excursion is inside the segment rather than at the point.
        between: bool,
    },
    /// Too fast for the joint at the speed scaling in force.
    #[error(
        "point {point}, joint {joint}: needs {value:.4} rad/s at speed scaling {scaling:.3} (limit {limit:.4} rad/s)"
    )]
    Speed {
        /// The segment's end point.
        point: usize,
        /// 1…6.
        joint: usize,
        /// The speed needed, rad/s.
        value: f64,
        /// The limit, rad/s.
        limit: f64,
        /// The speed scaling, 0 < f ≤ 1.
        scaling: f64,
    },
    /// Too much acceleration for the joint at the speed scaling in force.
    #[error(
        "point {point}, joint {joint}: needs {value:.4} rad/s² at speed scaling {scaling:.3} (limit {limit:.4} rad/s²)"
    )]
    Acceleration {
        /// The segment's end point.
        point: usize,
        /// 1…6.
        joint: usize,
        /// The acceleration needed, rad/s².
        value: f64,
        /// The limit, rad/s².
        limit: f64,
        /// The speed scaling, 0 < f ≤ 1.
        scaling: f64,
    },
}

/// One segment: per joint the coefficients c0…c5 of a quintic in u = τ − t0.
#[derive(Debug, Clone, PartialEq)]
struct Segment {
    t0: f64,
    t1: f64,
    c: [[f64; 6]; 6],
}

impl Segment {
    fn quintic(t0: f64, t1: f64, a: &Knot, b: &Knot) -> Self {
        let h = t1 - t0;
        let c = std::array::from_fn(|j| {
            let (p0, v0, a0) = (a.p[j], a.v[j], a.a[j]);
            let (p1, v1, a1) = (b.p[j], b.v[j], b.a[j]);
            // quintic Hermite in u ∈ [0, h] matching p, v, a at both ends
            let (h2, h3, h4, h5) = (h * h, h * h * h, h.powi(4), h.powi(5));
            let dp = p1 - p0;
            let c3 = (20.0 * dp - (8.0 * v1 + 12.0 * v0) * h - (3.0 * a0 - a1) * h2) / (2.0 * h3);
            let c4 = (-30.0 * dp + (14.0 * v1 + 16.0 * v0) * h + (3.0 * a0 - 2.0 * a1) * h2)
                / (2.0 * h4);
            let c5 = (12.0 * dp - 6.0 * (v1 + v0) * h - (a0 - a1) * h2) / (2.0 * h5);
            [p0, v0, a0 / 2.0, c3, c4, c5]
        });
        Self { t0, t1, c }
    }

    fn cubic(t0: f64, t1: f64, a: &Knot, b: &Knot) -> Self {
        let h = t1 - t0;
        let c = std::array::from_fn(|j| {
            let (p0, v0, p1, v1) = (a.p[j], a.v[j], b.p[j], b.v[j]);
            let d = (p1 - p0) / h;
            [
                p0,
                v0,
                (3.0 * d - 2.0 * v0 - v1) / h,
                (v0 + v1 - 2.0 * d) / (h * h),
                0.0,
                0.0,
            ]
        });
        Self { t0, t1, c }
    }

    fn eval(&self, tau: f64, q: &mut [f64; 6], qd: &mut [f64; 6], qdd: &mut [f64; 6]) {
        let u = (tau - self.t0).clamp(0.0, self.t1 - self.t0);
        for j in 0..6 {
            let c = &self.c[j];
            q[j] = c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5]))));
            qd[j] = c[1] + u * (2.0 * c[2] + u * (3.0 * c[3] + u * (4.0 * c[4] + u * 5.0 * c[5])));
            qdd[j] = 2.0 * c[2] + u * (6.0 * c[3] + u * (12.0 * c[4] + u * 20.0 * c[5]));
        }
    }
}

/// Position, velocity and acceleration at a knot.
#[derive(Debug, Clone, Copy)]
struct Knot {
    p: [f64; 6],
    v: [f64; 6],
    a: [f64; 6],
}

/// A checked trajectory in trajectory time τ (s at speed scaling 1).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    segs: Vec<Segment>,
}

/// A sample: positions (rad), velocities (rad/s) and accelerations (rad/s²) in trajectory
/// time (multiply by the scaling, resp. its square, for wall time).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrajectorySample {
    /// rad.
    pub q: [f64; 6],
    /// rad/s (τ).
    pub qd: [f64; 6],
    /// rad/s² (τ).
    pub qdd: [f64; 6],
}

impl Trajectory {
    /// Plans `points` from the current setpoint `start` and checks the whole of it against
    /// `lim` at speed scaling `scaling` (0 < f ≤ 1).
    pub fn plan(
        start: &Setpoint,
        points: &[TrajectoryPoint],
        lim: &Limits,
        scaling: f64,
    ) -> Result<Self, TrajectoryError> {
        if points.is_empty() || points.len() > MAX_POINTS {
            return Err(TrajectoryError::Count(points.len()));
        }
        let mut after = 0.0;
        for (i, p) in points.iter().enumerate() {
            let finite = |x: &[f64]| x.iter().all(|v| v.is_finite());
            let fields = [
                ("positions", Some(p.positions)),
                ("velocities", p.velocities),
                ("accelerations", p.accelerations),
            ];
            for (field, v) in fields {
                if v.is_some_and(|v| !finite(&v)) {
                    return Err(TrajectoryError::NonFinite { point: i, field });
                }
            }
            if !p.time_from_start.is_finite() {
                return Err(TrajectoryError::NonFinite {
                    point: i,
                    field: "time_from_start",
                });
            }
            if p.time_from_start <= after {
                return Err(TrajectoryError::Time {
                    point: i,
                    time: p.time_from_start,
                    after,
                });
            }
            after = p.time_from_start;
            if p.velocities.is_some() != points[0].velocities.is_some() {
                return Err(TrajectoryError::Mixed {
                    point: i,
                    field: "velocities",
                });
            }
            if p.accelerations.is_some() != points[0].accelerations.is_some() {
                return Err(TrajectoryError::Mixed {
                    point: i,
                    field: "accelerations",
                });
            }
            if p.accelerations.is_some() && p.velocities.is_none() {
                return Err(TrajectoryError::Mixed {
                    point: i,
                    field: "accelerations (without velocities)",
                });
            }
            for j in 0..6 {
                let x = p.positions[j];
                if x < lim.lower[j] || x > lim.upper[j] {
                    return Err(TrajectoryError::Position {
                        point: i,
                        joint: j + 1,
                        value: x,
                        lower: lim.lower[j],
                        upper: lim.upper[j],
                        between: false,
                    });
                }
            }
        }
        let mut knots = Vec::with_capacity(points.len() + 1);
        knots.push(Knot {
            p: start.q,
            v: start.qd,
            a: [0.0; 6],
        });
        for p in points {
            knots.push(Knot {
                p: p.positions,
                v: p.velocities.unwrap_or([0.0; 6]),
                a: p.accelerations.unwrap_or([0.0; 6]),
            });
        }
        let mut times = Vec::with_capacity(knots.len());
        times.push(0.0);
        times.extend(points.iter().map(|p| p.time_from_start));
        if points[0].velocities.is_none() {
            spline_velocities(&times, &mut knots);
        }
        let quintic = points[0].accelerations.is_some();
        let segs = (0..points.len())
            .map(|i| {
                let (t0, t1, a, b) = (times[i], times[i + 1], &knots[i], &knots[i + 1]);
                if quintic {
                    Segment::quintic(t0, t1, a, b)
                } else {
                    Segment::cubic(t0, t1, a, b)
                }
            })
            .collect();
        let t = Self { segs };
        t.check(lim, scaling)?;
        Ok(t)
    }

    /// Duration in trajectory time, s.
    pub fn duration(&self) -> f64 {
        self.segs.last().map_or(0.0, |s| s.t1)
    }

    /// The sample at trajectory time `tau` (clamped to `[0, duration]`). No allocation.
    pub fn sample(&self, tau: f64) -> TrajectorySample {
        let i = self
            .segs
            .partition_point(|s| s.t1 < tau)
            .min(self.segs.len() - 1);
        let mut s = TrajectorySample::default();
        self.segs[i].eval(tau, &mut s.q, &mut s.qd, &mut s.qdd);
        s
    }

    /// Checks positions, speeds and accelerations of the whole trajectory against `lim` at
    /// speed scaling `scaling`.
    pub fn check(&self, lim: &Limits, scaling: f64) -> Result<(), TrajectoryError> {
        self.check_from(0.0, lim, scaling)
    }

    /// As [`Trajectory::check`], for what remains after trajectory time `tau`.
    pub fn check_from(&self, tau: f64, lim: &Limits, scaling: f64) -> Result<(), TrajectoryError> {
        let mut s = TrajectorySample::default();
        for (i, seg) in self.segs.iter().enumerate().filter(|(_, s)| s.t1 >= tau) {
            for k in 0..=CHECK_SAMPLES {
                let t = seg.t0 + (seg.t1 - seg.t0) * k as f64 / CHECK_SAMPLES as f64;
                if t < tau {
                    continue;
                }
                seg.eval(t, &mut s.q, &mut s.qd, &mut s.qdd);
                for j in 0..6 {
                    let (lo, hi) = (lim.lower[j], lim.upper[j]);
                    let tol = SLACK * (1.0 + hi.abs().max(lo.abs()));
                    if s.q[j] < lo - tol || s.q[j] > hi + tol {
                        return Err(TrajectoryError::Position {
                            point: i,
                            joint: j + 1,
                            value: s.q[j],
                            lower: lo,
                            upper: hi,
                            between: k < CHECK_SAMPLES,
                        });
                    }
                    let v = scaling * s.qd[j].abs();
                    if v > lim.speed[j] * (1.0 + SLACK) {
                        return Err(TrajectoryError::Speed {
                            point: i,
                            joint: j + 1,
                            value: v,
                            limit: lim.speed[j],
                            scaling,
                        });
                    }
                    let a = scaling * scaling * s.qdd[j].abs();
                    if a > lim.acceleration[j] * (1.0 + SLACK) {
                        return Err(TrajectoryError::Acceleration {
                            point: i,
                            joint: j + 1,
                            value: a,
                            limit: lim.acceleration[j],
                            scaling,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

/// Interior velocities of the clamped cubic spline through the knots' positions (the first
/// knot's velocity as given, the last at rest): C² at every interior knot, per joint one
/// tridiagonal system solved by the Thomas algorithm.
fn spline_velocities(t: &[f64], k: &mut [Knot]) {
    let n = k.len() - 1; // segments
    k[n].v = [0.0; 6];
    if n < 2 {
        return;
    }
    let h: Vec<f64> = (0..n).map(|i| t[i + 1] - t[i]).collect();
    for j in 0..6 {
        // unknowns v_1 … v_{n-1}
        let m = n - 1;
        let mut diag = vec![0.0; m];
        let mut upper = vec![0.0; m];
        let mut lower = vec![0.0; m];
        let mut rhs = vec![0.0; m];
        for r in 0..m {
            let i = r + 1;
            let d0 = (k[i].p[j] - k[i - 1].p[j]) / h[i - 1];
            let d1 = (k[i + 1].p[j] - k[i].p[j]) / h[i];
            lower[r] = h[i];
            diag[r] = 2.0 * (h[i - 1] + h[i]);
            upper[r] = h[i - 1];
            rhs[r] = 3.0 * (h[i] * d0 + h[i - 1] * d1);
        }
        rhs[0] -= lower[0] * k[0].v[j];
        rhs[m - 1] -= upper[m - 1] * k[n].v[j];
        // forward sweep
        for r in 1..m {
            let w = lower[r] / diag[r - 1];
            diag[r] -= w * upper[r - 1];
            rhs[r] -= w * rhs[r - 1];
        }
        let mut v = vec![0.0; m];
        v[m - 1] = rhs[m - 1] / diag[m - 1];
        for r in (0..m - 1).rev() {
            v[r] = (rhs[r] - upper[r] * v[r + 1]) / diag[r];
        }
        for r in 0..m {
            k[r + 1].v[j] = v[r];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIM: Limits = Limits {
        lower: [-3.0; 6],
        upper: [3.0; 6],
        speed: [1.0; 6],
        acceleration: [2.0; 6],
        min_ramp_s: 0.0,
    };

    fn at(q: [f64; 6], t: f64) -> TrajectoryPoint {
        TrajectoryPoint {
            positions: q,
            velocities: None,
            accelerations: None,
            time_from_start: t,
        }
    }

    fn rest(q: [f64; 6]) -> Setpoint {
        Setpoint { q, qd: [0.0; 6] }
    }

    #[test]
    fn a_spline_passes_through_its_points_with_continuous_acceleration() {
        let pts = [
            at([0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0),
            at([0.5, 0.3, 0.0, 0.0, 0.0, 0.0], 2.0),
            at([0.4, 0.1, 0.1, 0.0, 0.0, 0.0], 3.5),
        ];
        let t = Trajectory::plan(&rest([0.0; 6]), &pts, &LIM, 1.0).unwrap();
        assert_eq!(t.duration(), 3.5);
        for p in &pts {
            let s = t.sample(p.time_from_start);
            for j in 0..6 {
                assert!((s.q[j] - p.positions[j]).abs() < 1e-12);
            }
        }
        assert!(
            t.sample(3.5).qd.iter().all(|v| v.abs() < 1e-12),
            "ends at rest"
        );
        assert_eq!(
            t.sample(0.0).qd,
            [0.0; 6],
            "starts from the setpoint at rest"
        );
        for k in [1.0, 2.0] {
            let (a, b) = (t.sample(k - 1e-9), t.sample(k + 1e-9));
            for j in 0..6 {
                assert!((a.qd[j] - b.qd[j]).abs() < 1e-6);
                assert!((a.qdd[j] - b.qdd[j]).abs() < 1e-5, "C² at {k}");
            }
        }
    }

    #[test]
    fn cubic_and_quintic_segments_meet_the_given_velocities_and_accelerations() {
        let mut p = at([0.3, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0);
        p.velocities = Some([0.2, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let mut q = at([0.6, 0.0, 0.0, 0.0, 0.0, 0.0], 2.0);
        q.velocities = Some([0.0; 6]);
        let t = Trajectory::plan(&rest([0.0; 6]), &[p, q], &LIM, 1.0).unwrap();
        assert!((t.sample(1.0).qd[0] - 0.2).abs() < 1e-12);
        p.accelerations = Some([0.1, 0.0, 0.0, 0.0, 0.0, 0.0]);
        q.accelerations = Some([0.0; 6]);
        let t = Trajectory::plan(&rest([0.0; 6]), &[p, q], &LIM, 1.0).unwrap();
        let s = t.sample(1.0);
        assert!((s.qd[0] - 0.2).abs() < 1e-12 && (s.qdd[0] - 0.1).abs() < 1e-9);
        assert!((t.sample(2.0).q[0] - 0.6).abs() < 1e-12);
    }

    #[test]
    fn a_replacement_starts_from_the_running_state_without_a_jump() {
        let start = Setpoint {
            q: [0.1; 6],
            qd: [0.3, -0.2, 0.0, 0.1, 0.0, 0.0],
        };
        let t = Trajectory::plan(&start, &[at([0.5; 6], 2.0)], &LIM, 1.0).unwrap();
        let s = t.sample(0.0);
        assert_eq!(s.q, start.q);
        assert_eq!(s.qd, start.qd);
    }

    #[test]
    fn refusals_name_the_point_and_the_joint() {
        let s = rest([0.0; 6]);
        let e = |pts: &[TrajectoryPoint], f: f64| Trajectory::plan(&s, pts, &LIM, f).unwrap_err();
        assert_eq!(e(&[], 1.0), TrajectoryError::Count(0));
        assert!(matches!(
            e(&[at([0.1; 6], 1.0), at([0.2; 6], 1.0)], 1.0),
            TrajectoryError::Time { point: 1, .. }
        ));
        assert!(matches!(
            e(&[at([0.1; 6], 0.0)], 1.0),
            TrajectoryError::Time { point: 0, .. }
        ));
        let mut bad = at([0.1; 6], 1.0);
        bad.positions[3] = f64::NAN;
        assert!(matches!(
            e(&[bad], 1.0),
            TrajectoryError::NonFinite {
                point: 0,
                field: "positions"
            }
        ));
        let mut out = at([0.1; 6], 2.0);
        out.positions[4] = 3.5;
        assert!(matches!(
            e(&[at([0.1; 6], 1.0), out], 1.0),
            TrajectoryError::Position {
                point: 1,
                joint: 5,
                between: false,
                ..
            }
        ));
        // 2 rad in 1 s needs ≈ 3 rad/s and 12 rad/s² on joint 2
        let mut fast = at([0.0; 6], 1.0);
        fast.positions[1] = 2.0;
        let err = e(&[fast], 1.0);
        assert!(
            matches!(
                err,
                TrajectoryError::Speed {
                    point: 0,
                    joint: 2,
                    ..
                } | TrajectoryError::Acceleration {
                    point: 0,
                    joint: 2,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("point 0, joint 2: needs"), "{err}");
        let mut v = at([0.1; 6], 1.0);
        v.velocities = Some([0.0; 6]);
        assert!(matches!(
            e(&[v, at([0.2; 6], 2.0)], 1.0),
            TrajectoryError::Mixed {
                point: 1,
                field: "velocities"
            }
        ));
    }

    #[test]
    fn a_slower_scaling_makes_a_fast_trajectory_feasible() {
        // 0.6 rad in 1 s: peak ≈ 0.9 rad/s and ≈ 3.6 rad/s² — too much acceleration at 1.0
        let mut p = at([0.0; 6], 1.0);
        p.positions[0] = 0.6;
        let s = rest([0.0; 6]);
        let err = Trajectory::plan(&s, &[p], &LIM, 1.0).unwrap_err();
        assert!(
            matches!(err, TrajectoryError::Acceleration { joint: 1, .. }),
            "{err}"
        );
        let t = Trajectory::plan(&s, &[p], &LIM, 0.5).unwrap();
        assert!(t.check(&LIM, 1.0).is_err(), "speeding up again is refused");
    }
}
