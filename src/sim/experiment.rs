//! The seed paper's measurement campaign, on a simulated robot.
//!
//! - **Calibration set**: 27 configurations on a 3 × 3 × 3 Cartesian grid of tool positions
//!   (x 0.45–0.70 m, y ±0.2 m, z −0.05–0.25 m in the robot base frame: a box in the instrument's
//!   volume in front of and below the shoulder), tool pointing down with ±0.15 rad tilts and yaws varied over the
//!   grid, at loads 0 / 22 / 44 N, 10 repeats each (810 rows). The 8 grid corners are the
//!   inner-level configurations (named in the sidecar).
//! - **Lines**: 10 points along the robot's x axis and 10 along its y axis (ids `x0…x9`,
//!   `y0…y9`), unloaded, for the base-frame seed (paper eqs 5–7).
//! - **Validation set**: 10 novel configurations up to 100 mm outside the grid's box with
//!   larger tilts, at 0 / 45 / 90 N, 3 repeats each.
//!
//! The operator commands joint angles from the *nominal* model's IK, as a real user would;
//! what the robot then does is the [`TrueRobot`]'s physics.

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;

use super::{SimNoise, TrueRobot};
use crate::calib::dataset::{Dataset, Meta, Noise};
use crate::model::{Frame, Model, ModelError, PoseData};

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignSpec {
    /// Seed of the truth and of every measurement.
    pub seed: u64,
    /// Repeats per calibration (configuration, load).
    pub repeats: usize,
    /// Calibration loads, N.
    pub loads: Vec<f64>,
    /// Validation loads, N.
    pub validation_loads: Vec<f64>,
    /// Flange → target (the tooling ball frame), known to the user.
    pub tool: Frame,
    /// Sensor noise.
    pub noise: SimNoise,
}

impl Default for CampaignSpec {
    fn default() -> Self {
        Self {
            seed: 1,
            repeats: 10,
            loads: vec![0.0, 22.0, 44.0],
            validation_loads: vec![0.0, 45.0, 90.0],
            tool: Frame::from_parts(
                Translation3::new(0.0, 0.0, 0.35),
                nalgebra::Rotation3::identity(),
            ),
            noise: SimNoise::default(),
        }
    }
}

/// A generated campaign. `truth` is the hidden true model: the calibration never reads it.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The calibration set (with its sidecar).
    pub cal: Dataset,
    /// Straight-line moves for the base-frame seed.
    pub lines: Dataset,
    /// The validation set.
    pub val: Dataset,
    /// The true robot.
    pub truth: TrueRobot,
}

/// Why a campaign could not be generated.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CampaignError {
    /// A model could not be built or a measurement not simulated.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A commanded pose has no IK solution on the nominal model.
    #[error("configuration {id}: the nominal model cannot reach it: {reason}")]
    Unreachable {
        /// The configuration.
        id: String,
        /// The IK error.
        reason: String,
    },
    /// A setting is out of range.
    #[error("invalid {0}")]
    Invalid(String),
}

/// A tool pose at `p` (m, robot base frame) pointing down, tilted about x and y and turned
/// about the tool axis by `yaw` (rad): the campaigns' pose family.
pub fn pose(p: [f64; 3], tilt_x: f64, tilt_y: f64, yaw: f64) -> Frame {
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let r = UnitQuaternion::from_euler_angles(tilt_x, tilt_y, 0.0)
        * down
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    Frame::from_parts(Translation3::new(p[0], p[1], p[2]), r.to_rotation_matrix())
}

/// A novel validation pose: position uniform in the box `lo`…`hi` (m, robot base frame),
/// tilts uniform in ±0.3 rad about x and y, yaw in ±0.6 rad ([`pose`]'s family).
pub fn random_pose(rng: &mut Pcg64, lo: [f64; 3], hi: [f64; 3]) -> Frame {
    let p: [f64; 3] = std::array::from_fn(|k| rng.random_range(lo[k]..hi[k]));
    pose(
        p,
        rng.random_range(-0.3..0.3),
        rng.random_range(-0.3..0.3),
        rng.random_range(-0.6..0.6),
    )
}

/// Grid coordinate of index 0…2 along an axis.
fn grid(i: usize, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * i as f64 / 2.0
}

/// The 27 grid poses with their ids (`gIJK`).
pub fn grid_poses() -> Vec<(String, Frame)> {
    let mut out = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                let p = [
                    grid(i, 0.45, 0.70),
                    grid(j, -0.2, 0.2),
                    grid(k, -0.05, 0.25),
                ];
                let c = |n: usize| 0.15 * (n % 3) as f64 - 0.15;
                out.push((
                    format!("g{i}{j}{k}"),
                    pose(p, c(i + j + k), c(i + 2 * j + k), 2.0 * c(2 * i + j + k)),
                ));
            }
        }
    }
    out
}

/// The sidecar of a simulated campaign: the instrument's name, the tool, the noise levels.
pub fn sidecar(instrument: String, tool: &Frame, noise: &SimNoise) -> Meta {
    Meta {
        instrument: Some(instrument),
        tool: Some(PoseData::from(tool)),
        noise: Some(Noise {
            position_m: noise.position_m,
            resolver_arcmin: noise.resolver_rad / crate::accuracy::ARCMIN,
        }),
        inner_configs: None,
    }
}

/// Generates the whole campaign for `spec`.
pub fn paper_campaign(spec: &CampaignSpec) -> Result<Campaign, CampaignError> {
    if spec.repeats == 0 || spec.loads.is_empty() || spec.validation_loads.is_empty() {
        return Err(CampaignError::Invalid(
            "campaign: needs ≥ 1 repeat and ≥ 1 load".into(),
        ));
    }
    if spec
        .loads
        .iter()
        .chain(&spec.validation_loads)
        .any(|l| !(l.is_finite() && *l >= 0.0 && *l <= 500.0))
    {
        return Err(CampaignError::Invalid(
            "campaign: loads must be within 0…500 N".into(),
        ));
    }
    let nominal = Model::nominal().with_tool(&spec.tool)?;
    let truth = TrueRobot::draw(spec.seed, &Model::nominal(), &spec.tool, spec.noise)?;
    let mut rng = Pcg64::seed_from_u64(spec.seed ^ 0x00ca_11b5);
    let command = |id: &str, target: &Frame| -> Result<[f64; 6], CampaignError> {
        let p = target.translation.vector;
        let reference = [p.y.atan2(p.x), 0.3, 1.6, 0.0, 1.2, 0.0];
        nominal
            .ik_nearest(target, &reference)
            .map_err(|e| CampaignError::Unreachable {
                id: id.into(),
                reason: e.to_string(),
            })
    };

    let mut cal = Dataset::default();
    let poses = grid_poses();
    for &load in &spec.loads {
        for (id, target) in &poses {
            let q = command(id, target)?;
            for _ in 0..spec.repeats {
                cal.rows.push(truth.measure(id, &q, load, &mut rng)?);
            }
        }
    }
    let corners: Vec<String> = poses
        .iter()
        .map(|(id, _)| id.clone())
        .filter(|id| !id[1..].contains('1'))
        .collect();
    let meta = Meta {
        inner_configs: Some(corners),
        ..sidecar(
            format!("simulated CMM (pa10 sim measure, seed {})", spec.seed),
            &spec.tool,
            &spec.noise,
        )
    };
    cal.meta = Some(meta.clone());

    let mut lines = Dataset::default();
    for k in 0..10 {
        let t = k as f64 / 9.0;
        for (id, p) in [
            (format!("x{k}"), [0.45 + 0.25 * t, -0.1, 0.1]),
            (format!("y{k}"), [0.575, -0.2 + 0.4 * t, 0.1]),
        ] {
            let target = pose(p, 0.0, 0.0, 0.0);
            let q = command(&id, &target)?;
            lines.rows.push(truth.measure(&id, &q, 0.0, &mut rng)?);
        }
    }
    lines.rows.sort_by(|a, b| a.config_id.cmp(&b.config_id));
    lines.meta = Some(Meta {
        inner_configs: None,
        ..meta.clone()
    });

    let mut val = Dataset::default();
    let mut placed = 0;
    while placed < 10 {
        let target = random_pose(&mut rng, [0.35, -0.3, -0.15], [0.80, 0.3, 0.35]);
        let id = format!("v{placed}");
        let Ok(q) = command(&id, &target) else {
            continue;
        };
        for &load in &spec.validation_loads {
            for _ in 0..3 {
                val.rows.push(truth.measure(&id, &q, load, &mut rng)?);
            }
        }
        placed += 1;
    }
    val.meta = Some(Meta {
        inner_configs: None,
        ..meta
    });
    Ok(Campaign {
        cal,
        lines,
        val,
        truth,
    })
}

/// A campaign designed for `pa10 discover`: random joint configurations spread over wide
/// joint ranges, every one measured at every load, from both approach directions, and in
/// a cold and a warm pass — so that load-, direction- and temperature-dependent effects
/// each show as contrasts *within* a configuration, where the configuration's resolver
/// error cancels.
#[derive(Debug, Clone, PartialEq)]
pub struct DiscoverySpec {
    /// Seed of the truth, the configurations and every measurement.
    pub seed: u64,
    /// Seed of the configurations and measurements alone (same truth, other poses: a
    /// holdout set).
    pub pose_seed: u64,
    /// Number of configurations.
    pub configs: usize,
    /// Loads, N.
    pub loads: Vec<f64>,
    /// Repeats per (configuration, load, direction, temperature).
    pub repeats: usize,
    /// Approach every configuration from both directions (−1 and +1 on every joint).
    pub both_directions: bool,
    /// Arm temperatures of the passes, °C (empty: one pass, no temperature column).
    pub temperatures_c: Vec<f64>,
    /// The hidden effects set on top of the drawn truth.
    pub hidden: Vec<Hidden>,
    /// Flange → target (the tooling ball frame), known to the user.
    pub tool: Frame,
    /// Sensor noise.
    pub noise: SimNoise,
}

impl Default for DiscoverySpec {
    fn default() -> Self {
        Self {
            seed: 1,
            pose_seed: 0,
            configs: 60,
            loads: vec![0.0, 45.0, 90.0],
            repeats: 2,
            both_directions: true,
            temperatures_c: vec![20.0, 35.0],
            hidden: Vec::new(),
            tool: CampaignSpec::default().tool,
            noise: SimNoise::default(),
        }
    }
}

/// Joint ranges of the discovery configurations, rad: wide, clear of the limits and of
/// the wrist singularity (q5 = 0).
const DISCOVERY_RANGES: [(f64, f64); 6] = [
    (-1.2, 1.2),
    (-0.5, 1.1),
    (0.4, 2.3),
    (-1.5, 1.5),
    (0.35, 1.8),
    (-1.5, 1.5),
];

/// A discovery campaign and its hidden truth.
#[derive(Debug, Clone)]
pub struct DiscoveryCampaign {
    /// The measurements (with sidecar: tool and noise).
    pub data: Dataset,
    /// The truth, with the hidden effects.
    pub truth: TrueRobot,
}

/// Generates the campaign of `spec`: the truth is [`TrueRobot::draw`]`(seed)` with the
/// hidden slots set on top.
pub fn discovery_campaign(spec: &DiscoverySpec) -> Result<DiscoveryCampaign, CampaignError> {
    if spec.configs < 8 || spec.configs > 1000 || spec.repeats == 0 || spec.loads.is_empty() {
        return Err(CampaignError::Invalid(
            "discovery campaign: needs 8…1000 configurations, ≥ 1 repeat and ≥ 1 load".into(),
        ));
    }
    if spec
        .loads
        .iter()
        .any(|l| !(l.is_finite() && *l >= 0.0 && *l <= 500.0))
    {
        return Err(CampaignError::Invalid(
            "discovery campaign: loads must be within 0…500 N".into(),
        ));
    }
    let mut truth = TrueRobot::draw(spec.seed, &Model::nominal(), &spec.tool, spec.noise)?;
    if !spec.hidden.is_empty() {
        let mut d = truth.model.data().clone();
        for h in &spec.hidden {
            h.apply(&mut d, &mut truth.extras);
        }
        truth.extras.t_ref_c = 20.0;
        truth.model = Model::new(d)?;
    }
    let mut rng = Pcg64::seed_from_u64(
        spec.seed ^ 0xd15c_0e7e ^ spec.pose_seed.wrapping_mul(0x9e37_79b9_7f4a_7c15),
    );
    let limits = *truth.model.limits();
    let mut data = Dataset::default();
    let dirs: &[i8] = if spec.both_directions { &[1, -1] } else { &[0] };
    let temps: Vec<Option<f64>> = if spec.temperatures_c.is_empty() {
        vec![None]
    } else {
        spec.temperatures_c.iter().map(|t| Some(*t)).collect()
    };
    let configs: Vec<[f64; 6]> = (0..spec.configs)
        .map(|_| {
            std::array::from_fn(|j| {
                let (lo, hi) = DISCOVERY_RANGES[j];
                rng.random_range(lo.max(limits.lower[j])..hi.min(limits.upper[j]))
            })
        })
        .collect();
    for &temperature_c in &temps {
        for (c, q) in configs.iter().enumerate() {
            for &load in &spec.loads {
                for &d in dirs {
                    for _ in 0..spec.repeats {
                        let cond = super::Conditions {
                            direction: [d; 6],
                            temperature_c,
                        };
                        data.rows.push(truth.measure_with(
                            &format!("c{c:03}"),
                            q,
                            load,
                            cond,
                            &mut rng,
                        )?);
                    }
                }
            }
        }
    }
    data.meta = Some(sidecar(
        format!("simulated CMM (discovery campaign, seed {})", spec.seed),
        &spec.tool,
        &spec.noise,
    ));
    Ok(DiscoveryCampaign { data, truth })
}

/// An effect the simulator's truth can hide (joints and DH rows zero-based). The simulator
/// applies it with its own code: joint effects as the truth's springs and joint errors,
/// thermal growth as real changes of the link lengths, bending in [`TrueRobot`]'s own
/// forward model — never with the discovery library's functions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hidden {
    /// A linear spring of stiffness `k` (N·m/rad) on joint `j` (keeps a cubic term there).
    Spring(usize, f64),
    /// Sets the cubic stiffness of joint `j` (N·m/rad³; 0 removes it).
    CubicStiffness(usize, f64),
    /// Transmission error once per wave-generator revolution on joint `j`: sin, cos (rad).
    WaveHarmonic(usize, f64, f64),
    /// Transmission error twice per output revolution on joint `j`: sin, cos (rad).
    OutputHarmonic2(usize, f64, f64),
    /// Backlash (total lost motion, rad) on joint `j`.
    Backlash(usize, f64),
    /// Thermal expansion of DH row `j` (1/K, against 20 °C).
    Thermal(usize, f64),
    /// Bending compliance of DH row `j` (rad/(N·m)).
    Bending(usize, f64),
}

impl Hidden {
    /// Puts the effect into the truth's model data or extras.
    pub fn apply(&self, d: &mut crate::model::ModelFile, extras: &mut super::TruthExtras) {
        fn je(d: &mut crate::model::ModelFile, j: usize) -> &mut crate::model::JointError {
            d.joint_errors[j].get_or_insert_with(Default::default)
        }
        match *self {
            Hidden::Spring(j, k) => {
                let kcub = d.stiffness[j].map_or(0.0, |s| s.kcub);
                d.stiffness[j] = Some(crate::model::Stiffness { klin: k, kcub });
            }
            Hidden::CubicStiffness(j, v) => {
                if let Some(s) = &mut d.stiffness[j] {
                    s.kcub = v;
                }
            }
            Hidden::WaveHarmonic(j, s, c) => je(d, j).wave[0] = [s, c],
            Hidden::OutputHarmonic2(j, s, c) => je(d, j).output[1] = [s, c],
            Hidden::Backlash(j, b) => je(d, j).backlash = b,
            Hidden::Thermal(j, a) => extras.thermal[j] = a,
            Hidden::Bending(j, c) => extras.bending[j] = c,
        }
    }
}

/// A hidden-effect scenario for `pa10 discover`: what the truth has that the starting
/// model lacks, and what discovery should name.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Short machine name (`pa10 sim discovery --scenario NAME`).
    pub name: &'static str,
    /// What is hidden, in words.
    pub description: &'static str,
    /// Whether the starting model is the paper's linear-only comparison model.
    pub linear_only: bool,
    /// What the truth has on top of the drawn robot.
    pub hidden: Vec<Hidden>,
    /// Labels discovery should name, in order of size.
    pub expect: Vec<&'static str>,
}

/// The scenarios the discovery tests and study use.
pub fn scenarios() -> Vec<Scenario> {
    use Hidden::*;
    vec![
        Scenario {
            name: "none",
            description: "nothing hidden: the truth is the paper's model",
            linear_only: false,
            hidden: vec![],
            expect: vec![],
        },
        Scenario {
            name: "cubic-j2",
            description: "cubic stiffness on J2 (the paper's 3.35e7 N·m/rad³ ±20 %), starting from a linear-only model",
            linear_only: true,
            hidden: vec![CubicStiffness(2, 0.0), CubicStiffness(4, 0.0)],
            expect: vec!["joint_compliance_cubic[J2]"],
        },
        Scenario {
            name: "compliance-j4",
            description: "a 4000 N·m/rad spring on J4, which the paper holds rigid",
            linear_only: false,
            hidden: vec![Spring(3, 4.0e3)],
            expect: vec!["joint_compliance_linear[J4]"],
        },
        Scenario {
            name: "transmission-j3",
            description: "transmission error on J3: 0.5 mrad once per wave-generator revolution (1:50) and 0.3 mrad twice per output revolution",
            linear_only: false,
            hidden: vec![WaveHarmonic(2, 4e-4, -3e-4), OutputHarmonic2(2, 3e-4, 0.0)],
            expect: vec!["transmission_error[J3]"],
        },
        Scenario {
            name: "backlash-j1",
            description: "0.4 mrad of backlash on J1",
            linear_only: false,
            hidden: vec![Backlash(0, 4e-4)],
            expect: vec!["backlash[J1]"],
        },
        Scenario {
            name: "thermal-forearm",
            description: "thermal expansion of the forearm (aluminium, 23e-6 /K) over a 15 K warm-up",
            linear_only: false,
            hidden: vec![Thermal(3, 2.3e-5)],
            expect: vec!["thermal_expansion[link 4]"],
        },
        Scenario {
            name: "j4-and-backlash",
            description: "two at once: the J4 spring (mm) and J1 backlash (0.1 mm)",
            linear_only: false,
            hidden: vec![Spring(3, 4.0e3), Backlash(0, 4e-4)],
            expect: vec!["joint_compliance_linear[J4]", "backlash[J1]"],
        },
    ]
}

/// The starting model of the discovery scenarios: nominal geometry with the paper's
/// stiffness on J2, J3, J5 (cubic terms zero when `linear_only`).
pub fn paper_model(linear_only: bool) -> Result<Model, ModelError> {
    let mut d = Model::nominal().data().clone();
    for (k, &j) in crate::model::STIFF_JOINTS.iter().enumerate() {
        d.stiffness[j] = Some(crate::model::Stiffness {
            klin: super::PAPER_STIFFNESS[k].0,
            kcub: if linear_only {
                0.0
            } else {
                super::PAPER_STIFFNESS[k].1
            },
        });
    }
    Model::new(d)
}
