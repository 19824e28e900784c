//! ISO 9283 pose accuracy (AP) and pose repeatability (RP): the standard's test poses in a
//! cube of the workspace, and the figures from attained poses. Plain functions on plain data.
//!
//! **Test poses** (ISO 9283:1998 §6.2): in the cube's inclined diagonal plane — through its
//! bottom edge at `y = ymin, z = zmin` and its top edge at `y = ymax, z = zmax` — P1 is the
//! cube's centre and P2…P5 lie on the plane's diagonals one tenth of the diagonal's length from
//! its corners (P2 at `(xmin, ymin, zmin)`, P3 at `(xmax, ymin, zmin)`, P4 at `(xmax, ymax,
//! zmax)`, P5 at `(xmin, ymax, zmax)`), all at one commanded orientation. Cycles visit P1 → P5 in
//! turn, always from the same side (30 cycles in the standard).
//!
//! **Figures** (§7.2): for each pose, over its n attained poses `x_j`:
//! `AP_x = x̄ − x_c` (and y, z), `AP_P = √(AP_x² + AP_y² + AP_z²)`; orientation `AP_a/b/c` = the
//! mean small rotation about x, y, z from commanded to attained; `RP_l = l̄ + 3·S_l` with
//! `l_j = ‖x_j − x̄‖`, `S_l` its standard deviation (n − 1); `RP_a/b/c = ±3·S` of the rotations.
//! Lengths in metres, angles in radians.

use nalgebra::{Rotation3, Translation3, Vector3};

use crate::model::{Frame, pose_error};

/// The test cube: centre (m, base frame) and side (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cube {
    /// Centre, m.
    pub centre: [f64; 3],
    /// Side, m.
    pub side: f64,
}

/// Why the figures could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum IsoError {
    /// A setting out of range.
    #[error("{0}")]
    Invalid(String),
}

/// The five test poses P1…P5 of `cube` at orientation `rot` (base frame).
pub fn test_poses(cube: &Cube, rot: &Rotation3<f64>) -> Result<[Frame; 5], IsoError> {
    if !(cube.side.is_finite() && cube.side > 0.0 && cube.centre.iter().all(|v| v.is_finite())) {
        return Err(IsoError::Invalid(format!(
            "cube: a finite centre and a positive side in metres, got {cube:?}"
        )));
    }
    let c = Vector3::from(cube.centre);
    let h = 0.5 * cube.side;
    let corners = [
        c + Vector3::new(-h, -h, -h),
        c + Vector3::new(h, -h, -h),
        c + Vector3::new(h, h, h),
        c + Vector3::new(-h, h, h),
    ];
    let frame = |p: Vector3<f64>| Frame::from_parts(Translation3::from(p), *rot);
    // one tenth of the diagonal from each corner, towards the opposite one
    let at = |k: usize| corners[k] + 0.1 * (corners[(k + 2) % 4] - corners[k]);
    Ok([
        frame(c),
        frame(at(0)),
        frame(at(1)),
        frame(at(2)),
        frame(at(3)),
    ])
}

/// The figures of one pose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PoseFigures {
    /// Attained poses used.
    pub n: usize,
    /// Position accuracy and its components (x̄ − x_c, …), m.
    pub ap_p: f64,
    /// `x̄ − x_c`, `ȳ − y_c`, `z̄ − z_c`, m.
    pub ap_xyz: [f64; 3],
    /// Orientation accuracy about x, y, z, rad.
    pub ap_abc: [f64; 3],
    /// Position repeatability `l̄ + 3·S_l`, m.
    pub rp_l: f64,
    /// Orientation repeatability `3·S` about x, y, z, rad (±).
    pub rp_abc: [f64; 3],
}

/// AP and RP of one pose: `commanded` and the `attained` poses (≥ 2, same frame).
pub fn figures(commanded: &Frame, attained: &[Frame]) -> Result<PoseFigures, IsoError> {
    let n = attained.len();
    if n < 2 {
        return Err(IsoError::Invalid(format!(
            "a pose needs at least 2 attained poses (the standard: 30), got {n}"
        )));
    }
    let nf = n as f64;
    let pts: Vec<Vector3<f64>> = attained.iter().map(|f| f.translation.vector).collect();
    let mean = pts.iter().fold(Vector3::zeros(), |a, p| a + p) / nf;
    let ap = mean - commanded.translation.vector;
    let rots: Vec<Vector3<f64>> = attained
        .iter()
        // pose_error is commanded ⊖ attained: the rotation from commanded to attained is its negative
        .map(|f| -pose_error(commanded, f).fixed_rows::<3>(3).into_owned())
        .collect();
    let rmean = rots.iter().fold(Vector3::zeros(), |a, r| a + r) / nf;
    let l: Vec<f64> = pts.iter().map(|p| (p - mean).norm()).collect();
    let lmean = l.iter().sum::<f64>() / nf;
    let sl = (l.iter().map(|v| (v - lmean).powi(2)).sum::<f64>() / (nf - 1.0)).sqrt();
    let s_abc: [f64; 3] = std::array::from_fn(|k| {
        (rots.iter().map(|r| (r[k] - rmean[k]).powi(2)).sum::<f64>() / (nf - 1.0)).sqrt()
    });
    Ok(PoseFigures {
        n,
        ap_p: ap.norm(),
        ap_xyz: [ap.x, ap.y, ap.z],
        ap_abc: [rmean.x, rmean.y, rmean.z],
        rp_l: lmean + 3.0 * sl,
        rp_abc: s_abc.map(|s| 3.0 * s),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_test_poses_lie_on_the_inclined_plane_a_tenth_of_the_diagonal_from_its_corners() {
        let cube = Cube {
            centre: [0.6, 0.0, 0.1],
            side: 0.2,
        };
        let p = test_poses(&cube, &Rotation3::identity()).unwrap();
        assert_eq!(p[0].translation.vector, Vector3::new(0.6, 0.0, 0.1));
        // the plane's diagonal: from (0.5, -0.1, 0.0) to (0.7, 0.1, 0.2), length 0.2·√3
        let d = (0.2f64 * 0.2 * 3.0).sqrt();
        let corner = Vector3::new(0.5, -0.1, 0.0);
        assert!(((p[1].translation.vector - corner).norm() - 0.1 * d).abs() < 1e-12);
        // every pose on the plane z − zmin = y − ymin
        for f in &p {
            let v = f.translation.vector;
            assert!(((v.z - 0.0) - (v.y + 0.1)).abs() < 1e-12, "{v:?}");
        }
        assert!(test_poses(&Cube { side: 0.0, ..cube }, &Rotation3::identity()).is_err());
    }

    #[test]
    fn figures_follow_the_standard_on_a_hand_computed_case() {
        let c = Frame::identity();
        let at = |x: f64, y: f64, rz: f64| {
            Frame::from_parts(
                Translation3::new(x, y, 0.0),
                Rotation3::from_euler_angles(0.0, 0.0, rz),
            )
        };
        // mean (0.002, 0.001, 0); spread ±0.001 in x
        let a = [at(0.001, 0.001, 0.01), at(0.003, 0.001, 0.03)];
        let f = figures(&c, &a).unwrap();
        assert!((f.ap_xyz[0] - 0.002).abs() < 1e-15 && (f.ap_xyz[1] - 0.001).abs() < 1e-15);
        assert!((f.ap_p - (0.002f64.powi(2) + 0.001f64.powi(2)).sqrt()).abs() < 1e-15);
        // l = 0.001 both: mean 0.001, S_l 0 → RP 0.001
        assert!((f.rp_l - 0.001).abs() < 1e-15, "{f:?}");
        assert!((f.ap_abc[2] - 0.02).abs() < 1e-12);
        // S of 0.01, 0.03 (n − 1): 0.01414 → 3S
        assert!(
            (f.rp_abc[2] - 3.0 * 0.02f64.sqrt() * 0.1).abs() < 1e-9,
            "{f:?}"
        );
        assert!(figures(&c, &a[..1]).is_err());
    }
}
