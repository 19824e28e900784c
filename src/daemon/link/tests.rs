//! The link's session and cycle assembly, driven frame by frame in simulated time.

use super::*;
use crate::can::protocol::{FaultCode, Feedback, mode, status};
use rand::{RngExt, SeedableRng};

const PERIOD: f64 = 0.002;

fn fb(axis: u8, cycle: u8, angle: i32) -> CanFrame {
    protocol::encode(&Message::Feedback(Feedback {
        axis,
        angle,
        current: 100,
        status: status::SERVO_ON,
        cycle,
    }))
    .unwrap()
}

fn state(s: ServoState) -> CanFrame {
    protocol::encode(&Message::State {
        state: s,
        fault: FaultCode::None,
        cycle: 0,
    })
    .unwrap()
}

fn sent(l: &mut Link) -> Vec<Message> {
    std::iter::from_fn(|| l.poll_transmit())
        .map(|f| protocol::decode(&f).unwrap())
        .collect()
}

fn control(r: Request) -> Message {
    Message::Control {
        request: r,
        watchdog_ms: 50,
    }
}

/// A link through the handshake to its first cycle, at t = 0.1 s.
fn connected() -> Link {
    let mut l = Link::new(LinkConfig::new(PERIOD, 50));
    l.connect(0.0);
    assert!(
        sent(&mut l).is_empty(),
        "nothing is sent before the controller is heard"
    );
    assert_eq!(l.handle(&state(ServoState::Stopped), 0.05), None);
    assert_eq!(sent(&mut l), [control(Request::ReleaseBrakes)]);
    l.handle(&state(ServoState::BrakeRelease), 0.06);
    assert_eq!(sent(&mut l), [control(Request::StartControl)]);
    l.handle(&state(ServoState::Control), 0.07);
    assert_eq!(sent(&mut l), [Message::Sync { cycle: 1 }]);
    for axis in 1..=5 {
        assert_eq!(l.handle(&fb(axis, 1, 0), 0.0701), None);
    }
    let Some(LinkEvent::Connected(js)) = l.handle(&fb(6, 1, 6000), 0.0702) else {
        panic!("not connected")
    };
    assert_eq!(js.stamp_s, 0.07);
    assert!((js.q_motor[5] - 6000.0 * protocol::ANGLE_LSB).abs() < 1e-15);
    let zero = sent(&mut l);
    assert_eq!(zero.len(), 6, "zero-speed commands feed the watchdog");
    assert!(l.is_running());
    l
}

#[test]
fn the_session_starts_with_the_handshake_and_then_cycles_on_time() {
    let mut l = connected();
    let t = l.poll_timeout().unwrap();
    assert!((t - 0.0722).abs() < 1e-12, "{t}");
    assert!(!l.expects_frames(), "between cycles the caller may sleep");
    assert_eq!(l.handle_timeout(t + 1e-4), None);
    let timing = l.take_timing().unwrap();
    assert!((timing.late_s - 1e-4).abs() < 1e-12 && !timing.overrun);
    assert_eq!(sent(&mut l), [Message::Sync { cycle: 2 }]);
    assert!(l.expects_frames());
    for axis in 1..=5 {
        l.handle(&fb(axis, 2, 0), t + 2e-4);
    }
    assert!(
        l.handle(&fb(6, 1, 0), t + 2e-4).is_none(),
        "another cycle's frame"
    );
    let Some(LinkEvent::Cycle { stamp_s, feedback }) = l.handle(&fb(6, 2, 0), t + 3e-4) else {
        panic!()
    };
    assert_eq!(stamp_s, t + 1e-4);
    assert!(feedback.is_some());
    l.send_commands(&[0.1; 6]);
    assert_eq!(sent(&mut l).len(), 6);
    // the schedule is absolute: the next SYNC is one period after the last one was due
    assert!((l.poll_timeout().unwrap() - (t + PERIOD)).abs() < 1e-12);
    assert_eq!(l.counters().stale, 1);
    assert_eq!(l.counters().cycles, 2);
}

#[test]
fn an_incomplete_cycle_closes_at_the_end_of_its_window() {
    let mut l = connected();
    let t = l.poll_timeout().unwrap();
    l.handle_timeout(t);
    sent(&mut l);
    l.handle(&fb(1, 2, 0), t + 1e-4);
    let end = l.poll_timeout().unwrap();
    assert!((end - (t + 0.6 * PERIOD)).abs() < 1e-12);
    assert_eq!(
        l.handle_timeout(end),
        Some(LinkEvent::Cycle {
            stamp_s: t,
            feedback: None
        })
    );
    assert_eq!(l.counters().incomplete, 1);
    // a late frame of the closed cycle is stale, not a second cycle
    assert_eq!(l.handle(&fb(2, 2, 0), end + 1e-4), None);
    assert_eq!(l.counters().stale, 1);
}

#[test]
fn a_window_judged_a_window_late_listens_once_more_instead_of_closing() {
    let mut l = connected();
    let t = l.poll_timeout().unwrap();
    l.handle_timeout(t);
    sent(&mut l);
    let end = l.poll_timeout().unwrap();
    // the loop was paused for 10 ms: the window is re-opened from the wake-up …
    assert_eq!(l.handle_timeout(end + 0.01), None);
    assert_eq!(l.counters().paused, 1);
    let again = l.poll_timeout().unwrap();
    assert!((again - (end + 0.01 + 0.6 * PERIOD)).abs() < 1e-12);
    // … where the queued feedback completes it
    for axis in 1..=5 {
        l.handle(&fb(axis, 2, 0), end + 0.0101);
    }
    assert!(matches!(
        l.handle(&fb(6, 2, 0), end + 0.0101),
        Some(LinkEvent::Cycle {
            feedback: Some(_),
            ..
        })
    ));
    // judged on time (within a window of its end), an incomplete window closes
    let t = l.poll_timeout().unwrap();
    l.handle_timeout(t);
    let end = l.poll_timeout().unwrap();
    assert!(matches!(
        l.handle_timeout(end + 0.5 * 0.6 * PERIOD),
        Some(LinkEvent::Cycle { feedback: None, .. })
    ));
    assert_eq!(l.counters().paused, 1);
    assert_eq!(l.counters().incomplete, 1);
}

#[test]
fn a_late_wake_up_is_an_overrun_and_resets_the_schedule() {
    let mut l = connected();
    let t = l.poll_timeout().unwrap();
    l.handle_timeout(t + 3.0 * PERIOD);
    assert!(l.take_timing().unwrap().overrun);
    l.handle_timeout(t + 3.0 * PERIOD + 0.6 * PERIOD);
    assert!((l.poll_timeout().unwrap() - (t + 4.0 * PERIOD)).abs() < 1e-12);
}

#[test]
fn a_silent_controller_and_a_refused_request_fail_the_session() {
    let mut l = Link::new(LinkConfig::new(PERIOD, 50));
    l.connect(0.0);
    assert_eq!(l.poll_timeout(), Some(3.0));
    assert_eq!(l.handle_timeout(2.9), None);
    assert_eq!(
        l.handle_timeout(3.0),
        Some(LinkEvent::Failed(LinkError::Silent { timeout_s: 3.0 }))
    );
    assert_eq!(l.poll_timeout(), None);
    let mut l = Link::new(LinkConfig::new(PERIOD, 50));
    l.connect(0.0);
    l.handle(&state(ServoState::Control), 0.01);
    let rejected = protocol::encode(&Message::Error {
        code: ErrorCode::Rejected,
        axis: 0,
        detail: 1,
    })
    .unwrap();
    assert_eq!(
        l.handle(&rejected, 0.02),
        Some(LinkEvent::Failed(LinkError::Refused {
            request: Request::ReleaseBrakes,
            state: Some(ServoState::Control)
        }))
    );
    // a controller that never answers a request
    let mut l = Link::new(LinkConfig::new(PERIOD, 50));
    l.connect(0.0);
    l.handle(&state(ServoState::Stopped), 0.01);
    assert!(matches!(
        l.handle_timeout(0.51),
        Some(LinkEvent::Failed(LinkError::NoAnswer { .. }))
    ));
}

#[test]
fn a_faulted_controller_is_reset_first_on_restart() {
    let mut l = connected();
    l.handle(&state(ServoState::Fault), 1.0);
    l.connect(1.0);
    assert_eq!(sent(&mut l), [control(Request::ResetFault)]);
    l.handle(&state(ServoState::Stopped), 1.01);
    assert_eq!(sent(&mut l), [control(Request::ReleaseBrakes)]);
}

#[test]
fn stop_is_acknowledged_or_times_out_while_the_cycles_go_on() {
    let mut l = connected();
    l.halt(Request::Stop, 0.1);
    assert_eq!(sent(&mut l), [control(Request::Stop)]);
    assert!(l.is_halting() && l.expects_frames());
    assert_eq!(
        l.handle(&state(ServoState::Stopped), 0.11),
        Some(LinkEvent::Acknowledged(Request::Stop, ServoState::Stopped))
    );
    l.halt(Request::Estop, 0.2);
    sent(&mut l);
    let due = l.poll_timeout().unwrap();
    assert!(due <= 0.25);
    let mut failed = false;
    let mut t = 0.2;
    while t < 0.3 {
        t += 1e-3;
        while l.poll_timeout().is_some_and(|d| d <= t) {
            if let Some(LinkEvent::Failed(LinkError::NoAnswer { request, .. })) =
                l.handle_timeout(t)
            {
                assert_eq!(request, Request::Estop);
                failed = true;
            }
        }
    }
    assert!(failed);
    assert!(l.is_running(), "the feedback cycles went on");
}

#[test]
fn a_storm_of_malformed_frames_only_counts() {
    let mut l = connected();
    let t = l.poll_timeout().unwrap();
    l.handle_timeout(t);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(0x5707);
    for _ in 0..100_000 {
        let id = rng.random_range(0..0x800u16);
        let n = rng.random_range(0..=8usize);
        let data: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        // whatever it decodes to, it is an event or nothing, never a panic
        let _ = l.handle(&CanFrame::new(id, &data).unwrap(), t);
    }
    assert!(l.counters().malformed > 50_000, "{:?}", l.counters());
}

#[test]
fn command_frames_answer_the_cycle_and_saturate() {
    let f = command_frames(0x0102, &[1.0, -1.0, 0.0, 100.0, f64::NAN, -100.0]);
    let Ok(Message::Command(c)) = protocol::decode(&f[0]) else {
        panic!()
    };
    assert_eq!(
        (c.axis, c.cycle, c.speed, c.mode),
        (1, 2, 5000, mode::SERVO)
    );
    let Ok(Message::Command(c)) = protocol::decode(&f[3]) else {
        panic!()
    };
    assert_eq!(c.speed, i16::MAX);
    let Ok(Message::Command(c)) = protocol::decode(&f[4]) else {
        panic!()
    };
    assert_eq!(c.speed, 0);
}

/// On CAN FD the link sends one COMMAND_FD a cycle and one FEEDBACK_FD completes the cycle;
/// a FEEDBACK_FD of another cycle counts once as stale.
#[test]
fn on_can_fd_one_frame_each_way_makes_a_cycle() {
    let fd = |cycle: u8, angle: i32| {
        protocol::encode(&Message::FeedbackFd(std::array::from_fn(|j| Feedback {
            axis: j as u8 + 1,
            angle: angle + j as i32,
            current: 100,
            status: status::SERVO_ON,
            cycle,
        })))
        .unwrap()
    };
    let mut l = Link::new(LinkConfig::new(PERIOD, 50).with_framing(Framing::Fd));
    l.connect(0.0);
    l.handle(&state(ServoState::Stopped), 0.05);
    l.handle(&state(ServoState::BrakeRelease), 0.06);
    l.handle(&state(ServoState::Control), 0.07);
    assert_eq!(
        sent(&mut l),
        [
            control(Request::ReleaseBrakes),
            control(Request::StartControl),
            Message::Sync { cycle: 1 }
        ]
    );
    let Some(LinkEvent::Connected(js)) = l.handle(&fd(1, 6000), 0.0701) else {
        panic!("one FEEDBACK_FD connects")
    };
    assert_eq!(js.q_motor[5], 6005.0 * protocol::ANGLE_LSB);
    let first = sent(&mut l);
    assert!(
        matches!(first.as_slice(), [Message::CommandFd(c)] if c.iter().all(|a| a.cycle == 1 && a.speed == 0)),
        "{first:?}"
    );
    // the next cycle: a stale FD frame counts once, the right one completes it
    l.handle_timeout(0.0701 + PERIOD);
    assert_eq!(sent(&mut l), [Message::Sync { cycle: 2 }]);
    assert_eq!(l.handle(&fd(1, 0), 0.0722), None);
    assert_eq!(l.counters().stale, 1);
    assert!(matches!(
        l.handle(&fd(2, 7000), 0.0723),
        Some(LinkEvent::Cycle {
            feedback: Some(_),
            ..
        })
    ));
    l.send_commands(&[0.1; 6]);
    let cmds = sent(&mut l);
    assert!(
        matches!(cmds.as_slice(), [Message::CommandFd(c)] if c.iter().all(|a| a.cycle == 2 && a.speed == 500)),
        "{cmds:?}"
    );
}
