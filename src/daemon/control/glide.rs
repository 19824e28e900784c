//! Step 4c of the control cycle: a change of the compensation that is not a motion of the
//! setpoint — a model loaded while the arm holds — reaches the motors as a smooth glide of
//! [`GLIDE_S`] instead of a step.
//!
//! A newly loaded model can put the motor target millimetres (milliradians at the joints)
//! away from the old one at the same link setpoint. Stepping the target there kicks the
//! loaded arm's lowest mode (the links on the drives' springs in series with the servo,
//! 1.5–6 Hz on a PA10 at 0–90 N) and it rings for seconds (docs/judge.md §8). The glide
//! carries the old target's offset from the new one and lets it go along a cycloid
//! `w(u) = 1 − u + sin(2πu)/2π`, `u = t / GLIDE_S`: continuous in position, speed and
//! acceleration at both ends, so a mode of period ≤ GLIDE_S / 2 is hardly excited. A payload
//! change is *not* glided: the weight is hung at once, and a target that moves with it cancels
//! the load's kick on the link instead of adding its own. Plain data, no clock: the cycle
//! passes its period.

/// How long a model change takes to reach the motors, s.
pub const GLIDE_S: f64 = 1.0;

/// The glide in progress (or none: [`Glide::default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Glide {
    /// A change was made since the last cycle: its offset is taken at the next target.
    pending: bool,
    /// The old target − the new one at the change, rad (motor side).
    offset: [f64; 6],
    /// Time since the change, s; at or beyond [`GLIDE_S`] the glide is over.
    elapsed_s: f64,
}

impl Glide {
    /// A change of the compensation has been made: the next target glides from the last one.
    pub fn start(&mut self) {
        self.pending = true;
    }

    /// This cycle's motor target (rad) from the compensation's `raw` target, given the target
    /// sent last cycle (`last`, rad) and the cycle period `dt_s` (s).
    pub fn apply(&mut self, raw: &[f64; 6], last: &[f64; 6], dt_s: f64) -> [f64; 6] {
        if self.pending {
            self.pending = false;
            self.offset = std::array::from_fn(|j| last[j] - raw[j]);
            self.elapsed_s = 0.0;
        } else if self.elapsed_s < GLIDE_S {
            self.elapsed_s += dt_s;
        }
        if self.elapsed_s >= GLIDE_S {
            return *raw;
        }
        let w = weight(self.elapsed_s / GLIDE_S);
        std::array::from_fn(|j| raw[j] + w * self.offset[j])
    }
}

impl Default for Glide {
    /// No glide: the state a controller starts in.
    fn default() -> Self {
        Self {
            pending: false,
            offset: [0.0; 6],
            elapsed_s: GLIDE_S,
        }
    }
}

/// What remains of the offset at `u` = elapsed / [`GLIDE_S`] ∈ [0, 1]: 1 → 0 along a cycloid
/// (zero slope and curvature at both ends).
fn weight(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    1.0 - u + (std::f64::consts::TAU * u).sin() / std::f64::consts::TAU
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.002;

    #[test]
    fn an_idle_glide_passes_the_target_through() {
        let mut g = Glide::default();
        let raw = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6];
        assert_eq!(g.apply(&raw, &[0.0; 6], DT), raw);
    }

    #[test]
    fn a_change_glides_from_the_last_target_to_the_new_one_smoothly() {
        let mut g = Glide::default();
        let old = [0.0, 0.5, 1.0, 0.0, 1.0, 0.0];
        let new = [0.0, 0.503, 1.0, 0.0, 0.998, 0.0];
        g.start();
        let mut last = old;
        let mut prev_step = [0.0f64; 6];
        let n = (GLIDE_S / DT).round() as usize + 5;
        let mut max_jerkish = 0.0f64;
        for k in 0..n {
            let t = g.apply(&new, &last, DT);
            if k == 0 {
                // the first target is the old one: no step
                assert_eq!(t, old);
            }
            for j in 0..6 {
                let step = t[j] - last[j];
                // per-cycle change within the cycloid's peak rate (2 × mean) + rounding
                assert!(step.abs() <= 2.0 * (new[j] - old[j]).abs() * DT / GLIDE_S + 1e-12);
                max_jerkish = max_jerkish.max((step - prev_step[j]).abs());
                prev_step[j] = step;
            }
            last = t;
        }
        assert_eq!(last, new);
        assert_eq!(
            g,
            Glide {
                pending: false,
                ..g
            }
        );
        assert!(g.elapsed_s >= GLIDE_S);
        // the speed changes by no more than the cycloid's peak acceleration allows
        let peak_acc = std::f64::consts::TAU * 3e-3 / (GLIDE_S * GLIDE_S);
        assert!(max_jerkish <= peak_acc * DT * DT * 1.01, "{max_jerkish}");
    }

    #[test]
    fn a_change_during_a_glide_starts_from_where_the_target_is() {
        let mut g = Glide::default();
        let a = [0.0; 6];
        let b = [1e-3; 6];
        let c = [-1e-3; 6];
        g.start();
        let mut last = a;
        for _ in 0..100 {
            last = g.apply(&b, &last, DT);
        }
        let mid = last;
        g.start();
        let first = g.apply(&c, &last, DT);
        assert_eq!(first, mid);
    }

    #[test]
    fn the_weight_is_a_cycloid_from_one_to_zero() {
        assert_eq!(weight(0.0), 1.0);
        assert!(weight(1.0).abs() < 1e-15);
        assert!((weight(0.5) - 0.5).abs() < 1e-15);
        for k in 0..100 {
            assert!(weight((k + 1) as f64 / 100.0) <= weight(k as f64 / 100.0));
        }
    }
}
