//! Criterion benchmark of `pa10 discover` on the discovery campaign (60 configurations ×
//! 3 loads × 2 directions × 2 temperatures × 2 repeats = 1440 rows).
//!
//! `cargo bench --bench discover`: "nothing hidden" is the lack-of-fit test alone (the fit,
//! the noise model, the strata, the cross-validated gap); "J4 spring hidden" adds one round
//! of candidate scoring over the whole library, the refits and a second round. "from the
//! rigid nominal model, paper-sized" is the whole search on the seed paper's campaign
//! (27 configurations × 0/22/44 N × 10 repeats, the independent generator of `tests/indep`,
//! nothing hidden beyond the paper's springs), 5-fold cross-validation; "calibrate,
//! paper-sized" is `pa10 calibrate` on the same data from the same model, the yardstick
//! discovery's time is judged against (#41: ≤ 10×, #44: ≤ 5×).

#[path = "../tests/indep/mod.rs"]
mod indep;

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use pa10::calib::dataset::Dataset;
use pa10::discover::{DiscoverOptions, discover};
use pa10::model::Model;
use pa10::sim::experiment::{DiscoverySpec, discovery_campaign, paper_model, scenarios};

fn bench(c: &mut Criterion) {
    let model = paper_model(false).expect("model");
    let mut g = c.benchmark_group("discover");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    for (label, name) in [
        ("nothing hidden, 1440 rows", "none"),
        ("J4 spring hidden, 1440 rows", "compliance-j4"),
    ] {
        let sc = scenarios()
            .into_iter()
            .find(|s| s.name == name)
            .expect("scenario");
        let data = discovery_campaign(&DiscoverySpec {
            hidden: sc.hidden,
            ..Default::default()
        })
        .expect("campaign")
        .data;
        g.bench_function(label, |b| {
            b.iter(|| discover(&model, &data, None, &DiscoverOptions::default()).expect("run"))
        });
    }
    let set = indep::generate(&indep::Spec::paper(16, indep::families()[0]));
    let dir = std::env::temp_dir().join(format!("pa10-bench-nominal-{}", std::process::id()));
    let (cal, _) = indep::write(&set, &dir);
    let data = Dataset::load(&cal).expect("load the paper-sized set");
    let _ = std::fs::remove_dir_all(&dir);
    // the yardstick: the calibration of the same data from the same model
    g.bench_function("calibrate, paper-sized (810 rows)", |b| {
        b.iter(|| {
            pa10::calib::fit::calibrate(
                &Model::nominal(),
                &data,
                None,
                &pa10::calib::fit::CalibOptions::default(),
                &|_| {},
            )
            .expect("calibrate")
        })
    });
    g.bench_function(
        "from the rigid nominal model, paper-sized (810 rows)",
        |b| {
            b.iter(|| {
                discover(&Model::nominal(), &data, None, &DiscoverOptions::default()).expect("run")
            })
        },
    );
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
