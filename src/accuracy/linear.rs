//! The linearised resolver bound: `Σ_p = J_p·Σ_q·J_pᵀ` and the exact mean and spread of the
//! norm of that 3-D Gaussian.
//!
//! For `x ~ N(0, Σ)` with eigenvalues λᵢ, `E‖x‖ = (1/(2√π)) ∫₀^∞ (1 − Πᵢ(1 + 2tλᵢ)^(−1/2)) t^(−3/2) dt`
//! (from `‖x‖ = (1/(2√π)) ∫₀^∞ (1 − e^(−t‖x‖²)) t^(−3/2) dt` and the Gaussian's Laplace
//! transform). With `t = e^u` the integrand decays exponentially at both ends, so the
//! trapezoid rule converges geometrically; `E‖x‖² = Σλᵢ` gives the spread.

use nalgebra::{Matrix3, SymmetricEigen};

use crate::model::Model;

/// Mean and standard deviation of the position error norm, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormStats {
    /// `E‖x‖`, m.
    pub mean: f64,
    /// `sqrt(E‖x‖² − (E‖x‖)²)`, m.
    pub sd: f64,
    /// `E‖x‖²`, m².
    pub mean_square: f64,
}

/// Position covariance (m²) of the tool point at link angles `q` for independent joint
/// errors with standard deviations `sigma` (rad).
pub fn position_covariance(model: &Model, q: &[f64; 6], sigma: &[f64; 6]) -> Matrix3<f64> {
    let j = model.jacobian(q);
    let jp = j.fixed_rows::<3>(0);
    let mut cov = Matrix3::zeros();
    for k in 0..6 {
        let c = jp.column(k);
        cov += c * c.transpose() * (sigma[k] * sigma[k]);
    }
    cov
}

/// `E‖x‖` and its spread for `x ~ N(0, cov)`.
pub fn norm_stats(cov: &Matrix3<f64>) -> NormStats {
    let eig = SymmetricEigen::new(*cov).eigenvalues;
    let l = [eig[0].max(0.0), eig[1].max(0.0), eig[2].max(0.0)];
    let trace = l[0] + l[1] + l[2];
    if trace <= 0.0 {
        return NormStats {
            mean: 0.0,
            sd: 0.0,
            mean_square: 0.0,
        };
    }
    // Integrate in u = ln t around the natural scale t ~ 1/trace. The integrand decays like
    // e^(−|u|/2) at both ends, so ±60 leaves < 1e-13 relative; it is analytic and smooth on
    // the scale of 1 in u, so the trapezoid rule with h = 0.1 is exact to rounding.
    let centre = -(trace.ln());
    let (lo, hi, n) = (centre - 60.0, centre + 60.0, 1200);
    let h = (hi - lo) / n as f64;
    let f = |u: f64| {
        let half = (0.5 * u).exp();
        let t = half * half;
        // 1 − Π(1 + 2tλ)^(−1/2) = −expm1(−½ Σ ln1p(2tλ)): full precision when t·λ is tiny
        let log_prod = 0.5 * l.iter().map(|li| (2.0 * t * li).ln_1p()).sum::<f64>();
        -(-log_prod).exp_m1() / half
    };
    let mut s = 0.5 * (f(lo) + f(hi));
    for i in 1..n {
        s += f(lo + i as f64 * h);
    }
    let mean = s * h / (2.0 * std::f64::consts::PI.sqrt());
    NormStats {
        mean,
        sd: (trace - mean * mean).max(0.0).sqrt(),
        mean_square: trace,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotropic_and_one_dimensional_cases_match_closed_forms() {
        let s: f64 = 2e-4;
        // 1-D: E|x| = σ√(2/π)
        let one = norm_stats(&Matrix3::from_diagonal(&nalgebra::Vector3::new(
            s * s,
            0.0,
            0.0,
        )));
        assert!(
            (one.mean / (s * (2.0 / std::f64::consts::PI).sqrt()) - 1.0).abs() < 1e-9,
            "{one:?}"
        );
        // 3-D isotropic (Maxwell): E‖x‖ = 2σ√(2/π)
        let three = norm_stats(&Matrix3::from_diagonal_element(s * s));
        assert!((three.mean / (2.0 * s * (2.0 / std::f64::consts::PI).sqrt()) - 1.0).abs() < 1e-9);
        // 2-D isotropic (Rayleigh): E‖x‖ = σ√(π/2)
        let two = norm_stats(&Matrix3::from_diagonal(&nalgebra::Vector3::new(
            s * s,
            s * s,
            0.0,
        )));
        assert!((two.mean / (s * (std::f64::consts::PI / 2.0).sqrt()) - 1.0).abs() < 1e-9);
        assert_eq!(norm_stats(&Matrix3::zeros()).mean, 0.0);
    }
}
