//! The host side of the servo link, sans IO: which frames one control cycle sends, and how
//! the frames that come back are assembled into one consistent [`JointState`].
//!
//! A cycle is `SYNC(n)` → six `FEEDBACK(n)` → six `COMMAND(n)`. [`CycleAssembler`] accepts
//! any frame the bus delivers, keeps only this cycle's feedback, and counts everything else
//! (other cycles, undecodable frames, controller errors) instead of failing: a storm of
//! malformed frames costs counters, never the loop.

use super::control::JointState;
use crate::can::protocol::{self, Command, DecodeError, Frame, Message, ServoState, mode, status};

/// Counters of what the link saw, for `status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct LinkCounters {
    /// Complete cycles assembled.
    pub cycles: u64,
    /// Cycles whose feedback was incomplete at the deadline.
    pub incomplete: u64,
    /// Frames that did not decode.
    pub malformed: u64,
    /// Feedback frames of another cycle.
    pub stale: u64,
    /// ERROR frames from the controller.
    pub controller_errors: u64,
}

/// Collects one cycle's feedback.
#[derive(Debug, Clone)]
pub struct CycleAssembler {
    cycle: u8,
    seen: u8,
    state: JointState,
    /// What the controller last reported in STATE.
    pub servo_state: Option<ServoState>,
    /// Counters.
    pub counters: LinkCounters,
}

impl Default for CycleAssembler {
    fn default() -> Self {
        Self {
            cycle: 0,
            seen: 0,
            state: JointState {
                q_motor: [0.0; 6],
                current: [0.0; 6],
                stamp_s: 0.0,
                controller_fault: false,
            },
            servo_state: None,
            counters: LinkCounters::default(),
        }
    }
}

impl CycleAssembler {
    /// Starts cycle `cycle` sampled at `now_s`; returns the SYNC frame to send.
    pub fn begin(&mut self, cycle: u16, now_s: f64) -> Frame {
        self.cycle = cycle as u8;
        self.seen = 0;
        self.state = JointState {
            q_motor: [0.0; 6],
            current: [0.0; 6],
            stamp_s: now_s,
            controller_fault: false,
        };
        // encoding a SYNC cannot fail
        protocol::encode(&Message::Sync { cycle }).unwrap_or(EMPTY)
    }

    /// Takes one received frame; true once all six axes of this cycle are in.
    pub fn accept(&mut self, frame: &Frame) -> bool {
        match protocol::decode(frame) {
            Ok(Message::Feedback(f)) if f.cycle == self.cycle => {
                let j = f.axis as usize - 1;
                self.state.q_motor[j] = f.angle_rad();
                self.state.current[j] = f.current_a();
                self.state.controller_fault |= f.status & status::FAULT != 0;
                self.seen |= 1 << j;
            }
            Ok(Message::Feedback(_)) => self.counters.stale += 1,
            Ok(Message::State { state, .. }) => self.servo_state = Some(state),
            Ok(Message::Error { .. }) => self.counters.controller_errors += 1,
            Ok(_) => {}
            Err(DecodeError::UnknownId(_)) | Err(_) => self.counters.malformed += 1,
        }
        self.complete()
    }

    /// Whether all six axes are in.
    pub fn complete(&self) -> bool {
        self.seen == 0b11_1111
    }

    /// The cycle's joint state when complete (counts the cycle), else `None` (counts an
    /// incomplete cycle).
    pub fn finish(&mut self) -> Option<JointState> {
        if self.complete() {
            self.counters.cycles += 1;
            Some(self.state)
        } else {
            self.counters.incomplete += 1;
            None
        }
    }
}

/// A placeholder for encodings that cannot fail (their inputs are in range by construction).
const EMPTY: Frame = match Frame::new_const(0, 0) {
    Some(f) => f,
    None => panic!(),
};

/// The six COMMAND frames answering cycle `cycle`: speed mode, servo on, brake off;
/// speeds (rad/s) are clamped to the field's range.
pub fn command_frames(cycle: u16, speeds: &[f64; 6]) -> [Frame; 6] {
    std::array::from_fn(|j| {
        let counts = (speeds[j] / protocol::SPEED_LSB)
            .round()
            .clamp(i16::MIN as f64, i16::MAX as f64);
        let counts = if counts.is_nan() { 0 } else { counts as i16 };
        let c = Command {
            axis: j as u8 + 1,
            mode: mode::SERVO,
            cycle: cycle as u8,
            speed: counts,
            torque: 0,
        };
        protocol::encode(&Message::Command(c)).unwrap_or(EMPTY)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::protocol::Feedback;
    use rand::{RngExt, SeedableRng};

    fn fb(axis: u8, cycle: u8, angle: i32) -> Frame {
        protocol::encode(&Message::Feedback(Feedback {
            axis,
            angle,
            current: 100,
            status: status::SERVO_ON,
            cycle,
        }))
        .unwrap()
    }

    #[test]
    fn one_cycle_assembles_from_its_own_feedback_only() {
        let mut a = CycleAssembler::default();
        let sync = a.begin(0x1234, 1.5);
        assert_eq!(protocol::decode(&sync), Ok(Message::Sync { cycle: 0x1234 }));
        for axis in 1..=5 {
            assert!(!a.accept(&fb(axis, 0x34, axis as i32 * 1000)));
        }
        assert!(
            !a.accept(&fb(6, 0x33, 1)),
            "another cycle's frame does not count"
        );
        assert_eq!(a.counters.stale, 1);
        assert!(a.accept(&fb(6, 0x34, 6000)));
        let s = a.finish().unwrap();
        assert_eq!(s.stamp_s, 1.5);
        assert!((s.q_motor[5] - 6000.0 * protocol::ANGLE_LSB).abs() < 1e-15);
        assert!((s.current[0] - 0.1).abs() < 1e-12);
        a.begin(0x1235, 1.502);
        a.accept(&fb(1, 0x35, 0));
        assert!(a.finish().is_none());
        assert_eq!(
            a.counters,
            LinkCounters {
                cycles: 1,
                incomplete: 1,
                malformed: 0,
                stale: 1,
                controller_errors: 0
            }
        );
    }

    #[test]
    fn a_storm_of_malformed_frames_only_counts() {
        let mut a = CycleAssembler::default();
        a.begin(7, 0.0);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x5707);
        for _ in 0..100_000 {
            let id = rng.random_range(0..0x800u16);
            let n = rng.random_range(0..=8usize);
            let data: Vec<u8> = (0..n).map(|_| rng.random()).collect();
            a.accept(&Frame::new(id, &data).unwrap());
        }
        assert!(a.counters.malformed > 90_000);
        // the cycle still completes from its real frames
        for axis in 1..=6 {
            a.accept(&fb(axis, 7, 0));
        }
        assert!(a.finish().is_some());
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
}
