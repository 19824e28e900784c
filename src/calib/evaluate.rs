//! Judging a model on a dataset: position and orientation errors per load, the resolver
//! floor at the data's poses, the base frame alone (the "before" of a calibration) and the
//! canonical base for comparisons.

use nalgebra::Vector6;

use super::base;
use super::dataset::Dataset;
use super::prepare::{CalibError, CalibOptions, choose_inner, prepare, seed_base};
use crate::model::{Frame, Model, frame_from_pose};

/// Position and orientation errors of `model` (with its base frame) on `data`, per load.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct ErrorSummary {
    /// Load, N.
    pub load_n: f64,
    /// Rows.
    pub rows: usize,
    /// Mean position error, mm.
    pub mean_mm: f64,
    /// Peak position error, mm.
    pub peak_mm: f64,
    /// Mean orientation error, degrees.
    pub mean_orient_deg: f64,
}

/// Errors of `model` on `data`: one summary per load, ascending. The model's own
/// `base_from_instrument` maps measurements into the base frame.
pub fn evaluate(
    model: &Model,
    data: &Dataset,
    kt: Option<[f64; 6]>,
) -> Result<Vec<ErrorSummary>, CalibError> {
    let rows = prepare(data, &[], kt)?;
    let base = *model.base_from_instrument();
    let mut out: Vec<ErrorSummary> = data
        .loads()
        .into_iter()
        .map(|l| ErrorSummary {
            load_n: l,
            ..Default::default()
        })
        .collect();
    for r in &rows {
        let pred = model.tool_at_rest(&r.q, &r.tau, r.load_n);
        let meas = base * r.meas;
        let e = crate::model::pose_error(&pred, &meas);
        let pe = e.fixed_rows::<3>(0).norm() * 1e3;
        let oe = e.fixed_rows::<3>(3).norm().to_degrees();
        if let Some(s) = out.iter_mut().find(|s| s.load_n == r.load_n) {
            s.rows += 1;
            s.mean_mm += pe;
            s.peak_mm = s.peak_mm.max(pe);
            s.mean_orient_deg += oe;
        }
    }
    for s in &mut out {
        s.mean_mm /= s.rows.max(1) as f64;
        s.mean_orient_deg /= s.rows.max(1) as f64;
    }
    Ok(out)
}

/// The base frame alone (inner level on `model`'s geometry): what "before calibration"
/// means — the nominal model placed as well as it can be in the instrument frame.
pub fn fit_base_only(
    model: &Model,
    data: &Dataset,
    lines: Option<&Dataset>,
    opts: &CalibOptions,
) -> Result<Model, CalibError> {
    let inner_ids = choose_inner(data, opts)?;
    let rows = prepare(data, &inner_ids, opts.torque_constants)?;
    let mut m = model.clone();
    if let Some(t) = data.meta.as_ref().and_then(|m| m.tool) {
        m = m.with_tool(&frame_from_pose(t.translation, t.quaternion))?;
    }
    let psi0 = seed_base(&m, &rows, lines)?;
    let pairs: Vec<(Frame, Frame)> = rows
        .iter()
        .filter(|r| r.inner)
        .map(|r| (m.tool_at_rest(&r.q, &r.tau, r.load_n), r.meas))
        .collect();
    let (psi, _) = base::fit_psi(&pairs, &psi0, opts.r_max);
    Ok(m.with_base_from_instrument(&base::frame_from_psi(&psi))?)
}

/// The resolver floor at `data`'s poses: the mean position error (mm) that joint errors of
/// `sigma_rad` (1σ, every joint) alone cause there, per load (the linearised bound of
/// [`crate::accuracy`]), evaluated with `model` at the rows' link angles.
pub fn resolver_floor(
    model: &Model,
    data: &Dataset,
    sigma_rad: f64,
    kt: Option<[f64; 6]>,
) -> Result<Vec<(f64, f64)>, CalibError> {
    let rows = prepare(data, &[], kt)?;
    let mut out: Vec<(f64, f64, usize)> = data.loads().into_iter().map(|l| (l, 0.0, 0)).collect();
    for r in &rows {
        let q = model.link_angles(&r.q, &r.tau);
        let cov = crate::accuracy::linear::position_covariance(model, &q, &[sigma_rad; 6]);
        let mean = crate::accuracy::linear::norm_stats(&cov).mean * 1e3;
        if let Some(o) = out.iter_mut().find(|o| o.0 == r.load_n) {
            o.1 += mean;
            o.2 += 1;
        }
    }
    Ok(out
        .into_iter()
        .map(|(l, s, n)| (l, s / n.max(1) as f64))
        .collect())
}

/// `base_from_instrument` with the joint-1 departures that commute with q1 (δd1 along and
/// δθ1 about the J1 axis) folded in: the part of the base frame the data can tell from the
/// geometry (a free base frame absorbs exactly these two).
pub fn canonical_base(model: &Model) -> Frame {
    let e = model.data().departures[0];
    let f = Frame::from_parts(
        nalgebra::Translation3::new(0.0, 0.0, e.dd),
        nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), e.dtheta),
    );
    f.inverse() * model.base_from_instrument()
}

/// Residual vector of one row (paper units) for external callers (reports, discovery): the
/// resolvers' `q` (rad), torques `tau` (N·m), `load_n` (N) hung at the tool.
pub fn row_residual(
    model: &Model,
    q: &[f64; 6],
    tau: &[f64; 6],
    load_n: f64,
    meas: &Frame,
    r_max: f64,
) -> Vector6<f64> {
    let pred = model.tool_at_rest(q, tau, load_n);
    let b = *model.base_from_instrument();
    base::residual_and_psi_jacobian(&pred, meas, &base::psi_from_frame(&b), &b, r_max).0
}
