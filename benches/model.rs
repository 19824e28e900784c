//! Criterion benchmarks of the model's per-cycle and per-evaluation functions.
//!
//! `cargo bench --bench model`; medians are recorded in BENCHMARKS.md. The "calibrated"
//! model has departures on every joint, the seed paper's stiffness on J2, J3, J5 and a
//! 0.35 m tool, so nothing is skipped that a real calibrated model exercises.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use pa10::model::{ExternalLoad, Model, NO_DIRECTION, Stiffness, Torques};

fn calibrated() -> Model {
    let mut d = Model::nominal().data().clone();
    for (j, e) in d.departures.iter_mut().enumerate() {
        let s = (j as f64 + 1.0) * 1e-4;
        e.da = s;
        e.dalpha = -s;
        if j == 1 {
            e.dbeta = 2.0 * s;
        } else {
            e.dd = -s;
        }
        e.dtheta = s * 0.5;
    }
    d.stiffness[1] = Some(Stiffness {
        klin: 1.98e4,
        kcub: 3.35e7,
    });
    d.stiffness[2] = Some(Stiffness {
        klin: 1.27e4,
        kcub: 1.46e7,
    });
    d.stiffness[4] = Some(Stiffness {
        klin: 2.56e3,
        kcub: 3.83e7,
    });
    d.tool.translation = [0.0, 0.0, 0.35];
    Model::new(d).expect("valid benchmark model")
}

fn bench(c: &mut Criterion) {
    let m = calibrated();
    let q = [0.3, 0.6, 1.2, -0.4, 0.9, 0.2];
    let tau = [0.5, -95.0, -30.0, 0.2, -4.0, 0.01];
    let load = ExternalLoad::hung(44.0, &m.gravity());
    c.bench_function("fk", |b| b.iter(|| m.fk(black_box(&q))));
    c.bench_function("jacobian", |b| b.iter(|| m.jacobian(black_box(&q))));
    c.bench_function("static_torques", |b| {
        b.iter(|| m.static_torques(black_box(&q), black_box(&load)))
    });
    c.bench_function("compensate (measured torques)", |b| {
        b.iter(|| {
            m.compensate(
                black_box(&q),
                Torques::Given(black_box(&tau)),
                &NO_DIRECTION,
            )
        })
    });
    c.bench_function("compensate (gravity + 44 N)", |b| {
        b.iter(|| {
            m.compensate(
                black_box(&q),
                Torques::Gravity(black_box(&load)),
                &NO_DIRECTION,
            )
        })
    });
    c.bench_function("identification_jacobian", |b| {
        b.iter(|| m.identification_jacobian(black_box(&q), black_box(&tau)))
    });
    let target = m.fk(&q);
    c.bench_function("ik (all branches, refined)", |b| {
        b.iter(|| m.ik(black_box(&target), black_box(&q)))
    });

    // One control cycle of the daemon (sans IO): torque estimate, compensation, position loop,
    // safety checks — holding, and following a Cartesian move (IK per setpoint).
    use pa10::daemon::config::TorqueSource;
    use pa10::daemon::control::{Controller, JointState, LoopParams};
    use pa10::daemon::plan::{Limits, Move};
    let params = LoopParams {
        period_s: 0.002,
        gain: 20.0,
        torque_source: TorqueSource::Measured,
        filter_hz: 20.0,
        hold_deadband: 4e-5,
        hold_damping: 1.0,
        gain_inertia_kgm2: Some(8.5),
        torque_constants: [15.0, 30.0, 15.0, 5.0, 5.0, 2.0],
        payload_n: 44.0,
        payload_com: [0.0; 3],
        // the position limits are the model's (the controller takes them)
        limits: Limits {
            lower: [f64::NEG_INFINITY; 6],
            upper: [f64::INFINITY; 6],
            speed: [0.5, 0.5, 1.0, 2.0, 2.0, 2.0],
            acceleration: [1.0, 1.0, 2.0, 4.0, 4.0, 4.0],
            min_ramp_s: 0.0,
        },
        following_error: 0.05,
        feedback_timeout_s: 1e9,
        stream_deadline_s: 1e9,
    };
    let js = JointState {
        q_motor: q,
        current: [0.0, -3.0, -1.5, 0.0, -0.4, 0.0],
        stamp_s: 0.0,
        controller_fault: false,
    };
    let mut hold = Controller::new(m.clone(), params.clone(), &js);
    c.bench_function("control cycle (holding)", |b| {
        b.iter(|| hold.step(black_box(0.0), Some(black_box(&js))))
    });
    let mut moving = Controller::new(m.clone(), params, &js);
    let mut goal = target;
    goal.translation.vector += nalgebra::Vector3::new(0.05, 0.05, 0.0);
    let mv = Move::cartesian(&m, moving.setpoint().q, goal, moving.limits()).expect("path");
    moving.start_move(mv, 0.0).expect("start");
    c.bench_function("control cycle (Cartesian move, IK per setpoint)", |b| {
        b.iter(|| moving.step(black_box(0.01), Some(black_box(&js))))
    });
    // trajectories: planning 50 points (under the control lock), sampling one (per cycle)
    use pa10::daemon::control::{Stream, Tolerances};
    use pa10::daemon::plan::{Trajectory, TrajectoryPoint};
    let start = *hold.setpoint();
    let points: Vec<TrajectoryPoint> = (1..=50)
        .map(|i| {
            let k = i as f64;
            TrajectoryPoint {
                positions: std::array::from_fn(|j| start.q[j] + 0.2 * (0.3 * k + j as f64).sin()),
                velocities: None,
                accelerations: None,
                time_from_start: 2.0 * k,
            }
        })
        .collect();
    let lim = *hold.limits();
    c.bench_function("trajectory plan + check (50 points, clamped spline)", |b| {
        b.iter(|| Trajectory::plan(black_box(&start), black_box(&points), &lim, 1.0).expect("plan"))
    });
    let traj = Trajectory::plan(&start, &points, &lim, 1.0).expect("plan");
    let mut tau = 0.0;
    c.bench_function("trajectory sample (50 points)", |b| {
        b.iter(|| {
            tau = (tau + 0.002) % 100.0;
            traj.sample(black_box(tau))
        })
    });
    let mut following = Controller::new(m.clone(), params_for_bench(&hold), &js);
    // the same path, 1000× slower: it lasts longer than the bench runs
    let slow: Vec<TrajectoryPoint> = points
        .iter()
        .map(|p| TrajectoryPoint {
            time_from_start: p.time_from_start * 1000.0,
            ..*p
        })
        .collect();
    following
        .start_trajectory(&slow, Tolerances::default())
        .expect("trajectory");
    c.bench_function("control cycle (following a trajectory)", |b| {
        b.iter(|| following.step(black_box(0.01), Some(black_box(&js))))
    });
    assert_eq!(
        following.trajectory().state,
        pa10::daemon::control::TrajectoryState::Executing
    );
    let mut servo = Controller::new(m.clone(), params_for_bench(&hold), &js);
    let mut target = start.q;
    target[0] += 0.3;
    servo.stream(Stream::Servo(target), 0.0).expect("servo");
    c.bench_function("control cycle (servo stream)", |b| {
        b.iter(|| servo.step(black_box(0.01), Some(black_box(&js))))
    });
    assert!(matches!(
        servo.activity(),
        pa10::daemon::control::Activity::Streaming { .. }
    ));
}

/// The loop parameters of `c` with no following-error limit (the bench's feedback stands
/// still while the setpoint moves; a fault would measure nothing).
fn params_for_bench(c: &pa10::daemon::control::Controller) -> pa10::daemon::control::LoopParams {
    pa10::daemon::control::LoopParams {
        following_error: 1e9,
        ..c.params().clone()
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
