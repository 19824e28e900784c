//! Model files: the shipped nominal, round trips, and precise errors for bad input.

use pa10::model::{Model, ModelError, NOMINAL_YAML};

use crate::common::{perturbed_model, rng};

fn err(yaml: &str) -> String {
    match Model::from_yaml_str(yaml, "test.yaml") {
        Ok(_) => panic!("accepted bad model:\n{yaml}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn shipped_nominal_is_valid_and_rigid() {
    let m = Model::nominal();
    assert!((0..6).all(|j| m.stiffness(j).is_none()));
    assert_eq!(m.data().dh[3].d, 0.480);
    let from_disk = Model::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/model-nominal.yaml"
    ))
    .unwrap();
    assert_eq!(from_disk, m);
}

#[test]
fn yaml_round_trip_is_exact() {
    let m = perturbed_model(&mut rng(21));
    let back = Model::from_yaml_str(&m.to_yaml(), "round trip").unwrap();
    assert_eq!(back, m);
    let dir = std::env::temp_dir().join(format!("pa10-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("m.yaml");
    m.save(&p).unwrap();
    assert_eq!(Model::load(&p).unwrap(), m);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_file_names_the_path() {
    let e = Model::load("/nonexistent/model.yaml").unwrap_err();
    assert!(matches!(e, ModelError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/model.yaml"));
}

#[test]
fn unknown_key_is_rejected_with_its_line() {
    let y = NOMINAL_YAML.replace("gravity:", "gravty:");
    let e = err(&y);
    assert!(
        e.contains("unknown field `gravty`") && e.contains("line"),
        "{e}"
    );
}

#[test]
fn negative_stiffness_is_rejected() {
    let y = NOMINAL_YAML.replace(
        "stiffness: [null, null, null, null, null, null]",
        "stiffness: [null, {klin: -5.0, kcub: 0.0}, null, null, null, null]",
    );
    assert_eq!(
        err(&y),
        "invalid `stiffness[1].klin`: must be a finite stiffness > 0 N·m/rad, got -5"
    );
    let y = NOMINAL_YAML.replace(
        "stiffness: [null, null, null, null, null, null]",
        "stiffness: [null, {klin: 5.0, kcub: -1.0}, null, null, null, null]",
    );
    assert!(err(&y).contains("stiffness[1].kcub"));
}

#[test]
fn non_unit_quaternion_is_rejected() {
    let y = NOMINAL_YAML.replace(
        "tool: {translation: [0.0, 0.0, 0.0], quaternion: [1.0, 0.0, 0.0, 0.0]}",
        "tool: {translation: [0.0, 0.0, 0.35], quaternion: [1.0, 0.2, 0.0, 0.0]}",
    );
    let e = err(&y);
    assert!(
        e.starts_with("invalid `tool.quaternion`: must be a unit quaternion"),
        "{e}"
    );
}

#[test]
fn hayati_rules_are_enforced() {
    let y = NOMINAL_YAML.replace(
        "  - {da: 0.0, dalpha: 0.0, dbeta: 0.0, dtheta: 0.0}",
        "  - {da: 0.0, dalpha: 0.0, dd: 0.001, dtheta: 0.0}",
    );
    assert!(err(&y).contains("departures[1].dd"), "{}", err(&y));
    let y = NOMINAL_YAML.replacen(
        "  - {da: 0.0, dalpha: 0.0, dd: 0.0,    dtheta: 0.0}",
        "  - {da: 0.0, dalpha: 0.0, dbeta: 0.001, dtheta: 0.0}",
        1,
    );
    assert!(err(&y).contains("departures[0].dbeta"), "{}", err(&y));
}

#[test]
fn structure_units_and_ranges_are_checked() {
    // a twist in degrees instead of radians
    let y = NOMINAL_YAML.replace(
        "alpha: -1.5707963267948966, d: 0.317",
        "alpha: -90, d: 0.317",
    );
    assert!(err(&y).contains("dh[0].alpha"));
    // a length in millimetres
    let y = NOMINAL_YAML.replace("d: 0.480", "d: 480");
    assert!(err(&y).contains("dh[3].d"), "{}", err(&y));
    // a departure far beyond a tolerance
    let y = NOMINAL_YAML.replacen(
        "{da: 0.0, dalpha: 0.0, dd: 0.0,    dtheta: 0.0}",
        "{da: 0.2, dalpha: 0.0, dd: 0.0, dtheta: 0.0}",
        1,
    );
    assert!(err(&y).contains("departures[0].da"));
    // five joints instead of six
    let y = NOMINAL_YAML.replace(
        "velocity: [1.0, 1.0, 2.0, 6.2832, 6.2832, 6.2832]",
        "velocity: [1.0, 1.0, 2.0, 6.2832, 6.2832]",
    );
    assert!(
        err(&y).contains("expected an array of length 6"),
        "{}",
        err(&y)
    );
    // inverted limits
    let y = NOMINAL_YAML.replace("lower: [-3.0892,", "lower: [3.5,");
    assert!(err(&y).contains("joint_limits.upper[0]"));
    // a body on a frame that does not exist
    let y = NOMINAL_YAML.replace("frame: 5,", "frame: 7,");
    assert!(err(&y).contains("bodies[2].frame"));
    let y = NOMINAL_YAML.replace("mass: 8.32", "mass: -8.32");
    assert!(err(&y).contains("bodies[1].mass"));
}
