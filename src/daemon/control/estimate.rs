//! Step 3 of the control cycle: the joint torques the compensation uses, from the configured
//! [`TorqueSource`], and the estimator's state (the measured torques' low-pass, a learnt
//! correction). Plain data in, torques out: no clock, no allocation, tested without a plant.
//!
//! Why the sources differ: a motor current × torque constant is the spring's torque only in
//! steady motion once friction is taken off. Accelerating, it also carries the rotor's
//! inertia torque; at rest a sticking harmonic drive holds anything within its breakaway
//! band, and the current then says nothing of the spring (docs/judge.md §8).
//! [`TorqueSource::Estimated`] therefore reads the currents only where they are unbiased —
//! a joint at constant speed (setpoint speed ≥ [`ESTIMATE_MIN_SPEED`], acceleration ≤
//! [`ESTIMATE_MAX_ACCEL`]) with the model's identified friction (`pa10 identify`)
//! subtracted — and learns from them a slow correction to the model's statics; at rest and
//! accelerating the correction is frozen. What the identified friction missed is odd in the
//! speed (a Coulomb level or viscous slope off), the statics' error is not: the odd part is
//! half the difference of the residual's slow means in positive and in negative motion
//! (learnt [`ODD_RATIO`] times slower than the correction), it is taken off before the
//! correction learns, and so the torque held at rest does not depend on the direction the
//! joint arrived from. A joint seen moving one way only has no odd part (it cannot be told
//! from the statics' error) and learns as it did without it.

use super::LoopParams;
use crate::daemon::vocab::{BLEND_HZ, Setpoint, TorqueSource};
use crate::model::{ExternalLoad, Model};

/// Slowest setpoint speed at which `estimated` reads a joint's current, rad/s (above the
/// Stribeck region of a harmonic drive: the friction there is its Coulomb + viscous level).
pub const ESTIMATE_MIN_SPEED: f64 = 0.02;

/// Largest setpoint acceleration at which `estimated` reads a joint's current, rad/s²: the
/// rotor's inertia torque (≈ 1 kg·m² reflected through the gear) stays below 0.05 N·m.
pub const ESTIMATE_MAX_ACCEL: f64 = 0.05;

/// How much slower than the correction (at [`BLEND_HZ`]) `estimated` learns the residual's
/// mean in each direction of motion, whose half difference is the odd part: 1/10, a time
/// constant of ≈ 8 s of constant-speed motion each way, long enough that a statics error
/// changing along the path mostly averages out of the difference while the correction
/// follows it.
pub const ODD_RATIO: f64 = 0.1;

/// What one cycle's estimate is computed from.
#[derive(Debug, Clone, Copy)]
pub struct EstimateInputs<'a> {
    /// The model in use (its bodies and, for `estimated`, its friction).
    pub model: &'a Model,
    /// The configured payload.
    pub load: &'a ExternalLoad,
    /// This cycle's link-side setpoint (angles rad, speeds rad/s).
    pub setpoint: &'a Setpoint,
    /// The loop holds (no move, trajectory or stream in force).
    pub holding: bool,
    /// This cycle's motor currents, A.
    pub current: &'a [f64; 6],
}

/// The estimator's state between cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TorqueEstimator {
    /// `measured`: the filtered measured torques; `blended`, `estimated`: the learnt
    /// correction to the model's statics, N·m.
    state: [f64; 6],
    /// `estimated`: per joint, the residual's slow mean in negative and in positive motion
    /// (index 0, 1), N·m, low-passed from zero …
    dir_sum: [[f64; 2]; 6],
    /// … and the same low-pass of 1 (how much each direction has been seen, 0..1).
    dir_weight: [[f64; 2]; 6],
    /// Last cycle's setpoint speeds, rad/s (`estimated`'s acceleration test).
    last_qd: [f64; 6],
}

impl TorqueEstimator {
    /// The joint torques (N·m, link side) for this cycle under `p.torque_source`:
    /// - `model`: the model's statics at the setpoint with the payload;
    /// - `measured`: currents × torque constants through a first-order low-pass of
    ///   `p.filter_hz`;
    /// - `blended`: the model's statics plus `measured − model` low-passed at [`BLEND_HZ`]
    ///   while holding, frozen in motion;
    /// - `estimated`: the model's statics plus `measured − friction − model` low-passed at
    ///   [`BLEND_HZ`] over the cycles a joint moves at constant speed, frozen otherwise (a
    ///   joint whose model has no friction learns nothing: its current is biased by an
    ///   unknown amount); the part of that residual odd in the speed (friction the
    ///   identification missed) is learnt apart and left out.
    pub fn estimate(&mut self, p: &LoopParams, i: &EstimateInputs) -> [f64; 6] {
        let qd = i.setpoint.qd;
        let accel: [f64; 6] = std::array::from_fn(|j| (qd[j] - self.last_qd[j]) / p.period_s);
        self.last_qd = qd;
        let alpha = |hz: f64| 1.0 - (-std::f64::consts::TAU * hz * p.period_s).exp();
        let measured = |j: usize| i.current[j] * p.torque_constants[j];
        match p.torque_source {
            TorqueSource::Measured => {
                let a = alpha(p.filter_hz);
                for j in 0..6 {
                    self.state[j] += a * (measured(j) - self.state[j]);
                }
                self.state
            }
            TorqueSource::Model => i.model.static_torques(&i.setpoint.q, i.load),
            TorqueSource::Blended | TorqueSource::Estimated => {
                let model = i.model.static_torques(&i.setpoint.q, i.load);
                let a = alpha(BLEND_HZ);
                for j in 0..6 {
                    let sample = match p.torque_source {
                        TorqueSource::Blended if i.holding => Some(measured(j)),
                        TorqueSource::Estimated
                            if qd[j].abs() >= ESTIMATE_MIN_SPEED
                                && accel[j].abs() <= ESTIMATE_MAX_ACCEL =>
                        {
                            i.model.friction(j).map(|f| measured(j) - f.torque(qd[j]))
                        }
                        _ => None,
                    };
                    if let Some(m) = sample {
                        let r = m - model[j];
                        let odd = if p.torque_source == TorqueSource::Estimated {
                            let d = usize::from(qd[j] > 0.0);
                            let b = ODD_RATIO * a;
                            self.dir_sum[j][d] += b * (r - self.dir_sum[j][d]);
                            self.dir_weight[j][d] += b * (1.0 - self.dir_weight[j][d]);
                            self.odd_part(j) * qd[j].signum()
                        } else {
                            0.0
                        };
                        self.state[j] += a * (r - odd - self.state[j]);
                    }
                }
                std::array::from_fn(|j| model[j] + self.state[j])
            }
        }
    }

    /// The learnt correction (`blended`, `estimated`) or the filtered torques (`measured`),
    /// N·m.
    pub fn state(&self) -> &[f64; 6] {
        &self.state
    }

    /// `estimated`: joint `j`'s residual part odd in the speed (friction the identification
    /// missed; positive: the current carries more than the identified friction in positive
    /// motion), N·m — half the difference of the two directions' means, weighted by how much
    /// the less seen direction has been seen; not in the torques returned. Zero for the other
    /// sources and for a joint seen moving one way only.
    pub fn odd_part(&self, j: usize) -> f64 {
        let [wn, wp] = self.dir_weight[j];
        if wn <= 0.0 || wp <= 0.0 {
            return 0.0;
        }
        let [sn, sp] = self.dir_sum[j];
        wn.min(wp) * (sp / wp - sn / wn) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Friction;

    const Q: [f64; 6] = [0.1, 0.4, 1.4, 0.0, 1.0, 0.0];

    fn with_friction() -> Model {
        let mut d = Model::nominal().data().clone();
        d.friction = [Some(Friction {
            breakaway: None,
            coulomb: 10.0,
            viscous: 5.0,
            sigma: None,
        }); 6];
        Model::new(d).expect("a valid model")
    }

    fn params(source: TorqueSource) -> LoopParams {
        LoopParams {
            torque_source: source,
            ..crate::daemon::control::test_params()
        }
    }

    /// Runs `cycles` cycles at the setpoint `(Q, qd)` with currents that carry `beyond` N·m
    /// more than the model's statics (an unmodelled load the spring sees, plus friction or a
    /// held band it never sees); the last estimate.
    fn run(
        e: &mut TorqueEstimator,
        p: &LoopParams,
        m: &Model,
        qd: [f64; 6],
        holding: bool,
        beyond: [f64; 6],
        cycles: usize,
    ) -> [f64; 6] {
        let load = ExternalLoad::hung(0.0, &Model::nominal().gravity());
        let sp = Setpoint { q: Q, qd };
        let tau = m.static_torques(&Q, &load);
        let current: [f64; 6] =
            std::array::from_fn(|j| (tau[j] + beyond[j]) / p.torque_constants[j]);
        let mut out = [0.0; 6];
        for _ in 0..cycles {
            out = e.estimate(
                p,
                &EstimateInputs {
                    model: m,
                    load: &load,
                    setpoint: &sp,
                    holding,
                    current: &current,
                },
            );
        }
        out
    }

    #[test]
    fn estimated_learns_in_steady_motion_with_friction_removed_and_ignores_the_held_band() {
        let m = with_friction();
        let p = params(TorqueSource::Estimated);
        let model = m.static_torques(&Q, &ExternalLoad::hung(0.0, &Model::nominal().gravity()));
        let mut e = TorqueEstimator::default();
        // at rest a sticking drive holds 20 N·m the spring does not carry: nothing learnt
        let t = run(&mut e, &p, &m, [0.0; 6], true, [20.0; 6], 5000);
        for j in 0..6 {
            assert!(
                (t[j] - model[j]).abs() < 1e-9,
                "J{}: {t:?} vs {model:?}",
                j + 1
            );
        }
        // in steady motion at +0.1 rad/s the current carries friction 10 + 0.5 N·m and an
        // unmodelled 3 N·m (a payload error): the correction finds the 3 N·m, not the friction
        let v = 0.1;
        let fr = 10.0 + 5.0 * v;
        let t = run(&mut e, &p, &m, [v; 6], false, [3.0 + fr; 6], 5000);
        for j in 0..6 {
            assert!(
                (t[j] - model[j] - 3.0).abs() < 0.01,
                "J{}: {}",
                j + 1,
                t[j] - model[j]
            );
        }
        // back at rest the correction stays (frozen), whatever the held band
        let t = run(&mut e, &p, &m, [0.0; 6], true, [-25.0; 6], 5000);
        for j in 0..6 {
            assert!((t[j] - model[j] - 3.0).abs() < 0.01);
        }
    }

    #[test]
    fn estimated_leaves_friction_the_identification_missed_out_of_the_torque_held_at_rest() {
        let m = with_friction();
        let load = ExternalLoad::hung(0.0, &Model::nominal().gravity());
        let model = m.static_torques(&Q, &load);
        let v = 0.1;
        // the identified friction is 2 N·m short of the true Coulomb level; an unmodelled
        // 3 N·m load on top: the current carries 3 + f(v) + 2·sign(v)
        let beyond = |qd: f64| 3.0 + (10.0 + 5.0 * qd.abs() + 2.0) * qd.signum();
        // the torque held at rest after arriving moving `qd`, following `tours` tours of
        // 3 s each way
        let p = params(TorqueSource::Estimated);
        let held = |tours: usize, qd: f64| {
            let mut e = TorqueEstimator::default();
            for _ in 0..tours {
                run(&mut e, &p, &m, [v; 6], false, [beyond(v); 6], 1500);
                run(&mut e, &p, &m, [-v; 6], false, [beyond(-v); 6], 1500);
            }
            run(&mut e, &p, &m, [qd; 6], false, [beyond(qd); 6], 1500);
            let t = run(&mut e, &p, &m, [0.0; 6], true, [0.0; 6], 10);
            (t[1] - model[1], e.odd_part(1))
        };
        // after one 3 s stretch each way the odd part is partly known …
        let (up, odd) = held(1, v);
        assert!(odd > 0.2 && odd < 2.0, "odd part {odd}");
        let (down, _) = held(1, -v);
        assert!((up - down).abs() < 3.0, "{up} vs {down}");
        // … after ten tours (60 s of motion) the held torque is the 3 N·m, whichever way
        // the joint arrived, within 0.2 N·m; the odd part is the 2 N·m
        let (up, odd) = held(10, v);
        let (down, _) = held(10, -v);
        assert!((odd - 2.0).abs() < 0.2, "odd part {odd}");
        assert!(
            (up - 3.0).abs() < 0.2 && (down - 3.0).abs() < 0.2,
            "{up}, {down}"
        );
        // a joint seen moving one way only: no odd part, the old behaviour (3 + 2 learnt)
        let mut e = TorqueEstimator::default();
        let t = run(&mut e, &p, &m, [v; 6], false, [beyond(v); 6], 5000);
        assert_eq!(e.odd_part(1), 0.0);
        assert!((t[1] - model[1] - 5.0).abs() < 0.01, "{}", t[1] - model[1]);
    }

    #[test]
    fn estimated_freezes_while_accelerating_and_learns_nothing_without_friction() {
        let m = with_friction();
        let p = params(TorqueSource::Estimated);
        let load = ExternalLoad::hung(0.0, &Model::nominal().gravity());
        let model = m.static_torques(&Q, &load);
        let mut e = TorqueEstimator::default();
        // a ramp of the speed at 1 rad/s² with 40 N·m of rotor torque in the current
        let current: [f64; 6] = std::array::from_fn(|j| (model[j] + 40.0) / p.torque_constants[j]);
        for k in 1..500 {
            let sp = Setpoint {
                q: Q,
                qd: [0.02 + k as f64 * p.period_s; 6],
            };
            let i = EstimateInputs {
                model: &m,
                load: &load,
                setpoint: &sp,
                holding: false,
                current: &current,
            };
            e.estimate(&p, &i);
        }
        assert_eq!(e.state(), &[0.0; 6]);
        // the nominal model has no friction: its currents are never read
        let nominal = Model::nominal();
        let mut e = TorqueEstimator::default();
        run(&mut e, &p, &nominal, [0.1; 6], false, [3.0; 6], 2000);
        assert_eq!(e.state(), &[0.0; 6]);
    }

    #[test]
    fn blended_learns_at_rest_and_measured_follows_the_currents() {
        let m = with_friction();
        let model = m.static_torques(&Q, &ExternalLoad::hung(0.0, &Model::nominal().gravity()));
        let p = params(TorqueSource::Blended);
        let mut e = TorqueEstimator::default();
        let t = run(&mut e, &p, &m, [0.0; 6], true, [2.0; 6], 5000);
        assert!((t[1] - model[1] - 2.0).abs() < 0.01);
        let t = run(&mut e, &p, &m, [0.1; 6], false, [9.0; 6], 5000);
        assert!((t[1] - model[1] - 2.0).abs() < 0.01, "frozen in motion");
        let p = params(TorqueSource::Measured);
        let mut e = TorqueEstimator::default();
        let t = run(&mut e, &p, &m, [0.1; 6], false, [1.0; 6], 5000);
        assert!((t[2] - model[2] - 1.0).abs() < 1e-6);
    }
}
