//! The daemon's shared vocabulary: what one cycle reads from the bus ([`JointState`]), what
//! the planners hand the loop ([`Setpoint`]), what every motion is held to ([`Limits`]) and
//! where the compensation's torques come from ([`TorqueSource`]). A leaf: it imports nothing
//! of the daemon, so the link, the planners, the loop and the configuration can all use it
//! without importing each other.

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

/// What every motion of the daemon is held to, link side: the model's position limits with
/// the configuration's speed and acceleration limits (`limits.speed`, `limits.acceleration`,
/// each speed ≤ the model's). Moves and trajectories are planned within it, streams are
/// clamped to it, the position loop clamps its speed commands to it and controlled stops
/// decelerate at its accelerations. The one limits type of the daemon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Lower position limits, rad.
    pub lower: [f64; 6],
    /// Upper position limits, rad.
    pub upper: [f64; 6],
    /// Speed limits, rad/s.
    pub speed: [f64; 6],
    /// Acceleration limits, rad/s².
    pub acceleration: [f64; 6],
    /// Shortest acceleration (and deceleration) ramp of a move, s: a small move is slowed
    /// down until its ramps last this long, so its ends do not ring the loaded arm's lowest
    /// mode (0: no minimum).
    pub min_ramp_s: f64,
}

impl Limits {
    /// The first joint (1…6) whose angle in `q` (rad) is not finite or outside
    /// `[lower, upper]`, with its value.
    pub fn violation(&self, q: &[f64; 6]) -> Option<(usize, f64)> {
        (0..6)
            .find(|&j| !(q[j].is_finite() && q[j] >= self.lower[j] && q[j] <= self.upper[j]))
            .map(|j| (j + 1, q[j]))
    }
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
    /// The model's gravity plus the payload, plus a correction learnt from the measured
    /// torques while the arm holds still: the correction follows `measured − model` through a
    /// slow low-pass ([`BLEND_HZ`]) at rest and is frozen while the setpoint moves. It sees
    /// an unknown payload or mass error after a few seconds at rest, like `measured`, but the
    /// currents' friction and rotor-acceleration torques never enter it, and no fast path
    /// from the spring's torque back to the motor command exists (with `measured`, a loaded,
    /// lightly damped joint rings up: docs/judge.md). On sticking drives the currents at
    /// rest carry whatever the stuck drive holds, and so does the correction.
    Blended,
    /// The model's gravity plus the payload, plus a correction learnt only where the currents
    /// are unbiased: a joint moving at constant speed, the model's identified friction
    /// (`pa10 identify`) subtracted; frozen at rest (a sticking drive's held torque is
    /// unknown) and while accelerating (the rotor's inertia torque). The part of the
    /// residual odd in the speed (friction the identification missed, seen as the two
    /// directions' means differing) is left out, so the torque held at rest does not depend on
    /// the direction of arrival. Without identified friction it is `model`. See
    /// `daemon::control::estimate`.
    Estimated,
}

/// Corner frequency of the `blended` torque source's correction, Hz: far below a loaded
/// wrist's spring resonance (≈ 6 Hz with 90 N at the tool, docs/judge.md), so the loop it
/// closes through the spring keeps a gain well under one there; 3 time constants ≈ 2.4 s.
pub const BLEND_HZ: f64 = 0.2;
