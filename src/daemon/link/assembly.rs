//! One cycle's frames: [`CycleAssembler`] gathers this cycle's six FEEDBACK frames (or its one
//! FEEDBACK_FD) into a [`JointState`] in SI units and counts everything else ([`LinkCounters`]);
//! [`command_frames`] encodes the six COMMAND frames of a cycle's speeds, [`command_frame_fd`]
//! the one COMMAND_FD frame. No allocation.

use crate::can::protocol::{self, AxisCommand, CanFrame, Message, status};
use crate::daemon::vocab::JointState;

/// Counters of what the link saw, for `status`.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
pub struct LinkCounters {
    /// Complete cycles assembled.
    pub cycles: u64,
    /// Cycles whose feedback was incomplete at the deadline.
    pub incomplete: u64,
    /// Feedback windows the loop judged more than a window late (it was paused, not
    /// listening) and listened to once more instead of closing.
    pub paused: u64,
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
            counters: LinkCounters::default(),
        }
    }
}

impl CycleAssembler {
    /// Starts cycle `cycle` sampled at `now_s`; returns the SYNC frame to send.
    pub fn begin(&mut self, cycle: u16, now_s: f64) -> CanFrame {
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

    /// Takes one frame's feedback — one axis (FEEDBACK) or all six (FEEDBACK_FD); true once
    /// all six axes of this cycle are in. A frame of another cycle counts once as stale.
    pub fn feedback(&mut self, axes: &[protocol::Feedback]) -> bool {
        if axes
            .iter()
            .any(|f| f.cycle != self.cycle || !(1..=6).contains(&f.axis))
        {
            self.counters.stale += 1;
            return self.complete();
        }
        for f in axes {
            let j = f.axis as usize - 1;
            self.state.q_motor[j] = f.angle_rad();
            self.state.current[j] = f.current_a();
            self.state.controller_fault |= f.status & status::FAULT != 0;
            self.seen |= 1 << j;
        }
        self.complete()
    }

    /// When this cycle was sampled, s.
    pub fn stamp_s(&self) -> f64 {
        self.state.stamp_s
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
const EMPTY: CanFrame = match CanFrame::new_const(0, 0) {
    Some(f) => f,
    None => panic!(),
};

/// The six axes' speed-mode commands of cycle `cycle` (servo on, brake off; speeds in rad/s
/// clamped to the field's range).
fn commands(cycle: u16, speeds: &[f64; 6]) -> [AxisCommand; 6] {
    std::array::from_fn(|j| AxisCommand::speed_saturating(j as u8 + 1, cycle as u8, speeds[j]))
}

/// The COMMAND_FD frame answering cycle `cycle` on CAN FD: the six commands of
/// [`command_frames`] in one frame.
pub fn command_frame_fd(cycle: u16, speeds: &[f64; 6]) -> CanFrame {
    protocol::encode(&Message::CommandFd(commands(cycle, speeds))).unwrap_or(EMPTY)
}

/// The six COMMAND frames answering cycle `cycle`: speed mode, servo on, brake off;
/// speeds (rad/s) are clamped to the field's range.
pub fn command_frames(cycle: u16, speeds: &[f64; 6]) -> [CanFrame; 6] {
    commands(cycle, speeds).map(|c| protocol::encode(&Message::Command(c)).unwrap_or(EMPTY))
}
