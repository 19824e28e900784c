//! Joint compliance of the harmonic-drive transmissions (seed paper eq. 1).
//!
//! `τ = Klin·δ + Kcub·δ³` with `δ = q_motor − q_link`. With `Klin > 0` and `Kcub ≥ 0` the
//! map is strictly increasing and odd, so every torque has exactly one real deflection;
//! [`Stiffness::deflection`] finds it with a safeguarded Newton iteration that starts above
//! the root and descends monotonically, ending at floating-point precision.

use serde::{Deserialize, Serialize};

/// Linear + cubic torsional spring of one joint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stiffness {
    /// Linear stiffness, N·m/rad (> 0).
    pub klin: f64,
    /// Cubic stiffness, N·m/rad³ (≥ 0).
    #[serde(default)]
    pub kcub: f64,
}

impl Stiffness {
    /// Spring torque for a deflection `delta` (rad), N·m.
    #[inline]
    pub fn torque(&self, delta: f64) -> f64 {
        self.klin * delta + self.kcub * delta * delta * delta
    }

    /// Tangent stiffness `dτ/dδ` at deflection `delta`, N·m/rad.
    #[inline]
    pub fn tangent(&self, delta: f64) -> f64 {
        self.klin + 3.0 * self.kcub * delta * delta
    }

    /// The unique real deflection δ (rad) with `torque(δ) == tau` (N·m).
    ///
    /// Requires `klin > 0`, `kcub ≥ 0` (a validated model guarantees it). A non-finite torque
    /// gives NaN. The result is the root to within a few ulps: both `τ/Klin` and
    /// `∛(τ/Kcub)` bound |δ| from above, Newton on the convex branch descends from the
    /// smaller bound, and the loop stops when an iterate no longer decreases.
    ///
    /// ```
    /// use pa10::model::Stiffness;
    /// let k = Stiffness { klin: 1.98e4, kcub: 3.35e7 }; // the paper's joint 2
    /// let d = k.deflection(83.0);
    /// assert!((k.torque(d) - 83.0).abs() < 1e-11);
    /// assert!((d - 4.08e-3).abs() < 1e-5); // the seed paper's arm-horizontal example (docs/references.md [P]): 4.08 mrad
    /// ```
    #[inline]
    pub fn deflection(&self, tau: f64) -> f64 {
        if !tau.is_finite() {
            return f64::NAN;
        }
        let a = tau.abs();
        if a == 0.0 {
            return 0.0;
        }
        let mut x = a / self.klin;
        if self.kcub > 0.0 {
            x = x.min((a / self.kcub).cbrt());
        }
        // Newton from the right of the root of a convex increasing function: the iterates
        // decrease monotonically to the root; rounding ends the descent.
        for _ in 0..100 {
            let f = self.kcub * x * x * x + self.klin * x - a;
            if f <= 0.0 {
                break;
            }
            let next = x - f / (3.0 * self.kcub * x * x + self.klin);
            if next >= x {
                break;
            }
            x = next;
        }
        x.copysign(tau)
    }

    /// Sensitivities of the deflection for a fixed torque: `(∂δ/∂Klin, ∂δ/∂Kcub)` at
    /// deflection `delta`, in rad per (N·m/rad) and rad per (N·m/rad³).
    #[inline]
    pub fn deflection_sensitivity(&self, delta: f64) -> (f64, f64) {
        let t = self.tangent(delta);
        (-delta / t, -delta * delta * delta / t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_pcg::Pcg64;

    /// The root by plain bisection down to adjacent floats: slow, obviously right.
    fn bisect(k: &Stiffness, tau: f64) -> f64 {
        let a = tau.abs();
        let (mut lo, mut hi) = (0.0_f64, a / k.klin);
        loop {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if k.torque(mid) < a {
                lo = mid
            } else {
                hi = mid
            }
        }
        // the float nearer the root
        let pick = if (k.torque(hi) - a).abs() < (a - k.torque(lo)).abs() {
            hi
        } else {
            lo
        };
        pick.copysign(tau)
    }

    #[test]
    fn zero_torque_is_zero_deflection_and_sign_is_odd() {
        let k = Stiffness {
            klin: 1.27e4,
            kcub: 1.46e7,
        };
        assert_eq!(k.deflection(0.0), 0.0);
        assert_eq!(k.deflection(50.0), -k.deflection(-50.0));
        assert!(k.deflection(f64::NAN).is_nan());
        assert!(k.deflection(f64::INFINITY).is_nan());
    }

    #[test]
    fn linear_only_is_tau_over_k() {
        let k = Stiffness {
            klin: 2.56e3,
            kcub: 0.0,
        };
        assert_eq!(k.deflection(7.85), 7.85 / 2.56e3);
    }

    #[test]
    fn inverse_is_exact_over_the_full_torque_range() {
        // τ in ±1e4 N·m, Klin log-uniform over 1e2…1e6, Kcub 0 or log-uniform 1e3…1e9.
        let mut rng = Pcg64::seed_from_u64(0x5eed_0001);
        let mut worst = 0.0_f64;
        for i in 0..20_000 {
            let klin = 10f64.powf(rng.random_range(2.0..6.0));
            let kcub = if i % 5 == 0 {
                0.0
            } else {
                10f64.powf(rng.random_range(3.0..9.0))
            };
            let k = Stiffness { klin, kcub };
            let tau = match i % 4 {
                0 => rng.random_range(-1e4..1e4),
                1 => rng.random_range(-1.0..1.0),
                2 => 10f64.powf(rng.random_range(-9.0..4.0)),
                _ => -1e4,
            };
            let d = k.deflection(tau);
            let reference = bisect(&k, tau);
            let err = (d - reference).abs() / reference.abs().max(1.0);
            worst = worst.max(err);
            assert!(
                err <= 1e-12,
                "klin {klin} kcub {kcub} tau {tau}: {d} vs {reference}"
            );
        }
        assert!(worst <= 1e-12);
    }

    #[test]
    fn newton_never_needs_many_steps_even_when_terms_balance() {
        // Balanced linear and cubic terms are the slowest case; still exact.
        let k = Stiffness {
            klin: 1.0e4,
            kcub: 1.0e10,
        };
        for &tau in &[1e-6, 1.0, 20.0, 1e4, -1e4] {
            let d = k.deflection(tau);
            assert!((k.torque(d) - tau).abs() <= 1e-12 * tau.abs().max(1.0) * 4.0);
        }
    }

    #[test]
    fn sensitivity_matches_finite_differences() {
        let k = Stiffness {
            klin: 1.98e4,
            kcub: 3.35e7,
        };
        let tau = 120.0;
        let d = k.deflection(tau);
        let (dk1, dk3) = k.deflection_sensitivity(d);
        let h1 = 1.0;
        let fd1 = (Stiffness {
            klin: k.klin + h1,
            ..k
        }
        .deflection(tau)
            - Stiffness {
                klin: k.klin - h1,
                ..k
            }
            .deflection(tau))
            / (2.0 * h1);
        let h3 = 1e3;
        let fd3 = (Stiffness {
            kcub: k.kcub + h3,
            ..k
        }
        .deflection(tau)
            - Stiffness {
                kcub: k.kcub - h3,
                ..k
            }
            .deflection(tau))
            / (2.0 * h3);
        assert!((dk1 - fd1).abs() < 1e-6 * dk1.abs());
        assert!((dk3 - fd3).abs() < 1e-6 * dk3.abs());
    }
}
