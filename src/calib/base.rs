//! The instrument → robot base frame: its six parameters Ψ (paper eq. 4), the inner-level
//! Gauss–Newton fit, and its seeds (straight-line moves, paper eqs 5–7; or a point fit).
//!
//! `Ψ = [p, γx, γy, γz]`: `p` is the instrument origin in the base frame (m), and the
//! instrument's orientation is `Rx(γx)·Ry(γy)·Rz(γz)` (body-fixed xyz angles, rad), so that
//! `base_from_instrument = Trans(p)·Rx(γx)·Ry(γy)·Rz(γz)`.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Translation3, Vector3, Vector6};

use crate::model::{Frame, rotation_log};

/// The six base-frame parameters.
pub type BaseParams = Vector6<f64>;

/// Ψ → `base_from_instrument`.
pub fn frame_from_psi(psi: &BaseParams) -> Frame {
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), psi[3])
        * Rotation3::from_axis_angle(&Vector3::y_axis(), psi[4])
        * Rotation3::from_axis_angle(&Vector3::z_axis(), psi[5]);
    Frame::from_parts(Translation3::new(psi[0], psi[1], psi[2]), r)
}

/// `base_from_instrument` → Ψ (γy within ±90°).
pub fn psi_from_frame(f: &Frame) -> BaseParams {
    let r = f.rotation.matrix();
    let gy = r[(0, 2)].clamp(-1.0, 1.0).asin();
    let gx = (-r[(1, 2)]).atan2(r[(2, 2)]);
    let gz = (-r[(0, 1)]).atan2(r[(0, 0)]);
    let t = f.translation.vector;
    Vector6::new(t.x, t.y, t.z, gx, gy, gz)
}

/// Rotation axes (base frame) of γx, γy, γz at Ψ: the columns of `∂R/∂γ` as angular rates.
pub fn psi_axes(psi: &BaseParams) -> [Vector3<f64>; 3] {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), psi[3]);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), psi[4]);
    [Vector3::x(), rx * Vector3::y(), rx * ry * Vector3::z()]
}

/// Residual of one measurement (paper units: position / `r_max`, orientation rad) and its
/// Jacobian with respect to Ψ. `pred` is the model's tool pose in the base frame, `meas`
/// the measured pose in the instrument frame.
pub fn residual_and_psi_jacobian(
    pred: &Frame,
    meas: &Frame,
    psi: &BaseParams,
    base: &Frame,
    r_max: f64,
) -> (Vector6<f64>, SMatrix<f64, 6, 6>) {
    let m = base * meas;
    let dp = (pred.translation.vector - m.translation.vector) / r_max;
    let dr = rotation_log(&(pred.rotation * m.rotation.inverse()));
    let r = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
    let mut j = SMatrix::<f64, 6, 6>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-Matrix3::identity() / r_max));
    let lever = m.translation.vector - base.translation.vector;
    for (k, a) in psi_axes(psi).iter().enumerate() {
        j.fixed_view_mut::<3, 1>(0, 3 + k)
            .copy_from(&(-a.cross(&lever) / r_max));
        j.fixed_view_mut::<3, 1>(3, 3 + k).copy_from(&(-a));
    }
    (r, j)
}

/// Inner level: Ψ minimising the squared residuals of `pairs` (model prediction in the
/// base frame, measurement in the instrument frame), Gauss–Newton with step halving from
/// `start`. Returns Ψ and the final cost.
pub fn fit_psi(pairs: &[(Frame, Frame)], start: &BaseParams, r_max: f64) -> (BaseParams, f64) {
    let cost_at = |psi: &BaseParams| {
        let b = frame_from_psi(psi);
        pairs
            .iter()
            .map(|(p, m)| {
                residual_and_psi_jacobian(p, m, psi, &b, r_max)
                    .0
                    .norm_squared()
            })
            .sum::<f64>()
    };
    let mut psi = *start;
    let mut cost = cost_at(&psi);
    for _ in 0..50 {
        let b = frame_from_psi(&psi);
        let mut h = SMatrix::<f64, 6, 6>::zeros();
        let mut g = SVector::<f64, 6>::zeros();
        for (p, m) in pairs {
            let (r, j) = residual_and_psi_jacobian(p, m, &psi, &b, r_max);
            h += j.transpose() * j;
            g += j.transpose() * r;
        }
        let Some(step) = h.cholesky().map(|c| -c.solve(&g)) else {
            break;
        };
        let mut scale = 1.0;
        let mut improved = false;
        for _ in 0..30 {
            let trial = psi + step * scale;
            let c = cost_at(&trial);
            if c <= cost {
                psi = trial;
                improved = c < cost;
                cost = c;
                break;
            }
            scale *= 0.5;
        }
        if !improved || (step * scale).norm() < 1e-14 {
            break;
        }
    }
    (psi, cost)
}

/// Seed of `base_from_instrument` from straight-line moves (paper eqs 5–7): `x_line` and
/// `y_line` are the instrument-frame positions measured while the robot moved along its own
/// x and y axes, in order of motion; `robot_points` / `inst_points` any corresponding
/// positions (base frame from the model, instrument frame measured) fix the translation.
pub fn seed_from_lines(
    x_line: &[Vector3<f64>],
    y_line: &[Vector3<f64>],
    robot_points: &[Vector3<f64>],
    inst_points: &[Vector3<f64>],
) -> Option<Frame> {
    let xd = line_direction(x_line)?;
    let yd = line_direction(y_line)?;
    let z = xd.cross(&yd).try_normalize(1e-9)?; // eq 5
    let y = z.cross(&xd).normalize(); // eq 6
    let x = xd;
    // eq 7: the base axes in instrument coordinates are the columns of R_inst_base
    let r_inst_base = Matrix3::from_columns(&[x, y, z]);
    let r = Rotation3::from_matrix_unchecked(r_inst_base.transpose()); // base_from_instrument
    if robot_points.is_empty() || robot_points.len() != inst_points.len() {
        return None;
    }
    let n = robot_points.len() as f64;
    let t = robot_points
        .iter()
        .zip(inst_points)
        .map(|(b, i)| b - r * i)
        .sum::<Vector3<f64>>()
        / n;
    Some(Frame::from_parts(Translation3::from(t), r))
}

/// Least-squares direction of ordered points (principal axis, signed first → last).
fn line_direction(pts: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vector3<f64>>() / n;
    let cov = pts
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum::<Matrix3<f64>>();
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let mut d = eig.eigenvectors.column(k).into_owned();
    if d.dot(&(pts[pts.len() - 1] - pts[0])) < 0.0 {
        d = -d;
    }
    d.try_normalize(1e-12)
}

/// Seed of `base_from_instrument` by a least-squares rigid fit (Kabsch) of model positions
/// (base frame) to measured positions (instrument frame).
pub fn seed_from_points(
    robot_points: &[Vector3<f64>],
    inst_points: &[Vector3<f64>],
) -> Option<Frame> {
    if robot_points.len() < 3 || robot_points.len() != inst_points.len() {
        return None;
    }
    let n = robot_points.len() as f64;
    let cb = robot_points.iter().sum::<Vector3<f64>>() / n;
    let ci = inst_points.iter().sum::<Vector3<f64>>() / n;
    let h = robot_points
        .iter()
        .zip(inst_points)
        .map(|(b, i)| (i - ci) * (b - cb).transpose())
        .sum::<Matrix3<f64>>();
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(vt.transpose() * d * u.transpose());
    Some(Frame::from_parts(Translation3::from(cb - r * ci), r))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn some_base() -> Frame {
        frame_from_psi(&BaseParams::new(0.4, -0.7, -0.2, 0.004, -0.006, 2.1))
    }

    #[test]
    fn psi_round_trips() {
        let psi = BaseParams::new(0.4, -0.7, -0.2, 0.004, -0.006, 2.1);
        assert!((psi_from_frame(&frame_from_psi(&psi)) - psi).norm() < 1e-14);
    }

    #[test]
    fn psi_jacobian_matches_finite_differences() {
        let psi = BaseParams::new(0.4, -0.7, -0.2, 0.004, -0.006, 2.1);
        let pred = crate::model::Model::nominal().fk(&[0.3, 0.6, 1.2, -0.4, 0.9, 0.2]);
        let meas = some_base().inverse() * pred * Frame::translation(1e-4, 0.0, -2e-4);
        let (_, j) = residual_and_psi_jacobian(&pred, &meas, &psi, &frame_from_psi(&psi), 1.0);
        for k in 0..6 {
            let mut d = BaseParams::zeros();
            d[k] = 1e-7;
            let rp = residual_and_psi_jacobian(
                &pred,
                &meas,
                &(psi + d),
                &frame_from_psi(&(psi + d)),
                1.0,
            )
            .0;
            let rm = residual_and_psi_jacobian(
                &pred,
                &meas,
                &(psi - d),
                &frame_from_psi(&(psi - d)),
                1.0,
            )
            .0;
            let fd = (rp - rm) / 2e-7;
            assert!(
                (j.column(k) - fd).norm() < 1e-6,
                "{k}: {} vs {fd}",
                j.column(k)
            );
        }
    }

    #[test]
    fn inner_level_recovers_a_known_base_exactly_on_noise_free_data() {
        let m = crate::model::Model::nominal();
        let base = some_base();
        let qs = [
            [0.1, 0.5, 1.2, 0.0, 0.8, 0.0],
            [0.6, 0.2, 1.6, 0.5, 1.1, -0.3],
            [-0.4, 0.7, 0.9, -0.2, 0.5, 0.4],
            [0.9, 0.4, 1.3, 0.8, -0.9, 1.0],
        ];
        let pairs: Vec<(Frame, Frame)> = qs
            .iter()
            .map(|q| (m.fk(q), base.inverse() * m.fk(q)))
            .collect();
        let (psi, cost) = fit_psi(&pairs, &BaseParams::new(0.0, 0.0, 0.0, 0.0, 0.0, 2.0), 1.0);
        assert!(cost < 1e-26, "{cost}");
        assert!((psi - psi_from_frame(&base)).norm() < 1e-12, "{psi}");
    }

    #[test]
    fn line_and_point_seeds_find_the_placement() {
        let base = some_base();
        let inv = base.inverse();
        let x: Vec<Vector3<f64>> = (0..10)
            .map(|k| inv * nalgebra::Point3::new(0.3 + 0.03 * k as f64, -0.1, 0.3))
            .map(|p| p.coords)
            .collect();
        let y: Vec<Vector3<f64>> = (0..10)
            .map(|k| inv * nalgebra::Point3::new(0.5, -0.2 + 0.04 * k as f64, 0.3))
            .map(|p| p.coords)
            .collect();
        let robot = vec![Vector3::new(0.3, -0.1, 0.3), Vector3::new(0.5, 0.2, 0.3)];
        let inst: Vec<Vector3<f64>> = robot
            .iter()
            .map(|p| (inv * nalgebra::Point3::from(*p)).coords)
            .collect();
        let s = seed_from_lines(&x, &y, &robot, &inst).unwrap();
        assert!(crate::model::pose_error(&s, &base).norm() < 1e-12);
        let robot: Vec<Vector3<f64>> = x
            .iter()
            .chain(&y)
            .map(|i| (base * nalgebra::Point3::from(*i)).coords)
            .collect();
        let inst: Vec<Vector3<f64>> = x.iter().chain(&y).cloned().collect();
        let s = seed_from_points(&robot, &inst).unwrap();
        assert!(crate::model::pose_error(&s, &base).norm() < 1e-12);
    }
}
