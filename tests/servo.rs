//! The simulated servo controller over the virtual bus: the protocol's state machine, the
//! watchdog, motion, feedback against the hidden truth, and injected faults. Time is tokio's
//! paused clock, so every test is deterministic and instant.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use pa10::can::bus::{BusError, BusEvent, CanBus};
use pa10::can::protocol::{
    self, ANGLE_LSB, AxisCommand, CanFrame, ErrorCode, FaultCode, Feedback, Message, Request,
    ServoState, status,
};
use pa10::can::{VirtualBus, VirtualConfig, VirtualEndpoint};
use pa10::model::Model;
use pa10::sim::servo::{self, ServoConfig, ServoSim, SharedServo};
use pa10::sim::{SimNoise, TrueRobot};
use tokio::sync::watch;

const Q0: [f64; 6] = [0.1, 0.5, 1.2, 0.0, 0.8, 0.0];

struct Rig {
    host: VirtualEndpoint,
    bus: VirtualBus,
    sim: SharedServo,
    _stop: watch::Sender<bool>,
    cycle: u16,
}

fn truth() -> TrueRobot {
    let tool = pa10::model::frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0]);
    TrueRobot::draw(11, &Model::nominal(), &tool, SimNoise::default()).unwrap()
}

fn rig(cfg: ServoConfig) -> Rig {
    let bus = VirtualBus::new(VirtualConfig::default());
    let host = bus.endpoint(false);
    let sim = Arc::new(Mutex::new(ServoSim::new(truth(), cfg, Q0, 3)));
    let (tx, rx) = watch::channel(false);
    tokio::spawn(servo::run(
        bus.endpoint(false),
        sim.clone(),
        Duration::from_millis(1),
        rx,
        |_, _| {},
    ));
    Rig {
        host,
        bus,
        sim,
        _stop: tx,
        cycle: 0,
    }
}

impl Rig {
    async fn send(&mut self, m: Message) {
        self.host.send(protocol::encode(&m).unwrap()).await.unwrap();
    }

    /// Next message of the wanted kind (skipping heartbeats etc.), or None after `ms`.
    async fn next<T>(&mut self, ms: u64, pick: impl Fn(Message) -> Option<T>) -> Option<T> {
        let deadline = tokio::time::Instant::now() + Duration::from_millis(ms);
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            match self.host.recv(left).await {
                Ok(BusEvent::Frame(f)) => {
                    if let Some(t) = protocol::decode(&f).ok().and_then(&pick) {
                        return Some(t);
                    }
                }
                Ok(_) => {}
                Err(_) => return None,
            }
        }
    }

    async fn control(&mut self, r: Request) -> (ServoState, FaultCode) {
        self.send(Message::Control {
            request: r,
            watchdog_ms: 0,
        })
        .await;
        self.next(20, |m| {
            if let Message::State { state, fault, .. } = m {
                Some((state, fault))
            } else {
                None
            }
        })
        .await
        .unwrap()
    }

    /// One 2 ms cycle: SYNC, read the six feedback frames, answer with six speed commands.
    async fn cycle(&mut self, speeds: [f64; 6]) -> [Option<Feedback>; 6] {
        self.cycle = self.cycle.wrapping_add(1);
        let c = self.cycle;
        self.send(Message::Sync { cycle: c }).await;
        let mut fb = [None; 6];
        for _ in 0..6 {
            match self
                .next(1, |m| {
                    if let Message::Feedback(f) = m {
                        Some(f)
                    } else {
                        None
                    }
                })
                .await
            {
                Some(f) => fb[f.axis as usize - 1] = Some(f),
                None => break,
            }
        }
        for (j, s) in speeds.iter().enumerate() {
            self.send(Message::Command(
                AxisCommand::speed(j as u8 + 1, c as u8, *s).unwrap(),
            ))
            .await;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
        fb
    }

    async fn start(&mut self) {
        assert_eq!(
            self.control(Request::ReleaseBrakes).await,
            (ServoState::BrakeRelease, FaultCode::None)
        );
        assert_eq!(
            self.control(Request::StartControl).await,
            (ServoState::Control, FaultCode::None)
        );
    }
}

#[tokio::test(start_paused = true)]
async fn the_state_machine_follows_the_protocol() {
    let mut r = rig(ServoConfig::default());
    // power-on: STOPPED, feedback answers SYNC, brakes on
    let fb = r.cycle([0.0; 6]).await;
    assert!(
        fb.iter()
            .all(|f| f.is_some_and(|f| f.status & status::BRAKE_ON != 0))
    );
    // START_CONTROL before the brakes are released is refused, state unchanged
    assert_eq!(
        r.control(Request::StartControl).await,
        (ServoState::Stopped, FaultCode::Rejected)
    );
    r.start().await;
    for _ in 0..20 {
        let fb = r.cycle([0.0; 6]).await;
        assert!(
            fb.iter()
                .all(|f| f.is_some_and(|f| f.status & status::SERVO_ON != 0))
        );
    }
    // STOP: controlled deceleration, then STOPPED with brakes on
    r.send(Message::Control {
        request: Request::Stop,
        watchdog_ms: 0,
    })
    .await;
    let stopped = r
        .next(500, |m| {
            matches!(
                m,
                Message::State {
                    state: ServoState::Stopped,
                    ..
                }
            )
            .then_some(())
        })
        .await;
    assert!(stopped.is_some());
    // ESTOP from anywhere; RESET_FAULT only from FAULT
    assert_eq!(r.control(Request::ResetFault).await.1, FaultCode::Rejected);
    r.start().await;
    assert_eq!(
        r.control(Request::Estop).await,
        (ServoState::Stopped, FaultCode::None)
    );
    assert_eq!(r.sim.lock().unwrap().state(), ServoState::Stopped);
}

#[tokio::test(start_paused = true)]
async fn the_watchdog_stops_the_servo_when_commands_stop() {
    let mut r = rig(ServoConfig::default());
    r.start().await;
    for _ in 0..50 {
        r.cycle([0.2, 0.0, 0.0, 0.0, 0.0, 0.0]).await;
    }
    // the host dies: no more commands
    let err = r
        .next(200, |m| {
            if let Message::Error { code, .. } = m {
                Some(code)
            } else {
                None
            }
        })
        .await;
    assert_eq!(err, Some(ErrorCode::Watchdog));
    let s = r
        .next(200, |m| {
            if let Message::State { state, fault, .. } = m {
                Some((state, fault))
            } else {
                None
            }
        })
        .await;
    assert_eq!(s, Some((ServoState::Fault, FaultCode::Watchdog)));
    let before = r.sim.lock().unwrap().motor_angles();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(
        r.sim.lock().unwrap().motor_angles(),
        before,
        "the arm stands still"
    );
    let fb = r.cycle([0.0; 6]).await;
    assert!(
        fb[0].unwrap().status & (status::FAULT | status::WATCHDOG | status::BRAKE_ON)
            == status::FAULT | status::WATCHDOG | status::BRAKE_ON
    );
    assert_eq!(
        r.control(Request::ResetFault).await,
        (ServoState::Stopped, FaultCode::None)
    );
}

#[tokio::test(start_paused = true)]
async fn a_speed_command_moves_the_motor_by_the_expected_angle_and_feedback_matches_truth() {
    let mut r = rig(ServoConfig {
        resolver_noise_counts: 0.0,
        current_noise_a: 0.0,
        ..Default::default()
    });
    r.start().await;
    let first = r.cycle([0.0; 6]).await;
    let a0 = first[0].unwrap().angle_rad();
    // 0.1 rad/s on J1 for 500 cycles of 2 ms = 1 s → 0.1 rad, less the 5 ms velocity lag
    for _ in 0..500 {
        r.cycle([0.1, 0.0, 0.0, 0.0, 0.0, -0.05]).await;
    }
    // let the velocity loop settle, then compare a snapshot with the truth
    for _ in 0..50 {
        r.cycle([0.0; 6]).await;
    }
    let fb = r.cycle([0.0; 6]).await;
    let moved = fb[0].unwrap().angle_rad() - a0;
    assert!((moved - 0.1).abs() < 0.001, "moved {moved} rad");
    assert!((fb[5].unwrap().angle_rad() - first[5].unwrap().angle_rad() + 0.05).abs() < 0.002);
    // feedback = true motor angle + the resolver's repeatable error, within quantisation
    let s = r.sim.lock().unwrap();
    let motor = s.motor_angles();
    for (j, f) in fb.iter().enumerate() {
        let f = f.unwrap();
        let want = s.truth().resolver_reading(j, motor[j]);
        assert!(
            (f.angle_rad() - want).abs() <= 0.5 * ANGLE_LSB + 1e-4 * 2e-3,
            "J{}: {} vs {want}",
            j + 1,
            f.angle_rad()
        );
        // current = true torque / Kt (±1 mA quantisation)
        let (_, tau) = s.link_state();
        assert!(
            (f.current_a() - tau[j] / servo::SIM_TORQUE_CONSTANTS[j]).abs() < 0.002,
            "J{}",
            j + 1
        );
    }
}

#[tokio::test(start_paused = true)]
async fn injected_faults_show_up_as_the_protocol_says() {
    let mut r = rig(ServoConfig {
        resolver_noise_counts: 0.0,
        current_noise_a: 0.0,
        ..Default::default()
    });
    let base = r.cycle([0.0; 6]).await;
    // an axis stops answering
    r.sim.lock().unwrap().injected.mute_axis = Some(3);
    let fb = r.cycle([0.0; 6]).await;
    assert!(fb[2].is_none() && fb[1].is_some() && fb[3].is_some());
    r.sim.lock().unwrap().injected.mute_axis = None;
    // a current-sensor offset
    r.sim.lock().unwrap().injected.current_offset_a[1] = 0.5;
    let fb = r.cycle([0.0; 6]).await;
    assert!((fb[1].unwrap().current_a() - base[1].unwrap().current_a() - 0.5).abs() < 0.002);
    // a resolver glitch: one reading jumps, the next is back
    r.sim.lock().unwrap().injected.resolver_glitch = Some((5, 4000));
    let g = r.cycle([0.0; 6]).await;
    assert_eq!(g[4].unwrap().angle - base[4].unwrap().angle, 4000);
    let back = r.cycle([0.0; 6]).await;
    assert_eq!(back[4].unwrap().angle, base[4].unwrap().angle);
    // frames lost on the bus: the feedback set is incomplete, the host sees it
    r.bus.set_config(VirtualConfig {
        loss: 1.0,
        ..Default::default()
    });
    let lost = r.cycle([0.0; 6]).await;
    assert!(lost.iter().all(Option::is_none));
    r.bus.set_config(VirtualConfig::default());
    // bus-off: the host sees it, and cannot send
    r.start().await;
    r.bus.set_bus_off(true);
    assert_eq!(
        r.host.recv(Duration::from_millis(5)).await,
        Ok(BusEvent::BusOff)
    );
    assert_eq!(
        r.host.send(CanFrame::new(0x080, &[0, 0]).unwrap()).await,
        Err(BusError::BusOff)
    );
    // … and the controller, no longer commanded, trips its watchdog
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(r.sim.lock().unwrap().state(), ServoState::Fault);
    assert_eq!(r.sim.lock().unwrap().fault(), FaultCode::Watchdog);
}

#[tokio::test(start_paused = true)]
async fn delayed_frames_arrive_late_but_complete() {
    // tokio's timer resolves 1 ms, so the virtual bus's latency does too
    let mut r = rig(ServoConfig::default());
    r.bus.set_config(VirtualConfig {
        latency: Duration::from_millis(1),
        ..Default::default()
    });
    let t0 = tokio::time::Instant::now();
    r.send(Message::Sync { cycle: 1 }).await;
    let mut got = 0;
    while let Some(f) = r
        .next(5, |m| {
            if let Message::Feedback(f) = m {
                Some(f)
            } else {
                None
            }
        })
        .await
    {
        assert_eq!(f.cycle, 1);
        got += 1;
        if got == 6 {
            break;
        }
    }
    assert_eq!(got, 6);
    assert!(
        tokio::time::Instant::now() - t0 >= Duration::from_millis(2),
        "two hops of 1 ms"
    );
}

#[tokio::test(start_paused = true)]
async fn traffic_logs_as_candump_and_replays_identically() {
    let bus = VirtualBus::new(VirtualConfig::default());
    let mut host = bus.endpoint(false);
    let mut listener = bus.endpoint(false);
    let sim = Arc::new(Mutex::new(ServoSim::new(
        truth(),
        ServoConfig::default(),
        Q0,
        3,
    )));
    let (_tx, rx) = watch::channel(false);
    let log = Arc::new(Mutex::new(pa10::can::candump::Logger::new(
        Vec::new(),
        "vcan0",
    )));
    let l2 = log.clone();
    tokio::spawn(servo::run(
        bus.endpoint(false),
        sim,
        Duration::from_millis(1),
        rx,
        move |t, f| {
            l2.lock().unwrap().log(t, f).unwrap();
        },
    ));
    host.send(protocol::encode(&Message::Sync { cycle: 7 }).unwrap())
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(5)).await;
    let text = String::from_utf8(std::mem::take(log.lock().unwrap().out_mut())).unwrap();
    // SYNC in, six FEEDBACK out (plus a heartbeat perhaps)
    let entries: Vec<_> = text
        .lines()
        .map(|l| pa10::can::candump::LoggedFrame::parse(l).unwrap())
        .collect();
    assert!(entries.len() >= 7, "{text}");
    assert_eq!(entries[0].frame.id(), 0x080);
    assert!(
        entries
            .iter()
            .filter(|e| (0x181..=0x186).contains(&e.frame.id()))
            .count()
            == 6
    );
    // drain what the listener heard live, then replay the log and hear the same frames
    let mut live = Vec::new();
    while let Ok(BusEvent::Frame(f)) = listener.recv(Duration::from_millis(1)).await {
        live.push(f);
    }
    let bus2 = VirtualBus::new(VirtualConfig::default());
    let mut player = bus2.endpoint(false);
    let mut ear = bus2.endpoint(false);
    let n = pa10::can::candump::replay(&mut player, &entries)
        .await
        .unwrap();
    assert_eq!(n, entries.len());
    let mut heard = Vec::new();
    while let Ok(BusEvent::Frame(f)) = ear.recv(Duration::from_millis(2)).await {
        heard.push(f);
    }
    assert_eq!(heard, entries.iter().map(|e| e.frame).collect::<Vec<_>>());
    assert_eq!(heard, live, "the replay sounds like the live traffic");
}
