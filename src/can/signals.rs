//! A message's fields as the named signals of `docs/pa10.dbc` (classic) and
//! `docs/pa10-fd.dbc` (CAN FD: the per-axis signals of COMMAND_FD and FEEDBACK_FD carry the
//! axis as a suffix, `speed_1` … `speed_6`), in SI units: plain data for comparing our codec
//! with a DBC tool's decoding (`pa10 sim decode`, the cantools check).

use super::protocol::{AxisCommand, Feedback, Message, mode, status};

/// `name_1` … `name_6`.
macro_rules! per_axis {
    ($n:literal) => {
        [
            concat!($n, "_1"),
            concat!($n, "_2"),
            concat!($n, "_3"),
            concat!($n, "_4"),
            concat!($n, "_5"),
            concat!($n, "_6"),
        ]
    };
}

fn flag(bits: u8, bit: u8) -> f64 {
    f64::from(u8::from(bits & bit != 0))
}

/// One axis's COMMAND signals (without the cycle), with the names of axis `j` (0…5) in `names`.
fn command(c: &AxisCommand, names: [&'static str; 6]) -> [(&'static str, f64); 6] {
    let v = [
        flag(c.mode, mode::BRAKE),
        flag(c.mode, mode::SERVO),
        flag(c.mode, mode::TORQUE),
        flag(c.mode, mode::DEADMAN),
        c.speed_rad_s(),
        c.torque_nm(),
    ];
    std::array::from_fn(|k| (names[k], v[k]))
}

/// One axis's FEEDBACK signals (without the cycle).
fn feedback(f: &Feedback, names: [&'static str; 8]) -> [(&'static str, f64); 8] {
    let v = [
        f.angle_rad(),
        f.current_a(),
        flag(f.status, status::BRAKE_ON),
        flag(f.status, status::SERVO_ON),
        flag(f.status, status::FAULT),
        flag(f.status, status::WATCHDOG),
        flag(f.status, status::LIMIT),
        flag(f.status, status::DEADMAN),
    ];
    std::array::from_fn(|k| (names[k], v[k]))
}

const COMMAND_NAMES: [&str; 6] = [
    "brake",
    "servo",
    "torque_mode",
    "deadman",
    "speed",
    "torque",
];
const FEEDBACK_NAMES: [&str; 8] = [
    "angle", "current", "brake_on", "servo_on", "fault", "watchdog", "limit", "deadman",
];
const COMMAND_FD_NAMES: [[&str; 6]; 6] = [
    per_axis!("brake"),
    per_axis!("servo"),
    per_axis!("torque_mode"),
    per_axis!("deadman"),
    per_axis!("speed"),
    per_axis!("torque"),
];
const FEEDBACK_FD_NAMES: [[&str; 6]; 8] = [
    per_axis!("angle"),
    per_axis!("current"),
    per_axis!("brake_on"),
    per_axis!("servo_on"),
    per_axis!("fault"),
    per_axis!("watchdog"),
    per_axis!("limit"),
    per_axis!("deadman"),
];

/// The signals of `m`: DBC signal name and value (SI units: rad, rad/s, A, N·m; flags 0/1;
/// enumerations as their wire numbers).
pub fn signals(m: &Message) -> Vec<(&'static str, f64)> {
    match *m {
        Message::Control {
            request,
            watchdog_ms,
        } => vec![
            ("request", f64::from(request as u8)),
            ("watchdog_ms", f64::from(watchdog_ms)),
        ],
        Message::State {
            state,
            fault,
            cycle,
        } => vec![
            ("state", f64::from(state as u8)),
            ("fault", f64::from(fault as u8)),
            ("cycle", f64::from(cycle)),
        ],
        Message::Sync { cycle } => vec![("cycle", f64::from(cycle))],
        Message::Error { code, axis, detail } => vec![
            ("code", f64::from(code as u8)),
            ("axis", f64::from(axis)),
            ("detail", f64::from(detail)),
        ],
        Message::Command(c) => {
            let mut v = command(&c, COMMAND_NAMES).to_vec();
            v.insert(4, ("cycle", f64::from(c.cycle)));
            v
        }
        Message::Feedback(f) => {
            let mut v = feedback(&f, FEEDBACK_NAMES).to_vec();
            v.push(("cycle", f64::from(f.cycle)));
            v
        }
        Message::CommandFd(axes) => {
            let mut v = vec![("cycle", f64::from(axes[0].cycle))];
            for (j, c) in axes.iter().enumerate() {
                v.extend(command(c, COMMAND_FD_NAMES.map(|n| n[j])));
            }
            v
        }
        Message::FeedbackFd(axes) => {
            let mut v = vec![("cycle", f64::from(axes[0].cycle))];
            for (j, f) in axes.iter().enumerate() {
                v.extend(feedback(f, FEEDBACK_FD_NAMES.map(|n| n[j])));
            }
            v
        }
    }
}
