//! What the measurement noise of a dataset is, estimated from the data as variance
//! components — never assumed from a simulator.
//!
//! Four components, each with a 95 % confidence interval:
//!
//! - **reading noise** per joint: the resolver *reading* scatters from repeat to repeat
//!   while the arm stays (errors in variables). It shows twice: as scatter of `q1..q6`
//!   within a repeat cell, and as a residual that follows that scatter (`Δr = −J·Δq`). If
//!   the arm really moved with the reading, the model predicts the motion and the residual
//!   does not follow. The within-cell regression of the residual deviations on `J_j·Δq_j`
//!   measures the share `ρ_j` of the reading scatter that is noise; the reading noise is
//!   `ρ_j·s²_q,j`.
//! - **instrument noise** per axis of the instrument frame, position (m) and orientation
//!   (rad): what is left of the within-cell residual deviations.
//! - **torque noise** per joint: the scatter of the measured torques within a cell (the
//!   load and the pose are constant there), as `a_j² + r_j²·τ²` (absolute and relative).
//! - **repeatable resolver error** (one σ for every joint): an offset shared by all rows of
//!   a configuration, seen only between configurations. It is estimated with the
//!   generalised Q statistic of the configuration means `Q(σ²) = Σ_c m̂_cᵀ(P_c⁻¹ +
//!   σ²·J_c J_cᵀ)⁻¹ m̂_c` solved for `Q = dof` (the Paule–Mandel estimator, a
//!   method-of-moments relative of REML), with the Q-profile confidence interval
//!   (Viechtbauer 2007) and the test of `σ = 0`: `P(χ²_dof > Q(0))`.
//!
//! The structure (reading noise, repeatable error, both, instrument only) is chosen by
//! those likelihood tests at α = 0.01; a repeatable error must also be material (≥ 35 % of
//! the resolver's scale) to count. Without repeats the within-cell components cannot be
//! measured: the prior (sidecar) instrument noise and resolver σ are taken, the resolver
//! error as independent per row, and the report says so.
//!
//! Plain functions on plain data: callers hand in residuals and sensitivities at their
//! current model ([`Sample`]); no model, no IO in here.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Vector6};
use serde::Serialize;

use crate::stats::{chi2_quantile, chi2_sf};

/// Significance level of the structure tests.
pub const ALPHA: f64 = 0.01;

/// Share of the resolver's scale (the larger of the reading noise and the prior σ) a
/// repeatable error must reach to count in the structure (see [`estimate`]).
pub const MATERIAL: f64 = 0.35;

/// Within-cell degrees of freedom below which the repeats are too few to measure noise.
pub const MIN_WITHIN_DOF: usize = 10;

/// One measured row, seen at the caller's current model.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Configuration index: rows of a configuration share its repeatable resolver error.
    pub config: usize,
    /// Repeat-cell index: rows of a cell are repeats (same configuration, load, approach
    /// direction, temperature).
    pub cell: usize,
    /// Resolver readings, rad.
    pub q: [f64; 6],
    /// Measured joint torques, N·m.
    pub tau: [f64; 6],
    /// Measured minus predicted pose in the robot base frame: position (m), then rotation
    /// vector (rad).
    pub residual: Vector6<f64>,
    /// `∂pred/∂q`: the predicted pose's sensitivity to the readings (m/rad, rad/rad).
    pub jq: Matrix6<f64>,
    /// `∂pred/∂τ`: the predicted pose's sensitivity to the measured torques through the
    /// springs (m/(N·m), rad/(N·m); `−J·dδ/dτ` for springs the link lags by `δ(τ)`); zero
    /// for a rigid model.
    pub jt: Matrix6<f64>,
}

/// What is assumed where the data cannot say (the dataset's sidecar, else the PA10's
/// specification and the paper's CMM).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Prior {
    /// Instrument position noise, 3-D rms, m (the paper's CMM: 12.1 µm).
    pub position_m: f64,
    /// Resolver uncertainty per joint (1σ), rad (the PA10: 0.64 arcmin).
    pub resolver_rad: f64,
}

impl Default for Prior {
    fn default() -> Self {
        Self {
            position_m: 12.1e-6,
            resolver_rad: 0.64 * crate::accuracy::ARCMIN,
        }
    }
}

/// An estimate (1σ) with its 95 % confidence interval, in the unit of its field.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    /// The estimate.
    pub value: f64,
    /// Lower 95 % bound.
    pub lo: f64,
    /// Upper 95 % bound.
    pub hi: f64,
}

impl Interval {
    fn fixed(v: f64) -> Self {
        Self {
            value: v,
            lo: v,
            hi: v,
        }
    }

    /// σ from a variance estimate `s2` with `dof` degrees of freedom (χ² interval).
    fn from_variance(s2: f64, dof: f64) -> Self {
        if dof < 1.0 || s2.is_nan() || s2 < 0.0 {
            return Self::fixed(s2.max(0.0).sqrt());
        }
        Self {
            value: s2.sqrt(),
            lo: (dof * s2 / chi2_quantile(0.975, dof)).sqrt(),
            hi: (dof * s2 / chi2_quantile(0.025, dof)).sqrt(),
        }
    }
}

/// Which noise structure the data showed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Structure {
    /// Reading noise: the readings scatter between repeats while the arm stays.
    Reading,
    /// Repeatable resolver error: an offset per configuration, readings repeat.
    Repeatable,
    /// Both at once.
    Both,
    /// Neither is significant: instrument (and torque) noise only.
    InstrumentOnly,
    /// No repeats: the structure cannot be measured; the prior was assumed.
    Assumed,
}

impl Structure {
    /// Short description.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Reading => "reading noise (readings scatter between repeats, the arm stays)",
            Self::Repeatable => "repeatable resolver error (an offset per configuration)",
            Self::Both => "reading noise and repeatable resolver error",
            Self::InstrumentOnly => "instrument noise only (no resolver error detected)",
            Self::Assumed => "assumed (no repeats to measure it)",
        }
    }

    /// Whether configurations share a resolver offset (GLS weighting pays off).
    pub fn shares_offsets(self) -> bool {
        matches!(self, Self::Repeatable | Self::Both)
    }
}

/// The estimated noise of a dataset.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseModel {
    /// The structure the tests chose.
    pub structure: Structure,
    /// Reading noise per joint (1σ), rad.
    pub reading_rad: [Interval; 6],
    /// Share of each joint's reading scatter that is noise (the rest is real motion), 0…1.
    pub reading_share: [f64; 6],
    /// Scatter of the readings within repeat cells per joint (1σ), rad.
    pub reading_scatter_rad: [f64; 6],
    /// Repeatable resolver error per joint (1σ), rad.
    pub repeatable_rad: Interval,
    /// Instrument position noise per instrument axis x, y, z (1σ), m.
    pub instrument_position_m: [Interval; 3],
    /// Instrument orientation noise per instrument axis (1σ), rad.
    pub instrument_orientation_rad: [Interval; 3],
    /// Torque noise per joint pooled over the data (1σ), N·m.
    pub torque_nm: [Interval; 6],
    /// Absolute torque noise per joint (1σ), N·m (the covariance uses `a² + r²τ²`).
    pub torque_abs_nm: [f64; 6],
    /// Relative torque noise per joint (1σ), fraction of the torque.
    pub torque_rel: [f64; 6],
    /// Degrees of freedom of the repeats (0: no repeats).
    pub within_dof: usize,
    /// Degrees of freedom of the configuration means (net of fitted parameters).
    pub between_dof: f64,
    /// P-value of "no reading noise" (1 when it could not be tested).
    pub reading_p: f64,
    /// P-value of "no repeatable error beyond the within-cell noise" (Q(0) test).
    pub repeatable_p: f64,
    /// What was assumed because the data could not say, if anything.
    pub assumption: Option<String>,
    /// Rotation from the instrument frame to the robot base frame.
    #[serde(skip)]
    pub base_from_instrument: Matrix3<f64>,
}

/// Why the noise could not be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NoiseError {
    /// No rows.
    #[error("no rows to estimate noise from")]
    Empty,
    /// A number is not finite.
    #[error("row {row}: {what} is not finite")]
    NotFinite {
        /// Row index.
        row: usize,
        /// Which quantity.
        what: &'static str,
    },
    /// The repeats do not scatter at all.
    #[error(
        "the repeat measurements show no scatter at all (instrument noise 0): repeats must be \
         separate measurements"
    )]
    NoScatter,
    /// The prior is not usable.
    #[error("invalid prior: {0}")]
    Prior(String),
}

fn rot6(r: &Matrix3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(r);
    m
}

fn check(samples: &[Sample], prior: &Prior) -> Result<(), NoiseError> {
    if samples.is_empty() {
        return Err(NoiseError::Empty);
    }
    if !(prior.position_m.is_finite() && prior.position_m > 0.0) {
        return Err(NoiseError::Prior(format!(
            "instrument noise must be a finite length > 0 m, got {}",
            prior.position_m
        )));
    }
    if !(prior.resolver_rad.is_finite() && prior.resolver_rad >= 0.0) {
        return Err(NoiseError::Prior(format!(
            "resolver σ must be a finite angle ≥ 0 rad, got {}",
            prior.resolver_rad
        )));
    }
    for (row, s) in samples.iter().enumerate() {
        let bad = |what| Err(NoiseError::NotFinite { row, what });
        if s.q.iter().any(|v| !v.is_finite()) {
            return bad("q");
        }
        if s.tau.iter().any(|v| !v.is_finite()) {
            return bad("tau");
        }
        if s.residual.iter().any(|v| !v.is_finite()) {
            return bad("residual");
        }
        if s.jq.iter().chain(s.jt.iter()).any(|v| !v.is_finite()) {
            return bad("sensitivity");
        }
    }
    Ok(())
}

/// The repeat cells with at least two rows.
fn cells(samples: &[Sample]) -> Vec<Vec<usize>> {
    let mut map: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, s) in samples.iter().enumerate() {
        map.entry(s.cell).or_default().push(i);
    }
    map.into_values().filter(|c| c.len() >= 2).collect()
}

fn mean_of<const N: usize>(rows: &[usize], f: impl Fn(usize) -> [f64; N]) -> [f64; N] {
    let mut m = [0.0; N];
    for &i in rows {
        let v = f(i);
        for k in 0..N {
            m[k] += v[k];
        }
    }
    m.map(|x| x / rows.len() as f64)
}

/// Estimates the noise model of `samples` (training rows only). `base_from_instrument`
/// rotates the instrument frame into the robot base frame; `between_dof` is the number of
/// configuration-mean residual components net of the parameters fitted to them (the caller
/// knows its model); `prior` stands in where the data cannot say.
pub fn estimate(
    samples: &[Sample],
    base_from_instrument: &Matrix3<f64>,
    between_dof: f64,
    prior: &Prior,
) -> Result<NoiseModel, NoiseError> {
    check(samples, prior)?;
    let mut model = within(samples, base_from_instrument, prior)?;
    let (rep, p) = repeatable(samples, &model, between_dof);
    model.repeatable_rad = rep;
    model.repeatable_p = p;
    model.between_dof = between_dof;
    // A repeatable error counts when it is significant *and* material: at least
    // `MATERIAL` of the larger of the reading noise and the prior resolver σ. A fit that is
    // not exactly the generalised least-squares optimum (a prior on the stiffness, the
    // paper's inner level) leaves a small between-configuration excess that the Q test,
    // with its hundreds of degrees of freedom, would otherwise call an offset.
    let reading_rms = (model
        .reading_rad
        .iter()
        .map(|i| i.value * i.value)
        .sum::<f64>()
        / 6.0)
        .sqrt();
    let material = rep.value >= MATERIAL * reading_rms.max(prior.resolver_rad);
    model.structure = if model.within_dof < MIN_WITHIN_DOF {
        Structure::Assumed
    } else {
        match (model.reading_p < ALPHA, p < ALPHA && material) {
            (true, true) => Structure::Both,
            (true, false) => Structure::Reading,
            (false, true) => Structure::Repeatable,
            (false, false) => Structure::InstrumentOnly,
        }
    };
    Ok(model)
}

/// The within-cell components (reading, instrument, torque); repeatable error left at 0.
pub fn within(
    samples: &[Sample],
    base_from_instrument: &Matrix3<f64>,
    prior: &Prior,
) -> Result<NoiseModel, NoiseError> {
    check(samples, prior)?;
    let rt = rot6(&base_from_instrument.transpose());
    let cells = cells(samples);
    let dof: usize = cells.iter().map(|c| c.len() - 1).sum();
    if dof < MIN_WITHIN_DOF {
        return Ok(assumed(base_from_instrument, prior, dof));
    }
    // Deviations from the cell means.
    let mut dq: Vec<[f64; 6]> = Vec::new();
    let mut y: Vec<Vector6<f64>> = Vec::new();
    let mut x: Vec<Matrix6<f64>> = Vec::new();
    let (mut ssq, mut sst) = ([0.0; 6], [0.0; 6]);
    // Torque scatter against the cell's mean torque: rows (1, τ̄²) → E[n/(n−1)·Δτ²].
    let mut teq: [Vec<(f64, f64)>; 6] = Default::default();
    for c in &cells {
        let n = c.len() as f64;
        let qm = mean_of(c, |i| samples[i].q);
        let tm = mean_of(c, |i| samples[i].tau);
        let rm = mean_of(c, |i| {
            let mut a = [0.0; 6];
            a.copy_from_slice(samples[i].residual.as_slice());
            a
        });
        for &i in c {
            let s = &samples[i];
            let d: [f64; 6] = std::array::from_fn(|j| s.q[j] - qm[j]);
            let dt = Vector6::from_fn(|j, _| s.tau[j] - tm[j]);
            let dr = s.residual - Vector6::from_column_slice(&rm);
            // Put the predicted effect of the torque scatter back: the true torque is
            // constant within a cell, so the scatter is noise.
            y.push(rt * (dr + s.jt * dt));
            let mut xm = rt * s.jq;
            for j in 0..6 {
                for r in 0..6 {
                    xm[(r, j)] *= d[j];
                }
                ssq[j] += d[j] * d[j];
                sst[j] += dt[j] * dt[j];
                teq[j].push((tm[j] * tm[j], dt[j] * dt[j] * n / (n - 1.0)));
            }
            dq.push(d);
            x.push(xm);
        }
    }
    let dof_f = dof as f64;
    let scatter: [f64; 6] = std::array::from_fn(|j| (ssq[j] / dof_f).sqrt());
    // Joints whose readings do not scatter carry no reading-noise information.
    let active: Vec<usize> = (0..6).filter(|&j| scatter[j] > 1e-10).collect();
    let k = active.len();
    let mut var = [0.0; 6];
    for v in &y {
        for a in 0..6 {
            var[a] += v[a] * v[a];
        }
    }
    for v in &mut var {
        *v = (*v / dof_f).max(1e-300);
    }
    let mut b = DVector::zeros(k);
    let mut info = DMatrix::zeros(k, k);
    for _ in 0..4 {
        let mut xtx = DMatrix::<f64>::zeros(k, k);
        let mut xty = DVector::<f64>::zeros(k);
        for (xi, yi) in x.iter().zip(&y) {
            for a in 0..6 {
                let w = 1.0 / var[a];
                for (ci, &j) in active.iter().enumerate() {
                    xty[ci] += w * xi[(a, j)] * yi[a];
                    for (cj, &l) in active.iter().enumerate() {
                        xtx[(ci, cj)] += w * xi[(a, j)] * xi[(a, l)];
                    }
                }
            }
        }
        b = if k > 0 {
            xtx.clone()
                .cholesky()
                .map(|ch| ch.solve(&xty))
                .unwrap_or_else(|| DVector::zeros(k))
        } else {
            b
        };
        info = xtx;
        let mut ss = [0.0; 6];
        for (xi, yi) in x.iter().zip(&y) {
            for (a, s) in ss.iter_mut().enumerate() {
                let fit: f64 = active
                    .iter()
                    .enumerate()
                    .map(|(ci, &j)| xi[(a, j)] * b[ci])
                    .sum();
                *s += (yi[a] - fit).powi(2);
            }
        }
        let nu = (dof_f - k as f64 / 6.0).max(1.0);
        for a in 0..6 {
            var[a] = (ss[a] / nu).max(1e-300);
        }
    }
    if var.iter().all(|v| *v <= 1e-299) {
        return Err(NoiseError::NoScatter);
    }
    let nu = (dof_f - k as f64 / 6.0).max(1.0);
    let cov_b = if k > 0 {
        info.clone()
            .pseudo_inverse(1e-14)
            .unwrap_or(DMatrix::zeros(k, k))
    } else {
        DMatrix::zeros(0, 0)
    };
    // The regression's coefficient is −ρ: the residual follows the reading scatter.
    let mut share = [0.0; 6];
    let mut reading = [Interval::fixed(0.0); 6];
    for (ci, &j) in active.iter().enumerate() {
        let rho = -b[ci];
        let se = cov_b[(ci, ci)].max(0.0).sqrt();
        share[j] = rho.clamp(0.0, 1.0);
        let s2 = Interval::from_variance(scatter[j] * scatter[j], dof_f);
        reading[j] = Interval {
            value: (share[j] * scatter[j] * scatter[j]).sqrt(),
            lo: ((rho - 1.96 * se).clamp(0.0, 1.0)).sqrt() * s2.lo,
            hi: ((rho + 1.96 * se).clamp(0.0, 1.0)).sqrt() * s2.hi,
        };
    }
    let reading_p = if k > 0 {
        let chi2 = (b.transpose() * &info * &b)[(0, 0)];
        chi2_sf(chi2, k as f64)
    } else {
        1.0
    };
    let mut torque_abs = [0.0; 6];
    let mut torque_rel = [0.0; 6];
    for j in 0..6 {
        let (a2, r2) = torque_levels(&teq[j]);
        torque_abs[j] = a2.sqrt();
        torque_rel[j] = r2.sqrt();
    }
    Ok(NoiseModel {
        structure: Structure::Assumed,
        reading_rad: reading,
        reading_share: share,
        reading_scatter_rad: scatter,
        repeatable_rad: Interval::fixed(0.0),
        instrument_position_m: std::array::from_fn(|a| Interval::from_variance(var[a], nu)),
        instrument_orientation_rad: std::array::from_fn(|a| {
            Interval::from_variance(var[3 + a], nu)
        }),
        torque_nm: std::array::from_fn(|j| Interval::from_variance(sst[j] / dof_f, dof_f)),
        torque_abs_nm: torque_abs,
        torque_rel,
        within_dof: dof,
        between_dof: 0.0,
        reading_p,
        repeatable_p: 1.0,
        assumption: None,
        base_from_instrument: *base_from_instrument,
    })
}

/// `(a², r²)` of `E[Δτ²·n/(n−1)] = a² + r²·τ̄²` by least squares, both ≥ 0.
fn torque_levels(eqs: &[(f64, f64)]) -> (f64, f64) {
    let n = eqs.len() as f64;
    if eqs.is_empty() {
        return (0.0, 0.0);
    }
    let mean_y = eqs.iter().map(|e| e.1).sum::<f64>() / n;
    let (sx, sxx, sxy) = eqs.iter().fold((0.0, 0.0, 0.0), |(a, b, c), e| {
        (a + e.0, b + e.0 * e.0, c + e.0 * e.1)
    });
    let det = n * sxx - sx * sx;
    if det <= 1e-12 * n * sxx.max(1e-300) {
        return (mean_y.max(0.0), 0.0);
    }
    let r2 = (n * sxy - sx * eqs.iter().map(|e| e.1).sum::<f64>()) / det;
    let a2 = mean_y - r2 * sx / n;
    match (a2 >= 0.0, r2 >= 0.0) {
        (true, true) => (a2, r2),
        (false, _) => (0.0, (sxy / sxx.max(1e-300)).max(0.0)),
        (true, false) => (mean_y.max(0.0), 0.0),
    }
}

/// The model without repeats: the prior, resolver error independent per row.
fn assumed(base_from_instrument: &Matrix3<f64>, prior: &Prior, dof: usize) -> NoiseModel {
    let axis = prior.position_m / 3f64.sqrt();
    NoiseModel {
        structure: Structure::Assumed,
        reading_rad: [Interval::fixed(prior.resolver_rad); 6],
        reading_share: [1.0; 6],
        reading_scatter_rad: [0.0; 6],
        repeatable_rad: Interval::fixed(0.0),
        instrument_position_m: [Interval::fixed(axis); 3],
        // A target frame from tooling balls ~0.1 m apart.
        instrument_orientation_rad: [Interval::fixed(axis / 0.1); 3],
        torque_nm: [Interval::fixed(0.0); 6],
        torque_abs_nm: [0.0; 6],
        torque_rel: [0.0; 6],
        within_dof: dof,
        between_dof: 0.0,
        reading_p: 1.0,
        repeatable_p: 1.0,
        assumption: Some(format!(
            "{dof} repeat degrees of freedom (< {MIN_WITHIN_DOF}): the noise cannot be measured \
             from these data; assumed instrument noise {:.1} µm (3-D rms) and resolver error \
             {:.2} arcmin per joint, independent per row (per-row weights lose least when \
             the structure is unknown); measure repeats to know",
            prior.position_m * 1e6,
            prior.resolver_rad / crate::accuracy::ARCMIN
        )),
        base_from_instrument: *base_from_instrument,
    }
}

impl NoiseModel {
    /// Covariance of one row's residual (base frame) from the row-independent components:
    /// instrument, reading noise through `jq`, torque noise through `jt` at torques `tau`.
    pub fn row_covariance(
        &self,
        jq: &Matrix6<f64>,
        jt: &Matrix6<f64>,
        tau: &[f64; 6],
    ) -> Matrix6<f64> {
        let r = rot6(&self.base_from_instrument);
        let inst = Matrix6::from_diagonal(&Vector6::from_fn(|a, _| {
            if a < 3 {
                self.instrument_position_m[a].value.powi(2)
            } else {
                self.instrument_orientation_rad[a - 3].value.powi(2)
            }
        }));
        let mut m = r * inst * r.transpose();
        for j in 0..6 {
            let c = jq.column(j);
            m += c * c.transpose() * self.reading_rad[j].value.powi(2);
            let g = jt.column(j);
            let v = self.torque_abs_nm[j].powi(2) + (self.torque_rel[j] * tau[j]).powi(2);
            m += g * g.transpose() * v;
        }
        // Symmetric and positive definite whatever the components.
        m = 0.5 * (m + m.transpose());
        for a in 0..6 {
            m[(a, a)] = m[(a, a)].max(1e-24);
        }
        m
    }

    /// Covariance of a configuration's shared offset at sensitivity `jq`, with the
    /// repeatable error `sigma` (rad) per joint.
    pub fn shared_covariance(jq: &Matrix6<f64>, sigma: f64) -> Matrix6<f64> {
        jq * jq.transpose() * (sigma * sigma)
    }

    /// One line for people.
    pub fn summary(&self) -> String {
        let um = |i: &Interval| i.value * 1e6;
        let am = |v: f64| v / crate::accuracy::ARCMIN;
        let reading: Vec<String> = self
            .reading_rad
            .iter()
            .map(|i| format!("{:.2}", am(i.value)))
            .collect();
        format!(
            "noise ({}; {} repeat dof): reading [{}] arcmin, repeatable {:.2} [{:.2}, {:.2}] \
             arcmin (p {:.1e}), instrument {:.1}/{:.1}/{:.1} µm, {:.0}/{:.0}/{:.0} µrad, \
             torque [{}] N·m",
            self.structure.describe(),
            self.within_dof,
            reading.join(", "),
            am(self.repeatable_rad.value),
            am(self.repeatable_rad.lo),
            am(self.repeatable_rad.hi),
            self.repeatable_p,
            um(&self.instrument_position_m[0]),
            um(&self.instrument_position_m[1]),
            um(&self.instrument_position_m[2]),
            um(&self.instrument_orientation_rad[0]),
            um(&self.instrument_orientation_rad[1]),
            um(&self.instrument_orientation_rad[2]),
            self.torque_nm
                .iter()
                .map(|i| format!("{:.2}", i.value))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// The repeatable error: the Q-profile over the configuration means given the row noise of
/// `model`. Returns the estimate with its interval, and the p-value of `σ = 0`.
pub fn repeatable(samples: &[Sample], model: &NoiseModel, dof: f64) -> (Interval, f64) {
    let mut configs: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, s) in samples.iter().enumerate() {
        configs.entry(s.config).or_default().push(i);
    }
    // Per configuration: precision-weighted mean residual, its covariance from row noise,
    // and the mean sensitivity.
    let means: Vec<(Vector6<f64>, Matrix6<f64>, Matrix6<f64>)> = configs
        .values()
        .filter_map(|rows| {
            let mut p = Matrix6::zeros();
            let mut pr = Vector6::zeros();
            let mut jq = Matrix6::zeros();
            for &i in rows {
                let s = &samples[i];
                let d = model.row_covariance(&s.jq, &s.jt, &s.tau);
                let di = d.try_inverse()?;
                p += di;
                pr += di * s.residual;
                jq += s.jq;
            }
            let pinv = p.try_inverse()?;
            Some((pinv * pr, pinv, jq / rows.len() as f64))
        })
        .collect();
    if dof < 1.0 || means.is_empty() {
        return (Interval::fixed(0.0), 1.0);
    }
    let q = |s2: f64| -> f64 {
        means
            .iter()
            .map(|(m, pinv, jq)| {
                let v = pinv + jq * jq.transpose() * s2;
                v.try_inverse()
                    .map_or(0.0, |vi| (m.transpose() * vi * m)[(0, 0)])
            })
            .sum()
    };
    let q0 = q(0.0);
    let p = chi2_sf(q0, dof);
    // Q is decreasing in σ²: solve Q(σ²) = target by bisection on a log scale.
    let solve = |target: f64| -> f64 {
        if q0 <= target {
            return 0.0;
        }
        let mut hi = 1e-12;
        while q(hi) > target && hi < 1.0 {
            hi *= 4.0;
        }
        let mut lo = 0.0;
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if q(mid) > target {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-6 * hi {
                break;
            }
        }
        0.5 * (lo + hi)
    };
    let est = solve(dof);
    let upper = solve(chi2_quantile(0.025, dof));
    let lower = solve(chi2_quantile(0.975, dof));
    (
        Interval {
            value: est.sqrt(),
            lo: lower.sqrt(),
            hi: upper.sqrt(),
        },
        p,
    )
}

/// `m^power` of a symmetric positive semi-definite 6×6 matrix (eigenvalues floored at
/// 1e-300): the inverse, square root and inverse square root that whitening needs.
pub fn sym_pow(m: &Matrix6<f64>, power: f64) -> Matrix6<f64> {
    let e = nalgebra::SymmetricEigen::new(*m);
    let d = e.eigenvalues.map(|v| v.max(1e-300).powf(power));
    e.eigenvectors * Matrix6::from_diagonal(&d) * e.eigenvectors.transpose()
}

#[cfg(test)]
mod tests;
