//! The core's command handling: refusals before the controller answers, the motion lease,
//! the shutdown of a session that never started, and a move planned on a stale basis — the
//! core alone, or in lockstep with the simulated servo controller.

use super::*;
use crate::daemon::control::Stream;
use crate::daemon::plan::Move;
use crate::daemon::runtime::lock;
use crate::model::Frame;
use crate::sim::rig::{HOME, Lockstep};
use crate::sim::servo::{ServoConfig, ServoSim};
use crate::sim::{SimNoise, TrueRobot};

const PERIOD: f64 = 0.002;

fn core() -> Core {
    let mut params = LoopParams {
        torque_constants: ServoConfig::default().torque_constants,
        following_error: 0.05,
        ..crate::daemon::control::test_params()
    };
    params.limits.speed = [0.5; 6];
    params.limits.acceleration = [1.0; 6];
    Core::new(Model::nominal(), params, LinkConfig::new(PERIOD, 10), 0.5)
}

const PAYLOAD: Command = Command::SetPayload {
    newtons: 20.0,
    com: [0.0, 0.0, 0.1],
};

#[test]
fn before_the_controller_answers_motion_is_refused_and_settings_are_kept() {
    let mut c = core();
    assert!(!c.is_ready());
    assert!(matches!(
        c.submit(Command::Stream(Stream::Jog([0.0; 6]))),
        Err(CommandError::NotReady(_))
    ));
    assert!(c.plan_basis().is_err());
    // a payload is kept for the controller to come; a bad one changes nothing
    c.submit(PAYLOAD).expect("payload");
    assert_eq!(c.params.payload_n, 20.0);
    let bad = Command::SetPayload {
        newtons: -1.0,
        com: [0.0; 3],
    };
    assert!(c.submit(bad).is_err());
    assert_eq!(c.params.payload_n, 20.0);
}

#[test]
fn the_lease_admits_only_its_holder_but_a_stop_from_anyone() {
    let mut c = core();
    c.submit_from(1, Command::Acquire).expect("acquire");
    assert_eq!(c.lease(), Some(1));
    assert_eq!(
        c.submit_from(2, Command::Acquire),
        Err(CommandError::Leased)
    );
    assert_eq!(c.submit_from(2, PAYLOAD), Err(CommandError::Leased));
    assert_eq!(c.params.payload_n, 0.0, "a refusal changes nothing");
    c.submit_from(2, Command::Stop)
        .expect("a stop is always taken");
    // only the holder gives it back (a disconnect counts)
    c.submit_from(2, Command::Release).expect("release");
    assert_eq!(c.lease(), Some(1));
    c.submit_from(1, Command::Disconnected).expect("disconnect");
    assert_eq!(c.lease(), None);
    c.submit_from(2, PAYLOAD).expect("free again");
}

#[test]
fn a_shutdown_before_the_session_closes_the_link() {
    let mut c = core();
    c.start(0.0);
    assert!(!c.is_closed());
    c.submit(Command::Shutdown).expect("shutdown");
    assert!(c.is_closed());
}

#[test]
fn a_move_planned_before_the_model_changed_is_refused_as_stale() {
    let truth = TrueRobot::draw(
        1,
        &Model::nominal(),
        &Frame::identity(),
        SimNoise::default(),
    )
    .expect("truth");
    let servo = ServoSim::new(truth, ServoConfig::default(), HOME, 1);
    let mut ls = Lockstep::new(core(), servo);
    ls.run_until_ready(1.0).expect("ready");
    ls.run_for(0.05);
    let (mv, to) = {
        let mut c = lock(&ls.core);
        let basis = c.plan_basis().expect("basis");
        let mut to = basis.from;
        to[0] += 0.1;
        let mv = Move::joints(basis.from, to, &basis.limits).expect("plan");
        // another model arrives between planning and starting
        c.submit(Command::LoadModel {
            model: Arc::new(Model::nominal()),
            file: "nominal".into(),
        })
        .expect("load while holding");
        let stale = Command::Start {
            mv: Box::new(mv.clone()),
            basis,
        };
        assert_eq!(c.submit(stale), Err(CommandError::Stale));
        assert!(matches!(
            c.controller().expect("ready").activity(),
            Activity::Holding
        ));
        let basis = c.plan_basis().expect("basis");
        c.submit(Command::Start {
            mv: Box::new(mv.clone()),
            basis,
        })
        .expect("start on a fresh basis");
        assert!(matches!(
            c.controller().expect("ready").activity(),
            Activity::Moving { .. }
        ));
        // a model cannot be swapped under a running move
        assert_eq!(
            c.submit(Command::LoadModel {
                model: Arc::new(Model::nominal()),
                file: "nominal".into()
            }),
            Err(CommandError::ModelDuringMove)
        );
        (mv, to)
    };
    ls.run_for(mv.duration() + 0.2);
    let c = lock(&ls.core);
    let ctl = c.controller().expect("ready");
    assert!(
        matches!(ctl.activity(), Activity::Holding),
        "{:?}",
        ctl.activity()
    );
    assert_eq!(
        ctl.setpoint().q,
        to,
        "the move ended where it was planned to"
    );
}

#[test]
fn the_model_status_says_what_the_model_holds() {
    use crate::daemon::wire::ModelKind;
    use crate::model::{EffectRecord, Stiffness};
    let nominal = Model::nominal();
    let s = status::model_status(&nominal, "nominal.yaml", 0.0);
    assert_eq!(s.kind, ModelKind::Nominal);
    let mut d = nominal.data().clone();
    d.departures[2].da = 1e-4;
    d.stiffness[1] = Some(Stiffness {
        klin: 5e4,
        kcub: 0.0,
    });
    let calibrated = Model::new(d.clone()).unwrap();
    let s = status::model_status(&calibrated, "cal.yaml", 3.5);
    assert_eq!(
        (s.kind, s.springs.as_slice()),
        (ModelKind::Calibrated, &[2u8][..])
    );
    assert_eq!((s.file.as_str(), s.since_s), ("cal.yaml", 3.5));
    d.discovered.push(EffectRecord {
        name: "thermal_expansion".into(),
        joint: None,
        params: Default::default(),
        stderr: Default::default(),
        compensated: false,
    });
    d.discovered.push(EffectRecord {
        name: "gear_ratio_error".into(),
        joint: Some(3),
        params: Default::default(),
        stderr: Default::default(),
        compensated: true,
    });
    let extended = Model::new(d).unwrap();
    let s = status::model_status(&extended, "ext.yaml", 9.0);
    assert_eq!(s.kind, ModelKind::Extended);
    assert_eq!(s.discovered, ["thermal_expansion", "gear_ratio_error[J3]"]);
}
