//! `pa10 urdf`: forward kinematics computed from the URDF's XML alone (parsed by roxmltree,
//! composed here) equals `pa10 fk --model FILE` at random configurations, for the nominal
//! model and a calibrated one (departures and Hayati β on every parameter); and Pinocchio,
//! reading the same file (`tests/pin/urdf_check.py`), computes the model's tool pose and the
//! model's static gravity torques from its inertials.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use serde_json::Value;

/// The chain of a URDF.
struct Chain {
    /// Per revolute joint, its origin.
    joints: Vec<Isometry3<f64>>,
    /// The tool's fixed origin.
    tool: Isometry3<f64>,
    /// Per revolute joint, its lower and upper limit, rad.
    limits: Vec<(f64, f64)>,
}

/// The chain of the URDF `xml`.
fn chain(xml: &str) -> Chain {
    let doc = roxmltree::Document::parse(xml).unwrap();
    let nums = |s: &str| -> Vec<f64> { s.split_whitespace().map(|x| x.parse().unwrap()).collect() };
    let origin = |j: roxmltree::Node| -> Isometry3<f64> {
        let o = j.children().find(|c| c.has_tag_name("origin")).unwrap();
        let t = nums(o.attribute("xyz").unwrap());
        let r = nums(o.attribute("rpy").unwrap());
        // URDF: fixed-axis roll, pitch, yaw
        let rot = Rotation3::from_euler_angles(r[0], r[1], r[2]);
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_rotation_matrix(&rot),
        )
    };
    let joints: Vec<roxmltree::Node> = doc
        .descendants()
        .filter(|n| n.has_tag_name("joint"))
        .collect();
    let mut revolute = Vec::new();
    let mut limits = Vec::new();
    let mut tool = None;
    for j in joints {
        match j.attribute("type") {
            Some("revolute") => {
                let axis = j.children().find(|c| c.has_tag_name("axis")).unwrap();
                assert_eq!(nums(axis.attribute("xyz").unwrap()), [0.0, 0.0, 1.0]);
                let l = j.children().find(|c| c.has_tag_name("limit")).unwrap();
                limits.push((
                    l.attribute("lower").unwrap().parse().unwrap(),
                    l.attribute("upper").unwrap().parse().unwrap(),
                ));
                revolute.push(origin(j));
            }
            Some("fixed") => tool = Some(origin(j)),
            t => panic!("joint type {t:?}"),
        }
    }
    Chain {
        joints: revolute,
        tool: tool.unwrap(),
        limits,
    }
}

fn urdf_fk(chain: &Chain, q: &[f64; 6]) -> Isometry3<f64> {
    let mut f = Isometry3::identity();
    for (o, qj) in chain.joints.iter().zip(q) {
        f = f * o * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), *qj);
    }
    f * chain.tool
}

fn check(model_file: &std::path::Path, tag: &str) {
    let dir = std::env::temp_dir().join(format!("pa10-urdf-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("pa10.urdf");
    let pa10 = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_pa10"))
            .args(args)
            .output()
            .unwrap()
    };
    let o = pa10(&[
        "urdf",
        "--model",
        model_file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c = chain(&std::fs::read_to_string(&out).unwrap());
    assert_eq!(c.joints.len(), 6);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    let mut worst: (f64, f64) = (0.0, 0.0);
    for _ in 0..20 {
        let q: [f64; 6] = std::array::from_fn(|j| rng.random_range(c.limits[j].0..c.limits[j].1));
        let args: Vec<String> = q.iter().map(|v| format!("{v:e}")).collect();
        let mut a = vec![
            "fk",
            "--json",
            "--model",
            model_file.to_str().unwrap(),
            "--",
        ];
        a.extend(args.iter().map(String::as_str));
        let o = pa10(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        let p: Vec<f64> = serde_json::from_value(v["position"].clone()).unwrap();
        let w: Vec<f64> = serde_json::from_value(v["quaternion"].clone()).unwrap();
        let f = urdf_fk(&c, &q);
        let dp = (f.translation.vector - Vector3::new(p[0], p[1], p[2])).norm();
        let qf = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w[0], w[1], w[2], w[3]));
        let dr = f.rotation.angle_to(&qf);
        worst = (worst.0.max(dp), worst.1.max(dr));
    }
    eprintln!(
        "urdf {tag}: worst {:.2e} m, {:.2e} rad over 20 configurations",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-9 && worst.1 < 1e-9, "{worst:?}");
    pinocchio_agrees(&out, model_file, tag);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Pinocchio on the URDF at `urdf`: its tool pose equals the model's FK and its generalized
/// gravity equals the model's static torques (no load) at random configurations; its total
/// mass is the model's bodies'. Skipped (said) without Pinocchio, a failure in CI
/// (`PA10_REQUIRE_PIN=1`).
fn pinocchio_agrees(urdf: &std::path::Path, model_file: &std::path::Path, tag: &str) {
    use std::io::Write;
    if !crate::common::pinocchio() {
        return;
    }
    let model = pa10::model::Model::load(model_file).unwrap();
    let lim = model.limits();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(12);
    let qs: Vec<[f64; 6]> = (0..20)
        .map(|_| std::array::from_fn(|j| rng.random_range(lim.lower[j]..lim.upper[j])))
        .collect();
    let g = model.gravity();
    let req = serde_json::json!({"q": qs, "gravity": [g.x, g.y, g.z]}).to_string();
    let mut child = std::process::Command::new("python3")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/pin/urdf_check.py"
        ))
        .arg(urdf)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(req.as_bytes())
        .unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["nq"], 6);
    let mass: f64 = model.data().bodies.iter().map(|b| b.mass).sum();
    assert!((v["mass_kg"].as_f64().unwrap() - mass).abs() < 1e-9, "{v}");
    let (mut dp, mut dr, mut dt, mut peak) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (k, q) in qs.iter().enumerate() {
        let t: Vec<f64> = serde_json::from_value(v["tool"][k].clone()).unwrap();
        let fk = model.fk(q);
        dp = dp.max((fk.translation.vector - Vector3::new(t[0], t[1], t[2])).norm());
        let pq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(t[3], t[4], t[5], t[6]));
        dr = dr.max(UnitQuaternion::from_rotation_matrix(&fk.rotation).angle_to(&pq));
        let tau: Vec<f64> = serde_json::from_value(v["gravity_torque"][k].clone()).unwrap();
        let ours = model.static_torques(q, &pa10::model::ExternalLoad::NONE);
        for j in 0..6 {
            dt = dt.max((tau[j] - ours[j]).abs());
            peak = peak.max(ours[j].abs());
        }
    }
    eprintln!(
        "urdf {tag} vs Pinocchio: tool {dp:.2e} m, {dr:.2e} rad; gravity torques {dt:.2e} N·m (largest {peak:.1} N·m)"
    );
    assert!(dp < 1e-9 && dr < 1e-9, "tool: {dp:e} m, {dr:e} rad");
    assert!(
        peak > 10.0,
        "the random poses load the shoulder: {peak} N·m"
    );
    assert!(
        dt < 1e-9 * peak.max(1.0),
        "gravity torques differ by {dt:e} N·m"
    );
}

#[test]
fn the_urdf_has_the_models_forward_kinematics() {
    let nominal = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/model-nominal.yaml"
    ));
    check(nominal, "nominal");
    let (_, calibrated, _) = crate::common::calibrated_and_nominal(3);
    let dir = std::env::temp_dir().join(format!("pa10-urdf-cal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("calibrated.yaml");
    calibrated.save(&file).unwrap();
    check(&file, "calibrated");
    std::fs::remove_dir_all(&dir).unwrap();
}
