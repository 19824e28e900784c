//! A position-only forward-kinematics kernel specialised for tiny joint perturbations.
//!
//! The Monte Carlo bound evaluates `p(q + δ)` a hundred million times with the same `q` and
//! |δ| of a few 1e-4 rad. Per point, the kernel stores `cos θ`, `sin θ` of every joint and the
//! constant link geometry; per draw it forms `cos(θ+δ)`, `sin(θ+δ)` by the angle-addition
//! identities with Taylor polynomials of `cos δ`, `sin δ` (exact to < 1e-19 for |δ| ≤ 0.05
//! rad; larger δ fall back to `sin_cos`), and pushes the tool point through the six DH
//! transforms from the flange down to the base. No allocation, no matrices.

use crate::model::Model;

/// Largest |δ| (rad) the Taylor path serves; beyond it `sin_cos` is called.
const TAYLOR_MAX: f64 = 0.05;

#[derive(Debug, Clone, Copy)]
struct JointConst {
    ct: f64,
    st: f64,
    a: f64,
    d: f64,
    ca: f64,
    sa: f64,
    cb: f64,
    sb: f64,
    theta: f64,
}

/// Precomputed data for one configuration.
#[derive(Debug, Clone, Copy)]
pub struct PositionKernel {
    j: [JointConst; 6],
    hayati: [bool; 6],
    tool: [f64; 3],
}

#[inline(always)]
fn cos_sin_small(d: f64) -> (f64, f64) {
    let d2 = d * d;
    // cos: 1 − d²/2 + d⁴/24 − d⁶/720 + d⁸/40320 ; sin: d(1 − d²/6 + d⁴/120 − d⁶/5040)
    let c = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24.0 + d2 * (-1.0 / 720.0 + d2 * (1.0 / 40320.0))));
    let s = d * (1.0 + d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0 + d2 * (-1.0 / 5040.0))));
    (c, s)
}

impl PositionKernel {
    /// Kernel for `model` at link angles `q` (rad); the tool point is the model's tool origin.
    pub fn new(model: &Model, q: &[f64; 6]) -> Self {
        let t = model.tool().translation.vector;
        let mut j = [JointConst {
            ct: 1.0,
            st: 0.0,
            a: 0.0,
            d: 0.0,
            ca: 1.0,
            sa: 0.0,
            cb: 1.0,
            sb: 0.0,
            theta: 0.0,
        }; 6];
        let mut hayati = [false; 6];
        for (i, g) in model.joints.iter().enumerate() {
            let theta = q[i] + g.offset;
            let (st, ct) = theta.sin_cos();
            j[i] = JointConst {
                ct,
                st,
                a: g.a,
                d: g.d,
                ca: g.ca,
                sa: g.sa,
                cb: g.cb,
                sb: g.sb,
                theta,
            };
            hayati[i] = g.hayati;
        }
        Self {
            j,
            hayati,
            tool: [t.x, t.y, t.z],
        }
    }

    /// Tool-point position (m, base frame) at `q + delta`.
    #[inline(always)]
    pub fn position(&self, delta: &[f64; 6]) -> [f64; 3] {
        let [mut x, mut y, mut z] = self.tool;
        for i in (0..6).rev() {
            let g = &self.j[i];
            let d = delta[i];
            let (ct, st) = if d.abs() <= TAYLOR_MAX {
                let (cd, sd) = cos_sin_small(d);
                (g.ct * cd - g.st * sd, g.st * cd + g.ct * sd)
            } else {
                let (s, c) = (g.theta + d).sin_cos();
                (c, s)
            };
            if self.hayati[i] {
                // Ry(β)
                let nx = g.cb * x + g.sb * z;
                let nz = -g.sb * x + g.cb * z;
                x = nx;
                z = nz;
            }
            // Rx(α), then Tx(a), Tz(d)
            let ny = g.ca * y - g.sa * z;
            let nz = g.sa * y + g.ca * z;
            let wx = x + g.a;
            let wz = nz + g.d;
            // Rz(θ)
            x = ct * wx - st * ny;
            y = st * wx + ct * ny;
            z = wz;
        }
        [x, y, z]
    }
}

/// Draws evaluated together by [`PositionKernel::positions`]: independent lanes give the CPU
/// parallel dependency chains (the six-joint chain is latency-bound on its own).
pub const LANES: usize = 8;

impl PositionKernel {
    /// Tool-point positions (m) for [`LANES`] perturbations at once, structure of arrays:
    /// `delta[joint][lane]` in, `out[axis][lane]` out. Lanes with |δ| > 0.05 rad take the
    /// exact scalar path.
    #[inline(always)]
    pub fn positions(&self, delta: &[[f64; LANES]; 6], out: &mut [[f64; LANES]; 3]) {
        let small = delta
            .iter()
            .all(|d| d.iter().all(|v| v.abs() <= TAYLOR_MAX));
        if !small {
            for l in 0..LANES {
                let p = self.position(&std::array::from_fn(|j| delta[j][l]));
                for a in 0..3 {
                    out[a][l] = p[a];
                }
            }
            return;
        }
        let mut x = [self.tool[0]; LANES];
        let mut y = [self.tool[1]; LANES];
        let mut z = [self.tool[2]; LANES];
        for i in (0..6).rev() {
            let g = &self.j[i];
            if self.hayati[i] {
                for l in 0..LANES {
                    let nx = g.cb * x[l] + g.sb * z[l];
                    z[l] = -g.sb * x[l] + g.cb * z[l];
                    x[l] = nx;
                }
            }
            for l in 0..LANES {
                let (cd, sd) = cos_sin_small(delta[i][l]);
                let ct = g.ct * cd - g.st * sd;
                let st = g.st * cd + g.ct * sd;
                let ny = g.ca * y[l] - g.sa * z[l];
                let nz = g.sa * y[l] + g.ca * z[l];
                let wx = x[l] + g.a;
                x[l] = ct * wx - st * ny;
                y[l] = st * wx + ct * ny;
                z[l] = nz + g.d;
            }
        }
        *out = [x, y, z];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_matches_the_model_fk() {
        let mut d = Model::nominal().data().clone();
        d.departures[1].dbeta = 8e-4;
        d.departures[2].dalpha = -5e-4;
        d.departures[3].da = 2e-4;
        d.tool.translation = [0.01, 0.0, 0.35];
        let m = Model::new(d).expect("valid");
        let q = [0.3, 0.6, 1.2, -0.4, 0.9, 0.2];
        let k = PositionKernel::new(&m, &q);
        for delta in [
            [0.0; 6],
            [1e-4, -2e-4, 3e-4, -1e-4, 5e-5, 2e-4],
            [0.04, -0.03, 0.02, 0.049, -0.045, 0.01],
            [0.3, -0.2, 0.1, 0.07, -0.5, 1.0],
        ] {
            let qd: [f64; 6] = std::array::from_fn(|i| q[i] + delta[i]);
            let want = m.fk(&qd).translation.vector;
            let got = k.position(&delta);
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 2e-15,
                    "{delta:?}: {got:?} vs {want}"
                );
            }
        }
    }

    #[test]
    fn lane_kernel_equals_the_scalar_kernel() {
        let m = Model::nominal();
        let k = PositionKernel::new(&m, &[0.3, 0.6, 1.2, -0.4, 0.9, 0.2]);
        for scale in [1e-4, 0.06] {
            let delta: [[f64; LANES]; 6] = std::array::from_fn(|j| {
                std::array::from_fn(|l| scale * ((j * LANES + l) as f64).sin())
            });
            let mut out = [[0.0; LANES]; 3];
            k.positions(&delta, &mut out);
            for l in 0..LANES {
                let p = k.position(&std::array::from_fn(|j| delta[j][l]));
                for a in 0..3 {
                    assert!((out[a][l] - p[a]).abs() < 1e-15);
                }
            }
        }
    }

    #[test]
    fn taylor_series_are_exact_to_rounding() {
        for &d in &[0.0, 1e-8, 1e-4, -3e-3, 0.02, -0.05] {
            let (c, s) = cos_sin_small(d);
            assert!((c - d.cos()).abs() <= 1.2e-16, "{d}");
            assert!(
                (s - d.sin()).abs() <= 1.2e-16 * d.abs().max(1e-300) + 1e-19,
                "{d}"
            );
        }
    }
}
