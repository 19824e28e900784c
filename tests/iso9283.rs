//! An ISO 9283 pose accuracy and repeatability test run end to end on the simulated daemon, as
//! a lab runs it: `pa10 iso9283 plan` writes the pose list, the daemon (with the nominal or the
//! calibrated model loaded) drives the arm through it in simulated time, the simulator's
//! ground truth plays the instrument, `pa10 iso9283 report` computes AP and RP.

use std::process::Command;

use pa10::calib::collect::{InstrumentSample, instrument_csv, parse_poses};
use pa10::daemon::config::Config;
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

fn pa10(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pa10"))
        .args(args)
        .output()
        .expect("run pa10")
}

#[test]
fn the_calibrated_daemon_passes_an_iso_9283_test_the_nominal_one_fails() {
    let _busy = crate::common::busy_lock();
    let (_, calibrated, nominal) = crate::common::calibrated_and_nominal(3);
    let dir = std::env::temp_dir().join(format!("pa10-iso-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut results = Vec::new();
    for (name, model) in [("calibrated", &calibrated), ("nominal", &nominal)] {
        let model_file = dir.join(format!("{name}.yaml"));
        model.save(&model_file).unwrap();
        let poses = dir.join(format!("{name}-poses.csv"));
        let o = pa10(&[
            "iso9283",
            "plan",
            "--model",
            model_file.to_str().unwrap(),
            "--cube",
            "0.58,0.0,0.1,0.2",
            "--cycles",
            "5",
            "--load",
            "44",
            "--out",
            poses.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let plan = parse_poses(&std::fs::read_to_string(&poses).unwrap(), "plan").unwrap();
        assert_eq!(plan.len(), 25);
        // the daemon with this model, the load hung and declared, through every pose in order
        let cfg = Config::load(&crate::daemon::config(&dir, model)).unwrap();
        let mut ls = Lockstep::from_config(&cfg).unwrap();
        ls.run_until_ready(1.0).unwrap();
        ls.servo.set_load(44.0);
        let r = ls.call_json(&json!({"cmd": "set_payload", "newtons": 44.0}));
        assert_eq!(r["ok"], true, "{r}");
        let mut measured = Vec::new();
        for t in &plan {
            let r = ls.call_json(&json!({"cmd": "move_joints", "q": t.q}));
            assert_eq!(r["ok"], true, "{r}");
            assert!(ls.run_while_not(20.0, |l| {
                l.call_json(&json!({"cmd": "status"}))["status"]["state"] == "holding"
            }));
            ls.run_for(0.4); // the resolvers and the compensation settle
            measured.push(InstrumentSample {
                config_id: t.config_id.clone(),
                load_n: t.load_n,
                pose: ls.servo.observe_tool(),
            });
        }
        let inst = dir.join(format!("{name}-cmm.csv"));
        std::fs::write(&inst, instrument_csv(&measured)).unwrap();
        let o = pa10(&[
            "iso9283",
            "report",
            "--model",
            model_file.to_str().unwrap(),
            "--poses",
            poses.to_str().unwrap(),
            "--measured",
            inst.to_str().unwrap(),
            "--limits",
            "0.5,0.05",
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: Value = serde_json::from_slice(&o.stdout).unwrap();
        let ap: Vec<f64> = j["poses"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["ap_p"].as_f64().unwrap() * 1e3)
            .collect();
        let rp: Vec<f64> = j["poses"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["rp_l"].as_f64().unwrap() * 1e3)
            .collect();
        eprintln!(
            "{name}: AP_P {ap:.3?} mm, RP_l {rp:.4?} mm, pass {}",
            j["pass"]
        );
        results.push((name, ap, rp, j["pass"].as_bool().unwrap()));
    }
    std::fs::remove_dir_all(&dir).ok();
    let (cal, nom) = (&results[0], &results[1]);
    assert!(cal.3, "calibrated: AP {:?} RP {:?}", cal.1, cal.2);
    assert!(!nom.3, "nominal passes: AP {:?}", nom.1);
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    assert!(
        worst(&nom.1) > 3.0 * worst(&cal.1),
        "AP nominal {:?} vs calibrated {:?}",
        nom.1,
        cal.1
    );
}

#[test]
fn iso_9283_refuses_bad_settings_precisely() {
    let dir = std::env::temp_dir().join(format!("pa10-iso-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("never.csv");
    let out_s = out.to_str().unwrap();
    for (args, why) in [
        (vec!["--cube", "0.6,0,0.1"], "CX,CY,CZ,SIDE"),
        (vec!["--cube", "0.6,0,0.1,-0.2"], "positive side"),
        (vec!["--cube", "3,0,0.1,0.2"], "not reachable"),
        (
            vec!["--cube", "0.6,0,0.1,0.2", "--cycles", "1"],
            "--cycles: 2…100",
        ),
        (
            vec!["--cube", "0.6,0,0.1,0.2", "--load", "-1"],
            "--load: 0…500 N",
        ),
    ] {
        let mut a = vec!["iso9283", "plan", "--out", out_s];
        a.extend(args);
        let o = pa10(&a);
        assert_eq!(o.status.code(), Some(1), "{a:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(why), "{a:?}: {err}");
        assert!(!out.exists());
    }
    // a measurement of a pose the plan does not have
    let poses = dir.join("p.csv");
    assert!(
        pa10(&[
            "iso9283",
            "plan",
            "--cube",
            "0.6,0,0.1,0.2",
            "--cycles",
            "2",
            "--out",
            poses.to_str().unwrap()
        ])
        .status
        .success()
    );
    let inst = dir.join("m.csv");
    std::fs::write(
        &inst,
        "config_id,load_n,x,y,z,qw,qx,qy,qz\nP9,0,0.6,0,0.1,1,0,0,0\n",
    )
    .unwrap();
    let o = pa10(&[
        "iso9283",
        "report",
        "--poses",
        poses.to_str().unwrap(),
        "--measured",
        inst.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("pose `P9` is not in the plan"));
    std::fs::remove_dir_all(&dir).ok();
}

/// The README's lab workflow on the simulated arm, every step a `pa10` command: plan, collect
/// (simulated daemon and instrument), merge, calibrate, an ISO 9283 test with the calibrated
/// model, its report and verdict.
#[test]
fn plan_collect_calibrate_iso9283_as_the_readme_says() {
    let _busy = crate::common::busy_lock();
    let dir = std::env::temp_dir().join(format!("pa10-lab-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml");
    let steps: Vec<Vec<String>> = vec![
        vec![
            "plan",
            "--box",
            "0.45,-0.2,-0.05,0.70,0.2,0.25",
            "--configs",
            "10",
            "--candidates",
            "400",
            "--out",
            &f("poses.csv"),
        ],
        vec![
            "collect",
            "run",
            "--simulate",
            config,
            "--poses",
            &f("poses.csv"),
            "--out",
            &f("robot.csv"),
            "--instrument-out",
            &f("cmm.csv"),
            "--samples",
            "2",
        ],
        vec![
            "collect",
            "merge",
            "--robot",
            &f("robot.csv"),
            "--instrument",
            &f("cmm.csv"),
            "--out",
            &f("cal.csv"),
        ],
        vec![
            "calibrate",
            "--data",
            &f("cal.csv"),
            "--torque-constants",
            "15,30,15,5,5,2",
            "--starts",
            "1",
            "--out",
            &f("calibrated.yaml"),
        ],
        vec![
            "iso9283",
            "plan",
            "--model",
            &f("calibrated.yaml"),
            "--cube",
            "0.58,0,0.1,0.2",
            "--cycles",
            "5",
            "--load",
            "44",
            "--out",
            &f("iso.csv"),
        ],
        vec![
            "collect",
            "run",
            "--simulate",
            config,
            "--model",
            &f("calibrated.yaml"),
            "--poses",
            &f("iso.csv"),
            "--out",
            &f("iso-robot.csv"),
            "--instrument-out",
            &f("iso-cmm.csv"),
        ],
    ]
    .into_iter()
    .map(|v| v.into_iter().map(String::from).collect())
    .collect();
    for s in &steps {
        let args: Vec<&str> = s.iter().map(String::as_str).collect();
        let o = pa10(&args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    // the sidecar travelled from the simulated instrument into the dataset
    assert!(dir.join("cal.meta.yaml").exists());
    let o = pa10(&[
        "iso9283",
        "report",
        "--model",
        &f("calibrated.yaml"),
        "--poses",
        &f("iso.csv"),
        "--measured",
        &f("iso-cmm.csv"),
        "--limits",
        "0.5,0.05",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: Value = serde_json::from_slice(&o.stdout).unwrap();
    eprintln!("{j}");
    assert_eq!(j["pass"], true, "{j}");
    std::fs::remove_dir_all(&dir).ok();
}
