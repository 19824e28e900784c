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
/// COMMAND_FD identifier (CAN FD): the six axes' commands of a cycle in one frame.
pub const ID_COMMAND_FD: u16 = 0x100;
/// FEEDBACK_FD identifier (CAN FD): the six axes' feedback of a cycle in one frame.
pub const ID_FEEDBACK_FD: u16 = 0x180;
/// COMMAND_FD payload, bytes: cycle, six mode bytes, a reserved byte, six speeds, six torques.
pub const COMMAND_FD_LEN: usize = 32;
/// FEEDBACK_FD payload, bytes: cycle, six status bytes, a reserved byte, six angles, six
/// currents, four reserved bytes.
pub const FEEDBACK_FD_LEN: usize = 48;

pub use super::frame::{CanFrame, FD_LENGTHS, FD_MAX_LEN, Framing};

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
    /// The six axes' commands of one cycle in one CAN FD frame: the fields of six COMMAND
    /// frames, `axes[j].axis == j + 1` and one `cycle` for all.
    CommandFd([AxisCommand; 6]),
    /// The six axes' feedback of one cycle in one CAN FD frame: the fields of six FEEDBACK
    /// frames, `axes[j].axis == j + 1` and one `cycle` for all.
    FeedbackFd([Feedback; 6]),
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
    /// A classic frame where the protocol has an FD one, or the other way round.
    #[error("CAN id 0x{id:03X}: a {got} frame, the protocol sends it as a {expected} frame")]
    WrongFormat {
        /// Identifier.
        id: u16,
        /// The frame's format ("classic" or "CAN FD").
        got: &'static str,
        /// The protocol's.
        expected: &'static str,
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
            mode_ok(c.mode)?;
            let (s, t) = (c.speed.to_le_bytes(), c.torque.to_le_bytes());
            f(
                ID_COMMAND + c.axis as u16 - 1,
                &[c.mode, c.cycle, s[0], s[1], t[0], t[1], 0, 0],
            )
        }
        Message::Feedback(b) => {
            axis_ok(b.axis)?;
            status_ok(b.status)?;
            let (a, i) = (b.angle.to_le_bytes(), b.current.to_le_bytes());
            f(
                ID_FEEDBACK + b.axis as u16 - 1,
                &[a[0], a[1], a[2], a[3], i[0], i[1], b.status, b.cycle],
            )
        }
        Message::CommandFd(axes) => {
            let cycle = set_cycle(axes.map(|c| (c.axis, c.cycle)))?;
            let mut d = [0u8; COMMAND_FD_LEN];
            d[0] = cycle;
            for (j, c) in axes.iter().enumerate() {
                mode_ok(c.mode)?;
                d[1 + j] = c.mode;
                d[8 + 2 * j..10 + 2 * j].copy_from_slice(&c.speed.to_le_bytes());
                d[20 + 2 * j..22 + 2 * j].copy_from_slice(&c.torque.to_le_bytes());
            }
            fd(ID_COMMAND_FD, &d)
        }
        Message::FeedbackFd(axes) => {
            let cycle = set_cycle(axes.map(|b| (b.axis, b.cycle)))?;
            let mut d = [0u8; FEEDBACK_FD_LEN];
            d[0] = cycle;
            for (j, b) in axes.iter().enumerate() {
                status_ok(b.status)?;
                d[1 + j] = b.status;
                d[8 + 4 * j..12 + 4 * j].copy_from_slice(&b.angle.to_le_bytes());
                d[32 + 2 * j..34 + 2 * j].copy_from_slice(&b.current.to_le_bytes());
            }
            fd(ID_FEEDBACK_FD, &d)
        }
    }
}

/// An FD frame of the protocol: always with the bit-rate switch (a bus without a faster data
/// phase ignores it in its timing).
fn fd(id: u16, d: &[u8]) -> Result<CanFrame, EncodeError> {
    CanFrame::new_fd(id, d, true).ok_or(EncodeError::OutOfRange {
        field: "frame",
        value: id as f64,
    })
}

/// The one cycle of a six-axis set whose axes are 1…6 in order.
fn set_cycle(axes: [(u8, u8); 6]) -> Result<u8, EncodeError> {
    for (j, &(axis, cycle)) in axes.iter().enumerate() {
        if axis as usize != j + 1 {
            return Err(EncodeError::OutOfRange {
                field: "axis",
                value: axis as f64,
            });
        }
        if cycle != axes[0].1 {
            return Err(EncodeError::OutOfRange {
                field: "cycle",
                value: cycle as f64,
            });
        }
    }
    Ok(axes[0].1)
}

fn mode_ok(mode: u8) -> Result<(), EncodeError> {
    if mode & 0xF0 != 0 {
        return Err(EncodeError::OutOfRange {
            field: "mode",
            value: mode as f64,
        });
    }
    Ok(())
}

fn status_ok(status: u8) -> Result<(), EncodeError> {
    if status & 0xC0 != 0 {
        return Err(EncodeError::OutOfRange {
            field: "status",
            value: status as f64,
        });
    }
    Ok(())
}

/// The payload of a frame of a known identifier: in the protocol's format for it (classic or
/// FD) and of its length.
fn dlc(frame: &CanFrame, expected: usize) -> Result<&[u8], DecodeError> {
    if frame.is_fd() != is_fd_id(frame.id()) {
        let name = |fd: bool| if fd { "CAN FD" } else { "classic" };
        return Err(DecodeError::WrongFormat {
            id: frame.id(),
            got: name(frame.is_fd()),
            expected: name(is_fd_id(frame.id())),
        });
    }
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

/// Whether the protocol sends `id` as a CAN FD frame.
fn is_fd_id(id: u16) -> bool {
    matches!(id, ID_COMMAND_FD | ID_FEEDBACK_FD)
}

/// The reserved bytes `at` of `d` must be zero (so that what decodes encodes back the same).
fn reserved(id: u16, d: &[u8], at: &[usize]) -> Result<(), DecodeError> {
    match at.iter().find(|&&i| d[i] != 0) {
        Some(&i) => Err(range(id, "reserved", d[i])),
        None => Ok(()),
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
        ID_COMMAND_FD => {
            let d = dlc(frame, COMMAND_FD_LEN)?;
            reserved(id, d, &[7])?;
            let mut axes = [AxisCommand {
                axis: 0,
                mode: 0,
                cycle: d[0],
                speed: 0,
                torque: 0,
            }; 6];
            for (j, c) in axes.iter_mut().enumerate() {
                if d[1 + j] & 0xF0 != 0 {
                    return Err(range(id, "mode", d[1 + j]));
                }
                c.axis = j as u8 + 1;
                c.mode = d[1 + j];
                c.speed = i16::from_le_bytes([d[8 + 2 * j], d[9 + 2 * j]]);
                c.torque = i16::from_le_bytes([d[20 + 2 * j], d[21 + 2 * j]]);
            }
            Ok(Message::CommandFd(axes))
        }
        ID_FEEDBACK_FD => {
            let d = dlc(frame, FEEDBACK_FD_LEN)?;
            reserved(id, d, &[7, 44, 45, 46, 47])?;
            let mut axes = [Feedback {
                axis: 0,
                angle: 0,
                current: 0,
                status: 0,
                cycle: d[0],
            }; 6];
            for (j, b) in axes.iter_mut().enumerate() {
                if d[1 + j] & 0xC0 != 0 {
                    return Err(range(id, "status", d[1 + j]));
                }
                b.axis = j as u8 + 1;
                b.status = d[1 + j];
                b.angle =
                    i32::from_le_bytes([d[8 + 4 * j], d[9 + 4 * j], d[10 + 4 * j], d[11 + 4 * j]]);
                b.current = i16::from_le_bytes([d[32 + 2 * j], d[33 + 2 * j]]);
            }
            Ok(Message::FeedbackFd(axes))
        }
        _ => Err(DecodeError::UnknownId(id)),
    }
}

#[cfg(test)]
mod tests;
