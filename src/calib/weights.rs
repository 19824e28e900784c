//! How calibration weighs its rows: the GLS transform for configurations that share a
//! resolver offset, built either from the noise model the data show ([`crate::noise`]:
//! reading noise, repeatable error, instrument and torque noise, estimated from the
//! repeats and the configuration means) or, for `--weighting gls`, from the assumption
//! that the resolver error repeats at a configuration with the sidecar's σ.

use nalgebra::{DMatrix, Matrix6, Vector6};

use super::dataset::Dataset;
use super::prepare::Prepared;
use crate::model::{Model, pose_error};
use crate::noise::{NoiseModel, Prior, Sample, sym_pow};

/// The GLS transform of rows that share a configuration's random offset: per group, rows
/// with independent noise `D_k` (6×6, paper units) and a shared offset `S`:
/// `r'_k = D_k^{-1/2}·(r_k − (I − Λ)·m̂)` with `m̂ = P⁻¹·Σ D_k⁻¹ r_k` the precision-weighted
/// mean, `P = Σ D_k⁻¹` and `Λ = P^{-1/2}·(P⁻¹ + S)^{-1/2}`. Its sum of squares is the exact
/// GLS cost `Σ (r_k − m̂)ᵀD_k⁻¹(r_k − m̂) + m̂ᵀ(P⁻¹ + S)⁻¹m̂`: the cross term vanishes
/// because the weighted deviations sum to zero, and `ΛᵀPΛ = (P⁻¹ + S)⁻¹`.
#[derive(Debug, Clone)]
pub(crate) struct Whitening {
    /// Row indices of each configuration.
    pub groups: Vec<Vec<usize>>,
    /// Per row: `D_k⁻¹` and `D_k^{-1/2}`.
    d_inv: Vec<Matrix6<f64>>,
    d_inv_sqrt: Vec<Matrix6<f64>>,
    /// Per group: `P⁻¹` and `I − Λ`.
    p_inv: Vec<Matrix6<f64>>,
    shrink: Vec<Matrix6<f64>>,
    /// Typical position noise (paper units): the unit of whitened residuals.
    unit: f64,
}

impl Whitening {
    /// The transform for row covariances `d` and group offsets `s` (paper units).
    pub fn new(groups: Vec<Vec<usize>>, d: &[Matrix6<f64>], s: &[Matrix6<f64>]) -> Self {
        let d_inv: Vec<Matrix6<f64>> = d.iter().map(|m| sym_pow(m, -1.0)).collect();
        let d_inv_sqrt = d.iter().map(|m| sym_pow(m, -0.5)).collect();
        let (p_inv, shrink) = groups
            .iter()
            .zip(s)
            .map(|(g, s)| {
                let p = g.iter().map(|&k| d_inv[k]).sum::<Matrix6<f64>>();
                let p_inv = sym_pow(&p, -1.0);
                let lambda = sym_pow(&p, -0.5) * sym_pow(&(p_inv + s), -0.5);
                (p_inv, Matrix6::identity() - lambda)
            })
            .unzip();
        let n = d.len().max(1) as f64;
        let unit = (d.iter().map(|m| m[(0, 0)]).sum::<f64>() / n).sqrt();
        Self {
            groups,
            d_inv,
            d_inv_sqrt,
            p_inv,
            shrink,
            unit,
        }
    }

    /// Applies the transform to the 6-per-row block of `m` (rows 0…6·n), in place; `cols`
    /// columns (1 for a residual vector).
    pub fn apply(&self, m: &mut DMatrix<f64>) {
        for (gi, g) in self.groups.iter().enumerate() {
            for col in 0..m.ncols() {
                let r = |k: usize| Vector6::from_fn(|c, _| m[(6 * k + c, col)]);
                let mean = self.p_inv[gi]
                    * g.iter()
                        .map(|&k| self.d_inv[k] * r(k))
                        .sum::<Vector6<f64>>();
                let shift = self.shrink[gi] * mean;
                let out: Vec<Vector6<f64>> = g
                    .iter()
                    .map(|&k| self.d_inv_sqrt[k] * (r(k) - shift))
                    .collect();
                for (&k, v) in g.iter().zip(&out) {
                    for c in 0..6 {
                        m[(6 * k + c, col)] = v[c];
                    }
                }
            }
        }
    }

    /// The position noise of a typical row (paper units): the unit of whitened residuals.
    pub fn unit(&self) -> f64 {
        self.unit
    }
}

/// Row indices grouped by configuration id (all loads and repeats), in first-appearance
/// order.
pub(crate) fn config_groups(data: &Dataset) -> Vec<Vec<usize>> {
    let mut ids: Vec<&str> = Vec::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (k, r) in data.rows.iter().enumerate() {
        match ids.iter().position(|i| *i == r.config_id) {
            Some(g) => groups[g].push(k),
            None => {
                ids.push(&r.config_id);
                groups.push(vec![k]);
            }
        }
    }
    groups
}

/// The GLS weights: σ_e from the repeat scatter of the data (pooled within configuration and
/// load, per residual component; the sidecar's instrument noise without repeats), σ_u from
/// the resolver uncertainty (sidecar or 0.64 arcmin) through the model's Jacobian, averaged
/// over the configurations.
pub(crate) fn whitening(data: &Dataset, model: &Model, rows: &[Prepared], r_max: f64) -> Whitening {
    let res_arcmin = data
        .meta
        .as_ref()
        .and_then(|m| m.noise)
        .map_or(0.64, |n| n.resolver_arcmin);
    let pos_noise = data
        .meta
        .as_ref()
        .and_then(|m| m.noise)
        .map_or(12.1e-6, |n| n.position_m);
    // σ_e from repeats
    let (mut ss, mut dof) = ([0.0; 6], 0usize);
    for g in data.groups() {
        if g.len() < 2 {
            continue;
        }
        let n = g.len() as f64;
        let mean_p = g
            .iter()
            .map(|&k| rows[k].meas.translation.vector)
            .sum::<nalgebra::Vector3<f64>>()
            / n;
        let r0 = rows[g[0]].meas.rotation;
        let devs: Vec<nalgebra::Vector3<f64>> = g
            .iter()
            .map(|&k| crate::model::rotation_log(&(rows[k].meas.rotation * r0.inverse())))
            .collect();
        let mean_r = devs.iter().sum::<nalgebra::Vector3<f64>>() / n;
        for (i, &k) in g.iter().enumerate() {
            let dp = (rows[k].meas.translation.vector - mean_p) / r_max;
            let dr = devs[i] - mean_r;
            for c in 0..3 {
                ss[c] += dp[c] * dp[c];
                ss[3 + c] += dr[c] * dr[c];
            }
        }
        dof += g.len() - 1;
    }
    let fallback = [
        pos_noise / 3f64.sqrt() / r_max,
        pos_noise / 3f64.sqrt() / r_max,
        pos_noise / 3f64.sqrt() / r_max,
        1e-4,
        1e-4,
        1e-4,
    ];
    // Torque noise moves the modelled deflection from row to row: its repeat scatter per
    // joint, through the (seed) stiffness and the Jacobian, adds to σ_e.
    let (mut tss, mut tdof) = ([0.0; 6], 0usize);
    for g in data.groups() {
        if g.len() < 2 {
            continue;
        }
        let n = g.len() as f64;
        for j in 0..6 {
            let mean = g.iter().map(|&k| rows[k].tau[j]).sum::<f64>() / n;
            tss[j] += g
                .iter()
                .map(|&k| (rows[k].tau[j] - mean).powi(2))
                .sum::<f64>();
        }
        tdof += g.len() - 1;
    }
    let sigma_defl: [f64; 6] = std::array::from_fn(|j| match model.stiffness(j) {
        Some(k) if tdof > 0 => (tss[j] / tdof as f64).sqrt() / k.klin,
        _ => 0.0,
    });
    // σ_u: resolver σ through the Jacobian; both averaged over the rows' configurations
    let sr = res_arcmin * crate::accuracy::ARCMIN;
    let (mut acc, mut tacc) = ([0.0; 6], [0.0; 6]);
    for r in rows {
        let j = model.jacobian(&model.link_angles(&r.q, &r.tau));
        for c in 0..6 {
            let scale = if c < 3 { 1.0 / r_max } else { 1.0 };
            acc[c] += (0..6)
                .map(|k| (j[(c, k)] * sr * scale).powi(2))
                .sum::<f64>();
            tacc[c] += (0..6)
                .map(|k| (j[(c, k)] * sigma_defl[k] * scale).powi(2))
                .sum::<f64>();
        }
    }
    let n = rows.len().max(1) as f64;
    let sigma_e: [f64; 6] = std::array::from_fn(|c| {
        let pose = if dof > 0 {
            (ss[c] / dof as f64).sqrt().max(fallback[c] * 1e-3)
        } else {
            fallback[c]
        };
        (pose * pose + tacc[c] / n).sqrt()
    });
    let sigma_u: [f64; 6] = std::array::from_fn(|c| (acc[c] / n).sqrt().max(1e-12));
    let groups = config_groups(data);
    let d = Matrix6::from_diagonal(&Vector6::from_fn(|c, _| sigma_e[c] * sigma_e[c]));
    let s = Matrix6::from_diagonal(&Vector6::from_fn(|c, _| sigma_u[c] * sigma_u[c]));
    let n = groups.len();
    Whitening::new(groups, &vec![d; rows.len()], &vec![s; n])
}

/// The noise samples of `rows` at `model` (its base frame placing the measurements):
/// configurations by id, repeat cells by (configuration, load, direction, temperature).
pub(crate) fn samples(data: &Dataset, model: &Model, rows: &[Prepared]) -> Vec<Sample> {
    let mut configs: Vec<&str> = Vec::new();
    let mut cells: Vec<(usize, u64, [i8; 6], u64)> = Vec::new();
    let base = *model.base_from_instrument();
    data.rows
        .iter()
        .zip(rows)
        .map(|(d, r)| {
            let config = configs
                .iter()
                .position(|c| *c == d.config_id)
                .unwrap_or_else(|| {
                    configs.push(&d.config_id);
                    configs.len() - 1
                });
            let key = (
                config,
                d.load_n.to_bits(),
                d.direction,
                d.temperature_c.map_or(u64::MAX, f64::to_bits),
            );
            let cell = cells.iter().position(|c| *c == key).unwrap_or_else(|| {
                cells.push(key);
                cells.len() - 1
            });
            let q = model.link_angles(&r.q, &r.tau);
            let jq = model.jacobian(&q);
            let mut jt = jq;
            for j in 0..6 {
                // ∂pred/∂τ_j: the link lags the motor by δ(τ), so the prediction moves by
                // −J·dδ/dτ.
                let dd = -model
                    .stiffness(j)
                    .map_or(0.0, |s| 1.0 / s.tangent(s.deflection(r.tau[j])));
                for k in 0..6 {
                    jt[(k, j)] *= dd;
                }
            }
            Sample {
                config,
                cell,
                q: r.q,
                tau: r.tau,
                residual: pose_error(&(base * r.meas), &model.fk_loaded(&q, r.load_n)),
                jq,
                jt,
            }
        })
        .collect()
}

/// The prior of `data`: its sidecar's noise, else the paper's CMM and the PA10's resolver.
pub(crate) fn prior(data: &Dataset) -> Prior {
    let n = data.meta.as_ref().and_then(|m| m.noise);
    Prior {
        position_m: n.map_or(12.1e-6, |n| n.position_m),
        resolver_rad: n.map_or(0.64, |n| n.resolver_arcmin) * crate::accuracy::ARCMIN,
    }
}

/// The GLS transform from a noise model: per row its full covariance (instrument, reading
/// noise and torque noise through the model), per configuration the repeatable error
/// `sigma_rep` (rad) through its mean Jacobian; paper units. With `sigma_rep = 0` this is
/// per-row weighting.
pub(crate) fn from_noise(
    data: &Dataset,
    noise: &NoiseModel,
    samples: &[Sample],
    sigma_rep: f64,
    r_max: f64,
) -> Whitening {
    let k = Matrix6::from_diagonal(&Vector6::from_fn(
        |c, _| {
            if c < 3 { 1.0 / r_max } else { 1.0 }
        },
    ));
    let d: Vec<Matrix6<f64>> = samples
        .iter()
        .map(|s| k * noise.row_covariance(&s.jq, &s.jt, &s.tau) * k)
        .collect();
    let groups = config_groups(data);
    let shared: Vec<Matrix6<f64>> = groups
        .iter()
        .map(|g| {
            let jq = g.iter().map(|&i| samples[i].jq).sum::<Matrix6<f64>>() / g.len() as f64;
            k * NoiseModel::shared_covariance(&jq, sigma_rep) * k
        })
        .collect();
    Whitening::new(groups, &d, &shared)
}
