//! Criterion benchmarks of the resolver-accuracy Monte Carlo.
//!
//! `cargo bench --bench accuracy`. The headline is the seed paper's whole experiment:
//! 5 planes × 200 points × 100 000 draws = 10⁸ forward kinematics (point selection and the
//! linearised twin included). Medians are recorded in BENCHMARKS.md next to the NumPy
//! reference in `benches/reference/accuracy_numpy.py`.

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use pa10::accuracy::{McConfig, run};
use pa10::model::Model;

fn bench(c: &mut Criterion) {
    let m = Model::nominal();
    let mut g = c.benchmark_group("accuracy");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    let paper = McConfig::paper();
    g.bench_function(
        "paper experiment (5 planes x 200 points x 100k draws)",
        |b| b.iter(|| run(&m, &paper, &|_| {}).expect("runs")),
    );
    let one = McConfig {
        planes: vec![0.5],
        points: 1,
        ..McConfig::paper()
    };
    g.bench_function("one point x 100k draws", |b| {
        b.iter(|| run(&m, &one, &|_| {}).expect("runs"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
