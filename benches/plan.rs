//! Criterion benchmark of campaign planning's selection (`pa10 plan`'s inner loop): 12 of
//! 1500 candidates, I-optimal, 10 exchange passes, and the "how many" curve's designs
//! (4 … 36 configurations, one exchange pass each), by the previous code (every candidate
//! scored with a fresh inverse at every step, a greedy pass per size: `select_by`) and the
//! current one (one greedy pass, candidates scored only where the criterion's tangent bound
//! lets them win, the Cholesky kernel: `greedy_order` + `exchange`), side by side. Both
//! choose the same configurations (asserted here, and in the unit tests).
//!
//! `cargo bench --bench plan`

use std::time::Duration;

use criterion::{Criterion as Bench, criterion_group, criterion_main};
use pa10::calib::plan::{
    Criterion, Information, PlanNoise, design_model, exchange, greedy_order, i_score, information,
    select_by, workspace_weight,
};
use pa10::model::Model;
use rand::{RngExt, SeedableRng};

const SIZES: [usize; 9] = [4, 6, 8, 10, 12, 16, 20, 27, 36];

fn bench(c: &mut Bench) {
    let model = design_model(&Model::nominal()).expect("model");
    let lim = *model.limits();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
    let qs: Vec<[f64; 6]> = (0..1500)
        .map(|_| {
            std::array::from_fn(|j| rng.random_range((lim.lower[j] + 0.1)..(lim.upper[j] - 0.1)))
        })
        .collect();
    let infos: Vec<Information> = qs
        .iter()
        .map(|q| information(&model, q, &[0.0, 22.0, 44.0], &PlanNoise::default()))
        .collect();
    let work: Vec<[f64; 6]> = qs.iter().step_by(4).take(150).copied().collect();
    let w = workspace_weight(&model, &work, &[0.0, 45.0, 90.0]);
    let crit = Criterion::I(&w);
    let previous = || {
        let score = |m: &Information| i_score(m, &w);
        let design = select_by(&infos, 12, 10, &score).expect("design").chosen;
        let curve: Vec<Vec<usize>> = SIZES
            .iter()
            .map(|&n| select_by(&infos, n, 1, &score).expect("curve").chosen)
            .collect();
        (design, curve)
    };
    let current = || {
        let order = greedy_order(&infos, 36, &crit).expect("greedy");
        let design = exchange(&infos, &order[..12], 10, &crit)
            .expect("design")
            .chosen;
        let curve: Vec<Vec<usize>> = SIZES
            .iter()
            .map(|&n| {
                exchange(&infos, &order[..n], 1, &crit)
                    .expect("curve")
                    .chosen
            })
            .collect();
        (design, curve)
    };
    assert_eq!(previous(), current(), "the two choose differently");
    let mut g = c.benchmark_group("plan");
    g.sample_size(10).measurement_time(Duration::from_secs(30));
    g.bench_function("12 of 1500, I, and the curve to 36: previous code", |b| {
        b.iter(previous)
    });
    g.bench_function("12 of 1500, I, and the curve to 36: current code", |b| {
        b.iter(current)
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
