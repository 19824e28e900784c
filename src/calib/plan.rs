//! Calibration campaign design: which configurations to measure, and how accurate the arm
//! will be after calibrating on them — before anything is measured.
//!
//! Plain functions on plain data. Per configuration `q` (link side) and load, the
//! *identification Jacobian* of the tool pose (position and orientation, base frame) over the
//! 30 parameters — geometric columns scaled by the seed paper's tolerances, stiffness columns
//! by `∂/∂ln K` at the paper's stiffness — and over the instrument → base frame (3 translations,
//! 3 small rotations), each row whitened by the noise of one measurement: the instrument's
//! (averaged over the repeats) plus the tool error the resolvers' repeatable error causes there
//! (which repeats do not average). Its information `JᵀJ`, summed over the campaign, plus a
//! prior of one tolerance per parameter (the fit's prior on what data cannot see), is `M`.
//!
//! - **Criteria**: **I-optimality**, the mean predicted position variance over where the arm
//!   will work, `trace(W M⁻¹)` with `W` = the average `J_pᵀJ_p` over the volume
//!   ([`i_score`], [`workspace_weight`]; `pa10 plan`'s default), and **D-optimality**,
//!   `log det M` ([`log_det`]; Borm & Menq's O1 is its geometric mean of singular values).
//!   D rewards pinning every parameter, including combinations that move the tool nowhere in
//!   the volume; I spends the measurements on what the tool's error there depends on. On the
//!   independent generator I beats random configurations and D does not (docs/calibration.md).
//! - **Selection**: greedy forward (each step the candidate with the best criterion after
//!   adding it), then exchange passes until no swap of a chosen configuration for a candidate
//!   improves it ([`select_with`] for a [`Criterion`], [`select`] for D): candidates are
//!   scored only where the criterion's tangent bound says they could win, with the answer of
//!   scoring them all ([`select_by`], the reference).
//! - **Prediction**: `Cov(X) = M⁻¹`; at a validation configuration and load the tool's position
//!   error covariance is `J_p M⁻¹ J_pᵀ` (calibration) plus the resolvers' own `J_q Σ_q J_qᵀ`
//!   (the floor, which no calibration removes); its expected norm is the predicted mean error.

use nalgebra::{Cholesky, Matrix3, SMatrix, Vector3};

mod kernel;
mod select;
pub use select::{Criterion, Design, exchange, greedy_order, select, select_by, select_with};

use crate::model::params::{
    HAYATI_JOINT, IDX_ALPHA, IDX_D, IDX_KCUB, IDX_KLIN, IDX_THETA, PAPER_STIFFNESS, STIFF_JOINTS,
    TOLERANCES,
};
use crate::model::{ExternalLoad, Model, ModelError, PARAM_COUNT, Stiffness};

/// Columns of the design: the 30 parameters, then the base frame (translation m, rotation rad).
pub const DESIGN_COLS: usize = PARAM_COUNT + 6;

/// The information matrix of a design (scaled units).
pub type Information = SMatrix<f64, DESIGN_COLS, DESIGN_COLS>;

/// One measurement's rows of the design: six pose components × the design's columns.
pub type DesignRows = SMatrix<f64, 6, DESIGN_COLS>;

/// The noise of one measurement and how often each is repeated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanNoise {
    /// Instrument position noise, m (3-D rms; 12.1 µm for the paper's CMM).
    pub position_m: f64,
    /// Instrument orientation noise, rad (3-D rms).
    pub orientation_rad: f64,
    /// Resolver repeatable error, rad (1σ per joint).
    pub resolver_rad: f64,
    /// Samples per configuration and load (they average the instrument's noise only).
    pub repeats: usize,
}

impl Default for PlanNoise {
    /// The seed paper's: CMM 12.1 µm over a 0.1 m triad, resolvers 0.64 arcmin, 10 repeats.
    fn default() -> Self {
        Self {
            position_m: 12.1e-6,
            orientation_rad: 12.1e-6 / 0.1,
            resolver_rad: 0.64 * crate::accuracy::ARCMIN,
            repeats: 10,
        }
    }
}

/// Why a design could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A setting out of range.
    #[error("{0}")]
    Invalid(String),
    /// The model.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// The model a design is computed for: `model` with the paper's stiffness on any of J2, J3,
/// J5 that it calls rigid (a design must let the springs be identified).
pub fn design_model(model: &Model) -> Result<Model, PlanError> {
    let mut d = model.data().clone();
    for (k, &j) in STIFF_JOINTS.iter().enumerate() {
        if d.stiffness[j].is_none() {
            let (klin, kcub) = PAPER_STIFFNESS[k];
            d.stiffness[j] = Some(Stiffness { klin, kcub });
        }
    }
    Ok(Model::new(d)?)
}

/// Checks the noise of a plan: positive finite instrument noise, a finite resolver error ≥ 0,
/// at least one repeat.
pub fn check_noise(noise: &PlanNoise) -> Result<(), PlanError> {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if !(ok(noise.position_m)
        && ok(noise.orientation_rad)
        && noise.resolver_rad >= 0.0
        && noise.resolver_rad.is_finite())
        || noise.repeats == 0
    {
        return Err(PlanError::Invalid(format!(
            "noise: positive finite instrument noise, a finite resolver error ≥ 0 and ≥ 1 repeat, got {noise:?}"
        )));
    }
    Ok(())
}

/// The whitened design rows of one measurement: `model` (a [`design_model`]) at link angles
/// `q` (rad) with `load_n` newtons hung at the tool.
pub fn design_rows(model: &Model, q: &[f64; 6], load_n: f64, noise: &PlanNoise) -> DesignRows {
    let load = ExternalLoad::hung(load_n, &model.gravity());
    let tau = model.static_torques(q, &load);
    // the resolver angles that put the link at q under tau
    let delta = model.deflections(&tau);
    let q_motor: [f64; 6] = std::array::from_fn(|j| q[j] + delta[j]);
    let ident = model.identification_jacobian(&q_motor, &tau);
    let p = model.fk(q).translation.vector;
    let mut rows = DesignRows::zeros();
    for c in 0..PARAM_COUNT {
        let scale = if c >= IDX_KLIN {
            // ∂/∂ln K = K ∂/∂K
            let k = (c - IDX_KLIN) % 3;
            let s = model.stiffness(STIFF_JOINTS[k]);
            match s {
                Some(s) if c < IDX_KCUB => s.klin,
                Some(s) => s.kcub,
                None => 0.0,
            }
        } else {
            tolerance(c)
        };
        for r in 0..6 {
            rows[(r, c)] = ident[(r, c)] * scale;
        }
    }
    // the base frame: p' = p + t + ω × p, orientation + ω
    for a in 0..3 {
        rows[(a, PARAM_COUNT + a)] = 1.0;
        let mut e = Vector3::zeros();
        e[a] = 1.0;
        let dp = e.cross(&p);
        for r in 0..3 {
            rows[(r, PARAM_COUNT + 3 + a)] = dp[r];
        }
        rows[(3 + a, PARAM_COUNT + 3 + a)] = 1.0;
    }
    // whitening: instrument noise over the repeats ⊕ the resolvers' repeatable error there
    let jq = model.jacobian(q);
    let mut cov = SMatrix::<f64, 6, 6>::zeros();
    let rep = noise.repeats as f64;
    for a in 0..3 {
        cov[(a, a)] = noise.position_m.powi(2) / 3.0 / rep;
        cov[(3 + a, 3 + a)] = noise.orientation_rad.powi(2) / 3.0 / rep;
    }
    cov += jq * jq.transpose() * noise.resolver_rad.powi(2);
    match Cholesky::new(cov) {
        Some(ch) => ch.l().solve_lower_triangular(&rows).unwrap_or(rows),
        None => rows,
    }
}

/// The scale of geometric parameter `c` (its tolerance: a, α, d, β, θ).
fn tolerance(c: usize) -> f64 {
    if c == IDX_D + HAYATI_JOINT {
        TOLERANCES[3]
    } else if c >= IDX_THETA {
        TOLERANCES[4]
    } else if c >= IDX_D {
        TOLERANCES[2]
    } else if c >= IDX_ALPHA {
        TOLERANCES[1]
    } else {
        TOLERANCES[0]
    }
}

/// The prior: one tolerance (one e-fold of stiffness) per parameter, 1 m / 1 rad on the base.
pub fn prior() -> Information {
    Information::identity()
}

/// The information of configuration `q` measured at every load of `loads_n` (N).
pub fn information(model: &Model, q: &[f64; 6], loads_n: &[f64], noise: &PlanNoise) -> Information {
    let mut m = Information::zeros();
    for &l in loads_n {
        let r = design_rows(model, q, l, noise);
        m += r.transpose() * r;
    }
    m
}

/// `log det` of a symmetric positive definite information matrix (−∞ when it is not).
pub fn log_det(m: &Information) -> f64 {
    match Cholesky::new(*m) {
        Some(ch) => 2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
        None => f64::NEG_INFINITY,
    }
}

/// The I-optimality score of information `m` (prior included) for where the arm will work:
/// minus the mean predicted position variance `trace(W M⁻¹)`, `W` = [`workspace_weight`]
/// (larger is better; −∞ when `m` is singular).
pub fn i_score(m: &Information, w: &Information) -> f64 {
    match Cholesky::new(*m) {
        // trace(W M⁻¹) = Σ W ∘ M⁻¹ (both symmetric)
        Some(ch) => -w.component_mul(&ch.inverse()).sum(),
        None => f64::NEG_INFINITY,
    }
}

/// `W = Σ J_pᵀ J_p / n` over link configurations `qs` and loads (unwhitened position rows):
/// the average over where the arm will work of what a parameter error does to the tool.
pub fn workspace_weight(model: &Model, qs: &[[f64; 6]], loads_n: &[f64]) -> Information {
    let unit = PlanNoise {
        position_m: 3f64.sqrt(),
        orientation_rad: 3f64.sqrt(),
        resolver_rad: 0.0,
        repeats: 1,
    };
    let mut w = Information::zeros();
    let mut n = 0usize;
    for q in qs {
        for &l in loads_n {
            let r = design_rows(model, q, l, &unit);
            let jp: SMatrix<f64, 3, DESIGN_COLS> = r.fixed_rows::<3>(0).into_owned();
            w += jp.transpose() * jp;
            n += 1;
        }
    }
    w / n.max(1) as f64
}

/// `log det` of the design made of every information in `infos` (a given pose set).
pub fn design_log_det(infos: &[Information]) -> f64 {
    log_det(&infos.iter().fold(prior(), |m, i| m + i))
}

/// Predicted mean position error (m) after calibrating on a design of information `m`
/// (prior included), at link configurations `qs` under each load of `loads_n`: the calibration's
/// share `J_p M⁻¹ J_pᵀ` plus the resolvers' floor `σ² J_q J_qᵀ`, its expected norm averaged.
/// Also returns the floor alone.
pub fn predicted_error(
    model: &Model,
    m: &Information,
    qs: &[[f64; 6]],
    loads_n: &[f64],
    noise: &PlanNoise,
) -> Result<(f64, f64), PlanError> {
    let Some(ch) = Cholesky::new(*m) else {
        return Err(PlanError::Invalid(
            "the design's information is singular".into(),
        ));
    };
    let cov = ch.inverse();
    // unwhitened rows: the same design rows with unit noise
    let unit = PlanNoise {
        position_m: 3f64.sqrt(),
        orientation_rad: 3f64.sqrt(),
        resolver_rad: 0.0,
        repeats: 1,
    };
    let (mut total, mut floor, mut n) = (0.0, 0.0, 0usize);
    for q in qs {
        let jq = model.jacobian(q).fixed_rows::<3>(0).into_owned();
        let floor_cov: Matrix3<f64> = jq * jq.transpose() * noise.resolver_rad.powi(2);
        for &l in loads_n {
            let r = design_rows(model, q, l, &unit);
            let jp: SMatrix<f64, 3, DESIGN_COLS> = r.fixed_rows::<3>(0).into_owned();
            let c: Matrix3<f64> = jp * cov * jp.transpose();
            total += crate::accuracy::linear::norm_stats(&(c + floor_cov)).mean;
            floor += crate::accuracy::linear::norm_stats(&floor_cov).mean;
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    Ok((total / n, floor / n))
}

/// Checks a plan's settings: loads finite and within 0…500 N, at least one.
pub fn check_loads(loads_n: &[f64]) -> Result<(), PlanError> {
    if loads_n.is_empty()
        || loads_n
            .iter()
            .any(|l| !(l.is_finite() && (0.0..=500.0).contains(l)))
    {
        return Err(PlanError::Invalid(format!(
            "loads: one or more within 0…500 N, got {loads_n:?}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Model {
        design_model(&Model::nominal()).unwrap()
    }

    const Q: [f64; 6] = [0.3, 0.5, 1.4, 0.2, 1.0, 0.3];

    #[test]
    fn design_columns_are_the_pose_derivatives_in_scaled_units() {
        let m = model();
        let unit = PlanNoise {
            position_m: 3f64.sqrt(),
            orientation_rad: 3f64.sqrt(),
            resolver_rad: 0.0,
            repeats: 1,
        };
        let load = 44.0;
        let rows = design_rows(&m, &Q, load, &unit);
        // the tool position at link angles q from the same resolver angles, after a scaled
        // step h of parameter c (stiffness: ln K)
        let g = ExternalLoad::hung(load, &m.gravity());
        let tau = m.static_torques(&Q, &g);
        let delta = m.deflections(&tau);
        let q_motor: [f64; 6] = std::array::from_fn(|j| Q[j] + delta[j]);
        let at = |p: &crate::model::ParamVector| {
            let mm = m.with_params(p).unwrap();
            let d = mm.deflections(&tau);
            let q: [f64; 6] = std::array::from_fn(|j| q_motor[j] - d[j]);
            mm.fk(&q).translation.vector
        };
        let p0 = m.params();
        for c in [0, 7, 13, 14, 20, IDX_KLIN, IDX_KLIN + 1, IDX_KCUB + 2] {
            let h: f64 = 1e-3;
            let mut p = p0;
            if c >= IDX_KLIN {
                p[c] *= h.exp();
            } else {
                p[c] += h * tolerance(c);
            }
            let fd = (at(&p) - at(&p0)) / h;
            let col = rows.fixed_view::<3, 1>(0, c).into_owned();
            assert!(
                (fd - col).norm() <= 1e-3 * col.norm().max(1e-9) + 1e-12,
                "column {c}: finite difference {fd:?} vs {col:?}"
            );
        }
        // the base translation moves the position one for one
        assert!((rows[(0, PARAM_COUNT)] - 1.0).abs() < 1e-12);
        assert!((rows[(4, PARAM_COUNT + 4)] - 1.0).abs() < 1e-12);
        assert!(rows[(1, PARAM_COUNT)].abs() < 1e-12);
    }

    #[test]
    fn the_chosen_design_beats_others_and_the_prediction_shrinks_with_configurations() {
        let m = model();
        let noise = PlanNoise::default();
        let loads = [0.0, 22.0, 44.0];
        // candidates: a deterministic spread over the joints
        let cands: Vec<[f64; 6]> = (0..60)
            .map(|i| {
                let f = i as f64;
                [
                    -0.8 + 1.6 * ((f * 0.37) % 1.0),
                    0.1 + 0.8 * ((f * 0.61) % 1.0),
                    0.9 + 0.9 * ((f * 0.23) % 1.0),
                    -1.5 + 3.0 * ((f * 0.71) % 1.0),
                    0.4 + 1.2 * ((f * 0.53) % 1.0),
                    -2.0 + 4.0 * ((f * 0.29) % 1.0),
                ]
            })
            .collect();
        let infos: Vec<Information> = cands
            .iter()
            .map(|q| information(&m, q, &loads, &noise))
            .collect();
        let d = select(&infos, 12, 3).unwrap();
        assert_eq!(d.chosen.len(), 12);
        let mut uniq = d.chosen.clone();
        uniq.sort();
        uniq.dedup();
        assert_eq!(uniq.len(), 12, "no candidate twice");
        // better than the first 12 and than every-fifth 12
        let first: Vec<Information> = infos[..12].to_vec();
        let spread: Vec<Information> = infos.iter().step_by(5).copied().collect();
        assert!(d.log_det > design_log_det(&first) && d.log_det > design_log_det(&spread));
        assert!(
            (d.log_det - design_log_det(&d.chosen.iter().map(|&i| infos[i]).collect::<Vec<_>>()))
                .abs()
                < 1e-6
        );
        // the prediction: more configurations, smaller error, never below the floor
        let val: Vec<[f64; 6]> = cands.iter().skip(1).step_by(7).copied().collect();
        let mut last = f64::INFINITY;
        for n in [4, 8, 16, 32] {
            let d = select(&infos, n, 1).unwrap();
            let mm = d.chosen.iter().fold(prior(), |a, &i| a + infos[i]);
            let (e, floor) = predicted_error(&m, &mm, &val, &[0.0, 45.0, 90.0], &noise).unwrap();
            assert!(e < last && e > floor, "{n}: {e} m (floor {floor} m)");
            last = e;
        }
        assert!(matches!(select(&infos, 0, 1), Err(PlanError::Invalid(_))));
        assert!(matches!(select(&infos, 61, 1), Err(PlanError::Invalid(_))));
        assert!(check_loads(&[0.0, f64::NAN]).is_err() && check_loads(&[]).is_err());
        assert!(
            check_noise(&PlanNoise {
                repeats: 0,
                ..noise
            })
            .is_err()
        );
    }
}
