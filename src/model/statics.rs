//! Static joint torques (gravity of the links plus an external force at the tool) and the
//! compliance relation between link-side and motor-side joint angles: one
//! [`Model::compensate`] (link → motor, the per-cycle step) and its exact inverse
//! [`Model::link_from_motor`], both with the model's springs and joint errors.

use nalgebra::Vector3;

use super::kinematics::Frame;
use super::robot::{Model, ModelError};

/// An external force acting at a point of the tool frame (its origin unless said), newtons,
/// base frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExternalLoad {
    /// Force on the robot, N, base frame.
    pub force: Vector3<f64>,
    /// Where it acts, in the tool frame, m (a payload's centre of mass; zero: the tool origin).
    pub at: Vector3<f64>,
}

impl ExternalLoad {
    /// No external force.
    pub const NONE: Self = Self {
        force: Vector3::new(0.0, 0.0, 0.0),
        at: Vector3::new(0.0, 0.0, 0.0),
    };

    /// A weight of `newtons` (≥ 0) hung at the tool, pulling along `gravity` (the model's
    /// gravity vector, any length ≠ 0): the paper's 0 / 22 / 44 / 90 N loads.
    pub fn hung(newtons: f64, gravity: &Vector3<f64>) -> Self {
        let n = gravity.norm();
        let dir = if n > 0.0 {
            gravity / n
        } else {
            Vector3::new(0.0, 0.0, -1.0)
        };
        Self {
            force: dir * newtons,
            at: Vector3::zeros(),
        }
    }

    /// A weight of `newtons` whose centre of mass is at `com` in the tool frame (m).
    pub fn hung_at(newtons: f64, gravity: &Vector3<f64>, com: &[f64; 3]) -> Self {
        Self {
            at: Vector3::from(*com),
            ..Self::hung(newtons, gravity)
        }
    }
}

/// Largest number of fixed-point iterations when link angles are solved from motor
/// angles with configuration-dependent (gravity) torques.
const MAX_FIXED_POINT: usize = 50;

impl Model {
    /// The joint torques (N·m) the drives apply to hold the arm static at link angles `q`
    /// (rad) with `load` at the tool: `τ = −Σ_b J_bᵀ·(m_b·g) − J_toolᵀ·F`, with `J_b` the
    /// positional Jacobian of body b's centre of mass. Positive along each joint axis.
    ///
    /// ```
    /// use pa10::model::{ExternalLoad, Model};
    /// let m = Model::nominal();
    /// // Upright, gravity acts through the joint axes: no torque on any joint.
    /// let t = m.static_torques(&[0.0; 6], &ExternalLoad::NONE);
    /// assert!(t.iter().all(|x| x.abs() < 1e-12));
    /// ```
    pub fn static_torques(&self, q: &[f64; 6], load: &ExternalLoad) -> [f64; 6] {
        let f = self.frames(q);
        self.static_torques_at(&f, load)
    }

    /// [`Model::static_torques`] from already computed DH frames 0…6.
    #[inline]
    pub(crate) fn static_torques_at(&self, f: &[Frame; 7], load: &ExternalLoad) -> [f64; 6] {
        // Body weights as forces at their world centres of mass.
        let mut w = [(Vector3::zeros(), Vector3::zeros(), 0usize); super::robot::MAX_BODIES];
        for (slot, m) in w.iter_mut().zip(&self.masses[..self.n_masses]) {
            *slot = (
                (f[m.frame] * nalgebra::Point3::from(m.com)).coords,
                self.gravity * m.mass,
                m.frame,
            );
        }
        let p_tool = (f[6] * self.tool * nalgebra::Point3::from(load.at)).coords;
        let mut tau = [0.0; 6];
        for (j, t) in tau.iter_mut().enumerate() {
            let z = f[j].rotation.matrix().column(2).into_owned();
            let o = f[j].translation.vector;
            // Moment about the joint origin of every force the joint carries.
            let mut moment = (p_tool - o).cross(&load.force);
            for (c, wf, frame) in &w[..self.n_masses] {
                if *frame > j {
                    moment += (c - o).cross(wf);
                }
            }
            *t = -z.dot(&moment);
        }
        tau
    }

    /// Spring deflections `δ(τ)` (rad) of each joint under torques `tau` (N·m); zero for
    /// rigid joints.
    #[inline]
    pub fn deflections(&self, tau: &[f64; 6]) -> [f64; 6] {
        let mut d = [0.0; 6];
        for (j, dj) in d.iter_mut().enumerate() {
            if let Some(s) = self.data().stiffness[j] {
                *dj = s.deflection(tau[j]);
            }
        }
        d
    }

    /// Link angles from resolver angles under torques `tau` (N·m) held fixed, with the
    /// backlash centred: `q_motor − δ(τ) − e(q_motor)`. The calibration's inner loop (its
    /// rows are validated once, on load); everything else uses [`Model::link_from_motor`].
    #[inline]
    pub(crate) fn link_angles(&self, q_motor: &[f64; 6], tau: &[f64; 6]) -> [f64; 6] {
        self.link_angles_dir(q_motor, tau, &NO_DIRECTION)
    }

    #[inline]
    fn link_angles_dir(&self, q_motor: &[f64; 6], tau: &[f64; 6], dir: &[f64; 6]) -> [f64; 6] {
        let d = self.deflections(tau);
        let e = &self.data().joint_errors;
        std::array::from_fn(|j| {
            let off = e[j].map_or(0.0, |e| e.offset(q_motor[j], dir[j]));
            q_motor[j] - d[j] - off
        })
    }

    /// Motor angles that put the link at `q` under `tau`: solves
    /// `q_motor = q + δ(τ) + e(q_motor) + (b/2)·dir` (the periodic error `e` by fixed-point
    /// iteration, contracting because the model validates |e′| ≤ 0.5).
    #[inline]
    fn motor_angles_dir(&self, q: &[f64; 6], tau: &[f64; 6], dir: &[f64; 6]) -> [f64; 6] {
        let d = self.deflections(tau);
        let mut out: [f64; 6] = std::array::from_fn(|j| q[j] + d[j]);
        for (j, e) in self.data().joint_errors.iter().enumerate() {
            if let Some(e) = e {
                let base = out[j];
                let mut qm = base;
                for _ in 0..MAX_FIXED_POINT {
                    let next = base + e.offset(qm, dir[j]);
                    let step = (next - qm).abs();
                    qm = next;
                    if step < 1e-15 {
                        break;
                    }
                }
                out[j] = qm;
            }
        }
        out
    }

    /// **The compensation step**: the motor (resolver) angles that put the *link* at
    /// `q_link` (rad), `q_motor = q_link + δ(τ) + e(q_motor) + (b/2)·dir`, with
    ///
    /// - `δ(τ)` the spring deflections under the joint torques `torques` (N·m): given
    ///   (measured), or those of gravity and a load at `q_link` ([`Torques::Gravity`]);
    /// - `e` the joint errors of the model (transmission error, eccentricity, polynomial
    ///   terms) and `b` each joint's backlash, taken up on the side of `dir` (−1, 0, +1 per
    ///   joint: the direction the joint approaches from; 0 centres it, [`NO_DIRECTION`]).
    ///
    /// [`Model::link_from_motor`] is its exact inverse. Errors when an input is not finite;
    /// nothing else can fail.
    ///
    /// ```
    /// use pa10::model::{Model, NO_DIRECTION, Stiffness, Torques};
    /// let mut data = Model::nominal().data().clone();
    /// data.stiffness[1] = Some(Stiffness { klin: 1.98e4, kcub: 0.0 });
    /// let m = Model::new(data).unwrap();
    /// let tau = [0.0, 19.8, 0.0, 0.0, 0.0, 0.0];
    /// let c = m.compensate(&[0.0, 0.5, 0.0, 0.0, 0.0, 0.0], Torques::Given(&tau), &NO_DIRECTION).unwrap();
    /// assert!((c.q_motor[1] - 0.501).abs() < 1e-12); // 19.8 N·m / 1.98e4 N·m/rad = 1 mrad ahead
    /// let back = m.link_from_motor(&c.q_motor, Torques::Given(&tau), &NO_DIRECTION).unwrap();
    /// assert!((back.q_link[1] - 0.5).abs() < 1e-15);
    /// ```
    #[inline]
    pub fn compensate(
        &self,
        q_link: &[f64; 6],
        torques: Torques<'_>,
        dir: &[f64; 6],
    ) -> Result<Compensation, ModelError> {
        check_finite("q_link", q_link)?;
        check_finite("dir", dir)?;
        let tau = match torques {
            Torques::Given(t) => {
                check_finite("tau", t)?;
                *t
            }
            Torques::Gravity(load) => {
                check_load(load)?;
                self.static_torques(q_link, load)
            }
        };
        Ok(Compensation {
            q_motor: self.motor_angles_dir(q_link, &tau, dir),
            q_link: *q_link,
            tau,
        })
    }

    /// The inverse of [`Model::compensate`]: the link angles of resolver angles `q_motor`
    /// (rad), `q_link = q_motor − δ(τ) − e(q_motor) − (b/2)·dir`. With
    /// [`Torques::Gravity`] the torques depend on the (unknown) link configuration, so
    /// `q_link` is solved by fixed-point iteration to 1e-13 rad; the error says so when the
    /// joints are too compliant for the load to converge.
    pub fn link_from_motor(
        &self,
        q_motor: &[f64; 6],
        torques: Torques<'_>,
        dir: &[f64; 6],
    ) -> Result<Compensation, ModelError> {
        check_finite("q_motor", q_motor)?;
        check_finite("dir", dir)?;
        let load = match torques {
            Torques::Given(t) => {
                check_finite("tau", t)?;
                return Ok(Compensation {
                    q_motor: *q_motor,
                    q_link: self.link_angles_dir(q_motor, t, dir),
                    tau: *t,
                });
            }
            Torques::Gravity(load) => {
                check_load(load)?;
                load
            }
        };
        let mut q = *q_motor;
        for _ in 0..MAX_FIXED_POINT {
            let tau = self.static_torques(&q, load);
            let next = self.link_angles_dir(q_motor, &tau, dir);
            let step = (0..6).map(|j| (next[j] - q[j]).abs()).fold(0.0, f64::max);
            q = next;
            if step < 1e-13 {
                return Ok(Compensation {
                    q_motor: *q_motor,
                    q_link: q,
                    tau: self.static_torques(&q, load),
                });
            }
        }
        Err(ModelError::Invalid {
            key: "q_motor".into(),
            reason: format!(
                "link angles did not converge in {MAX_FIXED_POINT} iterations: the joints are too compliant for this load"
            ),
        })
    }
}

/// Where the joint torques of a compensation come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Torques<'a> {
    /// Known torques, N·m (e.g. motor currents × torque constants), held fixed.
    Given(&'a [f64; 6]),
    /// The model's gravity plus `load` at the tool, evaluated at the link configuration.
    Gravity(&'a ExternalLoad),
}

/// One point of the compensation relation: motor (resolver) angles, the link angles they
/// put the link at, and the joint torques in force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    /// Motor-side (resolver) angles, rad.
    pub q_motor: [f64; 6],
    /// Link-side angles, rad.
    pub q_link: [f64; 6],
    /// Joint torques, N·m.
    pub tau: [f64; 6],
}

/// No approach direction: every joint's backlash centred.
pub const NO_DIRECTION: [f64; 6] = [0.0; 6];

fn check_load(load: &ExternalLoad) -> Result<(), ModelError> {
    if load.force.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ModelError::Invalid {
            key: "load".into(),
            reason: "force must be finite (N)".into(),
        })
    }
}

fn check_finite(key: &str, v: &[f64; 6]) -> Result<(), ModelError> {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(j) => Err(ModelError::Invalid {
            key: format!("{key}[{j}]"),
            reason: format!("must be finite, got {}", v[j]),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_payloads_centre_of_mass_off_the_tool_axis_adds_its_lever_arm() {
        let m = Model::nominal();
        let q = [0.0; 6];
        let g = m.gravity();
        // upright and rigid-free: at the origin a hung load loads no joint …
        let at_origin = m.static_torques(&q, &ExternalLoad::hung(50.0, &g));
        assert!(at_origin.iter().all(|t| t.abs() < 1e-9), "{at_origin:?}");
        // … 0.1 m off along the tool x axis it is 5 N·m on every horizontal axis it crosses
        let off = m.static_torques(&q, &ExternalLoad::hung_at(50.0, &g, &[0.1, 0.0, 0.0]));
        let lever =
            (m.fk(&q) * nalgebra::Point3::new(0.1, 0.0, 0.0)).coords - m.fk(&q).translation.vector;
        let expect = 50.0 * lever.xy().norm();
        assert!((expect - 5.0).abs() < 1e-9);
        let loaded: Vec<f64> = off.iter().filter(|t| t.abs() > 1e-9).copied().collect();
        assert!(!loaded.is_empty(), "{off:?}");
        assert!(
            loaded.iter().all(|t| (t.abs() - expect).abs() < 1e-6),
            "{off:?}"
        );
    }
}
