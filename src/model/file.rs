//! The model file format: [`ModelFile`], read and written as YAML (serde_yaml).
//!
//! This is the only place that knows the file layout; [`Model`](super::Model) validates
//! what is read here. Unknown keys are rejected (`deny_unknown_fields`), so a typo never
//! silently falls back to a default.

use serde::{Deserialize, Serialize};

use std::collections::BTreeMap;

use super::compliance::Stiffness;
use super::joint_error::JointError;
use super::params::{Departure, DhRow};

/// A rigid transform as written in files: translation (metres) and unit quaternion
/// `[w, x, y, z]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseData {
    /// Translation, metres.
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion `[w, x, y, z]`.
    pub quaternion: [f64; 4],
}

impl Default for PoseData {
    fn default() -> Self {
        Self {
            translation: [0.0; 3],
            quaternion: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// Standard gravity, m/s² (a model file's default gravity is this, straight down).
pub const STANDARD_GRAVITY: f64 = 9.806_65;

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -STANDARD_GRAVITY]
}

/// Everything a model file holds: plain data, no derived values.
///
/// See `config/model-nominal.yaml` for an annotated example. Build a [`Model`](super::Model)
/// from it to validate and evaluate it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// Free-text name of the robot this model describes.
    pub robot: String,
    /// Nominal standard DH table, joints 1…6 (a, d in metres; alpha, theta_offset in rad).
    pub dh: [DhRow; 6],
    /// Identified departures from the nominal table (zero for a nominal model).
    #[serde(default)]
    pub departures: [Departure; 6],
    /// Joint springs, joints 1…6; `null` is a rigid joint.
    #[serde(default)]
    pub stiffness: [Option<Stiffness>; 6],
    /// The measuring instrument's frame expressed in the robot base frame (`ᴮᴬˢᴱ_ᴵᴺˢᵀT`):
    /// maps points measured in the instrument frame into the base frame.
    #[serde(default)]
    pub base_from_instrument: PoseData,
    /// Flange → tool (measured target) transform. Identity makes tool poses flange poses.
    #[serde(default)]
    pub tool: PoseData,
    /// Gravity vector in the robot base frame, m/s².
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Rigid bodies whose weight loads the joints (links, fixed tooling).
    #[serde(default)]
    pub bodies: Vec<Body>,
    /// Joint position and speed limits.
    pub joint_limits: JointLimits,
    /// Transmission error, eccentricity and backlash per joint (`null`: none); added by
    /// `pa10 discover`, compensated by `pa10d`.
    #[serde(default, skip_serializing_if = "all_none")]
    pub joint_errors: [Option<JointError>; 6],
    /// Effects `pa10 discover` found, as a record (the run-time ones are also folded into
    /// the fields above; the others, e.g. thermal expansion, are not compensated at run time).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub discovered: Vec<EffectRecord>,
    /// Joint friction at the link side (`null`: not identified), as `pa10 identify` measured it
    /// from the arm's own motion; the daemon's `estimated` torque source subtracts it from the
    /// currents in motion.
    #[serde(default, skip_serializing_if = "no_friction")]
    pub friction: [Option<Friction>; 6],
    /// How well the calibration determined the 30 parameters (`pa10 calibrate` writes it; the
    /// daemon reports the tool position uncertainty it implies at the setpoint).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<ParamCovariance>,
}

/// The identified parameters' covariance and the resolvers' uncertainty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamCovariance {
    /// 30 rows of 30 numbers in the parameters' order and physical units (products of m, rad,
    /// N·m/rad, N·m/rad³; `docs/model.md`); rows and columns of parameters the fit held fixed
    /// are zero. Symmetric, non-negative diagonal.
    pub covariance: Vec<Vec<f64>>,
    /// The resolvers' repeatable error the data showed (1σ per joint, rad): the floor added to
    /// the calibration's share.
    pub resolver_rad: f64,
}

fn all_none(v: &[Option<JointError>; 6]) -> bool {
    v.iter().all(Option::is_none)
}

fn no_friction(v: &[Option<Friction>; 6]) -> bool {
    v.iter().all(Option::is_none)
}

/// One joint's friction, link side: `τ_f = coulomb·sign(q̇) + viscous·q̇` in motion (what the
/// motor current carries beyond the spring's torque at constant speed). At rest a drive
/// holds anything within its breakaway level: the current there says nothing of the spring.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    /// Coulomb level, N·m (≥ 0).
    pub coulomb: f64,
    /// Viscous coefficient, N·m·s/rad (≥ 0).
    pub viscous: f64,
    /// Standard errors of `coulomb` (N·m) and `viscous` (N·m·s/rad) from the identification.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<[f64; 2]>,
    /// Breakaway level, N·m (≥ 0): the torque beyond gravity a drive at rest needed to start
    /// moving (the median over the identification's sweep starts). Above `coulomb` on a drive
    /// that sticks; about `coulomb` on one that creeps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub breakaway: Option<f64>,
}

impl Friction {
    /// The friction torque at link speed `qd` (rad/s), N·m; zero at exactly zero speed.
    #[inline]
    pub fn torque(&self, qd: f64) -> f64 {
        let sign = if qd > 0.0 {
            1.0
        } else if qd < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.coulomb * sign + self.viscous * qd
    }

    /// Checks the values; the offending field and why.
    pub fn validate(&self, key: &str) -> Result<(), (String, String)> {
        let fields = [
            ("coulomb", self.coulomb, "N·m"),
            ("viscous", self.viscous, "N·m·s/rad"),
            ("breakaway", self.breakaway.unwrap_or(0.0), "N·m"),
        ];
        for (name, v, unit) in fields {
            if !(v.is_finite() && v >= 0.0) {
                return Err((
                    format!("{key}.{name}"),
                    format!("must be finite and ≥ 0 {unit}, got {v}"),
                ));
            }
        }
        if let Some(s) = self.sigma
            && s.iter().any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err((
                format!("{key}.sigma"),
                format!("standard errors must be finite and ≥ 0, got {s:?}"),
            ));
        }
        Ok(())
    }
}

/// Standard errors of an identified body's mass (kg) and centre of mass (m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySigma {
    /// Of the mass, kg.
    pub mass: f64,
    /// Of the centre of mass, m, in the body's frame.
    pub com: [f64; 3],
}

impl ParamCovariance {
    /// Checks the shape and values; the offending key and why.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let n = super::PARAM_COUNT;
        let key = "uncertainty.covariance".to_string();
        if self.covariance.len() != n || self.covariance.iter().any(|r| r.len() != n) {
            return Err((key, format!("must be {n} rows of {n} numbers")));
        }
        for (i, row) in self.covariance.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                let w = self.covariance[j][i];
                if !v.is_finite() || (v - w).abs() > 1e-9 * v.abs().max(w.abs()).max(1e-300) {
                    return Err((
                        format!("uncertainty.covariance[{i}][{j}]"),
                        format!(
                            "must be finite and equal to [{j}][{i}] (symmetric), got {v} and {w}"
                        ),
                    ));
                }
            }
            if row[i] < 0.0 {
                return Err((
                    format!("uncertainty.covariance[{i}][{i}]"),
                    format!("a variance must be ≥ 0, got {}", row[i]),
                ));
            }
        }
        if !(self.resolver_rad.is_finite() && (0.0..0.01).contains(&self.resolver_rad)) {
            return Err((
                "uncertainty.resolver_rad".into(),
                format!("must be within 0…0.01 rad, got {}", self.resolver_rad),
            ));
        }
        Ok(())
    }
}

/// One effect found by `pa10 discover`, as written into the extended model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectRecord {
    /// The effect's machine name, e.g. `transmission_error`.
    pub name: String,
    /// Joint or link (DH row 1…6) it acts on, when it has one.
    #[serde(default)]
    pub joint: Option<usize>,
    /// Estimated parameters by name (units in the name's documentation, SI).
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// Standard errors of the parameters, same units.
    #[serde(default)]
    pub stderr: BTreeMap<String, f64>,
    /// Whether `pa10d` compensates it at run time.
    #[serde(default)]
    pub compensated: bool,
}

impl EffectRecord {
    /// A compensated effect with one parameter `param` = `value` (SI) and no standard error,
    /// e.g. `EffectRecord::compensated_one("tool_sag", None, "compliance", 2e-6)`.
    pub fn compensated_one(name: &str, joint: Option<usize>, param: &str, value: f64) -> Self {
        Self {
            name: name.into(),
            joint,
            params: [(param.to_string(), value)].into(),
            stderr: BTreeMap::new(),
            compensated: true,
        }
    }
}

/// A rigid body whose weight the joints carry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Body {
    /// Name, for reports.
    pub name: String,
    /// DH frame the body is fixed to, 1…6 (6 = flange); joints 1…frame move it.
    pub frame: usize,
    /// Mass, kg (≥ 0).
    pub mass: f64,
    /// Centre of mass in that DH frame, metres.
    pub com: [f64; 3],
    /// Standard errors, when `pa10 identify` measured the body (absent: a seed value).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<BodySigma>,
}

/// Joint position and speed limits, link side.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointLimits {
    /// Lower position limits, rad.
    pub lower: [f64; 6],
    /// Upper position limits, rad.
    pub upper: [f64; 6],
    /// Speed limits, rad/s (> 0).
    pub velocity: [f64; 6],
}

impl JointLimits {
    /// True when every joint is within `[lower, upper]` (inclusive).
    pub fn contains(&self, q: &[f64; 6]) -> bool {
        (0..6).all(|j| q[j] >= self.lower[j] && q[j] <= self.upper[j])
    }
}
