//! The PA10-6CE flexible geometric model: geometry, compliance, statics, kinematics.
//!
//! [`ModelFile`] is the plain, serialisable description (what a model YAML file holds);
//! [`Model`] is the validated, ready-to-evaluate form built from it. Every evaluation is a
//! pure function of the model and its inputs, on fixed-size types, without allocation.
//!
//! Conventions:
//! - Standard (Spong) DH: `A_i = Rz(θ_i + off_i + δθ_i) · Tz(d_i + δd_i) · Tx(a_i + δa_i) ·
//!   Rx(α_i + δα_i)`, and joint 2 (parallel to joint 3) carries Hayati's extra `· Ry(δβ_2)`
//!   in place of a `δd_2` departure.
//! - Joint angles are *link-side* unless a function says "motor": the resolver reads the
//!   motor side, `q_motor = q_link + δ(τ)` with `τ = Klin·δ + Kcub·δ³` (seed paper eq. 1).
//! - Poses are [`Frame`]s (rigid transforms) in the robot base frame, z up at the zero pose.
//! - Torques are the torques the drives apply to hold the arm static (positive along the
//!   joint axis); the spring in the transmission carries exactly that torque.

mod compliance;
mod file;
mod frame;
mod ik;
mod inertia;
mod joint_error;
mod kinematics;
mod load_effects;
mod loaded;
pub mod params;
pub(crate) mod robot;
mod statics;
pub mod urdf;

pub use compliance::Stiffness;
pub use file::{
    Body, BodySigma, EffectRecord, Friction, JointLimits, ModelFile, ParamCovariance, PoseData,
    STANDARD_GRAVITY,
};
pub use ik::{IkError, IkSolutions, MAX_SOLUTIONS};
pub use joint_error::{DEFAULT_GEAR_RATIO, JointError};
pub use kinematics::{
    Frame, IdentJacobian, Jacobian, frame_from_pose, pose_error, pose_parts, rotation_log,
};
pub use load_effects::{LoadEffects, MAX_BENDING, MAX_PAYLOAD_ERROR_KG, MAX_TOOL_SAG};
pub use loaded::{MAX_LOAD_CORRECTION, displace as displace_by_load};
pub use params::{
    Departure, DhRow, PARAM_COUNT, ParamVector, STIFF_JOINTS, param_names, param_units,
};
pub use robot::{Model, ModelError, NOMINAL_YAML};
pub use statics::{Compensation, ExternalLoad, NO_DIRECTION, Torques};
