//! The library of candidate effects: what each one is called, what its parameters mean
//! (with units), and how it changes the predicted pose.
//!
//! Every effect's parameters live in one flat
//! [`EffectState`](super::forward::EffectState) (zero means "absent"), addressed by [`Slot`]s,
//! so that fitting a model with any set of effects is one least-squares problem over a list
//! of slots. [`predict`](super::forward::predict) is the forward model:
//!
//! 1. joint side: `q_link = q_motor − δ(τ) − e(q_motor) − (b/2)·dir` — compliance (linear
//!    `c·τ` or linear + cubic spring), transmission error, eccentricity, backlash
//!    ([`JointError`](crate::model::JointError), shared with the run-time
//!    [`Model`](crate::model::Model));
//! 2. the geometry (DH with departures, Hayati β) at those link angles;
//! 3. small rigid changes inserted along the chain from the flange back to the base: tool
//!    offset at the flange, thermal growth of a link along its axis, bending of a link about
//!    its midpoint by `c·M⊥` (M⊥: the bending moment it carries), base-frame error.

use crate::model::params::{IDX_D, IDX_THETA};

/// Links (DH rows, zero-based) whose length can grow with temperature: the shoulder column
/// d1, upper arm a2, forearm d4 and wrist d6.
pub const THERMAL_LINKS: [usize; 4] = [0, 1, 3, 5];
/// Links (DH rows, zero-based) that can bend: the upper arm (row 2) and forearm (row 4).
pub const BENDING_LINKS: [usize; 2] = [1, 3];
/// Human names of the links by DH row.
pub const LINK_NAMES: [&str; 6] = [
    "shoulder column (d1)",
    "upper arm (a2)",
    "elbow (row 3)",
    "forearm (d4)",
    "wrist (row 5)",
    "wrist flange (d6)",
];

/// The kinds of candidate effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// A linear spring on a joint the model holds rigid: `δ = c·τ`.
    JointComplianceLinear,
    /// A cubic term on a joint with a linear spring: `τ = Klin·δ + Kcub·δ³`.
    JointComplianceCubic,
    /// Harmonic-drive transmission error: first and second harmonics per output revolution
    /// and per wave-generator revolution.
    TransmissionError,
    /// Lost motion depending on the approach direction.
    Backlash,
    /// A link's length changing with temperature (or by a single factor without one).
    ThermalExpansion,
    /// A link bending under the moment it carries.
    LinkBending,
    /// A once-per-revolution sinusoid in a joint's link angle.
    EncoderEccentricity,
    /// A mass at the tool that the load figures miss.
    PayloadMassError,
    /// A wrong flange → target translation.
    ToolOffsetError,
    /// A wrong instrument → base placement.
    BaseFrameError,
    /// A DH departure the model does not fit.
    GeometricDeparture,
    /// A transmission whose ratio is off by a relative `s`: the link angle is off by `s·q`.
    GearRatioError,
    /// A tool or fixture that sags along gravity in proportion to the hung load, m/N.
    ToolSag,
    /// Outside the library: one term `δq = c·φ` of a sparse dictionary per joint (φ: q²,
    /// q³, sin q, cos q, sin 2q, cos 2q of the joint's angle, or its approach direction),
    /// tried only when the library is exhausted and the lack of fit stays significant.
    Generic,
}

/// The generic dictionary of one joint: the functions `φ` of [`Kind::Generic`] with the
/// joint-error slot that holds each coefficient, its name and unit.
pub const GENERIC_BASIS: [(&str, usize, &str, &str); 7] = [
    ("q²", 11, "quadratic in its angle", "rad/rad²"),
    ("q³", 12, "cubic in its angle", "rad/rad³"),
    ("sin q", 0, "once per revolution of its angle (sin)", "rad"),
    ("cos q", 1, "once per revolution of its angle (cos)", "rad"),
    (
        "sin 2q",
        2,
        "twice per revolution of its angle (sin)",
        "rad",
    ),
    (
        "cos 2q",
        3,
        "twice per revolution of its angle (cos)",
        "rad",
    ),
    ("dir", 10, "the approach direction", "rad"),
];

impl Kind {
    /// Every kind, in library order.
    pub const ALL: [Kind; 14] = [
        Kind::JointComplianceLinear,
        Kind::JointComplianceCubic,
        Kind::TransmissionError,
        Kind::Backlash,
        Kind::ThermalExpansion,
        Kind::LinkBending,
        Kind::EncoderEccentricity,
        Kind::PayloadMassError,
        Kind::ToolOffsetError,
        Kind::BaseFrameError,
        Kind::GeometricDeparture,
        Kind::GearRatioError,
        Kind::ToolSag,
        Kind::Generic,
    ];

    /// The stable machine name (used in JSON, model files and on the command line).
    pub fn name(self) -> &'static str {
        match self {
            Kind::JointComplianceLinear => "joint_compliance_linear",
            Kind::JointComplianceCubic => "joint_compliance_cubic",
            Kind::TransmissionError => "transmission_error",
            Kind::Backlash => "backlash",
            Kind::ThermalExpansion => "thermal_expansion",
            Kind::LinkBending => "link_bending",
            Kind::EncoderEccentricity => "encoder_eccentricity",
            Kind::PayloadMassError => "payload_mass_error",
            Kind::ToolOffsetError => "tool_offset_error",
            Kind::BaseFrameError => "base_frame_error",
            Kind::GeometricDeparture => "geometric_departure",
            Kind::GearRatioError => "gear_ratio_error",
            Kind::ToolSag => "tool_sag",
            Kind::Generic => "generic",
        }
    }

    /// The kind with machine name `name`.
    pub fn from_name(name: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Prior plausibility on an arm like the PA10, 0 most plausible: used only to choose
    /// among look-alikes that pass every test and that the held-out data cannot tell apart.
    /// Harmonic-drive springs and periodic errors dominate a PA10's compliance and
    /// repeatable error (the seed paper); geometry and frames come next; a cast link's
    /// bending, thermal growth, a payload error and unnamed terms last.
    pub fn plausibility(self) -> u8 {
        match self {
            Kind::JointComplianceLinear | Kind::JointComplianceCubic => 0,
            Kind::TransmissionError
            | Kind::EncoderEccentricity
            | Kind::Backlash
            | Kind::GearRatioError => 1,
            Kind::ToolOffsetError | Kind::BaseFrameError | Kind::GeometricDeparture => 2,
            Kind::LinkBending | Kind::ThermalExpansion | Kind::PayloadMassError | Kind::ToolSag => {
                3
            }
            Kind::Generic => 4,
        }
    }

    /// Why [`Kind::plausibility`] ranks it where it does, in words.
    pub fn plausibility_reason(self) -> &'static str {
        match self.plausibility() {
            0 => "a harmonic drive's spring: the PA10's dominant compliance",
            1 => "a periodic or lost-motion error of a joint's drive",
            2 => "a geometric or frame error",
            3 => "a link or load effect, smaller than a drive's on this arm",
            _ => "an unnamed term",
        }
    }

    /// A one-line human description.
    pub fn description(self) -> &'static str {
        match self {
            Kind::JointComplianceLinear => {
                "linear joint spring: the link lags the motor by c·τ (c in rad/(N·m))"
            }
            Kind::JointComplianceCubic => {
                "hardening joint spring: τ = Klin·δ + Kcub·δ³ (Kcub in N·m/rad³)"
            }
            Kind::TransmissionError => {
                "harmonic-drive transmission error: sin/cos of q, 2q, N·q, 2N·q (rad), N the gear ratio"
            }
            Kind::Backlash => {
                "lost motion b (rad): the link trails the motor by b/2 in the approach direction"
            }
            Kind::ThermalExpansion => {
                "link length L·(1 + α·(T − T_ref)) with a temperature column (α in 1/K), else L·(1 + s)"
            }
            Kind::LinkBending => {
                "link bending: rotation c·M⊥ (rad, c in rad/(N·m)) about the link's midpoint"
            }
            Kind::EncoderEccentricity => "encoder eccentricity: sin/cos of the link angle (rad)",
            Kind::PayloadMassError => "an unaccounted mass at the tool (kg), loading the links",
            Kind::ToolOffsetError => "flange → target translation error (m, flange frame)",
            Kind::BaseFrameError => "instrument → base frame error (m, rad)",
            Kind::GeometricDeparture => "a DH departure the model keeps fixed (m or rad)",
            Kind::GearRatioError => {
                "gear-ratio (scale) error: the link angle is off by s·q (s in rad/rad)"
            }
            Kind::ToolSag => {
                "a tool or fixture that sags along gravity by c·load (c in m/N): a compliance outside the joints"
            }
            Kind::Generic => {
                "an unnamed term outside the library: the link angle off by c·φ (rad), φ a function of the joint's angle or its approach direction"
            }
        }
    }
}

/// One candidate: a kind applied to a joint, a link or a DH parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Effect {
    /// What it is.
    pub kind: Kind,
    /// Zero-based joint / DH row for per-joint and per-link kinds; for
    /// [`Kind::GeometricDeparture`] the index 0…23 of the departure in the
    /// [`ParamVector`](crate::model::ParamVector) layout; for [`Kind::Generic`]
    /// `joint + 6·b` with `b` the index in [`GENERIC_BASIS`]; `None` for whole-arm kinds.
    pub target: Option<usize>,
}

/// A parameter of an effect: name and unit.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    /// Name, e.g. `out1_sin`.
    pub name: String,
    /// SI unit.
    pub unit: &'static str,
}

fn spec(name: &str, unit: &'static str) -> ParamSpec {
    ParamSpec {
        name: name.to_string(),
        unit,
    }
}

/// Names of the joint-error components addressed by [`Slot::JointErr`] 0…12.
pub const JOINT_ERROR_PARAMS: [&str; 14] = [
    "out1_sin",
    "out1_cos",
    "out2_sin",
    "out2_cos",
    "wave1_sin",
    "wave1_cos",
    "wave2_sin",
    "wave2_cos",
    "ecc_sin",
    "ecc_cos",
    "backlash",
    "poly2",
    "poly3",
    "scale",
];

impl Effect {
    /// The joint or link this effect acts on, 1-based (for geometric departures, the joint
    /// of the DH parameter).
    pub fn joint(&self) -> Option<usize> {
        match self.kind {
            Kind::GeometricDeparture | Kind::Generic => self.target.map(|i| i % 6 + 1),
            _ => self.target.map(|j| j + 1),
        }
    }

    /// The joint (zero-based) whose *angle* the effect is a function of, for the kinds that
    /// are (transmission error, eccentricity, gear ratio, backlash, the generic basis): such
    /// an effect is seen only where the campaign turns that joint.
    pub fn angle_joint(&self) -> Option<usize> {
        match self.kind {
            Kind::TransmissionError
            | Kind::EncoderEccentricity
            | Kind::GearRatioError
            | Kind::Backlash => self.target,
            Kind::Generic => self.target.map(|t| t % 6),
            _ => None,
        }
    }

    /// `name[J3]`-style label.
    pub fn label(&self) -> String {
        match (self.kind, self.target) {
            (Kind::GeometricDeparture, Some(i)) => {
                format!("{}[{}]", self.kind.name(), crate::model::param_names()[i])
            }
            (Kind::Generic, Some(i)) => {
                format!(
                    "{}[J{}: {}]",
                    self.kind.name(),
                    i % 6 + 1,
                    GENERIC_BASIS[i / 6].0
                )
            }
            (Kind::ThermalExpansion | Kind::LinkBending, Some(j)) => {
                format!("{}[link {}]", self.kind.name(), j + 1)
            }
            (_, Some(j)) => format!("{}[J{}]", self.kind.name(), j + 1),
            (_, None) => self.kind.name().to_string(),
        }
    }

    /// The state slots holding its parameters, in [`Effect::params`] order.
    pub fn slots(&self) -> Vec<Slot> {
        let t = self.target.unwrap_or(0);
        match self.kind {
            Kind::JointComplianceLinear => vec![Slot::Compliance(t)],
            Kind::JointComplianceCubic => vec![Slot::Kcub(t)],
            Kind::TransmissionError => (0..8).map(|k| Slot::JointErr(t, k)).collect(),
            Kind::EncoderEccentricity => vec![Slot::JointErr(t, 8), Slot::JointErr(t, 9)],
            Kind::Backlash => vec![Slot::JointErr(t, 10)],
            Kind::ThermalExpansion => vec![Slot::Thermal(t)],
            Kind::LinkBending => vec![Slot::Bending(t)],
            Kind::PayloadMassError => vec![Slot::Payload],
            Kind::ToolOffsetError => (0..3).map(Slot::Tool).collect(),
            Kind::BaseFrameError => (0..6).map(Slot::Base).collect(),
            Kind::GeometricDeparture => vec![Slot::Dep(t)],
            Kind::GearRatioError => vec![Slot::JointErr(t, 13)],
            Kind::ToolSag => vec![Slot::ToolSag],
            Kind::Generic => vec![Slot::JointErr(t % 6, GENERIC_BASIS[t / 6].1)],
        }
    }

    /// For a generic term: "δq2 ≈ c·q2² rad on J2, quadratic in its angle" at coefficient
    /// `c`; `None` for library effects.
    pub fn generic_form(&self, c: f64) -> Option<String> {
        let i = self.target.filter(|_| self.kind == Kind::Generic)?;
        let (j, (phi, _, words, _)) = (i % 6 + 1, GENERIC_BASIS[i / 6]);
        let phi = phi.replace('q', &format!("q{j}"));
        Some(format!("δq{j} ≈ {c:.3e}·{phi} rad on J{j}, {words}"))
    }

    /// Its parameters, with units (`thermal_per_kelvin`: whether the data carry
    /// temperatures).
    pub fn params(&self, thermal_per_kelvin: bool) -> Vec<ParamSpec> {
        match self.kind {
            Kind::JointComplianceLinear => vec![spec("compliance", "rad/(N·m)")],
            Kind::JointComplianceCubic => vec![spec("kcub", "N·m/rad³")],
            Kind::TransmissionError => JOINT_ERROR_PARAMS[..8]
                .iter()
                .map(|n| spec(n, "rad"))
                .collect(),
            Kind::EncoderEccentricity => vec![spec("sin", "rad"), spec("cos", "rad")],
            Kind::Backlash => vec![spec("backlash", "rad")],
            Kind::ThermalExpansion if thermal_per_kelvin => vec![spec("alpha", "1/K")],
            Kind::ThermalExpansion => vec![spec("factor", "1")],
            Kind::LinkBending => vec![spec("compliance", "rad/(N·m)")],
            Kind::PayloadMassError => vec![spec("mass", "kg")],
            Kind::ToolOffsetError => vec![spec("x", "m"), spec("y", "m"), spec("z", "m")],
            Kind::BaseFrameError => vec![
                spec("x", "m"),
                spec("y", "m"),
                spec("z", "m"),
                spec("rx", "rad"),
                spec("ry", "rad"),
                spec("rz", "rad"),
            ],
            Kind::GeometricDeparture => {
                let i = self.target.unwrap_or(0);
                vec![spec(
                    crate::model::param_names()[i],
                    crate::model::param_units()[i],
                )]
            }
            Kind::GearRatioError => vec![spec("scale", "rad/rad")],
            Kind::ToolSag => vec![spec("compliance", "m/N")],
            Kind::Generic => {
                let b = self.target.unwrap_or(0) / 6;
                vec![spec("coefficient", GENERIC_BASIS[b].3)]
            }
        }
    }

    /// Whether `pa10d` compensates it at run time once written into a model file.
    pub fn run_time(&self) -> bool {
        matches!(
            self.kind,
            Kind::JointComplianceLinear
                | Kind::JointComplianceCubic
                | Kind::TransmissionError
                | Kind::Backlash
                | Kind::EncoderEccentricity
                | Kind::ToolOffsetError
                | Kind::BaseFrameError
                | Kind::GeometricDeparture
                | Kind::GearRatioError
                | Kind::Generic
                | Kind::LinkBending
                | Kind::PayloadMassError
                | Kind::ToolSag
        )
    }
}

/// One scalar of an [`EffectState`](super::forward::EffectState).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Slot {
    /// Geometric departure, index 0…23 in the `ParamVector` layout.
    Dep(usize),
    /// Linear compliance of joint j (zero-based), rad/(N·m).
    Compliance(usize),
    /// Cubic stiffness of joint j, N·m/rad³.
    Kcub(usize),
    /// Joint-error component k (see [`JOINT_ERROR_PARAMS`]) of joint j, rad (rad/radⁿ for
    /// the polynomial and scale terms).
    JointErr(usize, usize),
    /// Base-frame correction: translation x, y, z (m), rotation x, y, z (rad), applied on
    /// the left of `base_from_instrument`.
    Base(usize),
    /// Thermal coefficient (1/K) or factor of DH row j.
    Thermal(usize),
    /// Bending compliance of DH row j, rad/(N·m).
    Bending(usize),
    /// Extra tool mass, kg.
    Payload,
    /// Tool offset component, m.
    Tool(usize),
    /// Sag of the tool along gravity per newton of hung load, m/N.
    ToolSag,
}

impl Slot {
    /// Typical size of the parameter: the unit of the scaled fit and of finite differences.
    pub fn scale(self) -> f64 {
        match self {
            Slot::Dep(_) => 1e-4,
            Slot::Compliance(_) => 1e-5,
            Slot::Kcub(_) => 1e7,
            Slot::JointErr(..) => 1e-4,
            Slot::Base(_) => 1e-4,
            Slot::Thermal(_) => 1e-5,
            Slot::Bending(_) => 1e-6,
            Slot::Payload => 0.1,
            Slot::Tool(_) => 1e-4,
            Slot::ToolSag => 1e-6,
        }
    }

    /// The joint (zero-based) whose link angle it adds to — a spring, a cubic stiffness or a
    /// joint error, per configuration — if any. (Not [`Effect::angle_joint`], the joint whose
    /// angle an effect is a function of: a spring adds to its link angle but is a function of
    /// the torque.)
    pub fn link_angle_joint(self) -> Option<usize> {
        match self {
            Slot::Compliance(j) | Slot::Kcub(j) | Slot::JointErr(j, _) => Some(j),
            _ => None,
        }
    }

    /// Whether changing it changes the geometry model (DH frames or base frame).
    pub fn geometric(self) -> bool {
        matches!(self, Slot::Dep(_) | Slot::Base(_))
    }
}

/// The slots of every candidate, library or generic, that acts on a joint's angle
/// ([`Slot::link_angle_joint`]), once each, for a model whose fitted slots are `fitted`.
pub fn angle_candidate_slots(fitted: &[Slot]) -> Vec<Slot> {
    let mut out: Vec<Slot> = Vec::new();
    for s in candidates(fitted, &[])
        .into_iter()
        .chain(generic_candidates(fitted))
        .flat_map(|e| e.slots())
    {
        if s.link_angle_joint().is_some() && !out.contains(&s) {
            out.push(s);
        }
    }
    out
}

/// Every candidate effect for a model whose fitted slots are `fitted` (effects already in
/// the model are not candidates). `geom_fixed` lists departures the model keeps fixed that
/// the data could see.
pub fn candidates(fitted: &[Slot], geom_fixed: &[usize]) -> Vec<Effect> {
    let has = |s: Slot| fitted.contains(&s);
    let mut out = Vec::new();
    for j in 0..6 {
        let e = |kind| Effect {
            kind,
            target: Some(j),
        };
        if !has(Slot::Compliance(j)) {
            out.push(e(Kind::JointComplianceLinear));
        } else if !has(Slot::Kcub(j)) {
            out.push(e(Kind::JointComplianceCubic));
        }
        if !has(Slot::JointErr(j, 0)) {
            out.push(e(Kind::TransmissionError));
        }
        if !has(Slot::JointErr(j, 10)) {
            out.push(e(Kind::Backlash));
        }
        if !has(Slot::JointErr(j, 8)) {
            out.push(e(Kind::EncoderEccentricity));
        }
        if !has(Slot::JointErr(j, 13)) {
            out.push(e(Kind::GearRatioError));
        }
    }
    for &j in &THERMAL_LINKS {
        if !has(Slot::Thermal(j)) {
            out.push(Effect {
                kind: Kind::ThermalExpansion,
                target: Some(j),
            });
        }
    }
    for &j in &BENDING_LINKS {
        if !has(Slot::Bending(j)) {
            out.push(Effect {
                kind: Kind::LinkBending,
                target: Some(j),
            });
        }
    }
    for (kind, slot) in [
        (Kind::PayloadMassError, Slot::Payload),
        (Kind::ToolOffsetError, Slot::Tool(0)),
        (Kind::ToolSag, Slot::ToolSag),
        (Kind::BaseFrameError, Slot::Base(0)),
    ] {
        if !has(slot) {
            out.push(Effect { kind, target: None });
        }
    }
    for &i in geom_fixed {
        if !has(Slot::Dep(i)) {
            out.push(Effect {
                kind: Kind::GeometricDeparture,
                target: Some(i),
            });
        }
    }
    out
}

/// The generic dictionary ([`Kind::Generic`]) for a model whose fitted slots are `fitted`:
/// every joint × every basis function whose slot is not fitted yet.
pub fn generic_candidates(fitted: &[Slot]) -> Vec<Effect> {
    (0..6 * GENERIC_BASIS.len())
        .map(|i| Effect {
            kind: Kind::Generic,
            target: Some(i),
        })
        .filter(|e| e.slots().iter().all(|s| !fitted.contains(s)))
        .collect()
}

/// Effects already in a model whose fitted slots are `fitted` (every slot of the effect
/// is fitted): reported as "already modelled", never candidates.
pub fn modelled(fitted: &[Slot]) -> Vec<Effect> {
    let mut all: Vec<Effect> = Vec::new();
    for kind in Kind::ALL {
        match kind {
            Kind::ThermalExpansion => all.extend(THERMAL_LINKS.iter().map(|&j| Effect {
                kind,
                target: Some(j),
            })),
            Kind::LinkBending => all.extend(BENDING_LINKS.iter().map(|&j| Effect {
                kind,
                target: Some(j),
            })),
            Kind::PayloadMassError
            | Kind::ToolOffsetError
            | Kind::BaseFrameError
            | Kind::ToolSag => all.push(Effect { kind, target: None }),
            Kind::GeometricDeparture => all.extend((0..24).map(|i| Effect {
                kind,
                target: Some(i),
            })),
            // Only the polynomial terms: the others share their slots with library kinds.
            Kind::Generic => all.extend((0..12).map(|i| Effect {
                kind,
                target: Some(i),
            })),
            _ => all.extend((0..6).map(|j| Effect {
                kind,
                target: Some(j),
            })),
        }
    }
    all.into_iter()
        .filter(|e| e.slots().iter().all(|s| fitted.contains(s)))
        .collect()
}

/// The departures a free base frame absorbs exactly (δd₁ along and δθ₁ about the J1 axis):
/// never fitted, never candidates, reported not identifiable.
pub const BASE_ABSORBED: [usize; 2] = [IDX_D, IDX_THETA];
