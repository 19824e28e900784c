//! Calibration and discovery judged on campaigns from the Pinocchio generator
//! (`tests/pin/campaign.py`: a URDF written from `shared/pa10-facts.md`, kinematics,
//! Jacobians and gravity by Pinocchio, random campaign designs), which shares no code with
//! `src/`. The library reads only the CSV and sidecar; the generator's `truth.json` is read
//! here, by the judge.
//!
//! Needs `pip install pin`. CI sets `PA10_REQUIRE_PIN=1`, so there a missing Pinocchio is a
//! failure; elsewhere these tests say SKIPPED. The distribution study is
//! `python3 tests/pin/study.py` (docs/discovery.md).

use std::path::{Path, PathBuf};
use std::process::Command;

use pa10::calib::dataset::Dataset;
use pa10::calib::fit::{CalibOptions, calibrate};
use pa10::discover::{DiscoverOptions, Discovery, discover};
use pa10::model::Model;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/pin/campaign.py")
}

/// A generated campaign: the training and held-out sets, and the generator's truth.
struct Campaign {
    cal: Dataset,
    val: Dataset,
    truth: serde_json::Value,
}

fn generate(tag: &str, args: &[&str]) -> Campaign {
    let dir = std::env::temp_dir().join(format!("pa10-pin-{tag}-{}", std::process::id()));
    let out = Command::new("python3")
        .arg(script())
        .args(args)
        .arg("--out")
        .arg(&dir)
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "campaign.py {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let c = Campaign {
        cal: Dataset::load(dir.join("cal.csv")).expect("cal.csv"),
        val: Dataset::load(dir.join("val.csv")).expect("val.csv"),
        truth: serde_json::from_str(
            &std::fs::read_to_string(dir.join("truth.json")).expect("truth.json"),
        )
        .expect("truth.json parses"),
    };
    let _ = std::fs::remove_dir_all(&dir);
    c
}

fn calibrated(c: &Campaign) -> Model {
    calibrate(
        &Model::nominal(),
        &c.cal,
        None,
        &CalibOptions::default(),
        &|_| {},
    )
    .expect("calibrate")
    .model
}

fn discovered(c: &Campaign, start: &Model) -> Discovery {
    discover(start, &c.cal, Some(&c.val), &DiscoverOptions::default()).expect("discover")
}

fn labels(d: &Discovery) -> Vec<&str> {
    d.effects.iter().map(|e| e.label.as_str()).collect()
}

/// On random designs (tool, instrument, poses, loads, repeats, noise family drawn from the
/// seed), a hidden effect in the library and two outside it are each named on the right
/// joint and in the right form; a clean campaign names nothing; no run aborts.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn hidden_effects_are_named_on_pinocchio_campaigns() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    for (seed, hidden, expect) in [
        ("3", "spring_j4", Some("joint_compliance_linear[J4]")),
        ("4", "scale_j3", Some("gear_ratio_error[J3]")),
        ("6", "tool_sag", Some("tool_sag")),
        ("8", "none", None),
    ] {
        let c = generate(hidden, &["--seed", seed, "--hidden", hidden]);
        let d = discovered(&c, &calibrated(&c));
        let design = &c.truth["design"];
        match expect {
            Some(label) => assert_eq!(
                labels(&d),
                vec![label],
                "{hidden} ({design}): {}",
                d.verdict
            ),
            None => assert!(d.effects.is_empty(), "clean ({design}): {:?}", labels(&d)),
        }
        assert!(
            d.gap_closed && d.gap_after_mm <= 1.25 * d.noise_floor_mm,
            "{hidden}: {}",
            d.verdict
        );
    }
}

/// The paper's campaign design with two effects hidden at once (a J4 spring and a J3
/// transmission error, the set that used to end the run with a runaway `da5`): both are
/// named, on their joints.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn two_hidden_effects_at_once_on_the_papers_design() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate(
        "two",
        &[
            "--seed",
            "1",
            "--paper",
            "--family",
            "reading",
            "--hidden",
            "spring_j4,transmission_j3",
        ],
    );
    let d = discovered(&c, &calibrated(&c));
    let l = labels(&d);
    assert!(
        l.contains(&"joint_compliance_linear[J4]"),
        "{l:?}: {}",
        d.verdict
    );
    assert!(
        d.effects
            .iter()
            .any(|e| e.joint == Some(3) && e.name != "joint_compliance_linear"),
        "{l:?}"
    );
    assert!(
        d.effects.iter().all(|e| matches!(e.joint, Some(3 | 4))),
        "{l:?}"
    );
}

/// From the rigid nominal model on a random design, the paper's springs on J2, J3 and J5
/// are found together (they compete in every bootstrap resample; stability is judged on the
/// selected set), nothing on the other joints, and the gap closes.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn from_the_nominal_model_the_springs_are_found_together() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate("nominal", &["--seed", "8", "--hidden", "none"]);
    let d = discovered(&c, &Model::nominal());
    let springs = crate::common::spring_joints(&d);
    assert_eq!(springs, vec![2, 3, 5], "{:?}", labels(&d));
    assert!(d.effects.iter().all(|e| matches!(e.joint, Some(2 | 3 | 5))));
    assert!(d.gap_closed, "{}", d.verdict);
    assert!(d.gap_after_mm <= 1.3 * d.noise_floor_mm, "{}", d.verdict);
    // The missing springs showed first as a repeatable component far above the resolver's
    // specification: reported as a finding, never taken for noise.
    assert!(
        d.findings
            .iter()
            .any(|f| f.contains("repeats per configuration")),
        "{:?}",
        d.findings
    );
}

/// From the rigid nominal model on the two designs that used to defeat it: two loads only
/// (seed 5: the J5 cubic's linearised held-out comparison overshoots at 90 N, so it is
/// compared again at its nonlinear refit) and one repeat only (seed 49: the noise is assumed
/// from the specification, so the candidates' tests are χ² tests, not F tests against a
/// pure error that does not exist). The springs are found, with the J5 cubic, and the
/// held-out error is within 1.3× the floor.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn from_the_nominal_model_on_two_loads_and_on_one_repeat() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    for seed in ["5", "49"] {
        // The design and the hidden set are drawn from the seed (both clean).
        let c = generate(&format!("nominal{seed}"), &["--seed", seed]);
        assert_eq!(c.truth["hidden"], serde_json::json!([]), "seed {seed}");
        let d = discovered(&c, &Model::nominal());
        let design = &c.truth["design"];
        assert_eq!(
            crate::common::spring_joints(&d),
            vec![2, 3, 5],
            "seed {seed} ({design}): {:?}",
            labels(&d)
        );
        assert!(
            labels(&d).contains(&"joint_compliance_cubic[J5]"),
            "seed {seed}: {:?}",
            labels(&d)
        );
        assert!(d.effects.iter().all(|e| matches!(e.joint, Some(2 | 3 | 5))));
        assert!(
            d.gap_after_mm <= 1.3 * d.noise_floor_mm,
            "seed {seed} ({design}): {}",
            d.verdict
        );
    }
}

/// From the rigid nominal model on a campaign whose training loads stop at 40 N while the
/// held-out set goes to 90 N (seed 243: 15 configurations x 0/21/40 N x 2 repeats, clean):
/// the J5 cubic cannot pass the training tests, and the held-out prediction at 90 N needs
/// it. The completion round takes it on the held-out data (its torques reach beyond the
/// training's), and the held-out error ends within 1.3x the floor (1.41x without it). The
/// J2 cubic, whose refit is softening on these data, is refused as not hardening.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn from_the_nominal_model_a_spring_is_completed_beyond_the_training_loads() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate("complete243", &["--seed", "243"]);
    assert_eq!(c.truth["hidden"], serde_json::json!([]));
    let d = discovered(&c, &Model::nominal());
    assert_eq!(
        crate::common::spring_joints(&d),
        vec![2, 3, 5],
        "{:?}",
        labels(&d)
    );
    let completed: Vec<&str> = d
        .steps
        .iter()
        .filter(|s| s.completion)
        .filter_map(|s| s.accepted.as_deref())
        .collect();
    assert_eq!(
        completed,
        ["joint_compliance_cubic[J5]"],
        "{:?}",
        labels(&d)
    );
    assert!(labels(&d).contains(&"joint_compliance_cubic[J5]"));
    let refused = d
        .steps
        .iter()
        .filter(|s| s.completion)
        .flat_map(|s| &s.candidates)
        .find(|c| c.label == "joint_compliance_cubic[J2]")
        .expect("J2 cubic tried");
    assert!(
        refused.note.contains("not a hardening spring"),
        "{}",
        refused.note
    );
    assert!(d.gap_after_mm <= 1.3 * d.noise_floor_mm, "{}", d.verdict);
    // Without a holdout set (cross-validation by configuration) nothing reaches beyond the
    // training torques: no completion round.
    let cv =
        discover(&Model::nominal(), &c.cal, None, &DiscoverOptions::default()).expect("discover");
    assert!(cv.steps.iter().all(|s| !s.completion));
}

/// A J3 transmission error on a campaign that can reveal it (40 configurations; the
/// generator's noncentrality λ ≈ 99 on the calibration set and ≈ 101 on the held-out set,
/// above the study's 45 / 80): named on J3. On the study's random designs of 15–40
/// configurations its λ is mostly 12–67: below what any test on those data could show.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn a_revealable_j3_transmission_error_is_named_on_j3() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate(
        "tr40",
        &[
            "--seed",
            "1",
            "--hidden",
            "transmission_j3",
            "--family",
            "reading",
            "--configs",
            "40",
            "--detectability",
        ],
    );
    let lam = c.truth["hidden"][0]["noncentrality"]
        .as_f64()
        .unwrap_or(0.0);
    let lam_out = c.truth["hidden"][0]["noncentrality_holdout"]
        .as_f64()
        .unwrap_or(0.0);
    assert!(lam >= 45.0 && lam_out >= 80.0, "λ {lam:.1} / {lam_out:.1}");
    let d = discovered(&c, &calibrated(&c));
    assert!(
        !d.effects.is_empty() && d.effects.iter().all(|e| e.joint == Some(3)),
        "{:?}: {}",
        labels(&d),
        d.verdict
    );
    assert!(d.gap_closed, "{}", d.verdict);
}

/// A soft J4 spring hidden on a two-load campaign (seed 142: 74 N, a 0.5 m tool) drags the
/// calibration's trial steps past a departure's bound; the optimiser refuses those steps
/// (a cost far above any real one) instead of ending the fit, so `calibrate` does not abort
/// and discovery names the spring.
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn calibration_survives_trial_steps_outside_the_valid_range() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate("c142", &["--seed", "142"]);
    assert_eq!(c.truth["hidden"][0]["name"], "spring_j4");
    let d = discovered(&c, &calibrated(&c));
    assert_eq!(
        labels(&d),
        vec!["joint_compliance_linear[J4]"],
        "{}",
        d.verdict
    );
}

/// A J4 spring so soft (seed 199: Klin 2683 N·m/rad, loads to 88 N, a 0.3 m tool) that the
/// paper's model, fitted, leaves a repeatable error of ~244 arcmin, 381× the resolver's
/// specification. The dataset's sidecar declares the set-up, so `calibrate` does not refuse:
/// it returns the best fit of the paper's model with the misfit stated (and what to run),
/// and discovery from that model names the J4 spring and closes the gap. (Without a sidecar
/// the same misfit is refused as a set-up error: `tests/cli.rs`.)
#[test]
#[ignore = "statistical, on an independent generator: cargo test -- --ignored (CI runs it)"]
fn a_calibration_that_cannot_explain_its_data_says_so_and_discovery_names_why() {
    if !crate::common::pinocchio() {
        return;
    }
    let _cpu = crate::common::busy_lock();
    let c = generate("c199", &["--seed", "199"]);
    assert_eq!(c.truth["hidden"][0]["name"], "spring_j4");
    let r = calibrate(
        &Model::nominal(),
        &c.cal,
        None,
        &CalibOptions::default(),
        &|_| {},
    )
    .expect("calibrate returns the fit");
    let misfit = r.misfit.as_deref().expect("the misfit is stated");
    assert!(
        misfit.contains("does not explain the data") && misfit.contains("pa10 discover"),
        "{misfit}"
    );
    let d = discovered(&c, &r.model);
    assert_eq!(
        labels(&d),
        vec!["joint_compliance_linear[J4]"],
        "{}",
        d.verdict
    );
    assert!(d.gap_closed, "{}", d.verdict);
}
