//! Trajectories, streams, speed scaling and the motion lease through the daemon's API, in
//! simulated time (`Lockstep`), judged by the simulator's ground truth: the true link angles
//! against the trajectory's desired positions.

use pa10::daemon::api::handle_from;
use pa10::daemon::config::Config;
use pa10::model::Model;
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

#[path = "../examples/common/six_points.rs"]
mod motion_path;
use motion_path::six_points;

const SEED: u64 = 3;
const PERIOD: f64 = 0.002;

fn lockstep(tag: &str, model: &Model) -> Lockstep {
    let dir = std::env::temp_dir().join(format!("pa10-traj-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let loaded = Config::load(&crate::daemon::config(&dir, model)).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    ls.run_until_ready(1.0).unwrap();
    ls.run_for(0.1);
    ls
}

fn status(ls: &Lockstep) -> Value {
    ls.call_json(&json!({"cmd": "status"}))["status"].clone()
}

fn six(v: &Value) -> [f64; 6] {
    serde_json::from_value(v.clone()).unwrap()
}

/// RMS and peak (mrad) of true link − desired over the whole trajectory, for `model` at
/// `load_n`; every cycle sampled.
fn track(model: &Model, load_n: f64) -> (f64, f64) {
    let mut ls = lockstep(&format!("track{load_n}"), model);
    ls.servo.set_load(load_n);
    let r = ls.call_json(&json!({"cmd": "set_payload", "newtons": load_n}));
    assert_eq!(r["ok"], true, "{r}");
    ls.run_for(0.5); // the measured torques settle
    let r = ls.call_json(&json!({"cmd": "follow_trajectory", "points": six_points()}));
    assert_eq!(r["ok"], true, "{r}");
    let (mut sum, mut peak, mut n) = (0.0, 0.0f64, 0);
    loop {
        ls.run_for(PERIOD);
        let st = status(&ls);
        let t = &st["trajectory"];
        let desired = six(&t["desired"]);
        let (truth, _) = ls.servo.link_state();
        for j in 0..6 {
            let e = (truth[j] - desired[j]) * 1e3;
            sum += e * e;
            peak = peak.max(e.abs());
        }
        n += 6;
        if t["state"] != "executing" {
            assert_eq!(t["state"], "succeeded", "{st}");
            assert_eq!(t["result"], "succeeded");
            assert_eq!(t["progress"], 1.0);
            break;
        }
        assert!(ls.now() < 20.0, "{st}");
    }
    ((sum / n as f64).sqrt(), peak)
}

#[test]
fn a_trajectory_is_tracked_by_the_true_link_and_the_calibrated_model_beats_the_nominal() {
    let _busy = crate::common::busy_lock();
    let (_, calibrated, nominal) = crate::common::calibrated_and_nominal(SEED);
    let mut rows = Vec::new();
    for (name, model) in [("calibrated", &calibrated), ("nominal", &nominal)] {
        for load in [0.0, 90.0] {
            let (rms, peak) = track(model, load);
            eprintln!("| {name} | {load} | {rms:.3} | {peak:.3} |");
            rows.push((name, load, rms, peak));
        }
    }
    let get = |n: &str, l: f64| rows.iter().find(|r| r.0 == n && r.1 == l).unwrap();
    let (cal0, cal90, nom90) = (
        get("calibrated", 0.0),
        get("calibrated", 90.0),
        get("nominal", 90.0),
    );
    // calibrated: the resolver floor (≈ 0.1 mrad) plus the loop's lag while moving
    assert!(
        cal0.2 < 1.0 && cal90.2 < 1.0,
        "calibrated RMS {} / {} mrad",
        cal0.2,
        cal90.2
    );
    assert!(
        nom90.2 > 2.0 * cal90.2,
        "nominal {} vs calibrated {} mrad",
        nom90.2,
        cal90.2
    );
}

#[test]
fn a_replacing_trajectory_continues_without_a_velocity_jump() {
    let mut ls = lockstep("replace", &Model::nominal());
    let first = json!([{"positions": [0.6, 0.7, 1.2, 0.5, 0.8, 0.6], "time_from_start": 3.0}]);
    let r = ls.call_json(&json!({"cmd": "follow_trajectory", "points": first}));
    assert_eq!(r["ok"], true, "{r}");
    let mut q = Vec::new();
    for k in 0..800 {
        if k == 400 {
            // mid-way, at speed: back where it came from
            let back =
                json!([{"positions": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0], "time_from_start": 3.0}]);
            let r = ls.call_json(&json!({"cmd": "follow_trajectory", "points": back}));
            assert_eq!(r["ok"], true, "{r}");
            assert_eq!(r["id"], 2);
        }
        ls.run_for(PERIOD);
        q.push(six(&status(&ls)["setpoint"]));
    }
    // velocity and acceleration of the setpoint, cycle by cycle, never beyond the limits
    let amax = [1.0, 1.0, 2.0, 4.0, 4.0, 4.0];
    let v: Vec<[f64; 6]> = q
        .windows(2)
        .map(|w| std::array::from_fn(|j| (w[1][j] - w[0][j]) / PERIOD))
        .collect();
    let mut worst = 0.0f64;
    for (k, w) in v.windows(2).enumerate() {
        for j in 0..6 {
            let a = (w[1][j] - w[0][j]) / PERIOD;
            assert!(
                a.abs() <= amax[j] * 1.05,
                "cycle {k}, joint {}: {a} rad/s²",
                j + 1
            );
            worst = worst.max(a.abs() / amax[j]);
        }
    }
    let speed_at_splice = v[398].iter().map(|x| x.abs()).fold(0.0, f64::max);
    assert!(
        speed_at_splice > 0.1,
        "replaced at speed: {speed_at_splice} rad/s"
    );
    eprintln!(
        "replace: speed at the splice {speed_at_splice:.3} rad/s, worst |a|/a_max {worst:.3}"
    );
    assert_eq!(status(&ls)["trajectory"]["id"], 2);
}

#[test]
fn an_infeasible_trajectory_is_refused_with_the_point_and_joint_and_changes_nothing() {
    let mut ls = lockstep("refuse", &Model::nominal());
    let before = status(&ls)["setpoint"].clone();
    for (points, why) in [
        (json!([]), "1…2000 points"),
        (
            json!([{"positions": [0.0, 1.4, 1.6, 0.0, 1.1, 0.0], "time_from_start": 0.5}]),
            "point 0, joint 2: needs",
        ),
        (
            json!([{"positions": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0], "time_from_start": 1.0},
                   {"positions": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0], "time_from_start": 1.0}]),
            "point 1: time_from_start",
        ),
        (
            json!([{"positions": [0.0, 0.4, 1.6, 0.0, 9.0, 0.0], "time_from_start": 10.0}]),
            "point 0, joint 5: 9.0000 rad is outside",
        ),
        (
            json!([{"positions": [0.0, 0.4, 1.6, 0.0, 1.1], "time_from_start": 1.0}]),
            "bad request",
        ),
    ] {
        let r = ls.call_json(&json!({"cmd": "follow_trajectory", "points": points}));
        assert_eq!(r["ok"], false, "{r}");
        assert!(r["error"].as_str().unwrap().contains(why), "{r}");
    }
    let r =
        ls.call_json(&json!({"cmd": "follow_trajectory", "points": six_points(), "unknown": 1}));
    assert!(
        r["error"].as_str().unwrap().contains("unknown field"),
        "{r}"
    );
    ls.run_for(0.1);
    assert_eq!(status(&ls)["setpoint"], before);
    assert_eq!(status(&ls)["state"], "holding");
}

#[test]
fn speed_scaling_slows_a_running_trajectory_and_tolerances_abort_it() {
    let mut ls = lockstep("scale", &Model::nominal());
    let pts = json!([{"positions": [0.4, 0.6, 1.3, 0.3, 0.9, 0.4], "time_from_start": 2.0}]);
    assert_eq!(
        ls.call_json(&json!({"cmd": "follow_trajectory", "points": pts.clone()}))["ok"],
        true
    );
    ls.run_for(0.5);
    for bad in [0.0, 1.5, f64::NAN] {
        let r = ls.call_json(&json!({"cmd": "set_speed_scaling", "fraction": bad}));
        assert_eq!(r["ok"], false, "{bad}: {r}");
    }
    assert_eq!(
        ls.call_json(&json!({"cmd": "set_speed_scaling", "fraction": 0.5}))["ok"],
        true
    );
    let t0 = ls.now();
    assert!(ls.run_while_not(10.0, |l| status(l)["trajectory"]["state"] != "executing"));
    let took = ls.now() - t0;
    // 1.5 s of trajectory left at half speed (after a 0.5 s ramp): ≈ 2.75 s, not 1.5 s
    assert!(took > 2.5 && took < 3.3, "{took}");
    assert_eq!(status(&ls)["speed_scaling"], 0.5);
    // a path tolerance no loop can keep: aborted with the reason, a controlled stop
    assert_eq!(
        ls.call_json(&json!({"cmd": "set_speed_scaling", "fraction": 1.0}))["ok"],
        true
    );
    let back = json!([{"positions": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0], "time_from_start": 2.0}]);
    let r = ls.call_json(
        &json!({"cmd": "follow_trajectory", "points": back, "path_tolerance": vec![1e-6; 6]}),
    );
    assert_eq!(r["ok"], true, "{r}");
    assert!(ls.run_while_not(1.0, |l| status(l)["trajectory"]["state"] != "executing"));
    let st = status(&ls);
    assert_eq!(st["trajectory"]["state"], "aborted", "{st}");
    assert_eq!(st["trajectory"]["result"], "path_tolerance_violated");
    assert!(ls.run_while_not(2.0, |l| status(l)["state"] == "holding"));
}

#[test]
fn a_servo_stream_that_stops_is_stopped_within_the_deadline() {
    let mut ls = lockstep("servo", &Model::nominal());
    let mut q = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
    for _ in 0..600 {
        q[0] += 0.0005; // 0.25 rad/s
        let r = ls.call_json(&json!({"cmd": "servo", "positions": q}));
        assert_eq!(r["ok"], true, "{r}");
        ls.run_for(PERIOD);
    }
    let st = status(&ls);
    assert_eq!(st["state"], "streaming", "{st}");
    let sp = six(&st["setpoint"]);
    // the target's velocity is fed forward: once the start-up transient (an acceleration
    // limited catch-up) is over, the lag is about a cycle's worth, not v²/2a = 31 mrad
    assert!((sp[0] - q[0]).abs() < 0.002, "{sp:?} vs {q:?}");
    // silence: still streaming just before the 100 ms deadline, stopping 3 cycles after it
    ls.run_for(0.1 - 2.0 * PERIOD);
    assert_eq!(status(&ls)["state"], "streaming");
    ls.run_for(5.0 * PERIOD);
    let st = status(&ls);
    assert!(
        st["state"] == "stopping" || st["state"] == "holding",
        "{st}"
    );
    assert!(
        st["stream_end"]
            .as_str()
            .unwrap()
            .contains("servo.deadline_ms"),
        "{st}"
    );
    assert!(ls.run_while_not(1.0, |l| status(l)["state"] == "holding"));
    // bad setpoints are refused with the joint
    let r = ls.call_json(&json!({"cmd": "servo", "positions": [0.0, 9.0, 1.6, 0.0, 1.1, 0.0]}));
    assert!(r["error"].as_str().unwrap().contains("joint 2"), "{r}");
    let r =
        ls.call_json(&json!({"cmd": "jog", "joint_velocities": [0.0, 0.0, 0.0, 0.0, 0.0, 9.0]}));
    assert!(r["error"].as_str().unwrap().contains("joint 6"), "{r}");
    // a jog moves at the asked velocity, then stops on its own deadline
    let r =
        ls.call_json(&json!({"cmd": "jog", "joint_velocities": [0.0, 0.0, 0.0, 0.0, 0.0, 0.2]}));
    assert_eq!(r["ok"], true, "{r}");
    let q6 = six(&status(&ls)["setpoint"])[5];
    ls.run_for(0.09);
    let moved = six(&status(&ls)["setpoint"])[5] - q6;
    assert!(moved > 0.005 && moved < 0.02, "{moved}");
    assert!(ls.run_while_not(1.0, |l| status(l)["state"] == "holding"));
}

#[test]
fn one_commander_at_a_time_with_the_lease() {
    let mut ls = lockstep("lease", &Model::nominal());
    let (a, b) = (101, 102);
    // a request in its wire form from connection `who`, answered in the reply's wire form
    let ask = |ls: &Lockstep, who, v: Value| {
        let req = serde::Deserialize::deserialize(&v).unwrap();
        serde_json::to_value(handle_from(&ls.core, req, who)).unwrap()
    };
    assert_eq!(ask(&ls, a, json!({"cmd": "acquire"}))["ok"], true);
    let mv = json!({"cmd": "move_joints", "q": [0.1, 0.45, 1.55, 0.0, 1.1, -0.1]});
    let r = ask(&ls, b, mv.clone());
    assert!(r["error"].as_str().unwrap().contains("motion lease"), "{r}");
    for req in [
        json!({"cmd": "acquire"}),
        json!({"cmd": "reset"}),
        json!({"cmd": "set_speed_scaling", "fraction": 0.5}),
        json!({"cmd": "servo", "positions": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0]}),
    ] {
        let r = ask(&ls, b, req.clone());
        assert!(
            r["error"].as_str().unwrap().contains("motion lease"),
            "{req}: {r}"
        );
    }
    assert_eq!(ask(&ls, b, json!({"cmd": "status"}))["ok"], true);
    assert_eq!(status(&ls)["leased"], true);
    // the holder moves; anyone may stop it
    assert_eq!(ask(&ls, a, mv.clone())["ok"], true,);
    ls.run_for(0.2);
    assert_eq!(ask(&ls, b, json!({"cmd": "stop"}))["ok"], true);
    assert!(ls.run_while_not(2.0, |l| status(l)["state"] == "holding"));
    // the holder's connection closes while it moves: a controlled stop, the lease is free
    assert_eq!(ask(&ls, a, mv)["ok"], true);
    ls.run_for(0.2);
    lock(&ls)
        .submit_from(a, pa10::daemon::core::Command::Disconnected)
        .unwrap();
    ls.run_for(PERIOD);
    assert_eq!(status(&ls)["state"], "stopping");
    assert_eq!(status(&ls)["leased"], false);
    assert!(ls.run_while_not(2.0, |l| status(l)["state"] == "holding"));
    let back = json!({"cmd": "move_joints", "q": [0.0, 0.4, 1.6, 0.0, 1.1, 0.0]});
    assert_eq!(ask(&ls, b, back)["ok"], true);
}

fn lock(ls: &Lockstep) -> pa10::daemon::runtime::CoreGuard<'_> {
    pa10::daemon::runtime::lock(&ls.core)
}

#[test]
fn payload_by_mass_and_centre_of_mass_and_a_new_tool_take_effect_at_once() {
    let mut ls = lockstep("payload", &Model::nominal());
    let r = ls.call_json(&json!({"cmd": "set_payload", "mass_kg": 2.0, "com": [0.1, 0.0, 0.05]}));
    assert_eq!(r["ok"], true, "{r}");
    let st = status(&ls);
    assert!(
        (st["payload_n"].as_f64().unwrap() - 2.0 * 9.80665).abs() < 1e-9,
        "{st}"
    );
    assert_eq!(st["payload_com"], json!([0.1, 0.0, 0.05]));
    for (req, why) in [
        (
            json!({"cmd": "set_payload", "mass_kg": 2.0, "newtons": 3.0}),
            "either",
        ),
        (json!({"cmd": "set_payload"}), "either"),
        (
            json!({"cmd": "set_payload", "newtons": 3.0, "com": [0.0, 0.0, 2.0]}),
            "within 1 m",
        ),
        (json!({"cmd": "set_payload", "mass_kg": -1.0}), "0…500 N"),
        (
            json!({"cmd": "set_tool", "translation": [0.0, 0.0, 0.1], "quaternion": [1.0, 1.0, 0.0, 0.0]}),
            "unit",
        ),
    ] {
        let r = ls.call_json(&req);
        assert!(r["error"].as_str().unwrap().contains(why), "{req}: {r}");
    }
    // a longer tool: the reported tool position moves 0.1 m along the tool's z axis
    let before = status(&ls);
    let r = ls.call_json(&json!({"cmd": "set_tool", "translation": [0.0, 0.0, 0.1], "quaternion": [1.0, 0.0, 0.0, 0.0]}));
    assert_eq!(r["ok"], true, "{r}");
    let after = status(&ls);
    let p = |v: &Value| -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::from(
            serde_json::from_value::<[f64; 3]>(v["tool_position"].clone()).unwrap(),
        )
    };
    assert!(
        ((p(&after) - p(&before)).norm() - 0.1).abs() < 1e-9,
        "{before} → {after}"
    );
    assert_eq!(
        after["setpoint"], before["setpoint"],
        "the arm does not move"
    );
    // not during motion
    let r = ls.call_json(&json!({"cmd": "move_joints", "q": [0.3, 0.5, 1.4, 0.2, 1.0, 0.3]}));
    assert_eq!(r["ok"], true, "{r}");
    ls.run_for(0.1);
    let r = ls.call_json(&json!({"cmd": "set_tool", "translation": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]}));
    assert!(
        r["error"].as_str().unwrap().contains("during a move"),
        "{r}"
    );
}

#[test]
fn a_cartesian_trajectory_keeps_the_tool_on_straight_lines_between_its_waypoints() {
    let mut ls = lockstep("cartesian", &Model::nominal());
    let model = Model::nominal();
    let start = model.fk(&six(&status(&ls)["setpoint"]));
    let (p0, q0) = pa10::model::pose_parts(&start);
    let p1 = [p0[0] - 0.08, p0[1] + 0.10, p0[2] - 0.05];
    let p2 = [p0[0] - 0.08, p0[1] - 0.05, p0[2] - 0.10];
    let pts = json!([
        {"position": p1, "quaternion": q0, "time_from_start": 2.0},
        {"position": p2, "quaternion": q0, "time_from_start": 4.0},
    ]);
    let r = ls.call_json(&json!({"cmd": "follow_cartesian", "points": pts}));
    assert_eq!(r["ok"], true, "{r}");
    // distance of a point from the segment a–b, m
    let off = |p: nalgebra::Vector3<f64>, a: [f64; 3], b: [f64; 3]| {
        let (a, b) = (nalgebra::Vector3::from(a), nalgebra::Vector3::from(b));
        let t = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
        (p - (a + t * (b - a))).norm()
    };
    let mut worst = 0.0f64;
    loop {
        ls.run_for(PERIOD);
        let st = status(&ls);
        let t = &st["trajectory"];
        let p = model.fk(&six(&t["desired"])).translation.vector;
        let d = off(p, p0, p1).min(off(p, p1, p2));
        worst = worst.max(d);
        if t["state"] != "executing" {
            assert_eq!(t["state"], "succeeded", "{st}");
            break;
        }
        assert!(ls.now() < 10.0);
    }
    let end = model.fk(&six(&status(&ls)["setpoint"])).translation.vector;
    assert!((end - nalgebra::Vector3::from(p2)).norm() < 1e-6, "{end}");
    eprintln!(
        "cartesian: worst distance from the straight lines {:.3} mm",
        worst * 1e3
    );
    assert!(worst < 0.2e-3, "{worst} m");
    // a waypoint out of reach is refused with its number; nothing moves
    let far = json!([
        {"position": p1, "quaternion": q0, "time_from_start": 2.0},
        {"position": [3.0, 0.0, 0.5], "quaternion": q0, "time_from_start": 4.0},
    ]);
    let r = ls.call_json(&json!({"cmd": "follow_cartesian", "points": far}));
    assert!(r["error"].as_str().unwrap().contains("waypoint 1,"), "{r}");
    let bad = json!([{"position": p1, "quaternion": [1.0, 1.0, 0.0, 0.0], "time_from_start": 2.0}]);
    let r = ls.call_json(&json!({"cmd": "follow_cartesian", "points": bad}));
    assert!(r["error"].as_str().unwrap().contains("waypoint 0"), "{r}");
    assert_eq!(status(&ls)["state"], "holding");
}

#[test]
fn a_tool_twist_jog_moves_the_tool_along_the_asked_direction() {
    let mut ls = lockstep("twist", &Model::nominal());
    let model = Model::nominal();
    let f0 = model.fk(&six(&status(&ls)["setpoint"]));
    for _ in 0..20 {
        let r = ls.call_json(&json!({"cmd": "jog", "tool_twist": [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]}));
        assert_eq!(r["ok"], true, "{r}");
        ls.run_for(0.05);
    }
    let f1 = model.fk(&six(&status(&ls)["setpoint"]));
    let d = f1.translation.vector - f0.translation.vector;
    eprintln!("twist jog: moved {d:?} m");
    assert!(d.z > 0.04 && d.z < 0.05, "{d}");
    assert!(d.xy().norm() < 0.01 * d.z, "straight up: {d}");
    assert!(
        (f1.rotation * f0.rotation.inverse()).angle() < 1e-3,
        "orientation kept"
    );
    // in the tool frame (pointing along the tool's own z), and refusals
    let r = ls.call_json(
        &json!({"cmd": "jog", "tool_twist": [0.0, 0.0, 0.0, 0.0, 0.0, 0.1], "frame": "tool"}),
    );
    assert_eq!(r["ok"], true, "{r}");
    for (req, why) in [
        (
            json!({"cmd": "jog", "tool_twist": [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]}),
            "within 0.25 m/s",
        ),
        (
            json!({"cmd": "jog", "tool_twist": [0.0, 0.0, 0.0, 0.0, 0.0, 0.1], "frame": "world"}),
            "\"base\" or \"tool\"",
        ),
        (json!({"cmd": "jog"}), "joint_velocities"),
    ] {
        let r = ls.call_json(&req);
        assert!(r["error"].as_str().unwrap().contains(why), "{req}: {r}");
    }
    assert!(ls.run_while_not(1.0, |l| status(l)["state"] == "holding"));
    assert!(
        status(&ls)["stream_end"]
            .as_str()
            .unwrap()
            .starts_with("jog:")
    );
}

#[test]
fn a_servo_pose_stream_moves_the_tool_to_the_streamed_pose() {
    let mut ls = lockstep("servo-pose", &Model::nominal());
    let model = Model::nominal();
    let goal_q = [0.05, 0.45, 1.55, 0.05, 1.05, 0.05];
    let (p, q) = pa10::model::pose_parts(&model.fk(&goal_q));
    for _ in 0..400 {
        let r = ls.call_json(&json!({"cmd": "servo", "position": p, "quaternion": q}));
        assert_eq!(r["ok"], true, "{r}");
        ls.run_for(PERIOD);
    }
    let sp = six(&status(&ls)["setpoint"]);
    assert!((0..6).all(|j| (sp[j] - goal_q[j]).abs() < 1e-6), "{sp:?}");
    let r = ls.call_json(&json!({"cmd": "servo", "position": [3.0, 0.0, 0.5], "quaternion": q}));
    assert!(
        r["error"].as_str().unwrap().starts_with("servo pose:"),
        "{r}"
    );
    let r = ls.call_json(&json!({"cmd": "servo", "positions": goal_q, "position": p}));
    assert!(r["error"].as_str().unwrap().contains("either"), "{r}");
}
