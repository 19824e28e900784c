//! The daemon judged by a physics engine we did not write: `pa10 demo`'s story on a PA10-6C that
//! MuJoCo computes (`tests/mujoco/plant.py`: rotor inertia, harmonic-drive friction, flexible
//! joints with hidden stiffness, masses and geometry), the daemon's unchanged core and the
//! simulated servo controller's protocol in lockstep with it.
//!
//! 1. A calibration campaign gathered through the daemon (27 poses × 0/22/44 N; the instrument
//!    is MuJoCo's tool pose seen through the drawn instrument frame with the paper's noise),
//!    calibrated (the 30-parameter model and the nominal model placed).
//!    Unless `--no-identify`, an identification tour comes first (`pa10 identify`'s sweeps through
//!    the daemon): the gravity model and friction it finds are the model every later step
//!    starts from (the fit's model torques, the daemon's), judged against MuJoCo's spring
//!    torques at rest at the novel poses.
//! 2. Novel poses at 0/45/90 N with each model loaded into the daemon, judged by MuJoCo's tool
//!    pose, beside the Monte Carlo resolver floor at those configurations.
//! 3. Tracking of `docs/motion.md`'s six-point trajectory at 0 and 90 N: MuJoCo's link angles
//!    against the trajectory's desired positions, every cycle.
//!
//! With `--discover` the loop closes (docs/judge.md §9): a held-out campaign through the
//! daemon, `pa10 discover` from the calibrated model, the extended model recalibrated by
//! `pa10 calibrate`'s method with the named effects held (`--no-recalibrate`: discovery's own
//! refit) loaded into the daemon and validated beside the others; at a load where the
//! extended model misses 1.1× the floor the judge says what the miss is (`Miss`: the
//! placement error split into where the servo rested, the torque estimate, the resolvers'
//! repeatable error and the model's own — the judge knows the plant's truth).
//!
//! `cargo run --release --example mujoco_judge [-- --json] [--quick] [--check] [--discover]
//! [--no-recalibrate] [--seed N]
//! [--friction F] [--friction-model creep|stick] [--torque-source measured|model|blended|estimated]
//! [--current-filter-hz HZ] [--no-identify] [--hold-deadband RAD] [--hold-damping D] [--gain-inertia KGM2] [--check-ratio R] [--trace FILE]
//! [--keep DIR] [--extra-configs N] [--extra-flipped] [--validation-poses N] [--hide-gear J:G]
//! [--hide-bearing J:A:PHI] [--hide-bend upper|forearm:C] [--hide-payload KG] [--exact-resolvers]
//! [--tool X,Y,Z]`
//! — by default as `config/sim-mujoco.yaml` runs the daemon and the README's workflow runs a
//! lab: `pa10 identify` first, `torque_source: estimated`, `hold_damping: 1`. Needs `pip install
//! mujoco` (the Python interpreter `PA10_PYTHON`, default `python3`; `PA10_PLANT` names another
//! plant script speaking docs/plant-protocol.md). docs/judge.md quotes it;
//! `tests/mujoco/study.py` runs it over seeds and friction behaviours.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail, ensure};
use pa10::calib::dataset::{Dataset, Effort, Meta, Row};
use pa10::calib::fit::{CalibOptions, calibrate, fit_base_only, settled_model_torques};
use pa10::calib::identify::SweepPlan;
use pa10::daemon::api::sweep;
use pa10::daemon::config::{Config, Settings};
use pa10::daemon::core::Core;
use pa10::daemon::wire::{Answer, ApiRequest, Reply, State, Status};
use pa10::discover::{DiscoverOptions, Found, discover};
use pa10::model::{
    Frame, IkError, JointLimits, Model, NOMINAL_YAML, Torques, frame_from_pose, pose_error,
    pose_parts,
};
use pa10::sim::experiment::{grid_poses, random_pose, sidecar};
use pa10::sim::mujoco::{MujocoOptions, MujocoPlant};
use pa10::sim::plant::{
    BENDING_ROWS, FrictionModel, HiddenEffects, MAX_FRICTION_SCALE, PlantConfig, PlantKind,
};
use pa10::sim::rig::{HOME, Lockstep, default_tool, truth_for};
use pa10::sim::servo::{ServoConfig, ServoSim};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use serde::Serialize;

#[path = "common/six_points.rs"]
mod motion_path;
use motion_path::six_points;
#[path = "common/tracking.rs"]
mod tracking;

const CAL_LOADS: [f64; 3] = [0.0, 22.0, 44.0];
/// `--extra-configs`' limit (each is ≈ 6 simulated settles at three loads).
const MAX_EXTRA_CONFIGS: usize = 200;
const VAL_LOADS: [f64; 3] = [0.0, 45.0, 90.0];
/// `--validation-poses`' limit (each is ≈ 9 simulated moves and settles per model).
const MAX_VALIDATION_POSES: usize = 100;
const PERIOD_S: f64 = 0.002;
/// How much worse than the calibrated model's mean error the extended model's may be, as a
/// fraction of the floor, before `--check` calls it worse, on creeping drives: one model
/// validated twice at the same poses differs by up to 0.12× the floor at a load (seed 4, full
/// run, nothing named; docs/judge.md §9). On sticking drives a stuck drive rests anywhere in
/// its holding band even in position, and one model validated twice differs by up to 0.18×
/// the floor (docs/judge.md §9, "Measuring in position"), so there `--check` judges the
/// placement pose by pose ([`Paired`]): worse by more than this slack *and* [`PAIRED_T`]
/// paired standard errors over at least [`PAIRED_MIN_POSES`] poses. The models' own error at
/// rest (`prediction_mean_mm`: where the servo stopped taken out) is checked with the same
/// slack on creeping drives. tests/mujoco/study.py uses the same rules.
const EXTENDED_SLACK: f64 = 0.15;
/// Paired standard errors the extended model's placement must be worse by (sticking drives).
const PAIRED_T: f64 = 3.0;
/// Poses a paired comparison needs before `--check` judges it (fewer say too little).
const PAIRED_MIN_POSES: usize = 6;
/// The per-seed goal (#42): the extended model's mean placement within this × the floor at
/// every load; a load that misses it is attributed ([`Miss`]).
const GOAL_RATIO: f64 = 1.1;

struct Opts {
    json: bool,
    quick: bool,
    check: bool,
    seed: u64,
    friction: f64,
    friction_model: FrictionModel,
    torque_source: String,
    /// The daemon's `current_filter_hz` (for `torque_source: measured`), Hz.
    filter_hz: Option<f64>,
    /// Identify the gravity model and friction through the daemon first.
    identify: bool,
    /// The daemon's `control.hold_deadband`, rad.
    hold_deadband: f64,
    /// The daemon's `control.hold_damping`.
    hold_damping: f64,
    /// The daemon's `control.gain_inertia_kgm2`, kg·m² (0: a constant gain).
    gain_inertia: f64,
    /// `--check`'s bound on calibrated mean / floor (default 2 quick, 1.3 full).
    check_ratio: Option<f64>,
    /// `--trace FILE`: every move's and settle's samples as CSV (for finding what rings).
    trace: Option<PathBuf>,
    /// Gather a held-out campaign, run `pa10 discover` from the calibrated model and validate
    /// the extended model beside it.
    discover: bool,
    /// With `--discover`: the extended model recalibrated by `pa10 calibrate` (the paper's
    /// parameters refitted, the named effects held at discovery's estimates); the default,
    /// `--no-recalibrate` keeps discovery's own refit.
    recalibrate: bool,
    /// `--keep DIR`: the campaigns (`campaign.csv`, with `--discover` `heldout.csv`, as the
    /// pa10 commands read them: the torques the fit used) and the models judged (`*.yaml`)
    /// written to DIR, so `pa10 calibrate` / `pa10 discover` can be re-run on them offline.
    keep: Option<PathBuf>,
    /// `--extra-configs N`: N configurations drawn in the grid's box (their own random stream,
    /// ids `c1`…) gathered after the 27 grid poses at the calibration loads, for a campaign
    /// with more configurations than the paper's (the resolvers' repeatable error is a
    /// function of the angles, so it averages over configurations, not over repeats).
    extra_configs: usize,
    /// `--validation-poses N`: novel poses validated at 0/45/90 N (default 6, `--quick` 2);
    /// drawn in order from the run's stream, so the first six are a default run's. The
    /// resolvers' error realised at six poses is within ±0.25× of the floor between seeds:
    /// more poses judge one seed against the floor more tightly.
    validation_poses: Option<usize>,
    /// `--extra-flipped`: every other `--extra-configs` configuration reached with the other
    /// wrist (J4 + π, −J5, J6 + π): a campaign that sees both wrist branches.
    extra_flipped: bool,
    /// `--hide-gear J:G`, `--hide-bearing J:A:PHI`, `--hide-bend LINK:C`, `--hide-payload KG`:
    /// effects the plant hides (a gear ratio off by a relative G on joint J; an output
    /// bearing's once-per-revolution error of A rad at phase PHI rad; the upper arm or the
    /// forearm bending at its midpoint by C rad/(N·m); KG at the tool beyond every declared
    /// payload), for judging what `--discover` names.
    hidden: Option<HiddenEffects>,
    /// `--exact-resolvers`: the plant's resolvers without their repeatable error (a
    /// diagnostic: what the loop does when the only error left is the instrument's and the
    /// servo's; the floor quoted stays the specified resolvers').
    exact_resolvers: bool,
    /// `--tool X,Y,Z`: the tool point (the tooling ball, where the load hangs) in the flange
    /// frame, m; default the campaigns' 0.35 m along the flange axis. Off the axis, J6 carries
    /// the load (the plant's J6 spring, which the model calls rigid, shows). A grid pose the
    /// tool cannot reach pointing down (a long or tilted tool) is measured at the paper tool's
    /// configuration there ([`campaign_config`]).
    tool: [f64; 3],
}

/// Largest distance of `--tool` from the flange, m.
const MAX_TOOL_M: f64 = 0.5;

/// Joint `J` (1…6) and the numbers after it of a `--hide-…` value `J:x[:y]`.
fn hidden_joint(flag: &str, v: &str, numbers: usize) -> Result<(usize, Vec<f64>)> {
    let parts: Vec<&str> = v.split(':').collect();
    ensure!(
        parts.len() == numbers + 1,
        "{flag}: joint and {numbers} number(s) separated by ':', got {v}"
    );
    let j: usize = parts[0]
        .parse()
        .with_context(|| format!("{flag}: a joint 1…6, got {}", parts[0]))?;
    ensure!((1..=6).contains(&j), "{flag}: a joint 1…6, got {j}");
    let x = parts[1..]
        .iter()
        .map(|p| {
            p.parse::<f64>()
                .with_context(|| format!("{flag}: a number, got {p}"))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((j - 1, x))
}

/// The options of the process's arguments.
fn opts() -> Result<Opts> {
    opts_from(std::env::args().skip(1))
}

/// The options of `args` (without the program's name), checked.
fn opts_from(mut args: impl Iterator<Item = String>) -> Result<Opts> {
    let mut o = Opts {
        json: false,
        quick: false,
        check: false,
        seed: 1,
        friction: 1.0,
        friction_model: FrictionModel::Creep,
        torque_source: "estimated".into(),
        filter_hz: None,
        identify: true,
        hold_deadband: 1e-4,
        hold_damping: 1.0,
        gain_inertia: 8.5,
        check_ratio: None,
        trace: None,
        discover: false,
        recalibrate: true,
        keep: None,
        extra_configs: 0,
        validation_poses: None,
        extra_flipped: false,
        hidden: None,
        exact_resolvers: false,
        tool: default_tool().translation.vector.into(),
    };
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or_else(|| anyhow!("{name} needs a value"));
        match a.as_str() {
            "--json" => o.json = true,
            "--quick" => o.quick = true,
            "--extra-flipped" => o.extra_flipped = true,
            "--exact-resolvers" => o.exact_resolvers = true,
            "--tool" => {
                let v = value("--tool")?;
                let xyz = v
                    .split(',')
                    .map(|p| {
                        p.trim()
                            .parse::<f64>()
                            .ok()
                            .filter(|x| x.is_finite())
                            .with_context(|| format!("--tool: X,Y,Z in m, got {v}"))
                    })
                    .collect::<Result<Vec<_>>>()?;
                ensure!(xyz.len() == 3, "--tool: X,Y,Z in m, got {v}");
                let t = [xyz[0], xyz[1], xyz[2]];
                let r = t.iter().map(|x| x * x).sum::<f64>().sqrt();
                ensure!(
                    (0.05..=MAX_TOOL_M).contains(&r),
                    "--tool: 0.05…{MAX_TOOL_M} m from the flange, got {r:.3} m"
                );
                o.tool = t;
            }
            "--check" => o.check = true,
            "--identify" => o.identify = true,
            "--discover" => o.discover = true,
            "--no-recalibrate" => o.recalibrate = false,
            "--no-identify" => o.identify = false,
            "--seed" => o.seed = value("--seed")?.parse().context("--seed: an integer")?,
            "--friction" => {
                o.friction = value("--friction")?
                    .parse()
                    .context("--friction: a number")?;
                ensure!(
                    (0.0..=MAX_FRICTION_SCALE).contains(&o.friction),
                    "--friction: a scale 0…{MAX_FRICTION_SCALE} of the plant's friction, got {}",
                    o.friction
                );
            }
            "--friction-model" => {
                o.friction_model = match value("--friction-model")?.as_str() {
                    "creep" => FrictionModel::Creep,
                    "stick" => FrictionModel::Stick,
                    other => bail!("--friction-model: creep or stick, got {other}"),
                }
            }
            "--torque-source" => {
                o.torque_source = value("--torque-source")?;
                ensure!(
                    ["measured", "model", "blended", "estimated"]
                        .contains(&o.torque_source.as_str()),
                    "--torque-source: measured, model, blended or estimated, got {}",
                    o.torque_source
                );
            }
            "--hold-deadband" => {
                o.hold_deadband = value("--hold-deadband")?
                    .parse()
                    .context("--hold-deadband: rad")?;
            }
            "--gain-inertia" => {
                o.gain_inertia = value("--gain-inertia")?
                    .parse()
                    .context("--gain-inertia: kg·m² (0: a constant gain)")?;
            }
            "--hold-damping" => {
                o.hold_damping = value("--hold-damping")?
                    .parse()
                    .context("--hold-damping: a number")?;
            }
            "--hide-gear" => {
                let (j, x) = hidden_joint("--hide-gear", &value("--hide-gear")?, 1)?;
                o.hidden.get_or_insert_with(Default::default).gear[j] = x[0];
            }
            "--hide-bearing" => {
                let (j, x) = hidden_joint("--hide-bearing", &value("--hide-bearing")?, 2)?;
                o.hidden.get_or_insert_with(Default::default).bearing[j] = [x[0], x[1]];
            }
            "--hide-bend" => {
                let v = value("--hide-bend")?;
                let (link, c) = v.split_once(':').with_context(|| {
                    format!("--hide-bend: upper:C or forearm:C (C rad/(N·m)), got {v}")
                })?;
                let row = match link {
                    "upper" => BENDING_ROWS[0],
                    "forearm" => BENDING_ROWS[1],
                    _ => bail!("--hide-bend: the link is upper or forearm, got {link}"),
                };
                o.hidden.get_or_insert_with(Default::default).bend[row] = c
                    .parse()
                    .with_context(|| format!("--hide-bend: a compliance rad/(N·m), got {c}"))?;
            }
            "--hide-payload" => {
                o.hidden.get_or_insert_with(Default::default).payload_kg = value("--hide-payload")?
                    .parse()
                    .context("--hide-payload: a mass, kg")?;
            }
            "--trace" => o.trace = Some(PathBuf::from(value("--trace")?)),
            "--keep" => o.keep = Some(PathBuf::from(value("--keep")?)),
            "--extra-configs" => {
                let n: usize = value("--extra-configs")?
                    .parse()
                    .context("--extra-configs: a count of configurations")?;
                ensure!(
                    n <= MAX_EXTRA_CONFIGS,
                    "--extra-configs: at most {MAX_EXTRA_CONFIGS}, got {n}"
                );
                o.extra_configs = n;
            }
            "--validation-poses" => {
                let n: usize = value("--validation-poses")?
                    .parse()
                    .context("--validation-poses: a count of poses")?;
                ensure!(
                    (1..=MAX_VALIDATION_POSES).contains(&n),
                    "--validation-poses: 1 to {MAX_VALIDATION_POSES}, got {n}"
                );
                o.validation_poses = Some(n);
            }
            "--check-ratio" => {
                let r: f64 = value("--check-ratio")?
                    .parse()
                    .context("--check-ratio: a number")?;
                ensure!(
                    r >= 1.0 && r.is_finite(),
                    "--check-ratio: at least 1, got {r}"
                );
                o.check_ratio = Some(r);
            }
            "--current-filter-hz" => {
                let f: f64 = value("--current-filter-hz")?
                    .parse()
                    .context("--current-filter-hz: a number")?;
                ensure!(f > 0.0 && f.is_finite(), "--current-filter-hz: positive Hz");
                o.filter_hz = Some(f);
            }
            other => bail!(
                "unknown argument {other} (--json, --quick, --check, --discover, --no-recalibrate, --identify, --no-identify, --seed N, --friction F, --friction-model creep|stick, --torque-source measured|model|blended|estimated, --current-filter-hz HZ, --hold-deadband RAD, --hold-damping D, --gain-inertia KGM2, --check-ratio R, --trace FILE, --keep DIR, --extra-configs N, --extra-flipped, --validation-poses N, --hide-gear J:G, --hide-bearing J:A:PHI, --hide-bend upper|forearm:C, --hide-payload KG, --exact-resolvers, --tool X,Y,Z)"
            ),
        }
    }
    if let Some(h) = &o.hidden {
        h.validate().map_err(|e| anyhow!("--hide-…: {e}"))?;
    }
    Ok(o)
}

/// Mean position error of one model at one load, mm.
#[derive(Debug, Serialize)]
struct LoadRow {
    load_n: f64,
    nominal_mean_mm: f64,
    calibrated_mean_mm: f64,
    nominal_peak_mm: f64,
    calibrated_peak_mm: f64,
    /// At rest: RMS over joints of MuJoCo's link angles − the daemon's setpoint, mean over
    /// poses, mrad (where the compensation says the link is vs where it came to rest)
    nominal_rest_mrad: f64,
    calibrated_rest_mrad: f64,
    /// Time from the load change until the resolvers and MuJoCo's links were still, mean over
    /// the calibrated model's poses, s (at most 5)
    settle_mean_s: f64,
    /// With `--discover`: the extended model's mean and peak position error, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    extended_mean_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    extended_peak_mm: Option<f64>,
    /// Where each model (nominal, calibrated[, extended]) says the tool is at rest — its
    /// forward model at the resolvers' rest angles and the torques the daemon used — against
    /// MuJoCo's tool, mean over poses, mm: the model's own error, without where the servo
    /// stopped (a stuck drive rests anywhere in its band; the placement error above has both).
    prediction_mean_mm: Vec<f64>,
    /// The same with MuJoCo's spring torques in place of the daemon's (when the plant reports
    /// them), mm: the model's kinematics and compliance alone, without the torque estimate's
    /// error at rest (the difference to `prediction_mean_mm` is that estimate's share).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    prediction_true_torque_mean_mm: Vec<f64>,
    /// The same from MuJoCo's motor angles as well (no resolver error), mm: what the model's
    /// geometry and compliance alone get wrong (the floor's resolver share taken out).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    prediction_exact_mean_mm: Vec<f64>,
    /// Per model, per joint: the model's joint deflection (link − motor, from MuJoCo's spring
    /// torques) − MuJoCo's, mean over poses, mrad: which joint's compliance is off.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    deflection_error_mrad: Vec<[f64; 6]>,
    /// Per model: how far the resolvers' error alone moves its tool (its prediction from the
    /// resolvers' angles − from MuJoCo's motor angles, both with MuJoCo's torques), mean over
    /// poses, mm: the floor these poses realised (`floor_mm` is its expectation).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    resolver_share_mean_mm: Vec<f64>,
    /// Per model, per joint: the daemon's joint torques at rest − MuJoCo's spring torques,
    /// RMS over poses, N·m: the torque estimate's error at rest (`torque_source`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    torque_error_rms_nm: Vec<[f64; 6]>,
    /// Per model: where the servo left the tool in the model's own eyes — |the target − the
    /// model's tool at the resolvers' rest angles and the daemon's torques| — mean over poses,
    /// mm (when the plant says its springs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    servo_mean_mm: Vec<f64>,
    /// With `--discover`: the extended model's placement − the calibrated one's, pose by pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    extended_paired: Option<Paired>,
    /// With `--discover`, where the extended model misses [`GOAL_RATIO`] × the floor: by what.
    #[serde(skip_serializing_if = "Option::is_none")]
    extended_miss: Option<Miss>,
}

/// The extended model's placement − the calibrated one's, pose by pose over the validation
/// poses both reached at one load (both validated on the same poses, so where stuck drives
/// happened to rest is told apart from the model): mean and its standard error, mm.
#[derive(Debug, Clone, Copy, Serialize)]
struct Paired {
    mean_mm: f64,
    se_mm: f64,
    poses: usize,
}

/// What a load at which the extended model misses [`GOAL_RATIO`] × the floor misses by: its
/// placement error at each pose split into four parts (tool point, mm) — where the servo left
/// the tool (the target − the model's tool at the resolvers' rest angles and the daemon's
/// torques), the daemon's torque estimate at rest (that tool − the same with MuJoCo's spring
/// torques), the resolvers' repeatable error (− the same from MuJoCo's motor angles) and the
/// model's own geometry and compliance (− MuJoCo's tool) — the mean placement with each part
/// taken out, and the model's own part once more from the same model fitted to the campaign
/// as exact resolvers would have read it. The judge knows the plant's truth; the daemon and
/// `pa10 discover` do not.
#[derive(Debug, Clone, Serialize)]
struct Miss {
    /// The extended model's mean placement over the poses the split covers ÷ the floor.
    ratio: f64,
    /// The resolvers' part, mean over the poses ÷ the floor: the floor these poses realised
    /// (its expectation is ≈ 1).
    resolvers_realised: f64,
    /// The mean placement ÷ the floor with one part taken out: servo, torque, resolvers, model.
    without: [f64; 4],
    /// The model's own part, mean ÷ the floor: as fitted, and fitted to the campaign as exact
    /// resolvers would have read it (the resolvers' error at the campaign's poses taken out of
    /// the fit).
    model_part: [f64; 2],
    /// The mean placement ÷ the floor with the model's part from that exact-resolver fit.
    with_exact_campaign: f64,
    /// What the miss is: `resolvers` (within [`GOAL_RATIO`] × the floor these poses realised:
    /// an error of the resolvers, not of the arm, that no parameter of the model removes),
    /// `campaign resolvers` (within it with the model fitted to the campaign as exact
    /// resolvers read it: the same error, carried into the fit at the campaign's poses), else
    /// the part whose removal helps most of `servo`, `torque` and `model` (what a fit to exact
    /// readings still misses: an effect the library lacks, or the instrument's noise).
    cause: &'static str,
    /// The same in words, with the numbers.
    says: String,
}

/// The parts of a placement error at one pose (tool point, instrument frame, mm): servo,
/// torque, resolvers, model ([`Miss`]), which sum to the target − MuJoCo's tool; and fifth,
/// the model part of the same model fitted to the campaign as exact resolvers would have
/// read it (the fourth again where that fit was not made).
type Parts = [nalgebra::Vector3<f64>; 5];

/// [`Paired`] over the poses where both `cal` and `ext` have an error (mm); `None` below two.
fn paired(cal: &[Option<f64>], ext: &[Option<f64>]) -> Option<Paired> {
    let d: Vec<f64> = cal
        .iter()
        .zip(ext)
        .filter_map(|(c, e)| Some((*e)? - (*c)?))
        .collect();
    let n = d.len();
    if n < 2 {
        return None;
    }
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    Some(Paired {
        mean_mm: mean,
        se_mm: (var / n as f64).sqrt(),
        poses: n,
    })
}

/// The [`Miss`] of the extended model's `parts` at one load against `floor_mm`; `None` when
/// it is within [`GOAL_RATIO`] × the floor (or nothing was split).
fn miss(parts: &[Parts], floor_mm: f64) -> Option<Miss> {
    if parts.is_empty() || floor_mm <= 0.0 {
        return None;
    }
    let mean = |f: &dyn Fn(&Parts) -> nalgebra::Vector3<f64>| {
        parts.iter().map(|p| f(p).norm()).sum::<f64>() / parts.len() as f64 / floor_mm
    };
    let total = |p: &Parts| p[..4].iter().sum::<nalgebra::Vector3<f64>>();
    let ratio = mean(&total);
    if ratio <= GOAL_RATIO {
        return None;
    }
    let realised = mean(&|p| p[2]);
    let without: [f64; 4] = std::array::from_fn(|k| mean(&|p| total(p) - p[k]));
    let model_part = [mean(&|p| p[3]), mean(&|p| p[4])];
    let with_exact_campaign = mean(&|p| total(p) - p[3] + p[4]);
    let goal = GOAL_RATIO * realised;
    let (cause, says) = if ratio <= goal {
        (
            "resolvers",
            format!(
                "the resolvers' repeatable error these poses realised is {realised:.2}× the floor, and the placement is within {GOAL_RATIO}× of that: an error of the resolvers, which no parameter of the arm's model removes (without it {:.2}×)",
                without[2]
            ),
        )
    } else if with_exact_campaign <= goal {
        (
            "campaign resolvers",
            format!(
                "the resolvers' repeatable error at the campaign's poses, carried into the fit: the same model fitted to the campaign as exact resolvers would have read it places within {with_exact_campaign:.2}× the floor (its own part {:.2} → {:.2}×; the resolvers realised {realised:.2}× here)",
                model_part[0], model_part[1]
            ),
        )
    } else {
        let k = [0, 1, 3]
            .into_iter()
            .min_by(|&a, &b| without[a].total_cmp(&without[b]))
            .unwrap_or(3);
        let what = match k {
            0 => (
                "servo",
                "where the drives came to rest (a stuck drive rests anywhere in its band)"
                    .to_string(),
            ),
            1 => ("torque", "the daemon's torque estimate at rest".to_string()),
            _ => (
                "model",
                format!(
                    "the model's own geometry and compliance, {:.2}× the floor fitted to exact readings too: an effect the library lacks, or the instrument's noise",
                    model_part[1]
                ),
            ),
        };
        (
            what.0,
            format!(
                "{}: without it {:.2}× the floor (the resolvers realised {realised:.2}×)",
                what.1, without[k]
            ),
        )
    };
    Some(Miss {
        ratio,
        resolvers_realised: realised,
        without,
        model_part,
        with_exact_campaign,
        cause,
        says,
    })
}

/// One validation pose of [`Outcome`].
#[derive(Debug, Serialize)]
struct PoseDetail {
    setpoint_rad: Option<[f64; 6]>,
    error_mm: Vec<Option<[f64; 3]>>,
    /// Each model's own error from MuJoCo's motor angles and torques (the model alone), mm.
    exact_mm: Vec<[Option<f64>; 3]>,
    /// The daemon's `position_sigma_mm` at 0 N with each model: its covariance's tool
    /// position uncertainty (1σ, mm) at the setpoint, `null` without one.
    sigma_mm: Vec<Option<f64>>,
}

/// With `--discover`: what `pa10 discover` said on the campaign and the held-out set.
#[derive(Debug, Serialize)]
struct DiscoverySummary {
    verdict: String,
    gap_closed: bool,
    /// Rows of the held-out campaign (novel configurations at 0/45/90 N).
    heldout_rows: usize,
    /// Discovery's held-out RMS position error, mm: the calibrated model, the extended one,
    /// and the noise floor it expects.
    heldout_before_mm: f64,
    heldout_after_mm: f64,
    noise_floor_mm: f64,
    /// Wall-clock time of the discovery, s.
    elapsed_s: f64,
}

#[derive(Debug, Serialize)]
struct Tracking {
    nominal_rms_mrad: f64,
    calibrated_rms_mrad: f64,
    nominal_peak_mrad: f64,
    calibrated_peak_mrad: f64,
    /// (load N, model, RMS mrad, peak mrad, how it ended) per run
    runs: Vec<Run>,
    /// A 500 Hz `servo` stream (sines on J1, J2, J3, J5, ≤ 0.25 rad/s, 4 s): (load N, model,
    /// RMS mrad, peak mrad, how it ended) of MuJoCo's link angles − the streamed target after
    /// the first second
    stream: Vec<Run>,
}

#[derive(Debug, Serialize)]
struct Outcome {
    floor_mm: f64,
    loads: Vec<LoadRow>,
    tracking: Tracking,
    friction: bool,
    friction_scale: f64,
    friction_model: FrictionModel,
    /// Time from the end of a validation move until the arm was still, mean, s: nominal,
    /// calibrated
    move_settle_mean_s: (f64, f64),
    ring: Option<Ring>,
    /// Faults during the validation (that model's pose skipped, the daemon reset)
    validation_faults: Vec<String>,
    /// Faults while gathering the campaigns (that configuration's rows left out, the daemon
    /// reset): a tool and load the drives cannot follow somewhere
    #[serde(skip_serializing_if = "Vec::is_empty")]
    campaign_faults: Vec<String>,
    /// Per validation pose: the calibrated model's setpoint there (rad) and each model's
    /// (nominal, calibrated[, extended]) position error at 0/45/90 N, mm (`null`: faulted).
    validation_poses_detail: Vec<PoseDetail>,
    /// Why the dynamic runs ended early (a fault the daemon did not recover from), if so
    aborted: Option<String>,
    torque_source: String,
    /// The daemon's `control.hold_deadband`, rad.
    hold_deadband: f64,
    /// The daemon's `control.hold_damping`.
    hold_damping: f64,
    /// The daemon's `control.gain_inertia_kgm2`, kg·m² (0: a constant gain).
    gain_inertia_kgm2: f64,
    identification: Option<Identification>,
    /// With `--discover`: the effects named, in the order added (`pa10 discover --json`'s).
    #[serde(skip_serializing_if = "Option::is_none")]
    discovered: Option<Vec<Found>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    discovery: Option<DiscoverySummary>,
    seed: u64,
    /// The effects the plant hid (`--hide-gear`, `--hide-bearing`, `--hide-bend`,
    /// `--hide-payload`), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    hidden: Option<HiddenEffects>,
    /// `--exact-resolvers`: the plant's resolvers had no repeatable error (a diagnostic run).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    exact_resolvers: bool,
    /// The tool point in the flange frame, m (`--tool`).
    tool_m: [f64; 3],
    calibration_rows: usize,
    validation_poses: usize,
    simulated_s: f64,
    elapsed_s: f64,
    /// Settles (after every move and load change) that ended with the daemon in position,
    /// and all settles: the rest hit the 5 s limit.
    settles_in_position: [usize; 2],
}

/// [`settle`]'s count: settles that ended in position, and all.
static SETTLES: [std::sync::atomic::AtomicUsize; 2] = [
    std::sync::atomic::AtomicUsize::new(0),
    std::sync::atomic::AtomicUsize::new(0),
];

/// What `--identify` found and how close its gravity model came to MuJoCo's.
#[derive(Debug, Serialize)]
struct Identification {
    /// Constant-speed samples the fit used.
    samples: usize,
    /// Simulated time the tour took, s.
    tour_s: f64,
    /// Identified Coulomb friction per joint, N·m.
    coulomb_nm: [f64; 6],
    /// Identified viscous friction per joint, N·m·s/rad.
    viscous_nms: [f64; 6],
    /// Identified breakaway level per joint (the sweeps' starts), N·m; 0 where none.
    breakaway_nm: [f64; 6],
    /// Per joint, RMS over the novel poses at rest at 0 N of the model's gravity torque −
    /// MuJoCo's spring torque, N·m: the nominal masses, the identified ones.
    gravity_rms_nm: [[f64; 6]; 2],
}

fn main() -> Result<()> {
    let o = opts()?;
    if let Some(path) = &o.trace {
        let f =
            std::fs::File::create(path).with_context(|| format!("--trace {}", path.display()))?;
        let mut w = std::io::BufWriter::new(f);
        use std::io::Write;
        writeln!(w, "# {TRACE_HEADER}")?;
        if let Ok(mut g) = TRACE.lock() {
            *g = Some(w);
        }
    }
    let t0 = Instant::now();
    let dir = std::env::temp_dir().join(format!("pa10-mujoco-judge-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = judge(&o, &dir, t0);
    std::fs::remove_dir_all(&dir).ok();
    let out = result?;
    if o.json {
        println!("{}", serde_json::to_string(&out)?);
    } else {
        print(&out);
    }
    if o.check {
        let ratio = o.check_ratio.unwrap_or(if o.quick { 2.0 } else { 1.3 });
        let bad = check(&out, ratio);
        for b in &bad {
            eprintln!("check failed: {b}");
        }
        ensure!(bad.is_empty(), "{} check(s) failed", bad.len());
    }
    Ok(())
}

/// What the judge requires of the daemon (`--check`; the reasons it does not hold): the
/// calibrated model's mean error within `ratio` × the Monte Carlo floor at every load (1.3 on
/// the full run, 2 on the quick one: 8 calibration poses, 2 validation poses), the nominal
/// model three times worse at 90 N, with `--discover` on creeping drives the extended model
/// not worse than the calibrated one (by more than [`EXTENDED_SLACK`] × the floor), neither
/// in placement nor in its own error at rest (`prediction_mean_mm`), on sticking drives not
/// worse pose by pose ([`Paired`]: by more than that slack and [`PAIRED_T`] paired standard
/// errors over at least [`PAIRED_MIN_POSES`] poses), tracking
/// better than nominal, the loaded wrist's ring decaying, and no run ending early.
fn check(o: &Outcome, ratio: f64) -> Vec<String> {
    let mut bad = Vec::new();
    for l in &o.loads {
        if l.calibrated_mean_mm > ratio * o.floor_mm {
            bad.push(format!(
                "{} N: calibrated mean {:.3} mm > {ratio} × the floor {:.3} mm",
                l.load_n, l.calibrated_mean_mm, o.floor_mm
            ));
        }
    }
    for l in o
        .loads
        .iter()
        .filter(|_| o.friction_model == FrictionModel::Creep)
    {
        if let Some(e) = l.extended_mean_mm
            && e > l.calibrated_mean_mm + EXTENDED_SLACK * o.floor_mm
        {
            bad.push(format!(
                "{} N: the extended model's mean {e:.3} mm is worse than the calibrated {:.3} mm",
                l.load_n, l.calibrated_mean_mm
            ));
        }
        // and the models' own error at rest, on creeping drives as the placement: on sticking
        // ones the same model validated twice differs by up to 0.21× the floor at 90 N even
        // there (the torque estimate at rest depends on how the drive arrived; docs/judge.md §9)
        if let [_, c, e] = l.prediction_mean_mm[..]
            && e > c + EXTENDED_SLACK * o.floor_mm
        {
            bad.push(format!(
                "{} N: the extended model's own error at rest {e:.3} mm is worse than the calibrated model's {c:.3} mm",
                l.load_n
            ));
        }
    }
    for l in o
        .loads
        .iter()
        .filter(|_| o.friction_model == FrictionModel::Stick)
    {
        if let Some(p) = l.extended_paired
            && p.poses >= PAIRED_MIN_POSES
            && p.mean_mm > EXTENDED_SLACK * o.floor_mm
            && p.mean_mm > PAIRED_T * p.se_mm
        {
            bad.push(format!(
                "{} N: the extended model places the tool {:.3} ± {:.3} mm worse than the calibrated one, pose by pose over {} poses",
                l.load_n, p.mean_mm, p.se_mm, p.poses
            ));
        }
    }
    if let Some(l) = o.loads.last()
        && l.nominal_mean_mm < 3.0 * l.calibrated_mean_mm
    {
        bad.push(format!(
            "90 N: nominal {:.3} mm is not 3 × calibrated {:.3} mm",
            l.nominal_mean_mm, l.calibrated_mean_mm
        ));
    }
    let t = &o.tracking;
    if t.runs.len() != 4 || t.calibrated_rms_mrad >= t.nominal_rms_mrad {
        bad.push(format!(
            "tracking: calibrated {:.3} mrad RMS vs nominal {:.3} over {} runs",
            t.calibrated_rms_mrad,
            t.nominal_rms_mrad,
            t.runs.len()
        ));
    }
    for r in t.runs.iter().chain(&t.stream) {
        if r.4 != "succeeded" && r.4 != "holding" {
            bad.push(format!("{} at {} N ended: {}", r.1, r.0, r.4));
        }
    }
    match &o.ring {
        Some(r) if r.ended == "holding" && r.last_mrad < 0.5 * r.first_mrad => {}
        other => bad.push(format!("J5's ring-down at 90 N: {other:?}")),
    }
    if let Some(a) = &o.aborted {
        bad.push(format!("ended early: {a}"));
    }
    bad.extend(o.validation_faults.iter().map(|f| format!("fault: {f}")));
    bad.extend(
        o.campaign_faults
            .iter()
            .map(|f| format!("campaign fault: {f}")),
    );
    bad
}

/// `config/sim.yaml` in `dir` beside the nominal model, with `torque_source`.
fn settings(dir: &Path, o: &Opts) -> Result<Settings> {
    std::fs::write(dir.join("model-nominal.yaml"), NOMINAL_YAML)?;
    let text = include_str!("../config/sim.yaml")
        .replace(
            "socket: /tmp/pa10d-sim.sock",
            &format!("socket: {}", dir.join("api.sock").display()),
        )
        .replace("  seed: 1", &format!("  seed: {}", o.seed))
        .replace(
            "torque_source: measured",
            &format!("torque_source: {}", o.torque_source),
        )
        // the demo's margin: a 90 N load on the wrist rings at ≈ 6 Hz after a move (docs/judge.md)
        .replace("following_error: 0.01", "following_error: 0.05")
        .replace(
            "current_filter_hz: 20.0",
            &format!(
                "current_filter_hz: {}\n  hold_deadband: {}\n  hold_damping: {}{}",
                o.filter_hz.unwrap_or(20.0),
                o.hold_deadband,
                o.hold_damping,
                if o.gain_inertia > 0.0 {
                    format!("\n  gain_inertia_kgm2: {}", o.gain_inertia)
                } else {
                    String::new()
                }
            ),
        )
        .replace("log_level: info", "log_level: warn");
    let path = dir.join("pa10d.yaml");
    std::fs::write(&path, text)?;
    Ok(Config::load(&path)?)
}

/// The daemon's core with the simulated controller driving the MuJoCo plant, ready.
fn rig(settings: &Settings, o: &Opts) -> Result<Lockstep> {
    let (truth, seed) = truth_for(settings)?;
    let truth = if o.exact_resolvers {
        truth.with_exact_resolvers()
    } else {
        truth
    };
    let mut plant = PlantConfig {
        kind: PlantKind::Mujoco,
        friction: Some(o.friction),
        friction_model: o.friction_model,
        hidden: o.hidden,
        ..PlantConfig::default()
    };
    if let Some(script) = std::env::var_os("PA10_PLANT") {
        plant.command = Some(vec![
            "python3".into(),
            script.to_string_lossy().into_owned(),
        ]);
    }
    let mo = MujocoOptions::from_config(&plant, o.seed, o.tool, HOME).honouring_pa10_python();
    let plant = MujocoPlant::start(&mo).context(
        "starting the MuJoCo plant (pip install mujoco; PA10_PYTHON names the interpreter)",
    )?;
    let servo = ServoSim::with_plant(truth, ServoConfig::default(), Box::new(plant), seed);
    let mut ls = Lockstep::new(Core::from_config(settings), servo);
    ls.run_until_ready(5.0)
        .map_err(|e| anyhow!("the simulated servo controller: {e}"))?;
    Ok(ls)
}

fn plant_ok(ls: &Lockstep) -> Result<()> {
    match ls.servo.plant().failure() {
        Some(f) => bail!("the MuJoCo plant failed: {f}"),
        None => Ok(()),
    }
}

fn ask(ls: &Lockstep, req: ApiRequest) -> Result<Answer> {
    match ls.call(req) {
        Reply::Ok(a) => Ok(a),
        Reply::Refused(e) => bail!("pa10d refused: {e}"),
    }
}

fn status(ls: &Lockstep) -> Result<Status> {
    match ask(ls, ApiRequest::Status {})? {
        Answer::Status(s) => Ok(*s),
        other => bail!("status answered {other:?}"),
    }
}

/// Sends a move and runs until the daemon holds again and the arm is still ([`settle`]); the
/// time from the end of the move until still, s.
fn move_settle(ls: &mut Lockstep, req: ApiRequest) -> Result<f64> {
    ask(ls, req)?;
    let t0 = ls.now();
    let end = t0 + 60.0;
    loop {
        ls.run_for(0.01);
        plant_ok(ls)?;
        let s = status(ls)?;
        trace_row(
            ls,
            "move",
            ls.now() - t0,
            &s.q_motor,
            &ls.servo.link_state().0,
            &s,
        );
        match s.state {
            State::Holding => break,
            State::Fault => bail!("fault: {}", s.fault.unwrap_or_default()),
            _ if ls.now() > end => bail!("the move did not settle in 60 s"),
            _ => {}
        }
    }
    settle(ls)
}

/// Runs until the daemon says the arm is in position (`status.in_position`: a sticking drive
/// can be winding up to break away, hundreds of µrad from its target, while every resolver is
/// still) and neither a resolver (by more than 1.5 counts) nor a MuJoCo link (by more than
/// 10 µrad) moves over 10 ms three times running, 0.1…5 s: the springs ring after a move or a
/// load change, and a link can ring while the motors are held still — the instrument waits
/// for the tool to stop, as a lab's does. Returns the time it took, s.
fn settle(ls: &mut Lockstep) -> Result<f64> {
    const COUNT: f64 = std::f64::consts::TAU / (16384.0 * 50.0);
    const LINK_STILL: f64 = 1e-5;
    let t = ls.now();
    let mut last = (status(ls)?.q_motor, ls.servo.link_state().0);
    let mut still = 0;
    loop {
        ls.run_for(0.01);
        plant_ok(ls)?;
        let st = status(ls)?;
        if st.state == State::Fault {
            bail!("fault: {}", st.fault.unwrap_or_default());
        }
        let now = (st.q_motor, ls.servo.link_state().0);
        trace_row(ls, "still", ls.now() - t, &now.0, &now.1, &st);
        let step =
            |a: &[f64; 6], b: &[f64; 6]| (0..6).map(|j| (a[j] - b[j]).abs()).fold(0.0, f64::max);
        let quiet = st.in_position
            && step(&now.0, &last.0) <= 1.5 * COUNT
            && step(&now.1, &last.1) <= LINK_STILL;
        still = if quiet { still + 1 } else { 0 };
        last = now;
        let waited = ls.now() - t;
        if (waited >= 0.1 && still >= 3) || waited >= 5.0 {
            SETTLES[0].fetch_add(usize::from(st.in_position), Ordering::Relaxed);
            SETTLES[1].fetch_add(1, Ordering::Relaxed);
            return Ok(waited);
        }
    }
}

/// `--trace`'s file: one CSV row per 10 ms of every move and settle ([`TRACE_HEADER`]), and
/// a row naming each load change.
const TRACE_HEADER: &str = "phase,t_s,motor1..6_rad,link1..6_rad (MuJoCo),setpoint1..6_rad,target1..6_rad (the daemon's motor target),tau1..6_nm (the torques the compensation used)";

static TRACE: std::sync::Mutex<Option<std::io::BufWriter<std::fs::File>>> =
    std::sync::Mutex::new(None);

fn trace_row(ls: &Lockstep, phase: &str, t: f64, motor: &[f64; 6], link: &[f64; 6], st: &Status) {
    use std::io::Write;
    let Ok(mut g) = TRACE.lock() else { return };
    let Some(w) = g.as_mut() else { return };
    let target = pa10::daemon::runtime::lock(&ls.core)
        .controller()
        .map(|c| c.output().target)
        .unwrap_or_default();
    let cells: Vec<String> = std::iter::once(t)
        .chain(motor.iter().copied())
        .chain(link.iter().copied())
        .chain(st.setpoint.iter().copied())
        .chain(target.iter().copied())
        .chain(st.tau.iter().copied())
        .map(|v| format!("{v:.9}"))
        .collect();
    let _ = writeln!(w, "{phase},{}", cells.join(","));
    let _ = w.flush();
}

/// After a run that may have faulted: `reset` when faulted, then until the daemon is ready;
/// what the fault was, if there was one.
fn recover(ls: &mut Lockstep) -> Result<Option<String>> {
    let st = status(ls)?;
    if st.state == State::Holding {
        return Ok(None);
    }
    let fault = st.fault.or(Some(format!("{:?}", st.state)));
    // the controller stops the arm and closes the brakes; the links ring down on the springs
    ls.run_for(5.0);
    // a reset restarts the session with the controller; the first may find it still in
    // control mode (it held the arm while the daemon was faulted) and fault again
    for _ in 0..3 {
        if status(ls)?.state == State::Fault {
            ask(ls, ApiRequest::Reset {})?;
        }
        if ls.run_until_ready(10.0).is_ok() {
            ls.run_for(0.2);
            if status(ls)?.state == State::Holding {
                return Ok(fault);
            }
        }
    }
    let speed = ls
        .servo
        .plant()
        .motor_speeds()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    bail!(
        "the daemon did not recover from {fault:?}: the controller is {:?}, its motors still turning at up to {speed:.2} rad/s",
        ls.servo.state()
    )
}

/// Hangs `newtons` on the arm, tells the daemon, waits until it is still; how long that took, s.
fn set_load(ls: &mut Lockstep, newtons: f64) -> Result<f64> {
    ls.servo.set_load(newtons);
    trace_row(
        ls,
        &format!("load {newtons}"),
        0.0,
        &[0.0; 6],
        &[0.0; 6],
        &status(ls)?,
    );
    ask(
        ls,
        ApiRequest::SetPayload {
            newtons: Some(newtons),
            mass_kg: None,
            com: None,
        },
    )?;
    settle(ls)
}

fn judge(o: &Opts, dir: &Path, t0: Instant) -> Result<Outcome> {
    let settings = settings(dir, o)?;
    let kt = settings.control.torque_constants;
    let tool = frame_from_pose(o.tool, [1.0, 0.0, 0.0, 0.0]);
    let nominal = Model::nominal().with_tool(&tool)?;
    let paper = Model::nominal().with_tool(&default_tool())?;
    let mut ls = rig(&settings, o)?;
    let truth = ls.servo.truth().clone();
    // 0. With --identify the identified gravity model and friction are the starting model.
    let (base, mut identification) = if o.identify {
        let (m, i) = identify_through(&mut ls, &nominal, kt, o).context("identification")?;
        (m, Some(i))
    } else {
        (nominal.clone(), None)
    };
    let mut rng = Pcg64::seed_from_u64(o.seed ^ 0x3d0c);
    let repeats = 2;

    // 1. The calibration campaign through the daemon (quick: the 8 corner poses).
    let poses: Vec<(String, Frame)> = grid_poses()
        .into_iter()
        .filter(|(id, _)| !o.quick || !id[1..].contains('1'))
        .collect();
    let mut reference = HOME;
    let mut configs = Vec::new();
    for (id, target) in &poses {
        reference = campaign_config(&nominal, &paper, target, &reference)
            .map_err(|e| anyhow!("pose {id}: {e}"))?;
        configs.push((id.clone(), reference));
    }
    let mut campaign_faults = Vec::new();
    let (rows, mut exact_q) = gather(
        &mut ls,
        &configs,
        &CAL_LOADS,
        repeats,
        &mut rng,
        &mut campaign_faults,
    )?;
    let mut data = Dataset {
        rows,
        ..Dataset::default()
    };
    // 1a. `--extra-configs`: drawn, reached and read on their own stream (so the validation
    //     poses, drawn from `rng` later, are those of a run without them).
    if o.extra_configs > 0 {
        let mut crng = Pcg64::seed_from_u64(o.seed ^ 0xca1b);
        let mut extra = Vec::with_capacity(o.extra_configs);
        while extra.len() < o.extra_configs {
            let t = random_pose(&mut crng, [0.45, -0.2, -0.05], [0.70, 0.2, 0.25]);
            // `--extra-flipped`: every other one with the wrist flipped (J4 + π, −J5, J6 + π)
            let flip = o.extra_flipped && extra.len() % 2 == 1;
            let near = if flip {
                Model::other_wrist_reference(&reference)
            } else {
                reference
            };
            if let Ok(q) = campaign_config(&nominal, &paper, &t, &near) {
                if !flip {
                    reference = q;
                }
                extra.push((format!("c{}", extra.len() + 1), q));
            }
        }
        let (rows, exact) = gather(
            &mut ls,
            &extra,
            &CAL_LOADS,
            repeats,
            &mut crng,
            &mut campaign_faults,
        )
        .context("the extra configurations")?;
        data.rows.extend(rows);
        exact_q.extend(exact);
    }
    data.meta = Some(Meta {
        inner_configs: Some(
            poses
                .iter()
                .map(|(id, _)| id.clone())
                .filter(|id| !id[1..].contains('1'))
                .collect(),
        ),
        ..sidecar(
            format!("MuJoCo plant (seed {}) through pa10d", o.seed),
            &tool,
            &truth.noise,
        )
    });

    // 1b. With --discover, a held-out campaign through the daemon as a lab gathers it: novel
    //     configurations at the validation loads (its own random stream, so the validation
    //     poses are those of a run without it).
    let holdout = if o.discover {
        let mut hrng = Pcg64::seed_from_u64(o.seed ^ 0x401d);
        let configs = novel_configs(&nominal, if o.quick { 4 } else { 10 }, &mut hrng);
        Some(Dataset {
            rows: gather(
                &mut ls,
                &configs,
                &VAL_LOADS,
                repeats,
                &mut hrng,
                &mut campaign_faults,
            )
            .context("the held-out campaign")?
            .0,
            meta: Some(sidecar(
                format!("MuJoCo plant (seed {}) through pa10d, held out", o.seed),
                &tool,
                &truth.noise,
            )),
        })
    } else {
        None
    };

    // 2. Calibrate: the full model and the nominal model placed.
    let copts = CalibOptions {
        torque_constants: Some(kt),
        starts: 2,
        seed: o.seed,
        ..Default::default()
    };
    // With the daemon's torques from the model, the fit's too (the currents carry friction):
    // `pa10 calibrate --model-torques`, at the links' angles.
    let model_torques = ["model", "estimated"].contains(&o.torque_source.as_str());
    let raw = data;
    let data =
        as_fitted(&base, &raw, model_torques, &copts).context("the campaign's model torques")?;
    if let Some(k) = &o.keep {
        std::fs::create_dir_all(k).with_context(|| format!("--keep {}", k.display()))?;
        data.save(k.join("campaign.csv"))?;
        base.save(k.join("identified.yaml"))?;
    }
    let full = calibrate(&base, &data, None, &copts, &|_| {})?.model;
    let placed = fit_base_only(&base, &data, None, &copts)?;
    // 2b. `pa10 discover --model-torques` from the calibrated model with the held-out
    //     campaign (both sets' torques at the calibrated model's link angles).
    let discovery = match &holdout {
        Some(h) => {
            let (data, h) = if model_torques {
                (
                    raw.with_model_torques(&full)
                        .context("the campaign's model torques")?,
                    h.with_model_torques(&full)
                        .context("the held-out campaign's model torques")?,
                )
            } else {
                (data.clone(), h.clone())
            };
            if let Some(k) = &o.keep {
                h.save(k.join("heldout.csv"))?;
            }
            let t = Instant::now();
            let dopts = DiscoverOptions {
                torque_constants: Some(kt),
                seed: o.seed,
                ..Default::default()
            };
            let mut d = discover(&full, &data, Some(&h), &dopts).context("pa10 discover")?;
            if o.recalibrate && !d.effects.is_empty() {
                // `pa10 calibrate --model extended.yaml --model-torques`
                let data = as_fitted(&d.model, &raw, model_torques, &copts)
                    .context("the extended model's torques")?;
                d.model = calibrate(&d.model, &data, None, &copts, &|_| {})
                    .context("recalibrating the extended model")?
                    .model;
            }
            Some((d, t.elapsed().as_secs_f64(), h.rows.len()))
        }
        None => None,
    };
    // 2c. The judge's diagnosis only (it knows the plant's motor angles): the extended model
    //     fitted again, its named effects held, to the campaign as exact resolvers would have
    //     read it — what its own error is once the resolvers' error at the campaign's poses
    //     no longer enters the fit (`Miss`).
    let twin = match &discovery {
        Some((d, _, _)) => {
            let mut exact = raw.clone();
            for (row, q) in exact.rows.iter_mut().zip(&exact_q) {
                row.q = *q;
            }
            let exact = as_fitted(&d.model, &exact, model_torques, &copts)
                .context("the exact-resolver campaign's model torques")?;
            Some(
                calibrate(&d.model, &exact, None, &copts, &|_| {})
                    .context("fitting the extended model to the exact-resolver campaign")?
                    .model,
            )
        }
        None => None,
    };

    // 3. Novel poses (instrument frame) at 0/45/90 N, each model loaded into the daemon.
    let n_val = o.validation_poses.unwrap_or(if o.quick { 2 } else { 6 });
    let targets: Vec<Frame> = (0..n_val)
        .map(|_| placed.base_from_instrument().inverse() * novel_pose(&nominal, &mut rng).0)
        .collect();
    let truth_base = *truth.model.base_from_instrument();
    let mut named: Vec<(&str, &Model)> = vec![("nominal", &placed), ("calibrated", &full)];
    if let Some((d, _, _)) = &discovery {
        named.push(("extended", &d.model));
    }
    let mut paths = Vec::new();
    for (name, m) in &named {
        let path = dir.join(format!("{name}.yaml"));
        m.save(&path)?;
        if let Some(k) = &o.keep {
            m.save(k.join(format!("{name}.yaml")))?;
        }
        paths.push(path);
    }
    // errs[model][load]: position errors, mm
    let mut errs = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    let mut predicted = errs.clone();
    let mut predicted_true = errs.clone();
    let mut predicted_exact = errs.clone();
    let mut deflection = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    let mut resolver_share = errs.clone();
    let mut torque_error = deflection.clone();
    let mut parts: Vec<Vec<Vec<Parts>>> = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    let mut rest = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    let mut settle_s = vec![vec![Vec::new(); VAL_LOADS.len()]; named.len()];
    let mut move_settle_s = vec![Vec::new(); named.len()];
    let mut faults = Vec::new();
    let mut val_q = Vec::new();
    // (link angles rad, MuJoCo's spring torques N·m) at rest at 0 N
    let mut at_rest = Vec::new();
    let mut detail = Vec::with_capacity(targets.len());
    for (k, target) in targets.iter().enumerate() {
        let mut d = PoseDetail {
            setpoint_rad: None,
            error_mm: vec![None; named.len()],
            exact_mm: vec![[None; 3]; named.len()],
            sigma_mm: vec![None; named.len()],
        };
        // one approach for every model: from the first model's solution where the arm is now
        // (an unreachable pose keeps the default; the first model's move says why)
        let approach = placed
            .ik_nearest(
                &(placed.base_from_instrument() * target),
                &status(&ls)?.setpoint,
            )
            .map_or(APPROACH_OFFSET, |q| approach_offset(&q, placed.limits()));
        for (mi, (name, m)) in named.iter().enumerate() {
            let path = paths[mi].display().to_string();
            ask(&ls, ApiRequest::LoadModel { path })
                .with_context(|| format!("validation pose {}: loading the {name} model", k + 1))?;
            // the calibrated and extended models take the loads in the same order
            let reversed = mi >= 1;
            let twin = twin.as_ref().filter(|_| mi == 2);
            match validate_pose(&mut ls, m, twin, target, &approach, &truth_base, reversed) {
                Ok(v) => {
                    move_settle_s[mi].push(v.after_move_s);
                    if mi == 1 {
                        val_q.push(v.setpoint);
                        d.setpoint_rad = Some(v.setpoint);
                    }
                    d.error_mm[mi] = Some(v.error_mm);
                    // the model alone (MuJoCo's motor angles and torques), the resolvers' share
                    // and the model with MuJoCo's torques, from the split
                    let exact = v.part_mm(|p| p[3]);
                    let share = v.part_mm(|p| p[2]);
                    let with_true = v.part_mm(|p| p[2] + p[3]);
                    d.exact_mm[mi] = exact;
                    d.sigma_mm[mi] = v.sigma_mm;
                    at_rest.extend(v.rest0);
                    for l in 0..VAL_LOADS.len() {
                        errs[mi][l].push(v.error_mm[l]);
                        predicted[mi][l].push(v.predicted_mm[l]);
                        predicted_true[mi][l].extend(with_true[l]);
                        predicted_exact[mi][l].extend(exact[l]);
                        deflection[mi][l].extend(v.deflection_error_mrad[l]);
                        resolver_share[mi][l].extend(share[l]);
                        torque_error[mi][l].extend(v.torque_error_nm[l]);
                        parts[mi][l].extend(v.parts_mm[l]);
                        rest[mi][l].push(v.rest_mrad[l]);
                        settle_s[mi][l].push(v.settle_s[l]);
                    }
                }
                Err(e) => {
                    // a fault (the loop ringing up): said, recovered from, this pose skipped
                    faults.push(format!(
                        "validation pose {} with the {name} model: {e:#}",
                        k + 1
                    ));
                    recover(&mut ls)?;
                }
            }
        }
        detail.push(d);
    }
    set_load(&mut ls, 0.0)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let peak = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    // per model that has values at load `l` (the plant says its springs): their mean
    let reported = |v: &[Vec<Vec<f64>>], l: usize| {
        v.iter()
            .filter(|p| !p[l].is_empty())
            .map(|p| mean(&p[l]))
            .collect()
    };
    // per model that has values at load `l`, per joint: `post` of the mean of `pre`
    let per_joint =
        |v: &[Vec<Vec<[f64; 6]>>], l: usize, pre: fn(f64) -> f64, post: fn(f64) -> f64| {
            v.iter()
                .filter(|d| !d[l].is_empty())
                .map(|d| {
                    let n = d[l].len() as f64;
                    std::array::from_fn(|j| post(d[l].iter().map(|x| pre(x[j])).sum::<f64>() / n))
                })
                .collect()
        };
    let floor_mm =
        pa10::accuracy::floor_at(&full, &val_q, truth.noise.resolver_rad, 20_000, o.seed) * 1e3;
    let loads = VAL_LOADS
        .iter()
        .enumerate()
        .map(|(l, &load_n)| LoadRow {
            load_n,
            nominal_mean_mm: mean(&errs[0][l]),
            calibrated_mean_mm: mean(&errs[1][l]),
            nominal_peak_mm: peak(&errs[0][l]),
            calibrated_peak_mm: peak(&errs[1][l]),
            nominal_rest_mrad: mean(&rest[0][l]),
            calibrated_rest_mrad: mean(&rest[1][l]),
            settle_mean_s: mean(&settle_s[1][l]),
            extended_mean_mm: errs.get(2).map(|e| mean(&e[l])),
            extended_peak_mm: errs.get(2).map(|e| peak(&e[l])),
            prediction_mean_mm: predicted.iter().map(|p| mean(&p[l])).collect(),
            prediction_true_torque_mean_mm: reported(&predicted_true, l),
            resolver_share_mean_mm: reported(&resolver_share, l),
            deflection_error_mrad: per_joint(&deflection, l, |x| x, |m| m),
            torque_error_rms_nm: per_joint(&torque_error, l, |x| x * x, f64::sqrt),
            prediction_exact_mean_mm: reported(&predicted_exact, l),
            servo_mean_mm: parts
                .iter()
                .filter(|p| !p[l].is_empty())
                .map(|p| mean(&p[l].iter().map(|x| x[0].norm()).collect::<Vec<_>>()))
                .collect(),
            extended_paired: (named.len() > 2)
                .then(|| {
                    let at = |mi: usize| -> Vec<Option<f64>> {
                        detail
                            .iter()
                            .map(|d| d.error_mm[mi].map(|e| e[l]))
                            .collect()
                    };
                    paired(&at(1), &at(2))
                })
                .flatten(),
            extended_miss: parts.get(2).and_then(|p| miss(&p[l], floor_mm)),
        })
        .collect();
    if let Some(i) = identification.as_mut() {
        let g = nominal.gravity();
        let none = pa10::model::ExternalLoad::hung(0.0, &g);
        for (k, m) in [&nominal, &base].into_iter().enumerate() {
            for j in 0..6 {
                let ss: f64 = at_rest
                    .iter()
                    .map(|(q, tau)| (m.static_torques(q, &none)[j] - tau[j]).powi(2))
                    .sum();
                i.gravity_rms_nm[k][j] = (ss / at_rest.len().max(1) as f64).sqrt();
            }
        }
    }

    // 4. Tracking of the six-point trajectory and a 500 Hz stream at 0 and 90 N; 5. the
    //    loaded wrist's ring-down. A run the daemon cannot come back from ends the judge
    //    there, said in `aborted` (the numbers before it stand).
    let (mut runs, mut streams, mut ring) = (Vec::new(), Vec::new(), None);
    let aborted = dynamics(
        &mut ls,
        &named[..2],
        &paths[..2],
        &mut runs,
        &mut streams,
        &mut ring,
    )
    .err()
    .map(|e| format!("{e:#}"));
    let pick = |name: &str, f: fn(&Run) -> f64| {
        runs.iter()
            .filter(|r| r.1 == name)
            .map(f)
            .fold(0.0, f64::max)
    };
    let tracking = Tracking {
        nominal_rms_mrad: pick("nominal", |r| r.2),
        calibrated_rms_mrad: pick("calibrated", |r| r.2),
        nominal_peak_mrad: pick("nominal", |r| r.3),
        calibrated_peak_mrad: pick("calibrated", |r| r.3),
        runs,
        stream: streams,
    };
    Ok(Outcome {
        floor_mm,
        loads,
        tracking,
        friction: o.friction > 0.0,
        friction_scale: o.friction,
        friction_model: o.friction_model,
        move_settle_mean_s: (mean(&move_settle_s[0]), mean(&move_settle_s[1])),
        ring,
        validation_faults: faults,
        campaign_faults,
        validation_poses_detail: detail,
        aborted,
        torque_source: o.torque_source.clone(),
        hold_deadband: o.hold_deadband,
        hold_damping: o.hold_damping,
        gain_inertia_kgm2: o.gain_inertia,
        identification,
        discovered: discovery.as_ref().map(|(d, _, _)| d.effects.clone()),
        discovery: discovery.map(|(d, secs, rows)| DiscoverySummary {
            verdict: d.verdict,
            gap_closed: d.gap_closed,
            heldout_rows: rows,
            heldout_before_mm: d.gap_before_mm,
            heldout_after_mm: d.gap_after_mm,
            noise_floor_mm: d.noise_floor_mm,
            elapsed_s: secs,
        }),
        seed: o.seed,
        hidden: o.hidden,
        exact_resolvers: o.exact_resolvers,
        tool_m: o.tool,
        calibration_rows: data.rows.len(),
        validation_poses: targets.len(),
        simulated_s: ls.now(),
        elapsed_s: t0.elapsed().as_secs_f64(),
        settles_in_position: SETTLES.each_ref().map(|c| c.load(Ordering::Relaxed)),
    })
}

/// A random tool pose in the validation volume (base frame) that the nominal model reaches
/// from an elbow-up reference, and those joint angles (rad): drawn until one is reachable.
fn novel_pose(nominal: &Model, rng: &mut Pcg64) -> (Frame, [f64; 6]) {
    loop {
        let t = random_pose(rng, [0.40, -0.25, -0.10], [0.75, 0.25, 0.30]);
        let p = t.translation.vector;
        let reference = [p.y.atan2(p.x), 0.3, 1.6, 0.0, 1.1, 0.0];
        if let Ok(q) = nominal.ik_nearest(&t, &reference) {
            return (t, q);
        }
    }
}

/// A calibration campaign's configuration (joint angles, rad) for `target` (the tool's pose in
/// the base frame, pointing down as the paper's grid): `nominal`'s inverse kinematics with the
/// mounted tool nearest `reference`, else — a tool that cannot reach it pointing down, a long
/// or tilted one — the configuration `paper` (the paper's 0.35 m tool) has there: the arm takes
/// the paper's pose and the instrument measures the mounted tool wherever it then is.
fn campaign_config(
    nominal: &Model,
    paper: &Model,
    target: &Frame,
    reference: &[f64; 6],
) -> Result<[f64; 6], IkError> {
    nominal
        .ik_nearest(target, reference)
        .or_else(|_| paper.ik_nearest(target, reference))
}

/// The campaign `raw` as the fit sees it from `model`: where the daemon's torques come from
/// the model, the model's torques at the links' angles (`pa10 calibrate --model-torques`; the
/// currents carry friction), else as gathered.
fn as_fitted(
    model: &Model,
    raw: &Dataset,
    model_torques: bool,
    copts: &CalibOptions,
) -> Result<Dataset> {
    Ok(if model_torques {
        settled_model_torques(model, raw, None, copts)?.0
    } else {
        raw.clone()
    })
}

/// `n` novel configurations (ids `H1`…) of [`novel_pose`].
fn novel_configs(nominal: &Model, n: usize, rng: &mut Pcg64) -> Vec<(String, [f64; 6])> {
    (1..=n)
        .map(|k| (format!("H{k}"), novel_pose(nominal, rng).1))
        .collect()
}

/// A campaign gathered through the daemon as a lab does: each of `configs` (joint angles, rad)
/// reached, then at each of `loads` (N; every other configuration in reverse order) `repeats`
/// stationary measurements one after the other, each over its share of [`OBSERVE_S`]: the
/// means of the motor angles and currents the daemon reads beside the instrument's reading of
/// MuJoCo's mean tool pose (with the drawn instrument noise) — as a tracker takes a stationary
/// point and `pa10 collect` averages a still phase. One instant of a link still ringing on
/// stuck drives is not where the arm rests (docs/judge.md §9, eleventh session). Returns the
/// rows and, per row, MuJoCo's motor angles (rad): what exact resolvers would have read. A
/// fault at a configuration (a drive that cannot follow a heavy tool's swing: a following
/// error) is recovered from and said in `faults`, and that configuration's rows are left out,
/// as a lab re-homes and carries on; a fault the daemon does not recover from, or an error
/// that is not a fault, is an error.
fn gather(
    ls: &mut Lockstep,
    configs: &[(String, [f64; 6])],
    loads: &[f64],
    repeats: usize,
    rng: &mut Pcg64,
    faults: &mut Vec<String>,
) -> Result<(Vec<Row>, Vec<[f64; 6]>)> {
    let truth = ls.servo.truth().clone();
    let (mut rows, mut exact) = (Vec::new(), Vec::new());
    for (n, (id, q)) in configs.iter().enumerate() {
        let mut order = loads.to_vec();
        if n % 2 == 1 {
            order.reverse();
        }
        let mut at = Vec::with_capacity(order.len() * repeats);
        let reached = (|| -> Result<()> {
            move_settle(ls, ApiRequest::MoveJoints { q: *q }).context("the move")?;
            for &load in &order {
                set_load(ls, load).with_context(|| format!("at {load} N"))?;
                for _ in 0..repeats {
                    at.push((load, observe_for(ls, OBSERVE_S / repeats as f64)?));
                }
            }
            Ok(())
        })();
        if let Err(e) = reached {
            // a fault is recovered from and said; any other error (the plant gone, a refusal
            // while holding) ends the run as before
            if recover(ls)
                .with_context(|| format!("pose {id}: {e:#}"))?
                .is_none()
            {
                return Err(e.context(format!("pose {id}")));
            }
            faults.push(format!("pose {id}: {e:#}"));
            continue;
        }
        for (load, o) in at {
            rows.push(Row {
                config_id: id.clone(),
                load_n: load,
                q: o.q_motor,
                effort: Effort::Current(o.current),
                pose: truth.observe_pose(&o.tool, rng),
                direction: [0; 6],
                temperature_c: None,
                line: 0,
            });
            exact.push(o.motor);
        }
    }
    Ok((rows, exact))
}

/// `pa10 identify`'s tour through the daemon (6 waypoints quick, 10 full): the nominal model
/// with the identified bodies and friction.
fn identify_through(
    ls: &mut Lockstep,
    nominal: &Model,
    kt: [f64; 6],
    o: &Opts,
) -> Result<(Model, Identification)> {
    let t = ls.now();
    let plan = SweepPlan {
        waypoints: if o.quick { 6 } else { 10 },
        seed: o.seed,
        ..SweepPlan::default()
    };
    let run = sweep::identify_through(ls, nominal, &kt, &plan, &sweep::DEFAULT_SPEEDS)?;
    let (samples, id, model) = (run.samples, run.identified, run.model);
    let i = Identification {
        samples: samples.len(),
        tour_s: ls.now() - t,
        coulomb_nm: id.friction.map(|f| f.coulomb),
        breakaway_nm: id.friction.map(|f| f.breakaway.unwrap_or(0.0)),
        viscous_nms: id.friction.map(|f| f.viscous),
        gravity_rms_nm: [[0.0; 6]; 2],
    };
    Ok((model, i))
}

type Run = (f64, String, f64, f64, String);

/// Phases 4 and 5 of [`judge`]: what each measured goes into `runs`, `streams`, `ring`.
fn dynamics(
    ls: &mut Lockstep,
    named: &[(&str, &Model)],
    paths: &[PathBuf],
    runs: &mut Vec<Run>,
    streams: &mut Vec<Run>,
    ring: &mut Option<Ring>,
) -> Result<()> {
    for load in [0.0, 90.0] {
        for (mi, (name, _)) in named.iter().enumerate() {
            let what = format!("at {load} N with the {name} model");
            let path = paths[mi].display().to_string();
            ask(ls, ApiRequest::LoadModel { path }).with_context(|| what.clone())?;
            move_settle(ls, ApiRequest::MoveJoints { q: HOME }).with_context(|| what.clone())?;
            set_load(ls, load)?;
            let (rms, pk, ended) = track(ls).with_context(|| format!("tracking {what}"))?;
            runs.push((load, name.to_string(), rms, pk, ended));
            recover(ls).with_context(|| format!("after tracking {what}"))?;
            move_settle(ls, ApiRequest::MoveJoints { q: HOME }).with_context(|| what.clone())?;
            let (rms, pk) = stream(ls).with_context(|| format!("the stream {what}"))?;
            let ended = recover(ls)
                .with_context(|| format!("after the stream {what}"))?
                .unwrap_or_else(|| "holding".into());
            streams.push((load, name.to_string(), rms, pk, ended));
        }
    }
    let path = paths[1].display().to_string();
    ask(ls, ApiRequest::LoadModel { path })?;
    move_settle(ls, ApiRequest::MoveJoints { q: HOME }).context("the ring-down: to HOME")?;
    set_load(ls, 90.0)?;
    *ring = Some(ring_down(ls).context("the ring-down")?);
    recover(ls).context("after the ring-down")?;
    set_load(ls, 0.0)?;
    Ok(())
}

/// J5's link after a 0.2 rad move of J5 at [`HOME`] with 90 N at the tool (calibrated model).
#[derive(Debug, Serialize)]
struct Ring {
    /// Time from holding until the daemon said in position (at most [`RING_WAIT_S`]), s.
    in_position_after_s: f64,
    /// Dominant frequency of MuJoCo's J5 link − setpoint after the move (zero crossings), Hz.
    freq_hz: f64,
    /// Its amplitude (half peak-to-peak) in the first and the last half second of 4 s, mrad.
    first_mrad: f64,
    last_mrad: f64,
    /// How the 4 s ended: "holding" or the daemon's fault.
    ended: String,
}

/// Runs the arm a cycle at a time until `done` says so of the daemon's status, it faults, or
/// `secs` (s) have passed.
fn run_until(ls: &mut Lockstep, secs: f64, done: fn(&Status) -> bool) -> Result<()> {
    let end = ls.now() + secs;
    loop {
        let st = status(ls)?;
        if done(&st) || st.state == State::Fault || ls.now() >= end {
            return Ok(());
        }
        ls.run_for(PERIOD_S);
    }
}

/// How long the ring-down waits after the move for the daemon's in position, s.
const RING_WAIT_S: f64 = 10.0;

/// Moves J5 by 0.2 rad and, once the daemon holds and says in position, records MuJoCo's J5
/// link − the daemon's setpoint every cycle for 4 s.
fn ring_down(ls: &mut Lockstep) -> Result<Ring> {
    let mut q = HOME;
    q[4] += 0.2;
    ask(ls, ApiRequest::MoveJoints { q })?;
    run_until(ls, 30.0, |st| st.state == State::Holding)?;
    // from where `pa10 move --wait` would measure: in position (a stuck drive off its target
    // is broken away by the hold loop first, and each slip excites the link mode anew)
    let holding = ls.now();
    run_until(ls, RING_WAIT_S, |st| st.in_position)?;
    let in_position_after_s = ls.now() - holding;
    let mut e = Vec::with_capacity(2000);
    let mut ended = "holding".to_string();
    for _ in 0..2000 {
        ls.run_for(PERIOD_S);
        plant_ok(ls)?;
        let st = status(ls)?;
        if st.state == State::Fault {
            ended = st.fault.unwrap_or_default();
            break;
        }
        e.push((ls.servo.link_state().0[4] - st.setpoint[4]) * 1e3);
    }
    let half = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(*x), b.max(*x))
            });
        if v.is_empty() { 0.0 } else { 0.5 * (hi - lo) }
    };
    let n = e.len();
    let mean = e.iter().sum::<f64>() / n.max(1) as f64;
    let crossings = e
        .windows(2)
        .filter(|w| (w[0] - mean).signum() != (w[1] - mean).signum())
        .count();
    Ok(Ring {
        in_position_after_s,
        freq_hz: crossings as f64 / 2.0 / (n.max(1) as f64 * PERIOD_S),
        first_mrad: half(&e[..n.min(250)]),
        last_mrad: half(&e[n.saturating_sub(250)..]),
        ended,
    })
}

/// One model at one novel pose: what [`validate_pose`] measured.
struct PoseResult {
    after_move_s: f64,
    setpoint: [f64; 6],
    /// Per load of [`VAL_LOADS`]: position error mm, link − setpoint mrad, settling s.
    error_mm: [f64; 3],
    /// Per load: |MuJoCo's tool − the model's prediction at the rest angles|, mm.
    predicted_mm: [f64; 3],
    /// Per load: the model's joint deflection − MuJoCo's, mrad (when the plant says its springs).
    deflection_error_mrad: [Option<[f64; 6]>; 3],
    /// Per load: the daemon's joint torques at rest − MuJoCo's spring torques, N·m.
    torque_error_nm: [Option<[f64; 6]>; 3],
    /// Per load: the placement error's parts ([`Parts`]; when the plant says its springs), mm:
    /// the prediction with MuJoCo's spring torques misses MuJoCo's tool by the resolvers' and
    /// the model's parts, from MuJoCo's motor angles too by the model's alone.
    parts_mm: [Option<Parts>; 3],
    rest_mrad: [f64; 3],
    settle_s: [f64; 3],
    /// At rest at 0 N: MuJoCo's link angles, rad, and spring torques, N·m (when it says them).
    rest0: Option<([f64; 6], [f64; 6])>,
    /// At rest at 0 N: the daemon's `position_sigma_mm`.
    sigma_mm: Option<f64>,
}

impl PoseResult {
    /// Per load: |what `pick` takes of the split| (mm), when the plant said its springs.
    fn part_mm(&self, pick: fn(&Parts) -> nalgebra::Vector3<f64>) -> [Option<f64>; 3] {
        self.parts_mm.map(|p| p.map(|p| pick(&p).norm()))
    }
}

/// Every joint's offset of the approach configuration from a validation pose's, rad: each
/// model reaches each pose by the same move (a stuck drive rests where its path left it, so
/// two models approaching from each other's resting places would not be compared alike).
const APPROACH_OFFSET: [f64; 6] = [0.05, 0.05, -0.05, 0.05, 0.05, 0.05];

/// How far inside its limits an approach keeps every joint, rad: the models' solutions of one
/// pose differ by milliradians, so one pose's approach is decided once for all of them.
const APPROACH_MARGIN: f64 = 0.02;

/// The approach offsets (rad) of a pose whose joint angles are `q` (rad; any model's): each of
/// [`APPROACH_OFFSET`], turned to the other side where it would take its joint within
/// [`APPROACH_MARGIN`] of a limit (a wrist roll near ±255° with an off-axis tool: the daemon
/// refuses a target beyond the limit, and the pose would be lost to every model).
fn approach_offset(q: &[f64; 6], limits: &JointLimits) -> [f64; 6] {
    std::array::from_fn(|j| {
        let off = APPROACH_OFFSET[j];
        let beyond = q[j] + off > limits.upper[j] - APPROACH_MARGIN
            || q[j] + off < limits.lower[j] + APPROACH_MARGIN;
        if beyond { -off } else { off }
    })
}

/// Moves to the approach configuration of `target` (its inverse kinematics on `model` plus
/// `approach`, the pose's [`approach_offset`]), then to `model`'s estimate of `target`
/// (instrument frame), and measures it at 0/45/90 N (in reverse order when `reversed`) by
/// MuJoCo's tool pose; any fault is an error. `twin`: the same model fitted to the campaign
/// as exact resolvers would have read it, whose own error the split's fifth part is
/// ([`Parts`]).
fn validate_pose(
    ls: &mut Lockstep,
    model: &Model,
    twin: Option<&Model>,
    target: &Frame,
    approach: &[f64; 6],
    truth_base: &Frame,
    reversed: bool,
) -> Result<PoseResult> {
    let base_target = model.base_from_instrument() * target;
    let q = model
        .ik_nearest(&base_target, &status(ls)?.setpoint)
        .map_err(|e| anyhow!("the validation pose: {e}"))?;
    let approach = std::array::from_fn(|j| q[j] + approach[j]);
    move_settle(ls, ApiRequest::MoveJoints { q: approach }).context("the approach")?;
    let (position, quaternion) = pose_parts(&base_target);
    let after_move_s = move_settle(
        ls,
        ApiRequest::MovePose {
            position,
            quaternion,
        },
    )?;
    let mut r = PoseResult {
        after_move_s,
        setpoint: status(ls)?.setpoint,
        error_mm: [0.0; 3],
        predicted_mm: [0.0; 3],
        deflection_error_mrad: [None; 3],
        torque_error_nm: [None; 3],
        parts_mm: [None; 3],
        rest_mrad: [0.0; 3],
        settle_s: [0.0; 3],
        rest0: None,
        sigma_mm: None,
    };
    let mut order = vec![0, 1, 2];
    if reversed {
        order.reverse();
    }
    for l in order {
        r.settle_s[l] = set_load(ls, VAL_LOADS[l])?;
        let st = status(ls)?;
        r.rest_mrad[l] = rest_mrad(ls, &st);
        if l == 0 {
            r.sigma_mm = st.position_sigma_mm;
        }
        let o = observe(ls)?;
        let got = truth_base.inverse() * o.tool;
        r.error_mm[l] = apart_mm(target, &got);
        let (_, own) = predicted(&o.q_motor, &o.tau, model, VAL_LOADS[l])?;
        r.predicted_mm[l] = apart_mm(&own, &got);
        if let Some(tau) = o.spring {
            let (_, at) = predicted(&o.q_motor, &tau, model, VAL_LOADS[l])?;
            let (link, exact) = predicted(&o.motor, &tau, model, VAL_LOADS[l])?;
            let p = |f: &Frame| f.translation.vector * 1e3;
            let twin_exact = match twin {
                Some(t) => predicted(&o.motor, &tau, t, VAL_LOADS[l])?.1,
                None => exact,
            };
            r.parts_mm[l] = Some([
                p(target) - p(&own),
                p(&own) - p(&at),
                p(&at) - p(&exact),
                p(&exact) - p(&got),
                p(&twin_exact) - p(&got),
            ]);
            r.torque_error_nm[l] = Some(std::array::from_fn(|j| o.tau[j] - tau[j]));
            r.deflection_error_mrad[l] = Some(std::array::from_fn(|j| (link[j] - o.link[j]) * 1e3));
        }
        if l == 0 {
            let plant = ls.servo.plant();
            r.rest0 = plant
                .spring_torques()
                .map(|tau| (plant.link_state().0, tau));
        }
    }
    Ok(r)
}

/// How long the judge observes a pose at rest, s, and how often it samples, s: a laser
/// tracker's stationary measurement averages over a window; a loaded wrist on stuck drives
/// can still ring at its ≈ 6 Hz link mode within [`settle`]'s stillness test (1 mrad/s),
/// ± 1 N·m of spring torque on J2/J3 at 90 N, and one instant of it is not where the arm
/// rests. Three periods of that mode.
const OBSERVE_S: f64 = 0.5;
const OBSERVE_EVERY_S: f64 = 0.01;

/// A pose at rest observed over a window: means of MuJoCo's tool pose (point, and
/// orientation as the normalised mean of its quaternions), motor and link angles (rad) and
/// spring torques (N·m, when the plant says them), and of the daemon's resolver angles (rad),
/// torques (N·m) and motor currents (A).
struct Observed {
    tool: Frame,
    motor: [f64; 6],
    link: [f64; 6],
    spring: Option<[f64; 6]>,
    q_motor: [f64; 6],
    tau: [f64; 6],
    current: [f64; 6],
}

/// Observes the arm at rest for [`OBSERVE_S`] ([`Observed`]); a fault is an error.
fn observe(ls: &mut Lockstep) -> Result<Observed> {
    observe_for(ls, OBSERVE_S)
}

/// Observes the arm at rest for `window_s` seconds, sampled every [`OBSERVE_EVERY_S`]
/// ([`Observed`]); a fault is an error.
fn observe_for(ls: &mut Lockstep, window_s: f64) -> Result<Observed> {
    let n = ((window_s / OBSERVE_EVERY_S).round() as usize).max(1);
    let mut sum = [[0.0; 6]; 6];
    let mut point = nalgebra::Vector3::zeros();
    let mut springs = true;
    let mut tool = ls.servo.true_tool_pose();
    let first = nalgebra::UnitQuaternion::from_rotation_matrix(&tool.rotation);
    let mut quat = nalgebra::Vector4::zeros();
    for k in 0..n {
        if k > 0 {
            ls.run_for(OBSERVE_EVERY_S);
            plant_ok(ls)?;
        }
        let st = status(ls)?;
        if st.state == State::Fault {
            bail!("fault: {}", st.fault.unwrap_or_default());
        }
        let plant = ls.servo.plant();
        let spring = plant.spring_torques();
        springs &= spring.is_some();
        let rows = [
            plant.motor_angles(),
            plant.link_state().0,
            spring.unwrap_or_default(),
            st.q_motor,
            st.tau,
            st.current,
        ];
        for (s, r) in sum.iter_mut().zip(rows) {
            for j in 0..6 {
                s[j] += r[j] / n as f64;
            }
        }
        tool = ls.servo.true_tool_pose();
        point += tool.translation.vector / n as f64;
        // the quaternions on one side of the first's, so that their mean is the mean rotation
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(&tool.rotation).coords;
        quat += if q.dot(&first.coords) < 0.0 { -q } else { q };
    }
    tool.translation.vector = point;
    tool.rotation = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(quat))
        .to_rotation_matrix();
    let [motor, link, spring, q_motor, tau, current] = sum;
    Ok(Observed {
        tool,
        motor,
        link,
        spring: springs.then_some(spring),
        q_motor,
        tau,
        current,
    })
}

/// Where `model` says the tool is now (instrument frame): its link angles from the resolvers'
/// angles `q_motor` (rad) and joint torques `tau` (N·m; the daemon's at rest, or MuJoCo's
/// springs') with backlash centred, through its kinematics with `load_n` (N) hung at the tool.
/// Returns those link angles (rad) and the tool.
fn predicted(
    q_motor: &[f64; 6],
    tau: &[f64; 6],
    model: &Model,
    load_n: f64,
) -> Result<([f64; 6], Frame)> {
    let link = model
        .link_from_motor(q_motor, Torques::Given(tau), &[0.0; 6])
        .map_err(|e| anyhow!("the model's link angles at rest: {e}"))?
        .q_link;
    let tool = model.base_from_instrument().inverse() * model.fk_loaded(&link, load_n);
    Ok((link, tool))
}

/// Distance between the tool points of `a` and `b`, mm.
fn apart_mm(a: &Frame, b: &Frame) -> f64 {
    pose_error(a, b).fixed_rows::<3>(0).norm() * 1e3
}

/// RMS over joints of MuJoCo's link angles − the daemon's setpoint (in `st`), mrad.
fn rest_mrad(ls: &Lockstep, st: &Status) -> f64 {
    let (link, _) = ls.servo.link_state();
    let ss: f64 = (0..6).map(|j| (link[j] - st.setpoint[j]).powi(2)).sum();
    (ss / 6.0).sqrt() * 1e3
}

/// The 0.2 Hz sine stream (`examples/common/tracking.rs`) for 4 s at the cycle rate, then
/// the stream's deadline stops the arm and it comes to rest.
fn stream(ls: &mut Lockstep) -> Result<(f64, f64)> {
    let amp = [0.2, 0.1, -0.1, 0.0, 0.2, 0.0];
    let r = tracking::sine_stream(ls, PERIOD_S, 4.0, amp, plant_ok)?;
    ls.run_for(0.5);
    if status(ls)?.state == State::Holding {
        settle(ls)?;
    }
    Ok(r)
}

/// RMS and peak (mrad) of MuJoCo's link angles − the trajectory's desired positions, every
/// cycle, over all joints, and how the trajectory ended ("succeeded" or the daemon's fault).
fn track(ls: &mut Lockstep) -> Result<(f64, f64, String)> {
    tracking::trajectory(ls, &six_points(), PERIOD_S, 40.0, |l: &Lockstep| {
        plant_ok(l).map_err(|e| e.to_string())
    })
    .map_err(anyhow::Error::msg)
}

fn print(o: &Outcome) {
    println!(
        "MuJoCo judge (plant seed {}, friction ×{} {:?}, torque source {}): {} calibration rows, {} novel poses, {:.0} s simulated in {:.0} s",
        o.seed,
        o.friction_scale,
        o.friction_model,
        o.torque_source,
        o.calibration_rows,
        o.validation_poses,
        o.simulated_s,
        o.elapsed_s
    );
    if o.exact_resolvers {
        println!(
            "Exact resolvers (--exact-resolvers): no repeatable resolver error in the plant; the floor quoted is the specified resolvers'."
        );
    }
    println!(
        "{} of {} settles ended in position (the rest at the 5 s limit).",
        o.settles_in_position[0], o.settles_in_position[1]
    );
    println!(
        "\n| load [N] | nominal mean / peak [mm] | calibrated mean / peak [mm] | MC floor [mm] |"
    );
    println!("|---|---|---|---|");
    for l in &o.loads {
        println!(
            "| {:.0} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} |",
            l.load_n,
            l.nominal_mean_mm,
            l.nominal_peak_mm,
            l.calibrated_mean_mm,
            l.calibrated_peak_mm,
            o.floor_mm
        );
    }
    if let (Some(d), Some(found)) = (&o.discovery, &o.discovered) {
        println!(
            "\npa10 discover from the calibrated model ({} held-out rows, {:.1} s): {}",
            d.heldout_rows, d.elapsed_s, d.verdict
        );
        for f in found {
            let params: Vec<String> = f
                .params
                .iter()
                .map(|(k, v)| {
                    let se = f.stderr.get(k).copied().unwrap_or(f64::NAN);
                    format!("{k} = {v:.3e} ± {se:.1e} {}", f.units.get(k).unwrap_or(&""))
                })
                .collect();
            println!("  named {}: {}", f.label, params.join(", "));
        }
        println!(
            "\n| load [N] | calibrated mean [mm] | extended mean / peak [mm] | MC floor [mm] |"
        );
        println!("|---|---|---|---|");
        for l in &o.loads {
            println!(
                "| {:.0} | {:.3} | {:.3} / {:.3} | {:.3} |",
                l.load_n,
                l.calibrated_mean_mm,
                l.extended_mean_mm.unwrap_or(f64::NAN),
                l.extended_peak_mm.unwrap_or(f64::NAN),
                o.floor_mm
            );
        }
        for l in &o.loads {
            if let Some(p) = l.extended_paired {
                println!(
                    "  {:.0} N, pose by pose: extended − calibrated {:+.3} ± {:.3} mm over {} poses",
                    l.load_n, p.mean_mm, p.se_mm, p.poses
                );
            }
            if let Some(m) = &l.extended_miss {
                println!(
                    "  {:.0} N: the extended model {:.2}× the floor, above {GOAL_RATIO}×: {}",
                    l.load_n, m.ratio, m.says
                );
            }
        }
    }
    println!(
        "\nThe models' own error at rest (MuJoCo's tool − the model's tool at the resolvers' rest angles; without where the servo stopped), mean [mm], nominal / calibrated{}:",
        if o.discovered.is_some() {
            " / extended"
        } else {
            ""
        }
    );
    let per_load = |field: fn(&LoadRow) -> &[f64]| {
        for l in &o.loads {
            let v: Vec<String> = field(l).iter().map(|e| format!("{e:.3}")).collect();
            println!("  {:.0} N: {}", l.load_n, v.join(" / "));
        }
    };
    per_load(|l| &l.prediction_mean_mm);
    if o.loads
        .iter()
        .any(|l| !l.prediction_true_torque_mean_mm.is_empty())
    {
        println!("The same with MuJoCo's spring torques in place of the daemon's, mean [mm]:");
        per_load(|l| &l.prediction_true_torque_mean_mm);
    }
    println!(
        "\nAt rest, MuJoCo's link − the daemon's setpoint (RMS over joints, mean over poses):"
    );
    for l in &o.loads {
        println!(
            "  {:.0} N: nominal {:.3} mrad, calibrated {:.3} mrad; still after {:.2} s",
            l.load_n, l.nominal_rest_mrad, l.calibrated_rest_mrad, l.settle_mean_s
        );
    }
    println!(
        "After a validation move the arm was still in {:.2} s (nominal) / {:.2} s (calibrated), mean.",
        o.move_settle_mean_s.0, o.move_settle_mean_s.1
    );
    if let Some(r) = &o.ring {
        println!(
            "J5 after a 0.2 rad move at 90 N (calibrated): {:.1} Hz, amplitude {:.3} mrad in the first 0.5 s, {:.3} mrad in the last 0.5 s of 4 s ({})",
            r.freq_hz, r.first_mrad, r.last_mrad, r.ended
        );
    }
    if let Some(i) = &o.identification {
        let row = |v: &[f64; 6]| v.map(|x| format!("{x:.2}")).join(" / ");
        println!(
            "\nIdentified through the daemon ({} samples, {:.0} s tour): Coulomb {} N·m, viscous {} N·m·s/rad, breakaway {} N·m",
            i.samples,
            i.tour_s,
            row(&i.coulomb_nm),
            row(&i.viscous_nms),
            row(&i.breakaway_nm)
        );
        println!(
            "Gravity torque − MuJoCo's spring torque at rest, RMS over the novel poses per joint: nominal masses {} N·m, identified {} N·m",
            row(&i.gravity_rms_nm[0]),
            row(&i.gravity_rms_nm[1])
        );
    }
    for f in &o.campaign_faults {
        println!("Campaign fault (the configuration left out): {f}");
    }
    for f in &o.validation_faults {
        println!("Validation fault: {f}");
    }
    if let Some(a) = &o.aborted {
        println!("\nThe dynamic runs ended early: {a}");
    }
    println!("\n| 500 Hz servo stream | load [N] | RMS [mrad] | peak [mrad] | ended |");
    println!("|---|---|---|---|---|");
    for (load, name, rms, pk, ended) in &o.tracking.stream {
        println!("| {name} | {load:.0} | {rms:.3} | {pk:.3} | {ended} |");
    }
    println!("\n| six-point trajectory | load [N] | RMS [mrad] | peak [mrad] | ended |");
    println!("|---|---|---|---|---|");
    for (load, name, rms, pk, ended) in &o.tracking.runs {
        println!("| {name} | {load:.0} | {rms:.3} | {pk:.3} | {ended} |");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn parse(args: &str) -> Result<Opts> {
        opts_from(args.split_whitespace().map(String::from))
    }

    #[test]
    fn a_grid_pose_a_tool_cannot_reach_is_taken_at_the_paper_tools_configuration() {
        let paper = Model::nominal().with_tool(&default_tool()).unwrap();
        let long = Model::nominal()
            .with_tool(&frame_from_pose([0.0, 0.0, 0.5], [1.0, 0.0, 0.0, 0.0]))
            .unwrap();
        let grid = grid_poses();
        let (id, far) = grid.iter().find(|(id, _)| id == "g222").unwrap();
        assert!(long.ik_nearest(far, &HOME).is_err(), "{id} reachable");
        let q = campaign_config(&long, &paper, far, &HOME).unwrap();
        assert_eq!(q, paper.ik_nearest(far, &HOME).unwrap());
        // a pose the mounted tool reaches is its own solution
        let (_, near) = &grid[0];
        let q = campaign_config(&paper, &long, near, &HOME).unwrap();
        assert_eq!(q, paper.ik_nearest(near, &HOME).unwrap());
    }

    #[test]
    fn an_approach_turns_back_where_it_would_leave_a_joint_limit() {
        let limits = *Model::nominal().limits();
        let mid = [0.1, 0.4, 1.6, 0.0, 1.1, 0.0];
        assert_eq!(approach_offset(&mid, &limits), APPROACH_OFFSET);
        // seed 3 off the axis: a validation pose with J6 at 4.433 rad of ±4.4506
        let mut q = mid;
        q[5] = limits.upper[5] - 0.0176;
        let a = approach_offset(&q, &limits);
        assert_eq!(a[5], -APPROACH_OFFSET[5]);
        assert_eq!(a[..5], APPROACH_OFFSET[..5]);
        assert!(q[5] + a[5] < limits.upper[5] - APPROACH_MARGIN);
        // J3's offset is negative: near its lower limit it turns positive
        let mut q = mid;
        q[2] = limits.lower[2] + 0.03;
        let a = approach_offset(&q, &limits);
        assert_eq!(a[2], -APPROACH_OFFSET[2]);
        assert!(q[2] + a[2] > limits.lower[2] + APPROACH_MARGIN);
    }

    #[test]
    fn the_tool_and_the_hidden_effects_are_read_and_bad_values_refused() {
        let o = parse(
            "--tool 0.08,0,0.3 --hide-bend forearm:2e-5 --hide-bend upper:1e-5 --hide-payload 1",
        )
        .unwrap();
        assert_eq!(o.tool, [0.08, 0.0, 0.3]);
        let h = o.hidden.unwrap();
        assert_eq!((h.bend[1], h.bend[3], h.payload_kg), (1e-5, 2e-5, 1.0));
        assert_eq!(parse("").unwrap().tool, [0.0, 0.0, 0.35]);
        for (args, why) in [
            ("--tool 1,2", "X,Y,Z"),
            ("--tool 0,0,0.01", "from the flange"),
            ("--tool 0,0,0.6", "from the flange"),
            ("--tool 0,nan,0.3", "X,Y,Z"),
            ("--hide-bend elbow:1e-5", "upper or forearm"),
            ("--hide-bend forearm", "upper:C or forearm:C"),
            ("--hide-bend forearm:1", "bend[3]"),
            ("--hide-payload -1", "payload_kg"),
            ("--hide-payload", "needs a value"),
        ] {
            let e = match parse(args) {
                Ok(_) => panic!("{args}: accepted"),
                Err(e) => format!("{e:#}"),
            };
            assert!(e.contains(why), "{args}: {e}");
        }
    }

    #[test]
    fn paired_compares_only_the_poses_both_models_reached() {
        let cal = [Some(1.0), Some(2.0), None, Some(4.0)];
        let ext = [Some(1.5), Some(2.5), Some(3.0), Some(3.5)];
        let p = paired(&cal, &ext).expect("three poses");
        assert_eq!(p.poses, 3);
        assert!((p.mean_mm - 0.5 / 3.0).abs() < 1e-12);
        // differences 0.5, 0.5, -0.5: sample variance 1/3, standard error 1/3
        assert!((p.se_mm - 1.0 / 3.0).abs() < 1e-12);
        assert!(paired(&[Some(1.0), None], &[Some(2.0), Some(2.0)]).is_none());
    }

    /// Parts at `n` poses with the magnitudes given (mm): servo, resolvers and model along
    /// three orthogonal directions (turned about z from pose to pose), the torque's along
    /// their diagonal, the exact-resolver fit's model part along the model's.
    fn parts(n: usize, mags: [f64; 5]) -> Vec<Parts> {
        (0..n)
            .map(|i| {
                let (s, c) = (i as f64).sin_cos();
                let (x, y, z) = (
                    Vector3::new(c, s, 0.0),
                    Vector3::new(-s, c, 0.0),
                    Vector3::z(),
                );
                [
                    x * mags[0],
                    (x + y + z).normalize() * mags[1],
                    y * mags[2],
                    z * mags[3],
                    z * mags[4],
                ]
            })
            .collect()
    }

    #[test]
    fn a_load_within_the_goal_has_no_miss_and_misses_are_told_apart() {
        let floor = 0.2;
        assert!(miss(&parts(6, [0.02, 0.01, 0.15, 0.04, 0.04]), floor).is_none());
        assert!(miss(&[], floor).is_none());
        // the resolvers realised well above the floor, the rest small: theirs
        let m = miss(&parts(6, [0.02, 0.01, 0.30, 0.03, 0.03]), floor).expect("a miss");
        assert_eq!(m.cause, "resolvers");
        assert!(m.ratio > GOAL_RATIO && m.resolvers_realised > 1.4);
        // the resolvers at the floor, the servo's miss large: the servo's
        let m = miss(&parts(6, [0.20, 0.01, 0.20, 0.03, 0.03]), floor).expect("a miss");
        assert_eq!(m.cause, "servo");
        assert!(m.without[0] < m.without[3] && m.says.contains("came to rest"));
        // the model off, and as far off fitted to exact readings: the model's
        let m = miss(&parts(6, [0.02, 0.01, 0.20, 0.25, 0.24]), floor).expect("a miss");
        assert_eq!(m.cause, "model");
        assert!(m.says.contains("effect the library lacks"));
        // the model off, but not once fitted to exact readings: the campaign's resolvers
        let m = miss(&parts(6, [0.02, 0.01, 0.20, 0.25, 0.02]), floor).expect("a miss");
        assert_eq!(m.cause, "campaign resolvers");
        assert!((m.model_part[0] - 1.25).abs() < 1e-9 && m.with_exact_campaign < 1.1);
    }
}
