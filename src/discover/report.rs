//! What a discovery reports: the lack-of-fit strata, the noise, every candidate's score,
//! the steps, the effects found with their parameters, and the residual evidence for plots.

use super::*;

/// One stratum of the lack-of-fit test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stratum {
    /// Whitened residual sum of squares of the stratum.
    pub chi2: f64,
    /// Its degrees of freedom (net of the parameters' leverage on it).
    pub dof: f64,
    /// `chi2 / dof` (≈ 1 when noise explains it).
    pub ratio: f64,
    /// P(χ²_dof > chi2).
    pub p_value: f64,
}

impl Stratum {
    /// χ² test (variance known), or F test against the pure error's `df_pe` degrees of
    /// freedom when the variance was estimated from the repeats.
    pub(super) fn new(chi2: f64, dof: f64, df_pe: Option<usize>) -> Self {
        let dof = dof.max(1.0);
        let p_value = match df_pe {
            Some(d) if d > 0 => stats::f_sf(chi2 / dof, dof, d as f64),
            _ => stats::chi2_sf(chi2, dof),
        };
        Self {
            chi2,
            dof,
            ratio: chi2 / dof,
            p_value,
        }
    }
}

/// The χ² test of lack of fit, in two strata: configuration means (where a configuration's
/// resolver error sits, and effects of the configuration alone show: transmission error,
/// eccentricity, geometry) and contrasts within configurations between loads, directions
/// and temperatures (where compliance, backlash, thermal growth show), net of the pure
/// error of repeats. Either stratum can reveal a missing effect; `p_value` is the smaller
/// of the two, doubled (Bonferroni).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LackOfFit {
    /// Between configurations.
    pub between: Stratum,
    /// Within configurations (between cells).
    pub within: Stratum,
    /// The combined p-value.
    pub p_value: f64,
}

/// The noise the floor and the weights come from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseReport {
    /// The components estimated from the data, with their structure.
    pub model: crate::noise::NoiseModel,
    /// Repeatable resolver error used in the weights and the floor (the estimate capped at
    /// the resolver's specified σ), rad.
    pub repeatable_used_rad: f64,
}

/// How one candidate scored at one step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// Label, e.g. `transmission_error[J3]`.
    pub label: String,
    /// Machine name.
    pub name: &'static str,
    /// Joint or link, 1-based.
    pub joint: Option<usize>,
    /// Parameters of the effect.
    pub params: usize,
    /// Of those, directions the data can see beyond the current model.
    pub identifiable: usize,
    /// Linearised drop of the whitened cost, scaled by the dispersion.
    pub delta_chi2: f64,
    /// `delta_chi2 − identifiable·ln N`.
    pub delta_bic: f64,
    /// Likelihood-ratio p-value, Bonferroni-adjusted over the step's candidates.
    pub p_adjusted: f64,
    /// Held-out cost drop (whitened), when evaluated.
    pub heldout_gain: Option<f64>,
    /// Paired t statistic over held-out configurations, when evaluated.
    pub paired_t: Option<f64>,
    /// One-sided Wilcoxon signed-rank p-value of "held-out configurations fit better" (their
    /// whitened cost drops), when evaluated.
    pub rank_p: Option<f64>,
    /// Held-out RMS position error with the effect, mm, when evaluated.
    pub heldout_gap_mm: Option<f64>,
    /// Share of bootstrap resamples by configuration in which it is the best candidate,
    /// when evaluated (named only at ≥ 0.8).
    pub stability: Option<f64>,
    /// Whether it passed every test.
    pub passed: bool,
    /// Why it failed, or "not identifiable …".
    pub note: String,
}

/// One round of the forward selection.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step {
    /// 1-based.
    pub step: usize,
    /// Training RMS position residual before this step, mm.
    pub gap_train_mm: f64,
    /// Held-out RMS position error before this step, mm.
    pub gap_heldout_mm: f64,
    /// Lack-of-fit test before this step.
    pub lack_of_fit: LackOfFit,
    /// Candidates, best ΔBIC first.
    pub candidates: Vec<Score>,
    /// The label of the effect added, if any.
    pub accepted: Option<String>,
    /// Whether this step searched the generic dictionary (the library was exhausted).
    pub generic: bool,
    /// Whether this step completed springs by their cubic term on held-out data beyond the
    /// training torques (after the selection; see `complete`).
    pub completion: bool,
    /// Other candidates whose columns, beyond the current model, are nearly parallel to the
    /// accepted one's on these poses (largest canonical correlation ≥ 0.9): what the data
    /// barely tell apart from it, with that correlation.
    pub look_alikes: Vec<(String, f64)>,
    /// How the accepted effect was chosen among look-alikes that pass every test (by the
    /// held-out data, else by physical plausibility), when there were several.
    pub choice: Option<String>,
}

/// An effect found and added.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Found {
    /// Machine name.
    pub name: &'static str,
    /// Joint or link, 1-based (`null` for whole-arm effects).
    pub joint: Option<usize>,
    /// Label.
    pub label: String,
    /// Human description.
    pub description: &'static str,
    /// Estimates by parameter name (SI units, see `units`).
    pub params: BTreeMap<String, f64>,
    /// Standard errors, same units.
    pub stderr: BTreeMap<String, f64>,
    /// Unit of each parameter.
    pub units: BTreeMap<String, &'static str>,
    /// Held-out RMS position error drop when it was added, mm.
    pub gain_mm: f64,
    /// Whether `pa10d` compensates it when the extended model is loaded.
    pub run_time: bool,
    /// For an unnamed generic term, its form, e.g. "δq2 ≈ -4.0e-4·q2² rad on J2, quadratic
    /// in its angle".
    pub form: Option<String>,
}

/// Residuals against an effect's regressor, before and after it was added (for plots).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evidence {
    /// The effect's label.
    pub label: String,
    /// Name and unit of the regressor.
    pub regressor: String,
    /// `(regressor, residual along the effect's signature before, after)`, residuals in mm
    /// (position) — one point per training row.
    pub points: Vec<(f64, f64, f64)>,
}

/// What a discovery found.
#[derive(Debug, Clone, Serialize)]
pub struct Discovery {
    /// Whether the starting model's lack of fit is significant (anything missing at all).
    pub significant_gap_before: bool,
    /// Whether the gap is closed: the extended model's lack of fit is not significant and
    /// its held-out error is within 1.25× the noise floor.
    pub gap_closed: bool,
    /// Whether the library ran out with the lack of fit still significant (the generic
    /// dictionary was then searched).
    pub library_exhausted: bool,
    /// The conclusion in one sentence.
    pub verdict: String,
    /// Held-out RMS position error of the starting model, mm.
    pub gap_before_mm: f64,
    /// Held-out RMS position error of the extended model, mm.
    pub gap_after_mm: f64,
    /// Training RMS position residual of the starting model, mm.
    pub train_gap_before_mm: f64,
    /// Training RMS position residual of the extended model, mm.
    pub train_gap_after_mm: f64,
    /// Expected held-out RMS position error from noise alone (resolver + instrument), mm.
    pub noise_floor_mm: f64,
    /// How the held-out numbers were made.
    pub heldout: String,
    /// Lack of fit of the starting model.
    pub lack_of_fit_before: LackOfFit,
    /// Lack of fit of the extended model.
    pub lack_of_fit_after: LackOfFit,
    /// The noise model of the starting model's fit.
    pub noise: NoiseReport,
    /// The noise model re-estimated at the extended model's fit.
    pub noise_after: NoiseReport,
    /// Effects found, in the order added.
    pub effects: Vec<Found>,
    /// Every round of the selection.
    pub steps: Vec<Step>,
    /// Candidates the data cannot tell from the model at the first step.
    pub not_identifiable: Vec<String>,
    /// Effects the starting model already has (fitted, never candidates).
    pub already_modelled: Vec<String>,
    /// Effects accepted on the way and removed at the end because the effects found after
    /// them explain them (backward elimination), with why.
    pub pruned: Vec<String>,
    /// The combinations of the starting model's parameters these data cannot determine,
    /// held at their start values in every fit (standard error, scale units of 0.1 mm /
    /// 0.1 mrad, and the parameters with their weights).
    pub held: Vec<String>,
    /// Findings about the data that are not effects: a repeatable component far above the
    /// resolver's specification is lack of fit that repeats per configuration, not noise.
    pub findings: Vec<String>,
    /// Residual evidence per effect found.
    #[serde(skip)]
    pub evidence: Vec<Evidence>,
    /// The extended model (what `--out` writes).
    #[serde(skip)]
    pub model: Model,
}

/// The effect's regressor for one observation, and its name.
pub(super) fn regressor(e: &Effect, o: &Obs) -> f64 {
    let j = e.target.unwrap_or(0);
    match e.kind {
        Kind::JointComplianceLinear | Kind::JointComplianceCubic => o.tau[j],
        Kind::TransmissionError | Kind::EncoderEccentricity => o.q[j],
        Kind::Backlash => o.dir[j],
        Kind::ThermalExpansion => o.thermal,
        Kind::LinkBending | Kind::PayloadMassError => o.load_n,
        _ => o.q[0],
    }
}

pub(super) fn regressor_name(e: &Effect, per_kelvin: bool) -> String {
    let j = e.target.map_or(0, |j| j + 1);
    match e.kind {
        Kind::JointComplianceLinear | Kind::JointComplianceCubic => format!("torque of J{j} (N·m)"),
        Kind::TransmissionError | Kind::EncoderEccentricity => {
            format!("resolver angle of J{j} (rad)")
        }
        Kind::Backlash => format!("approach direction of J{j}"),
        Kind::ThermalExpansion if per_kelvin => "temperature − T_ref (K)".into(),
        Kind::ThermalExpansion => "factor regressor (1)".into(),
        Kind::LinkBending | Kind::PayloadMassError => "load (N)".into(),
        _ => "resolver angle of J1 (rad)".into(),
    }
}

/// Residuals along the effect's signature (its fitted contribution's direction at each
/// row), before and after, against its regressor.
pub(super) fn evidence(
    p: &Problem,
    state: &EffectState,
    e: &Effect,
    before: &[Vector6<f64>],
    after: &[Vector6<f64>],
) -> Result<Evidence, ModelError> {
    let mut without = state.clone();
    for s in e.slots() {
        without.set(s, 0.0);
    }
    let raw_without = p.raw(&without)?;
    let per_kelvin = p.obs.iter().any(|o| o.thermal != 1.0);
    let mut points = Vec::new();
    for b in p.blocks.iter().filter(|b| b.train) {
        for &i in &b.rows {
            let c = (after[i] - raw_without[i]).fixed_rows::<3>(0).into_owned();
            let n = c.norm();
            let u = if n > 0.0 {
                c / n
            } else {
                nalgebra::Vector3::x()
            };
            points.push((
                regressor(e, &p.obs[i]),
                -before[i].fixed_rows::<3>(0).dot(&u) * 1e3,
                -after[i].fixed_rows::<3>(0).dot(&u) * 1e3,
            ));
        }
    }
    Ok(Evidence {
        label: e.label(),
        regressor: regressor_name(e, per_kelvin),
        points,
    })
}

/// The effects found, with their parameters at `state` and standard errors from `cov` (the
/// covariance over `slots`, in the slots' scale units), and the held-out gain each brought.
pub(super) fn found(
    found: &[(Effect, f64)],
    slots: &[Slot],
    state: &EffectState,
    cov: &DMatrix<f64>,
    per_kelvin: bool,
) -> Vec<Found> {
    found
        .iter()
        .map(|(e, gain)| {
            let specs = e.params(per_kelvin);
            let mut params = BTreeMap::new();
            let mut stderr = BTreeMap::new();
            let mut units = BTreeMap::new();
            for (sp, sl) in specs.iter().zip(e.slots()) {
                let idx = slots.iter().position(|&s| s == sl).unwrap_or(0);
                params.insert(sp.name.clone(), state.get(sl));
                stderr.insert(
                    sp.name.clone(),
                    cov[(idx, idx)].max(0.0).sqrt() * sl.scale(),
                );
                units.insert(sp.name.clone(), sp.unit);
            }
            Found {
                name: e.kind.name(),
                joint: e.joint(),
                label: e.label(),
                description: e.kind.description(),
                params,
                stderr,
                units,
                gain_mm: *gain,
                run_time: e.run_time(),
                form: e
                    .slots()
                    .first()
                    .and_then(|&sl| e.generic_form(state.get(sl))),
            }
        })
        .collect()
}

/// The extended model file: `state`'s model, named after `start`'s robot, with the effects
/// found recorded (what `pa10d` compensates, with its standard errors).
pub(super) fn extended_model(
    state: &EffectState,
    start: &Model,
    effects: &[Found],
) -> Result<Model, DiscoverError> {
    let mut d = state.to_model()?.data().clone();
    d.robot = format!("{} + effects found by pa10 discover", start.data().robot);
    d.discovered = effects
        .iter()
        .map(|f| EffectRecord {
            name: f.name.to_string(),
            joint: f.joint,
            params: f.params.clone(),
            stderr: f.stderr.clone(),
            compensated: f.run_time,
        })
        .collect();
    // Load effects the starting model carried (its own earlier discovery), refitted here.
    let mut kept = |name: &str, joint: Option<usize>, param: &str, v: f64| {
        let found = effects.iter().any(|f| f.name == name && f.joint == joint);
        if v != 0.0 && !found {
            d.discovered
                .push(EffectRecord::compensated_one(name, joint, param, v));
        }
    };
    for j in 0..6 {
        kept("link_bending", Some(j + 1), "compliance", state.bending[j]);
    }
    kept("payload_mass_error", None, "mass", state.payload_kg);
    kept("tool_sag", None, "compliance", state.tool_sag);
    Ok(Model::new(d)?)
}
