//! The forward model of discovery: every effect's parameters in one flat [`EffectState`]
//! (zero means absent) and [`predict`], the pose an observation ([`Obs`]: resolver angles,
//! torques, load, approach direction, temperature) should show under that state. The
//! effects' names, parameters and candidate rules are [`super::effects`]'s; this file owns
//! only the arithmetic.

use nalgebra::{Rotation3, Translation3, Vector3, Vector6};

use super::effects::Slot;
use crate::model::params::HAYATI_JOINT;
use crate::model::{
    Frame, JointError, LoadEffects, Model, ModelError, ModelFile, Stiffness, displace_by_load,
    pose_error,
};

/// Every parameter of every effect, plus the model's geometry; zero means absent.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectState {
    /// Geometry: DH, departures, tool, base frame, masses, limits (springs and joint
    /// errors are held below instead).
    pub geom: ModelFile,
    /// Linear compliance per joint, rad/(N·m) (0: rigid).
    pub compliance: [f64; 6],
    /// Cubic stiffness per joint, N·m/rad³.
    pub kcub: [f64; 6],
    /// Transmission error, eccentricity and backlash per joint.
    pub joint_err: [JointError; 6],
    /// Base-frame correction (see [`Slot::Base`]).
    pub base: [f64; 6],
    /// Thermal coefficient (1/K) or factor per DH row.
    pub thermal: [f64; 6],
    /// Bending compliance per DH row, rad/(N·m).
    pub bending: [f64; 6],
    /// Extra tool mass, kg.
    pub payload_kg: f64,
    /// Tool offset in the flange frame, m.
    pub tool_offset: [f64; 3],
    /// Sag of the tool along gravity per newton of hung load, m/N.
    pub tool_sag: f64,
}

impl EffectState {
    /// The state of `model`: its geometry, springs, joint errors and compensated load
    /// effects (tool sag, link bending, tool mass); every other effect zero. `gear_ratio` is
    /// used for joints without joint errors.
    pub fn from_model(model: &Model, gear_ratio: f64) -> Self {
        let d = model.data();
        let mut compliance = [0.0; 6];
        let mut kcub = [0.0; 6];
        for j in 0..6 {
            if let Some(s) = d.stiffness[j] {
                compliance[j] = 1.0 / s.klin;
                kcub[j] = s.kcub;
            }
        }
        let joint_err = std::array::from_fn(|j| {
            d.joint_errors[j].unwrap_or(JointError {
                gear_ratio,
                ..Default::default()
            })
        });
        let mut geom = d.clone();
        geom.stiffness = [None; 6];
        geom.joint_errors = [None; 6];
        geom.discovered.clear();
        let load = model.load_effects();
        Self {
            geom,
            compliance,
            kcub,
            joint_err,
            base: [0.0; 6],
            thermal: [0.0; 6],
            bending: load.bending,
            payload_kg: load.payload_kg,
            tool_offset: [0.0; 3],
            tool_sag: load.tool_sag,
        }
    }

    /// The value in `slot`.
    pub fn get(&self, slot: Slot) -> f64 {
        match slot {
            Slot::Dep(i) => dep_ref(&self.geom, i),
            Slot::Compliance(j) => self.compliance[j],
            Slot::Kcub(j) => self.kcub[j],
            Slot::JointErr(j, k) => *je_ref(&self.joint_err[j], k),
            Slot::Base(k) => self.base[k],
            Slot::Thermal(j) => self.thermal[j],
            Slot::Bending(j) => self.bending[j],
            Slot::Payload => self.payload_kg,
            Slot::Tool(k) => self.tool_offset[k],
            Slot::ToolSag => self.tool_sag,
        }
    }

    /// Sets `slot` to `v`.
    pub fn set(&mut self, slot: Slot, v: f64) {
        match slot {
            Slot::Dep(i) => set_dep(&mut self.geom, i, v),
            Slot::Compliance(j) => self.compliance[j] = v,
            Slot::Kcub(j) => self.kcub[j] = v,
            Slot::JointErr(j, k) => *je_mut(&mut self.joint_err[j], k) = v,
            Slot::Base(k) => self.base[k] = v,
            Slot::Thermal(j) => self.thermal[j] = v,
            Slot::Bending(j) => self.bending[j] = v,
            Slot::Payload => self.payload_kg = v,
            Slot::Tool(k) => self.tool_offset[k] = v,
            Slot::ToolSag => self.tool_sag = v,
        }
    }

    /// The state's load effects outside the joints (tool sag, link bending, tool mass).
    pub fn load_effects(&self) -> LoadEffects {
        LoadEffects {
            tool_sag: self.tool_sag,
            bending: self.bending,
            payload_kg: self.payload_kg,
        }
    }

    /// The geometry as a rigid [`Model`] with the base correction folded in.
    pub fn geometry(&self) -> Result<Model, ModelError> {
        let mut d = self.geom.clone();
        let base = crate::model::frame_from_pose(
            d.base_from_instrument.translation,
            d.base_from_instrument.quaternion,
        );
        d.base_from_instrument = (&(base_correction(&self.base) * base)).into();
        Model::new(d)
    }

    /// The whole state as a model file the daemon loads: geometry (tool offset and base
    /// correction folded in), springs of every compliant joint, joint errors. Effects outside
    /// the joints (thermal, bending, tool mass, tool sag) are left out here; the caller records
    /// them in `discovered` (the load effects' ranges are checked here all the same).
    pub fn to_model(&self) -> Result<Model, ModelError> {
        // the load effects' own ranges (written as records by the caller), checked here so
        // a refit beyond them is a failed fit, never an aborted run
        self.load_effects()
            .check()
            .map_err(|(key, reason)| ModelError::Invalid { key, reason })?;
        let mut d = self.geometry()?.data().clone();
        let tool = crate::model::frame_from_pose(d.tool.translation, d.tool.quaternion);
        let off = Translation3::new(
            self.tool_offset[0],
            self.tool_offset[1],
            self.tool_offset[2],
        );
        d.tool = (&(Frame::from_parts(off, Rotation3::identity()) * tool)).into();
        for j in 0..6 {
            d.stiffness[j] = (self.compliance[j] > 0.0).then(|| Stiffness {
                klin: 1.0 / self.compliance[j],
                kcub: self.kcub[j].max(0.0),
            });
            let e = self.joint_err[j];
            let zero = JointError {
                gear_ratio: e.gear_ratio,
                ..Default::default()
            };
            let mut e = e;
            e.backlash = e.backlash.max(0.0);
            d.joint_errors[j] = (e != zero).then_some(e);
        }
        Model::new(d)
    }
}

/// The base correction of [`Slot::Base`] as a transform.
pub fn base_correction(b: &[f64; 6]) -> Frame {
    Frame::from_parts(
        Translation3::new(b[0], b[1], b[2]),
        Rotation3::new(Vector3::new(b[3], b[4], b[5])),
    )
}

fn dep_ref(d: &ModelFile, i: usize) -> f64 {
    let j = i % 6;
    let e = &d.departures[j];
    match i / 6 {
        0 => e.da,
        1 => e.dalpha,
        2 if j == HAYATI_JOINT => e.dbeta,
        2 => e.dd,
        _ => e.dtheta,
    }
}

fn set_dep(d: &mut ModelFile, i: usize, v: f64) {
    let j = i % 6;
    let e = &mut d.departures[j];
    match i / 6 {
        0 => e.da = v,
        1 => e.dalpha = v,
        2 if j == HAYATI_JOINT => e.dbeta = v,
        2 => e.dd = v,
        _ => e.dtheta = v,
    }
}

fn je_ref(e: &JointError, k: usize) -> &f64 {
    match k {
        0..=3 => &e.output[k / 2][k % 2],
        4..=7 => &e.wave[(k - 4) / 2][k % 2],
        8 | 9 => &e.eccentricity[k - 8],
        11 | 12 => &e.polynomial[k - 11],
        13 => &e.scale,
        _ => &e.backlash,
    }
}

fn je_mut(e: &mut JointError, k: usize) -> &mut f64 {
    match k {
        0..=3 => &mut e.output[k / 2][k % 2],
        4..=7 => &mut e.wave[(k - 4) / 2][k % 2],
        8 | 9 => &mut e.eccentricity[k - 8],
        11 | 12 => &mut e.polynomial[k - 11],
        13 => &mut e.scale,
        _ => &mut e.backlash,
    }
}

/// One measurement, ready for the forward model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obs {
    /// Resolver (motor-side) angles, rad.
    pub q: [f64; 6],
    /// Joint torques, N·m.
    pub tau: [f64; 6],
    /// Load hung at the tool, N.
    pub load_n: f64,
    /// Approach direction per joint (−1, 0, +1).
    pub dir: [f64; 6],
    /// Thermal regressor: `T − T_ref` (K) with temperatures, else 1 (a factor).
    pub thermal: f64,
    /// Measured target pose in the instrument frame.
    pub meas: Frame,
}

/// Deflection of a joint with compliance `c` (rad/(N·m)) and cubic stiffness `kcub`
/// under torque `tau` (N·m), rad.
#[inline]
pub fn deflection(c: f64, kcub: f64, tau: f64) -> f64 {
    if kcub != 0.0 && c > 0.0 {
        Stiffness {
            klin: 1.0 / c,
            kcub: kcub.max(0.0),
        }
        .deflection(tau)
            + if kcub < 0.0 {
                // A negative cubic term (softening) only as a small perturbation, so the
                // fit stays smooth through zero.
                -kcub * (c * tau).powi(3) * c
            } else {
                0.0
            }
    } else {
        c * tau
    }
}

/// Link angles of `obs` under the state's joint-side effects, rad.
#[inline]
pub fn link_angles(s: &EffectState, obs: &Obs) -> [f64; 6] {
    std::array::from_fn(|j| {
        obs.q[j]
            - deflection(s.compliance[j], s.kcub[j], obs.tau[j])
            - s.joint_err[j].offset(obs.q[j], obs.dir[j])
    })
}

/// What one prediction computed along the chain, kept so that the next one at a nearby
/// state (a finite-difference step) reuses what did not change, bit for bit: each joint's DH
/// angle with its sine and cosine (`[angle, sin, cos]`), and the DH frames.
#[derive(Debug, Clone, Copy)]
pub struct Near {
    trig: [[f64; 3]; 6],
    frames: [Frame; 7],
}

impl Near {
    /// One that matches no angle.
    pub fn none() -> Self {
        Self {
            trig: [[f64::NAN; 3]; 6],
            frames: [Frame::identity(); 7],
        }
    }
}

/// The predicted target pose in the robot base frame. `geom` must be
/// [`EffectState::geometry`] of `s`.
pub fn predict(s: &EffectState, geom: &Model, obs: &Obs) -> Frame {
    predict_near(s, geom, obs, &mut Near::none(), 0)
}

/// [`predict`] from `near` (what a prediction of this observation computed at a state whose
/// joints before `same` had this geometry): an angle's sine and cosine are reused where the
/// angle is the one it holds, the frames up to the first joint whose geometry or angle
/// differs; `near` is left holding this prediction's.
pub fn predict_near(
    s: &EffectState,
    geom: &Model,
    obs: &Obs,
    near: &mut Near,
    same: usize,
) -> Frame {
    let q = link_angles(s, obs);
    let mut from = same;
    for (j, t) in near.trig.iter_mut().enumerate() {
        let x = geom.dh_angle(j, q[j]);
        if x.to_bits() != t[0].to_bits() {
            let (sn, c) = x.sin_cos();
            *t = [x, sn, c];
            from = from.min(j);
        }
    }
    geom.frames_trig_from(&near.trig, &mut near.frames, from);
    let f = &near.frames;
    let off = Translation3::new(s.tool_offset[0], s.tool_offset[1], s.tool_offset[2]);
    let x = f[6] * Frame::from_parts(off, Rotation3::identity()) * *geom.tool();
    displace_by_load(
        geom,
        f,
        x,
        obs.load_n,
        &s.load_effects(),
        &s.thermal,
        obs.thermal,
    )
}

/// Residual of one observation: predicted minus measured pose (position m, orientation
/// rad) in the base frame, with `base` = `geom.base_from_instrument()`.
#[inline]
pub fn residual(s: &EffectState, geom: &Model, obs: &Obs) -> Vector6<f64> {
    residual_near(s, geom, obs, &mut Near::none(), 0)
}

/// [`residual`] through [`predict_near`].
#[inline]
pub fn residual_near(
    s: &EffectState,
    geom: &Model,
    obs: &Obs,
    near: &mut Near,
    same: usize,
) -> Vector6<f64> {
    let pred = predict_near(s, geom, obs, near, same);
    let meas = geom.base_from_instrument() * obs.meas;
    pose_error(&pred, &meas)
}
