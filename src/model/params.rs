//! The paper's 30 identification parameters: their layout, names and units.
//!
//! The flexible geometric model of the seed paper (II-C) is identified through 30 numbers:
//! 24 geometric departures (δa, δα, δd, δθ for six joints, with Hayati's δβ₂ standing in for
//! δd₂ because joints 2 and 3 are parallel) and the linear and cubic stiffness of joints
//! 2, 3 and 5. This module fixes their order in a [`ParamVector`], grouped by kind as the
//! paper writes `X = [δa δα δd δβ δθ Klin Kcub]`:
//!
//! | index | parameters | unit |
//! |---|---|---|
//! | 0–5 | δa₁ … δa₆ | m |
//! | 6–11 | δα₁ … δα₆ | rad |
//! | 12–17 | δd₁, **δβ₂**, δd₃ … δd₆ | m (δβ₂: rad) |
//! | 18–23 | δθ₁ … δθ₆ | rad |
//! | 24–26 | Klin of J2, J3, J5 | N·m/rad |
//! | 27–29 | Kcub of J2, J3, J5 | N·m/rad³ |
//!
//! A rigid joint's Klin is `+∞` (and its Kcub 0) in this vector.

use serde::{Deserialize, Serialize};

/// Number of identification parameters (24 geometric + 6 stiffness).
pub const PARAM_COUNT: usize = 30;

/// The 30 identification parameters in the order documented in this module.
pub type ParamVector = [f64; PARAM_COUNT];

/// The seed paper's manufacturing tolerances: a (m), α (rad), d (m), β (rad), θ (rad).
pub const TOLERANCES: [f64; 5] = [0.25e-3, 1e-3, 0.25e-3, 1e-3, 5e-4];

/// The seed paper's identified stiffness of J2, J3, J5: (Klin N·m/rad, Kcub N·m/rad³).
pub const PAPER_STIFFNESS: [(f64, f64); 3] = [(1.98e4, 3.35e7), (1.27e4, 1.46e7), (2.56e3, 3.83e7)];

/// Zero-based indices of the joints whose stiffness is identified (J2, J3, J5).
pub const STIFF_JOINTS: [usize; 3] = [1, 2, 4];

/// Zero-based index of the joint that carries Hayati's β instead of a d departure (J2).
pub const HAYATI_JOINT: usize = 1;

/// Index of δa₁ in a [`ParamVector`]; δa_j is at `IDX_A + j` (j zero-based).
pub const IDX_A: usize = 0;
/// Index of δα₁.
pub const IDX_ALPHA: usize = 6;
/// Index of δd₁ (δβ₂ sits at `IDX_D + 1`).
pub const IDX_D: usize = 12;
/// Index of δθ₁.
pub const IDX_THETA: usize = 18;
/// Index of Klin of J2 (then J3, J5).
pub const IDX_KLIN: usize = 24;
/// Index of Kcub of J2 (then J3, J5).
pub const IDX_KCUB: usize = 27;

/// One row of the nominal standard DH table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DhRow {
    /// Link length along x_i, metres.
    pub a: f64,
    /// Link twist about x_i, radians.
    pub alpha: f64,
    /// Link offset along z_{i-1}, metres.
    pub d: f64,
    /// Constant added to the joint angle about z_{i-1}, radians.
    pub theta_offset: f64,
}

/// Departures of one joint's DH parameters from nominal (what calibration identifies).
///
/// `dd` must be zero on joint 2 and `dbeta` zero everywhere else: the model file validator
/// enforces the paper's minimal parameterisation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Departure {
    /// δa, metres.
    #[serde(default)]
    pub da: f64,
    /// δα, radians.
    #[serde(default)]
    pub dalpha: f64,
    /// δd, metres (not on joint 2).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub dd: f64,
    /// Hayati δβ about y, radians (joint 2 only).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub dbeta: f64,
    /// δθ, radians.
    #[serde(default)]
    pub dtheta: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Human-readable names of the 30 parameters, in [`ParamVector`] order
/// (`da1`, …, `dbeta2`, …, `klin2`, `kcub5`).
pub fn param_names() -> [&'static str; PARAM_COUNT] {
    [
        "da1", "da2", "da3", "da4", "da5", "da6", //
        "dalpha1", "dalpha2", "dalpha3", "dalpha4", "dalpha5", "dalpha6", //
        "dd1", "dbeta2", "dd3", "dd4", "dd5", "dd6", //
        "dtheta1", "dtheta2", "dtheta3", "dtheta4", "dtheta5", "dtheta6", //
        "klin2", "klin3", "klin5", //
        "kcub2", "kcub3", "kcub5",
    ]
}

/// Unit of each parameter, in [`ParamVector`] order.
pub fn param_units() -> [&'static str; PARAM_COUNT] {
    let mut u = ["m"; PARAM_COUNT];
    for (i, slot) in u.iter_mut().enumerate() {
        *slot = match i {
            0..=5 => "m",
            6..=11 => "rad",
            13 => "rad",
            12..=17 => "m",
            18..=23 => "rad",
            24..=26 => "N·m/rad",
            _ => "N·m/rad³",
        };
    }
    u
}

/// Packs six joints' departures into the geometric part (indices 0–23) of a vector.
pub(crate) fn pack_departures(dep: &[Departure; 6], p: &mut ParamVector) {
    for (j, d) in dep.iter().enumerate() {
        p[IDX_A + j] = d.da;
        p[IDX_ALPHA + j] = d.dalpha;
        p[IDX_D + j] = if j == HAYATI_JOINT { d.dbeta } else { d.dd };
        p[IDX_THETA + j] = d.dtheta;
    }
}

/// Unpacks indices 0–23 of a vector into six joints' departures.
pub(crate) fn unpack_departures(p: &ParamVector) -> [Departure; 6] {
    let mut dep = [Departure::default(); 6];
    for (j, d) in dep.iter_mut().enumerate() {
        d.da = p[IDX_A + j];
        d.dalpha = p[IDX_ALPHA + j];
        if j == HAYATI_JOINT {
            d.dbeta = p[IDX_D + j];
        } else {
            d.dd = p[IDX_D + j];
        }
        d.dtheta = p[IDX_THETA + j];
    }
    dep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_units_line_up_with_indices() {
        let n = param_names();
        let u = param_units();
        assert_eq!(n[IDX_D + HAYATI_JOINT], "dbeta2");
        assert_eq!(u[IDX_D + HAYATI_JOINT], "rad");
        assert_eq!(u[IDX_D], "m");
        assert_eq!(n[IDX_KLIN], "klin2");
        assert_eq!(n[IDX_KCUB + 2], "kcub5");
        assert_eq!(u[IDX_KCUB], "N·m/rad³");
        assert_eq!(u[IDX_THETA + 5], "rad");
    }

    #[test]
    fn departures_round_trip_through_the_vector() {
        let mut dep = [Departure::default(); 6];
        for (j, d) in dep.iter_mut().enumerate() {
            let s = j as f64 + 1.0;
            d.da = 1e-4 * s;
            d.dalpha = 2e-4 * s;
            if j == HAYATI_JOINT {
                d.dbeta = 3e-4 * s;
            } else {
                d.dd = 4e-4 * s;
            }
            d.dtheta = 5e-4 * s;
        }
        let mut p = [0.0; PARAM_COUNT];
        pack_departures(&dep, &mut p);
        assert_eq!(p[IDX_D + 1], 6e-4);
        assert_eq!(unpack_departures(&p), dep);
    }
}
