//! The statistics of the whole method on data from the independent generator
//! (`tests/indep`, which shares no code with the library): for each noise family (reading
//! noise, repeatable resolver error, both) and each seed, a paper-sized campaign is
//! generated and
//!
//! 1. calibrated (`calibrate`, default options): the noise structure it names, the
//!    validation mean against the generator's own floor;
//! 2. the noise components re-measured at discovery's fit of the calibrated model, each
//!    checked against the generator's truth (within 20 %);
//! 3. discovered on the clean set (any name is a false naming), on a set with a hidden J4
//!    spring (in the library: must be named on J4 in ≥ 90 % of seeds), and on a set with
//!    `δq1 = 3e-4·q1³` (outside it: localised on J1 where the data have the power; never
//!    named on another joint in more than 4 % of seeds).
//!
//! `cargo run --release --example independent_study [seeds]` (default 10 seeds per family;
//! CI runs 2 and checks only the hard invariants). Prints one line per family;
//! `PA10_STUDY_FAMILY=reading|repeatable|both` runs one family, `PA10_STUDY_FIRST=N` starts
//! at seed N, `PA10_STUDY_VERBOSE=1` prints the q1³ cases that were not localised.

#[path = "../tests/indep/mod.rs"]
mod indep;
#[path = "common/indep_run.rs"]
mod indep_run;

use std::time::Instant;

use indep::{Hidden, Spec, families, generate};
use pa10::calib::fit::{CalibOptions, calibrate, evaluate};
use pa10::discover::{DiscoverOptions, Discovery, discover};
use pa10::model::Model;

use indep_run::{calibrate_and_discover, load};

/// A set of `fam` with `hidden`, calibrated from the nominal model, then discovered from the
/// calibrated model with the validation set held out.
fn hidden_run(fam: indep::Family, hidden: Hidden, seed: u64) -> anyhow::Result<Discovery> {
    let set = generate(&Spec {
        hidden,
        ..Spec::paper(seed, fam)
    });
    Ok(calibrate_and_discover(&set, fam.name)?.discovery)
}

fn within(est: f64, truth: f64) -> bool {
    (est / truth - 1.0).abs() <= 0.2
}

fn main() -> anyhow::Result<()> {
    let seeds: u64 = std::env::args().nth(1).map_or(Ok(10), |s| s.parse())?;
    let t0 = Instant::now();
    let mut failures = 0usize;
    let only = std::env::var("PA10_STUDY_FAMILY").ok();
    for fam in families() {
        if only.as_deref().is_some_and(|o| o != fam.name) {
            continue;
        }
        let (mut structure_ok, mut noise_ok, mut worst_ratio, mut ratio_sum) =
            (0usize, 0usize, 0.0f64, 0.0f64);
        let (mut false_named, mut j4_named, mut poly_localised, mut closed) = (0, 0, 0, 0);
        let mut poly_wrong = 0;
        let first: u64 = std::env::var("PA10_STUDY_FIRST").map_or(Ok(1), |v| v.parse())?;
        for seed in first..first + seeds {
            // 1. calibration on the clean set
            let set = generate(&Spec::paper(1000 + seed, fam));
            let (cal, val) = load(&set, fam.name)?;
            let res = calibrate(
                &Model::nominal(),
                &cal,
                None,
                &CalibOptions::default(),
                &|_| {},
            )?;
            let s = evaluate(&res.model, &val, None)?;
            let ratio =
                s.iter().map(|s| s.mean_mm).sum::<f64>() / s.len() as f64 / set.val_floor_mm;
            ratio_sum += ratio;
            worst_ratio = worst_ratio.max(ratio);
            // 2. noise at discovery's fit; 3a. clean discovery
            let d = discover(&res.model, &cal, Some(&val), &DiscoverOptions::default())?;
            let n = &d.noise_after.model;
            let expect = match (fam.reading_rad > 0.0, fam.repeatable_rad > 0.0) {
                (true, true) => "both",
                (true, false) => "reading",
                _ => "repeatable",
            };
            let named_structure = serde_json::to_value(n.structure)?;
            structure_ok += usize::from(named_structure == expect);
            let reading_ok = n.reading_rad.iter().all(|r| {
                if fam.reading_rad > 0.0 {
                    within(r.value, fam.reading_rad)
                } else {
                    r.value < 0.05 * fam.repeatable_rad
                }
            });
            let rep_ok =
                fam.repeatable_rad == 0.0 || within(n.repeatable_rad.value, fam.repeatable_rad);
            let inst_ok = (0..3).all(|a| {
                within(n.instrument_position_m[a].value, fam.instrument_m[a])
                    && within(n.instrument_orientation_rad[a].value, fam.instrument_rad[a])
            });
            noise_ok += usize::from(reading_ok && rep_ok && inst_ok);
            false_named += usize::from(!d.effects.is_empty());
            // 3b. a J4 spring
            let d = hidden_run(fam, Hidden::SpringJ4(4000.0), 2000 + seed)?;
            j4_named += usize::from(
                d.effects.first().map(|e| e.label.as_str()) == Some("joint_compliance_linear[J4]"),
            );
            closed += usize::from(d.gap_closed);
            // 3c. outside the library
            let d = hidden_run(fam, Hidden::Poly(0, 3, 3e-4), 3000 + seed)?;
            let ok = !d.effects.is_empty() && d.effects.iter().all(|e| e.joint == Some(1));
            poly_localised += usize::from(ok);
            poly_wrong += usize::from(d.effects.iter().any(|e| e.joint != Some(1)));
            if !ok && std::env::var_os("PA10_STUDY_VERBOSE").is_some() {
                let labels: Vec<&str> = d.effects.iter().map(|e| e.label.as_str()).collect();
                println!("  {} seed {seed}, q1³: {labels:?}; {}", fam.name, d.verdict);
            }
        }
        let n = seeds as usize;
        println!(
            "{:>10}: structure named {structure_ok}/{n}, noise within 20 % {noise_ok}/{n}, calibration {:.3}× the floor (mean; worst {worst_ratio:.3}×), false namings {false_named}/{n}, J4 spring named {j4_named}/{n} (gap closed {closed}/{n}), q1³ localised on J1 {poly_localised}/{n} (on a wrong joint {poly_wrong}/{n})",
            fam.name,
            ratio_sum / seeds as f64,
        );
        // The bars, scaled to the number of seeds (45 of 50 = 90 %); with fewer than
        // 10 seeds (CI's reduced run) only what must never happen is checked: a false naming,
        // an effect named on the wrong joint, a wrong noise structure.
        let bar = |k: usize| 10 * k >= 9 * n;
        let statistical = seeds >= 10;
        let hard = 25 * false_named <= n && 25 * poly_wrong <= n && structure_ok == n;
        let stats =
            bar(structure_ok) && bar(noise_ok) && ratio_sum / seeds as f64 <= 1.15 && bar(j4_named);
        if !(hard && (stats || !statistical)) {
            failures += 1;
        }
    }
    println!(
        "{} families, {seeds} seeds each, {:.0} s; {}",
        families().len(),
        t0.elapsed().as_secs_f64(),
        if failures == 0 {
            "every bar met"
        } else {
            "SOME BARS MISSED"
        }
    );
    if failures > 0 {
        anyhow::bail!("{failures} families missed a bar");
    }
    Ok(())
}
