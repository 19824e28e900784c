//! The arithmetic of a model's load effects outside the joints ([`LoadEffects`]): [`displace`],
//! shared by discovery's forward model and the daemon, the loaded forward kinematics
//! ([`Model::fk_loaded`]) and the link-angle correction ([`Model::load_correction`]) that
//! puts the tool where the rigid model's forward kinematics of a setpoint says despite them.

use nalgebra::{Matrix6, Point3, Rotation3, Translation3, Vector3};

use super::kinematics::{Frame, jacobian_from_frames, pose_error};
use super::load_effects::LoadEffects;
use super::robot::Model;

/// The unit vector along gravity (straight down when the model has none).
fn down(g: &Vector3<f64>) -> Vector3<f64> {
    if g.norm() > 0.0 {
        g / g.norm()
    } else {
        -Vector3::z()
    }
}

/// The bending moment (N·m, base frame) carried at point `p` by everything fixed to DH
/// frames ≥ `first_frame` and the tool force `force` at `p_tool`.
fn moment_at(
    geom: &Model,
    f: &[Frame; 7],
    p: &Vector3<f64>,
    first_frame: usize,
    p_tool: &Vector3<f64>,
    force: &Vector3<f64>,
) -> Vector3<f64> {
    let mut m = (p_tool - p).cross(force);
    for b in &geom.masses[..geom.n_masses] {
        if b.frame >= first_frame {
            let c = (f[b.frame] * Point3::from(b.com)).coords;
            m += (c - p).cross(&(geom.gravity * b.mass));
        }
    }
    m
}

/// Nominal length (m) of DH row `j` and its direction in the base frame: `a` along x of
/// frame j+1, `d` along z of frame j.
fn link_axis(geom: &Model, f: &[Frame; 7], j: usize) -> (f64, Vector3<f64>) {
    let row = &geom.data().dh[j];
    if row.a != 0.0 {
        (row.a, f[j + 1].rotation * Vector3::x())
    } else {
        (row.d, f[j].rotation * Vector3::z())
    }
}

/// Applies a rotation `theta` (rotation vector, base frame) about point `c` to `x`.
fn rotate_about(x: &Frame, c: &Vector3<f64>, theta: &Vector3<f64>) -> Frame {
    let r = Rotation3::new(*theta);
    Frame::from_parts(
        Translation3::from(r * (x.translation.vector - c) + c),
        r * x.rotation,
    )
}

/// The tool pose `x` (base frame, the rigid chain's at frames `f` of `geom`) displaced by
/// `e` under `load_n` (N hung at the tool) and by thermal growth `thermal[j]·thermal_reg`
/// of each DH row's length (discovery's; zero at run time): from the flange back to the
/// base, each bending rotation and length change moves everything distal of it, then the
/// tool sags along gravity.
pub fn displace(
    geom: &Model,
    f: &[Frame; 7],
    mut x: Frame,
    load_n: f64,
    e: &LoadEffects,
    thermal: &[f64; 6],
    thermal_reg: f64,
) -> Frame {
    let g = geom.gravity();
    let force = if e.bending.iter().any(|c| *c != 0.0) {
        down(&g) * load_n + g * e.payload_kg
    } else {
        Vector3::zeros()
    };
    let p_tool = x.translation.vector;
    for j in (0..6).rev() {
        if e.bending[j] != 0.0 {
            let (a, b) = (f[j].translation.vector, f[j + 1].translation.vector);
            let u = (b - a).normalize();
            let m = moment_at(geom, f, &a, j + 1, &p_tool, &force);
            let theta = (m - u * m.dot(&u)) * e.bending[j];
            x = rotate_about(&x, &(0.5 * (a + b)), &theta);
        }
        if thermal[j] != 0.0 {
            let (len, u) = link_axis(geom, f, j);
            x.translation.vector += u * (len * thermal[j] * thermal_reg);
        }
    }
    if e.tool_sag != 0.0 {
        x.translation.vector += down(&g) * (e.tool_sag * load_n);
    }
    x
}

/// Newton steps of [`Model::load_correction`]: the effects are a fraction of a millimetre,
/// so the third step leaves an error below 1e-9 m away from singularities.
const CORRECTION_STEPS: usize = 3;
/// Damping λ² of the correction's least-squares step (m², rad²): negligible where the
/// Jacobian's singular values are ≳ 0.05, a bound on the step near a singularity.
const CORRECTION_DAMPING: f64 = 1e-6;
/// Largest correction of any joint, rad: a sub-millimetre effect needs about a milliradian
/// away from singularities; near one the correction is scaled down to this.
pub const MAX_LOAD_CORRECTION: f64 = 0.005;

impl Model {
    /// The load effects outside the joints this model compensates.
    pub fn load_effects(&self) -> &LoadEffects {
        &self.load_effects
    }

    /// The tool pose (base frame) at link angles `q` (rad) with `load_n` (N) hung at the
    /// tool, the model's [`LoadEffects`] included.
    pub fn fk_loaded(&self, q: &[f64; 6], load_n: f64) -> Frame {
        let f = self.frames(q);
        let x = f[6] * self.tool;
        if self.load_effects.is_empty() {
            return x;
        }
        displace(self, &f, x, load_n, &self.load_effects, &[0.0; 6], 0.0)
    }

    /// The tool pose (base frame) the calibration predicts for one of its rows: the link
    /// angles from the resolvers' `q_motor` (rad) under the torques `tau` (N·m) held fixed,
    /// backlash centred, through the kinematics with `load_n` (N) hung at the tool and the
    /// model's [`LoadEffects`] — so that a model that bends, sags or carries an unaccounted
    /// mass outside its joints is fitted with them, not with its joints taking their place.
    #[inline]
    pub(crate) fn tool_at_rest(&self, q_motor: &[f64; 6], tau: &[f64; 6], load_n: f64) -> Frame {
        self.fk_loaded(&self.link_angles(q_motor, tau), load_n)
    }

    /// Link angles (rad) that put the tool, with `load_n` (N) hung at it and the model's
    /// [`LoadEffects`], where the rigid chain puts it at `q`: `q` itself when the model has
    /// none. The daemon applies it to every setpoint, so a setpoint means "the tool at
    /// `fk(q)`" whether it came from a pose or from joint angles. Allocation-free; near a
    /// singularity the damped step leaves the correction partial, and no joint's correction
    /// exceeds [`MAX_LOAD_CORRECTION`].
    ///
    /// ```
    /// use pa10::model::{EffectRecord, Model};
    /// let mut d = Model::nominal().data().clone();
    /// // 2 µm per N
    /// d.discovered.push(EffectRecord::compensated_one("tool_sag", None, "compliance", 2e-6));
    /// let m = Model::new(d).unwrap();
    /// let q = [0.1, 0.6, 1.2, 0.0, 1.0, 0.0];
    /// let (rigid, sagging) = (m.fk(&q), m.fk_loaded(&q, 90.0));
    /// assert!((rigid.translation.z - sagging.translation.z - 1.8e-4).abs() < 1e-12);
    /// let c = m.load_correction(&q, 90.0);
    /// let got = m.fk_loaded(&c, 90.0);
    /// assert!((got.translation.vector - rigid.translation.vector).norm() < 1e-9);
    /// ```
    pub fn load_correction(&self, q: &[f64; 6], load_n: f64) -> [f64; 6] {
        if self.load_effects.is_empty() || !load_n.is_finite() {
            return *q;
        }
        let target = self.fk(q);
        let mut c = *q;
        for _ in 0..CORRECTION_STEPS {
            let f = self.frames(&c);
            let x = displace(
                self,
                &f,
                f[6] * self.tool,
                load_n,
                &self.load_effects,
                &[0.0; 6],
                0.0,
            );
            let err = pose_error(&target, &x);
            // damped least squares: near a singularity the step stays bounded (and the
            // correction partial) instead of jumping
            let jac = jacobian_from_frames(&f, &x.translation.vector);
            let jjt = jac * jac.transpose() + Matrix6::identity() * CORRECTION_DAMPING;
            let Some(w) = jjt.lu().solve(&err) else {
                break;
            };
            let step = jac.transpose() * w;
            if !step.iter().all(|v| v.is_finite()) {
                break;
            }
            for j in 0..6 {
                c[j] += step[j];
            }
        }
        let largest = (0..6).map(|j| (c[j] - q[j]).abs()).fold(0.0, f64::max);
        if largest > MAX_LOAD_CORRECTION {
            let k = MAX_LOAD_CORRECTION / largest;
            for j in 0..6 {
                c[j] = q[j] + k * (c[j] - q[j]);
            }
        }
        c
    }
}
