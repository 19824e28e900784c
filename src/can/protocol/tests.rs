//! The codec's tests: documented scalings, typed errors, round trips of every message and
//! of any frame that decodes (classic and FD), as 5000-case property tests.

use super::*;
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

#[test]
fn scalings_are_the_documented_ones() {
    let f = encode(&Message::Command(AxisCommand::speed(2, 7, 1.0).unwrap())).unwrap();
    assert_eq!(f.id(), 0x102);
    assert_eq!(f.data(), &[0x02, 7, 0x88, 0x13, 0, 0, 0, 0]); // 5000 counts = 1 rad/s
    let fb = Feedback {
        axis: 1,
        angle: 819_200,
        current: -1500,
        status: status::SERVO_ON,
        cycle: 9,
    };
    let m = decode(&encode(&Message::Feedback(fb)).unwrap()).unwrap();
    let Message::Feedback(b) = m else { panic!() };
    assert!((b.angle_rad() - std::f64::consts::TAU).abs() < 1e-12);
    assert_eq!(b.current_a(), -1.5);
    assert!(AxisCommand::speed(1, 0, 7.0).is_err());
    // the loop's encoder saturates instead, and sends 0 for a non-finite speed
    let max = AxisCommand::speed_saturating(1, 0, 7.0);
    assert_eq!(max.speed, i16::MAX);
    assert_eq!(AxisCommand::speed_saturating(1, 0, -7.0).speed, i16::MIN);
    assert_eq!(AxisCommand::speed_saturating(1, 0, f64::NAN).speed, 0);
    assert_eq!(
        AxisCommand::speed_saturating(2, 7, 1.0),
        AxisCommand::speed(2, 7, 1.0).expect("in range")
    );
    assert!(AxisCommand::speed(1, 0, f64::NAN).is_err());
    assert!(angle_counts(1e6).is_err());
    assert_eq!(current_counts(99.0), i16::MAX);
}

#[test]
fn malformed_frames_are_typed_errors() {
    let fr = |id, d: &[u8]| CanFrame::new(id, d).unwrap();
    assert_eq!(decode(&fr(0x123, &[])), Err(DecodeError::UnknownId(0x123)));
    assert_eq!(
        decode(&fr(0x181, &[0; 7])),
        Err(DecodeError::WrongDlc {
            id: 0x181,
            got: 7,
            expected: 8
        })
    );
    assert!(matches!(
        decode(&fr(0x010, &[9, 0])),
        Err(DecodeError::OutOfRange {
            field: "request",
            ..
        })
    ));
    assert!(matches!(
        decode(&fr(0x011, &[7, 0, 0, 0])),
        Err(DecodeError::OutOfRange { field: "state", .. })
    ));
    assert!(matches!(
        decode(&fr(0x101, &[0x10, 0, 0, 0, 0, 0, 0, 0])),
        Err(DecodeError::OutOfRange { field: "mode", .. })
    ));
    assert!(matches!(
        decode(&fr(0x081, &[1, 9, 0, 0, 0, 0, 0, 0])),
        Err(DecodeError::OutOfRange { field: "axis", .. })
    ));
    assert!(CanFrame::new(0x800, &[]).is_none());
    assert!(CanFrame::new(0x100, &[0; 9]).is_none());
    assert!(
        encode(&Message::Command(AxisCommand {
            axis: 7,
            mode: 0,
            cycle: 0,
            speed: 0,
            torque: 0
        }))
        .is_err()
    );
}

fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        (1u8..=5, any::<u8>()).prop_map(|(r, w)| {
            let request = [
                Request::ReleaseBrakes,
                Request::StartControl,
                Request::Stop,
                Request::Estop,
                Request::ResetFault,
            ][r as usize - 1];
            Message::Control {
                request,
                watchdog_ms: w,
            }
        }),
        (0u8..4, 0u8..6, any::<u16>()).prop_map(|(s, f, cycle)| Message::State {
            state: [
                ServoState::Stopped,
                ServoState::BrakeRelease,
                ServoState::Control,
                ServoState::Fault
            ][s as usize],
            fault: [
                FaultCode::None,
                FaultCode::Watchdog,
                FaultCode::AxisFault,
                FaultCode::Limit,
                FaultCode::Bus,
                FaultCode::Rejected
            ][f as usize],
            cycle
        }),
        any::<u16>().prop_map(|cycle| Message::Sync { cycle }),
        (1u8..=6, 0u8..=6, any::<i32>()).prop_map(|(c, axis, detail)| Message::Error {
            code: [
                ErrorCode::Watchdog,
                ErrorCode::AxisTimeout,
                ErrorCode::CurrentOffset,
                ErrorCode::ResolverGlitch,
                ErrorCode::Limit,
                ErrorCode::Rejected
            ][c as usize - 1],
            axis,
            detail
        }),
        (1u8..=6, 0u8..16, any::<u8>(), any::<i16>(), any::<i16>()).prop_map(
            |(axis, mode, cycle, speed, torque)| Message::Command(AxisCommand {
                axis,
                mode,
                cycle,
                speed,
                torque
            })
        ),
        (1u8..=6, any::<i32>(), any::<i16>(), 0u8..64, any::<u8>()).prop_map(
            |(axis, angle, current, status, cycle)| Message::Feedback(Feedback {
                axis,
                angle,
                current,
                status,
                cycle
            })
        ),
        (
            any::<u8>(),
            proptest::array::uniform6((0u8..16, any::<i16>(), any::<i16>()))
        )
            .prop_map(|(cycle, a)| Message::CommandFd(std::array::from_fn(|j| {
                AxisCommand {
                    axis: j as u8 + 1,
                    mode: a[j].0,
                    cycle,
                    speed: a[j].1,
                    torque: a[j].2,
                }
            }))),
        (
            any::<u8>(),
            proptest::array::uniform6((any::<i32>(), any::<i16>(), 0u8..64))
        )
            .prop_map(|(cycle, a)| Message::FeedbackFd(std::array::from_fn(|j| {
                Feedback {
                    axis: j as u8 + 1,
                    angle: a[j].0,
                    current: a[j].1,
                    status: a[j].2,
                    cycle,
                }
            }))),
    ]
}

fn axes_fd(cycle: u8) -> [Feedback; 6] {
    std::array::from_fn(|j| Feedback {
        axis: j as u8 + 1,
        angle: -1_000_000 * (j as i32 + 1),
        current: 250 * j as i16 - 700,
        status: status::SERVO_ON | if j == 4 { status::LIMIT } else { 0 },
        cycle,
    })
}

#[test]
fn fd_frames_carry_the_six_axes_with_the_classic_fields() {
    let fb = axes_fd(42);
    let f = encode(&Message::FeedbackFd(fb)).unwrap();
    assert_eq!(
        (f.id(), f.dlc(), f.is_fd(), f.brs()),
        (0x180, 48, true, true)
    );
    // cycle, six status bytes, reserved, six angles, six currents, reserved
    assert_eq!(f.data()[0], 42);
    assert_eq!(f.data()[5], status::SERVO_ON | status::LIMIT);
    assert_eq!(&f.data()[8..12], &(-1_000_000i32).to_le_bytes());
    assert_eq!(&f.data()[42..44], &(550i16).to_le_bytes());
    let Ok(Message::FeedbackFd(back)) = decode(&f) else {
        panic!("FEEDBACK_FD decodes")
    };
    // the same SI accessors as six FEEDBACK frames
    for (b, classic) in back.iter().zip(fb) {
        let c = decode(&encode(&Message::Feedback(classic)).unwrap()).unwrap();
        assert_eq!(Message::Feedback(*b), c);
        assert_eq!(b.angle_rad(), classic.angle_rad());
    }
    let cmds: [AxisCommand; 6] =
        std::array::from_fn(|j| AxisCommand::speed(j as u8 + 1, 9, 0.1 * j as f64 - 0.2).unwrap());
    let f = encode(&Message::CommandFd(cmds)).unwrap();
    assert_eq!((f.id(), f.dlc()), (0x100, 32));
    assert_eq!(&f.data()[..8], &[9, 2, 2, 2, 2, 2, 2, 0]);
    assert_eq!(&f.data()[8..10], &(-1000i16).to_le_bytes()); // -0.2 rad/s
    assert_eq!(decode(&f), Ok(Message::CommandFd(cmds)));
}

#[test]
fn fd_frames_refuse_what_they_cannot_carry() {
    // axes out of order, or two cycles in one frame
    let mut fb = axes_fd(1);
    fb.swap(0, 1);
    assert!(matches!(
        encode(&Message::FeedbackFd(fb)),
        Err(EncodeError::OutOfRange { field: "axis", .. })
    ));
    let mut fb = axes_fd(1);
    fb[3].cycle = 2;
    assert!(matches!(
        encode(&Message::FeedbackFd(fb)),
        Err(EncodeError::OutOfRange { field: "cycle", .. })
    ));
    // the format must be the protocol's: FD ids in FD frames, classic ids in classic ones
    let good = encode(&Message::FeedbackFd(axes_fd(1))).unwrap();
    let classic = CanFrame::new(0x180, &good.data()[..8]).unwrap();
    assert_eq!(
        decode(&classic),
        Err(DecodeError::WrongFormat {
            id: 0x180,
            got: "classic",
            expected: "CAN FD"
        })
    );
    let sync_fd = CanFrame::new_fd(ID_SYNC, &[1, 0], true).unwrap();
    assert!(matches!(
        decode(&sync_fd),
        Err(DecodeError::WrongFormat { id: 0x080, .. })
    ));
    let short = CanFrame::new_fd(0x180, &good.data()[..32], true).unwrap();
    assert!(matches!(
        decode(&short),
        Err(DecodeError::WrongDlc {
            expected: 48,
            got: 32,
            ..
        })
    ));
    let mut d = good.data().to_vec();
    d[46] = 1;
    assert!(matches!(
        decode(&good.with_data(&d).unwrap()),
        Err(DecodeError::OutOfRange {
            field: "reserved",
            ..
        })
    ));
    d[46] = 0;
    d[2] = 0x40;
    assert!(matches!(
        decode(&good.with_data(&d).unwrap()),
        Err(DecodeError::OutOfRange {
            field: "status",
            ..
        })
    ));
    assert_eq!(
        decode(&CanFrame::new_fd(0x123, &[], true).unwrap()),
        Err(DecodeError::UnknownId(0x123))
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 5000, rng_seed: RngSeed::Fixed(0xCA11), failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn every_message_round_trips(m in message()) {
        let f = encode(&m).unwrap();
        prop_assert_eq!(decode(&f), Ok(m));
    }

    /// A valid FD frame with one byte replaced, its length cut to another FD length or its
    /// identifier changed: a typed error or a message that encodes back to the same frame.
    #[test]
    fn mangled_fd_frames_decode_or_err_without_panicking(
        m in message(),
        at in 0usize..64,
        byte in any::<u8>(),
        cut in 0usize..16,
        id in prop_oneof![Just(None), (0u16..0x800).prop_map(Some)],
    ) {
        let f = encode(&m).unwrap();
        let mut d = [0u8; 64];
        d[..f.dlc()].copy_from_slice(f.data());
        d[at] = byte;
        let len = if cut == 15 { FD_LENGTHS[at % 16] } else { f.dlc().max(FD_LENGTHS[cut.min(8)]) };
        let g = CanFrame::new_fd(id.unwrap_or(f.id()), &d[..len], true).unwrap();
        if let Ok(m) = decode(&g) {
            prop_assert_eq!(encode(&m).unwrap(), g);
        }
    }

    #[test]
    fn any_frame_decodes_or_errs_without_panicking(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let f = CanFrame::new(id, &data).unwrap();
        if let Ok(m) = decode(&f) {
            prop_assert_eq!(encode(&m).unwrap(), f);
        }
    }
}
