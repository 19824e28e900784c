//! What a calibration starts from: its options and errors, the dataset rows prepared for
//! fitting (torques from the effort columns, the inner-level flag), the inner-level
//! configurations, the base-frame seed and the starting model. Shared by the fit
//! ([`super::fit`]), its weights and the evaluation; it imports none of them.

use super::base::{self, BaseParams};
use super::dataset::{Dataset, Effort};
use crate::model::params::PAPER_STIFFNESS;
use crate::model::{Frame, Model, ModelError, Stiffness};

/// How to calibrate.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibOptions {
    /// The paper's regularisation weight ε on `Σ(δ/tol)²` (the paper used 1.6e-4).
    pub epsilon: f64,
    /// Fit linear stiffness only (Kcub = 0), the paper's comparison model.
    pub linear_only: bool,
    /// Number of starts (the first is the nominal geometry with the seed stiffness).
    pub starts: usize,
    /// Seed of the random starts.
    pub seed: u64,
    /// Position normalisation, m (the paper's `r_max` = 1 m).
    pub r_max: f64,
    /// A scaled direction whose standard error exceeds this (in tolerances, or log-units of
    /// stiffness) is regularised.
    pub weak_threshold: f64,
    /// Configurations for the inner level; the sidecar's, else every unloaded configuration
    /// with [`Weighting::Measured`] and 8 chosen automatically with the others.
    pub inner_configs: Option<Vec<String>>,
    /// Starting stiffness (Klin N·m/rad, Kcub N·m/rad³) of J2, J3, J5 when the model has
    /// none; also the centre of the stiffness prior.
    pub stiffness_seed: [(f64, f64); 3],
    /// Motor current → joint torque constants, N·m/A, for datasets with currents.
    pub torque_constants: Option<[f64; 6]>,
    /// Residual noise level per component (paper units); estimated from the sidecar's
    /// noise when `None`. Used by [`Weighting::Paper`].
    pub noise_level: Option<f64>,
    /// How rows are weighted.
    pub weighting: Weighting,
}

/// How the data residuals are weighted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Weighting {
    /// From the noise the data show ([`crate::noise`]): per-row weights from the measured
    /// instrument, reading and torque noise, then — if the configuration means show a
    /// repeatable resolver error — a second fit with the GLS transform at its estimate.
    Measured,
    /// The paper's cost exactly: every row's position error / `r_max` and orientation error
    /// (rad), all with weight one.
    Paper,
    /// Generalised least squares for the error structure of a real campaign: resolver errors
    /// repeat at a configuration (same angles for every repeat and load) while instrument
    /// noise does not. Rows of a configuration share a random offset (σ_u: the resolver
    /// floor) on top of independent noise (σ_e: the repeat scatter), so the fit trusts
    /// within-configuration contrasts — the load steps that reveal stiffness — and
    /// discounts configuration means. Residuals are whitened (unit variance).
    Gls,
}

impl Default for CalibOptions {
    fn default() -> Self {
        Self {
            epsilon: 0.0,
            linear_only: false,
            starts: 4,
            seed: 1,
            r_max: 1.0,
            weak_threshold: 0.5,
            inner_configs: None,
            stiffness_seed: PAPER_STIFFNESS,
            torque_constants: None,
            noise_level: None,
            weighting: Weighting::Measured,
        }
    }
}

/// Why a calibration could not run. Nothing is written when one is returned.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibError {
    /// An option is out of range.
    #[error("invalid option {key}: {reason}")]
    Option {
        /// The option.
        key: &'static str,
        /// Why.
        reason: String,
    },
    /// The data cannot support the fit.
    #[error("dataset: {0}")]
    Data(String),
    /// A model could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The optimiser failed on every start.
    #[error("the optimisation failed on every start: {0}")]
    Failed(String),
    /// The data's noise could not be estimated.
    #[error("dataset: {0}")]
    Noise(#[from] crate::noise::NoiseError),
}

/// A dataset row prepared for fitting.
#[derive(Debug, Clone)]
pub(crate) struct Prepared {
    pub q: [f64; 6],
    pub tau: [f64; 6],
    pub meas: Frame,
    pub load_n: f64,
    pub inner: bool,
}

/// Prepares rows: torques from the effort columns, the inner flag.
pub(crate) fn prepare(
    data: &Dataset,
    inner_ids: &[String],
    kt: Option<[f64; 6]>,
) -> Result<Vec<Prepared>, CalibError> {
    data.rows
        .iter()
        .map(|r| {
            let tau = match r.effort {
                Effort::Torque(t) => t,
                Effort::Current(i) => {
                    let k = kt.ok_or_else(|| {
                        CalibError::Data(format!(
                            "line {}: motor currents need torque constants (N·m/A); give them or record torques",
                            r.line
                        ))
                    })?;
                    std::array::from_fn(|j| i[j] * k[j])
                }
            };
            Ok(Prepared { q: r.q, tau, meas: r.pose, load_n: r.load_n, inner: r.load_n == 0.0 && inner_ids.contains(&r.config_id) })
        })
        .collect()
}

/// Eight inner-level configurations: the sidecar's, or farthest-point picks among the
/// unloaded configurations (spread out, so the base frame is well determined).
pub(crate) fn choose_inner(data: &Dataset, opts: &CalibOptions) -> Result<Vec<String>, CalibError> {
    if let Some(ids) = opts
        .inner_configs
        .clone()
        .or_else(|| data.meta.as_ref().and_then(|m| m.inner_configs.clone()))
    {
        for id in &ids {
            if !data
                .rows
                .iter()
                .any(|r| &r.config_id == id && r.load_n == 0.0)
            {
                return Err(CalibError::Data(format!(
                    "inner-level configuration `{id}` has no unloaded row"
                )));
            }
        }
        return Ok(ids);
    }
    let mut ids: Vec<(String, nalgebra::Vector3<f64>)> = Vec::new();
    for r in data.rows.iter().filter(|r| r.load_n == 0.0) {
        if !ids.iter().any(|(i, _)| i == &r.config_id) {
            ids.push((r.config_id.clone(), r.pose.translation.vector));
        }
    }
    if ids.len() < 3 {
        return Err(CalibError::Data(format!(
            "the inner level needs ≥ 3 unloaded configurations, found {}",
            ids.len()
        )));
    }
    // With the measured weighting, rows of a configuration may share a resolver offset that
    // GLS discounts: a base frame placed on eight configurations would carry their offsets
    // into every prediction, so the inner level uses every unloaded configuration.
    if opts.weighting == Weighting::Measured {
        return Ok(ids.into_iter().map(|(i, _)| i).collect());
    }
    let mut chosen = vec![0usize];
    while chosen.len() < 8.min(ids.len()) {
        let next = (0..ids.len())
            .filter(|i| !chosen.contains(i))
            .max_by(|&a, &b| {
                let d = |i: usize| {
                    chosen
                        .iter()
                        .map(|&c| (ids[i].1 - ids[c].1).norm())
                        .fold(f64::INFINITY, f64::min)
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap_or(0);
        chosen.push(next);
    }
    Ok(chosen.into_iter().map(|i| ids[i].0.clone()).collect())
}

/// The base-frame seed: straight lines when given, else a point fit on the inner rows.
pub(crate) fn seed_base(
    model: &Model,
    rows: &[Prepared],
    lines: Option<&Dataset>,
) -> Result<BaseParams, CalibError> {
    let inner: Vec<&Prepared> = rows.iter().filter(|r| r.inner).collect();
    let robot: Vec<_> = inner
        .iter()
        .map(|r| {
            model
                .tool_at_rest(&r.q, &r.tau, r.load_n)
                .translation
                .vector
        })
        .collect();
    let inst: Vec<_> = inner.iter().map(|r| r.meas.translation.vector).collect();
    let frame = match lines {
        Some(l) => {
            let pick = |prefix: char| {
                let mut v: Vec<_> = l
                    .rows
                    .iter()
                    .filter(|r| r.config_id.starts_with(prefix))
                    .collect();
                v.sort_by_key(|r| {
                    r.config_id
                        .trim_start_matches(prefix)
                        .parse::<u32>()
                        .unwrap_or(u32::MAX)
                });
                v.iter()
                    .map(|r| r.pose.translation.vector)
                    .collect::<Vec<_>>()
            };
            let (x, y) = (pick('x'), pick('y'));
            if x.len() < 2 || y.len() < 2 {
                return Err(CalibError::Data(
                    "the lines file needs ≥ 2 rows along x (ids x0, x1, …) and ≥ 2 along y (y0, y1, …)".into(),
                ));
            }
            base::seed_from_lines(&x, &y, &robot, &inst)
        }
        None => base::seed_from_points(&robot, &inst),
    };
    let frame = frame.ok_or_else(|| {
        CalibError::Data("the base-frame seed is degenerate (points on a line?)".into())
    })?;
    Ok(base::psi_from_frame(&frame))
}

/// The model to start from: tool from the sidecar, seed stiffness where the model has none.
pub(crate) fn start_model(
    model: &Model,
    data: &Dataset,
    opts: &CalibOptions,
) -> Result<Model, CalibError> {
    let mut d = model.data().clone();
    if let Some(t) = data.meta.as_ref().and_then(|m| m.tool) {
        d.tool = t;
    }
    for (k, &j) in crate::model::STIFF_JOINTS.iter().enumerate() {
        let (kl, kc) = opts.stiffness_seed[k];
        let s = d.stiffness[j].unwrap_or(Stiffness { klin: kl, kcub: kc });
        d.stiffness[j] = Some(Stiffness {
            klin: s.klin,
            kcub: if opts.linear_only {
                0.0
            } else if s.kcub > 0.0 {
                s.kcub
            } else {
                kc
            },
        });
    }
    Ok(Model::new(d)?)
}

pub(crate) fn check(opts: &CalibOptions) -> Result<(), CalibError> {
    let bad = |key, reason: String| Err(CalibError::Option { key, reason });
    if !(opts.epsilon.is_finite() && opts.epsilon >= 0.0) {
        return bad(
            "epsilon",
            format!("must be finite and ≥ 0, got {}", opts.epsilon),
        );
    }
    if opts.starts == 0 || opts.starts > 1000 {
        return bad("starts", format!("must be 1…1000, got {}", opts.starts));
    }
    if !(opts.r_max.is_finite() && opts.r_max > 0.0) {
        return bad(
            "r_max",
            format!("must be a length > 0 m, got {}", opts.r_max),
        );
    }
    if !(opts.weak_threshold.is_finite() && opts.weak_threshold > 0.0) {
        return bad(
            "weak_threshold",
            format!("must be > 0, got {}", opts.weak_threshold),
        );
    }
    for (k, (kl, kc)) in opts.stiffness_seed.iter().enumerate() {
        if !(kl.is_finite() && *kl > 0.0 && kc.is_finite() && *kc > 0.0) {
            return bad(
                "stiffness_seed",
                format!("entry {k} needs Klin > 0 N·m/rad and Kcub > 0 N·m/rad³"),
            );
        }
    }
    Ok(())
}
