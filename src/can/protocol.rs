//! The sans-IO codec of the pa10 CAN protocol (`docs/protocol.md`): frames ⇄ typed messages.
//!
//! No sockets, no clocks: [`encode`] and [`decode`] are pure functions on [`CanFrame`]s. Fields
//! are kept in wire units (counts) so that a round trip is exact; constructors and accessors
//! convert to SI with range checks. Every malformed frame is a [`DecodeError`], never a panic.

/// Angle LSB, rad: 2π/(16384·50) (the RobWork PA10 driver's unit).
pub const ANGLE_LSB: f64 = std::f64::consts::TAU / (16384.0 * 50.0);
/// Speed LSB, rad/s (0.2 mrad/s).
pub const SPEED_LSB: f64 = 2e-4;
/// Torque LSB, N·m.
pub const TORQUE_LSB: f64 = 0.01;
/// Current LSB, A.
pub const CURRENT_LSB: f64 = 1e-3;

/// CONTROL identifier.
pub const ID_CONTROL: u16 = 0x010;
/// STATE identifier.
pub const ID_STATE: u16 = 0x011;
/// SYNC identifier.
pub const ID_SYNC: u16 = 0x080;
/// ERROR identifier.
pub const ID_ERROR: u16 = 0x081;
/// COMMAND identifier of axis 1 (axis n: `ID_COMMAND + n - 1`).
pub const ID_COMMAND: u16 = 0x101;
/// FEEDBACK identifier of axis 1.
pub const ID_FEEDBACK: u16 = 0x181;

/// A classic CAN data frame: 11-bit identifier and 0–8 data bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: u16,
    len: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// A frame; `None` when `id` exceeds 11 bits or `data` 8 bytes.
    pub fn new(id: u16, data: &[u8]) -> Option<Self> {
        if id > 0x7FF || data.len() > 8 {
            return None;
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            len: data.len() as u8,
            data: d,
        })
    }
    /// A frame of `len` zero bytes, usable in constants; `None` when `id` exceeds 11 bits or
    /// `len` 8.
    pub const fn new_const(id: u16, len: u8) -> Option<Self> {
        if id > 0x7FF || len > 8 {
            return None;
        }
        Some(Self {
            id,
            len,
            data: [0; 8],
        })
    }
    /// The 11-bit identifier.
    pub fn id(&self) -> u16 {
        self.id
    }
    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }
    /// Data length code.
    pub fn dlc(&self) -> usize {
        self.len as usize
    }
    /// Worst-case length on the wire, bits (stuffing and interframe space included).
    pub fn worst_case_bits(&self) -> u32 {
        frame_bits_worst(self.dlc())
    }
}

/// Worst-case bits of a standard frame with `dlc` data bytes, including bit stuffing and the
/// 3-bit interframe space: `34 + 8s + 13 + ⌊(34 + 8s − 1)/4⌋` (Davis et al. 2007).
pub fn frame_bits_worst(dlc: usize) -> u32 {
    let g = 34 + 8 * dlc as u32;
    g + 13 + (g - 1) / 4
}

/// Nominal bits of a standard frame (no stuffing), interframe space included.
pub fn frame_bits_nominal(dlc: usize) -> u32 {
    47 + 8 * dlc as u32
}

/// Worst-case bits of one control cycle: 6 COMMAND + 1 SYNC + 6 FEEDBACK.
pub fn cycle_bits_worst() -> u32 {
    12 * frame_bits_worst(8) + frame_bits_worst(2)
}

/// Worst-case bus load (0…1+) of the cyclic traffic at `rate_hz` on a `bitrate` bit/s bus.
pub fn bus_load(rate_hz: f64, bitrate: f64) -> f64 {
    rate_hz * cycle_bits_worst() as f64 / bitrate
}

/// A cycle rate is refused when its worst-case load exceeds `limit` (0…1).
pub fn check_rate(rate_hz: f64, bitrate: f64, limit: f64) -> Result<f64, String> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(format!("cycle rate must be > 0 Hz, got {rate_hz}"));
    }
    if !(bitrate.is_finite() && bitrate > 0.0) {
        return Err(format!("bitrate must be > 0 bit/s, got {bitrate}"));
    }
    let load = bus_load(rate_hz, bitrate);
    if load > limit {
        return Err(format!(
            "{rate_hz} Hz needs {:.1} % of a {:.0} kbit/s bus worst case, above the {:.1} % limit (max {:.0} Hz)",
            load * 100.0,
            bitrate / 1e3,
            limit * 100.0,
            limit * bitrate / cycle_bits_worst() as f64
        ));
    }
    Ok(load)
}

/// An enumeration with wire numbers, written once: the enum with its discriminants, and
/// `ALL` / `from_wire` for decoding.
macro_rules! wire_enum {
    ($(#[$m:meta])* $vis:vis enum $name:ident { $($(#[$vm:meta])* $var:ident = $val:expr,)+ }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u8)]
        $vis enum $name { $($(#[$vm])* $var = $val,)+ }

        impl $name {
            /// Every value, in wire order.
            pub const ALL: &'static [$name] = &[$($name::$var),+];
            /// The value whose wire number is `v`.
            pub fn from_wire(v: u8) -> Option<Self> {
                Self::ALL.iter().copied().find(|x| *x as u8 == v)
            }
        }
    };
}

wire_enum! {
/// CONTROL requests.
pub enum Request {
    /// STOPPED → BRAKE_RELEASE.
    ReleaseBrakes = 1,
    /// BRAKE_RELEASE → CONTROL.
    StartControl = 2,
    /// Controlled stop → STOPPED.
    Stop = 3,
    /// Immediate servo off, brakes on → STOPPED.
    Estop = 4,
    /// FAULT → STOPPED.
    ResetFault = 5,
}
}

wire_enum! {
/// Servo controller states.
pub enum ServoState {
    /// Servo off, brakes on (power-on).
    Stopped = 0,
    /// Servo holding at speed 0, brakes released.
    BrakeRelease = 1,
    /// Cyclic control, watchdog armed.
    Control = 2,
    /// Servo off, brakes on, until RESET_FAULT.
    Fault = 3,
}
}

wire_enum! {
/// Fault codes of STATE.
pub enum FaultCode {
    /// No fault.
    None = 0,
    /// Command watchdog expired.
    Watchdog = 1,
    /// An axis failed.
    AxisFault = 2,
    /// A limit was exceeded.
    Limit = 3,
    /// Bus trouble.
    Bus = 4,
    /// The last request was not valid in the current state.
    Rejected = 5,
}
}

wire_enum! {
/// ERROR codes.
pub enum ErrorCode {
    /// Command watchdog expired.
    Watchdog = 1,
    /// An axis stopped answering.
    AxisTimeout = 2,
    /// A current sensor reads an offset.
    CurrentOffset = 3,
    /// A resolver reading jumped.
    ResolverGlitch = 4,
    /// A limit was exceeded.
    Limit = 5,
    /// A request was refused.
    Rejected = 6,
}
}

/// COMMAND mode bits.
pub mod mode {
    /// Brake on.
    pub const BRAKE: u8 = 0x01;
    /// Servo on.
    pub const SERVO: u8 = 0x02;
    /// Torque mode (else speed mode).
    pub const TORQUE: u8 = 0x04;
    /// Deadman pressed.
    pub const DEADMAN: u8 = 0x08;
}

/// FEEDBACK status bits.
pub mod status {
    /// Brake engaged.
    pub const BRAKE_ON: u8 = 0x01;
    /// Servo on.
    pub const SERVO_ON: u8 = 0x02;
    /// Axis fault.
    pub const FAULT: u8 = 0x04;
    /// Watchdog tripped.
    pub const WATCHDOG: u8 = 0x08;
    /// At a limit.
    pub const LIMIT: u8 = 0x10;
    /// Deadman pressed.
    pub const DEADMAN: u8 = 0x20;
}

/// One axis command (wire units).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisCommand {
    /// Axis 1…6.
    pub axis: u8,
    /// [`mode`] bits.
    pub mode: u8,
    /// SYNC cycle (low byte) this answers.
    pub cycle: u8,
    /// Speed, counts of [`SPEED_LSB`].
    pub speed: i16,
    /// Torque, counts of [`TORQUE_LSB`].
    pub torque: i16,
}

impl AxisCommand {
    /// A speed-mode command with servo on, brake off: `speed` rad/s, rounded to 0.2 mrad/s.
    pub fn speed(axis: u8, cycle: u8, speed_rad_s: f64) -> Result<Self, EncodeError> {
        let s = counts_i16(speed_rad_s, SPEED_LSB, "speed")?;
        Ok(Self {
            axis,
            mode: mode::SERVO,
            cycle,
            speed: s,
            torque: 0,
        })
    }
    /// The speed-mode command the loop sends every cycle: as [`AxisCommand::speed`], but a speed
    /// beyond the field's range saturates at it and a non-finite one is 0 rad/s (the loop
    /// has already clamped to the joint's limit; this never fails inside a cycle).
    pub fn speed_saturating(axis: u8, cycle: u8, speed_rad_s: f64) -> Self {
        let counts = (speed_rad_s / SPEED_LSB)
            .round()
            .clamp(i16::MIN as f64, i16::MAX as f64);
        Self {
            axis,
            mode: mode::SERVO,
            cycle,
            speed: if counts.is_nan() { 0 } else { counts as i16 },
            torque: 0,
        }
    }
    /// Speed, rad/s.
    pub fn speed_rad_s(&self) -> f64 {
        self.speed as f64 * SPEED_LSB
    }
    /// Torque, N·m.
    pub fn torque_nm(&self) -> f64 {
        self.torque as f64 * TORQUE_LSB
    }
}

/// One axis feedback snapshot (wire units).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Feedback {
    /// Axis 1…6.
    pub axis: u8,
    /// Resolver angle, counts of [`ANGLE_LSB`].
    pub angle: i32,
    /// Motor current, mA.
    pub current: i16,
    /// [`status`] bits.
    pub status: u8,
    /// SYNC cycle (low byte) of the snapshot.
    pub cycle: u8,
}

impl Feedback {
    /// Angle, rad.
    pub fn angle_rad(&self) -> f64 {
        self.angle as f64 * ANGLE_LSB
    }
    /// Current, A.
    pub fn current_a(&self) -> f64 {
        self.current as f64 * CURRENT_LSB
    }
}

/// A protocol message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Host → servo request; `watchdog_ms` 0 keeps the current watchdog.
    Control {
        /// The request.
        request: Request,
        /// Watchdog, ms.
        watchdog_ms: u8,
    },
    /// Servo state (reply and heartbeat).
    State {
        /// State.
        state: ServoState,
        /// Fault code.
        fault: FaultCode,
        /// Last applied cycle.
        cycle: u16,
    },
    /// Cycle marker.
    Sync {
        /// Cycle number.
        cycle: u16,
    },
    /// Error report.
    Error {
        /// Code.
        code: ErrorCode,
        /// Axis 1…6 or 0.
        axis: u8,
        /// Code-specific detail.
        detail: i32,
    },
    /// Axis command.
    Command(AxisCommand),
    /// Axis feedback.
    Feedback(Feedback),
}

/// Why a frame is not a valid message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The identifier is not in the protocol.
    #[error("unknown CAN id 0x{0:03X}")]
    UnknownId(u16),
    /// The DLC does not match the identifier.
    #[error("CAN id 0x{id:03X}: DLC {got}, expected {expected}")]
    WrongDlc {
        /// Identifier.
        id: u16,
        /// DLC received.
        got: usize,
        /// DLC required.
        expected: usize,
    },
    /// A field holds a value outside its range.
    #[error("CAN id 0x{id:03X}: {field} = {value} is out of range")]
    OutOfRange {
        /// Identifier.
        id: u16,
        /// Field.
        field: &'static str,
        /// Raw value.
        value: i64,
    },
}

/// Why a message cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// A value does not fit its field.
    #[error("{field} = {value} does not fit its field")]
    OutOfRange {
        /// Field.
        field: &'static str,
        /// Value in SI units (or raw).
        value: f64,
    },
}

fn counts_i16(v: f64, lsb: f64, field: &'static str) -> Result<i16, EncodeError> {
    let c = (v / lsb).round();
    if !c.is_finite() || c < i16::MIN as f64 || c > i16::MAX as f64 {
        return Err(EncodeError::OutOfRange { field, value: v });
    }
    Ok(c as i16)
}

/// Angle (rad) → counts, rounded; errors beyond ±2³¹ counts.
pub fn angle_counts(rad: f64) -> Result<i32, EncodeError> {
    let c = (rad / ANGLE_LSB).round();
    if !c.is_finite() || c < i32::MIN as f64 || c > i32::MAX as f64 {
        return Err(EncodeError::OutOfRange {
            field: "angle",
            value: rad,
        });
    }
    Ok(c as i32)
}

/// Current (A) → mA counts, saturating at the field's range.
pub fn current_counts(a: f64) -> i16 {
    if a.is_nan() {
        return 0;
    }
    (a / CURRENT_LSB)
        .round()
        .clamp(i16::MIN as f64, i16::MAX as f64) as i16
}

fn axis_ok(axis: u8) -> Result<(), EncodeError> {
    if (1..=6).contains(&axis) {
        Ok(())
    } else {
        Err(EncodeError::OutOfRange {
            field: "axis",
            value: axis as f64,
        })
    }
}

/// Encodes a message. Errors when an axis is not 1…6 or mode/status bits are undefined.
pub fn encode(m: &Message) -> Result<CanFrame, EncodeError> {
    let f = |id: u16, d: &[u8]| {
        CanFrame::new(id, d).ok_or(EncodeError::OutOfRange {
            field: "frame",
            value: id as f64,
        })
    };
    match *m {
        Message::Control {
            request,
            watchdog_ms,
        } => f(ID_CONTROL, &[request as u8, watchdog_ms]),
        Message::State {
            state,
            fault,
            cycle,
        } => {
            let c = cycle.to_le_bytes();
            f(ID_STATE, &[state as u8, fault as u8, c[0], c[1]])
        }
        Message::Sync { cycle } => f(ID_SYNC, &cycle.to_le_bytes()),
        Message::Error { code, axis, detail } => {
            if axis > 6 {
                return Err(EncodeError::OutOfRange {
                    field: "axis",
                    value: axis as f64,
                });
            }
            let d = detail.to_le_bytes();
            f(ID_ERROR, &[code as u8, axis, d[0], d[1], d[2], d[3], 0, 0])
        }
        Message::Command(c) => {
            axis_ok(c.axis)?;
            if c.mode & 0xF0 != 0 {
                return Err(EncodeError::OutOfRange {
                    field: "mode",
                    value: c.mode as f64,
                });
            }
            let (s, t) = (c.speed.to_le_bytes(), c.torque.to_le_bytes());
            f(
                ID_COMMAND + c.axis as u16 - 1,
                &[c.mode, c.cycle, s[0], s[1], t[0], t[1], 0, 0],
            )
        }
        Message::Feedback(b) => {
            axis_ok(b.axis)?;
            if b.status & 0xC0 != 0 {
                return Err(EncodeError::OutOfRange {
                    field: "status",
                    value: b.status as f64,
                });
            }
            let (a, i) = (b.angle.to_le_bytes(), b.current.to_le_bytes());
            f(
                ID_FEEDBACK + b.axis as u16 - 1,
                &[a[0], a[1], a[2], a[3], i[0], i[1], b.status, b.cycle],
            )
        }
    }
}

fn dlc(frame: &CanFrame, expected: usize) -> Result<&[u8], DecodeError> {
    if frame.dlc() != expected {
        return Err(DecodeError::WrongDlc {
            id: frame.id(),
            got: frame.dlc(),
            expected,
        });
    }
    Ok(frame.data())
}

fn range(id: u16, field: &'static str, value: u8) -> DecodeError {
    DecodeError::OutOfRange {
        id,
        field,
        value: value as i64,
    }
}

/// Decodes a frame.
pub fn decode(frame: &CanFrame) -> Result<Message, DecodeError> {
    let id = frame.id();
    match id {
        ID_CONTROL => {
            let d = dlc(frame, 2)?;
            let request = Request::from_wire(d[0]).ok_or_else(|| range(id, "request", d[0]))?;
            Ok(Message::Control {
                request,
                watchdog_ms: d[1],
            })
        }
        ID_STATE => {
            let d = dlc(frame, 4)?;
            let state = ServoState::from_wire(d[0]).ok_or_else(|| range(id, "state", d[0]))?;
            let fault = FaultCode::from_wire(d[1]).ok_or_else(|| range(id, "fault", d[1]))?;
            Ok(Message::State {
                state,
                fault,
                cycle: u16::from_le_bytes([d[2], d[3]]),
            })
        }
        ID_SYNC => {
            let d = dlc(frame, 2)?;
            Ok(Message::Sync {
                cycle: u16::from_le_bytes([d[0], d[1]]),
            })
        }
        ID_ERROR => {
            let d = dlc(frame, 8)?;
            let code = ErrorCode::from_wire(d[0]).ok_or_else(|| range(id, "code", d[0]))?;
            if d[1] > 6 {
                return Err(range(id, "axis", d[1]));
            }
            Ok(Message::Error {
                code,
                axis: d[1],
                detail: i32::from_le_bytes([d[2], d[3], d[4], d[5]]),
            })
        }
        0x101..=0x106 => {
            let d = dlc(frame, 8)?;
            if d[0] & 0xF0 != 0 {
                return Err(range(id, "mode", d[0]));
            }
            Ok(Message::Command(AxisCommand {
                axis: (id - ID_COMMAND + 1) as u8,
                mode: d[0],
                cycle: d[1],
                speed: i16::from_le_bytes([d[2], d[3]]),
                torque: i16::from_le_bytes([d[4], d[5]]),
            }))
        }
        0x181..=0x186 => {
            let d = dlc(frame, 8)?;
            if d[6] & 0xC0 != 0 {
                return Err(range(id, "status", d[6]));
            }
            Ok(Message::Feedback(Feedback {
                axis: (id - ID_FEEDBACK + 1) as u8,
                angle: i32::from_le_bytes([d[0], d[1], d[2], d[3]]),
                current: i16::from_le_bytes([d[4], d[5]]),
                status: d[6],
                cycle: d[7],
            }))
        }
        _ => Err(DecodeError::UnknownId(id)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;

    #[test]
    fn bus_load_matches_the_design_numbers() {
        assert_eq!(frame_bits_worst(8), 135);
        assert_eq!(frame_bits_nominal(8), 111);
        assert_eq!(frame_bits_worst(2), 75);
        assert_eq!(cycle_bits_worst(), 1695);
        assert!((bus_load(500.0, 1e6) - 0.8475).abs() < 1e-12);
        assert!(check_rate(500.0, 1e6, 0.9).is_ok());
        let e = check_rate(600.0, 1e6, 0.9).unwrap_err();
        assert!(e.contains("101.7 %") && e.contains("max 531 Hz"), "{e}");
        assert!(check_rate(0.0, 1e6, 0.9).is_err());
    }

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
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 5000, rng_seed: RngSeed::Fixed(0xCA11), failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn every_message_round_trips(m in message()) {
            let f = encode(&m).unwrap();
            prop_assert_eq!(decode(&f), Ok(m));
        }

        #[test]
        fn any_frame_decodes_or_errs_without_panicking(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let f = CanFrame::new(id, &data).unwrap();
            if let Ok(m) = decode(&f) {
                prop_assert_eq!(encode(&m).unwrap(), f);
            }
        }
    }
}
