//! Gravity and friction identified from the arm's own motion (`pa10 identify`), sans IO.
//!
//! A motor current × torque constant is not the spring's torque: it also carries friction, the
//! rotor's acceleration torque and, at rest, whatever torque a stuck drive happens to hold.
//! In motion at constant speed the rotor does not accelerate and the friction is a function of
//! the speed, so there the current is exactly
//!
//! `τ_j = Σ_f Y_jf(q)·φ_f + Fc_j·sign(q̇_j) + Fv_j·q̇_j`
//!
//! with `φ_f = (m, m·cx, m·cy, m·cz)` the mass and first moment of what DH frame `f` (2, 3, 5,
//! 6) carries: linear in every unknown, so one weighted linear least-squares fit identifies the
//! gravity model and every joint's Coulomb and viscous friction together. Samples of a joint
//! at rest or accelerating are left out for that joint (the held band at rest is unknown, the
//! rotor inertia is not modelled); slow sweeps in both directions separate gravity (the mean)
//! from friction (half the difference). Combinations of `φ` the motion cannot see (a centre of
//! mass along a joint axis, frames whose origins coincide) are held near the start model's
//! bodies by a weak prior, so every identified body stays physical; the posterior covariance
//! gives each value its standard error.
//!
//! [`plan_sweep`] draws the waypoints (joint margins, the tool above a floor), [`samples`] cuts
//! constant-speed samples from polled daemon status, [`identify`] fits, [`Identified::apply`]
//! writes the bodies and friction into a model.

use nalgebra::{DMatrix, DVector, Vector3};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;

use crate::model::{Body, BodySigma, ExternalLoad, Friction, Model, ModelError};

/// DH frames whose carried mass is identified: upper arm, forearm, wrist, flange (tooling).
pub const FRAMES: [usize; 4] = [2, 3, 5, 6];
/// Gravity parameters: four per frame of [`FRAMES`].
pub(crate) const NG: usize = 4 * FRAMES.len();
/// Every parameter: gravity, then Coulomb and viscous per joint.
const NP: usize = NG + 12;

/// Prior standard deviation of a frame's mass around the start model's, kg: weak (the data
/// decide wherever they can), it only fixes what the motion cannot see.
pub const PRIOR_MASS_KG: f64 = 3.0;
/// Prior standard deviation of a frame's first moment around the start model's, kg·m.
pub const PRIOR_MOMENT_KGM: f64 = 0.5;

/// One sample of the arm in motion: link angles (rad), link speeds (rad/s), which joints are at
/// a constant speed worth using, and the torques the currents carry (N·m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Link angles, rad.
    pub q: [f64; 6],
    /// Link speeds, rad/s.
    pub qd: [f64; 6],
    /// Per joint: moving at a constant speed (its row enters the fit).
    pub usable: [bool; 6],
    /// Motor current × torque constant, N·m.
    pub tau: [f64; 6],
}

/// One poll of the daemon's status: its time (s), link setpoint (rad) and currents (A).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Poll {
    /// The daemon's clock, s.
    pub t: f64,
    /// The link setpoint, rad.
    pub setpoint: [f64; 6],
    /// Motor currents, A.
    pub current: [f64; 6],
}

/// Why identification could not be done.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IdentifyError {
    /// Too few usable rows for a joint's friction.
    #[error(
        "joint {joint}: {rows} samples at constant speed in each direction are too few (need ≥ {need}): sweep it further or slower"
    )]
    TooFewRows {
        /// 1-based joint.
        joint: usize,
        /// Samples in its scarcer direction.
        rows: usize,
        /// Needed.
        need: usize,
    },
    /// An input that is not a number.
    #[error("sample {0}: a value is not finite")]
    NotFinite(usize),
    /// The normal equations could not be solved.
    #[error("the fit is singular")]
    Singular,
    /// The identified model did not validate.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A planning option out of range.
    #[error("{0}")]
    Option(String),
}

/// Fewest samples per joint and direction.
pub const MIN_ROWS: usize = 10;

/// Constant-speed samples from polls taken at a steady interval: the middle of three
/// consecutive polls, a joint usable where its setpoint speed is at least `min_speed` (rad/s)
/// and changed by less than 2 % between the two intervals (no acceleration). The torques are
/// `current × kt` (N·m/A); `q` the setpoint (link side), `qd` the setpoint's speed.
pub fn samples(polls: &[Poll], kt: &[f64; 6], min_speed: f64) -> Vec<Sample> {
    polls
        .windows(3)
        .filter_map(|w| {
            let (d1, d2) = (w[1].t - w[0].t, w[2].t - w[1].t);
            if !(d1 > 0.0 && d2 > 0.0) {
                return None;
            }
            let v1: [f64; 6] = std::array::from_fn(|j| (w[1].setpoint[j] - w[0].setpoint[j]) / d1);
            let v2: [f64; 6] = std::array::from_fn(|j| (w[2].setpoint[j] - w[1].setpoint[j]) / d2);
            let usable: [bool; 6] = std::array::from_fn(|j| {
                let v = 0.5 * (v1[j] + v2[j]);
                v.abs() >= min_speed && (v1[j] - v2[j]).abs() <= 0.02 * v.abs()
            });
            usable.iter().any(|u| *u).then(|| Sample {
                q: w[1].setpoint,
                qd: std::array::from_fn(|j| 0.5 * (v1[j] + v2[j])),
                usable,
                tau: std::array::from_fn(|j| w[1].current[j] * kt[j]),
            })
        })
        .collect()
}

/// How long after a sweep starts its status is polled every control cycle for [`breakaway`], s.
pub const START_WINDOW_S: f64 = 0.4;

/// Least setpoint travel of a joint over a start window for it to count as starting, rad.
const MIN_START_RAD: f64 = 1e-4;

/// Per joint, the breakaway level (N·m) from the polls of sweep starts (`starts`: each the
/// polls of one sweep's first [`START_WINDOW_S`], every control cycle): in each start where a
/// joint's setpoint travels, the peak of `direction × (current × kt − gravity(q))` with
/// `model`'s gravity — at rest the drive holds what it held, the torque then rises until the
/// drive breaks away and falls to the sliding level — and the median over the starts in both
/// directions. `None` for a joint with fewer than two starts.
pub fn breakaway(model: &Model, starts: &[Vec<Poll>], kt: &[f64; 6]) -> [Option<f64>; 6] {
    let mut peaks: [Vec<f64>; 6] = Default::default();
    for polls in starts {
        let (Some(first), Some(last)) = (polls.first(), polls.last()) else {
            continue;
        };
        for (j, peak) in peaks.iter_mut().enumerate() {
            let travel = last.setpoint[j] - first.setpoint[j];
            if travel.abs() < MIN_START_RAD {
                continue;
            }
            let p = polls
                .iter()
                .map(|p| {
                    let g = model.static_torques(&p.setpoint, &ExternalLoad::NONE)[j];
                    travel.signum() * (p.current[j] * kt[j] - g)
                })
                .fold(f64::NEG_INFINITY, f64::max);
            if p.is_finite() {
                peak.push(p.max(0.0));
            }
        }
    }
    peaks.map(|mut v| {
        if v.len() >= 2 {
            crate::stats::median(&mut v)
        } else {
            None
        }
    })
}

/// The gravity regressor at link angles `q`: `τ_g = Y·φ` (N·m) with `φ` the four parameters of
/// each frame in [`FRAMES`] (kg, kg·m), in the model's convention (the torques the drives
/// apply to hold the arm).
pub fn gravity_regressor(model: &Model, q: &[f64; 6]) -> [[f64; NG]; 6] {
    let f = model.frames(q);
    let g = model.gravity();
    let mut y = [[0.0; NG]; 6];
    for (k, &frame) in FRAMES.iter().enumerate() {
        let fr = &f[frame];
        let o_f = fr.translation.vector;
        let r = &fr.rotation;
        for (i, row) in y.iter_mut().enumerate().take(frame) {
            let z = f[i].rotation * Vector3::z();
            let o = f[i].translation.vector;
            // τ_i = −(z × (p − o))·(m g), p·m = o_f·m + R·(m c)
            row[4 * k] = -(z.cross(&(o_f - o))).dot(&g);
            for c in 0..3 {
                let axis = r.matrix().column(c).into_owned();
                row[4 * k + 1 + c] = -(z.cross(&axis)).dot(&g);
            }
        }
    }
    y
}

/// The start model's bodies of [`FRAMES`] as their parameters (bodies of other frames are not
/// identified: [`identify`] takes their torques as known and [`Identified::apply`] keeps them).
pub(crate) fn prior_params(model: &Model) -> [f64; NG] {
    let mut phi = [0.0; NG];
    for b in &model.data().bodies {
        if let Some(k) = FRAMES.iter().position(|&f| f == b.frame) {
            phi[4 * k] += b.mass;
            for c in 0..3 {
                phi[4 * k + 1 + c] += b.mass * b.com[c];
            }
        }
    }
    phi
}

/// Every value of every sample is a number; the first that is not is named by its index.
pub(crate) fn check_finite(samples: &[Sample]) -> Result<(), IdentifyError> {
    match samples.iter().position(|s| {
        s.q.iter()
            .chain(&s.qd)
            .chain(&s.tau)
            .any(|v| !v.is_finite())
    }) {
        Some(i) => Err(IdentifyError::NotFinite(i)),
        None => Ok(()),
    }
}

/// Per sample: the gravity regressor at its angles, and the torques of the bodies outside
/// [`FRAMES`] (known: the model's statics less what its [`FRAMES`] bodies give), N·m.
pub(crate) fn regressors(model: &Model, samples: &[Sample]) -> Vec<([[f64; NG]; 6], [f64; 6])> {
    let prior = prior_params(model);
    samples
        .iter()
        .map(|s| {
            let y = gravity_regressor(model, &s.q);
            let all = model.static_torques(&s.q, &ExternalLoad::NONE);
            let known =
                std::array::from_fn(|j| all[j] - (0..NG).map(|p| y[j][p] * prior[p]).sum::<f64>());
            (y, known)
        })
        .collect()
}

/// The weak prior's weight on gravity parameter `p` (1/σ², σ = [`PRIOR_MASS_KG`] for a mass,
/// [`PRIOR_MOMENT_KGM`] for a first moment).
pub(crate) fn prior_weight(p: usize) -> f64 {
    let s0 = if p.is_multiple_of(4) {
        PRIOR_MASS_KG
    } else {
        PRIOR_MOMENT_KGM
    };
    1.0 / (s0 * s0)
}

/// What [`identify`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Identified {
    /// Mass (kg) and first moment (kg·m) per frame of [`FRAMES`].
    pub params: [f64; NG],
    /// Their standard errors.
    pub params_sigma: [f64; NG],
    /// Per joint: Coulomb (N·m), viscous (N·m·s/rad) and their standard errors.
    pub friction: [Friction; 6],
    /// RMS of each joint's residual, N·m.
    pub residual_rms: [f64; 6],
    /// Rows used per joint.
    pub rows: [usize; 6],
}

/// Fits gravity and friction to `samples` (module documentation), starting from `model`'s
/// bodies as the weak prior.
pub fn identify(model: &Model, samples: &[Sample]) -> Result<Identified, IdentifyError> {
    check_finite(samples)?;
    for j in 0..6 {
        let (up, down) = samples
            .iter()
            .filter(|s| s.usable[j])
            .fold((0, 0), |(u, d), s| {
                if s.qd[j] > 0.0 {
                    (u + 1, d)
                } else {
                    (u, d + 1)
                }
            });
        if up.min(down) < MIN_ROWS {
            return Err(IdentifyError::TooFewRows {
                joint: j + 1,
                rows: up.min(down),
                need: MIN_ROWS,
            });
        }
    }
    let rows: Vec<(usize, usize)> = samples
        .iter()
        .enumerate()
        .flat_map(|(i, s)| (0..6).filter(move |&j| s.usable[j]).map(move |j| (i, j)))
        .collect();
    let prior = prior_params(model);
    let regs = regressors(model, samples);
    let mut a = DMatrix::<f64>::zeros(rows.len(), NP);
    let mut b = DVector::<f64>::zeros(rows.len());
    let mut counts = [0usize; 6];
    for (r, &(i, j)) in rows.iter().enumerate() {
        let (s, (y, known)) = (&samples[i], &regs[i]);
        for p in 0..NG {
            a[(r, p)] = y[j][p];
        }
        a[(r, NG + 2 * j)] = s.qd[j].signum();
        a[(r, NG + 2 * j + 1)] = s.qd[j];
        b[r] = s.tau[j] - known[j];
        counts[j] += 1;
    }
    let mut sigma_j = [1.0; 6];
    let mut x = DVector::<f64>::zeros(NP);
    let mut cov = DMatrix::<f64>::zeros(NP, NP);
    // two passes: the second weighs each joint's rows by the noise the first pass left
    for _ in 0..2 {
        let mut n = DMatrix::<f64>::zeros(NP, NP);
        let mut rhs = DVector::<f64>::zeros(NP);
        for (r, &(_, j)) in rows.iter().enumerate() {
            let w = 1.0 / (sigma_j[j] * sigma_j[j]);
            let row = a.row(r);
            n += w * row.transpose() * row;
            rhs += w * row.transpose() * b[r];
        }
        for p in 0..NG {
            n[(p, p)] += prior_weight(p);
            rhs[p] += prior[p] * prior_weight(p);
        }
        let chol = n.cholesky().ok_or(IdentifyError::Singular)?;
        x = chol.solve(&rhs);
        cov = chol.inverse();
        let res = &b - &a * &x;
        let mut ss = [0.0; 6];
        for (r, &(_, j)) in rows.iter().enumerate() {
            ss[j] += res[r] * res[r];
        }
        sigma_j = std::array::from_fn(|j| (ss[j] / counts[j].max(1) as f64).sqrt().max(1e-6));
    }
    Ok(Identified {
        params: std::array::from_fn(|p| x[p]),
        params_sigma: std::array::from_fn(|p| cov[(p, p)].sqrt()),
        friction: std::array::from_fn(|j| Friction {
            breakaway: None,
            coulomb: x[NG + 2 * j].max(0.0),
            viscous: x[NG + 2 * j + 1].max(0.0),
            sigma: Some([
                cov[(NG + 2 * j, NG + 2 * j)].sqrt(),
                cov[(NG + 2 * j + 1, NG + 2 * j + 1)].sqrt(),
            ]),
        }),
        residual_rms: sigma_j,
        rows: counts,
    })
}

impl Identified {
    /// `model` with the identified bodies (one per frame of [`FRAMES`] whose mass is positive,
    /// named as the model's body of that frame or `frame N`; bodies of other frames kept) and
    /// every joint's friction.
    pub fn apply(&self, model: &Model) -> Result<Model, IdentifyError> {
        let mut d = model.data().clone();
        let names: Vec<(usize, String)> =
            d.bodies.iter().map(|b| (b.frame, b.name.clone())).collect();
        d.bodies.retain(|b| !FRAMES.contains(&b.frame));
        for (k, &frame) in FRAMES.iter().enumerate() {
            let m = self.params[4 * k];
            if m <= 1e-3 {
                continue;
            }
            let com: [f64; 3] = std::array::from_fn(|c| self.params[4 * k + 1 + c] / m);
            let sm = self.params_sigma[4 * k];
            let name = names
                .iter()
                .find(|(f, _)| *f == frame)
                .map_or_else(|| format!("frame {frame}"), |(_, n)| n.clone());
            d.bodies.push(Body {
                name,
                frame,
                mass: m,
                com,
                // first-order: σ(c) ≈ √(σ(mc)² + (c·σ(m))²) / m
                sigma: Some(BodySigma {
                    mass: sm,
                    com: std::array::from_fn(|c| {
                        let smc = self.params_sigma[4 * k + 1 + c];
                        (smc * smc + (com[c] * sm).powi(2)).sqrt() / m
                    }),
                }),
            });
        }
        d.bodies.sort_by_key(|b| b.frame);
        d.friction = self.friction.map(Some);
        Ok(Model::new(d)?)
    }
}

/// Options of [`plan_sweep`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepPlan {
    /// Waypoints of the tour (each segment is driven there and back).
    pub waypoints: usize,
    /// Fraction of each joint's range kept clear at both ends (0…0.45).
    pub margin: f64,
    /// Lowest tool height allowed at every waypoint and halfway between, m (base frame).
    pub floor_z: f64,
    /// Largest change of any joint from one waypoint to the next, rad.
    pub max_step: f64,
    /// Seed of the draw.
    pub seed: u64,
}

impl Default for SweepPlan {
    fn default() -> Self {
        Self {
            waypoints: 10,
            margin: 0.25,
            floor_z: 0.3,
            max_step: 0.8,
            seed: 1,
        }
    }
}

/// A tour of link-angle waypoints (rad) for the sweeps: drawn uniformly within the joint
/// limits less `margin`, each with the tool above `floor_z` at it and halfway from the
/// previous one. The caller drives every segment there and back.
pub fn plan_sweep(
    model: &Model,
    start: &[f64; 6],
    p: &SweepPlan,
) -> Result<Vec<[f64; 6]>, IdentifyError> {
    if !(0.0..=0.45).contains(&p.margin) {
        return Err(IdentifyError::Option(format!(
            "margin: 0…0.45 of each joint's range, got {}",
            p.margin
        )));
    }
    if !(1..=200).contains(&p.waypoints) {
        return Err(IdentifyError::Option(format!(
            "waypoints: 1…200, got {}",
            p.waypoints
        )));
    }
    if !(p.max_step.is_finite() && p.max_step > 0.0) {
        return Err(IdentifyError::Option(format!(
            "max_step: a positive step in rad, got {}",
            p.max_step
        )));
    }
    if !p.floor_z.is_finite() {
        return Err(IdentifyError::Option("floor: a finite height in m".into()));
    }
    let lim = model.limits();
    let mut rng = Pcg64::seed_from_u64(p.seed);
    let above = |q: &[f64; 6]| model.fk(q).translation.vector.z >= p.floor_z;
    let mut out = vec![*start];
    for _ in 0..p.waypoints {
        let prev = out[out.len() - 1];
        let mut found = None;
        for _ in 0..10_000 {
            let q: [f64; 6] = std::array::from_fn(|j| {
                let span = lim.upper[j] - lim.lower[j];
                let lo = (lim.lower[j] + p.margin * span).max(prev[j] - p.max_step);
                let hi = (lim.upper[j] - p.margin * span).min(prev[j] + p.max_step);
                if lo < hi {
                    rng.random_range(lo..hi)
                } else {
                    prev[j]
                }
            });
            let mid: [f64; 6] = std::array::from_fn(|j| 0.5 * (q[j] + prev[j]));
            if above(&q) && above(&mid) {
                found = Some(q);
                break;
            }
        }
        out.push(found.ok_or_else(|| {
            IdentifyError::Option(format!(
                "no waypoint with the tool above {} m: lower the floor",
                p.floor_z
            ))
        })?);
    }
    Ok(out)
}

/// A timed trajectory point: time from the start (s), positions (rad), velocities (rad/s).
pub type TimedPoint = (f64, [f64; 6], [f64; 6]);

/// One sweep from `a` to `b` (link angles, rad) at constant speed: the fastest-moving joint at
/// `speed` (rad/s; less on a segment too short to reach it), every joint arriving together,
/// accelerating and braking at `accel` (rad/s², the fastest joint's). Timed points `(time from
/// start s, positions rad, velocities rad/s)` for a trajectory that interpolates cubic Hermite
/// segments: the ramps are then at constant acceleration and the middle segment exactly at
/// constant speed. `None` when `a` is `b` or `speed` or `accel` is not positive.
pub fn sweep_segment(
    a: &[f64; 6],
    b: &[f64; 6],
    speed: f64,
    accel: f64,
) -> Option<Vec<TimedPoint>> {
    let dist = (0..6).map(|j| (b[j] - a[j]).abs()).fold(0.0, f64::max);
    if !(speed > 0.0 && accel > 0.0) || dist < 1e-9 {
        return None;
    }
    // both ramps together cover speed²/accel; a short segment is driven slower
    let speed = speed.min((dist * accel).sqrt());
    let ramp_s = speed / accel;
    let cruise = (dist - speed * ramp_s) / speed;
    let total = cruise + ramp_s;
    let v: [f64; 6] = std::array::from_fn(|j| (b[j] - a[j]) / total);
    let p1: [f64; 6] = std::array::from_fn(|j| a[j] + 0.5 * v[j] * ramp_s);
    let p2: [f64; 6] = std::array::from_fn(|j| b[j] - 0.5 * v[j] * ramp_s);
    Some(vec![
        (ramp_s, p1, v),
        (ramp_s + cruise, p2, v),
        (2.0 * ramp_s + cruise, *b, [0.0; 6]),
    ])
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn truth() -> Model {
        let mut d = Model::nominal().data().clone();
        d.bodies[0].mass *= 1.08;
        d.bodies[1].com[2] += 0.012;
        d.bodies[2].mass *= 0.9;
        Model::new(d).unwrap()
    }

    /// The torques an arm gives, `torques(q rad, q̇ rad/s, at rest, rng)` in N·m.
    pub(crate) type Torques<'a> = dyn Fn(&[f64; 6], &[f64; 6], bool, &mut Pcg64) -> [f64; 6] + 'a;

    /// Polls every 20 ms of `tour` driven out (0.15 rad/s) and back (0.3 rad/s) segment by
    /// segment at constant speed, a second at rest between sweeps; `torques` gives each
    /// poll's "currents" (torque constants 1 N·m/A).
    pub(crate) fn synthetic_polls(
        tour: &[[f64; 6]],
        rng: &mut Pcg64,
        torques: &Torques<'_>,
    ) -> Vec<Poll> {
        let mut polls = Vec::new();
        let mut time = 0.0;
        let dt = 0.02;
        for w in tour.windows(2) {
            for (a, b, speed) in [(w[0], w[1], 0.15), (w[1], w[0], 0.3)] {
                let dist = (0..6).map(|j| (b[j] - a[j]).abs()).fold(0.0, f64::max);
                let n = (dist / speed / dt).ceil() as usize + 1;
                for k in 0..=n {
                    let s = k as f64 / n as f64;
                    let q: [f64; 6] = std::array::from_fn(|j| a[j] + s * (b[j] - a[j]));
                    let qd: [f64; 6] = std::array::from_fn(|j| (b[j] - a[j]) / (n as f64 * dt));
                    polls.push(Poll {
                        t: time,
                        setpoint: q,
                        current: torques(&q, &qd, k == 0 || k == n, rng),
                    });
                    time += dt;
                }
                time += 1.0; // a pause at rest
            }
        }
        polls
    }

    #[test]
    fn the_regressor_times_the_bodies_is_the_models_gravity() {
        let m = Model::nominal();
        let phi = prior_params(&m);
        for q in [
            [0.3, -0.7, 1.1, 0.4, -0.9, 0.2],
            [0.0, 0.5, 1.6, 0.0, 1.1, 0.0],
        ] {
            let y = gravity_regressor(&m, &q);
            let t = m.static_torques(&q, &ExternalLoad::NONE);
            for j in 0..6 {
                let g: f64 = (0..NG).map(|p| y[j][p] * phi[p]).sum();
                assert!((g - t[j]).abs() < 1e-9, "joint {j}: {g} vs {t:?}");
            }
        }
    }

    /// Sweeps of a truth with other masses and friction, with stuck-drive torques at rest that
    /// must not enter, and current noise: the truth's gravity and friction come back.
    #[test]
    fn gravity_and_friction_come_back_from_sweeps_and_held_torques_stay_out() {
        let t = truth();
        let fc = [12.0, 27.0, 13.0, 4.5, 4.0, 1.8];
        let fv = [8.0, 8.0, 4.0, 1.0, 1.0, 0.3];
        let mut rng = Pcg64::seed_from_u64(7);
        let tour = plan_sweep(&t, &[0.0, 0.4, 1.6, 0.0, 1.1, 0.0], &SweepPlan::default()).unwrap();
        let polls = synthetic_polls(&tour, &mut rng, &|q, qd, at_rest, rng| {
            let g = t.static_torques(q, &ExternalLoad::NONE);
            std::array::from_fn(|j| {
                let f = if at_rest {
                    // at rest: a stuck drive holds anything within ±1.6 Fc
                    rng.random_range(-1.6..1.6) * fc[j]
                } else {
                    fc[j] * qd[j].signum() + fv[j] * qd[j]
                };
                g[j] + f + 0.3 * rng.random_range(-1.0..1.0)
            })
        });
        let s = samples(&polls, &[1.0; 6], 0.02);
        let id = identify(&Model::nominal(), &s).unwrap();
        for j in 0..6 {
            let f = id.friction[j];
            assert!(
                (f.coulomb - fc[j]).abs() < 0.1 + 0.02 * fc[j],
                "J{}: {f:?}",
                j + 1
            );
            assert!(
                (f.viscous - fv[j]).abs() < 0.5 + 0.05 * fv[j],
                "J{}: {f:?}",
                j + 1
            );
        }
        // the gravity torques over fresh configurations match the truth's
        let m = id.apply(&Model::nominal()).unwrap();
        let mut off_by = |model: &Model| {
            let mut worst = 0.0f64;
            for _ in 0..50 {
                let q: [f64; 6] = std::array::from_fn(|_| rng.random_range(-1.2..1.2));
                let a = model.static_torques(&q, &ExternalLoad::NONE);
                let b = t.static_torques(&q, &ExternalLoad::NONE);
                worst = (0..6).map(|j| (a[j] - b[j]).abs()).fold(worst, f64::max);
            }
            worst
        };
        let worst = off_by(&m);
        assert!(worst < 0.3, "gravity torques off by {worst} N·m");
        // the nominal model is off by far more at other configurations
        let nominal = off_by(&Model::nominal());
        assert!(
            nominal > 5.0 * worst,
            "nominal {nominal} N·m vs identified {worst}"
        );
        assert!(m.friction(1).is_some() && m.data().bodies.iter().all(|b| b.sigma.is_some()));
    }

    /// Sweep starts of a sticking drive: at rest it holds a random torque, then the torque
    /// rises until it breaks away at 1.6 × Coulomb and falls to the sliding level; J6 never
    /// moves. The breakaway comes back per joint; J6 has none.
    #[test]
    fn the_breakaway_is_the_peak_over_gravity_at_the_sweeps_starts() {
        let m = Model::nominal();
        let fc = [12.0, 27.0, 13.0, 4.5, 4.0, 1.8];
        let mut rng = Pcg64::seed_from_u64(3);
        let mut starts = Vec::new();
        for k in 0..6 {
            let dir = if k % 2 == 0 { 1.0 } else { -1.0 };
            let q0 = [0.1 * k as f64, 0.4, 1.4, 0.2, 0.9, 0.0];
            let held: [f64; 6] = std::array::from_fn(|j| rng.random_range(-1.0..1.0) * fc[j]);
            let polls: Vec<Poll> = (0..200)
                .map(|i| {
                    let t = i as f64 * 0.002;
                    let mut q = q0;
                    for qj in q.iter_mut().take(5) {
                        *qj += dir * 0.2 * t * t; // 0.4 rad/s² from rest
                    }
                    let g = m.static_torques(&q, &ExternalLoad::NONE);
                    let current = std::array::from_fn(|j| {
                        // held, rising over 0.1 s (50 polls) to breakaway, then sliding
                        let f = if i <= 50 {
                            held[j] + (dir * 1.6 * fc[j] - held[j]) * i as f64 / 50.0
                        } else {
                            dir * fc[j]
                        };
                        g[j] + f + 0.05 * rng.random_range(-1.0..1.0)
                    });
                    Poll {
                        t,
                        setpoint: q,
                        current,
                    }
                })
                .collect();
            starts.push(polls);
        }
        let b = breakaway(&m, &starts, &[1.0; 6]);
        for j in 0..5 {
            let got = b[j].expect("moved");
            assert!((got - 1.6 * fc[j]).abs() < 0.1, "J{}: {got}", j + 1);
        }
        assert_eq!(b[5], None, "J6 never moved");
        assert_eq!(breakaway(&m, &starts[..1], &[1.0; 6])[0], None, "one start");
    }

    #[test]
    fn too_few_rows_and_bad_plans_are_refused_with_the_reason() {
        let e = identify(&Model::nominal(), &[]).unwrap_err();
        assert!(e.to_string().contains("joint 1"), "{e}");
        let bad = SweepPlan {
            margin: 0.6,
            ..SweepPlan::default()
        };
        assert!(
            plan_sweep(&Model::nominal(), &[0.0; 6], &bad)
                .unwrap_err()
                .to_string()
                .contains("margin")
        );
        let high = SweepPlan {
            floor_z: 5.0,
            ..SweepPlan::default()
        };
        assert!(
            plan_sweep(&Model::nominal(), &[0.0; 6], &high)
                .unwrap_err()
                .to_string()
                .contains("floor")
        );
    }
}
