//! The configuration's unit tests: the shipped files parse, every key is validated by name.

use super::*;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config")
}

fn sim_yaml() -> String {
    std::fs::read_to_string(root().join("sim.yaml")).unwrap()
}

fn err(text: &str) -> String {
    match Config::parse(text, "t.yaml").and_then(|c| c.validate(&root())) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn shipped_configs_are_valid() {
    let s = shipped_sim();
    assert_eq!(s.bus.backend, Backend::Virtual);
    assert!((s.bus_load - 0.8475).abs() < 1e-9);
    assert_eq!(s.api.mode, 0o660);
    // the loop's parameters, in seconds, with the model's position limits
    assert!((s.control.period_s - 0.002).abs() < 1e-15);
    assert!((s.control.feedback_timeout_s - 0.02).abs() < 1e-15);
    assert_eq!(s.control.limits.upper, s.model.limits().upper);
    assert_eq!(s.link.watchdog_ms, 50);
    assert_eq!(s.api.model_dir, root());
    // the hardware config names /etc/pa10d/calibrated.yaml; validate it against the nominal
    let mut h = Config::parse(
        &std::fs::read_to_string(root().join("pa10d.yaml")).unwrap(),
        "pa10d.yaml",
    )
    .unwrap();
    assert_eq!(h.model, PathBuf::from("/etc/pa10d/calibrated.yaml"));
    h.model = root().join("model-nominal.yaml");
    let h = h.validate(&root()).unwrap();
    assert_eq!(h.bus.interface.as_deref(), Some("can0"));
    assert_eq!(h.realtime.sched_fifo_priority, Some(80));
}

#[test]
fn every_torque_source_parses_and_a_wrong_one_is_named() {
    let y = sim_yaml();
    for (name, want) in [
        ("measured", TorqueSource::Measured),
        ("model", TorqueSource::Model),
        ("blended", TorqueSource::Blended),
        ("estimated", TorqueSource::Estimated),
    ] {
        let text = y.replace("torque_source: measured", &format!("torque_source: {name}"));
        let s = Config::parse(&text, "t.yaml")
            .unwrap()
            .validate(&root())
            .unwrap();
        assert_eq!(s.control.torque_source, want);
    }
    let e = match Config::parse(
        &y.replace("torque_source: measured", "torque_source: guess"),
        "t.yaml",
    ) {
        Ok(_) => panic!("accepted torque_source: guess"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("guess") && e.contains("blended"), "{e}");
}

#[test]
fn every_error_names_its_key() {
    let y = sim_yaml();
    assert!(
        err(&y.replace("  port: 8765", "  port: 8765\n  rate_hz: 0"))
            .contains("invalid `live.rate_hz`: must be within 1…500 Hz, got 0")
    );
    assert!(
        err(&y.replace("rate_hz: 500", "rate_hz: 700"))
            .contains("invalid `control.rate_hz`: 700 Hz needs 118.")
    );
    assert!(err(&y.replace("payload_n: 0.0", "payload_n: -3")).contains("`payload_n`"));
    assert!(
        err(&y.replace("following_error: 0.01", "following_error: 2"))
            .contains("`limits.following_error`")
    );
    assert!(err(&y.replace("mode: \"0660\"", "mode: \"rw\"")).contains("`api.mode`"));
    assert!(
        err(&y.replace("controller_watchdog_ms: 50", "controller_watchdog_ms: 300"))
            .contains("`limits.controller_watchdog_ms`")
    );
    assert!(
        err(&y.replace("  mode: \"0660\"", "  mode: \"0660\"\n  max_clients: 0"))
            .contains("`api.max_clients`")
    );
    assert!(err(&y.replace("backend: virtual", "backend: socketcan")).contains("`bus.interface`"));
    assert!(
        err(&y.replace("log_level: info", "log_levle: info")).contains("unknown field `log_levle`")
    );
    assert!(
        err(&y.replace("model: model-nominal.yaml", "model: nope.yaml"))
            .contains("invalid `model`")
    );
    assert!(
        err(&y.replace(
            "[15.0, 30.0, 15.0, 5.0, 5.0, 2.0]",
            "[15.0, 30.0, 0.0, 5.0, 5.0, 2.0]"
        ))
        .contains("`torque_constants[2]`")
    );
    assert!(
        err(&y.replace(
            "speed: [0.5, 0.5, 1.0, 2.0, 2.0, 2.0]",
            "speed: [0.5, 3.0, 1.0, 2.0, 2.0, 2.0]"
        ))
        .contains("`limits.speed[1]`")
    );
    assert!(
        err(&y.replace("feedback_timeout_ms: 20", "feedback_timeout_ms: 1"))
            .contains("at least two cycles")
    );
    for bad in ["-0.1", "2.5", ".nan"] {
        let text = y.replace("min_ramp_s: 0.5", &format!("min_ramp_s: {bad}"));
        assert!(err(&text).contains("`limits.min_ramp_s`"), "{bad}");
    }
    let text = y.replace("min_ramp_s: 0.5", "min_ramp_s: 0.25");
    let s = Config::parse(&text, "t.yaml")
        .unwrap()
        .validate(&root())
        .unwrap();
    assert_eq!(s.control.limits.min_ramp_s, 0.25);
    for bad in ["-0.00001", "0.01", ".nan"] {
        let text = y.replace(
            "current_filter_hz: 20.0",
            &format!("current_filter_hz: 20.0\n  hold_deadband: {bad}"),
        );
        assert!(err(&text).contains("`control.hold_deadband`"), "{bad}");
    }
    let text = y.replace(
        "current_filter_hz: 20.0",
        "current_filter_hz: 20.0\n  hold_deadband: 0.00004",
    );
    let s = Config::parse(&text, "t.yaml")
        .unwrap()
        .validate(&root())
        .unwrap();
    assert_eq!(s.control.hold_deadband, 4e-5);
    for bad in ["-1", "11", ".inf"] {
        let text = y.replace(
            "current_filter_hz: 20.0",
            &format!("current_filter_hz: 20.0\n  hold_damping: {bad}"),
        );
        assert!(err(&text).contains("`control.hold_damping`"), "{bad}");
    }
    for bad in ["0", "-8", ".nan", "1e9"] {
        let text = y.replace(
            "current_filter_hz: 20.0",
            &format!("current_filter_hz: 20.0\n  gain_inertia_kgm2: {bad}"),
        );
        assert!(err(&text).contains("`control.gain_inertia_kgm2`"), "{bad}");
    }
    let text = y.replace(
        "current_filter_hz: 20.0",
        "current_filter_hz: 20.0\n  gain_inertia_kgm2: 8.5",
    );
    let s = Config::parse(&text, "t.yaml")
        .unwrap()
        .validate(&root())
        .unwrap();
    assert_eq!(s.control.gain_inertia_kgm2, Some(8.5));
}
