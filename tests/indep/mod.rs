//! An independent generator of PA10 measurement sets: the judge of calibration and
//! discovery, sharing no code with `src/` (no `pa10` item, no nalgebra, its own random
//! numbers). It writes the same CSV and sidecar a real campaign would.
//!
//! Its physics: standard DH with Hayati's β on joint 2 (own 4×4 matrices), departures within
//! the seed paper's tolerances, linear + cubic springs on J2, J3, J5 deflected by gravity and
//! load torques it computes as `∂V/∂q` of its own point masses (finite differences of the
//! potential energy, not Jacobians), a 0.35 m tool tilted up to 35°, an instrument frame
//! anywhere within a metre. Its noise families:
//!
//! - `reading`: the readings scatter from repeat to repeat, the arm stays (errors in
//!   variables);
//! - `repeatable`: each configuration's readings are off by a fixed error, identical for
//!   every repeat;
//! - `both`;
//! - per-axis instrument noise (x, y, z differ), relative + absolute torque noise.
//!
//! Hidden effects of its own: a J4 spring (in the discovery library), and a polynomial
//! error `δq_j = c·q_jⁿ` on one joint (outside it).
#![allow(dead_code)]

use std::fmt::Write as _;

/// SplitMix64 + Box–Muller: this generator's own random numbers.
pub struct Rng(u64, Option<f64>);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x1d3e_9c5a_77b1_0f42, None)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    pub fn normal(&mut self) -> f64 {
        if let Some(v) = self.1.take() {
            return v;
        }
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.1 = Some(r * t.sin());
        r * t.cos()
    }
}

type M4 = [[f64; 4]; 4];

fn mul(a: &M4, b: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            c[i][j] = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

fn ident() -> M4 {
    let mut m = [[0.0; 4]; 4];
    for (i, r) in m.iter_mut().enumerate() {
        r[i] = 1.0;
    }
    m
}

fn rot(axis: usize, a: f64) -> M4 {
    let (s, c) = a.sin_cos();
    let mut m = ident();
    let (i, j) = match axis {
        0 => (1, 2),
        1 => (2, 0),
        _ => (0, 1),
    };
    m[i][i] = c;
    m[i][j] = -s;
    m[j][i] = s;
    m[j][j] = c;
    m
}

fn trans(x: f64, y: f64, z: f64) -> M4 {
    let mut m = ident();
    m[0][3] = x;
    m[1][3] = y;
    m[2][3] = z;
    m
}

fn inverse(m: &M4) -> M4 {
    let mut r = ident();
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = m[j][i];
        }
    }
    for i in 0..3 {
        r[i][3] = -(0..3).map(|k| m[k][i] * m[k][3]).sum::<f64>();
    }
    r
}

/// Unit quaternion `[w, x, y, z]` of a rotation matrix (Shepperd).
fn quat(m: &M4) -> [f64; 4] {
    let t = m[0][0] + m[1][1] + m[2][2];
    let q = if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let sgn = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|v| sgn * v / n)
}

/// Small rotation of `v` (rotation vector, rad) as a matrix (Rodrigues).
fn rotvec(v: [f64; 3]) -> M4 {
    let a = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if a < 1e-300 {
        return ident();
    }
    let k = [v[0] / a, v[1] / a, v[2] / a];
    let (s, c) = a.sin_cos();
    let mut m = ident();
    for i in 0..3 {
        for j in 0..3 {
            let kk = k[i] * k[j] * (1.0 - c);
            let skew = match (i, j) {
                (0, 1) => -k[2],
                (1, 0) => k[2],
                (0, 2) => k[1],
                (2, 0) => -k[1],
                (1, 2) => -k[0],
                (2, 1) => k[0],
                _ => 0.0,
            };
            m[i][j] = if i == j { c + kk } else { kk + s * skew };
        }
    }
    m
}

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// The nominal PA10-6C standard DH table: (a, α, d, θ offset), m and rad.
const DH: [(f64, f64, f64, f64); 6] = [
    (0.0, -HALF_PI, 0.317, 0.0),
    (0.450, 0.0, 0.0, -HALF_PI),
    (0.0, HALF_PI, 0.0, HALF_PI),
    (0.0, -HALF_PI, 0.480, 0.0),
    (0.0, HALF_PI, 0.0, 0.0),
    (0.0, 0.0, 0.070, 0.0),
];

/// Point masses: (link frame index 1…6, kg, centre in that frame, m). Its own values,
/// not the model file's.
const MASSES: [(usize, f64, [f64; 3]); 4] = [
    (2, 12.5, [-0.28, 0.0, 0.01]),
    (3, 7.9, [0.0, 0.01, 0.17]),
    (5, 1.9, [0.0, 0.0, -0.03]),
    (6, 0.6, [0.0, 0.0, 0.02]),
];

/// The paper's springs (Klin N·m/rad, Kcub N·m/rad³) on J2, J3, J5.
const SPRINGS: [(usize, f64, f64); 3] = [
    (1, 1.98e4, 3.35e7),
    (2, 1.27e4, 1.46e7),
    (4, 2.56e3, 3.83e7),
];

const G: f64 = 9.80665;

/// One noise family.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Family {
    pub name: &'static str,
    /// Reading noise per joint (1σ), rad.
    pub reading_rad: f64,
    /// Repeatable error per joint and configuration (1σ), rad.
    pub repeatable_rad: f64,
    /// Instrument position noise per axis (1σ), m.
    pub instrument_m: [f64; 3],
    /// Instrument orientation noise per axis (1σ), rad.
    pub instrument_rad: [f64; 3],
    /// Torque noise: relative, absolute (N·m).
    pub torque_rel: f64,
    pub torque_abs_nm: f64,
}

const ARCMIN: f64 = std::f64::consts::PI / (180.0 * 60.0);

/// The families the statistics are made on: 0.64 arcmin of resolver error in each
/// structure, the paper's 12 µm instrument with unequal axes.
pub fn families() -> [Family; 3] {
    let base = Family {
        name: "reading",
        reading_rad: 0.64 * ARCMIN,
        repeatable_rad: 0.0,
        instrument_m: [6e-6, 7e-6, 8.5e-6],
        instrument_rad: [5e-5, 6e-5, 8e-5],
        torque_rel: 0.02,
        torque_abs_nm: 0.15,
    };
    [
        base,
        Family {
            name: "repeatable",
            reading_rad: 0.0,
            repeatable_rad: 0.64 * ARCMIN,
            ..base
        },
        Family {
            name: "both",
            reading_rad: 0.45 * ARCMIN,
            repeatable_rad: 0.45 * ARCMIN,
            ..base
        },
    ]
}

/// What is hidden from the paper's model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hidden {
    None,
    /// A linear spring on J4, N·m/rad.
    SpringJ4(f64),
    /// `δq_j = c·q_jⁿ` on joint `j` (zero-based): `(j, n, c)`, c in rad/radⁿ.
    Poly(usize, i32, f64),
}

/// A measurement campaign to generate.
#[derive(Debug, Clone)]
pub struct Spec {
    pub seed: u64,
    pub configs: usize,
    pub loads: Vec<f64>,
    pub repeats: usize,
    pub family: Family,
    pub hidden: Hidden,
    /// Validation configurations (each at 0/44/90 N): 30, or the paper's Fig. 6 design of 10.
    pub validation_configs: usize,
    /// J6 commanded to 0 in every configuration (the paper's campaigns never turn the tool
    /// about its axis): no J6 effect can be seen, and none may be named.
    pub still_j6: bool,
}

impl Spec {
    /// The paper's campaign: 27 configurations × 0/22/44 N × 10 repeats.
    pub fn paper(seed: u64, family: Family) -> Self {
        Self {
            seed,
            configs: 27,
            loads: vec![0.0, 22.0, 44.0],
            repeats: 10,
            family,
            hidden: Hidden::None,
            validation_configs: 30,
            still_j6: false,
        }
    }

    /// The paper's campaign with the paper's validation design: 10 novel configurations,
    /// J6 never turned.
    pub fn paper_validation(seed: u64, family: Family) -> Self {
        Self {
            validation_configs: 10,
            still_j6: true,
            ..Self::paper(seed, family)
        }
    }
}

/// The hidden robot.
#[derive(Debug, Clone)]
pub struct Robot {
    /// Per joint (a, α, d, θ offset) with departures, and β2.
    dh: [(f64, f64, f64, f64); 6],
    beta2: f64,
    tool: M4,
    /// Instrument frame in the base frame.
    instrument: M4,
    springs: [(f64, f64); 6],
    hidden: Hidden,
}

impl Robot {
    pub fn draw(rng: &mut Rng, hidden: Hidden) -> Self {
        let mut dh = DH;
        for (j, row) in dh.iter_mut().enumerate() {
            row.0 += rng.range(-0.25e-3, 0.25e-3);
            row.1 += rng.range(-1e-3, 1e-3);
            if j != 1 {
                row.2 += rng.range(-0.25e-3, 0.25e-3);
            }
            row.3 += rng.range(-0.5e-3, 0.5e-3);
        }
        let beta2 = rng.range(-1e-3, 1e-3);
        let mut springs = [(0.0, 0.0); 6];
        for &(j, kl, kc) in &SPRINGS {
            springs[j] = (kl * rng.range(0.9, 1.1), kc * rng.range(0.8, 1.2));
        }
        if let Hidden::SpringJ4(k) = hidden {
            springs[3] = (k, 0.0);
        }
        let tilt = rng.range(0.0, 35f64.to_radians());
        let az = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
        let r = mul(&rot(2, az), &rot(0, tilt));
        // The tool frame is the tilted one, at the tip.
        let tool = mul(&r, &trans(0.0, 0.0, 0.35));
        let yaw = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
        let ang = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
        let dist = rng.range(0.6, 1.1);
        let instrument = mul(
            &trans(dist * ang.cos(), dist * ang.sin(), rng.range(-0.4, 0.1)),
            &mul(
                &rot(2, yaw),
                &mul(
                    &rot(0, rng.range(-0.02, 0.02)),
                    &rot(1, rng.range(-0.02, 0.02)),
                ),
            ),
        );
        Self {
            dh,
            beta2,
            tool,
            instrument,
            springs,
            hidden,
        }
    }

    /// Base-frame transforms of frames 0…6 at link angles `q`.
    fn frames(&self, q: &[f64; 6]) -> [M4; 7] {
        let mut f = [ident(); 7];
        for j in 0..6 {
            let (a, al, d, off) = self.dh[j];
            let mut t = mul(&rot(2, q[j] + off), &mul(&trans(a, 0.0, d), &rot(0, al)));
            if j == 1 {
                t = mul(&t, &rot(1, self.beta2));
            }
            f[j + 1] = mul(&f[j], &t);
        }
        f
    }

    /// Tool pose in the base frame.
    fn tool_pose(&self, q: &[f64; 6]) -> M4 {
        mul(&self.frames(q)[6], &self.tool)
    }

    /// Potential energy, J (masses and a hung load at the tool).
    fn potential(&self, q: &[f64; 6], load_n: f64) -> f64 {
        let f = self.frames(q);
        let mut v = 0.0;
        for &(k, m, c) in &MASSES {
            let z = (0..3).map(|i| f[k][2][i] * c[i]).sum::<f64>() + f[k][2][3];
            v += m * G * z;
        }
        let t = mul(&f[6], &self.tool);
        v + load_n * t[2][3]
    }

    /// Joint torques the drives carry, `∂V/∂q` (central differences), N·m.
    fn torques(&self, q: &[f64; 6], load_n: f64) -> [f64; 6] {
        std::array::from_fn(|j| {
            let h = 1e-6;
            let (mut a, mut b) = (*q, *q);
            a[j] += h;
            b[j] -= h;
            (self.potential(&a, load_n) - self.potential(&b, load_n)) / (2.0 * h)
        })
    }

    /// Spring deflection under `tau` (Newton on `klin·δ + kcub·δ³ = τ`).
    fn deflection(&self, j: usize, tau: f64) -> f64 {
        let (kl, kc) = self.springs[j];
        if kl == 0.0 {
            return 0.0;
        }
        let mut d = tau / kl;
        for _ in 0..30 {
            let f = kl * d + kc * d * d * d - tau;
            d -= f / (kl + 3.0 * kc * d * d);
        }
        d
    }

    /// Where the link sits for motor angles `qm` under `load_n`, and its torques.
    fn settle(&self, qm: &[f64; 6], load_n: f64) -> ([f64; 6], [f64; 6]) {
        let mut q = *qm;
        let mut tau = [0.0; 6];
        for _ in 0..60 {
            tau = self.torques(&q, load_n);
            let next: [f64; 6] = std::array::from_fn(|j| {
                let extra = match self.hidden {
                    Hidden::Poly(k, n, c) if j == k => c * qm[j].powi(n),
                    _ => 0.0,
                };
                qm[j] - self.deflection(j, tau[j]) - extra
            });
            let step = (0..6).map(|j| (next[j] - q[j]).abs()).fold(0.0, f64::max);
            q = next;
            if step < 1e-14 {
                break;
            }
        }
        (q, tau)
    }

    /// Position Jacobian (3×6, m/rad) of the tool at link angles `q`, by differences.
    fn position_jacobian(&self, q: &[f64; 6]) -> [[f64; 6]; 3] {
        let mut j = [[0.0; 6]; 3];
        for k in 0..6 {
            let (mut a, mut b) = (*q, *q);
            a[k] += 1e-6;
            b[k] -= 1e-6;
            let (pa, pb) = (self.tool_pose(&a), self.tool_pose(&b));
            for (i, row) in j.iter_mut().enumerate() {
                row[k] = (pa[i][3] - pb[i][3]) / 2e-6;
            }
        }
        j
    }
}

/// A generated set: the CSVs, their sidecar, and the truth to judge by.
#[derive(Debug, Clone)]
pub struct Set {
    pub cal_csv: String,
    pub val_csv: String,
    pub meta_yaml: String,
    /// Validation "floor": the mean position error (mm) that the family's resolver and
    /// instrument noise alone cause on the validation rows (Monte Carlo, 200 draws a row).
    pub val_floor_mm: f64,
    pub family: Family,
}

const HEADER: &str =
    "config_id,load_n,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6,x,y,z,qw,qx,qy,qz";

/// Random joint configurations clear of limits and the wrist singularity.
fn configs(rng: &mut Rng, n: usize) -> Vec<[f64; 6]> {
    const R: [(f64, f64); 6] = [
        (-1.4, 1.4),
        (-0.4, 1.2),
        (0.3, 2.2),
        (-1.6, 1.6),
        (0.4, 1.9),
        (-1.6, 1.6),
    ];
    (0..n)
        .map(|_| std::array::from_fn(|j| rng.range(R[j].0, R[j].1)))
        .collect()
}

fn row(out: &mut String, id: &str, load: f64, q: &[f64; 6], tau: &[f64; 6], pose: &M4) {
    let qq = quat(pose);
    let _ = write!(out, "{id},{load}");
    for v in q.iter().chain(tau) {
        let _ = write!(out, ",{v:.15e}");
    }
    for v in [
        pose[0][3], pose[1][3], pose[2][3], qq[0], qq[1], qq[2], qq[3],
    ] {
        let _ = write!(out, ",{v:.15e}");
    }
    out.push('\n');
}

/// Measures `q_cmd` (motor-side command) on `robot`: returns readings, measured torques and
/// the measured pose in the instrument frame. `rep` is the configuration's repeatable error.
fn measure(
    robot: &Robot,
    fam: &Family,
    q_cmd: &[f64; 6],
    rep: &[f64; 6],
    load: f64,
    rng: &mut Rng,
) -> ([f64; 6], [f64; 6], M4) {
    // The servo holds the motor where the repeatable-error-laden reading equals the command.
    let qm: [f64; 6] = std::array::from_fn(|j| q_cmd[j] - rep[j]);
    let (q, tau) = robot.settle(&qm, load);
    let reading: [f64; 6] = std::array::from_fn(|j| q_cmd[j] + fam.reading_rad * rng.normal());
    let tau_m: [f64; 6] = std::array::from_fn(|j| {
        tau[j] * (1.0 + fam.torque_rel * rng.normal()) + fam.torque_abs_nm * rng.normal()
    });
    let truth = mul(&inverse(&robot.instrument), &robot.tool_pose(&q));
    let dr = [0, 1, 2].map(|a| fam.instrument_rad[a] * rng.normal());
    let mut pose = mul(&rotvec(dr), &truth);
    for a in 0..3 {
        pose[a][3] = truth[a][3] + fam.instrument_m[a] * rng.normal();
    }
    (reading, tau_m, pose)
}

/// Generates the campaign `spec` and a validation set (`spec.validation_configs` other
/// configurations × 0/44/90 N, one measurement each).
pub fn generate(spec: &Spec) -> Set {
    let mut rng = Rng::new(spec.seed);
    let robot = Robot::draw(&mut rng, spec.hidden);
    let fam = spec.family;
    let mut cal = format!("{HEADER}\n");
    let still = |mut q: [f64; 6]| {
        if spec.still_j6 {
            q[5] = 0.0;
        }
        q
    };
    for (c, q) in configs(&mut rng, spec.configs)
        .into_iter()
        .map(still)
        .enumerate()
    {
        let q = &q;
        let rep: [f64; 6] = std::array::from_fn(|_| fam.repeatable_rad * rng.normal());
        for &load in &spec.loads {
            for _ in 0..spec.repeats {
                let (qr, t, p) = measure(&robot, &fam, q, &rep, load, &mut rng);
                row(&mut cal, &format!("k{c:02}"), load, &qr, &t, &p);
            }
        }
    }
    let mut val = format!("{HEADER}\n");
    let (mut floor, mut n) = (0.0, 0usize);
    for (c, q) in configs(&mut rng, spec.validation_configs)
        .into_iter()
        .map(still)
        .enumerate()
    {
        let q = &q;
        let rep: [f64; 6] = std::array::from_fn(|_| fam.repeatable_rad * rng.normal());
        for load in [0.0, 44.0, 90.0] {
            let (qr, t, p) = measure(&robot, &fam, q, &rep, load, &mut rng);
            row(&mut val, &format!("v{c:02}"), load, &qr, &t, &p);
            // The error a perfect model makes here: resolver error through the Jacobian
            // plus instrument noise.
            let (ql, _) = robot.settle(q, load);
            let j = robot.position_jacobian(&ql);
            let s = (fam.reading_rad.powi(2) + fam.repeatable_rad.powi(2)).sqrt();
            for _ in 0..200 {
                let e: [f64; 6] = std::array::from_fn(|_| s * rng.normal());
                let d: [f64; 3] = std::array::from_fn(|i| {
                    (0..6).map(|k| j[i][k] * e[k]).sum::<f64>() + fam.instrument_m[i] * rng.normal()
                });
                floor += (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                n += 1;
            }
        }
    }
    let tq = quat(&robot.tool);
    let meta_yaml = format!(
        "instrument: independent generator (tests/indep), family {}, seed {}\ntool:\n  translation: [{:.15e}, {:.15e}, {:.15e}]\n  quaternion: [{:.15e}, {:.15e}, {:.15e}, {:.15e}]\nnoise: {{position_m: 12.1e-6, resolver_arcmin: 0.64}}\n",
        fam.name,
        spec.seed,
        robot.tool[0][3],
        robot.tool[1][3],
        robot.tool[2][3],
        tq[0],
        tq[1],
        tq[2],
        tq[3]
    );
    Set {
        cal_csv: cal,
        val_csv: val,
        meta_yaml,
        val_floor_mm: floor / n as f64 * 1e3,
        family: fam,
    }
}

/// Writes `set` as `dir/cal.csv`, `dir/val.csv` and their sidecars; returns the paths.
pub fn write(set: &Set, dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    std::fs::create_dir_all(dir).expect("create the set's directory");
    let cal = dir.join("cal.csv");
    let val = dir.join("val.csv");
    std::fs::write(&cal, &set.cal_csv).expect("write cal.csv");
    std::fs::write(&val, &set.val_csv).expect("write val.csv");
    std::fs::write(dir.join("cal.meta.yaml"), &set.meta_yaml).expect("write the sidecar");
    std::fs::write(dir.join("val.meta.yaml"), &set.meta_yaml).expect("write the sidecar");
    (cal, val)
}
