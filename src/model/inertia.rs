//! The inertia each joint's drive moves, from the model's bodies as point masses and a payload
//! at the tool (kg·m², about each joint axis, link side). The control loop schedules its gain on
//! it: a drive's speed loop slows as the inertia it moves grows, and a position loop around it
//! tuned for the bare arm then drives the arm's link mode (docs/daemon.md). Point masses give
//! the part that configuration and payload change; the links' own rotational inertia and the
//! rotors' are not in the model.

use nalgebra::{Point3, Vector3};

use super::robot::Model;

impl Model {
    /// Per joint, the inertia (kg·m²) about its axis at link angles `q` (rad) of the bodies it
    /// carries (point masses at their centres) and a payload of `payload_kg` (≥ 0) at
    /// `payload_com` (tool frame, m). Allocation-free.
    ///
    /// ```
    /// use pa10::model::Model;
    /// let m = Model::nominal();
    /// let bent = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
    /// let stretched = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0];
    /// let i = |q, kg| m.link_inertia(q, kg, &[0.0; 3])[1];
    /// // a payload adds more to the shoulder's inertia the farther out the tool is
    /// assert!(i(&stretched, 9.0) - i(&stretched, 0.0) > i(&bent, 9.0) - i(&bent, 0.0));
    /// ```
    pub fn link_inertia(&self, q: &[f64; 6], payload_kg: f64, payload_com: &[f64; 3]) -> [f64; 6] {
        let f = self.frames(q);
        let p_load = (f[6] * self.tool * Point3::from(Vector3::from(*payload_com))).coords;
        let kg = payload_kg.max(0.0);
        std::array::from_fn(|j| {
            let z = f[j].rotation.matrix().column(2).into_owned();
            let o = f[j].translation.vector;
            let arm = |p: &Vector3<f64>| z.cross(&(p - o)).norm_squared();
            let bodies: f64 = self.masses[..self.n_masses]
                .iter()
                .filter(|m| m.frame > j)
                .map(|m| m.mass * arm(&(f[m.frame] * Point3::from(m.com)).coords))
                .sum();
            bodies + kg * arm(&p_load)
        })
    }
}
