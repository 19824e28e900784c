//! The noise estimator on synthetic samples of known noise, seeded.

use super::*;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

/// Synthetic rows: a random sensitivity per configuration, reading noise `read`,
/// repeatable error `rep` (rad), instrument noise per axis `inst` (m / rad), torque noise
/// 0.3 N·m; `moves`: the readings' scatter is real motion rather than noise.
fn rows(read: f64, rep: f64, inst: [f64; 6], moves: bool, seed: u64) -> Vec<Sample> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut out = Vec::new();
    for c in 0..40 {
        let jq = Matrix6::from_fn(|_, _| 0.4 * g());
        let jt = Matrix6::from_fn(|_, _| 1e-5 * g());
        let off: [f64; 6] = std::array::from_fn(|_| rep * g());
        for load in 0..3 {
            let tau0: [f64; 6] = std::array::from_fn(|j| 10.0 * (j as f64 + load as f64));
            for _ in 0..5 {
                let eps: [f64; 6] = std::array::from_fn(|_| read * g());
                let dtau: [f64; 6] = std::array::from_fn(|_| 0.3 * g());
                let nu = Vector6::from_fn(|a, _| inst[a] * g());
                let e = Vector6::from_fn(|j, _| off[j] + if moves { 0.0 } else { eps[j] });
                let t = Vector6::from_fn(|j, _| dtau[j]);
                out.push(Sample {
                    config: c,
                    cell: 3 * c + load,
                    q: std::array::from_fn(|j| 0.1 * j as f64 + eps[j]),
                    tau: std::array::from_fn(|j| tau0[j] + dtau[j]),
                    residual: nu - jq * e - jt * t,
                    jq,
                    jt,
                });
            }
        }
    }
    out
}

const INST: [f64; 6] = [5e-6, 8e-6, 12e-6, 50e-6, 60e-6, 70e-6];

fn within_20(est: f64, truth: f64) -> bool {
    (est / truth - 1.0).abs() < 0.2
}

#[test]
fn reading_noise_is_recovered_and_named() {
    let s = rows(2e-4, 0.0, INST, false, 1);
    let m = estimate(
        &s,
        &Matrix3::identity(),
        6.0 * 40.0 - 30.0,
        &Prior::default(),
    )
    .unwrap();
    assert_eq!(m.structure, Structure::Reading, "{}", m.summary());
    for j in 0..6 {
        assert!(within_20(m.reading_rad[j].value, 2e-4), "{}", m.summary());
    }
    // 95 % intervals: with six joints one may miss by chance, two would be a defect.
    let covered = m
        .reading_rad
        .iter()
        .filter(|i| i.lo <= 2e-4 && 2e-4 <= i.hi)
        .count();
    assert!(covered >= 5, "{:?}", m.reading_rad);
    for a in 0..3 {
        assert!(
            within_20(m.instrument_position_m[a].value, INST[a]),
            "{}",
            m.summary()
        );
        assert!(within_20(
            m.instrument_orientation_rad[a].value,
            INST[3 + a]
        ));
    }
    for j in 0..6 {
        assert!(within_20(m.torque_nm[j].value, 0.3), "{}", m.summary());
    }
    assert!(m.repeatable_rad.value < 5e-5, "{}", m.summary());
}

#[test]
fn real_motion_is_not_reading_noise() {
    let s = rows(2e-4, 0.0, INST, true, 2);
    let m = estimate(&s, &Matrix3::identity(), 210.0, &Prior::default()).unwrap();
    assert_eq!(m.structure, Structure::InstrumentOnly, "{}", m.summary());
    for j in 0..6 {
        assert!(m.reading_rad[j].value < 4e-5, "{}", m.summary());
        assert!(within_20(m.reading_scatter_rad[j], 2e-4));
    }
}

#[test]
fn repeatable_error_is_recovered_and_named() {
    let s = rows(0.0, 2e-4, INST, false, 3);
    // 40 configurations × 6 components, nothing fitted to them in this synthetic set.
    let m = estimate(&s, &Matrix3::identity(), 240.0, &Prior::default()).unwrap();
    assert_eq!(m.structure, Structure::Repeatable, "{}", m.summary());
    assert!(within_20(m.repeatable_rad.value, 2e-4), "{}", m.summary());
    assert!(m.repeatable_rad.lo < 2e-4 && 2e-4 < m.repeatable_rad.hi);
}

#[test]
fn both_are_recovered_and_named() {
    let s = rows(1.5e-4, 2e-4, INST, false, 4);
    let m = estimate(&s, &Matrix3::identity(), 240.0, &Prior::default()).unwrap();
    assert_eq!(m.structure, Structure::Both, "{}", m.summary());
    assert!(within_20(m.repeatable_rad.value, 2e-4), "{}", m.summary());
    assert!(within_20(m.reading_rad[2].value, 1.5e-4), "{}", m.summary());
}

#[test]
fn the_instrument_axes_are_those_of_the_instrument_frame() {
    // The base frame is the instrument frame turned 90° about z: x and y swap.
    let r = nalgebra::Rotation3::from_axis_angle(
        &nalgebra::Vector3::z_axis(),
        0.5 * std::f64::consts::PI,
    );
    let mut s = rows(0.0, 0.0, INST, false, 5);
    let r6 = rot6(r.matrix());
    for x in &mut s {
        x.residual = r6 * x.residual;
        x.jq = r6 * x.jq;
        x.jt = r6 * x.jt;
    }
    let m = estimate(&s, r.matrix(), 240.0, &Prior::default()).unwrap();
    for a in 0..3 {
        assert!(
            within_20(m.instrument_position_m[a].value, INST[a]),
            "{}",
            m.summary()
        );
    }
}

#[test]
fn without_repeats_the_prior_is_assumed_and_said() {
    let s: Vec<Sample> = rows(2e-4, 0.0, INST, false, 6)
        .into_iter()
        .step_by(5)
        .collect();
    let m = estimate(&s, &Matrix3::identity(), 100.0, &Prior::default()).unwrap();
    assert_eq!(m.structure, Structure::Assumed);
    assert!(
        m.assumption
            .as_deref()
            .is_some_and(|a| a.contains("cannot be measured"))
    );
    assert_eq!(m.reading_rad[0].value, Prior::default().resolver_rad);
}

#[test]
fn bad_input_is_refused() {
    assert_eq!(
        estimate(&[], &Matrix3::identity(), 1.0, &Prior::default()),
        Err(NoiseError::Empty)
    );
    let mut s = rows(1e-4, 0.0, INST, false, 7);
    s[3].q[2] = f64::NAN;
    assert!(matches!(
        estimate(&s, &Matrix3::identity(), 1.0, &Prior::default()),
        Err(NoiseError::NotFinite { row: 3, what: "q" })
    ));
    let p = Prior {
        position_m: -1.0,
        ..Prior::default()
    };
    assert!(matches!(
        estimate(
            &rows(1e-4, 0.0, INST, false, 8),
            &Matrix3::identity(),
            1.0,
            &p
        ),
        Err(NoiseError::Prior(_))
    ));
}
