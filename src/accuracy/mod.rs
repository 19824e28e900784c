//! The resolver-uncertainty accuracy bound (seed paper §II-D, §III-A): what positioning error
//! remains even with a perfect model, because the joint resolvers are uncertain.
//!
//! Two twins, reported side by side:
//! - **Monte Carlo**: at points chosen uniformly over the reachable part of horizontal
//!   planes (tool at a fixed orientation, IK on the model), draw independent Gaussian joint
//!   errors (σ per joint) many times and measure `‖p(q + δ) − p(q)‖` with a specialised
//!   position kernel ([`kernel`]).
//! - **Linearised**: `Σ_p = J_p·Σ_q·J_pᵀ` and the exact mean and spread of the norm of that
//!   Gaussian ([`linear`]).
//!
//! Determinism: point selection runs sequentially from the seed; every point's draws come
//! from its own generator seeded by (seed, plane, point), and per-point results are combined
//! in point order, so results are bit-identical whatever the number of threads. Percentiles
//! come from a histogram with 16 384 bins over `[0, 12·rms_lin)` of the plane (resolution
//! ≈ 0.07 % of the mean); mean, standard deviation and maximum are exact.

pub mod iso9283;
pub mod kernel;
pub mod linear;

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use crate::model::{Frame, Model};
use kernel::{LANES, PositionKernel};

/// One arcminute in radians.
pub const ARCMIN: f64 = std::f64::consts::PI / (180.0 * 60.0);

/// Histogram bins used for percentiles.
const BINS: usize = 16_384;
/// Histogram range in units of the plane's largest linearised rms error.
const RANGE_RMS: f64 = 12.0;
/// Candidate positions tried per requested point before a plane is declared unreachable.
const ATTEMPTS_PER_POINT: usize = 200;

/// Rectangular region of the plane to draw points from, metres, base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// x range, m.
    pub x: (f64, f64),
    /// y range, m.
    pub y: (f64, f64),
}

impl Default for Region {
    /// ±1.2 m in x and y: the whole reach of the arm; IK keeps the reachable part.
    fn default() -> Self {
        Self {
            x: (-1.2, 1.2),
            y: (-1.2, 1.2),
        }
    }
}

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct McConfig {
    /// Resolver standard deviation per joint, rad.
    pub sigma: [f64; 6],
    /// Plane heights (z of the tool point in the base frame), m.
    pub planes: Vec<f64>,
    /// Points per plane (≥ 1).
    pub points: usize,
    /// Draws per point (≥ 1).
    pub draws: usize,
    /// Tool point: this offset along the flange z axis, m (replaces the model's tool).
    pub tool_offset: f64,
    /// Orientation of the tool frame in the base frame (default: flange z pointing down).
    pub tool_orientation: UnitQuaternion<f64>,
    /// Where in each plane points may lie.
    pub region: Region,
    /// Seed of every random choice.
    pub seed: u64,
}

impl McConfig {
    /// The paper's experiment: σ = 0.64 arcmin on every joint, planes z = 0.3 … 0.7 m,
    /// 200 points × 100 000 draws, a 0.35 m tool pointing down, seed 1.
    pub fn paper() -> Self {
        Self {
            sigma: [0.64 * ARCMIN; 6],
            planes: vec![0.3, 0.4, 0.5, 0.6, 0.7],
            points: 200,
            draws: 100_000,
            tool_offset: 0.35,
            tool_orientation: pointing_down(),
            region: Region::default(),
            seed: 1,
        }
    }
}

/// Tool z axis along −z of the base (a half turn about x).
pub fn pointing_down() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
}

/// Why a bound could not be computed. Nothing is computed when one is returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AccuracyError {
    /// A configuration value is out of range.
    #[error("invalid {key}: {reason}")]
    Invalid {
        /// The setting.
        key: &'static str,
        /// Why, with units.
        reason: String,
    },
    /// Too few reachable points were found in a plane.
    #[error(
        "plane z = {z} m: only {found} of {wanted} points are reachable with this tool and orientation inside x {x:?} m, y {y:?} m"
    )]
    PlaneUnreachable {
        /// Plane height, m.
        z: f64,
        /// Reachable points found.
        found: usize,
        /// Points asked for.
        wanted: usize,
        /// Region x range, m.
        x: (f64, f64),
        /// Region y range, m.
        y: (f64, f64),
    },
}

/// Distribution summary of a position error, millimetres.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct ErrorStats {
    /// Mean, mm.
    pub mean_mm: f64,
    /// Standard deviation, mm.
    pub sd_mm: f64,
    /// Median, mm (histogram).
    pub median_mm: f64,
    /// 95th percentile, mm (histogram).
    pub p95_mm: f64,
    /// 99th percentile, mm (histogram).
    pub p99_mm: f64,
    /// Maximum, mm.
    pub max_mm: f64,
}

/// One point of a plane and its errors.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PointResult {
    /// Tool point, m, base frame.
    pub position: [f64; 3],
    /// Link angles (rad) the IK chose.
    pub q: [f64; 6],
    /// Monte Carlo error statistics.
    pub mc: ErrorStats,
    /// Linearised mean error, mm.
    pub linearised_mean_mm: f64,
    /// Linearised standard deviation of the error, mm.
    pub linearised_sd_mm: f64,
}

/// One plane's results.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlaneResult {
    /// Plane height, m.
    pub z: f64,
    /// Monte Carlo statistics over all draws of all points.
    pub mc: ErrorStats,
    /// Linearised mean error over the points, mm.
    pub linearised_mean_mm: f64,
    /// Linearised standard deviation over the points' mixture, mm.
    pub linearised_sd_mm: f64,
    /// Per-point results, in selection order.
    pub points: Vec<PointResult>,
}

fn check(cfg: &McConfig) -> Result<(), AccuracyError> {
    let bad = |key, reason: String| Err(AccuracyError::Invalid { key, reason });
    if let Some(j) = cfg.sigma.iter().position(|s| !(s.is_finite() && *s >= 0.0)) {
        return bad(
            "sigma",
            format!(
                "joint {} σ must be finite and ≥ 0 rad, got {}",
                j + 1,
                cfg.sigma[j]
            ),
        );
    }
    if cfg.sigma.iter().any(|s| *s > 0.1) {
        return bad(
            "sigma",
            "σ above 0.1 rad (5.7°) is not a resolver uncertainty".into(),
        );
    }
    if cfg.planes.is_empty() {
        return bad("planes", "at least one plane height is needed".into());
    }
    if let Some(z) = cfg.planes.iter().find(|z| !z.is_finite()) {
        return bad("planes", format!("plane height must be finite, got {z}"));
    }
    if cfg.points == 0 {
        return bad("points", "at least one point per plane is needed".into());
    }
    if cfg.draws == 0 {
        return bad("draws", "at least one draw per point is needed".into());
    }
    if !(cfg.tool_offset.is_finite() && cfg.tool_offset.abs() <= 2.0) {
        return bad(
            "tool_offset",
            format!(
                "must be a finite length within ±2 m, got {}",
                cfg.tool_offset
            ),
        );
    }
    let r = &cfg.region;
    if !(r.x.0.is_finite() && r.x.1.is_finite() && r.y.0.is_finite() && r.y.1.is_finite())
        || r.x.0 >= r.x.1
        || r.y.0 >= r.y.1
    {
        return bad(
            "region",
            format!(
                "needs finite min < max in x and y (m), got x {:?}, y {:?}",
                r.x, r.y
            ),
        );
    }
    Ok(())
}

/// The model with the configured tool (offset along flange z).
fn tool_model(model: &Model, cfg: &McConfig) -> Model {
    let tool = Frame::from_parts(
        Translation3::new(0.0, 0.0, cfg.tool_offset),
        nalgebra::Rotation3::identity(),
    );
    // A z offset within ±2 m always validates.
    model.with_tool(&tool).unwrap_or_else(|_| model.clone())
}

/// A selected point: tool position (m, base frame) and the link angles (rad) reaching it.
pub type SelectedPoint = ([f64; 3], [f64; 6]);

/// Points chosen uniformly over the reachable part of plane `plane` (index into
/// `cfg.planes`): `(position, link angles)` pairs, from the seed alone.
pub fn select_points(
    model: &Model,
    cfg: &McConfig,
    plane: usize,
) -> Result<Vec<SelectedPoint>, AccuracyError> {
    check(cfg)?;
    let Some(&z) = cfg.planes.get(plane) else {
        return Err(AccuracyError::Invalid {
            key: "planes",
            reason: format!("no plane with index {plane}"),
        });
    };
    let m = tool_model(model, cfg);
    let mut rng = Pcg64Mcg::seed_from_u64(mix(cfg.seed, 0x5e1e_c7ed, plane as u64));
    let mut out = Vec::with_capacity(cfg.points);
    let r = cfg.region;
    for _ in 0..cfg.points * ATTEMPTS_PER_POINT {
        if out.len() == cfg.points {
            break;
        }
        let x = rng.random_range(r.x.0..r.x.1);
        let y = rng.random_range(r.y.0..r.y.1);
        let target = Frame::from_parts(
            Translation3::new(x, y, z),
            cfg.tool_orientation.to_rotation_matrix(),
        );
        // Elbow up, wrist bent down: the posture a tool pointing down is usually reached in.
        let reference = [y.atan2(x), 0.5, 1.5, 0.0, 1.1, 0.0];
        if let Ok(q) = m.ik_nearest(&target, &reference) {
            out.push(([x, y, z], q));
        }
    }
    if out.len() < cfg.points {
        return Err(AccuracyError::PlaneUnreachable {
            z,
            found: out.len(),
            wanted: cfg.points,
            x: r.x,
            y: r.y,
        });
    }
    Ok(out)
}

/// SplitMix64-style mixing of (seed, stream, index) into a generator seed.
fn mix(seed: u64, stream: u64, index: u64) -> u64 {
    let mut z = seed ^ stream.rotate_left(17) ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Running sums and a histogram of one point's (or plane's) errors.
#[derive(Debug, Clone)]
struct Accum {
    n: u64,
    sum: f64,
    sum_sq: f64,
    max: f64,
    hist: Vec<u32>,
    overflow: u64,
}

impl Accum {
    fn new() -> Self {
        Self {
            n: 0,
            sum: 0.0,
            sum_sq: 0.0,
            max: 0.0,
            hist: vec![0; BINS],
            overflow: 0,
        }
    }

    fn merge(&mut self, o: &Accum) {
        self.n += o.n;
        self.sum += o.sum;
        self.sum_sq += o.sum_sq;
        self.max = self.max.max(o.max);
        self.overflow += o.overflow;
        for (a, b) in self.hist.iter_mut().zip(&o.hist) {
            *a += b;
        }
    }

    /// Statistics in mm; `bin_w` is the histogram bin width in metres.
    fn stats(&self, bin_w: f64) -> ErrorStats {
        if self.n == 0 {
            return ErrorStats::default();
        }
        let n = self.n as f64;
        let mean = self.sum / n;
        let var = (self.sum_sq / n - mean * mean).max(0.0) * n / (n - 1.0).max(1.0);
        let pct = |p: f64| -> f64 {
            if bin_w == 0.0 {
                return 0.0;
            }
            let k = (p * n).ceil().max(1.0) as u64;
            let mut cum = 0u64;
            for (i, &c) in self.hist.iter().enumerate() {
                if cum + c as u64 >= k {
                    let frac = (k - cum) as f64 / c as f64;
                    return (i as f64 + frac) * bin_w;
                }
                cum += c as u64;
            }
            // in the overflow (beyond 12 rms): the maximum bounds it
            self.max
        };
        ErrorStats {
            mean_mm: mean * 1e3,
            sd_mm: var.sqrt() * 1e3,
            median_mm: pct(0.5) * 1e3,
            p95_mm: pct(0.95) * 1e3,
            p99_mm: pct(0.99) * 1e3,
            max_mm: self.max * 1e3,
        }
    }
}

/// Monte Carlo draws at one point, into `acc` (histogram bin width `bin_w` m).
///
/// On x86-64 CPUs with AVX2 the same code is compiled a second time for 256-bit vectors and
/// chosen at run time. No fused multiply-add is used, so both versions produce bit-identical
/// results.
fn simulate_point(m: &Model, q: &[f64; 6], cfg: &McConfig, seed: u64, bin_w: f64, acc: &mut Accum) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: `simulate_point_avx2` only needs AVX2, and the CPU has it (checked above).
        #[allow(unsafe_code)]
        unsafe {
            return simulate_point_avx2(m, q, cfg, seed, bin_w, acc);
        }
    }
    simulate_point_impl(m, q, cfg, seed, bin_w, acc)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn simulate_point_avx2(
    m: &Model,
    q: &[f64; 6],
    cfg: &McConfig,
    seed: u64,
    bin_w: f64,
    acc: &mut Accum,
) {
    simulate_point_impl(m, q, cfg, seed, bin_w, acc)
}

#[inline(always)]
fn simulate_point_impl(
    m: &Model,
    q: &[f64; 6],
    cfg: &McConfig,
    seed: u64,
    bin_w: f64,
    acc: &mut Accum,
) {
    let k = PositionKernel::new(m, q);
    let p0 = k.position(&[0.0; 6]);
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let inv_w = if bin_w > 0.0 { 1.0 / bin_w } else { 0.0 };
    let sigma = cfg.sigma;
    let mut delta = [[0.0; LANES]; 6];
    let mut pos = [[0.0; LANES]; 3];
    // Per-lane running sums (independent chains), reduced in lane order at the end.
    let (mut sum, mut sum_sq, mut max, mut e2) =
        ([0.0; LANES], [0.0; LANES], [0.0f64; LANES], [0.0; LANES]);
    let mut left = cfg.draws;
    while left > 0 {
        let n = left.min(LANES);
        // Draw order: lane by lane, joint by joint (fixed, so results depend on the seed only).
        for l in 0..LANES {
            for j in 0..6 {
                let z: f64 = StandardNormal.sample(&mut rng);
                delta[j][l] = z * sigma[j];
            }
        }
        k.positions(&delta, &mut pos);
        let mut e = [0.0; LANES];
        for l in 0..LANES {
            let (dx, dy, dz) = (pos[0][l] - p0[0], pos[1][l] - p0[1], pos[2][l] - p0[2]);
            e2[l] = dx * dx + dy * dy + dz * dz;
            e[l] = e2[l].sqrt();
        }
        if n < LANES {
            // the last, partial block: unused lanes add nothing
            for l in n..LANES {
                e[l] = 0.0;
                e2[l] = 0.0;
            }
        }
        for l in 0..LANES {
            sum[l] += e[l];
            sum_sq[l] += e2[l];
            max[l] = max[l].max(e[l]);
        }
        for &el in &e[..n] {
            let bin = (el * inv_w) as usize;
            if bin < BINS {
                acc.hist[bin] += 1;
            } else {
                acc.overflow += 1;
            }
        }
        left -= n;
    }
    for l in 0..LANES {
        acc.sum += sum[l];
        acc.sum_sq += sum_sq[l];
        acc.max = acc.max.max(max[l]);
    }
    acc.n += cfg.draws as u64;
}

/// Runs the Monte Carlo and the linearised bound on every plane. `progress` is called with
/// the number of points finished so far (from worker threads).
pub fn run(
    model: &Model,
    cfg: &McConfig,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Vec<PlaneResult>, AccuracyError> {
    check(cfg)?;
    let m = tool_model(model, cfg);
    // Select every plane's points first, so a bad plane fails before any long work.
    let selected: Vec<_> = (0..cfg.planes.len())
        .map(|i| select_points(model, cfg, i))
        .collect::<Result<_, _>>()?;
    let done = std::sync::atomic::AtomicU64::new(0);
    let sigma = cfg.sigma;
    let mut planes = Vec::with_capacity(cfg.planes.len());
    for (pi, points) in selected.iter().enumerate() {
        let lin: Vec<linear::NormStats> = points
            .iter()
            .map(|(_, q)| linear::norm_stats(&linear::position_covariance(&m, q, &sigma)))
            .collect();
        let rms_max = lin.iter().map(|l| l.mean_square.sqrt()).fold(0.0, f64::max);
        let bin_w = RANGE_RMS * rms_max / BINS as f64;
        let results: Vec<(PointResult, Accum)> = points
            .par_iter()
            .enumerate()
            .map(|(i, (pos, q))| {
                let mut acc = Accum::new();
                simulate_point(
                    &m,
                    q,
                    cfg,
                    mix(cfg.seed, pi as u64 + 1, i as u64),
                    bin_w,
                    &mut acc,
                );
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
                let pr = PointResult {
                    position: *pos,
                    q: *q,
                    mc: acc.stats(bin_w),
                    linearised_mean_mm: lin[i].mean * 1e3,
                    linearised_sd_mm: lin[i].sd * 1e3,
                };
                (pr, acc)
            })
            .collect();
        let mut total = Accum::new();
        for (_, a) in &results {
            total.merge(a);
        }
        let n = lin.len() as f64;
        let lin_mean = lin.iter().map(|l| l.mean).sum::<f64>() / n;
        let lin_ms = lin.iter().map(|l| l.mean_square).sum::<f64>() / n;
        planes.push(PlaneResult {
            z: cfg.planes[pi],
            mc: total.stats(bin_w),
            linearised_mean_mm: lin_mean * 1e3,
            linearised_sd_mm: (lin_ms - lin_mean * lin_mean).max(0.0).sqrt() * 1e3,
            points: results.into_iter().map(|(p, _)| p).collect(),
        });
    }
    Ok(planes)
}

/// Mean position error (m) that resolver errors of `sigma` rad (1σ, every joint) alone cause
/// at the link configurations `qs` of `model`: `draws` seeded draws per configuration through
/// the position kernel (the floor a calibrated arm's validation error is judged against).
/// Sequential and deterministic for a seed; 0 when `qs` is empty.
pub fn floor_at(model: &Model, qs: &[[f64; 6]], sigma: f64, draws: usize, seed: u64) -> f64 {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut sum = 0.0;
    for q in qs {
        let k = PositionKernel::new(model, q);
        let p0 = k.position(&[0.0; 6]);
        for _ in 0..draws {
            let d: [f64; 6] = std::array::from_fn(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                sigma * z
            });
            let p = k.position(&d);
            sum +=
                ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2) + (p[2] - p0[2]).powi(2)).sqrt();
        }
    }
    sum / (qs.len() * draws).max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_floor_at_configurations_is_the_linearised_mean_norm() {
        let m = Model::nominal();
        let q = [0.2, 0.5, 1.4, 0.1, 1.0, 0.3];
        let sigma = 0.64 * ARCMIN;
        let mc = floor_at(&m, &[q], sigma, 20_000, 7);
        let lin = linear::norm_stats(&linear::position_covariance(&m, &q, &[sigma; 6])).mean;
        assert!(
            (mc / lin - 1.0).abs() < 0.02,
            "MC {mc} m vs linearised {lin} m"
        );
        assert_eq!(floor_at(&m, &[], sigma, 10, 7), 0.0);
    }

    fn small(points: usize, draws: usize) -> McConfig {
        McConfig {
            planes: vec![0.5],
            points,
            draws,
            ..McConfig::paper()
        }
    }

    #[test]
    fn monte_carlo_mean_matches_the_linearised_mean_within_one_percent_per_point() {
        let planes = run(&Model::nominal(), &small(6, 40_000), &|_| {}).expect("runs");
        for p in &planes[0].points {
            let ratio = p.mc.mean_mm / p.linearised_mean_mm;
            assert!((ratio - 1.0).abs() < 0.01, "{p:?}");
            // and the spread
            assert!(
                (p.mc.sd_mm / p.linearised_sd_mm - 1.0).abs() < 0.03,
                "{p:?}"
            );
        }
    }

    #[test]
    fn zero_sigma_gives_zero_error() {
        let cfg = McConfig {
            sigma: [0.0; 6],
            ..small(3, 100)
        };
        let planes = run(&Model::nominal(), &cfg, &|_| {}).expect("runs");
        assert_eq!(planes[0].mc, ErrorStats::default());
        assert_eq!(planes[0].linearised_mean_mm, 0.0);
    }

    #[test]
    fn one_joint_alone_gives_the_rayleigh_like_one_dimensional_error() {
        // Only J1 uncertain: the error is |r·δ| with r the radius of the point: E = r·σ·√(2/π).
        let cfg = McConfig {
            sigma: [0.64 * ARCMIN, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..small(2, 50_000)
        };
        let planes = run(&Model::nominal(), &cfg, &|_| {}).expect("runs");
        for p in &planes[0].points {
            let r = p.position[0].hypot(p.position[1]);
            let expect = r * cfg.sigma[0] * (2.0 / std::f64::consts::PI).sqrt() * 1e3;
            assert!((p.linearised_mean_mm / expect - 1.0).abs() < 1e-6);
            assert!((p.mc.mean_mm / expect - 1.0).abs() < 0.01);
        }
    }

    #[test]
    fn results_do_not_depend_on_the_number_of_threads() {
        let cfg = small(8, 3_000);
        let pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .expect("pool")
        };
        let one = pool(1)
            .install(|| run(&Model::nominal(), &cfg, &|_| {}))
            .expect("runs");
        let three = pool(3)
            .install(|| run(&Model::nominal(), &cfg, &|_| {}))
            .expect("runs");
        assert_eq!(one, three);
        let other_seed =
            run(&Model::nominal(), &McConfig { seed: 2, ..cfg }, &|_| {}).expect("runs");
        assert_ne!(one, other_seed);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_build_is_bit_identical_to_the_generic_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let m = Model::nominal();
        let cfg = small(1, 5_000);
        let (_, q) = select_points(&m, &cfg, 0).expect("points")[0];
        let m = tool_model(&m, &cfg);
        let (mut a, mut b) = (Accum::new(), Accum::new());
        simulate_point_impl(&m, &q, &cfg, 7, 1e-7, &mut a);
        #[allow(unsafe_code)]
        // SAFETY: AVX2 presence checked above.
        unsafe {
            simulate_point_avx2(&m, &q, &cfg, 7, 1e-7, &mut b)
        };
        assert_eq!(
            (a.sum, a.sum_sq, a.max, a.overflow),
            (b.sum, b.sum_sq, b.max, b.overflow)
        );
        assert_eq!(a.hist, b.hist);
    }

    #[test]
    fn bad_inputs_get_clear_errors() {
        let m = Model::nominal();
        let e = run(
            &m,
            &McConfig {
                sigma: [-1e-4, 0.0, 0.0, 0.0, 0.0, 0.0],
                ..small(1, 1)
            },
            &|_| {},
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("joint 1 σ must be finite and ≥ 0 rad"),
            "{e}"
        );
        let e = run(&m, &small(0, 1), &|_| {}).unwrap_err();
        assert!(e.to_string().contains("at least one point"), "{e}");
        let e = run(&m, &small(1, 0), &|_| {}).unwrap_err();
        assert!(e.to_string().contains("at least one draw"), "{e}");
        let e = run(
            &m,
            &McConfig {
                planes: vec![0.5, 3.0],
                ..small(2, 1)
            },
            &|_| {},
        )
        .unwrap_err();
        assert!(
            matches!(e, AccuracyError::PlaneUnreachable { z, found: 0, wanted: 2, .. } if z == 3.0),
            "{e}"
        );
        let e = run(
            &m,
            &McConfig {
                planes: vec![],
                ..small(1, 1)
            },
            &|_| {},
        )
        .unwrap_err();
        assert!(e.to_string().contains("at least one plane"));
        let cfg = McConfig {
            region: Region {
                x: (1.0, -1.0),
                y: (0.0, 1.0),
            },
            ..small(1, 1)
        };
        assert!(
            run(&m, &cfg, &|_| {})
                .unwrap_err()
                .to_string()
                .contains("region")
        );
    }

    #[test]
    fn points_are_reachable_and_in_the_region_with_the_tool_pointing_down() {
        let m = Model::nominal();
        let cfg = McConfig {
            region: Region {
                x: (0.2, 0.6),
                y: (-0.3, 0.3),
            },
            ..small(20, 1)
        };
        let tm = tool_model(&m, &cfg);
        for (p, q) in select_points(&m, &cfg, 0).expect("points") {
            assert!(p[0] >= 0.2 && p[0] < 0.6 && p[1] >= -0.3 && p[1] < 0.3);
            let f = tm.fk(&q);
            assert!((f.translation.vector - Vector3::from(p)).norm() < 1e-9);
            assert!((f.rotation.matrix().column(2) + Vector3::z()).norm() < 1e-9);
        }
    }
}
