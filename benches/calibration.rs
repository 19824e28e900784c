//! Criterion benchmark of the two-level calibration on the paper-sized data set.
//!
//! `cargo bench --bench calibration`: 27 configurations × 3 loads × 10 repeats = 810 rows,
//! lines for the base seed. "default" is what `pa10 calibrate` runs (GLS, 4 starts); "paper
//! weighting, 1 start" is the problem the SciPy reference (`benches/reference/
//! calibration_scipy.py`) solves, for the side-by-side in BENCHMARKS.md.

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use pa10::calib::fit::{CalibOptions, Weighting, calibrate};
use pa10::model::Model;
use pa10::sim::experiment::{CampaignSpec, paper_campaign};

fn bench(c: &mut Criterion) {
    let camp = paper_campaign(&CampaignSpec::default()).expect("campaign");
    let m = Model::nominal();
    let mut g = c.benchmark_group("calibration");
    g.sample_size(20).measurement_time(Duration::from_secs(15));
    g.bench_function("default (measured weighting, 4 starts), 810 rows", |b| {
        b.iter(|| {
            calibrate(
                &m,
                &camp.cal,
                Some(&camp.lines),
                &CalibOptions::default(),
                &|_| {},
            )
            .expect("fit")
        })
    });
    let paper = CalibOptions {
        weighting: Weighting::Paper,
        starts: 1,
        ..Default::default()
    };
    g.bench_function("paper weighting, 1 start, 810 rows", |b| {
        b.iter(|| calibrate(&m, &camp.cal, Some(&camp.lines), &paper, &|_| {}).expect("fit"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
