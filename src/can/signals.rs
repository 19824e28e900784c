//! A message's fields as the named signals of `docs/pa10.dbc`, in SI units: plain data for
//! comparing our codec with a DBC tool's decoding (`pa10 sim decode`, the cantools check).

use super::protocol::{Message, mode, status};

/// The signals of `m`: DBC signal name and value (SI units: rad, rad/s, A, N·m; flags 0/1;
/// enumerations as their wire numbers).
pub fn signals(m: &Message) -> Vec<(&'static str, f64)> {
    let flag = |bits: u8, bit: u8| f64::from(u8::from(bits & bit != 0));
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
        Message::Command(c) => vec![
            ("brake", flag(c.mode, mode::BRAKE)),
            ("servo", flag(c.mode, mode::SERVO)),
            ("torque_mode", flag(c.mode, mode::TORQUE)),
            ("deadman", flag(c.mode, mode::DEADMAN)),
            ("cycle", f64::from(c.cycle)),
            ("speed", c.speed_rad_s()),
            ("torque", c.torque_nm()),
        ],
        Message::Feedback(f) => vec![
            ("angle", f.angle_rad()),
            ("current", f.current_a()),
            ("brake_on", flag(f.status, status::BRAKE_ON)),
            ("servo_on", flag(f.status, status::SERVO_ON)),
            ("fault", flag(f.status, status::FAULT)),
            ("watchdog", flag(f.status, status::WATCHDOG)),
            ("limit", flag(f.status, status::LIMIT)),
            ("deadman", flag(f.status, status::DEADMAN)),
            ("cycle", f64::from(f.cycle)),
        ],
    }
}
