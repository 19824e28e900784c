//! The resolver bound on the seed paper's setting.

use pa10::accuracy::{McConfig, run};
use pa10::model::Model;

/// The paper's five planes and 200 points per plane, at 2 000 draws per point (the full
/// 100 000 is a benchmark): Monte Carlo and linearised means agree within 2 % per plane,
/// and the z = 0.5 m figure lands near the paper's 0.197 ± 0.096 mm.
#[test]
fn paper_setting_monte_carlo_and_linearised_agree_within_two_percent() {
    let _cpu = crate::common::busy_lock();
    let cfg = McConfig {
        draws: 2_000,
        ..McConfig::paper()
    };
    let planes = run(&Model::nominal(), &cfg, &|_| {}).unwrap();
    assert_eq!(planes.len(), 5);
    for p in &planes {
        let ratio = p.mc.mean_mm / p.linearised_mean_mm;
        assert!(
            (ratio - 1.0).abs() < 0.02,
            "z {}: MC {} vs lin {}",
            p.z,
            p.mc.mean_mm,
            p.linearised_mean_mm
        );
        assert!(
            p.mc.median_mm < p.mc.mean_mm * 1.05
                && p.mc.p95_mm > p.mc.mean_mm
                && p.mc.p99_mm > p.mc.p95_mm
        );
        assert!(p.mc.max_mm >= p.mc.p99_mm);
        assert_eq!(p.points.len(), 200);
    }
    let mid = &planes[2];
    assert!(
        (0.12..0.28).contains(&mid.mc.mean_mm),
        "z 0.5: {} mm",
        mid.mc.mean_mm
    );
    assert!(
        (0.05..0.14).contains(&mid.mc.sd_mm),
        "z 0.5: sd {} mm",
        mid.mc.sd_mm
    );
}

/// The floor a judge compares placements with (`floor_at`: resolver errors drawn as
/// independent Gaussians of σ per joint) is the expectation of what a simulated arm's
/// repeatable resolver error (three harmonics of the motor revolution per joint, rms σ)
/// realises at novel poses — with the tool on J6's axis and well off it, where J6's error
/// moves the tool point too. Over 40 drawn arms × 20 poses the realised / floor ratio
/// averages within 5 % of 1 (its spread between arms is ≈ 0.1, so the mean's standard error
/// is ≈ 0.016); a floor that left the tool's 0.2 m offset from the axis out would be a fifth low.
/// The MuJoCo judge calls a miss the resolvers' against this expectation (docs/judge.md §9).
#[test]
fn the_floor_is_the_expectation_of_a_repeatable_resolver_error_on_or_off_axis() {
    use pa10::accuracy::{floor_at, kernel::PositionKernel};
    use pa10::model::frame_from_pose;
    use pa10::sim::{SimNoise, TrueRobot, experiment::random_pose, rig::default_tool};
    use rand::SeedableRng;

    for (tool, off_axis) in [([0.0, 0.0, 0.35], false), ([0.2, 0.0, 0.2], true)] {
        let tool = frame_from_pose(tool, [1.0, 0.0, 0.0, 0.0]);
        let nominal = Model::nominal().with_tool(&tool).unwrap();
        let mut ratios = Vec::new();
        let mut without_tool = Vec::new();
        for seed in 1..=40u64 {
            let truth = TrueRobot::draw(
                seed,
                &Model::nominal(),
                &default_tool(),
                SimNoise::default(),
            )
            .unwrap();
            let arm = truth.model.with_tool(&tool).unwrap();
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0xf100);
            let mut qs = Vec::new();
            while qs.len() < 20 {
                let t = random_pose(&mut rng, [0.40, -0.25, -0.10], [0.75, 0.25, 0.30]);
                let p = t.translation.vector;
                let reference = [p.y.atan2(p.x), 0.3, 1.6, 0.0, 1.1, 0.0];
                if let Ok(q) = nominal.ik_nearest(&t, &reference) {
                    qs.push(q);
                }
            }
            // the servo holds the reading at q: the motor rests at q − e(q)
            let realised = qs
                .iter()
                .map(|q| {
                    let k = PositionKernel::new(&arm, q);
                    let e: [f64; 6] = std::array::from_fn(|j| -truth.resolver_error(j, q[j]));
                    let (a, b) = (k.position(&[0.0; 6]), k.position(&e));
                    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
                })
                .sum::<f64>()
                / qs.len() as f64;
            let sigma = truth.noise.resolver_rad;
            ratios.push(realised / floor_at(&arm, &qs, sigma, 500, seed));
            if off_axis {
                let flange = arm
                    .with_tool(&frame_from_pose([0.0, 0.0, 0.2], [1.0, 0.0, 0.0, 0.0]))
                    .unwrap();
                without_tool.push(realised / floor_at(&flange, &qs, sigma, 500, seed));
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let m = mean(&ratios);
        assert!(
            (m - 1.0).abs() < 0.05,
            "off axis {off_axis}: realised / floor {m:.3} over 40 arms"
        );
        if off_axis {
            let w = mean(&without_tool);
            assert!(w > 1.15, "a floor without the tool's offset: {w:.3}");
        }
    }
}
