//! The two-level Levenberg–Marquardt identification (seed paper §II-C).
//!
//! **OuterProblem level**: the 30 parameters (or 27 with `linear_only`) in scaled form — geometric
//! departures divided by the paper's tolerances (a 0.25 mm, α 1e-3 rad, d 0.25 mm,
//! β 1e-3 rad, θ 5e-4 rad) and stiffness as `ln(K / K_seed)` — minimising the paper's cost:
//! position errors / `r_max` and orientation errors (rad) over every row, plus the optional
//! `ε·Σ(δ/tol)²` term. Solved with the `levenberg-marquardt` crate (MINPACK's algorithm).
//! **Inner level**: at every outer step the base frame Ψ is re-solved by Gauss–Newton on the
//! inner configurations; the outer Jacobian carries `∂Ψ*/∂X` by implicit differentiation.
//!
//! **Unidentifiable directions**: the SVD of the scaled outer Jacobian at the start shows
//! which parameter combinations the data cannot determine (standard error above
//! [`CalibOptions::weak_threshold`] in scaled units, from the residual noise level). Only
//! those get a prior pulling them to their nominal / seed value, with one tolerance (or a
//! factor e in stiffness) as its standard deviation; everything the data see stays
//! unbiased. The paper's global ε is still available.

use nalgebra::{DMatrix, DVector, Dyn, Owned, SMatrix};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use super::base::{self, BaseParams};
use super::dataset::Dataset;
pub use super::prepare::{CalibError, CalibOptions, Weighting};
use super::prepare::{Prepared, check, choose_inner, prepare, seed_base, start_model};
use super::weights::{self, Whitening, config_groups, whitening};
use crate::model::params::TOLERANCES;
use crate::model::params::{IDX_KCUB, IDX_KLIN, PARAM_COUNT};
use crate::model::{Frame, Model, ParamVector, param_names};

/// Levenberg–Marquardt patience (evaluations per parameter) of a refit that starts from a
/// solution on other weights.
const PATIENCE_REFIT: usize = 20;

/// A parameter combination the data cannot determine.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WeakDirection {
    /// Singular value of the scaled Jacobian.
    pub singular_value: f64,
    /// Its standard error without the prior, scaled units.
    pub std_error: f64,
    /// The parameters it involves most, with their loadings (|loading| ≥ 0.2).
    pub params: Vec<(String, f64)>,
}

/// What a calibration found.
#[derive(Debug, Clone)]
pub struct CalibResult {
    /// The calibrated model: departures, stiffness, base frame and tool filled in.
    pub model: Model,
    /// Final cost (sum of squared residuals, paper units, priors included).
    pub cost: f64,
    /// Data part of the cost.
    pub data_cost: f64,
    /// Per-parameter standard errors in physical units (`None`: fixed or not estimable).
    pub std_errors: [Option<f64>; PARAM_COUNT],
    /// Singular values of the scaled data Jacobian at the solution, descending.
    pub singular_values: Vec<f64>,
    /// Directions regularised because the data cannot see them.
    pub weak: Vec<WeakDirection>,
    /// Set when the fitted model leaves a repeatable error far above the resolver's
    /// specification (more than 100×, at least 10 arcmin) on a dataset whose sidecar declares
    /// the set-up: what the data show, and that `pa10 discover` names what is missing.
    /// (Without a sidecar the same misfit is refused as a set-up error.)
    pub misfit: Option<String>,
    /// Cost reached by each start, in start order.
    pub start_costs: Vec<f64>,
    /// Residual noise level used for the weak-direction test (paper units).
    pub noise_level: f64,
    /// The noise the data show, at the fitted model (with [`Weighting::Measured`]).
    pub noise: Option<crate::noise::NoiseModel>,
    /// Base-frame parameters Ψ (m, rad).
    pub psi: BaseParams,
}

/// What one start reached: scaled parameters, cost, base frame.
type StartOutcome = (DVector<f64>, f64, BaseParams);

/// Scaled ⇄ physical parameters.
#[derive(Debug, Clone)]
struct ParamMap {
    /// Indices (into the 30) of the free parameters.
    free: Vec<usize>,
    k_ref: [(f64, f64); 3],
    linear_only: bool,
}

fn tolerance(i: usize) -> f64 {
    match i {
        0..=5 => TOLERANCES[0],
        6..=11 => TOLERANCES[1],
        13 => TOLERANCES[3],
        12..=17 => TOLERANCES[2],
        _ => TOLERANCES[4],
    }
}

impl ParamMap {
    fn physical(&self, s: &DVector<f64>) -> ParamVector {
        let mut p = [0.0; PARAM_COUNT];
        for k in 0..3 {
            p[IDX_KLIN + k] = self.k_ref[k].0;
            p[IDX_KCUB + k] = if self.linear_only {
                0.0
            } else {
                self.k_ref[k].1
            };
        }
        for (c, &i) in self.free.iter().enumerate() {
            p[i] = if i < IDX_KLIN {
                s[c] * tolerance(i)
            } else {
                p[i] * s[c].exp()
            };
        }
        p
    }
    /// dX_i/ds for the free parameters at physical `p`.
    fn chain(&self, p: &ParamVector) -> Vec<f64> {
        self.free
            .iter()
            .map(|&i| if i < IDX_KLIN { tolerance(i) } else { p[i] })
            .collect()
    }
    fn scaled(&self, p: &ParamVector) -> DVector<f64> {
        DVector::from_iterator(
            self.free.len(),
            self.free.iter().map(|&i| {
                if i < IDX_KLIN {
                    p[i] / tolerance(i)
                } else {
                    let r = if i < IDX_KCUB {
                        self.k_ref[i - IDX_KLIN].0
                    } else {
                        self.k_ref[i - IDX_KCUB].1
                    };
                    (p[i] / r).ln()
                }
            }),
        )
    }
}

/// The outer least-squares problem for the `levenberg-marquardt` crate.
struct OuterProblem<'a> {
    base_model: &'a Model,
    rows: &'a [Prepared],
    map: &'a ParamMap,
    opts: &'a CalibOptions,
    /// Prior rows: (weight vector over the scaled params, centre).
    priors: &'a [DVector<f64>],
    /// GLS whitening, when used.
    whiten: Option<&'a Whitening>,
    s: DVector<f64>,
    model: Option<Model>,
    psi: BaseParams,
}

impl<'a> OuterProblem<'a> {
    /// The problem at scaled parameters `s` (the inner level solved from `psi`).
    #[allow(clippy::too_many_arguments)]
    fn at(
        base_model: &'a Model,
        rows: &'a [Prepared],
        map: &'a ParamMap,
        opts: &'a CalibOptions,
        whiten: Option<&'a Whitening>,
        priors: &'a [DVector<f64>],
        s: &DVector<f64>,
        psi: BaseParams,
    ) -> Self {
        let mut pb = OuterProblem {
            base_model,
            rows,
            map,
            opts,
            priors,
            whiten,
            s: s.clone(),
            model: None,
            psi,
        };
        levenberg_marquardt::LeastSquaresProblem::set_params(&mut pb, s);
        pb
    }

    fn n_res(&self) -> usize {
        6 * self.rows.len()
            + if self.opts.epsilon > 0.0 {
                self.map.free.iter().filter(|&&i| i < IDX_KLIN).count()
            } else {
                0
            }
            + self.priors.len()
    }

    fn predictions(&self, model: &Model) -> Vec<Frame> {
        self.rows
            .iter()
            .map(|r| model.tool_at_rest(&r.q, &r.tau, r.load_n))
            .collect()
    }

    fn solve_inner(&self, model: &Model, start: &BaseParams) -> BaseParams {
        let pairs: Vec<(Frame, Frame)> = self
            .rows
            .iter()
            .filter(|r| r.inner)
            .map(|r| (model.tool_at_rest(&r.q, &r.tau, r.load_n), r.meas))
            .collect();
        base::fit_psi(&pairs, start, self.opts.r_max).0
    }

    /// Data residuals and, when asked, the full Jacobian in scaled parameters.
    fn evaluate(&self, with_jacobian: bool) -> Option<(DVector<f64>, Option<DMatrix<f64>>)> {
        let model = self.model.as_ref()?;
        let n = self.map.free.len();
        let bf = base::frame_from_psi(&self.psi);
        let preds = self.predictions(model);
        let mut r = DVector::zeros(self.n_res());
        let p = model.params();
        let chain = self.map.chain(&p);
        let mut jac = with_jacobian.then(|| DMatrix::zeros(self.n_res(), n));
        // Per-row scaled Jacobians w.r.t. the free parameters and Ψ.
        let mut js: Vec<(SMatrix<f64, 6, 6>, DMatrix<f64>)> = Vec::new();
        for (k, row) in self.rows.iter().enumerate() {
            let (res, jpsi) = base::residual_and_psi_jacobian(
                &preds[k],
                &row.meas,
                &self.psi,
                &bf,
                self.opts.r_max,
            );
            r.fixed_rows_mut::<6>(6 * k).copy_from(&res);
            if with_jacobian {
                let ident = model.identification_jacobian(&row.q, &row.tau);
                let mut jx = DMatrix::zeros(6, n);
                for (c, &i) in self.map.free.iter().enumerate() {
                    let col = ident.column(i) * chain[c];
                    for a in 0..3 {
                        jx[(a, c)] = col[a] / self.opts.r_max;
                        jx[(3 + a, c)] = col[3 + a];
                    }
                }
                js.push((jpsi, jx));
            }
        }
        if let Some(jac) = jac.as_mut() {
            // Implicit differentiation of the inner optimum: dΨ/ds = −H⁻¹ Σ_inner J_Ψᵀ J_s.
            let mut h = SMatrix::<f64, 6, 6>::zeros();
            let mut b = DMatrix::<f64>::zeros(6, n);
            for (k, row) in self.rows.iter().enumerate() {
                if row.inner {
                    let (jp, jx) = &js[k];
                    h += jp.transpose() * jp;
                    b += DMatrix::from_iterator(6, 6, (jp.transpose()).iter().cloned()) * jx;
                }
            }
            let hinv = h.try_inverse()?;
            let dpsi = -DMatrix::from_iterator(6, 6, hinv.iter().cloned()) * b;
            for (k, (jp, jx)) in js.iter().enumerate() {
                let total = jx + DMatrix::from_iterator(6, 6, jp.iter().cloned()) * &dpsi;
                jac.view_mut((6 * k, 0), (6, n)).copy_from(&total);
            }
        }
        if let Some(wh) = self.whiten {
            let m = 6 * self.rows.len();
            let mut rv = DMatrix::from_column_slice(m, 1, &r.as_slice()[..m]);
            wh.apply(&mut rv);
            r.rows_mut(0, m).copy_from(&rv.column(0));
            if let Some(j) = jac.as_mut() {
                let mut block = j.rows(0, m).into_owned();
                wh.apply(&mut block);
                j.rows_mut(0, m).copy_from(&block);
            }
        }
        let mut at = 6 * self.rows.len();
        if self.opts.epsilon > 0.0 {
            // ε is defined against the paper's units; whitened residuals are in units of
            // the position noise, so scale it alike.
            let unit = self.whiten.map_or(1.0, Whitening::unit);
            let w = self.opts.epsilon.sqrt() / unit;
            for (c, &i) in self.map.free.iter().enumerate() {
                if i < IDX_KLIN {
                    r[at] = w * self.s[c];
                    if let Some(j) = jac.as_mut() {
                        j[(at, c)] = w;
                    }
                    at += 1;
                }
            }
        }
        for pr in self.priors {
            r[at] = pr.dot(&self.s);
            if let Some(j) = jac.as_mut() {
                j.row_mut(at).copy_from(&pr.transpose());
            }
            at += 1;
        }
        Some((r, jac))
    }
}

/// The repeatable error, in multiples of the resolver's specification, above which a fit is
/// refused as not explaining the data (a full model leaves a few times the specification, about
/// 25× with a soft J4 spring missing — which discovery then finds; a wrong tool leaves hundreds).
const NOT_EXPLAINED: f64 = 100.0;

/// What to say when the dataset has no sidecar (empty when it has one).
fn sidecar_hint(data: &Dataset) -> &'static str {
    if data.meta.is_some() {
        return "";
    }
    ". The dataset has no sidecar (<name>.meta.yaml beside the CSV): without it \
     the tool is the model's (the nominal model's is the flange itself, which \
     a measured tooling ball is not). The sidecar must give `tool` (flange → measured point: translation m, \
     quaternion w, x, y, z) and should give `noise` (position_m, \
     resolver_arcmin) and `instrument`; see docs/calibration.md"
}

/// The residual of every row at a trial step outside the model's valid range (whitened or
/// scaled units: far above any real residual).
const OUTSIDE: f64 = 1e6;

impl levenberg_marquardt::LeastSquaresProblem<f64, Dyn, Dyn> for OuterProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.s.copy_from(x);
        let p = self.map.physical(x);
        self.model = self.base_model.with_params(&p).ok();
        if let Some(m) = &self.model {
            self.psi = self.solve_inner(m, &self.psi);
        }
    }
    fn params(&self) -> DVector<f64> {
        self.s.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        match self.evaluate(false) {
            Some((r, _)) => Some(r),
            // A trial step outside the model's valid range (a missing effect dragging a
            // departure past its bound): a cost far above any the fit has seen, so the
            // optimiser refuses the step and shrinks its trust region, where `None` would
            // end the whole fit.
            None if self.model.is_none() => Some(DVector::from_element(self.n_res(), OUTSIDE)),
            None => None,
        }
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.evaluate(true).and_then(|(_, j)| j)
    }
}

/// `data` with `model`'s static joint torques in place of its efforts (pa10d's `torque_source:
/// model`, `pa10 calibrate --model-torques`), evaluated where the links are
/// ([`Dataset::with_model_torques`]): first at the link angles of the model the fit starts
/// from (`model`'s springs, the seed stiffness where it has none), then — after a first
/// [`calibrate`] on those — at the fitted model's. Returns that dataset, for the fit to run
/// on, and the first fit's model (whose springs place other datasets' links alike).
///
/// # Errors
/// As [`calibrate`]; a row whose link angles do not converge under its load.
pub fn settled_model_torques(
    model: &Model,
    data: &Dataset,
    lines: Option<&Dataset>,
    opts: &CalibOptions,
) -> Result<(Dataset, Model), CalibError> {
    let start = start_model(model, data, opts)?;
    let first = calibrate(
        model,
        &data.with_model_torques(&start)?,
        lines,
        opts,
        &|_| {},
    )?;
    Ok((data.with_model_torques(&first.model)?, first.model))
}

/// Runs the two-level calibration of `model` on `data` (optional straight-line `lines` for
/// the base-frame seed). `progress` is called with the number of finished starts.
pub fn calibrate(
    model: &Model,
    data: &Dataset,
    lines: Option<&Dataset>,
    opts: &CalibOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<CalibResult, CalibError> {
    check(opts)?;
    let inner_ids = choose_inner(data, opts)?;
    let rows = prepare(data, &inner_ids, opts.torque_constants)?;
    let m0 = start_model(model, data, opts)?;
    let p0 = m0.params();
    let k_ref: [(f64, f64); 3] = std::array::from_fn(|k| {
        (
            p0[IDX_KLIN + k],
            if opts.linear_only {
                1.0
            } else {
                p0[IDX_KCUB + k]
            },
        )
    });
    let free: Vec<usize> = (0..PARAM_COUNT)
        .filter(|&i| !(opts.linear_only && i >= IDX_KCUB))
        .collect();
    let map = ParamMap {
        free,
        k_ref,
        linear_only: opts.linear_only,
    };
    let s0 = map.scaled(&p0);
    if 6 * rows.len() < 2 * map.free.len() {
        return Err(CalibError::Data(format!(
            "{} rows are too few for {} parameters",
            rows.len(),
            map.free.len()
        )));
    }
    let psi0 = seed_base(&m0, &rows, lines)?;
    let prior = weights::prior(data);
    let mut first_sigma = 0.0;
    let mut whitening = match opts.weighting {
        Weighting::Paper => None,
        Weighting::Gls => Some(whitening(data, &m0, &rows, opts.r_max)),
        Weighting::Measured => {
            // The within-cell components need only the Jacobians; the repeatable error
            // waits for the fit (configuration means of a nominal model are all misfit).
            let placed = m0.with_base_from_instrument(&base::frame_from_psi(&psi0))?;
            let samples = weights::samples(data, &placed, &rows);
            let rot = *placed.base_from_instrument().rotation.matrix();
            let nm = crate::noise::within(&samples, &rot, &prior)?;
            // The part of the resolver's specified uncertainty the readings do not carry is
            // presumably repeatable: start from it as a shared offset (the estimate follows).
            let reading2 = nm
                .reading_rad
                .iter()
                .map(|r| r.value * r.value)
                .sum::<f64>()
                / 6.0;
            first_sigma = (prior.resolver_rad.powi(2) - reading2).max(0.0).sqrt();
            Some(weights::from_noise(
                data,
                &nm,
                &samples,
                first_sigma,
                opts.r_max,
            ))
        }
    };
    let noise = match &whitening {
        // whitened residuals have unit variance and their correlation is modelled
        Some(_) => 1.0,
        None => {
            // Resolver errors repeat at a configuration (same angles for every repeat and
            // load), so rows of one configuration are not independent: scale the noise by
            // √(rows per configuration) when judging what the data can see.
            let configs = config_groups(data).len();
            opts.noise_level
                .unwrap_or_else(|| noise_level(data, opts.r_max))
                * (rows.len() as f64 / configs as f64).sqrt()
        }
    };

    // Weak directions from the SVD at the start.
    let probe = OuterProblem::at(&m0, &rows, &map, opts, whitening.as_ref(), &[], &s0, psi0);
    let j0 = probe
        .evaluate(true)
        .and_then(|(_, j)| j)
        .ok_or_else(|| CalibError::Failed("no Jacobian at the start".into()))?;
    let j0 = j0.rows(0, 6 * rows.len()).into_owned();
    let (weak, mut priors) = weak_directions(&j0, &map, noise, opts.weak_threshold);
    // Stiffness is known from the seed to within an order of magnitude: a mild prior
    // (standard deviation ln 10 in log-stiffness) keeps a term the data stop seeing (a cubic
    // coefficient sliding towards 0, where its log loses all sensitivity) from running off.
    for (c, &i) in map.free.iter().enumerate() {
        if i >= IDX_KLIN {
            let mut v = DVector::zeros(map.free.len());
            v[c] = noise / std::f64::consts::LN_10;
            priors.push(v);
        }
    }

    // Starts: the nominal one, then random ones within the tolerances.
    let mut rng = Pcg64::seed_from_u64(opts.seed);
    let starts: Vec<DVector<f64>> = (0..opts.starts)
        .map(|k| {
            if k == 0 {
                s0.clone()
            } else {
                DVector::from_iterator(
                    s0.len(),
                    map.free.iter().enumerate().map(|(c, &i)| {
                        s0[c]
                            + if i < IDX_KLIN {
                                rng.random_range(-1.0..1.0)
                            } else {
                                rng.random_range(-0.5..0.5)
                            }
                    }),
                )
            }
        })
        .collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let solve = |starts: &[(DVector<f64>, BaseParams)],
                 whitening: Option<&Whitening>,
                 patience: usize|
     -> Result<(DVector<f64>, f64, BaseParams, Vec<f64>), CalibError> {
        let runs: Vec<Result<StartOutcome, String>> = starts
            .par_iter()
            .map(|(s, psi)| {
                let pb = OuterProblem::at(&m0, &rows, &map, opts, whitening, &priors, s, *psi);
                let (pb, report) = levenberg_marquardt::LevenbergMarquardt::new()
                    .with_patience(patience)
                    .minimize(pb);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
                use levenberg_marquardt::TerminationReason as T;
                // A step that can no longer reduce the cost is a converged fit, not a failure.
                let ok = report.termination.was_successful()
                    || matches!(
                        report.termination,
                        T::LostPatience | T::NoImprovementPossible(_) | T::Orthogonal
                    );
                if ok && pb.model.is_some() && report.objective_function.is_finite() {
                    Ok((pb.s.clone(), 2.0 * report.objective_function, pb.psi))
                } else {
                    Err(format!("{:?}", report.termination))
                }
            })
            .collect();
        let start_costs: Vec<f64> = runs
            .iter()
            .map(|r| r.as_ref().map_or(f64::NAN, |r| r.1))
            .collect();
        let reasons: Vec<String> = runs
            .iter()
            .filter_map(|r| r.as_ref().err().cloned())
            .collect();
        let (s, cost, psi) = runs
            .into_iter()
            .flatten()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .ok_or_else(|| {
                // the optimiser's own words for "the residual function gave up"
                let mut reasons: Vec<String> = reasons
                    .iter()
                    .map(|r| {
                        r.replace(
                            "User(\"residuals\")",
                            "the model could not be evaluated where the optimiser went (a parameter left its valid range)",
                        )
                    })
                    .collect();
                reasons.dedup();
                let msg = format!("no start converged: {}", reasons.join("; "));
                CalibError::Failed(msg + sidecar_hint(data))
            })?;
        Ok((s, cost, psi, start_costs))
    };
    let starts: Vec<(DVector<f64>, BaseParams)> = starts.into_iter().map(|s| (s, psi0)).collect();
    let (mut s, mut cost, mut psi, start_costs) = solve(&starts, whitening.as_ref(), 200)?;
    let mut noise_model = None;
    if opts.weighting == Weighting::Measured {
        // The whole noise model at the fit; where the configuration means show a repeatable
        // resolver error, refit from this solution with the GLS transform at its estimate,
        // and re-estimate there (a per-row fit leaves more in the configuration means than
        // a GLS fit does), until the estimate settles (three rounds at most).
        let configs = config_groups(data).len();
        let between_dof = ((6 * configs) as f64 - map.free.len() as f64 - 6.0).max(1.0);
        let mut used = first_sigma;
        for _ in 0..3 {
            let fitted =
                OuterProblem::at(&m0, &rows, &map, opts, whitening.as_ref(), &priors, &s, psi);
            let model = fitted
                .model
                .clone()
                .ok_or_else(|| CalibError::Failed("model at the solution".into()))?;
            // The inner level places the base on its few configurations; the noise of the
            // configuration means is judged with the base fitted to all of them, so that
            // the inner configurations' own errors are not counted as resolver error.
            let pairs: Vec<(Frame, Frame)> = rows
                .iter()
                .map(|r| (model.tool_at_rest(&r.q, &r.tau, r.load_n), r.meas))
                .collect();
            let (psi_all, _) = base::fit_psi(&pairs, &psi, opts.r_max);
            let model = model.with_base_from_instrument(&base::frame_from_psi(&psi_all))?;
            let samples = weights::samples(data, &model, &rows);
            let rot = *model.base_from_instrument().rotation.matrix();
            let nm = crate::noise::estimate(&samples, &rot, between_dof, &prior)?;
            // Between-configuration variance beyond the resolver's specification is a
            // misfit (a missing effect), not noise: the weights use at most the prior.
            let sigma = if nm.structure.shares_offsets() {
                nm.repeatable_rad.value.min(prior.resolver_rad)
            } else {
                0.0
            };
            let mut settled = (sigma - used).abs() <= 0.1 * sigma.max(used);
            if !settled {
                let w = weights::from_noise(data, &nm, &samples, sigma, opts.r_max);
                // A refit from the solution on other weights: close, so a shorter patience.
                match solve(&[(s.clone(), psi)], Some(&w), PATIENCE_REFIT) {
                    Ok((s2, c2, p2, _)) => {
                        (s, cost, psi) = (s2, c2, p2);
                        whitening = Some(w);
                        used = sigma;
                    }
                    // Keep the solution on the weights that converged.
                    Err(_) => settled = true,
                }
            }
            noise_model = Some(nm);
            if settled {
                break;
            }
        }
    }

    // A fit that leaves the configurations repeating an error far beyond the resolver's
    // specification has not explained the data (a wrong tool, a missing sidecar): refused,
    // never written as a calibration.
    let mut misfit = None;
    if let Some(nm) = &noise_model {
        let r = nm.repeatable_rad;
        // (At least 10 arcmin: a sidecar may call the resolvers exact.)
        let limit = (NOT_EXPLAINED * prior.resolver_rad).max(10.0 * crate::accuracy::ARCMIN);
        if nm.structure.shares_offsets() && r.lo > limit {
            let what = format!(
                "the fit does not explain the data: the configurations repeat an error of {:.1} arcmin (95 % interval from {:.1}), {:.0}× the resolver's specified {:.2} arcmin",
                r.value / crate::accuracy::ARCMIN,
                r.lo / crate::accuracy::ARCMIN,
                r.value / prior.resolver_rad,
                prior.resolver_rad / crate::accuracy::ARCMIN,
            );
            // Without a sidecar the likeliest cause is the set-up (the tool taken at the
            // flange): refused, with what is missing. With one, the set-up is declared and the
            // misfit is an effect the paper's model lacks: the model is the best fit of that
            // model, and `pa10 discover` is the tool that names what is missing.
            if data.meta.is_none() {
                return Err(CalibError::Data(format!("{what}{}", sidecar_hint(data))));
            }
            misfit = Some(format!(
                "{what}: the model lacks an effect these data show (a spring on another joint, a tool that sags, …); run `pa10 discover` on these data from this model to name it"
            ));
        }
    }

    // Final model, Jacobian, covariance.
    let fin = OuterProblem::at(&m0, &rows, &map, opts, whitening.as_ref(), &priors, &s, psi);
    let (r, j) = fin
        .evaluate(true)
        .ok_or_else(|| CalibError::Failed("final evaluation".into()))?;
    let j = j.ok_or_else(|| CalibError::Failed("final Jacobian".into()))?;
    let m_data = 6 * rows.len();
    let data_cost = r.rows(0, m_data).norm_squared();
    let dof = (m_data as f64 - map.free.len() as f64).max(1.0);
    let s2 = data_cost / dof;
    let jtj = j.transpose() * &j;
    let cov = jtj
        .clone()
        .pseudo_inverse(1e-14)
        .map_err(|e| CalibError::Failed(e.to_string()))?
        * s2;
    let p = map.physical(&s);
    let chain = map.chain(&p);
    let mut std_errors = [None; PARAM_COUNT];
    for (c, &i) in map.free.iter().enumerate() {
        std_errors[i] = Some(cov[(c, c)].max(0.0).sqrt() * chain[c]);
    }
    let sv = j.rows(0, m_data).into_owned().singular_values();
    let mut singular_values: Vec<f64> = sv.iter().cloned().collect();
    singular_values.sort_by(|a, b| b.total_cmp(a));
    let model = fin
        .model
        .clone()
        .ok_or_else(|| CalibError::Failed("final model".into()))?;
    let model = model.with_base_from_instrument(&base::frame_from_psi(&fin.psi))?;
    // the parameters' covariance in physical units, written into the model (fixed ones zero)
    let mut full = vec![vec![0.0; PARAM_COUNT]; PARAM_COUNT];
    for (a, &i) in map.free.iter().enumerate() {
        for (b, &k) in map.free.iter().enumerate() {
            full[i][k] = 0.5 * (cov[(a, b)] + cov[(b, a)]) * chain[a] * chain[b];
        }
    }
    let resolver_rad = noise_model
        .as_ref()
        .map_or(prior.resolver_rad, |nm| nm.repeatable_rad.value);
    let mut d = model.data().clone();
    d.uncertainty = Some(crate::model::ParamCovariance {
        covariance: full,
        resolver_rad: resolver_rad.clamp(0.0, 0.0099),
    });
    let model = Model::new(d)?;
    Ok(CalibResult {
        model,
        cost,
        data_cost,
        std_errors,
        singular_values,
        weak,
        misfit,
        start_costs,
        noise_level: noise,
        noise: noise_model,
        psi: fin.psi,
    })
}

/// Residual noise per component (paper units): instrument noise and the resolver floor
/// (σ_res at a ~0.8 m lever), from the sidecar or the paper's values.
fn noise_level(data: &Dataset, r_max: f64) -> f64 {
    let (pos, res_arcmin) = data
        .meta
        .as_ref()
        .and_then(|m| m.noise)
        .map_or((12.1e-6, 0.64), |n| (n.position_m, n.resolver_arcmin));
    let res = res_arcmin * crate::accuracy::ARCMIN * 0.8;
    ((pos * pos / 3.0 + res * res).sqrt()) / r_max
}

/// Weak directions of the scaled data Jacobian and their prior rows.
fn weak_directions(
    j: &DMatrix<f64>,
    map: &ParamMap,
    noise: f64,
    threshold: f64,
) -> (Vec<WeakDirection>, Vec<DVector<f64>>) {
    let svd = j.clone().svd(false, true);
    let Some(vt) = svd.v_t else {
        return (Vec::new(), Vec::new());
    };
    let names = param_names();
    let mut weak = Vec::new();
    let mut priors = Vec::new();
    // Noise-free data still cannot see structurally null directions: keep a floor.
    let noise = noise.max(1e-7);
    let sv_max = svd.singular_values.max();
    for (k, &sv) in svd.singular_values.iter().enumerate() {
        let se = if sv > 0.0 { noise / sv } else { f64::INFINITY };
        if se > threshold || sv < 1e-8 * sv_max {
            let v = vt.row(k).transpose();
            let mut params: Vec<(String, f64)> = map
                .free
                .iter()
                .enumerate()
                .filter(|(c, _)| v[*c].abs() >= 0.2)
                .map(|(c, &i)| (names[i].to_string(), v[c]))
                .collect();
            params.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            weak.push(WeakDirection {
                singular_value: sv,
                std_error: se,
                params,
            });
            priors.push(v * noise);
        }
    }
    (weak, priors)
}

pub use super::evaluate::{
    ErrorSummary, canonical_base, evaluate, fit_base_only, resolver_floor, row_residual,
};
