//! Inverse kinematics: closed-form branches of the ideal spherical-wrist PA10, refined by
//! Newton steps on the full non-ideal model (departures, Hayati β, tool).
//!
//! The closed form uses the nominal lengths d1, a2, d4, d6: shoulder left/right (2) ×
//! elbow up/down (2) × wrist flip (2) = up to 8 branches. Each branch's angles are wrapped
//! by 2π into the joint limits as near the reference configuration as possible, refined to
//! 1e-10 m / 1e-10 rad on the full model, checked against the limits again, deduplicated
//! and returned nearest-first. Results are link-side angles.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::kinematics::{Frame, pose_error};
use super::robot::{JointGeom, Model};

/// Largest number of IK solutions (2 × 2 × 2 branches).
pub const MAX_SOLUTIONS: usize = 8;

/// Position tolerance of the Newton refinement, m.
const POS_TOL: f64 = 1e-10;
/// Orientation tolerance of the Newton refinement, rad.
const ROT_TOL: f64 = 1e-10;
/// Newton iterations per branch.
const MAX_NEWTON: usize = 60;
/// Largest joint change of one Newton step, rad.
const MAX_STEP: f64 = 0.2;
/// How far (rad) a closed-form seed may lie outside a joint limit: the ideal geometry's
/// seed differs from the refined solution by about the departures.
const SEED_LIMIT_MARGIN: f64 = 0.05;
/// Smallest |q3| (rad) of a closed-form seed, keeping Newton off the straight-elbow
/// singularity.
const ELBOW_SEED_MIN: f64 = 0.03;
/// Below this distance (m) of the wrist centre from the J1 axis the shoulder is singular.
const SHOULDER_SINGULAR_M: f64 = 1e-6;
/// Below this |sin q5| the wrist is singular (J4 and J6 aligned).
const WRIST_SINGULAR: f64 = 1e-6;

/// Why no joint solution was returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IkError {
    /// An input number is not finite.
    #[error("target pose is not finite")]
    NonFinite,
    /// The wrist centre is out of the arm's reach.
    #[error(
        "target out of reach: the wrist centre is {distance:.4} m from the shoulder, reach is {min_reach:.4}…{max_reach:.4} m"
    )]
    Unreachable {
        /// Shoulder → wrist-centre distance the target needs, m.
        distance: f64,
        /// Shortest reachable distance, m.
        min_reach: f64,
        /// Longest reachable distance, m.
        max_reach: f64,
    },
    /// The target lies on a singularity where the solutions form a continuum.
    #[error("target is singular: {0}")]
    Singular(&'static str),
    /// Every branch violates a joint limit.
    #[error("every solution violates a joint limit")]
    OutsideLimits,
    /// The Newton refinement did not converge on any branch (pose error left, m / rad).
    #[error(
        "Newton refinement did not converge (position error {position_m:.3e} m, orientation error {orientation_rad:.3e} rad)"
    )]
    NoConvergence {
        /// Remaining position error, m.
        position_m: f64,
        /// Remaining orientation error, rad.
        orientation_rad: f64,
    },
}

/// Up to [`MAX_SOLUTIONS`] joint solutions, nearest to the reference first. No allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolutions {
    q: [[f64; 6]; MAX_SOLUTIONS],
    len: usize,
}

impl IkSolutions {
    /// The solutions, nearest-first (link angles, rad).
    pub fn as_slice(&self) -> &[[f64; 6]] {
        &self.q[..self.len]
    }
    /// The nearest solution.
    pub fn nearest(&self) -> [f64; 6] {
        self.q[0]
    }
    /// Number of solutions (≥ 1).
    pub fn len(&self) -> usize {
        self.len
    }
    /// Always false: an empty set is an error instead.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

fn dist2(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    (0..6).map(|j| (a[j] - b[j]).powi(2)).sum()
}

impl Model {
    /// All joint solutions (link angles, rad) that put the tool at `target` (base frame),
    /// nearest to `reference` first.
    ///
    /// ```
    /// use pa10::model::Model;
    /// let m = Model::nominal();
    /// let q = [0.3, 0.4, 1.2, -0.5, 0.8, 0.2];
    /// let sols = m.ik(&m.fk(&q), &[0.0; 6]).unwrap();
    /// assert!(sols.len() >= 2);
    /// let near = m.ik(&m.fk(&q), &q).unwrap().nearest();
    /// assert!((0..6).all(|j| (near[j] - q[j]).abs() < 1e-9));
    /// ```
    pub fn ik(&self, target: &Frame, reference: &[f64; 6]) -> Result<IkSolutions, IkError> {
        let t = target.translation.vector;
        if !t
            .iter()
            .chain(target.rotation.matrix().iter())
            .chain(reference.iter())
            .all(|v| v.is_finite())
        {
            return Err(IkError::NonFinite);
        }
        let nom = &self.data().dh;
        let (d1, a2, d4, d6) = (nom[0].d, nom[1].a, nom[3].d, nom[5].d);
        let flange = target * self.tool_inv;
        let rf = flange.rotation.matrix();
        let pw: Vector3<f64> = flange.translation.vector - rf.column(2) * d6;
        let v = pw - Vector3::new(0.0, 0.0, d1);
        let rho = v.x.hypot(v.y);
        let dist = v.norm();
        let (min_reach, max_reach) = ((a2 - d4).abs(), a2 + d4);
        // Departures move the true reach by at most the sum of the length departures (plus
        // what the small angle departures add); beyond that margin no refinement can help.
        let margin: f64 = 1e-9
            + self
                .data()
                .departures
                .iter()
                .map(|e| e.da.abs() + e.dd.abs())
                .sum::<f64>()
            + self
                .data()
                .departures
                .iter()
                .map(|e| e.dalpha.abs() + e.dbeta.abs())
                .sum::<f64>()
                * max_reach;
        let unreachable = IkError::Unreachable {
            distance: dist,
            min_reach,
            max_reach,
        };
        let outside_nominal = dist > max_reach || dist < min_reach;
        if dist > max_reach + margin || dist < min_reach - margin {
            return Err(unreachable);
        }
        if rho < SHOULDER_SINGULAR_M {
            return Err(IkError::Singular(
                "shoulder: the wrist centre is on the J1 axis, J1 is free",
            ));
        }
        let c3 = ((dist * dist - a2 * a2 - d4 * d4) / (2.0 * a2 * d4)).clamp(-1.0, 1.0);
        let q3a = c3.acos();

        let mut out = IkSolutions {
            q: [[0.0; 6]; MAX_SOLUTIONS],
            len: 0,
        };
        let mut any_in_limits = false;
        let mut best_err = (f64::INFINITY, f64::INFINITY);
        for shoulder in [1.0, -1.0] {
            let q1 = v.y.atan2(v.x) + if shoulder < 0.0 { PI } else { 0.0 };
            let (r, h) = (shoulder * rho, v.z);
            for elbow in [1.0, -1.0] {
                // A straight elbow (q3 = 0) is singular for Newton: seed both elbow branches
                // just off it, on their own side, and let the refinement settle.
                let q3 = elbow * q3a.max(ELBOW_SEED_MIN);
                let q2 = r.atan2(h) - (d4 * q3.sin()).atan2(a2 + d4 * q3.cos());
                let f3 = self.nominal_frame3([q1, q2, q3]);
                let r36 = f3.rotation.matrix().transpose() * rf;
                let s5 = r36[(0, 2)].hypot(r36[(1, 2)]);
                if s5 < WRIST_SINGULAR {
                    return Err(IkError::Singular(
                        "wrist: q5 = 0 aligns J4 and J6, only q4 + q6 is determined",
                    ));
                }
                for wrist in [1.0, -1.0] {
                    let q5 = (wrist * s5).atan2(r36[(2, 2)]);
                    let q4 = (wrist * r36[(1, 2)]).atan2(wrist * r36[(0, 2)]);
                    let q6 = (wrist * r36[(2, 1)]).atan2(-wrist * r36[(2, 0)]);
                    let seed = [q1, q2, q3, q4, q5, q6];
                    let Some(seed) = self.wrap_into_limits(&seed, reference, SEED_LIMIT_MARGIN)
                    else {
                        continue;
                    };
                    any_in_limits = true;
                    match self.refine(target, seed) {
                        Ok(q) => {
                            let Some(q) = self.wrap_into_limits(&q, reference, 1e-12) else {
                                continue;
                            };
                            if out.as_slice().iter().any(|s| dist2(s, &q) < 1e-16) {
                                continue;
                            }
                            out.q[out.len] = q;
                            out.len += 1;
                        }
                        Err(e) => {
                            if e.0 + e.1 < best_err.0 + best_err.1 {
                                best_err = e;
                            }
                        }
                    }
                }
            }
        }
        if out.len == 0 {
            return Err(if outside_nominal {
                unreachable
            } else if !any_in_limits {
                IkError::OutsideLimits
            } else if best_err.0.is_finite() {
                IkError::NoConvergence {
                    position_m: best_err.0,
                    orientation_rad: best_err.1,
                }
            } else {
                IkError::OutsideLimits
            });
        }
        out.q[..out.len].sort_by(|a, b| dist2(a, reference).total_cmp(&dist2(b, reference)));
        Ok(out)
    }

    /// Motor-side joint targets that put the *tool* at `target` (base frame) with `load`
    /// hung at the tool: the IK solution nearest `reference` (link angles, rad), through
    /// [`Model::compensate`] with gravity and the load (springs and joint errors, backlash
    /// on the side of `dir`, −1/0/+1 per joint).
    ///
    /// ```
    /// use pa10::model::{ExternalLoad, Model, NO_DIRECTION, Stiffness};
    /// let mut d = Model::nominal().data().clone();
    /// d.stiffness[1] = Some(Stiffness { klin: 1.98e4, kcub: 3.35e7 });
    /// let m = Model::new(d).unwrap();
    /// let q = [0.1, 0.8, 0.9, 0.0, 0.6, 0.0];
    /// let load = ExternalLoad::hung(44.0, &m.gravity());
    /// let c = m.compensate_pose(&m.fk(&q), &load, &q, &NO_DIRECTION).unwrap();
    /// assert!((0..6).all(|j| (c.q_link[j] - q[j]).abs() < 1e-9));
    /// // the drive leads the link by the spring's deflection (J2 carries ~ −150 N·m here)
    /// assert!(c.q_motor[1] < c.q_link[1] - 1e-3);
    /// ```
    pub fn compensate_pose(
        &self,
        target: &Frame,
        load: &super::statics::ExternalLoad,
        reference: &[f64; 6],
        dir: &[f64; 6],
    ) -> Result<super::statics::Compensation, IkError> {
        if !load
            .force
            .iter()
            .chain(load.at.iter())
            .all(|v| v.is_finite())
        {
            return Err(IkError::NonFinite);
        }
        let q_link = self.ik_nearest(target, reference)?;
        self.compensate(&q_link, super::statics::Torques::Gravity(load), dir)
            .map_err(|_| IkError::NonFinite)
    }

    /// The link angles (rad) that put the tool where it is at `q` with the other wrist: the
    /// spherical wrist's twin (J4 ± π, −J5, J6 ± π on the ideal arm), solved on this model;
    /// `None` where the twin is outside the joint limits or J5 is at its singularity (0).
    ///
    /// ```
    /// use pa10::model::Model;
    /// let m = Model::nominal();
    /// let q = [0.1, 0.4, 1.5, 0.2, 1.0, -0.3];
    /// let t = m.other_wrist(&q).unwrap();
    /// assert!(t[4] < 0.0 && (t[3] - q[3]).abs() > 3.0);
    /// let (a, b) = (m.fk(&q), m.fk(&t));
    /// assert!((a.translation.vector - b.translation.vector).norm() < 1e-9);
    /// ```
    pub fn other_wrist(&self, q: &[f64; 6]) -> Option<[f64; 6]> {
        if q[4] == 0.0 || !q.iter().all(|v| v.is_finite()) {
            return None;
        }
        let t = self
            .ik_nearest(&self.fk(q), &Self::other_wrist_reference(q))
            .ok()?;
        (t[4] * q[4] < 0.0).then_some(t)
    }

    /// The ideal arm's other-wrist twin of `q` (rad): J4 and J6 moved by π toward zero, J5
    /// negated — the reference [`Model::other_wrist`] solves from (an IK seed for the other
    /// wrist).
    pub fn other_wrist_reference(q: &[f64; 6]) -> [f64; 6] {
        let half = |a: f64| if a > 0.0 { a - PI } else { a + PI };
        [q[0], q[1], q[2], half(q[3]), -q[4], half(q[5])]
    }

    /// The solution nearest to `reference` (link angles, rad).
    pub fn ik_nearest(&self, target: &Frame, reference: &[f64; 6]) -> Result<[f64; 6], IkError> {
        self.ik(target, reference).map(|s| s.nearest())
    }

    /// Base-frame pose of DH frame 3 of the ideal PA10 (nominal table, no departures), the
    /// frame the closed-form wrist solution is expressed in.
    fn nominal_frame3(&self, q: [f64; 3]) -> Frame {
        let mut f = Frame::identity();
        for (n, qj) in self.data().dh.iter().zip(q) {
            let (sa, ca) = n.alpha.sin_cos();
            let g = JointGeom {
                a: n.a,
                d: n.d,
                offset: n.theta_offset,
                ca,
                sa,
                cb: 1.0,
                sb: 0.0,
                hayati: false,
            };
            f *= g.transform(qj);
        }
        f
    }

    /// Each joint moved by a multiple of 2π to lie within its limits widened by `margin`
    /// (rad) as near the reference as possible, then clamped to the limits when `margin`
    /// is a rounding allowance; `None` when some joint has no such representative.
    fn wrap_into_limits(
        &self,
        q: &[f64; 6],
        reference: &[f64; 6],
        margin: f64,
    ) -> Option<[f64; 6]> {
        let lim = self.limits();
        let mut out = [0.0; 6];
        for j in 0..6 {
            let mut best: Option<f64> = None;
            for k in -2..=2 {
                let c = q[j] + 2.0 * PI * k as f64;
                if c >= lim.lower[j] - margin && c <= lim.upper[j] + margin {
                    let c = if margin <= 1e-12 {
                        c.clamp(lim.lower[j], lim.upper[j])
                    } else {
                        c
                    };
                    if best.is_none_or(|b| (c - reference[j]).abs() < (b - reference[j]).abs()) {
                        best = Some(c);
                    }
                }
            }
            out[j] = best?;
        }
        Some(out)
    }

    /// Newton steps on the full model from `q`, each limited to [`MAX_STEP`] rad per joint,
    /// kept on the seed's branch and backtracked until the pose error shrinks. Err carries
    /// the remaining (m, rad) error.
    fn refine(&self, target: &Frame, mut q: [f64; 6]) -> Result<[f64; 6], (f64, f64)> {
        let error_at = |q: &[f64; 6]| {
            let f = self.frames(q);
            let tool = f[6] * self.tool;
            (pose_error(target, &tool), f, tool)
        };
        let (mut e, mut f, mut tool) = error_at(&q);
        for _ in 0..MAX_NEWTON {
            let err = (e.fixed_rows::<3>(0).norm(), e.fixed_rows::<3>(3).norm());
            if err.0 < POS_TOL && err.1 < ROT_TOL {
                return Ok(q);
            }
            let jac = super::kinematics::jacobian_from_frames(&f, &tool.translation.vector);
            let dq = match jac.lu().solve(&e) {
                Some(dq) if dq.iter().all(|v| v.is_finite()) => dq,
                _ => return Err(err),
            };
            let mut scale: f64 = (MAX_STEP / dq.amax()).min(1.0);
            // Stay on the seed's branch: q3 (elbow) and q5 (wrist) must not cross zero, the
            // singularities that separate the branches.
            for j in [2, 4] {
                if q[j] != 0.0 && (q[j] + scale * dq[j]) * q[j] <= 0.0 {
                    scale = scale.min(0.5 * (q[j] / dq[j]).abs());
                }
            }
            let mut accepted = false;
            for _ in 0..20 {
                let trial: [f64; 6] = std::array::from_fn(|j| q[j] + scale * dq[j]);
                let (te, tf, tt) = error_at(&trial);
                if te.norm_squared() < e.norm_squared() {
                    (q, e, f, tool) = (trial, te, tf, tt);
                    accepted = true;
                    break;
                }
                scale *= 0.5;
            }
            if !accepted {
                return Err(err);
            }
        }
        Err((e.fixed_rows::<3>(0).norm(), e.fixed_rows::<3>(3).norm()))
    }
}
