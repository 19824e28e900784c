use super::*;
use crate::daemon::control::{TrajectoryResult, TrajectoryState};

/// One request of every kind, every optional field set somewhere.
fn every_request() -> Vec<ApiRequest> {
    let tp = TrajectoryPoint {
        positions: [0.1; 6],
        velocities: Some([0.0; 6]),
        accelerations: None,
        time_from_start: 1.5,
    };
    let cp = CartesianPoint {
        position: [0.4, 0.0, 0.6],
        quaternion: [1.0, 0.0, 0.0, 0.0],
        time_from_start: 2.0,
    };
    vec![
        ApiRequest::Status {},
        ApiRequest::MoveJoints { q: [0.1; 6] },
        ApiRequest::MovePose {
            position: [0.4, 0.1, 0.5],
            quaternion: [0.0, 1.0, 0.0, 0.0],
        },
        ApiRequest::Stop {},
        ApiRequest::Estop {},
        ApiRequest::Reset {},
        ApiRequest::SetPayload {
            newtons: Some(44.0),
            mass_kg: None,
            com: Some([0.0, 0.0, 0.05]),
        },
        ApiRequest::SetTool {
            translation: [0.0, 0.0, 0.1],
            quaternion: [1.0, 0.0, 0.0, 0.0],
        },
        ApiRequest::LoadModel {
            path: "calibrated.yaml".into(),
        },
        ApiRequest::Subscribe { rate_hz: 20.0 },
        ApiRequest::FollowTrajectory {
            points: vec![tp],
            path_tolerance: None,
            goal_tolerance: Some([0.01; 6]),
            goal_time_tolerance: Some(0.5),
        },
        ApiRequest::FollowCartesian {
            points: vec![cp],
            path_tolerance: Some([0.1; 6]),
            goal_tolerance: None,
            goal_time_tolerance: None,
        },
        ApiRequest::Servo {
            positions: Some([0.2; 6]),
            position: None,
            quaternion: None,
        },
        ApiRequest::Jog {
            joint_velocities: None,
            tool_twist: Some([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]),
            frame: Some("tool".into()),
        },
        ApiRequest::SetSpeedScaling { fraction: 0.5 },
        ApiRequest::RecordStart {
            file: Some("run.mcap".into()),
            duration_s: Some(3.0),
        },
        ApiRequest::RecordStop {},
        ApiRequest::Acquire {},
        ApiRequest::Release {},
    ]
}

#[test]
fn every_request_round_trips_and_is_named_as_on_the_wire() {
    let all = every_request();
    assert_eq!(all.len(), ApiRequest::NAMES.len(), "one sample a request");
    for (req, name) in all.iter().zip(ApiRequest::NAMES) {
        let text = serde_json::to_string(req).unwrap();
        let back: ApiRequest = serde_json::from_str(&text).unwrap();
        assert_eq!(&back, req, "{text}");
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["cmd"], req.name(), "{text}");
        assert_eq!(req.name(), name);
        assert_eq!(ApiRequest::name_in(&text), name);
    }
    // unset options are left out, not sent as null
    let t = serde_json::to_string(&ApiRequest::Servo {
        positions: Some([0.0; 6]),
        position: None,
        quaternion: None,
    })
    .unwrap();
    assert_eq!(
        t,
        r#"{"cmd":"servo","positions":[0.0,0.0,0.0,0.0,0.0,0.0]}"#
    );
}

#[test]
fn a_line_that_does_not_parse_is_named_only_by_a_known_cmd() {
    assert_eq!(
        ApiRequest::name_in(r#"{"cmd":"move_joints","q":[1,2]}"#),
        "move_joints"
    );
    assert_eq!(ApiRequest::name_in(r#"{"cmd":"rm -rf /"}"#), "");
    assert_eq!(ApiRequest::name_in("not json"), "");
    assert!(serde_json::from_str::<ApiRequest>(r#"{"cmd":"stop","now":true}"#).is_err());
}

fn a_status() -> Status {
    Status {
        state: State::Following,
        fault: None,
        servo: Some("Control".into()),
        setpoint: [0.1; 6],
        q_motor: [0.2; 6],
        current: [0.3; 6],
        time_s: 12.5,
        tau: [1.0; 6],
        tool_position: [0.4, 0.0, 0.6],
        tool_quaternion: [1.0, 0.0, 0.0, 0.0],
        position_sigma_mm: None,
        payload_n: 44.0,
        payload_com: [0.0; 3],
        link: LinkCounters::default(),
        cycle: CycleStats::default(),
        trajectory: TrajectoryStatus {
            id: 3,
            state: TrajectoryState::Aborted,
            result: TrajectoryResult::PathToleranceViolated,
            ..Default::default()
        },
        speed_scaling: 1.0,
        stream_end: Some("servo: no setpoint within servo.deadline_ms; stopped".into()),
        leased: true,
        recording: None,
        model: Some(ModelStatus {
            file: "/var/lib/pa10d/models/extended.yaml".into(),
            kind: ModelKind::Extended,
            springs: vec![2, 3, 5],
            friction: vec![1, 2, 3, 4, 5, 6],
            discovered: vec!["gear_ratio_error[J3]".into()],
            since_s: 4.0,
        }),
        last_refusal: Some(RefusalStatus {
            request: "move_joints".into(),
            error: "joint 2 out of range".into(),
            time_s: 11.0,
        }),
        in_position: true,
    }
}

#[test]
fn every_reply_round_trips_in_its_wire_form() {
    let replies = [
        Reply::Ok(Answer::Done),
        Reply::Ok(Answer::Status(Box::new(a_status()))),
        Reply::Ok(Answer::Moving { duration_s: 1.25 }),
        Reply::Ok(Answer::Following { id: 7 }),
        Reply::Ok(Answer::Recording {
            path: "/var/lib/pa10d/x.mcap".into(),
        }),
        Reply::Refused("joint 2 out of range".into()),
    ];
    for r in replies {
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<Reply>(&text).unwrap(), r, "{text}");
    }
    assert_eq!(
        serde_json::to_string(&Reply::Ok(Answer::Done)).unwrap(),
        r#"{"ok":true}"#
    );
    let st = serde_json::to_value(Reply::Ok(Answer::Status(Box::new(a_status())))).unwrap();
    assert_eq!(st["status"]["state"], "following");
    assert_eq!(
        st["status"]["trajectory"]["result"],
        "path_tolerance_violated"
    );
    assert_eq!(serde_json::to_value(TrajectoryResult::Running).unwrap(), "");
}

#[test]
fn a_reply_that_mixes_forms_is_refused() {
    for bad in [
        r#"{"ok":true,"error":"x"}"#,
        r#"{"ok":false}"#,
        r#"{"ok":false,"error":"x","id":1}"#,
        r#"{"ok":true,"id":1,"duration_s":2.0}"#,
        r#"{"ok":true,"extra":1}"#,
        r#"{"error":"x"}"#,
    ] {
        assert!(serde_json::from_str::<Reply>(bad).is_err(), "{bad}");
    }
}

#[test]
fn the_state_names_are_the_wire_names_and_the_modes_names() {
    for s in [
        State::Starting,
        State::Holding,
        State::Moving,
        State::Following,
        State::Streaming,
        State::Stopping,
        State::Fault,
        State::Closed,
    ] {
        assert_eq!(serde_json::to_value(s).unwrap(), s.name());
    }
    for m in Mode::ALL {
        assert_eq!(State::from(m).name(), m.name());
    }
}

/// `docs/api.schema.json` is the schema these types generate; `PA10_UPDATE_SCHEMA=1 cargo
/// test --lib wire` rewrites it after a change to the protocol.
#[test]
fn the_published_schema_is_the_generated_one() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/api.schema.json");
    let generated = format!("{}\n", serde_json::to_string_pretty(&schema()).unwrap());
    if std::env::var("PA10_UPDATE_SCHEMA").is_ok_and(|v| v == "1") {
        std::fs::write(&path, &generated).unwrap();
    }
    let published = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        published == generated,
        "docs/api.schema.json is not what pa10::daemon::wire generates: run `PA10_UPDATE_SCHEMA=1 cargo test --lib wire` and commit it"
    );
}

#[test]
fn the_schema_names_every_request_and_the_reply() {
    let s = schema();
    let text = s.to_string();
    for name in ApiRequest::NAMES {
        assert!(text.contains(&format!("\"const\":\"{name}\"")), "{name}");
    }
    assert!(s["$defs"]["Status"].is_object(), "{s}");
    assert!(s["$defs"]["ApiRequest"].is_object(), "{s}");
    assert!(
        s["$defs"]["Reply"]["properties"]["ok"].is_object(),
        "the reply's wire form: {s}"
    );
}
