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
    use pa10::daemon::motion::Move;
    let params = LoopParams {
        period_s: 0.002,
        gain: 20.0,
        torque_source: TorqueSource::Measured,
        filter_hz: 20.0,
        torque_constants: [15.0, 30.0, 15.0, 5.0, 5.0, 2.0],
        payload_n: 44.0,
        speed: [0.5, 0.5, 1.0, 2.0, 2.0, 2.0],
        acceleration: [1.0, 1.0, 2.0, 4.0, 4.0, 4.0],
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
    let v = [0.5, 0.5, 1.0, 2.0, 2.0, 2.0];
    let a = [1.0, 1.0, 2.0, 4.0, 4.0, 4.0];
    let mv = Move::cartesian(&m, moving.setpoint().q, goal, &v, &a).expect("path");
    moving.start_move(mv, 0.0).expect("start");
    c.bench_function("control cycle (Cartesian move, IK per setpoint)", |b| {
        b.iter(|| moving.step(black_box(0.01), Some(black_box(&js))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
