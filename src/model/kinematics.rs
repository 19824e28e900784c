//! Forward kinematics, the geometric Jacobian and the identification Jacobian.
//!
//! All functions work on link-side joint angles and fixed-size nalgebra types, and never
//! allocate. Angular parts are rotation vectors / angular velocities in the base frame.

use nalgebra::{Matrix3, Rotation3, SMatrix, Translation3, UnitQuaternion, Vector3, Vector6};

use super::params::{
    IDX_A, IDX_ALPHA, IDX_D, IDX_KCUB, IDX_KLIN, IDX_THETA, PARAM_COUNT, STIFF_JOINTS,
};
use super::robot::{JointGeom, Model};

pub use super::frame::Frame;

/// 6×6 geometric Jacobian: rows 0–2 linear velocity (m/s per rad/s), rows 3–5 angular
/// velocity (rad/s per rad/s), both in the base frame; column j is joint j+1.
pub type Jacobian = SMatrix<f64, 6, 6>;

/// 6×30 identification Jacobian: tool pose (position m; small rotation rad, base frame)
/// with respect to the 30 parameters in [`ParamVector`](super::ParamVector) order.
pub type IdentJacobian = SMatrix<f64, 6, PARAM_COUNT>;

/// Builds a frame from a position (m) and a quaternion `[w, x, y, z]` (normalised here).
pub fn frame_from_pose(position: [f64; 3], quaternion: [f64; 4]) -> Frame {
    let [w, x, y, z] = quaternion;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    Frame::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        q.to_rotation_matrix(),
    )
}

/// Splits a frame into position (m) and quaternion `[w, x, y, z]` with `w ≥ 0`.
pub fn pose_parts(f: &Frame) -> ([f64; 3], [f64; 4]) {
    let d = super::file::PoseData::from(f);
    (d.translation, d.quaternion)
}

/// Pose error `target ⊖ actual`: `[p_t − p_a; log(R_t·R_aᵀ)]` (m; rad, base frame).
#[inline]
pub fn pose_error(target: &Frame, actual: &Frame) -> Vector6<f64> {
    let dp = target.translation.vector - actual.translation.vector;
    let dr = rotation_log(&(target.rotation * actual.rotation.inverse()));
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Rotation vector (axis × angle, rad) of a rotation, accurate for small angles.
///
/// Uses `θ = atan2(‖v‖, (tr R − 1)/2)` with `v` the skew part of `R` (`sin θ · axis`),
/// which keeps full relative precision near θ = 0 where an `acos` of the trace loses half
/// the digits; near θ = π it defers to nalgebra's axis-angle extraction.
pub fn rotation_log(r: &Rotation3<f64>) -> Vector3<f64> {
    let m = r.matrix();
    let v = 0.5
        * Vector3::new(
            m[(2, 1)] - m[(1, 2)],
            m[(0, 2)] - m[(2, 0)],
            m[(1, 0)] - m[(0, 1)],
        );
    let s = v.norm();
    let c = 0.5 * (m.trace() - 1.0);
    if c > -0.9 {
        let theta = s.atan2(c);
        if s < 1e-300 { v } else { v * (theta / s) }
    } else {
        r.scaled_axis()
    }
}

impl JointGeom {
    /// The DH transform of this joint at link angle `q` (rad).
    #[inline]
    pub(crate) fn transform(&self, q: f64) -> Frame {
        let (st, ct) = (q + self.offset).sin_cos();
        self.transform_trig(st, ct)
    }

    /// [`JointGeom::transform`] from the sine and cosine of its DH angle (link angle +
    /// offset), computed elsewhere.
    #[inline]
    pub(crate) fn transform_trig(&self, st: f64, ct: f64) -> Frame {
        let (ca, sa) = (self.ca, self.sa);
        // Rz(θ)·Rx(α)
        let mut m = Matrix3::new(ct, -st * ca, st * sa, st, ct * ca, -ct * sa, 0.0, sa, ca);
        if self.hayati {
            // ·Ry(β): col0 ← cb·col0 − sb·col2, col2 ← sb·col0 + cb·col2
            let c0 = m.column(0).into_owned();
            let c2 = m.column(2).into_owned();
            m.set_column(0, &(c0 * self.cb - c2 * self.sb));
            m.set_column(2, &(c0 * self.sb + c2 * self.cb));
        }
        Frame::from_parts(
            Translation3::new(self.a * ct, self.a * st, self.d),
            Rotation3::from_matrix_unchecked(m),
        )
    }
}

impl Model {
    /// Base-frame poses of DH frames 0…6 at link angles `q` (frame 0 is the base, frame 6
    /// the flange; joint j+1 turns about the z axis of frame j).
    #[inline]
    pub fn frames(&self, q: &[f64; 6]) -> [Frame; 7] {
        let mut f = [Frame::identity(); 7];
        for j in 0..6 {
            f[j + 1] = f[j] * self.joints[j].transform(q[j]);
        }
        f
    }

    /// [`Model::frames`] from each joint's DH angle sine and cosine (`trig[j]` = `[angle, sin,
    /// cos]`, the angle being the link angle plus the joint's offset), computed elsewhere,
    /// into `f`, whose frames `0..=from` are kept as they are (already this model's at these
    /// angles: `f[0]` is the identity).
    #[inline]
    pub(crate) fn frames_trig_from(&self, trig: &[[f64; 3]; 6], f: &mut [Frame; 7], from: usize) {
        for j in from..6 {
            f[j + 1] = f[j] * self.joints[j].transform_trig(trig[j][1], trig[j][2]);
        }
    }

    /// The first joint (0-based; 6 for none) whose geometry differs from `other`'s, to the
    /// bit: frames before it are the same at the same angles.
    pub(crate) fn first_joint_unlike(&self, other: &Model) -> usize {
        let bits = |g: &super::robot::JointGeom| {
            [g.a, g.d, g.offset, g.ca, g.sa, g.cb, g.sb].map(f64::to_bits)
        };
        (0..6)
            .find(|&j| {
                self.joints[j].hayati != other.joints[j].hayati
                    || bits(&self.joints[j]) != bits(&other.joints[j])
            })
            .unwrap_or(6)
    }

    /// The DH angle of joint `j` (0-based) at link angle `q` (rad): `q` plus its offset.
    #[inline]
    pub(crate) fn dh_angle(&self, j: usize, q: f64) -> f64 {
        q + self.joints[j].offset
    }

    /// Flange pose in the base frame at link angles `q`.
    #[inline]
    pub fn flange(&self, q: &[f64; 6]) -> Frame {
        let mut f = Frame::identity();
        for j in 0..6 {
            f *= self.joints[j].transform(q[j]);
        }
        f
    }

    /// Tool (measured target) pose in the base frame at link angles `q` (rad).
    #[inline]
    pub fn fk(&self, q: &[f64; 6]) -> Frame {
        self.flange(q) * self.tool
    }

    /// Tool pose predicted in the *instrument* frame: `(ᴮᴬˢᴱT_ᴵᴺˢᵀ)⁻¹ · fk(q)`.
    #[inline]
    pub fn fk_in_instrument(&self, q: &[f64; 6]) -> Frame {
        self.base_from_instrument.inverse() * self.fk(q)
    }

    /// Geometric Jacobian of the tool frame origin at link angles `q` (rad).
    pub fn jacobian(&self, q: &[f64; 6]) -> Jacobian {
        let f = self.frames(q);
        let p = (f[6] * self.tool).translation.vector;
        jacobian_from_frames(&f, &p)
    }

    /// Identification Jacobian at resolver (motor-side) angles `q_motor` (rad) under joint
    /// torques `tau` (N·m, held fixed, as when they come from measured currents).
    ///
    /// Columns follow the [`ParamVector`](super::ParamVector) layout. The link angles are
    /// `q_motor − δ(τ)`, so the stiffness columns are the joint columns times `∂q/∂K`.
    /// The columns of a rigid joint's stiffness are zero.
    pub fn identification_jacobian(&self, q_motor: &[f64; 6], tau: &[f64; 6]) -> IdentJacobian {
        let q = self.link_angles(q_motor, tau);
        let f = self.frames(&q);
        let p = (f[6] * self.tool).translation.vector;
        let mut jac = IdentJacobian::zeros();
        let mut set = |col: usize, lin: Vector3<f64>, ang: Vector3<f64>| {
            jac.fixed_view_mut::<3, 1>(0, col).copy_from(&lin);
            jac.fixed_view_mut::<3, 1>(3, col).copy_from(&ang);
        };
        for j in 0..6 {
            let g = &self.joints[j];
            let r_prev = f[j].rotation.matrix();
            let z = r_prev.column(2).into_owned();
            let o_prev = f[j].translation.vector;
            let o = f[j + 1].translation.vector;
            let (st, ct) = (q[j] + g.offset).sin_cos();
            // x' = R_{j}·Rz(θ)·x̂ : direction of Tx(a) and axis of Rx(α)
            let xp = r_prev * Vector3::new(ct, st, 0.0);
            // y'' = R_{j}·Rz(θ)·Rx(α)·ŷ : axis of Ry(β) (unchanged by Ry itself)
            let ypp = r_prev * Vector3::new(-st * g.ca, ct * g.ca, g.sa);
            set(IDX_THETA + j, z.cross(&(p - o_prev)), z);
            set(IDX_A + j, xp, Vector3::zeros());
            set(IDX_ALPHA + j, xp.cross(&(p - o)), xp);
            if g.hayati {
                set(IDX_D + j, ypp.cross(&(p - o)), ypp);
            } else {
                set(IDX_D + j, z, Vector3::zeros());
            }
        }
        for (k, &j) in STIFF_JOINTS.iter().enumerate() {
            if let Some(s) = self.stiffness(j) {
                let delta = q_motor[j] - q[j];
                let (dd_dklin, dd_dkcub) = s.deflection_sensitivity(delta);
                let z = f[j].rotation.matrix().column(2).into_owned();
                let lin = z.cross(&(p - f[j].translation.vector));
                // q = q_motor − δ  ⇒  ∂q/∂K = −∂δ/∂K
                set(IDX_KLIN + k, lin * -dd_dklin, z * -dd_dklin);
                set(IDX_KCUB + k, lin * -dd_dkcub, z * -dd_dkcub);
            }
        }
        jac
    }
}

impl Model {
    /// The tool position's 1σ uncertainty (m, 3-D rms: `√trace Σ_p`) at link angles `q` (rad)
    /// under joint torques `tau` (N·m), from the calibration's parameter covariance
    /// (`J_X Σ_X J_Xᵀ`) and the resolvers' repeatable error (`σ² J_q J_qᵀ`); `None` for a
    /// model without one (a nominal model). Relative to the calibrated base frame: δd₁ and δθ₁,
    /// which a free base frame absorbs exactly (the data fix only their sum with it), are left
    /// out — their prior is a convention of where the base frame sits, not an error of the arm.
    pub fn position_uncertainty(&self, q: &[f64; 6], tau: &[f64; 6]) -> Option<f64> {
        let u = self.data().uncertainty.as_ref()?;
        let delta = self.deflections(tau);
        let q_motor: [f64; 6] = std::array::from_fn(|j| q[j] + delta[j]);
        let jx = self.identification_jacobian(&q_motor, tau);
        let mut trace = 0.0;
        for r in 0..3 {
            // (J Σ Jᵀ)_rr = Σ_ab J_ra Σ_ab J_rb
            let col = |a: usize| {
                if a == IDX_D || a == IDX_THETA {
                    0.0
                } else {
                    jx[(r, a)]
                }
            };
            for a in 0..PARAM_COUNT {
                let ja = col(a);
                if ja == 0.0 {
                    continue;
                }
                for b in 0..PARAM_COUNT {
                    trace += ja * u.covariance[a][b] * col(b);
                }
            }
        }
        let jq = self.jacobian(q);
        let floor: f64 = (0..3)
            .map(|r| (0..6).map(|j| jq[(r, j)].powi(2)).sum::<f64>())
            .sum::<f64>()
            * u.resolver_rad.powi(2);
        Some((trace.max(0.0) + floor).sqrt())
    }
}

/// Geometric Jacobian of point `p` (base frame) from the DH frames 0…6.
#[inline]
pub(crate) fn jacobian_from_frames(f: &[Frame; 7], p: &Vector3<f64>) -> Jacobian {
    let mut jac = Jacobian::zeros();
    for j in 0..6 {
        let z = f[j].rotation.matrix().column(2).into_owned();
        let lin = z.cross(&(p - f[j].translation.vector));
        jac.fixed_view_mut::<3, 1>(0, j).copy_from(&lin);
        jac.fixed_view_mut::<3, 1>(3, j).copy_from(&z);
    }
    jac
}
