//! `pa10 discover`: the effect library's physics, and the proof on hidden effects — each
//! scenario names exactly its effect (and joint), the held-out gap ends within 1.5× of the
//! noise floor, and data with nothing hidden names nothing.

use nalgebra::Vector3;
use pa10::calib::dataset::Dataset;
use pa10::discover::effects::{Effect, Kind, Slot};
use pa10::discover::forward::{self, EffectState, Obs};
use pa10::discover::{DiscoverError, DiscoverOptions, Discovery, discover};
use pa10::model::{Frame, JointError, Model, Torques};
use pa10::sim::experiment::{DiscoverySpec, discovery_campaign, paper_model, scenarios};

use crate::common::{max_diff, perturbed_model, random_q, rng};

fn obs(q: [f64; 6], tau: [f64; 6], load_n: f64, dir: f64, thermal: f64) -> Obs {
    Obs {
        q,
        tau,
        load_n,
        dir: [dir; 6],
        thermal,
        meas: Frame::identity(),
    }
}

fn position(s: &EffectState, o: &Obs) -> Vector3<f64> {
    let g = s.geometry().unwrap();
    forward::predict(s, &g, o).translation.vector
}

#[test]
fn every_kind_has_a_stable_name_a_description_and_units() {
    let _cpu = crate::common::busy_lock();
    for k in Kind::ALL {
        assert_eq!(Kind::from_name(k.name()), Some(k));
        assert!(!k.description().is_empty());
        let e = Effect {
            kind: k,
            target: Some(3),
        };
        let params = e.params(true);
        assert_eq!(params.len(), e.slots().len(), "{}", k.name());
        assert!(params.iter().all(|p| !p.unit.is_empty()));
    }
    assert_eq!(Kind::from_name("no_such_effect"), None);
}

#[test]
fn joint_side_effects_move_the_link_as_documented() {
    let _cpu = crate::common::busy_lock();
    let m = perturbed_model(&mut rng(3));
    let mut r = rng(4);
    let q = random_q(&mut r, &m);
    let tau = [0.0, 60.0, 20.0, 8.0, 3.0, 0.5];
    let mut s = EffectState::from_model(&m, 50.0);
    let base = forward::link_angles(&s, &obs(q, tau, 0.0, 1.0, 0.0));
    // Linear compliance on J4: the link lags by c·τ.
    s.set(Slot::Compliance(3), 2.5e-4);
    let l = forward::link_angles(&s, &obs(q, tau, 0.0, 1.0, 0.0));
    assert!((base[3] - l[3] - 2.5e-4 * 8.0).abs() < 1e-15);
    s.set(Slot::Compliance(3), 0.0);
    // Backlash on J1: half the lost motion, on the side of the approach.
    s.set(Slot::JointErr(0, 10), 4e-4);
    let up = forward::link_angles(&s, &obs(q, tau, 0.0, 1.0, 0.0));
    let down = forward::link_angles(&s, &obs(q, tau, 0.0, -1.0, 0.0));
    assert!((base[0] - up[0] - 2e-4).abs() < 1e-15);
    assert!((down[0] - up[0] - 4e-4).abs() < 1e-15);
    // Transmission error on J3 at the wave-generator frequency (1:50).
    s.set(Slot::JointErr(2, 4), 3e-4);
    let t = forward::link_angles(&s, &obs(q, tau, 0.0, 1.0, 0.0));
    assert!((up[2] - t[2] - 3e-4 * (50.0 * q[2]).sin()).abs() < 1e-15);
}

#[test]
fn the_model_file_compensates_the_run_time_effects_exactly_as_discovery_predicts_them() {
    let _cpu = crate::common::busy_lock();
    let m = perturbed_model(&mut rng(5));
    let mut s = EffectState::from_model(&m, 50.0);
    for (slot, v) in [
        (Slot::Compliance(3), 1.0 / 4e3),
        (Slot::JointErr(2, 2), 3e-4),
        (Slot::JointErr(2, 5), -2e-4),
        (Slot::JointErr(0, 10), 4e-4),
        (Slot::JointErr(4, 8), 1e-4),
        // Generic terms localised outside the library: q² on J2, q³ on J1.
        (Slot::JointErr(1, 11), -4e-4),
        (Slot::JointErr(0, 12), 3e-4),
    ] {
        s.set(slot, v);
    }
    let model = s.to_model().unwrap();
    assert_eq!(
        model.data().joint_errors[1].unwrap().polynomial,
        [-4e-4, 0.0]
    );
    // The file round-trips.
    let back = Model::from_yaml_str(&model.to_yaml(), "test").unwrap();
    assert_eq!(back.data(), model.data());
    let mut r = rng(6);
    for _ in 0..200 {
        let q = random_q(&mut r, &m);
        let tau: [f64; 6] = std::array::from_fn(|j| 30.0 * ((j as f64) - 2.5) * q[j].sin());
        for dir in [-1.0, 0.0, 1.0] {
            let o = obs(q, tau, 0.0, dir, 0.0);
            let expect = forward::link_angles(&s, &o);
            let got = model
                .link_from_motor(&q, Torques::Given(&tau), &[dir; 6])
                .unwrap()
                .q_link;
            assert!(max_diff(&expect, &got) < 1e-12);
            // The daemon's compensation inverts it.
            let qm = model
                .compensate(&got, Torques::Given(&tau), &[dir; 6])
                .unwrap()
                .q_motor;
            assert!(max_diff(&qm, &q) < 1e-12, "{qm:?} vs {q:?}");
        }
    }
}

/// A tool that sags, links that bend and a heavier tool, written into a model file as
/// `pa10 discover` writes them: the model's loaded forward kinematics is discovery's forward
/// model, its run-time correction undoes them, and a discovery started from it keeps them.
#[test]
fn load_effects_in_the_model_file_are_discoverys_forward_model() {
    let m = perturbed_model(&mut rng(8));
    let mut s = EffectState::from_model(&m, 50.0);
    for (slot, v) in [
        (Slot::ToolSag, 4e-6),
        (Slot::Bending(1), 2e-6),
        (Slot::Bending(3), 3e-6),
        (Slot::Payload, 1.5),
    ] {
        s.set(slot, v);
    }
    let mut d = s.to_model().unwrap().data().clone();
    for (name, joint, param, v) in [
        ("tool_sag", None, "compliance", 4e-6),
        ("link_bending", Some(2), "compliance", 2e-6),
        ("link_bending", Some(4), "compliance", 3e-6),
        ("payload_mass_error", None, "mass", 1.5),
    ] {
        d.discovered
            .push(pa10::model::EffectRecord::compensated_one(
                name, joint, param, v,
            ));
    }
    let model = Model::new(d.clone()).unwrap();
    let geom = s.geometry().unwrap();
    let mut r = rng(9);
    for k in 0..100 {
        let q = random_q(&mut r, &m);
        let load = 10.0 * (k % 10) as f64;
        let tau: [f64; 6] = std::array::from_fn(|j| 20.0 * ((j as f64) - 2.5) * q[j].cos());
        let o = obs(q, tau, load, 0.0, 0.0);
        let expect = forward::predict(&s, &geom, &o);
        let link = model
            .link_from_motor(&q, Torques::Given(&tau), &[0.0; 6])
            .unwrap()
            .q_link;
        let got = model.fk_loaded(&link, load);
        let e = pa10::model::pose_error(&expect, &got);
        assert!(e.norm() < 1e-12, "{e:?}");
        // the run-time correction puts the loaded tool at the rigid pose (away from
        // singularities; near one it stays small)
        let c = model.load_correction(&link, load);
        assert!(
            max_diff(&c, &link) <= pa10::model::MAX_LOAD_CORRECTION + 1e-15,
            "{k}: {c:?} vs {link:?}"
        );
        let miss = pa10::model::pose_error(&model.fk(&link), &model.fk_loaded(&c, load));
        let sv = model.jacobian(&link).singular_values().min();
        if sv > 0.05 {
            assert!(
                miss.fixed_rows::<3>(0).norm() < 1e-9,
                "{k} {link:?} {miss:?}"
            );
        }
    }
    // the state of the model file is the state it was written from
    let back = EffectState::from_model(&model, 50.0);
    assert_eq!(
        (back.tool_sag, back.bending, back.payload_kg),
        (s.tool_sag, s.bending, s.payload_kg)
    );
    // out-of-range and incomplete records are refused by key, nothing built
    let bad = |edit: &dyn Fn(&mut pa10::model::EffectRecord)| {
        let mut d = d.clone();
        edit(&mut d.discovered[0]);
        Model::new(d).unwrap_err().to_string()
    };
    let e = bad(&|r| {
        r.params.insert("compliance".into(), 1.0);
    });
    assert!(e.contains("discovered[0].params.compliance"), "{e}");
    let e = bad(&|r| {
        r.name = "link_bending".into();
        r.joint = None;
    });
    assert!(e.contains("discovered[0].joint"), "{e}");
    let e = bad(&|r| {
        r.params.clear();
    });
    assert!(e.contains("missing"), "{e}");
    // a record marked not compensated is a report only
    let mut d2 = d.clone();
    for r in &mut d2.discovered {
        r.compensated = false;
    }
    assert!(Model::new(d2).unwrap().load_effects().is_empty());
}

#[test]
fn frame_effects_move_the_target_as_documented() {
    let _cpu = crate::common::busy_lock();
    let m = perturbed_model(&mut rng(7));
    let q = random_q(&mut rng(8), &m);
    let tau = [0.0; 6];
    let o = obs(q, tau, 40.0, 0.0, 15.0);
    let s0 = EffectState::from_model(&m, 50.0);
    let p0 = position(&s0, &o);
    let f = m.frames(&q);
    // Thermal growth of the forearm (d4 along z3): the target moves by L·α·ΔT along z3.
    let mut s = s0.clone();
    s.set(Slot::Thermal(3), 2.3e-5);
    let d = position(&s, &o) - p0;
    let expect = f[3].rotation * Vector3::z() * (m.data().dh[3].d * 2.3e-5 * 15.0);
    assert!((d - expect).norm() < 1e-12, "{d} vs {expect}");
    // A tool offset is a translation in the flange frame.
    let mut s = s0.clone();
    s.set(Slot::Tool(1), 1e-3);
    let d = position(&s, &o) - p0;
    assert!((d - f[6].rotation * Vector3::new(0.0, 1e-3, 0.0)).norm() < 1e-12);
    // Bending grows with the load, and a link without load moment does not bend.
    let mut s = s0.clone();
    s.set(Slot::Bending(1), 1e-6);
    let d40 = (position(&s, &o) - p0).norm();
    let o80 = obs(q, tau, 80.0, 0.0, 15.0);
    let d80 = (position(&s, &o80) - position(&s0, &o80)).norm();
    assert!(d40 > 0.0 && d80 > d40);
}

#[test]
fn bad_options_and_thin_data_get_precise_errors() {
    let _cpu = crate::common::busy_lock();
    let c = discovery_campaign(&DiscoverySpec {
        configs: 8,
        loads: vec![0.0],
        temperatures_c: vec![],
        both_directions: false,
        ..Default::default()
    })
    .unwrap();
    let m = paper_model(false).unwrap();
    for (opts, key) in [
        (
            DiscoverOptions {
                folds: 1,
                ..Default::default()
            },
            "folds",
        ),
        (
            DiscoverOptions {
                alpha: 0.0,
                ..Default::default()
            },
            "alpha",
        ),
        (
            DiscoverOptions {
                gear_ratio: f64::NAN,
                ..Default::default()
            },
            "gear_ratio",
        ),
    ] {
        match discover(&m, &c.data, None, &opts) {
            Err(DiscoverError::Option { key: k, .. }) => assert_eq!(k, key),
            other => panic!("{key}: {other:?}"),
        }
    }
    let mut few = c.data.clone();
    few.rows.retain(|r| r.config_id.as_str() < "c005");
    let err = discover(&m, &few, None, &DiscoverOptions::default()).unwrap_err();
    assert!(err.to_string().contains("at least 8"), "{err}");
}

#[test]
fn datasets_carry_directions_and_temperatures_through_csv() {
    let _cpu = crate::common::busy_lock();
    let c = discovery_campaign(&DiscoverySpec {
        configs: 8,
        loads: vec![0.0],
        repeats: 1,
        ..Default::default()
    })
    .unwrap();
    let text = c.data.to_csv();
    assert!(text.lines().next().unwrap().ends_with("dir6,temp_c"));
    let back = Dataset::parse(&text, "t").unwrap();
    assert_eq!(back.rows.len(), c.data.rows.len());
    for (a, b) in back.rows.iter().zip(&c.data.rows) {
        assert_eq!(a.direction, b.direction);
        assert_eq!(a.temperature_c, b.temperature_c);
    }
    // A previous configuration gives the direction; a bad direction is refused by line.
    let prev = "config_id,load_n,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6,x,y,z,qw,qx,qy,qz,prev_q1,prev_q2,prev_q3,prev_q4,prev_q5,prev_q6\n\
                a,0,0.1,0.2,1.0,0,1,0,0,0,0,0,0,0,0.5,0,0.3,1,0,0,0,0.0,0.3,1.0,0,1,0\n";
    let d = Dataset::parse(prev, "p").unwrap();
    assert_eq!(d.rows[0].direction, [1, -1, 0, 0, 0, 0]);
    let bad = text.replacen(",1,1,1,1,1,1,", ",1,1,2,1,1,1,", 1);
    let err = Dataset::parse(&bad, "b").unwrap_err().to_string();
    assert!(err.contains("dir3") || err.contains("direction"), "{err}");
}

fn run(name: &str, seed: u64) -> Discovery {
    let sc = scenarios().into_iter().find(|s| s.name == name).unwrap();
    let c = discovery_campaign(&DiscoverySpec {
        seed,
        hidden: sc.hidden.clone(),
        ..Default::default()
    })
    .unwrap();
    let d = discover(
        &paper_model(sc.linear_only).unwrap(),
        &c.data,
        None,
        &DiscoverOptions::default(),
    )
    .unwrap();
    let labels: Vec<&str> = d.effects.iter().map(|e| e.label.as_str()).collect();
    assert_eq!(labels, sc.expect, "{name} seed {seed}: {:#?}", d.steps);
    // every effect named won the bootstrap by configuration
    for s in &d.steps {
        if let Some(a) = &s.accepted {
            let c = s.candidates.iter().find(|c| &c.label == a).unwrap();
            assert!(c.stability.unwrap() >= 0.8, "{a}: {:?}", c.stability);
        }
    }
    assert_eq!(d.significant_gap_before, !sc.expect.is_empty(), "{name}");
    assert!(
        d.gap_after_mm <= 1.5 * d.noise_floor_mm,
        "{name}: held-out gap {:.3} mm vs floor {:.3} mm",
        d.gap_after_mm,
        d.noise_floor_mm
    );
    d
}

#[test]
fn hidden_cubic_stiffness_on_j2_is_named_from_a_linear_only_model() {
    let _cpu = crate::common::busy_lock();
    let d = run("cubic-j2", 11);
    let truth = pa10::sim::TrueRobot::draw(
        11,
        &Model::nominal(),
        &pa10::sim::experiment::CampaignSpec::default().tool,
        Default::default(),
    )
    .unwrap();
    let kcub = truth.model.stiffness(1).unwrap().kcub;
    let found = d.effects[0].params["kcub"];
    let se = d.effects[0].stderr["kcub"];
    assert!(
        (found - kcub).abs() < 4.0 * se + 0.05 * kcub,
        "{found} ± {se} vs {kcub}"
    );
}

#[test]
fn hidden_compliance_on_j4_is_named_and_its_spring_estimated() {
    let _cpu = crate::common::busy_lock();
    let d = run("compliance-j4", 12);
    assert!(
        d.steps[0].look_alikes.is_empty(),
        "{:?}",
        d.steps[0].look_alikes
    );
    let c = d.effects[0].params["compliance"];
    assert!((c - 2.5e-4).abs() < 0.02 * 2.5e-4, "{c}");
    assert_eq!(d.effects[0].joint, Some(4));
    assert!(d.gap_before_mm > 3.0 * d.gap_after_mm);
    // The extended model gives the daemon the spring.
    let k = d.model.stiffness(3).unwrap();
    assert!((k.klin - 4.0e3).abs() < 80.0, "{k:?}");
}

#[test]
fn hidden_transmission_error_on_j3_is_named() {
    let _cpu = crate::common::busy_lock();
    let d = run("transmission-j3", 13);
    // the eccentricity is its first harmonic: reported as a look-alike
    assert!(
        d.steps[0]
            .look_alikes
            .iter()
            .any(|(n, r)| n == "encoder_eccentricity[J3]" && *r > 0.99),
        "{:?}",
        d.steps[0].look_alikes
    );
    let p = &d.effects[0].params;
    assert!((p["wave1_sin"] - 4e-4).abs() < 1e-4, "{p:?}");
    assert!(d.model.data().joint_errors[2].is_some());
}

#[test]
fn hidden_backlash_on_j1_is_named() {
    let _cpu = crate::common::busy_lock();
    let d = run("backlash-j1", 14);
    let b = d.effects[0].params["backlash"];
    assert!((b - 4e-4).abs() < 2e-5, "{b}");
    assert_eq!(
        d.model.data().joint_errors[0].map(|e: JointError| e.backlash > 0.0),
        Some(true)
    );
}

#[test]
fn hidden_thermal_expansion_of_the_forearm_is_named() {
    let _cpu = crate::common::busy_lock();
    let d = run("thermal-forearm", 15);
    let a = d.effects[0].params["alpha"];
    assert!((a - 2.3e-5).abs() < 2e-6, "{a}");
    assert!(!d.effects[0].run_time);
}

#[test]
fn two_hidden_effects_are_found_in_order_of_size() {
    let _cpu = crate::common::busy_lock();
    let d = run("j4-and-backlash", 16);
    assert!(d.effects[0].gain_mm > d.effects[1].gain_mm);
    assert_eq!(d.effects.len(), 2, "{:?}", d.effects);
    // Two acceptances, then (the repeatable resolver error keeps the search open) steps
    // that accept nothing, library and generic.
    assert!(d.steps.iter().skip(2).all(|s| s.accepted.is_none()));
    assert!(d.gap_closed, "{}", d.verdict);
}

#[test]
fn nothing_is_named_when_nothing_is_hidden() {
    let _cpu = crate::common::busy_lock();
    // The false-positive rate over many seeds is measured by the discovery_study example
    // (0 of 40 at 40 configurations); here a handful of seeds guard the thresholds.
    for seed in 21..=24 {
        let d = run("none", seed);
        assert!(d.lack_of_fit_before.p_value > 0.01);
        // No significant gap. The simulator's repeatable resolver error opens the search
        // (it could hide an effect of the configuration), and nothing passes it.
        assert!(d.effects.is_empty(), "{:?}", d.effects);
        assert!(d.steps.iter().all(|s| s.accepted.is_none()));
        assert_eq!(d.gap_after_mm, d.gap_before_mm);
        assert!(d.gap_closed, "{}", d.verdict);
        // Nothing named: `--out` writes the starting model unchanged, not its refit.
        let start = paper_model(false).unwrap();
        assert_eq!(d.model.to_yaml(), start.to_yaml());
    }
}

#[test]
fn effects_the_data_cannot_see_are_reported_not_identifiable() {
    let _cpu = crate::common::busy_lock();
    let sc = scenarios()
        .into_iter()
        .find(|s| s.name == "backlash-j1")
        .unwrap();
    let c = discovery_campaign(&DiscoverySpec {
        seed: 17,
        configs: 30,
        hidden: sc.hidden,
        ..Default::default()
    })
    .unwrap();
    let d = discover(
        &paper_model(false).unwrap(),
        &c.data,
        None,
        &DiscoverOptions::default(),
    )
    .unwrap();
    assert!(d.already_modelled.iter().any(|l| l == "base_frame_error"));
    assert!(
        d.already_modelled
            .iter()
            .any(|l| l == "joint_compliance_cubic[J2]")
    );
    // Without link bending in the model the measured torques already carry any payload.
    for label in [
        "payload_mass_error",
        "geometric_departure[dd1]",
        "geometric_departure[dtheta1]",
    ] {
        assert!(
            d.not_identifiable.iter().any(|l| l == label),
            "{label} in {:?}",
            d.not_identifiable
        );
    }
    // A holdout set from the same instrument set-up is used instead of cross-validation.
    let hold = discovery_campaign(&DiscoverySpec {
        seed: 17,
        pose_seed: 1,
        configs: 10,
        hidden: scenarios()[4].hidden.clone(),
        ..Default::default()
    })
    .unwrap();
    let d2 = discover(
        &paper_model(false).unwrap(),
        &c.data,
        Some(&hold.data),
        &DiscoverOptions::default(),
    )
    .unwrap();
    assert!(d2.heldout.starts_with("holdout set"));
    assert_eq!(d2.effects[0].label, "backlash[J1]");
}

#[test]
fn a_gear_ratio_hidden_in_mujocos_plant_is_estimated_where_the_calibration_absorbed_part_of_it() {
    // A campaign gathered through pa10d on MuJoCo's plant with J3's gear ratio 0.2 % off
    // (tests/mujoco/campaigns/gear-j3/README.md): the calibrated model's J3 offset took the
    // ratio's constant part, in a direction these poses hold. Discovery must give it back.
    let _cpu = crate::common::busy_lock();
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mujoco/campaigns/gear-j3");
    let model = Model::load(dir.join("calibrated.yaml")).unwrap();
    let data = Dataset::load(dir.join("campaign.csv")).unwrap();
    let holdout = Dataset::load(dir.join("heldout.csv")).unwrap();
    let d = discover(&model, &data, Some(&holdout), &DiscoverOptions::default()).unwrap();
    let gear = d
        .effects
        .iter()
        .find(|e| e.label == "gear_ratio_error[J3]")
        .unwrap_or_else(|| panic!("J3's ratio not named: {:?}", d.effects));
    let (s, se) = (gear.params["scale"], gear.stderr["scale"]);
    // the plant's 2e-3 within three standard errors (1.33e-3 ± 1.4e-4 with the offset held)
    assert!(
        (s - 2e-3).abs() < 3.0 * se,
        "{s} ± {se} against the plant's 2e-3"
    );
    // nothing named on a joint where the plant hides nothing but its springs (J4's is one)
    for e in &d.effects {
        assert!(matches!(e.joint, Some(3) | Some(4)), "{}", e.label);
    }
    assert!(d.gap_closed, "{}", d.verdict);
    assert!(
        d.gap_after_mm <= 1.1 * d.noise_floor_mm,
        "held-out {:.3} mm against the floor {:.3} mm",
        d.gap_after_mm,
        d.noise_floor_mm
    );
}
