//! [`Model`]: a validated PA10 model, ready to evaluate, and its construction, validation
//! and file IO.

use std::f64::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};

use super::compliance::Stiffness;
use super::file::{JointLimits, ModelFile, PoseData};
use super::frame::Frame;
use super::params::{
    self, HAYATI_JOINT, IDX_KCUB, IDX_KLIN, PARAM_COUNT, ParamVector, STIFF_JOINTS,
};

/// The nominal PA10-6C model file shipped in `config/model-nominal.yaml`.
pub const NOMINAL_YAML: &str = include_str!("../../config/model-nominal.yaml");

/// Why a model could not be read or built. Nothing is changed when one is returned.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The YAML is malformed or has an unknown or mistyped key (the message has the line).
    #[error("{origin}: {message}")]
    Parse {
        /// Where the text came from (a path, or `<string>`).
        origin: String,
        /// The parser's message, with line and column.
        message: String,
    },
    /// A value is out of its valid range.
    #[error("invalid `{key}`: {reason}")]
    Invalid {
        /// Path of the offending key, e.g. `stiffness[2].klin`.
        key: String,
        /// What is wrong and what is expected, with units.
        reason: String,
    },
}

/// A parser message with every double-quoted value replaced by `"…"` and cut to 300 bytes:
/// it names keys, lines and columns, never the file's content (a wrong path must not print
/// a secret file back).
fn without_values(message: &str) -> String {
    let mut out = String::with_capacity(message.len().min(320));
    let mut chars = message.chars();
    while let Some(c) = chars.next() {
        if c == '"' {
            let mut escaped = false;
            for d in chars.by_ref() {
                match d {
                    '\\' if !escaped => escaped = true,
                    '"' if !escaped => break,
                    _ => escaped = false,
                }
            }
            out.push_str("\"…\"");
        } else {
            out.push(c);
        }
        if out.len() > 300 {
            out.push('…');
            break;
        }
    }
    out
}

fn invalid(key: impl Into<String>, reason: impl Into<String>) -> ModelError {
    ModelError::Invalid {
        key: key.into(),
        reason: reason.into(),
    }
}

/// Per-joint geometry with departures folded in and constant trigonometry precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct JointGeom {
    /// a + δa, m.
    pub a: f64,
    /// d + δd, m.
    pub d: f64,
    /// θ offset + δθ, rad.
    pub offset: f64,
    /// cos, sin of α + δα.
    pub ca: f64,
    pub sa: f64,
    /// cos, sin of δβ (Hayati; identity elsewhere).
    pub cb: f64,
    pub sb: f64,
    /// Whether the Ry(β) factor is present.
    pub hayati: bool,
}

/// A body with its mass and centre of mass as vectors, for the statics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MassPoint {
    pub frame: usize,
    pub mass: f64,
    pub com: Vector3<f64>,
}

/// Largest number of bodies a model may carry (keeps the statics allocation-free).
pub const MAX_BODIES: usize = 16;

/// A validated PA10 model: nominal geometry, departures, joint springs, base and tool
/// frames, and mass data. Cheap to evaluate; immutable (build a new one to change it).
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    data: ModelFile,
    pub(crate) joints: [JointGeom; 6],
    pub(crate) tool: Frame,
    pub(crate) tool_inv: Frame,
    pub(crate) base_from_instrument: Frame,
    pub(crate) gravity: Vector3<f64>,
    pub(crate) masses: [MassPoint; MAX_BODIES],
    pub(crate) n_masses: usize,
    /// The compensated load effects outside the joints of `data.discovered`.
    pub(crate) load_effects: super::load_effects::LoadEffects,
}

/// The PA10-6C structure of the standard DH table: twists and angle offsets.
const PA10_ALPHA: [f64; 6] = [-FRAC_PI_2, 0.0, FRAC_PI_2, -FRAC_PI_2, FRAC_PI_2, 0.0];
const PA10_OFFSET: [f64; 6] = [0.0, -FRAC_PI_2, FRAC_PI_2, 0.0, 0.0, 0.0];
/// Which nominal a (true) and d (false) entries must be non-zero.
const PA10_A_NONZERO: [bool; 6] = [false, true, false, false, false, false];
const PA10_D_NONZERO: [bool; 6] = [true, false, false, true, false, true];

/// Largest accepted length departure, m, and angle departure, rad: departures are small
/// corrections; anything larger is a wrong nominal table or a unit mistake.
const MAX_LENGTH_DEPARTURE: f64 = 0.05;
const MAX_ANGLE_DEPARTURE: f64 = 0.1;

/// Converts file pose data to a frame, validating it under `key`.
pub(crate) fn frame_from_data(key: &str, p: &PoseData) -> Result<Frame, ModelError> {
    if p.translation.iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            format!("{key}.translation"),
            "must be three finite numbers (m)",
        ));
    }
    if p.quaternion.iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            format!("{key}.quaternion"),
            "must be four finite numbers [w, x, y, z]",
        ));
    }
    let [w, x, y, z] = p.quaternion;
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    if (norm - 1.0).abs() > 1e-6 {
        return Err(invalid(
            format!("{key}.quaternion"),
            format!("must be a unit quaternion [w, x, y, z]; its norm is {norm}"),
        ));
    }
    let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
    let t = Translation3::new(p.translation[0], p.translation[1], p.translation[2]);
    Ok(Frame::from_parts(t, q.to_rotation_matrix()))
}

impl Model {
    /// Validates `data` and builds the model. Every rule violated is reported by key.
    pub fn new(data: ModelFile) -> Result<Self, ModelError> {
        validate(&data)?;
        let mut joints = [JointGeom {
            a: 0.0,
            d: 0.0,
            offset: 0.0,
            ca: 1.0,
            sa: 0.0,
            cb: 1.0,
            sb: 0.0,
            hayati: false,
        }; 6];
        for (j, g) in joints.iter_mut().enumerate() {
            let n = &data.dh[j];
            let e = &data.departures[j];
            let (sa, ca) = (n.alpha + e.dalpha).sin_cos();
            let (sb, cb) = e.dbeta.sin_cos();
            *g = JointGeom {
                a: n.a + e.da,
                d: n.d + e.dd,
                offset: n.theta_offset + e.dtheta,
                ca,
                sa,
                cb,
                sb,
                hayati: j == HAYATI_JOINT,
            };
        }
        let tool = frame_from_data("tool", &data.tool)?;
        let base = frame_from_data("base_from_instrument", &data.base_from_instrument)?;
        let mut masses = [MassPoint {
            frame: 0,
            mass: 0.0,
            com: Vector3::zeros(),
        }; MAX_BODIES];
        for (m, b) in masses.iter_mut().zip(&data.bodies) {
            *m = MassPoint {
                frame: b.frame,
                mass: b.mass,
                com: Vector3::from(b.com),
            };
        }
        let load_effects = super::load_effects::LoadEffects::from_records(&data.discovered)
            .map_err(|(key, reason)| invalid(key, reason))?;
        Ok(Self {
            load_effects,
            joints,
            tool,
            tool_inv: tool.inverse(),
            base_from_instrument: base,
            gravity: Vector3::from(data.gravity),
            masses,
            n_masses: data.bodies.len(),
            data,
        })
    }

    /// The nominal PA10-6C model (`config/model-nominal.yaml`, compiled in): rigid joints,
    /// identity tool and base frame.
    pub fn nominal() -> Self {
        Self::from_yaml_str(NOMINAL_YAML, "config/model-nominal.yaml")
            .expect("the shipped nominal model is valid (checked by tests)")
    }

    /// Parses and validates a model from YAML text; `origin` names it in errors.
    pub fn from_yaml_str(text: &str, origin: &str) -> Result<Self, ModelError> {
        let data: ModelFile = serde_yaml::from_str(text).map_err(|e| ModelError::Parse {
            origin: origin.to_string(),
            message: without_values(&e.to_string()),
        })?;
        Self::new(data)
    }

    /// Reads and validates a model file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ModelError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_yaml_str(&text, &path.display().to_string())
    }

    /// The model as YAML text (the same format [`Model::load`] reads).
    pub fn to_yaml(&self) -> String {
        // Serialising plain numbers, strings and arrays cannot fail.
        serde_yaml::to_string(&self.data).unwrap_or_default()
    }

    /// Writes the model file (YAML).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ModelError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_yaml()).map_err(|source| ModelError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The plain data this model was built from.
    pub fn data(&self) -> &ModelFile {
        &self.data
    }

    /// Joint `j`'s identified friction (0-based), if any.
    pub fn friction(&self, j: usize) -> Option<crate::model::Friction> {
        self.data.friction.get(j).copied().flatten()
    }

    /// Joint limits.
    pub fn limits(&self) -> &JointLimits {
        &self.data.joint_limits
    }

    /// Spring of joint `j` (zero-based), `None` when rigid.
    pub fn stiffness(&self, j: usize) -> Option<Stiffness> {
        self.data.stiffness.get(j).copied().flatten()
    }

    /// Flange → tool transform.
    pub fn tool(&self) -> &Frame {
        &self.tool
    }

    /// Instrument frame expressed in the base frame.
    pub fn base_from_instrument(&self) -> &Frame {
        &self.base_from_instrument
    }

    /// Gravity in the base frame, m/s².
    pub fn gravity(&self) -> Vector3<f64> {
        self.gravity
    }

    /// A copy with another tool transform.
    pub fn with_tool(&self, tool: &Frame) -> Result<Self, ModelError> {
        let mut d = self.data.clone();
        d.tool = PoseData::from(tool);
        Self::new(d)
    }

    /// A copy with another instrument → base placement.
    pub fn with_base_from_instrument(&self, base: &Frame) -> Result<Self, ModelError> {
        let mut d = self.data.clone();
        d.base_from_instrument = PoseData::from(base);
        Self::new(d)
    }

    /// The 30 identification parameters (layout in [`params`](super::params) docs).
    pub fn params(&self) -> ParamVector {
        let mut p = [0.0; PARAM_COUNT];
        params::pack_departures(&self.data.departures, &mut p);
        for (k, &j) in STIFF_JOINTS.iter().enumerate() {
            match self.data.stiffness[j] {
                Some(s) => {
                    p[IDX_KLIN + k] = s.klin;
                    p[IDX_KCUB + k] = s.kcub;
                }
                None => {
                    p[IDX_KLIN + k] = f64::INFINITY;
                    p[IDX_KCUB + k] = 0.0;
                }
            }
        }
        p
    }

    /// A copy with the 30 identification parameters replaced (an infinite Klin makes the
    /// joint rigid). Validated like a file.
    pub fn with_params(&self, p: &ParamVector) -> Result<Self, ModelError> {
        let mut d = self.data.clone();
        d.departures = params::unpack_departures(p);
        for (k, &j) in STIFF_JOINTS.iter().enumerate() {
            let (klin, kcub) = (p[IDX_KLIN + k], p[IDX_KCUB + k]);
            d.stiffness[j] = if klin == f64::INFINITY {
                None
            } else {
                Some(Stiffness { klin, kcub })
            };
        }
        Self::new(d)
    }
}

fn check_finite(key: String, v: f64, unit: &str) -> Result<(), ModelError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(
            key,
            format!("must be a finite number ({unit}), got {v}"),
        ))
    }
}

fn validate(d: &ModelFile) -> Result<(), ModelError> {
    for (j, row) in d.dh.iter().enumerate() {
        let k = |f: &str| format!("dh[{j}].{f}");
        check_finite(k("a"), row.a, "m")?;
        check_finite(k("d"), row.d, "m")?;
        check_finite(k("alpha"), row.alpha, "rad")?;
        check_finite(k("theta_offset"), row.theta_offset, "rad")?;
        if (row.alpha - PA10_ALPHA[j]).abs() > 1e-9 {
            return Err(invalid(
                k("alpha"),
                format!(
                    "the PA10-6C structure needs {:.10} rad here, got {}; put small errors in `departures`",
                    PA10_ALPHA[j], row.alpha
                ),
            ));
        }
        if (row.theta_offset - PA10_OFFSET[j]).abs() > 1e-9 {
            return Err(invalid(
                k("theta_offset"),
                format!(
                    "the PA10-6C structure needs {:.10} rad here, got {}; put small errors in `departures`",
                    PA10_OFFSET[j], row.theta_offset
                ),
            ));
        }
        for (name, v, nonzero) in [
            ("a", row.a, PA10_A_NONZERO[j]),
            ("d", row.d, PA10_D_NONZERO[j]),
        ] {
            if nonzero && !(v > 0.0 && v < 2.0) {
                return Err(invalid(
                    k(name),
                    format!("must be a positive length below 2 m, got {v} m"),
                ));
            }
            if !nonzero && v != 0.0 {
                return Err(invalid(
                    k(name),
                    format!(
                        "must be 0 in the PA10-6C structure, got {v} m; put small errors in `departures`"
                    ),
                ));
            }
        }
    }
    for (j, e) in d.departures.iter().enumerate() {
        let k = |f: &str| format!("departures[{j}].{f}");
        for (name, v, unit, max) in [
            ("da", e.da, "m", MAX_LENGTH_DEPARTURE),
            ("dd", e.dd, "m", MAX_LENGTH_DEPARTURE),
            ("dalpha", e.dalpha, "rad", MAX_ANGLE_DEPARTURE),
            ("dbeta", e.dbeta, "rad", MAX_ANGLE_DEPARTURE),
            ("dtheta", e.dtheta, "rad", MAX_ANGLE_DEPARTURE),
        ] {
            check_finite(k(name), v, unit)?;
            if v.abs() > max {
                return Err(invalid(
                    k(name),
                    format!("|{v}| {unit} exceeds {max} {unit}: departures are small corrections"),
                ));
            }
        }
        if j == HAYATI_JOINT && e.dd != 0.0 {
            return Err(invalid(
                k("dd"),
                "joint 2 is parallel to joint 3: its d departure is replaced by Hayati's `dbeta` (paper II-C)",
            ));
        }
        if j != HAYATI_JOINT && e.dbeta != 0.0 {
            return Err(invalid(
                k("dbeta"),
                "Hayati's beta departure exists only on joint 2 (index 1)",
            ));
        }
    }
    for (j, s) in d.stiffness.iter().enumerate() {
        if let Some(s) = s {
            if !(s.klin.is_finite() && s.klin > 0.0) {
                return Err(invalid(
                    format!("stiffness[{j}].klin"),
                    format!("must be a finite stiffness > 0 N·m/rad, got {}", s.klin),
                ));
            }
            if !(s.kcub.is_finite() && s.kcub >= 0.0) {
                return Err(invalid(
                    format!("stiffness[{j}].kcub"),
                    format!("must be a finite stiffness ≥ 0 N·m/rad³, got {}", s.kcub),
                ));
            }
        }
    }
    for (j, e) in d.joint_errors.iter().enumerate() {
        if let Some(e) = e {
            e.validate(&format!("joint_errors[{j}]"))
                .map_err(|(key, reason)| invalid(key, reason))?;
        }
    }
    for (j, f) in d.friction.iter().enumerate() {
        if let Some(f) = f {
            f.validate(&format!("friction[{j}]"))
                .map_err(|(key, reason)| invalid(key, reason))?;
        }
    }
    if let Some(u) = &d.uncertainty {
        u.validate().map_err(|(key, reason)| invalid(key, reason))?;
    }
    frame_from_data("tool", &d.tool)?;
    frame_from_data("base_from_instrument", &d.base_from_instrument)?;
    for (i, g) in d.gravity.iter().enumerate() {
        check_finite(format!("gravity[{i}]"), *g, "m/s²")?;
    }
    if d.bodies.len() > MAX_BODIES {
        return Err(invalid(
            "bodies",
            format!("at most {MAX_BODIES} bodies, got {}", d.bodies.len()),
        ));
    }
    for (i, b) in d.bodies.iter().enumerate() {
        let k = |f: &str| format!("bodies[{i}].{f}");
        if !(1..=6).contains(&b.frame) {
            return Err(invalid(
                k("frame"),
                format!("must be a DH frame 1…6, got {}", b.frame),
            ));
        }
        if !(b.mass.is_finite() && b.mass >= 0.0) {
            return Err(invalid(
                k("mass"),
                format!("must be a finite mass ≥ 0 kg, got {}", b.mass),
            ));
        }
        for (c, v) in b.com.iter().enumerate() {
            check_finite(format!("bodies[{i}].com[{c}]"), *v, "m")?;
        }
    }
    let l = &d.joint_limits;
    for j in 0..6 {
        check_finite(format!("joint_limits.lower[{j}]"), l.lower[j], "rad")?;
        check_finite(format!("joint_limits.upper[{j}]"), l.upper[j], "rad")?;
        if l.lower[j] >= l.upper[j] {
            return Err(invalid(
                format!("joint_limits.upper[{j}]"),
                format!(
                    "must exceed the lower limit {} rad, got {} rad",
                    l.lower[j], l.upper[j]
                ),
            ));
        }
        if !(l.velocity[j].is_finite() && l.velocity[j] > 0.0) {
            return Err(invalid(
                format!("joint_limits.velocity[{j}]"),
                format!("must be a finite speed > 0 rad/s, got {}", l.velocity[j]),
            ));
        }
    }
    Ok(())
}
