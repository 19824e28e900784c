//! The calibration workflow end to end, as plain data: before / after tables on the
//! calibration set, the paper's validation comparison (nominal vs linear stiffness vs full
//! model), identified parameters with standard errors, identifiability diagnostics.

use std::collections::BTreeMap;

use serde::Serialize;

use super::dataset::Dataset;
use super::fit::{
    CalibError, CalibOptions, CalibResult, ErrorSummary, WeakDirection, calibrate, evaluate,
    fit_base_only, resolver_floor,
};
use crate::model::{Model, PARAM_COUNT, param_names, param_units};

/// Errors per load, keyed by the load in newtons (as text, for JSON).
pub type ByLoad = BTreeMap<String, ErrorSummary>;

fn by_load(v: Vec<ErrorSummary>) -> ByLoad {
    v.into_iter()
        .map(|s| (format!("{}", s.load_n), s))
        .collect()
}

/// One identified parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamReport {
    /// Name (`da1`, `dbeta2`, `klin2`, …).
    pub name: String,
    /// Value in `unit`.
    pub value: f64,
    /// Standard error in `unit` (absent when fixed).
    pub std_error: Option<f64>,
    /// Unit.
    pub unit: String,
}

/// Validation of the three models on held-out data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Validation {
    /// Nominal model (base frame fitted).
    pub before: ByLoad,
    /// Linear-stiffness calibration.
    pub linear: ByLoad,
    /// Full (linear + cubic) calibration.
    pub after: ByLoad,
    /// Resolver floor at the validation poses (mean error, mm, per load).
    pub floor_mm: BTreeMap<String, f64>,
}

/// Everything `pa10 calibrate` reports.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Rows, configurations and loads of the calibration set.
    pub rows: usize,
    /// Distinct configurations.
    pub configurations: usize,
    /// The nominal model's errors on the calibration set (base frame fitted).
    pub before: ByLoad,
    /// The calibrated model's errors on the calibration set.
    pub after: ByLoad,
    /// Validation, when a validation set was given.
    pub validation: Option<Validation>,
    /// Identified stiffness of J2, J3, J5.
    pub stiffness: Stiffness3,
    /// All 30 parameters.
    pub params: Vec<ParamReport>,
    /// Singular values of the scaled identification Jacobian, descending.
    pub singular_values: Vec<f64>,
    /// Their ratio, largest / smallest, over the directions that are not structurally null.
    pub condition_number: f64,
    /// Structurally null directions (singular value below 1e-8 of the largest).
    pub null_directions: usize,
    /// Parameter combinations the data cannot determine (held near nominal / seed).
    pub weak: Vec<WeakDirection>,
    /// The fit leaves a repeatable error far above the resolver's specification: why, and
    /// what to run (see [`crate::calib::fit::CalibResult::misfit`]).
    pub misfit: Option<String>,
    /// Final cost per start.
    pub start_costs: Vec<f64>,
    /// Options used.
    pub epsilon: f64,
    /// Weighting used.
    pub weighting: super::fit::Weighting,
    /// The noise the data show (with the measured weighting).
    pub noise: Option<crate::noise::NoiseModel>,
    /// Linear-only fit.
    pub linear_only: bool,
    /// Seconds the fits took.
    pub elapsed_s: f64,
    /// How well the calibration determines the tool with the other wrist (`None` without a
    /// covariance or a configuration whose wrist can flip).
    pub wrist: Option<WristCoverage>,
}

/// Above this ratio of the flipped wrist's predicted uncertainty to the campaign's own,
/// [`WristCoverage::warning`] says so: a campaign of one wrist leaves the parameters that
/// the other wrist's poses move the tool along undetermined (measured on MuJoCo, docs/judge.md
/// §9: 2.3× predicted, 3–4× realised, and 1.0× once half the extra configurations flip).
pub const WRIST_WARN_RATIO: f64 = 1.5;

/// The calibrated model's predicted tool position uncertainty at the calibration set's
/// configurations and at the same tool poses reached with the other wrist.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WristCoverage {
    /// Configurations with J5 > 0 and with J5 < 0.
    pub configurations: [usize; 2],
    /// Median predicted 1σ (3-D rms) at the configurations, without load, mm.
    pub sigma_mm: f64,
    /// The same at their other-wrist twins within the joint limits, mm.
    pub other_wrist_sigma_mm: f64,
    /// How many configurations had a twin.
    pub twins: usize,
    /// What to do when the ratio exceeds [`WRIST_WARN_RATIO`].
    pub warning: Option<String>,
}

/// [`WristCoverage`] of `model` (a calibrated one: with `uncertainty:`) over `data`'s
/// configurations (each one's first row's resolver angles, as link angles, rad).
pub fn wrist_coverage(model: &Model, data: &Dataset) -> Option<WristCoverage> {
    let none = crate::model::ExternalLoad::hung(0.0, &model.gravity());
    let mut seen = std::collections::BTreeSet::new();
    let mut counts = [0usize; 2];
    let sigma = |q: &[f64; 6]| model.position_uncertainty(q, &model.static_torques(q, &none));
    let (mut own, mut twin) = (Vec::new(), Vec::new());
    for r in &data.rows {
        if !seen.insert(r.config_id.as_str()) {
            continue;
        }
        counts[usize::from(r.q[4] < 0.0)] += 1;
        own.push(sigma(&r.q)?);
        if let Some(s) = model.other_wrist(&r.q).and_then(|t| sigma(&t)) {
            twin.push(s);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2] * 1e3
    };
    if own.is_empty() || twin.is_empty() {
        return None;
    }
    let twins = twin.len();
    let (sigma_mm, other_wrist_sigma_mm) = (median(&mut own), median(&mut twin));
    let ratio = other_wrist_sigma_mm / sigma_mm;
    let warning = (ratio > WRIST_WARN_RATIO).then(|| {
        format!(
            "the campaign determines the tool poorly with the other wrist: predicted 1σ {other_wrist_sigma_mm:.3} mm there against {sigma_mm:.3} mm at its configurations ({ratio:.1}×; J5 > 0 at {}, < 0 at {}): poses the daemon reaches with the wrist flipped will miss by more; add configurations with it (`pa10 plan` draws both)",
            counts[0], counts[1]
        )
    });
    Some(WristCoverage {
        configurations: counts,
        sigma_mm,
        other_wrist_sigma_mm,
        twins,
        warning,
    })
}

/// Stiffness of J2, J3, J5.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stiffness3 {
    /// Klin, N·m/rad.
    pub klin: [f64; 3],
    /// Kcub, N·m/rad³.
    pub kcub: [f64; 3],
}

/// The calibrated model and its report.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The calibration.
    pub result: CalibResult,
    /// The nominal model with its base frame fitted (the "before").
    pub before_model: Model,
    /// The linear-stiffness calibration, when a validation set asked for the comparison.
    pub linear_model: Option<Model>,
    /// The report.
    pub report: Report,
}

/// Calibrates `model` on `data`, and validates on `val` when given.
pub fn run(
    model: &Model,
    data: &Dataset,
    lines: Option<&Dataset>,
    val: Option<&Dataset>,
    opts: &CalibOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Outcome, CalibError> {
    let t0 = std::time::Instant::now();
    let result = calibrate(model, data, lines, opts, progress)?;
    let before_model = fit_base_only(model, data, lines, opts)?;
    let linear_model = match val {
        Some(_) if !opts.linear_only => Some(
            calibrate(
                model,
                data,
                lines,
                &CalibOptions {
                    linear_only: true,
                    ..opts.clone()
                },
                &|_| {},
            )?
            .model,
        ),
        _ => None,
    };
    let elapsed_s = t0.elapsed().as_secs_f64();
    let kt = opts.torque_constants;
    let validation = match val {
        Some(v) => {
            let sigma = data
                .meta
                .as_ref()
                .and_then(|m| m.noise)
                .map_or(0.64, |n| n.resolver_arcmin)
                * crate::accuracy::ARCMIN;
            Some(Validation {
                before: by_load(evaluate(&before_model, v, kt)?),
                linear: by_load(evaluate(
                    linear_model.as_ref().unwrap_or(&result.model),
                    v,
                    kt,
                )?),
                after: by_load(evaluate(&result.model, v, kt)?),
                floor_mm: resolver_floor(&result.model, v, sigma, kt)?
                    .into_iter()
                    .map(|(l, f)| (format!("{l}"), f))
                    .collect(),
            })
        }
        None => None,
    };
    let p = result.model.params();
    let names = param_names();
    let units = param_units();
    let params = (0..PARAM_COUNT)
        .map(|i| ParamReport {
            name: names[i].into(),
            value: p[i],
            std_error: result.std_errors[i],
            unit: units[i].into(),
        })
        .collect();
    // Structurally null directions (a free base frame absorbs δd1 and δθ1 exactly) would make
    // the ratio meaningless: count them apart and condition the rest.
    let sv_max = result.singular_values.first().copied().unwrap_or(0.0);
    let nz: Vec<f64> = result
        .singular_values
        .iter()
        .cloned()
        .filter(|s| *s > 1e-8 * sv_max)
        .collect();
    let null_directions = result.singular_values.len() - nz.len();
    let condition_number = match (nz.first(), nz.last()) {
        (Some(a), Some(b)) => a / b,
        _ => f64::INFINITY,
    };
    let configurations = {
        let mut ids: Vec<&str> = data.rows.iter().map(|r| r.config_id.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        ids.len()
    };
    let report = Report {
        rows: data.rows.len(),
        configurations,
        before: by_load(evaluate(&before_model, data, kt)?),
        after: by_load(evaluate(&result.model, data, kt)?),
        validation,
        stiffness: Stiffness3 {
            klin: [p[24], p[25], p[26]],
            kcub: [p[27], p[28], p[29]],
        },
        params,
        singular_values: result.singular_values.clone(),
        condition_number,
        null_directions,
        weak: result.weak.clone(),
        misfit: result.misfit.clone(),
        start_costs: result.start_costs.clone(),
        epsilon: opts.epsilon,
        weighting: opts.weighting,
        noise: result.noise.clone(),
        linear_only: opts.linear_only,
        elapsed_s,
        wrist: wrist_coverage(&result.model, data),
    };
    Ok(Outcome {
        result,
        before_model,
        linear_model,
        report,
    })
}
