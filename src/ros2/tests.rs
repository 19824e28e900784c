//! The bridge's translations, message by message, without DDS.

use super::*;

/// A `follow_trajectory` request's parts: points, path and goal tolerances (rad), goal time
/// tolerance (s).
fn follow(r: ApiRequest) -> (Vec<TrajectoryPoint>, [f64; 6], [f64; 6], f64) {
    match r {
        ApiRequest::FollowTrajectory {
            points,
            path_tolerance: Some(p),
            goal_tolerance: Some(g),
            goal_time_tolerance: Some(t),
        } => (points, p, g, t),
        other => panic!("not a follow_trajectory with its tolerances: {other:?}"),
    }
}

fn names(order: [usize; 6]) -> Vec<String> {
    order.iter().map(|&j| JOINT_NAMES[j].to_string()).collect()
}

fn goal(order: [usize; 6], pts: &[([f64; 6], f64)]) -> FollowJointTrajectoryGoal {
    FollowJointTrajectoryGoal {
        trajectory: JointTrajectory {
            joint_names: names(order),
            points: pts
                .iter()
                .map(|(q, t)| JointTrajectoryPoint {
                    positions: order.iter().map(|&j| q[j]).collect(),
                    time_from_start: Duration::from_secs(*t),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        },
        ..Default::default()
    }
}

const NOW: Time = Time {
    sec: 1_800_000_000,
    nanosec: 0,
};
const Q0: [f64; 6] = [0.0, 0.4, 1.6, 0.0, 1.1, 0.0];
const Q1: [f64; 6] = [0.1, 0.5, 1.5, 0.1, 1.0, 0.2];

#[test]
fn a_moveit_goal_in_any_joint_order_becomes_the_arms_order_without_its_start_state() {
    let order = [3, 1, 5, 0, 2, 4];
    let g = goal(order, &[(Q0, 0.0), (Q1, 2.0)]);
    let (points, path, goal, goal_time) = follow(goal_request(&g, NOW, &Q0).unwrap());
    assert_eq!(points.len(), 1);
    assert_eq!(points[0].positions, Q1);
    assert_eq!(points[0].time_from_start, 2.0);
    assert_eq!(goal, [0.005; 6]);
    assert_eq!(path, [0.0; 6]);
    assert_eq!(goal_time, 1.0);
}

#[test]
fn tolerances_by_name_with_zero_default_and_minus_one_unchecked() {
    let mut g = goal([0, 1, 2, 3, 4, 5], &[(Q1, 1.5)]);
    let tol = |name: &str, p: f64| JointTolerance {
        name: name.into(),
        position: p,
        ..Default::default()
    };
    g.path_tolerance = vec![tol("pa10_joint_3", 0.05)];
    g.goal_tolerance = vec![tol("pa10_joint_2", -1.0), tol("pa10_joint_6", 0.0)];
    g.goal_time_tolerance = Duration {
        sec: 2,
        nanosec: 500_000_000,
    };
    let (_, path, goal, goal_time) = follow(goal_request(&g, NOW, &Q0).unwrap());
    assert_eq!(path, [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]);
    assert_eq!(goal, [0.005, 0.0, 0.005, 0.005, 0.005, 0.005]);
    assert_eq!(goal_time, 2.5);
}

#[test]
fn refusals_carry_the_code_and_name_what_is_wrong() {
    let ok = goal([0, 1, 2, 3, 4, 5], &[(Q1, 1.0)]);
    let check = |g: FollowJointTrajectoryGoal, code: i32, words: &str| {
        let e = goal_request(&g, NOW, &Q0).unwrap_err();
        assert_eq!(e.code, code, "{e}");
        assert!(e.message.contains(words), "{e}");
    };
    let mut g = ok.clone();
    g.trajectory.joint_names[4] = "elbow".into();
    check(g, code::INVALID_JOINTS, "unknown joint \"elbow\"");
    let mut g = ok.clone();
    g.trajectory.joint_names[4] = "pa10_joint_1".into();
    check(g, code::INVALID_JOINTS, "named twice");
    let mut g = ok.clone();
    g.trajectory.joint_names.pop();
    check(g, code::INVALID_JOINTS, "names 5 joints");
    let mut g = ok.clone();
    g.trajectory.points.clear();
    check(g, code::INVALID_GOAL, "no points");
    let mut g = ok.clone();
    g.trajectory.points[0].positions[2] = f64::NAN;
    check(g, code::INVALID_GOAL, "pa10_joint_3 is not a finite number");
    let mut g = ok.clone();
    g.trajectory.points[0].velocities = vec![0.0; 5];
    check(g, code::INVALID_GOAL, "point 0 velocities: 5 values");
    let mut g = ok.clone();
    g.trajectory.points[0].effort = vec![0.0; 6];
    check(g, code::INVALID_GOAL, "effort is not supported");
    let mut g = ok.clone();
    g.trajectory.points[0].time_from_start.nanosec = 1_000_000_000;
    check(g, code::INVALID_GOAL, "point 0: time_from_start");
    let mut g = ok.clone();
    g.multi_dof_trajectory.joint_names = vec!["base".into()];
    check(g, code::INVALID_JOINTS, "multi-DOF");
    let mut g = ok.clone();
    g.component_goal_tolerance = vec![JointComponentTolerance::default()];
    check(g, code::INVALID_GOAL, "component tolerances");
    let mut g = ok.clone();
    g.path_tolerance = vec![JointTolerance {
        name: "pa10_joint_1".into(),
        velocity: 0.1,
        ..Default::default()
    }];
    check(
        g,
        code::INVALID_GOAL,
        "velocity tolerances are not supported",
    );
    let mut g = ok.clone();
    g.goal_tolerance = vec![JointTolerance {
        name: "wrist".into(),
        ..Default::default()
    }];
    check(g, code::INVALID_JOINTS, "goal_tolerance: unknown joint");
    // a start state that is not where the arm is
    let g = goal([0, 1, 2, 3, 4, 5], &[(Q1, 0.0), (Q0, 1.0)]);
    check(
        g,
        code::INVALID_GOAL,
        "point 0 at time 0 is 0.1000 rad from the arm on pa10_joint_1",
    );
    // only a start state
    let g = goal([0, 1, 2, 3, 4, 5], &[(Q0, 0.0)]);
    check(g, code::INVALID_GOAL, "only its start state");
    // stamps: over already, or a delayed start
    let mut g = ok.clone();
    g.trajectory.header.stamp = Time {
        sec: NOW.sec - 10,
        nanosec: 0,
    };
    check(g, code::OLD_HEADER_TIMESTAMP, "ended 9.000 s ago");
    let mut g = ok.clone();
    g.trajectory.header.stamp = Time {
        sec: NOW.sec + 3,
        nanosec: 0,
    };
    check(g, code::INVALID_GOAL, "in the future");
    // a stamp of now (within the slack) starts now
    let mut g = ok;
    g.trajectory.header.stamp = NOW;
    assert!(goal_request(&g, NOW, &Q0).is_ok());
}

fn report(state: TrajectoryState, result: TrajectoryResult) -> TrajectoryStatus {
    TrajectoryStatus {
        id: 3,
        state,
        result,
        error: [0.0, -0.02, 0.001, 0.0, 0.0, 0.0],
        ..Default::default()
    }
}

#[test]
fn every_ending_has_its_status_and_code() {
    use TrajectoryResult as R;
    use TrajectoryState as S;
    assert_eq!(
        goal_result(&report(S::Executing, R::Running), false, None),
        None
    );
    let cases = [
        (
            S::Succeeded,
            R::Succeeded,
            false,
            Ending::Succeeded,
            code::SUCCESSFUL,
        ),
        (
            S::Aborted,
            R::PathToleranceViolated,
            false,
            Ending::Aborted,
            code::PATH_TOLERANCE_VIOLATED,
        ),
        (
            S::Aborted,
            R::GoalToleranceViolated,
            false,
            Ending::Aborted,
            code::GOAL_TOLERANCE_VIOLATED,
        ),
        (
            S::Aborted,
            R::Stopped,
            true,
            Ending::Canceled,
            code::SUCCESSFUL,
        ),
        (
            S::Aborted,
            R::Stopped,
            false,
            Ending::Aborted,
            code::INVALID_GOAL,
        ),
        (
            S::Preempted,
            R::Preempted,
            false,
            Ending::Canceled,
            code::INVALID_GOAL,
        ),
        (
            S::Aborted,
            R::Fault,
            false,
            Ending::Aborted,
            code::INVALID_GOAL,
        ),
    ];
    for (state, why, canceling, ending, c) in cases {
        let (e, r) = goal_result(&report(state, why), canceling, Some("watchdog")).unwrap();
        assert_eq!((e, r.error_code), (ending, c), "{state:?}/{why:?}");
    }
    let (_, r) = goal_result(&report(S::Aborted, R::PathToleranceViolated), false, None).unwrap();
    assert!(
        r.error_string.contains("pa10_joint_2: error -0.02000 rad"),
        "{r:?}"
    );
    let (_, r) = goal_result(&report(S::Aborted, R::Fault), false, Some("watchdog")).unwrap();
    assert!(r.error_string.contains("watchdog"), "{r:?}");
}

/// A status with `state`, `fault` and the wake-up jitter p50 / p99 / max (µs).
fn status(state: State, fault: Option<&str>, jitter_us: [f64; 3]) -> Status {
    Status {
        state,
        fault: fault.map(str::to_owned),
        servo: None,
        setpoint: [0.0; 6],
        q_motor: [0.0; 6],
        current: [0.0; 6],
        time_s: 0.0,
        tau: [0.0; 6],
        tool_position: [0.0; 3],
        tool_quaternion: [1.0, 0.0, 0.0, 0.0],
        position_sigma_mm: None,
        payload_n: 0.0,
        payload_com: [0.0; 3],
        link: Default::default(),
        cycle: crate::daemon::timing::CycleStats {
            cycles: 10,
            jitter_us,
            ..Default::default()
        },
        trajectory: Default::default(),
        speed_scaling: 1.0,
        stream_end: None,
        leased: false,
        recording: None,
        model: None,
        last_refusal: None,
        in_position: true,
    }
}

#[test]
fn diagnostics_rate_the_daemon() {
    let d = diagnostics(&status(State::Holding, None, [50.0, 100.0, 300.0]), NOW);
    assert_eq!(d.status[0].level, level::OK);
    assert!(
        d.status[0]
            .values
            .iter()
            .any(|kv| kv.key == "cycles" && kv.value == "10")
    );
    let st = status(State::Fault, Some("servo controller: watchdog"), [0.0; 3]);
    let d = diagnostics(&st, NOW);
    assert_eq!(d.status[0].level, level::ERROR);
    assert!(d.status[0].message.contains("watchdog"));
    let st = status(State::Holding, None, [50.0, 900.0, 3000.0]);
    assert_eq!(diagnostics(&st, NOW).status[0].level, level::WARN);
    let st = status(State::Starting, None, [0.0; 3]);
    assert_eq!(diagnostics(&st, NOW).status[0].level, level::WARN);
}

#[test]
fn a_goal_too_long_for_one_request_line_is_refused_by_its_size() {
    // a MoveIt-like plan: positions, velocities and accelerations on every point
    let plan = |n: usize| {
        let mut g = goal(
            [0, 1, 2, 3, 4, 5],
            &(1..=n)
                .map(|i| {
                    let s = i as f64 / n as f64;
                    (
                        std::array::from_fn(|j| Q0[j] + 0.3 * s + 1e-7 / 3.0),
                        0.01 * i as f64,
                    )
                })
                .collect::<Vec<_>>(),
        );
        for p in &mut g.trajectory.points {
            p.velocities = vec![0.123_456_789_123; 6];
            p.accelerations = vec![-0.987_654_321_987; 6];
        }
        g
    };
    let r = goal_request(&plan(200), NOW, &Q0).unwrap();
    assert!(serde_json::to_vec(&r).unwrap().len() < MAX_LINE_BYTES);
    // sent to 1e-9
    assert_eq!(follow(r).0[0].velocities.unwrap()[0], 0.123_456_789);
    let e = goal_request(&plan(MAX_POINTS + 1), NOW, &Q0).unwrap_err();
    assert_eq!(e.code, code::INVALID_GOAL);
    assert!(
        e.message
            .contains("2001 points: pa10d follows at most 2000"),
        "{e}"
    );
    let e = goal_request(&plan(2000), NOW, &Q0).unwrap_err();
    assert_eq!(e.code, code::INVALID_GOAL);
    assert!(e.message.contains("2000 points make a"), "{e}");
    assert!(e.message.contains("send fewer points"), "{e}");
    eprintln!("{e}");
}

#[test]
fn times_and_durations_round_trip() {
    let t = Time::from_secs(1_800_000_000.25);
    assert_eq!((t.sec, t.nanosec), (1_800_000_000, 250_000_000));
    assert!((Duration::from_secs(2.5).secs().unwrap() - 2.5).abs() < 1e-12);
}
