//! How well `pa10 discover` names hidden effects, and how often it names one when nothing
//! is hidden: runs every scenario of [`pa10::sim::experiment::scenarios`] over many seeds
//! and prints what was named, the worst held-out gap against the noise floor, and the time
//! per run.
//!
//! `cargo run --release --example discovery_study [seeds]` (default 20 seeds);
//! `PA10_STUDY_ONLY=<scenario>` runs one scenario, `PA10_STUDY_CONFIGS=<n>` changes the
//! number of configurations (default 60), `PA10_STUDY_VERBOSE=1` prints every seed's steps.

use std::collections::BTreeMap;
use std::time::Instant;

use pa10::discover::{DiscoverOptions, discover};
use pa10::sim::experiment::{DiscoverySpec, discovery_campaign, paper_model, scenarios};

fn main() -> anyhow::Result<()> {
    let seeds: u64 = std::env::args().nth(1).map_or(Ok(20), |s| s.parse())?;
    let configs: usize = std::env::var("PA10_STUDY_CONFIGS").map_or(Ok(60), |v| v.parse())?;
    let only = std::env::var("PA10_STUDY_ONLY").ok();
    let verbose = std::env::var_os("PA10_STUDY_VERBOSE").is_some();
    for sc in scenarios() {
        if only.as_deref().is_some_and(|o| o != sc.name) {
            continue;
        }
        let model = paper_model(sc.linear_only)?;
        let mut named = BTreeMap::<String, usize>::new();
        let (mut right, mut worst, mut t_sum) = (0, 0.0f64, 0.0);
        for seed in 1..=seeds {
            let spec = DiscoverySpec {
                seed,
                configs,
                hidden: sc.hidden.clone(),
                ..Default::default()
            };
            let c = discovery_campaign(&spec)?;
            let t = Instant::now();
            let d = discover(&model, &c.data, None, &DiscoverOptions::default())?;
            t_sum += t.elapsed().as_secs_f64();
            let labels: Vec<&str> = d.effects.iter().map(|e| e.label.as_str()).collect();
            right += usize::from(labels == sc.expect);
            *named.entry(format!("{labels:?}")).or_default() += 1;
            worst = worst.max(d.gap_after_mm / d.noise_floor_mm);
            if verbose {
                println!(
                    "{} seed {seed}: gap {:.3} → {:.3} mm (floor {:.3}), lack of fit between {:.2} within {:.2} (p {:.1e})",
                    sc.name,
                    d.gap_before_mm,
                    d.gap_after_mm,
                    d.noise_floor_mm,
                    d.lack_of_fit_before.between.ratio,
                    d.lack_of_fit_before.within.ratio,
                    d.lack_of_fit_before.p_value
                );
                for s in &d.steps {
                    for c in s.candidates.iter().take(3) {
                        println!(
                            "  step {} {:32} k {} Δχ² {:9.1} ΔBIC {:9.1} p {:.1e} {}",
                            s.step,
                            c.label,
                            c.identifiable,
                            c.delta_chi2,
                            c.delta_bic,
                            c.p_adjusted,
                            c.note
                        );
                    }
                }
            }
        }
        println!(
            "{:16} {right}/{seeds} exactly as expected {:?}; named {named:?}; worst held-out gap / floor {worst:.2}; {:.2} s per run",
            sc.name,
            sc.expect,
            t_sum / seeds as f64
        );
    }
    Ok(())
}
