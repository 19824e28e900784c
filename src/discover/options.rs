//! How a discovery is asked for and how it can refuse: [`DiscoverOptions`] with their valid
//! ranges, [`DiscoverError`], and the parameters ("slots") a given starting model fits.

use super::effects::{BASE_ABSORBED, Kind, Slot};
use super::forward::EffectState;
use crate::model::{Model, ModelError};

/// How to run a discovery.
#[derive(Debug, Clone, PartialEq)]
pub struct DiscoverOptions {
    /// Folds of the cross-validation by configuration (used without a holdout set), ≥ 2.
    pub folds: usize,
    /// Significance level of every test (family-wise for the candidate tests).
    pub alpha: f64,
    /// Smallest ΔBIC that accepts an effect ("very strong" evidence is > 10).
    pub min_delta_bic: f64,
    /// Largest number of effects to add.
    pub max_effects: usize,
    /// Wave-generator revolutions per output revolution for transmission-error candidates.
    pub gear_ratio: f64,
    /// Resolver error per joint (1σ), arcmin; the sidecar's, else the paper's 0.64.
    pub resolver_arcmin: Option<f64>,
    /// Motor current → joint torque constants, N·m/A, for datasets with currents.
    pub torque_constants: Option<[f64; 6]>,
    /// Reference temperature of the thermal regressor, °C.
    pub t_ref_c: f64,
    /// Seed of the fold assignment.
    pub seed: u64,
    /// Restrict the candidate library to these kinds (`None`: all).
    pub only: Option<Vec<Kind>>,
}

impl Default for DiscoverOptions {
    fn default() -> Self {
        Self {
            folds: 5,
            alpha: 0.01,
            min_delta_bic: 10.0,
            max_effects: 8,
            gear_ratio: crate::model::DEFAULT_GEAR_RATIO,
            resolver_arcmin: None,
            torque_constants: None,
            t_ref_c: 20.0,
            seed: 1,
            only: None,
        }
    }
}

/// Why a discovery could not run. Nothing is written when one is returned.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiscoverError {
    /// An option is out of range.
    #[error("invalid option {key}: {reason}")]
    Option {
        /// The option.
        key: &'static str,
        /// Why.
        reason: String,
    },
    /// The data cannot support a discovery.
    #[error("dataset: {0}")]
    Data(String),
    /// A model could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The starting fit failed.
    #[error(transparent)]
    Calib(#[from] crate::calib::fit::CalibError),
    /// The data's noise could not be estimated.
    #[error("dataset: {0}")]
    Noise(#[from] crate::noise::NoiseError),
}

/// The slots the given model fits: departures (but the two a free base absorbs), the base
/// frame, the springs it has, the joint errors it has.
pub(super) fn model_slots(model: &Model) -> Vec<Slot> {
    let mut s: Vec<Slot> = (0..24)
        .filter(|i| !BASE_ABSORBED.contains(i))
        .map(Slot::Dep)
        .collect();
    s.extend((0..6).map(Slot::Base));
    let d = model.data();
    for j in 0..6 {
        if let Some(k) = d.stiffness[j] {
            s.push(Slot::Compliance(j));
            if k.kcub > 0.0 {
                s.push(Slot::Kcub(j));
            }
        }
        if let Some(e) = d.joint_errors[j] {
            let st = EffectState::from_model(model, e.gear_ratio);
            s.extend(
                (0..14)
                    .map(|k| Slot::JointErr(j, k))
                    .filter(|&sl| st.get(sl) != 0.0),
            );
        }
    }
    // Load effects outside the joints a previous discovery wrote (compensated).
    let load = model.load_effects();
    s.extend(
        (0..6)
            .filter(|&j| load.bending[j] != 0.0)
            .map(Slot::Bending),
    );
    if load.payload_kg != 0.0 {
        s.push(Slot::Payload);
    }
    if load.tool_sag != 0.0 {
        s.push(Slot::ToolSag);
    }
    s
}

pub(super) fn check(opts: &DiscoverOptions) -> Result<(), DiscoverError> {
    let bad = |key, reason: String| Err(DiscoverError::Option { key, reason });
    if !(2..=50).contains(&opts.folds) {
        return bad("folds", format!("must be 2…50, got {}", opts.folds));
    }
    if !(opts.alpha > 0.0 && opts.alpha < 0.5) {
        return bad("alpha", format!("must be in (0, 0.5), got {}", opts.alpha));
    }
    if !(opts.min_delta_bic.is_finite() && opts.min_delta_bic >= 0.0) {
        return bad(
            "min_delta_bic",
            format!("must be ≥ 0, got {}", opts.min_delta_bic),
        );
    }
    if !(opts.gear_ratio.is_finite() && opts.gear_ratio > 0.0 && opts.gear_ratio <= 1e4) {
        return bad(
            "gear_ratio",
            format!("must be in (0, 10000], got {}", opts.gear_ratio),
        );
    }
    if let Some(r) = opts.resolver_arcmin
        && !(r.is_finite() && r > 0.0 && r < 60.0)
    {
        return bad(
            "resolver_arcmin",
            format!("must be in (0, 60) arcmin, got {r}"),
        );
    }
    if !(opts.t_ref_c.is_finite() && (-50.0..=150.0).contains(&opts.t_ref_c)) {
        return bad(
            "t_ref_c",
            format!("must be within -50…150 °C, got {}", opts.t_ref_c),
        );
    }
    if opts.max_effects > 10 {
        return bad(
            "max_effects",
            format!("at most 10, got {}", opts.max_effects),
        );
    }
    Ok(())
}
