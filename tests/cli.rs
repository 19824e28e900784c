//! The `pa10` and `pa10d` command lines, run as a user would.

use std::process::{Command, Output};

fn pa10(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pa10"))
        .args(args)
        .output()
        .expect("pa10 runs")
}

fn stdout_json(o: &Output) -> serde_json::Value {
    assert!(
        o.status.success(),
        "failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("one JSON object")
}

fn f(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

#[test]
fn fk_of_the_zero_pose_prints_the_flange_at_1317_mm() {
    let _cpu = crate::common::busy_lock();
    let j = stdout_json(&pa10(&["fk", "--json", "0", "0", "0", "0", "0", "0"]));
    let p = f(&j["position"]);
    assert!(
        (p[2] - 1.317).abs() < 1e-12 && p[0].abs() < 1e-12 && p[1].abs() < 1e-12,
        "{p:?}"
    );
    assert_eq!(f(&j["quaternion"]), vec![1.0, 0.0, 0.0, 0.0]);
}

#[test]
fn negative_numbers_parse_as_positionals_and_ik_inverts_fk() {
    let _cpu = crate::common::busy_lock();
    let q = ["0.3", "-0.5", "1.1", "-0.4", "0.7", "-0.2"];
    let mut args = vec!["fk", "--json"];
    args.extend(q);
    let j = stdout_json(&pa10(&args));
    let (p, r) = (f(&j["position"]), f(&j["quaternion"]));
    let pose: Vec<String> = p.iter().chain(&r).map(|x| format!("{x:.17}")).collect();
    let mut args = vec!["ik", "--json", "--near", "0.3,-0.5,1.1,-0.4,0.7,-0.2"];
    args.extend(pose.iter().map(String::as_str));
    let j = stdout_json(&pa10(&args));
    let first = f(&j["solutions"][0]);
    for (a, b) in first.iter().zip(q) {
        assert!((a - b.parse::<f64>().unwrap()).abs() < 1e-8, "{first:?}");
    }
    assert!(j["solutions"].as_array().unwrap().len() >= 2);
}

#[test]
fn fk_in_degrees_and_with_resolver_deflection() {
    let _cpu = crate::common::busy_lock();
    let a = stdout_json(&pa10(&[
        "fk", "--json", "--deg", "0", "90", "0", "0", "0", "0",
    ]));
    assert!((f(&a["position"])[0] - 1.0).abs() < 1e-12);
    // A rigid nominal model does not deflect: resolver reading = link angle.
    let b = stdout_json(&pa10(&[
        "fk",
        "--json",
        "--deg",
        "--resolver",
        "--load-n",
        "44",
        "0",
        "90",
        "0",
        "0",
        "0",
        "0",
    ]));
    assert_eq!(a, b);
}

#[test]
fn a_loaded_compliant_arm_sags() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("stiff.yaml");
    let text = pa10::model::NOMINAL_YAML.replace(
        "stiffness: [null, null, null, null, null, null]",
        "stiffness: [null, {klin: 1.98e4, kcub: 3.35e7}, {klin: 1.27e4, kcub: 1.46e7}, null, {klin: 2.56e3, kcub: 3.83e7}, null]",
    );
    std::fs::write(&path, text).unwrap();
    let p = path.to_str().unwrap();
    let rigid = stdout_json(&pa10(&[
        "fk", "--json", "--model", p, "0", "1.5", "0", "0", "0", "0",
    ]));
    let sag = stdout_json(&pa10(&[
        "fk",
        "--json",
        "--model",
        p,
        "--resolver",
        "--load-n",
        "44",
        "0",
        "1.5",
        "0",
        "0",
        "0",
        "0",
    ]));
    let dz = f(&rigid["position"])[2] - f(&sag["position"])[2];
    // ≈ 1 m lever × (4 + 2…) mrad: several millimetres of sag
    assert!(dz > 0.004 && dz < 0.02, "sag {dz} m");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_gets_a_precise_error_and_a_failing_exit() {
    let _cpu = crate::common::busy_lock();
    let o = pa10(&["ik", "0.5", "0.1", "0.6", "0", "1", "0.5", "0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("unit quaternion"));
    let o = pa10(&["ik", "3.0", "0.1", "0.6", "0", "1", "0", "0"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("out of reach"));
    let o = pa10(&["fk", "0", "0", "0"]);
    assert_eq!(o.status.code(), Some(2), "clap usage error");
    let o = pa10(&["fk", "--load-n", "10", "0", "0", "0", "0", "0", "0"]);
    assert_eq!(o.status.code(), Some(2), "--load-n needs --resolver");
    let o = pa10(&["model", "check", "/nonexistent.yaml"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent.yaml"));
    // the URDF's torque limits: six positive numbers, N·m
    let o = pa10(&["urdf", "--effort", "1,2,3"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("six torques"));
    let o = pa10(&["urdf", "--effort", "1,2,3,4,5,-1"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("joint 6 torque -1 N·m"));
}

#[test]
fn model_check_summarises_a_valid_file() {
    let _cpu = crate::common::busy_lock();
    let nominal = concat!(env!("CARGO_MANIFEST_DIR"), "/config/model-nominal.yaml");
    let o = pa10(&["model", "check", nominal]);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("valid model") && s.contains("d4 0.48 m") && s.contains("all joints rigid"),
        "{s}"
    );
}

#[test]
fn the_daemon_checks_its_config() {
    let _cpu = crate::common::busy_lock();
    let pa10d = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pa10d"))
            .args(args)
            .output()
            .unwrap()
    };
    let sim = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml");
    let o = pa10d(&["--check-config", sim]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("valid") && s.contains("84.8 %") && s.contains("rigid joints"),
        "{s}"
    );
    // a bad config names the key
    let dir = std::env::temp_dir().join(format!("pa10d-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(sim).unwrap().replace(
        "model: model-nominal.yaml",
        &format!(
            "model: {}",
            concat!(env!("CARGO_MANIFEST_DIR"), "/config/model-nominal.yaml")
        ),
    );
    // the CAN FD configuration: 1 kHz at 31.8 % worst case
    let fd = crate::canfd::on_fd(&text, 1000.0, 5e6);
    std::fs::write(dir.join("fd.yaml"), fd).unwrap();
    let o = pa10d(&["--check-config", dir.join("fd.yaml").to_str().unwrap()]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        s.contains("CAN FD bus at 1000/5000 kbit/s")
            && s.contains("1000 Hz, worst-case bus load 31.8 %"),
        "{s}"
    );
    std::fs::write(
        dir.join("bad.yaml"),
        text.replace("rate_hz: 500", "rate_hz: 1000"),
    )
    .unwrap();
    let o = pa10d(&["--check-config", dir.join("bad.yaml").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("invalid `control.rate_hz`"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(
        pa10d(&[]).status.code(),
        Some(2),
        "one of --config / --check-config is required"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn accuracy_prints_json_writes_csv_and_plots() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-acc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("points.csv");
    let plots = dir.join("plots");
    let o = pa10(&[
        "accuracy",
        "--planes",
        "0.4,0.6",
        "--points",
        "5",
        "--draws",
        "2000",
        "--seed",
        "3",
        "--json",
        "--csv",
        csv.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
    ]);
    let j = stdout_json(&o);
    let planes = j["planes"].as_array().unwrap();
    assert_eq!(planes.len(), 2);
    for (p, z) in planes.iter().zip([0.4, 0.6]) {
        assert_eq!(p["z"].as_f64().unwrap(), z);
        for key in ["mean_mm", "sd_mm", "p95_mm", "max_mm", "linearised_mean_mm"] {
            assert!(p[key].as_f64().unwrap() > 0.0, "{key}");
        }
        let ratio = p["mean_mm"].as_f64().unwrap() / p["linearised_mean_mm"].as_f64().unwrap();
        assert!((ratio - 1.0).abs() < 0.03, "{ratio}");
    }
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 1 + 2 * 5);
    assert!(text.starts_with("z_m,point,x_m,y_m,q1"));
    for z in ["0.400", "0.600"] {
        let svg = std::fs::read_to_string(plots.join(format!("accuracy-z{z}.svg"))).unwrap();
        assert!(svg.contains("<svg") && svg.contains("<circle"));
    }
    // same seed, same numbers; the table mode works too
    let again = stdout_json(&pa10(&[
        "accuracy",
        "--planes",
        "0.4,0.6",
        "--points",
        "5",
        "--draws",
        "2000",
        "--seed",
        "3",
        "--json",
        "--threads",
        "1",
    ]));
    assert_eq!(j["planes"], again["planes"]);
    let o = pa10(&[
        "accuracy", "--planes", "0.5", "--points", "3", "--draws", "100",
    ]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("0.197 ± 0.096"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn accuracy_rejects_bad_settings() {
    let _cpu = crate::common::busy_lock();
    for (args, msg) in [
        (vec!["--sigma-arcmin", "-0.5"], "σ must be finite and ≥ 0"),
        (vec!["--sigma-arcmin", "0.6,0.6"], "one value or six"),
        (vec!["--points", "0"], "at least one point"),
        (vec!["--planes", "2.5", "--points", "2"], "reachable"),
        (vec!["--region", "0,1,0"], "XMIN,XMAX,YMIN,YMAX"),
        (vec!["--tool-quaternion", "1,1,0,0"], "unit quaternion"),
    ] {
        let mut a = vec!["accuracy", "--draws", "10"];
        a.extend(args);
        let o = pa10(&a);
        assert_eq!(o.status.code(), Some(1), "{a:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(msg), "{a:?}: {err}");
    }
}

#[test]
fn sim_measure_then_calibrate_end_to_end() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-cal-{}", std::process::id()));
    let d = dir.to_str().unwrap();
    let o = pa10(&[
        "sim",
        "measure",
        "--seed",
        "2",
        "--repeats",
        "3",
        "--out",
        d,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "cal.csv",
        "cal.meta.yaml",
        "lines.csv",
        "val.csv",
        "truth.yaml",
    ] {
        assert!(dir.join(f).exists(), "{f}");
    }
    let out = dir.join("calibrated.yaml");
    let report = dir.join("report");
    let j = stdout_json(&pa10(&[
        "calibrate",
        "--data",
        &format!("{d}/cal.csv"),
        "--base-seed",
        &format!("{d}/lines.csv"),
        "--validate",
        &format!("{d}/val.csv"),
        "--out",
        out.to_str().unwrap(),
        "--json",
        "--report",
        report.to_str().unwrap(),
        "--starts",
        "2",
    ]));
    for load in ["0", "22", "44"] {
        let b = j["before"][load]["mean_mm"].as_f64().unwrap();
        let a = j["after"][load]["mean_mm"].as_f64().unwrap();
        assert!(a < 0.35 && b > 2.0 * a, "{load}: before {b} after {a}");
        assert!(j["after"][load]["peak_mm"].as_f64().unwrap() >= a);
        assert!(j["after"][load]["mean_orient_deg"].as_f64().unwrap() < 0.1);
    }
    for load in ["0", "45", "90"] {
        let v = &j["validation"];
        assert!(
            v["after"][load]["mean_mm"].as_f64().unwrap()
                < v["before"][load]["mean_mm"].as_f64().unwrap()
        );
        assert!(v["linear"][load]["mean_mm"].as_f64().is_some());
    }
    assert_eq!(j["stiffness"]["klin"].as_array().unwrap().len(), 3);
    assert_eq!(j["stiffness"]["kcub"].as_array().unwrap().len(), 3);
    assert_eq!(j["params"].as_array().unwrap().len(), 30);
    // the paper's 27 poses take one wrist: the report says the other is determined worse
    let w = &j["wrist"];
    assert_eq!(w["configurations"], serde_json::json!([27, 0]));
    assert!(
        w["other_wrist_sigma_mm"].as_f64().unwrap() > 1.5 * w["sigma_mm"].as_f64().unwrap(),
        "{w}"
    );
    assert!(w["warning"].as_str().unwrap().contains("other wrist"));
    for f in [
        "residuals-before.svg",
        "residuals-after.svg",
        "validation-after.svg",
    ] {
        assert!(
            std::fs::read_to_string(report.join(f))
                .unwrap()
                .contains("<svg"),
            "{f}"
        );
    }
    // the calibrated model is a model file fk and model check accept
    let o = pa10(&["model", "check", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("J2 stiffness"));
    assert!(
        pa10(&[
            "fk",
            "--model",
            out.to_str().unwrap(),
            "0",
            "0.5",
            "1",
            "0",
            "0.5",
            "0"
        ])
        .status
        .success()
    );
    // the calibrated model's predicted uncertainty over a plane; a nominal model has none
    let map_csv = dir.join("map.csv");
    let o = pa10(&[
        "accuracy",
        "map",
        "--model",
        out.to_str().unwrap(),
        "--z",
        "0.1",
        "--step",
        "0.1",
        "--out",
        dir.join("map.svg").to_str().unwrap(),
        "--csv",
        map_csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sig: Vec<f64> = std::fs::read_to_string(&map_csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(
        sig.len() > 20 && sig.iter().all(|s| (0.1..1.0).contains(s)),
        "{sig:?}"
    );
    assert!(dir.join("map.svg").exists());
    let o = pa10(&[
        "accuracy",
        "map",
        "--model",
        "config/model-nominal.yaml",
        "--z",
        "0.1",
        "--out",
        dir.join("never.svg").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no `uncertainty:` section"));
    // torques from the model's statics (for a daemon on `torque_source: model`): the
    // campaign's truth carries a 2.4 kg tooling the nominal bodies lack; the springs absorb it
    let j = stdout_json(&pa10(&[
        "calibrate",
        "--data",
        &format!("{d}/cal.csv"),
        "--model-torques",
        "--out",
        dir.join("model-torques.yaml").to_str().unwrap(),
        "--json",
        "--starts",
        "1",
    ]));
    for load in ["0", "22", "44"] {
        let a = j["after"][load]["mean_mm"].as_f64().unwrap();
        eprintln!("--model-torques: {load} N after {a} mm");
        assert!(a < 0.5, "{load}: after {a} mm with the model's torques");
    }
    // the text report
    let o = pa10(&[
        "calibrate",
        "--data",
        &format!("{d}/cal.csv"),
        "--out",
        out.to_str().unwrap(),
        "--starts",
        "1",
    ]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("identified parameters")
            && s.contains("klin2")
            && s.contains("condition number"),
        "{s}"
    );

    // a corrupted row: refused with its line, nothing written
    let text = std::fs::read_to_string(dir.join("cal.csv")).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    let bad = lines[7].replacen(",0.0,", ",zero,", 1);
    lines[7] = &bad;
    std::fs::write(dir.join("bad.csv"), lines.join("\n")).unwrap();
    let fresh = dir.join("never.yaml");
    let o = pa10(&[
        "calibrate",
        "--data",
        &format!("{d}/bad.csv"),
        "--out",
        fresh.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.csv:8: column `load_n`"), "{err}");
    assert!(!fresh.exists());
    // without its sidecar the fit cannot place the tool: the error says what is missing
    let bare = dir.join("bare.csv");
    std::fs::copy(dir.join("cal.csv"), &bare).unwrap();
    let o = pa10(&[
        "calibrate",
        "--data",
        bare.to_str().unwrap(),
        "--out",
        fresh.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no sidecar") && err.contains("`tool`") && !err.contains("User("),
        "{err}"
    );
    assert!(!fresh.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn plan_writes_a_pose_list_collect_reads_and_refuses_bad_settings() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-plan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("poses.csv");
    let j = stdout_json(&pa10(&[
        "plan",
        "--box",
        "0.45,-0.2,-0.05,0.70,0.2,0.25",
        "--configs",
        "8",
        "--loads",
        "0,44",
        "--candidates",
        "300",
        "--table-z",
        "-0.3",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]));
    let poses =
        pa10::calib::collect::parse_poses(&std::fs::read_to_string(&out).unwrap(), "p").unwrap();
    assert_eq!(poses.len(), 16, "8 configurations × 2 loads");
    // every planned pose puts the tool in the box, above the table
    let tool = pa10::model::frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0]);
    let m = pa10::model::Model::nominal().with_tool(&tool).unwrap();
    for p in &poses {
        let t = m.fk(&p.q).translation.vector;
        assert!(
            (0.45..=0.70).contains(&t.x)
                && (-0.2..=0.2).contains(&t.y)
                && (-0.05..=0.25).contains(&t.z),
            "{p:?}: tool at {t:?}"
        );
    }
    // the same volume given in the instrument's frame (placed at (0.5, 0, 0.1) m, axes as the
    // base's), with the curve plotted
    let inst_out = dir.join("inst.csv");
    let o = pa10(&[
        "plan",
        "--box=-0.05,-0.2,-0.15,0.2,0.2,0.15",
        "--instrument-frame",
        "0.5",
        "0",
        "0.1",
        "1",
        "0",
        "0",
        "0",
        "--configs",
        "6",
        "--loads",
        "0",
        "--candidates",
        "200",
        "--plot",
        dir.join("curve.svg").to_str().unwrap(),
        "--out",
        inst_out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("curve.svg").exists());
    for p in pa10::calib::collect::parse_poses(&std::fs::read_to_string(&inst_out).unwrap(), "i")
        .unwrap()
    {
        let t = m.fk(&p.q).translation.vector;
        assert!(
            (0.45..=0.70).contains(&t.x)
                && (-0.2..=0.2).contains(&t.y)
                && (-0.05..=0.25).contains(&t.z),
            "{p:?}: tool at {t:?} (instrument-frame box)"
        );
    }
    let planned = j["planned"]["predicted_mm"].as_f64().unwrap();
    let floor = j["planned"]["floor_mm"].as_f64().unwrap();
    assert!(planned > floor && planned < 2.0 * floor, "{j}");
    assert!(j["paper"]["configs"] == 27 && j["curve"].as_array().unwrap().len() >= 5);
    for (args, why) in [
        (
            vec!["--box", "0.7,-0.2,-0.05,0.45,0.2,0.25"],
            "each minimum below its maximum",
        ),
        (vec!["--box", "0.45,-0.2,-0.05,0.70,0.2"], "six values"),
        (
            vec!["--box", "0.45,-0.2,-0.05,0.70,0.2,0.25", "--configs", "0"],
            "--configs: 1…200",
        ),
        (
            vec!["--box", "0.45,-0.2,-0.05,0.70,0.2,0.25", "--loads", "0,-5"],
            "loads",
        ),
        (
            vec!["--box", "5,5,5,6,6,6", "--candidates", "20"],
            "reachable",
        ),
        (
            vec![
                "--box",
                "0.45,-0.2,-0.05,0.70,0.2,0.25",
                "--sphere",
                "0.6,0,0.1,0.2",
            ],
            "cannot be used with",
        ),
        (vec!["--sphere", "0.6,0,0.1,-1"], "positive radius"),
        (
            vec![
                "--box",
                "0.45,-0.2,-0.05,0.70,0.2,0.25",
                "--instrument-frame",
                "0",
                "0",
                "0",
                "2",
                "0",
                "0",
                "0",
            ],
            "unit quaternion",
        ),
    ] {
        let fresh = dir.join("never.csv");
        let mut a = vec!["plan", "--out", fresh.to_str().unwrap()];
        a.extend(args);
        let o = pa10(&a);
        // 1: refused by pa10; 2: a usage error clap reports (two volumes at once)
        assert!(matches!(o.status.code(), Some(1 | 2)), "{a:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(why), "{a:?}: {err}");
        assert!(!fresh.exists(), "nothing written on a refusal");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn sim_on_a_missing_can_interface_fails_clearly() {
    let _cpu = crate::common::busy_lock();
    let o = pa10(&["sim", "--can", "pa10-no-such-if", "--duration", "0.1"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("opening CAN interface pa10-no-such-if"),
        "{err}"
    );
    let o = pa10(&["sim"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("needs --can IFACE"));
    let o = pa10(&["sim", "--can", "x", "--duration", "-1"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--duration must be > 0 s"));
    let o = pa10(&["sim", "--can", "x", "--current-offset", "7=0.5"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--current-offset takes AXIS=VALUE"));
    let o = pa10(&["sim", "--can", "x", "--mute-axis", "9"]);
    assert_eq!(o.status.code(), Some(2));
    let dir = std::env::temp_dir().join(format!("pa10-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("bad.log"), "(0.0) vcan0 080#0100\nnot a frame\n").unwrap();
    let o = pa10(&[
        "sim",
        "replay",
        "--can",
        "x",
        dir.join("bad.log").to_str().unwrap(),
    ]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("bad.log:2: not a candump line"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn discover_names_hidden_backlash_from_files_and_writes_a_model_the_daemon_loads() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-cli-discover-{}", std::process::id()));
    let d = dir.to_str().unwrap();
    let o = pa10(&[
        "sim",
        "discovery",
        "--scenario",
        "backlash-j1",
        "--seed",
        "3",
        "--configs",
        "24",
        "--out",
        d,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let (start, cal, hold, ext, rep) = (
        p("start.yaml"),
        p("cal.csv"),
        p("holdout.csv"),
        p("extended.yaml"),
        p("report"),
    );
    let j = stdout_json(&pa10(&[
        "discover",
        "--model",
        &start,
        "--data",
        &cal,
        "--holdout",
        &hold,
        "--json",
        "--out",
        &ext,
        "--report",
        &rep,
    ]));
    assert_eq!(j["significant_gap_before"], true);
    let e = &j["effects"][0];
    assert_eq!(e["name"], "backlash");
    assert_eq!(e["joint"], 1);
    let b = e["params"]["backlash"].as_f64().unwrap();
    assert!((b - 4e-4).abs() < 4.0 * e["stderr"]["backlash"].as_f64().unwrap() + 2e-5);
    assert!(e["gain_mm"].as_f64().unwrap() > 0.0);
    assert!(j["gap_after_mm"].as_f64().unwrap() < j["gap_before_mm"].as_f64().unwrap());
    assert!(j["noise_floor_mm"].as_f64().unwrap() > 0.0);
    assert_eq!(j["steps"][0]["accepted"], "backlash[J1]");
    // The extended model loads and carries the backlash for the daemon.
    let m = pa10::model::Model::load(&ext).unwrap();
    assert!(m.data().joint_errors[0].unwrap().backlash > 3e-4);
    assert_eq!(m.data().discovered[0].name, "backlash");
    assert!(
        std::fs::read_dir(&rep).unwrap().any(|f| f
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(".svg"))
    );
    // Currents that lie (every torque column zero, as a stuck drive's current can read):
    // `--model-torques` takes both sets' torques from the start model's statics instead.
    for f in ["cal", "holdout"] {
        let text = std::fs::read_to_string(p(&format!("{f}.csv"))).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let tau: Vec<usize> = (1..=6)
            .map(|j| header.iter().position(|h| *h == format!("tau{j}")).unwrap())
            .collect();
        let mut out = header.join(",") + "\n";
        for l in lines {
            let mut cells: Vec<&str> = l.split(',').collect();
            for &k in &tau {
                cells[k] = "0";
            }
            out += &(cells.join(",") + "\n");
        }
        std::fs::write(p(&format!("zero-{f}.csv")), out).unwrap();
        std::fs::copy(
            p(&format!("{f}.meta.yaml")),
            p(&format!("zero-{f}.meta.yaml")),
        )
        .unwrap();
    }
    let zero = |flag: &[&str]| {
        let mut args = vec![
            "discover",
            "--model",
            &start,
            "--json",
            "--max-effects",
            "1",
        ];
        let (zc, zh) = (p("zero-cal.csv"), p("zero-holdout.csv"));
        args.extend(["--data", &zc, "--holdout", &zh]);
        args.extend(flag);
        stdout_json(&pa10(&args))
    };
    let (lying, modelled) = (zero(&[]), zero(&["--model-torques"]));
    let gap = |j: &serde_json::Value| j["gap_before_mm"].as_f64().unwrap();
    assert!(
        gap(&modelled) < 0.6 * gap(&lying),
        "--model-torques: held-out gap {} mm vs {} mm on the zero torques",
        gap(&modelled),
        gap(&lying)
    );
    assert_eq!(modelled["effects"][0]["name"], "backlash");
    assert_ne!(lying["effects"][0]["name"], "backlash");
    // Bad input: a precise error, nothing written.
    let o = pa10(&["discover", "--data", &cal, "--only", "gremlins"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown effect `gremlins`"));
    let o = pa10(&["sim", "discovery", "--scenario", "nope", "--out", d]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("known: none, cubic-j2"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_mujoco_config_checks_and_a_bad_plant_section_is_refused_by_key() {
    let _cpu = crate::common::busy_lock();
    let pa10d = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pa10d"))
            .args(args)
            .output()
            .unwrap()
    };
    let cfg = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-mujoco.yaml");
    let o = pa10d(&["--check-config", cfg]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dir = std::env::temp_dir().join(format!("pa10d-plant-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("model-nominal.yaml"), pa10::model::NOMINAL_YAML).unwrap();
    let text = std::fs::read_to_string(cfg).unwrap();
    for (from, to, key) in [
        ("friction: 1.0  ", "friction: 20.0  ", "sim.plant.friction"),
        (
            "friction_model: stick",
            "friction_model: glue",
            "friction_model",
        ),
        ("kind: mujoco", "kind: model", "sim.plant.kind"),
        (
            "command: [python3, ../tests/mujoco/plant.py]",
            "command: []",
            "sim.plant.command",
        ),
        (
            "friction_model: stick",
            "friction_model: stick\n    hidden: {gear: [0, 0, 0.5, 0, 0, 0]}",
            "sim.plant.hidden",
        ),
        (
            "friction_model: stick",
            "friction_model: stick\n    hidden: {bearing: [[0, 0], [0.01, 0], [0, 0], [0, 0], [0, 0], [0, 0]]}",
            "bearing[1]",
        ),
        (
            "friction_model: stick",
            "friction_model: stick\n    hidden: {gears: [0, 0, 0, 0, 0, 0]}",
            "gears",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        std::fs::write(dir.join("bad.yaml"), text.replace(from, to)).unwrap();
        let o = pa10d(&["--check-config", dir.join("bad.yaml").to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{to}: {e}");
        assert!(e.contains(key), "{to}: {e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `pa10 identify` on the simulated arm (the in-process plant: no friction): the identified
/// bodies give the hidden truth's gravity torques (its masses ±10 % and a 2.4 kg tooling the
/// nominal model does not know) far better than the nominal model does.
/// `pa10 identify --known-weight`: a configuration whose torque constants are 10 % high on J2
/// and 5 % low on J3 (the simulated drives are the simulator's) is caught against a 90 N weight
/// the simulation hangs, the right ones pass, and a model without a tool is refused.
#[test]
fn identify_checks_the_torque_constants_against_a_known_weight() {
    let _cpu = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-ktcheck-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml");
    let text = std::fs::read_to_string(src).unwrap();
    let wrong = "torque_constants: [15.0, 33.0, 14.25, 5.0, 5.0, 2.0]";
    let cfg = dir.join("sim.yaml");
    std::fs::write(
        &cfg,
        text.replace("torque_constants: [15.0, 30.0, 15.0, 5.0, 5.0, 2.0]", wrong),
    )
    .unwrap();
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/config/model-nominal.yaml"),
        dir.join("model-nominal.yaml"),
    )
    .unwrap();
    assert!(std::fs::read_to_string(&cfg).unwrap().contains(wrong));
    let out = dir.join("identified.yaml");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "identify",
            "--simulate",
            cfg.to_str().unwrap(),
            "--waypoints",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--known-weight",
            "90",
            "--json",
        ];
        args.extend_from_slice(extra);
        pa10(&args)
    };
    let refused = run(&[]);
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--tool"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    assert!(!out.exists(), "a refusal writes nothing");
    let o = run(&["--tool", "0", "0", "0.35", "1", "0", "0", "0"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = stdout_json(&o);
    let c = &v["torque_constant_check"];
    let f = |key: &str, j: usize| c[key][j].as_f64().unwrap();
    let b = |key: &str, j: usize| c[key][j].as_bool().unwrap();
    assert!(!b("seen", 0), "J1's axis is vertical: {c}");
    // the in-process arm's weight is a force without mass: the check's centripetal term reads
    // its ratios ≈ 0.7 % high (docs/judge.md §8)
    assert!((f("ratio", 1) - 1.1).abs() < 0.015 && b("off", 1), "{c}");
    assert!((f("ratio", 2) - 0.95).abs() < 0.015 && b("off", 2), "{c}");
    assert!((f("corrected", 1) - 30.0).abs() < 0.45, "{c}");
    for j in [3, 4] {
        assert!(b("seen", j) && !b("off", j), "J{}: {c}", j + 1);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn identify_recovers_the_hidden_gravity_through_the_daemon() {
    let _cpu = crate::common::busy_lock();
    use pa10::model::{ExternalLoad, Model};
    let dir = std::env::temp_dir().join(format!("pa10-identify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("identified.yaml");
    let cfg = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml");
    let o = pa10(&[
        "identify",
        "--simulate",
        cfg,
        "--waypoints",
        "4",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = stdout_json(&o);
    assert!(v["samples"].as_u64().unwrap() > 300, "{v}");
    let m = Model::load(&out).unwrap();
    let settings = pa10::daemon::config::Config::load(std::path::Path::new(cfg)).unwrap();
    let (truth, _) = pa10::sim::rig::truth_for(&settings).unwrap();
    let nominal = Model::nominal();
    let (mut id_err, mut nom_err) = (0.0f64, 0.0f64);
    for k in 0..40 {
        let x = k as f64 * 0.37;
        let q = [
            x.sin(),
            0.6 * (1.3 * x).cos(),
            0.5 + 0.6 * x.sin(),
            x.cos(),
            1.0 * (0.7 * x).sin(),
            0.0,
        ];
        let t = truth.model.static_torques(&q, &ExternalLoad::NONE);
        let a = m.static_torques(&q, &ExternalLoad::NONE);
        let b = nominal.static_torques(&q, &ExternalLoad::NONE);
        for j in 0..6 {
            id_err = id_err.max((a[j] - t[j]).abs());
            nom_err = nom_err.max((b[j] - t[j]).abs());
        }
    }
    assert!(
        id_err < 1.0 && nom_err > 4.0 * id_err,
        "identified {id_err} N·m, nominal {nom_err} N·m"
    );
    // no friction in this plant: none identified
    for j in 0..6 {
        let f = m.friction(j).unwrap();
        assert!(f.coulomb < 0.5, "J{}: {f:?}", j + 1);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
