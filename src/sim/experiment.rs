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

fn pose(p: [f64; 3], tilt_x: f64, tilt_y: f64, yaw: f64) -> Frame {
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let r = UnitQuaternion::from_euler_angles(tilt_x, tilt_y, 0.0)
        * down
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
    Frame::from_parts(Translation3::new(p[0], p[1], p[2]), r.to_rotation_matrix())
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
        instrument: Some(format!(
            "simulated CMM (pa10 sim measure, seed {})",
            spec.seed
        )),
        tool: Some(PoseData {
            translation: crate::model::pose_parts(&spec.tool).0,
            quaternion: crate::model::pose_parts(&spec.tool).1,
        }),
        noise: Some(Noise {
            position_m: spec.noise.position_m,
            resolver_arcmin: spec.noise.resolver_rad / crate::accuracy::ARCMIN,
        }),
        inner_configs: Some(corners),
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
        let p = [
            rng.random_range(0.35..0.80),
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.15..0.35),
        ];
        let target = pose(
            p,
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.6..0.6),
        );
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
