//! How the calibration choices play out over many simulated robots.
//!
//! `cargo run --release --example calibration_study [SEEDS]` — for each seed, a hidden true
//! robot and the paper's campaign (`pa10 sim measure`), calibrated four ways: GLS or the
//! paper's row weighting, with ε = 0 (priors only on unidentifiable directions) or the
//! paper's ε = 1.6e-4. Prints the stiffness errors, the validation error against the resolver
//! floor, and the base-frame error (δd1, δθ1 folded in). docs/calibration.md quotes its output.

use pa10::accuracy::ARCMIN;
use pa10::calib::fit::{
    CalibOptions, Weighting, calibrate, canonical_base, evaluate, resolver_floor,
};
use pa10::model::{Model, pose_error};
use pa10::sim::experiment::{CampaignSpec, paper_campaign};

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(8);
    let variants = [
        ("GLS, ε = 0 (default)", Weighting::Gls, 0.0),
        ("paper weighting, ε = 0", Weighting::Paper, 0.0),
        ("GLS, ε = 1.6e-4", Weighting::Gls, 1.6e-4),
        (
            "paper weighting, ε = 1.6e-4 (the paper)",
            Weighting::Paper,
            1.6e-4,
        ),
    ];
    println!(
        "| variant | worst \\|ΔKlin\\| J2, J3 | worst \\|ΔKlin\\| J5 | validation / floor: mean (worst) | validation mean [mm] | base error, worst [mm, mrad] |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, weighting, epsilon) in variants {
        let (mut k23, mut k5, mut ratios, mut vals, mut bp, mut br) =
            (0.0f64, 0.0f64, Vec::new(), Vec::new(), 0.0f64, 0.0f64);
        for seed in 1..=seeds {
            let c = paper_campaign(&CampaignSpec {
                seed,
                ..Default::default()
            })
            .expect("campaign");
            let opts = CalibOptions {
                weighting,
                epsilon,
                ..Default::default()
            };
            let res = calibrate(&Model::nominal(), &c.cal, Some(&c.lines), &opts, &|_| {})
                .expect("calibration");
            let t = &c.truth.model;
            for j in [1usize, 2, 4] {
                let (f, tr) = (
                    res.model.stiffness(j).expect("fitted"),
                    t.stiffness(j).expect("true"),
                );
                let e = (f.klin / tr.klin - 1.0).abs() * 100.0;
                if j == 4 {
                    k5 = k5.max(e)
                } else {
                    k23 = k23.max(e)
                }
            }
            let v: f64 = evaluate(&res.model, &c.val, None)
                .expect("eval")
                .iter()
                .map(|s| s.mean_mm)
                .sum::<f64>()
                / 3.0;
            let floor: f64 = resolver_floor(&res.model, &c.val, 0.64 * ARCMIN, None)
                .expect("floor")
                .iter()
                .map(|s| s.1)
                .sum::<f64>()
                / 3.0;
            ratios.push(v / floor);
            vals.push(v);
            let b = pose_error(&canonical_base(&res.model), &canonical_base(t));
            bp = bp.max(b.fixed_rows::<3>(0).norm() * 1e3);
            br = br.max(b.fixed_rows::<3>(3).norm() * 1e3);
        }
        let n = ratios.len() as f64;
        println!(
            "| {name} | {k23:.1} % | {k5:.1} % | {:.2} ({:.2}) | {:.3} | {bp:.2}, {br:.2} |",
            ratios.iter().sum::<f64>() / n,
            ratios.iter().cloned().fold(0.0, f64::max),
            vals.iter().sum::<f64>() / n
        );
    }
}
