//! Property tests (proptest, fixed RNG seed so every run checks the same cases).

use pa10::model::{ExternalLoad, Model, Stiffness};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

use crate::common::{max_diff, perturbed_model, rng};

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(0x9a10),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config(4000))]

    /// δ(τ) inverts τ(δ) for every torque in ±1e4 N·m and every Klin > 0, Kcub ≥ 0.
    #[test]
    fn compliance_inverse_is_exact(
        tau in -1e4f64..1e4,
        log_klin in 2.0f64..6.0,
        log_kcub in prop_oneof![Just(f64::NEG_INFINITY), 3.0f64..9.0],
    ) {
        let k = Stiffness { klin: 10f64.powf(log_klin), kcub: 10f64.powf(log_kcub) };
        let d = k.deflection(tau);
        // Both spring terms share the torque's sign, so evaluating τ(δ) rounds by a few
        // ulps of |τ|: the residual must be that small, i.e. δ is exact to float precision.
        prop_assert!((k.torque(d) - tau).abs() <= 8.0 * f64::EPSILON * tau.abs());
        prop_assert_eq!(d.signum(), if tau == 0.0 { d.signum() } else { tau.signum() });
    }
}

proptest! {
    #![proptest_config(config(300))]

    /// Compensating a link target and reading it back through the gravity fixed point
    /// recovers the link angles, for any configuration and hung load up to 100 N.
    #[test]
    fn compensation_round_trip(
        q in proptest::array::uniform6(-1.5f64..1.5),
        load_n in 0.0f64..100.0,
        seed in 0u64..16,
    ) {
        let m: Model = perturbed_model(&mut rng(seed));
        let load = ExternalLoad::hung(load_n, &m.gravity());
        let (qm, _) = m.compensate_static(&q, &load).unwrap();
        let (back, _) = m.link_from_motor_static(&qm, &load).unwrap();
        prop_assert!(max_diff(&back, &q) < 1e-12);
    }
}
