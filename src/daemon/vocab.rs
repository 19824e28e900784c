//! The daemon's shared vocabulary: what one cycle reads from the bus ([`JointState`]), what
//! the planners hand the loop ([`Setpoint`]) and where the compensation's torques come from
//! ([`TorqueSource`]). A leaf: it imports nothing of the daemon, so the link, the planners,
//! the loop and the configuration can all use it without importing each other.

use serde::{Deserialize, Serialize};

/// The joint state of one cycle, as decoded from the six FEEDBACK frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    /// Resolver (motor-side) angles, rad.
    pub q_motor: [f64; 6],
    /// Motor currents, A.
    pub current: [f64; 6],
    /// When it was sampled (the SYNC time), s.
    pub stamp_s: f64,
    /// The controller reported a fault on some axis.
    pub controller_fault: bool,
}

/// A setpoint: link-side joint angles (rad) and speeds (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    /// Link angles, rad.
    pub q: [f64; 6],
    /// Link speeds, rad/s.
    pub qd: [f64; 6],
}

/// Where the joint torques for the compensation come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TorqueSource {
    /// Measured motor currents through the torque constants, low-pass filtered: sees every
    /// load — link masses, tooling, payload, known or not — but carries current noise and
    /// friction. The default: calibration identifies the springs from measured torques and
    /// never the masses, so the model's gravity is only as good as its mass seed.
    Measured,
    /// The model's gravity plus the configured payload: noise-free, exact only when the
    /// model's bodies (tooling included) and the payload are right.
    Model,
}
