//! Criterion benchmark of `pa10 discover` on the discovery campaign (60 configurations ×
//! 3 loads × 2 directions × 2 temperatures × 2 repeats = 1440 rows).
//!
//! `cargo bench --bench discover`: "nothing hidden" is the lack-of-fit test alone (the fit,
//! the noise model, the strata, the cross-validated gap); "J4 spring hidden" adds one round
//! of candidate scoring over the whole library, the refits and a second round.

use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use pa10::discover::{DiscoverOptions, discover};
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
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
