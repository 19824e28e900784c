//! Periodic and lost-motion errors of one joint between its resolver and its link:
//! harmonic-drive transmission error, encoder eccentricity and backlash.
//!
//! These are the run-time effects `pa10 discover` can add to a model (besides compliance).
//! With them the link angle is
//! `q_link = q_motor − δ(τ) − e(q_motor) − (b/2)·dir`, where `e` is the periodic error plus
//! a gear-ratio error `s·q` and any polynomial term `p₂·q² + p₃·q³` (an unnamed term discovery localised outside its
//! library), `b` the backlash (total lost motion, rad) and `dir` ∈ {−1, 0, +1} the
//! direction the joint last moved in (0: unknown, the centre of the lost motion).

use serde::{Deserialize, Serialize};

/// Default wave-generator revolutions per output revolution (the PA10's 1:50 drives; the
/// gear ratios are not published, see R4 in `docs/references.md`).
pub const DEFAULT_GEAR_RATIO: f64 = 50.0;

fn default_gear_ratio() -> f64 {
    DEFAULT_GEAR_RATIO
}

fn is_zero2(v: &[[f64; 2]; 2]) -> bool {
    v.iter().flatten().all(|x| *x == 0.0)
}

fn is_zero1(v: &[f64; 2]) -> bool {
    v.iter().all(|x| *x == 0.0)
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Transmission error, eccentricity and backlash of one joint (all angles in rad, link side).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointError {
    /// Wave-generator revolutions per output revolution (> 0).
    #[serde(default = "default_gear_ratio")]
    pub gear_ratio: f64,
    /// Transmission error per output revolution: `[[sin, cos] of q, [sin, cos] of 2q]`, rad.
    #[serde(default, skip_serializing_if = "is_zero2")]
    pub output: [[f64; 2]; 2],
    /// Transmission error per wave-generator revolution: `[[sin, cos] of N·q, [sin, cos] of
    /// 2N·q]` with `N = gear_ratio`, rad.
    #[serde(default, skip_serializing_if = "is_zero2")]
    pub wave: [[f64; 2]; 2],
    /// Encoder eccentricity: `[sin, cos]` of the link angle, once per revolution, rad.
    #[serde(default, skip_serializing_if = "is_zero1")]
    pub eccentricity: [f64; 2],
    /// Backlash: total lost motion between the two approach directions, rad (≥ 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub backlash: f64,
    /// Polynomial error `[p₂, p₃]`: `p₂·q² + p₃·q³` (rad/rad², rad/rad³), a generic term
    /// `pa10 discover` localised when its library was exhausted.
    #[serde(default, skip_serializing_if = "is_zero1")]
    pub polynomial: [f64; 2],
    /// Gear-ratio (scale) error `s`: the link angle is off by `s·q` (rad/rad), a
    /// transmission whose ratio differs from the nominal by the relative amount `s`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub scale: f64,
}

impl Default for JointError {
    fn default() -> Self {
        Self {
            gear_ratio: DEFAULT_GEAR_RATIO,
            output: [[0.0; 2]; 2],
            wave: [[0.0; 2]; 2],
            eccentricity: [0.0; 2],
            backlash: 0.0,
            polynomial: [0.0; 2],
            scale: 0.0,
        }
    }
}

/// Largest slope |de/dq| a joint error may have, rad/rad: the compensation's fixed point
/// contracts by at least this factor per iteration.
pub const MAX_SLOPE: f64 = 0.5;

impl JointError {
    /// The periodic part `e(q)` (rad) at motor-side angle `q` (rad): transmission error plus
    /// eccentricity (evaluated at the motor angle; the two differ by the spring deflection,
    /// a relative 10⁻³ of an already small term).
    #[inline]
    pub fn periodic(&self, q: f64) -> f64 {
        let n = self.gear_ratio;
        // a term whose coefficients are zero adds exactly zero: its sine and cosine (most of
        // the cost: discovery evaluates every joint's error at every residual) are skipped
        let zero = |ab: &[f64; 2]| ab[0] == 0.0 && ab[1] == 0.0;
        let mut e = 0.0;
        for h in 0..2 {
            let k = (h + 1) as f64;
            if !zero(&self.output[h]) {
                let (s, c) = (k * q).sin_cos();
                e += self.output[h][0] * s + self.output[h][1] * c;
            }
            if !zero(&self.wave[h]) {
                let (s, c) = (k * n * q).sin_cos();
                e += self.wave[h][0] * s + self.wave[h][1] * c;
            }
        }
        if !zero(&self.eccentricity) {
            let (s, c) = q.sin_cos();
            // (as `e + a·s + b·c`: the sum associates as it always did)
            e = e + self.eccentricity[0] * s + self.eccentricity[1] * c;
        }
        e + q * (self.scale + q * (self.polynomial[0] + self.polynomial[1] * q))
    }

    /// The whole offset `q_motor − δ − q_link` (rad) at motor angle `q` after an approach in
    /// direction `dir` (−1, 0 or +1).
    #[inline]
    pub fn offset(&self, q: f64, dir: f64) -> f64 {
        self.periodic(q) + 0.5 * self.backlash * dir
    }

    /// An upper bound of |de/dq| (rad/rad) over |q| ≤ 2π: the contraction constant of the
    /// fixed point [`Model::compensate`](super::Model::compensate) solves.
    pub fn max_slope(&self) -> f64 {
        let n = self.gear_ratio;
        let mut s = 0.0;
        for h in 0..2 {
            let k = (h + 1) as f64;
            s += k * (self.output[h][0].abs() + self.output[h][1].abs());
            s += k * n * (self.wave[h][0].abs() + self.wave[h][1].abs());
        }
        let r = std::f64::consts::TAU;
        s + self.eccentricity[0].abs()
            + self.eccentricity[1].abs()
            + self.scale.abs()
            + 2.0 * r * self.polynomial[0].abs()
            + 3.0 * r * r * self.polynomial[1].abs()
    }

    /// Validates the values; `key` names the entry in errors.
    pub(crate) fn validate(&self, key: &str) -> Result<(), (String, String)> {
        if !(self.gear_ratio.is_finite() && self.gear_ratio > 0.0 && self.gear_ratio <= 1e4) {
            return Err((
                format!("{key}.gear_ratio"),
                format!(
                    "must be a ratio in (0, 10000] revolutions per output revolution, got {}",
                    self.gear_ratio
                ),
            ));
        }
        let all = self
            .output
            .iter()
            .chain(&self.wave)
            .flatten()
            .chain(&self.eccentricity);
        for v in all {
            if !(v.is_finite() && v.abs() <= 0.01) {
                return Err((
                    key.to_string(),
                    format!(
                        "periodic error amplitudes must be finite and within ±0.01 rad, got {v}"
                    ),
                ));
            }
        }
        for v in self.polynomial {
            if !(v.is_finite() && v.abs() <= 0.01) {
                return Err((
                    format!("{key}.polynomial"),
                    format!("coefficients must be finite and within ±0.01 rad/radⁿ, got {v}"),
                ));
            }
        }
        if !(self.scale.is_finite() && self.scale.abs() <= 0.01) {
            return Err((
                format!("{key}.scale"),
                format!(
                    "a gear-ratio error must be finite and within ±0.01 rad/rad, got {}",
                    self.scale
                ),
            ));
        }
        let slope = self.max_slope();
        if slope > MAX_SLOPE {
            return Err((
                key.to_string(),
                format!(
                    "the error's slope can reach {slope:.3} rad/rad (harmonic k of the wave generator \
                     counts k × gear_ratio); above {MAX_SLOPE} the compensation is not invertible"
                ),
            ));
        }
        if !(self.backlash.is_finite() && (0.0..=0.01).contains(&self.backlash)) {
            return Err((
                format!("{key}.backlash"),
                format!("must be within 0…0.01 rad, got {}", self.backlash),
            ));
        }
        Ok(())
    }
}
