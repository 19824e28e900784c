//! The servo link on CAN FD (`bus.fd: true`): the daemon at 1 kHz and 2 kHz on the simulated
//! arm in simulated time with the wire modelled (every frame its exact time at the arbitration
//! and data bit rates, one after another), its status, the configuration's refusals, and what
//! must not change with the rate: the feedback timeout in milliseconds.

use pa10::can::protocol::{self, Message};
use pa10::daemon::config::{Config, ConfigError};
use pa10::model::Model;
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};

/// A `config/sim.yaml` text on CAN FD (1 Mbit/s arbitration, `data_bitrate` bit/s) at
/// `rate_hz`.
pub(crate) fn on_fd(sim_yaml: &str, rate_hz: f64, data_bitrate: f64) -> String {
    sim_yaml
        .replace(
            "  bitrate: 1000000          # bit/s",
            &format!("  bitrate: 1000000\n  fd: true\n  data_bitrate: {data_bitrate}"),
        )
        .replace("rate_hz: 500 ", &format!("rate_hz: {rate_hz} "))
}

/// `config/sim.yaml` (the tests' variant) [`on_fd`], loaded.
fn fd_config(
    tag: &str,
    rate_hz: f64,
    data_bitrate: f64,
) -> Result<pa10::daemon::config::Settings, ConfigError> {
    let dir = std::env::temp_dir().join(format!("pa10-canfd-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = crate::daemon::config(&dir, &Model::nominal());
    let text = on_fd(
        &std::fs::read_to_string(&path).unwrap(),
        rate_hz,
        data_bitrate,
    );
    std::fs::write(&path, text).unwrap();
    let loaded = Config::load(&path);
    std::fs::remove_dir_all(&dir).unwrap();
    loaded
}

fn status(ls: &Lockstep) -> Value {
    ls.call_json(&json!({"cmd": "status"}))["status"].clone()
}

/// The daemon of `settings` on the simulated arm with the wire modelled (20 µs from a frame's
/// last bit to the receiver acting on it), holding.
fn running(settings: &pa10::daemon::config::Settings) -> Lockstep {
    let mut ls = Lockstep::from_config(settings)
        .unwrap()
        .with_wire(settings.bus.timing(), 20e-6);
    ls.run_until_ready(1.0).unwrap();
    assert!(
        ls.run_while_not(1.0, |l| status(l)["state"] == "holding"),
        "{}",
        status(&ls)
    );
    ls
}

#[test]
fn the_daemon_runs_the_simulated_arm_at_1_khz_on_can_fd() {
    let _busy = crate::common::busy_lock();
    let settings = fd_config("1k", 1000.0, 5e6).unwrap();
    assert_eq!(settings.link.framing, protocol::Framing::Fd);
    let mut ls = running(&settings);
    let st = status(&ls);
    assert_eq!(st["cycle"]["rate_hz"], 1000.0, "{st}");
    assert_eq!(st["cycle"]["framing"], "fd", "{st}");
    let worst = st["cycle"]["bus_load_pct"].as_f64().unwrap();
    assert!((worst - 31.82).abs() < 0.01, "worst-case load {worst} %");
    // a move lands where it was sent; one cycle a millisecond, none incomplete
    let (c0, t0) = (st["link"]["cycles"].as_u64().unwrap(), ls.now());
    let q = [0.2, 0.6, 1.3, 0.1, 1.0, -0.2];
    assert_eq!(
        ls.call_json(&json!({"cmd": "move_joints", "q": q}))["ok"],
        true
    );
    assert!(ls.run_while_not(10.0, |l| status(l)["state"] == "holding"
        && l.now() > t0 + 0.1));
    ls.run_for(0.5);
    let st = status(&ls);
    let cycles = st["link"]["cycles"].as_u64().unwrap() - c0;
    let expected = ((ls.now() - t0) * 1000.0).round() as u64;
    assert!(
        cycles.abs_diff(expected) <= 2,
        "{cycles} cycles in {} s",
        ls.now() - t0
    );
    assert_eq!(st["link"]["incomplete"], 0, "{st}");
    assert_eq!(st["link"]["malformed"], 0, "{st}");
    for j in 0..6 {
        let m = st["q_motor"][j].as_f64().unwrap();
        assert!(
            (m - q[j]).abs() < 0.02,
            "joint {}: motor {m} vs {}",
            j + 1,
            q[j]
        );
    }
    // the wire was busy for the load the worst case bounds
    let measured = ls.wire_load().unwrap() * 100.0;
    assert!(
        measured > 20.0 && measured < worst,
        "measured {measured} % vs worst {worst} %"
    );
}

#[test]
fn the_simulated_controller_answers_fd_commands_with_one_fd_feedback_frame() {
    use pa10::sim::servo::{ServoConfig, ServoSim};
    let truth = pa10::sim::TrueRobot::draw(
        1,
        &Model::nominal(),
        &pa10::sim::rig::default_tool(),
        pa10::sim::SimNoise::default(),
    )
    .unwrap();
    let cfg = ServoConfig {
        framing: protocol::Framing::Fd,
        ..ServoConfig::default()
    };
    let mut sim = ServoSim::new(truth, cfg, pa10::sim::rig::HOME, 1);
    let mut out = Vec::new();
    let send = |m: Message| protocol::encode(&m).unwrap();
    for (t, r) in [
        (0.001, protocol::Request::ReleaseBrakes),
        (0.002, protocol::Request::StartControl),
    ] {
        sim.handle(
            t,
            &send(Message::Control {
                request: r,
                watchdog_ms: 50,
            }),
            &mut out,
        );
    }
    out.clear();
    sim.handle(0.003, &send(Message::Sync { cycle: 7 }), &mut out);
    assert_eq!(out.len(), 1, "one frame for six axes: {out:?}");
    let Ok(Message::FeedbackFd(fb)) = protocol::decode(&out[0]) else {
        panic!("FEEDBACK_FD, got {:?}", protocol::decode(&out[0]))
    };
    assert!(out[0].is_fd() && fb.iter().all(|f| f.cycle == 7));
    // a COMMAND_FD is applied at once: the motors move at the commanded speed
    let before = sim.motor_angles();
    let speeds = [0.1, -0.1, 0.2, 0.0, 0.0, 0.3];
    sim.handle(
        0.0035,
        &pa10::daemon::link::command_frame_fd(7, &speeds),
        &mut out,
    );
    sim.tick(0.2035, &mut out);
    let after = sim.motor_angles();
    for j in 0..6 {
        let moved = after[j] - before[j];
        assert!(
            (moved - 0.2 * speeds[j]).abs() < 0.01,
            "axis {}: {moved} rad",
            j + 1
        );
    }
    // an axis that does not answer withholds the one frame
    sim.injected.mute_axis = Some(2);
    out.clear();
    sim.handle(0.21, &send(Message::Sync { cycle: 8 }), &mut out);
    assert!(
        out.iter()
            .all(|f| protocol::decode(f).is_ok_and(|m| !matches!(m, Message::FeedbackFd(_))))
    );
}

/// At 2 kHz a 20 ms feedback timeout is 40 cycles: the silent controller is caught after
/// 20 ms, not after 20 cycles (10 ms).
#[test]
fn the_feedback_timeout_stays_in_milliseconds_at_2_khz() {
    let _busy = crate::common::busy_lock();
    let settings = fd_config("2k", 2000.0, 5e6).unwrap();
    let mut ls = running(&settings);
    assert_eq!(status(&ls)["cycle"]["rate_hz"], 2000.0);
    ls.run_for(0.05);
    assert_eq!(status(&ls)["link"]["incomplete"], 0, "{}", status(&ls));
    ls.servo.injected.mute_axis = Some(3);
    let t0 = ls.now();
    assert!(ls.run_while_not(0.1, |l| status(l)["state"] == "fault"));
    let after_ms = (ls.now() - t0) * 1e3;
    let st = status(&ls);
    assert!(
        st["fault"].as_str().unwrap().contains("stale feedback"),
        "{st}"
    );
    assert!(
        (19.0..=23.0).contains(&after_ms),
        "faulted {after_ms} ms after the controller fell silent"
    );
}

#[test]
fn the_configuration_refuses_what_the_fd_bus_cannot_carry() {
    let err = |r: Result<_, ConfigError>| r.err().map(|e| e.to_string()).unwrap_or_default();
    // 3 kHz needs more than 90 % of 1/5 Mbit/s; the message names the highest rate
    let e = err(fd_config("3k", 3000.0, 5e6));
    assert!(
        e.contains("control.rate_hz") && e.contains("max 2828 Hz"),
        "{e}"
    );
    // no faster data phase: 1 kHz does not fit
    let e = err(fd_config("slow", 1000.0, 1e6));
    assert!(
        e.contains("control.rate_hz") && e.contains("max 883 Hz"),
        "{e}"
    );
    for (bad, key) in [
        (20e6, "bus.data_bitrate"),
        (0.5e6, "bus.data_bitrate"),
        (f64::NAN, "bus.data_bitrate"),
    ] {
        let e = err(fd_config("bad", 1000.0, bad));
        assert!(e.contains(key), "{bad}: {e}");
    }
    // a data phase without FD is a contradiction, named
    let dir = std::env::temp_dir().join(format!("pa10-canfd-nofd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = crate::daemon::config(&dir, &Model::nominal());
    let text = std::fs::read_to_string(&path).unwrap().replace(
        "  bitrate: 1000000          # bit/s",
        "  bitrate: 1000000\n  data_bitrate: 5000000",
    );
    std::fs::write(&path, text).unwrap();
    let e = err(Config::load(&path));
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        e.contains("bus.data_bitrate") && e.contains("bus.fd: true"),
        "{e}"
    );
}
