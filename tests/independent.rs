//! Calibration, the noise estimator and discovery judged on data from the independent
//! generator (`tests/indep`), which shares no code with `src/`.

#[path = "indep/mod.rs"]
mod indep;

use indep::{Hidden, Spec, families, generate, write};

/// Writes sets for manual study: `PA10_INDEP_DIR=/tmp/x cargo test --release dump_sets -- --ignored`.
#[test]
#[ignore]
fn dump_sets() {
    let dir = std::path::PathBuf::from(std::env::var("PA10_INDEP_DIR").unwrap());
    for fam in families() {
        for (tag, hidden) in [
            ("clean", Hidden::None),
            ("j4", Hidden::SpringJ4(4000.0)),
            ("quad", Hidden::Poly(1, 2, -4e-4)),
            ("cube1", Hidden::Poly(0, 3, 3e-4)),
        ] {
            let set = generate(&Spec {
                hidden,
                ..Spec::paper(1, fam)
            });
            write(&set, &dir.join(format!("{}-{tag}", fam.name)));
            println!("{} {tag}: floor {:.3} mm", fam.name, set.val_floor_mm);
        }
    }
}

use pa10::calib::dataset::Dataset;
use pa10::calib::fit::{CalibOptions, calibrate, evaluate};
use pa10::discover::{DiscoverOptions, Discovery, discover};
use pa10::model::Model;
use pa10::noise::Structure;

const ARCMIN: f64 = std::f64::consts::PI / (180.0 * 60.0);

/// Writes `set` to a fresh temporary directory and loads it back (sidecar included).
fn load(set: &indep::Set, tag: &str) -> (Dataset, Dataset) {
    // Callers hold the real-time lock: these campaigns load both cores, which would starve a
    // real-time daemon test running beside them.
    let dir = std::env::temp_dir().join(format!("pa10-indep-{tag}-{}", std::process::id()));
    let (cal, val) = write(set, &dir);
    let out = (Dataset::load(&cal).unwrap(), Dataset::load(&val).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
    out
}

fn calibrated(cal: &Dataset) -> pa10::calib::fit::CalibResult {
    calibrate(
        &Model::nominal(),
        cal,
        None,
        &CalibOptions::default(),
        &|_| {},
    )
    .unwrap()
}

fn within(est: f64, truth: f64, tol: f64) -> bool {
    (est / truth - 1.0).abs() <= tol
}

/// The noise estimator recovers every component within 20 % and names the structure, on
/// each family (at discovery's generalised least-squares fit of the calibrated model: the
/// calibration's own estimate of the repeatable part runs ~20 % high, its fit being the
/// paper's two-level one with a stiffness prior, not the GLS optimum); calibration names the
/// same structure and validates within 1.15× of the generator's own floor.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn noise_is_measured_and_calibration_reaches_the_floor_on_every_family() {
    let _cpu = crate::common::busy_lock();
    for fam in families() {
        let set = generate(&Spec::paper(11, fam));
        let (cal, val) = load(&set, fam.name);
        let res = calibrated(&cal);
        let expect = match (fam.reading_rad > 0.0, fam.repeatable_rad > 0.0) {
            (true, true) => Structure::Both,
            (true, false) => Structure::Reading,
            (false, true) => Structure::Repeatable,
            (false, false) => Structure::InstrumentOnly,
        };
        let nc = res.noise.as_ref().unwrap();
        assert_eq!(
            nc.structure,
            expect,
            "calibrate, {}: {}",
            fam.name,
            nc.summary()
        );
        let d = discovered(&set, &res.model, fam.name);
        let n = &d.noise_after.model;
        let s = n.summary();
        assert_eq!(n.structure, expect, "{}: {s}", fam.name);
        for j in 0..6 {
            let r = n.reading_rad[j].value;
            if fam.reading_rad > 0.0 {
                assert!(within(r, fam.reading_rad, 0.2), "{}: {s}", fam.name);
            } else {
                assert!(r < 0.05 * ARCMIN, "{}: {s}", fam.name);
            }
        }
        if fam.repeatable_rad > 0.0 {
            assert!(
                within(n.repeatable_rad.value, fam.repeatable_rad, 0.2),
                "{}: {s}",
                fam.name
            );
        }
        for a in 0..3 {
            assert!(
                within(n.instrument_position_m[a].value, fam.instrument_m[a], 0.2),
                "{}: {s}",
                fam.name
            );
            assert!(
                within(
                    n.instrument_orientation_rad[a].value,
                    fam.instrument_rad[a],
                    0.2
                ),
                "{}: {s}",
                fam.name
            );
        }
        // Validation against the generator's floor, averaged over three sets (one set's
        // 90 validation rows scatter by a few per cent).
        let mut ratio = validation_mean(&res.model, &val) / set.val_floor_mm;
        for seed in [21, 31] {
            let set = generate(&Spec::paper(seed, fam));
            let (cal, val) = load(&set, fam.name);
            ratio += validation_mean(&calibrated(&cal).model, &val) / set.val_floor_mm;
        }
        ratio /= 3.0;
        assert!(
            ratio <= 1.15,
            "{}: validation {ratio:.3}× the floor",
            fam.name
        );
    }
}

fn validation_mean(model: &Model, val: &Dataset) -> f64 {
    let summaries = evaluate(model, val, None).unwrap();
    summaries.iter().map(|s| s.mean_mm).sum::<f64>() / summaries.len() as f64
}

/// Without repeats the structure cannot be measured: it is assumed, said, and calibration
/// still works.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn sets_without_repeats_calibrate_on_a_stated_assumption() {
    let _cpu = crate::common::busy_lock();
    let fam = families()[0];
    let set = generate(&Spec {
        repeats: 1,
        ..Spec::paper(12, fam)
    });
    let (cal, val) = load(&set, "norepeat");
    let res = calibrated(&cal);
    let n = res.noise.as_ref().unwrap();
    assert_eq!(n.structure, Structure::Assumed);
    assert!(
        n.assumption
            .as_deref()
            .unwrap()
            .contains("cannot be measured")
    );
    let mean = validation_mean(&res.model, &val);
    assert!(
        mean <= 1.4 * set.val_floor_mm,
        "{mean} vs {}",
        set.val_floor_mm
    );
    // Discovery runs on the same assumption, says so, and names nothing on this clean set.
    let d = discover(&res.model, &cal, Some(&val), &DiscoverOptions::default()).unwrap();
    assert_eq!(d.noise_after.model.structure, Structure::Assumed);
    assert!(d.noise_after.model.assumption.is_some());
    assert!(
        d.effects.is_empty(),
        "{:?}",
        d.effects.iter().map(|e| &e.label).collect::<Vec<_>>()
    );
}

fn discovered(set: &indep::Set, start: &Model, tag: &str) -> Discovery {
    let (cal, val) = load(set, tag);
    discover(start, &cal, Some(&val), &DiscoverOptions::default()).unwrap()
}

/// On clean sets of every family, discovery from the calibrated model names nothing.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn discovery_names_nothing_on_clean_independent_sets() {
    let _cpu = crate::common::busy_lock();
    for fam in families() {
        let set = generate(&Spec::paper(13, fam));
        let (cal, _) = load(&set, "clean-cal");
        let start = calibrated(&cal).model;
        let d = discovered(&set, &start, fam.name);
        assert!(
            d.effects.is_empty(),
            "{}: named {:?}",
            fam.name,
            d.effects.iter().map(|e| &e.label).collect::<Vec<_>>()
        );
        assert!(
            d.gap_after_mm <= 1.25 * d.noise_floor_mm,
            "{}: {} vs floor {}",
            fam.name,
            d.gap_after_mm,
            d.noise_floor_mm
        );
    }
}

/// The paper's validation design (10 novel configurations, J6 never turned) with a J3
/// gear-ratio error of 1e-3: no candidate of J6's angle is tried or named — each is reported
/// not identifiable from these poses (issue #41: `gear_ratio_error[J6]` was named with
/// 6e-4 ± 1e-3, having "explained" J6's reading noise) — and the run ends with a report.
#[test]
fn a_joint_the_campaign_never_turns_gets_no_effect_of_its_angle() {
    let _cpu = crate::common::busy_lock();
    let fam = families()[0];
    let set = generate(&Spec {
        hidden: Hidden::Poly(2, 1, 1e-3),
        ..Spec::paper_validation(1, fam)
    });
    let (cal, _) = load(&set, "still-j6-cal");
    let start = calibrated(&cal).model;
    let d = discovered(&set, &start, "still-j6");
    assert!(
        d.effects.iter().all(|e| e.joint != Some(6)),
        "named {:?}",
        d.effects.iter().map(|e| &e.label).collect::<Vec<_>>()
    );
    for label in [
        "gear_ratio_error[J6]",
        "transmission_error[J6]",
        "encoder_eccentricity[J6]",
        "backlash[J6]",
    ] {
        assert!(
            d.not_identifiable.iter().any(|l| l == label),
            "{label} not among {:?}",
            d.not_identifiable
        );
    }
    let first = &d.steps[0];
    let note = &first
        .candidates
        .iter()
        .find(|c| c.label == "gear_ratio_error[J6]")
        .expect("listed in the first step")
        .note;
    assert!(note.contains("not identifiable from these poses"), "{note}");
    // J3 turns: its candidates are scored
    assert!(
        first
            .candidates
            .iter()
            .any(|c| c.label == "gear_ratio_error[J3]" && c.identifiable > 0)
    );
}

/// A J4 spring the paper's model lacks is named on J4, on every family.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn discovery_names_a_hidden_j4_spring_on_every_family() {
    let _cpu = crate::common::busy_lock();
    for fam in families() {
        let set = generate(&Spec {
            hidden: Hidden::SpringJ4(4000.0),
            ..Spec::paper(14, fam)
        });
        let (cal, _) = load(&set, "j4-cal");
        let start = calibrated(&cal).model;
        let d = discovered(&set, &start, fam.name);
        let labels: Vec<&str> = d.effects.iter().map(|e| e.label.as_str()).collect();
        assert_eq!(
            labels.first(),
            Some(&"joint_compliance_linear[J4]"),
            "{}",
            fam.name
        );
        let c = d.effects[0].params["compliance"];
        assert!(
            (c * 4000.0 - 1.0).abs() < 0.1,
            "{}: compliance {c}",
            fam.name
        );
    }
}

/// An effect outside the library (`δq1 = 3e-4·q1³`) is localised on J1 on every family:
/// by a library look-alike where one explains it (eccentricity: `sin q ≈ q − q³/6`), else
/// by the generic dictionary — and the gap ends within 1.25× the floor.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn an_out_of_library_effect_is_localised_on_its_joint() {
    let _cpu = crate::common::busy_lock();
    for fam in families() {
        let set = generate(&Spec {
            hidden: Hidden::Poly(0, 3, 3e-4),
            ..Spec::paper(15, fam)
        });
        let (cal, _) = load(&set, "poly-cal");
        let start = calibrated(&cal).model;
        let d = discovered(&set, &start, fam.name);
        assert!(!d.effects.is_empty(), "{}: {}", fam.name, d.verdict);
        assert!(
            d.effects.iter().all(|e| e.joint == Some(1)),
            "{}: {:?}",
            fam.name,
            d.effects.iter().map(|e| &e.label).collect::<Vec<_>>()
        );
        assert!(
            d.gap_after_mm <= 1.25 * d.noise_floor_mm,
            "{}: {}",
            fam.name,
            d.verdict
        );
    }
}

/// From the rigid nominal model, discovery finds the paper's springs on J2, J3 and J5 (and
/// nothing on the other joints), and closes the gap.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn discovery_from_the_nominal_model_finds_the_papers_springs() {
    let _cpu = crate::common::busy_lock();
    let set = generate(&Spec::paper(16, families()[0]));
    let (cal, _) = load(&set, "nominal");
    let d = discover(&Model::nominal(), &cal, None, &DiscoverOptions::default()).unwrap();
    let springs = crate::common::spring_joints(&d);
    assert_eq!(
        springs,
        vec![2, 3, 5],
        "{:?}",
        d.effects.iter().map(|e| &e.label).collect::<Vec<_>>()
    );
    assert!(d.effects.iter().all(|e| matches!(e.joint, Some(2 | 3 | 5))));
    assert!(d.gap_closed, "{}", d.verdict);
}
