//! The host side of the servo link, sans IO: one state machine ([`Link`]) for the whole
//! session — hearing the controller, the start-up handshake (RELEASE_BRAKES, START_CONTROL,
//! a first complete feedback), the cyclic exchange, STOP/ESTOP and the restart after a reset.
//!
//! In the manner of `quinn-proto`, the link never reads a clock or touches a socket: the
//! caller hands it received frames ([`Link::handle`]) and the time, asks it when it next needs
//! to be woken ([`Link::poll_timeout`], then [`Link::handle_timeout`]) and drains the frames
//! it wants sent ([`Link::poll_transmit`]). What happened comes back as a [`LinkEvent`].
//!
//! A cycle is `SYNC(n)` → six `FEEDBACK(n)` → six `COMMAND(n)`. [`CycleAssembler`] keeps
//! only this cycle's feedback and counts everything else (other cycles, undecodable frames,
//! controller errors) instead of failing: a storm of malformed frames costs counters, never
//! the loop. Nothing here allocates once the link is built.

use std::collections::VecDeque;

use super::vocab::JointState;
use crate::can::protocol::{
    self, Command, ErrorCode, Frame, Message, Request, ServoState, mode, status,
};

/// Timing of the link, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConfig {
    /// Cycle period, s.
    pub period_s: f64,
    /// Command watchdog asked of the controller with each CONTROL request, ms (1…255).
    pub watchdog_ms: u8,
    /// How long to wait for the controller's first STATE heartbeat, s.
    pub listen_timeout_s: f64,
    /// How long each start-up request may take to show its STATE, s.
    pub request_timeout_s: f64,
    /// How long a STOP / ESTOP / shutdown STOP may take to show STOPPED, s.
    pub halt_timeout_s: f64,
    /// Share of the period the feedback of a cycle may take to arrive (0…1).
    pub feedback_window: f64,
    /// Wait for the first complete feedback after START_CONTROL, per attempt, s.
    pub priming_wait_s: f64,
    /// Attempts at a first complete feedback before giving up.
    pub priming_attempts: u16,
}

impl LinkConfig {
    /// The defaults for a cycle period `period_s` (s) and a watchdog of `watchdog_ms` (ms).
    pub fn new(period_s: f64, watchdog_ms: u8) -> Self {
        Self {
            period_s,
            watchdog_ms: watchdog_ms.max(1),
            listen_timeout_s: 3.0,
            request_timeout_s: 0.5,
            halt_timeout_s: 0.05,
            feedback_window: 0.6,
            priming_wait_s: 0.005,
            priming_attempts: 20,
        }
    }
}

/// Why the link failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinkError {
    /// No STATE heartbeat within the listen timeout.
    #[error("the controller is silent (no STATE heartbeat within {timeout_s:.1} s)")]
    Silent {
        /// The timeout, s.
        timeout_s: f64,
    },
    /// The controller answered a request with ERROR(REJECTED).
    #[error("{request:?} refused by the controller (state {state:?})")]
    Refused {
        /// The request.
        request: Request,
        /// The controller's last reported state.
        state: Option<ServoState>,
    },
    /// The expected STATE did not come in time.
    #[error("no STATE {expected:?} within {timeout_ms:.0} ms of {request:?} (last seen {last:?})")]
    NoAnswer {
        /// The request.
        request: Request,
        /// The state it should have led to.
        expected: ServoState,
        /// The controller's last reported state.
        last: Option<ServoState>,
        /// The timeout, ms.
        timeout_ms: f64,
    },
    /// START_CONTROL was accepted but no complete feedback followed.
    #[error("no complete feedback in {attempts} cycles after START_CONTROL")]
    NoFeedback {
        /// Cycles tried.
        attempts: u16,
    },
    /// The bus went off.
    #[error("bus off")]
    BusOff,
    /// The bus failed.
    #[error("bus: {0}")]
    Bus(String),
}

/// What a call into the link produced.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// The controller is in control mode and this is its first complete feedback.
    Connected(JointState),
    /// A cycle's feedback window closed: its complete feedback, or `None`. Answer now with
    /// [`Link::send_commands`] (or do not, to let the controller's watchdog act).
    Cycle {
        /// When the cycle's SYNC was sent, s.
        stamp_s: f64,
        /// The cycle's feedback when complete.
        feedback: Option<JointState>,
    },
    /// A STOP / ESTOP sent while running was acknowledged with this state.
    Acknowledged(Request, ServoState),
    /// The session or a request failed.
    Failed(LinkError),
}

/// The session's phase.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Not connected, no cycles.
    Idle,
    /// Waiting for any STATE heartbeat until `until`.
    Listening { until: f64 },
    /// Sent `request`; waiting for its STATE until `until`.
    Handshake { request: Request, until: f64 },
    /// Waiting for a first complete feedback (attempt `attempt`).
    Priming { attempt: u16 },
    /// Cyclic exchange.
    Running,
    /// Shut down for good.
    Closed,
}

/// A STOP / ESTOP awaiting its STATE while the cycles go on.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pending {
    request: Request,
    expected: ServoState,
    until: f64,
}

/// The state a request leads to.
fn expected(r: Request) -> ServoState {
    match r {
        Request::ReleaseBrakes => ServoState::BrakeRelease,
        Request::StartControl => ServoState::Control,
        Request::Stop | Request::Estop | Request::ResetFault => ServoState::Stopped,
    }
}

/// An ERROR frame's content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerError {
    /// The error code.
    pub code: ErrorCode,
    /// Axis 1…6, 0 for the controller itself.
    pub axis: u8,
    /// Code-specific detail (e.g. ms since the last command for a watchdog).
    pub detail: i32,
}

/// Wake-up timing of the last cycle start, for statistics.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CycleTiming {
    /// How late the SYNC went out against its schedule, s.
    pub late_s: f64,
    /// It was later than one period (the schedule was reset, not caught up).
    pub overrun: bool,
}

/// The host side of the servo link (see the module documentation).
#[derive(Debug, Clone)]
pub struct Link {
    cfg: LinkConfig,
    phase: Phase,
    asm: CycleAssembler,
    cycle: u16,
    /// End of the open feedback window, s.
    window_end: Option<f64>,
    /// When the next SYNC is due, s.
    next_sync: f64,
    pending: Option<Pending>,
    servo: Option<ServoState>,
    servo_fault: protocol::Fault,
    last_error: Option<ControllerError>,
    timing: Option<CycleTiming>,
    tx: VecDeque<Frame>,
}

/// Frames the link may have queued at once: a SYNC, six COMMANDs and a CONTROL, twice over.
const TX_CAPACITY: usize = 16;

impl Link {
    /// An idle link; [`Link::connect`] starts the session.
    pub fn new(cfg: LinkConfig) -> Self {
        Self {
            cfg,
            phase: Phase::Idle,
            asm: CycleAssembler::default(),
            cycle: 0,
            window_end: None,
            next_sync: 0.0,
            pending: None,
            servo: None,
            servo_fault: protocol::Fault::None,
            last_error: None,
            timing: None,
            tx: VecDeque::with_capacity(TX_CAPACITY),
        }
    }

    /// Starts (or restarts) the session at `now` (s): listens for the controller if it was
    /// never heard, resets its fault if it reports one, then releases the brakes, starts
    /// control and waits for a first complete feedback ([`LinkEvent::Connected`]).
    pub fn connect(&mut self, now: f64) {
        self.pending = None;
        self.window_end = None;
        match self.servo {
            None => {
                self.phase = Phase::Listening {
                    until: now + self.cfg.listen_timeout_s,
                }
            }
            Some(ServoState::Fault) => self.begin_handshake(Request::ResetFault, now),
            Some(_) => self.begin_handshake(Request::ReleaseBrakes, now),
        }
    }

    /// Sends STOP or ESTOP at `now` while the cycles go on (the feedback keeps coming);
    /// [`LinkEvent::Acknowledged`] or [`LinkEvent::Failed`] follows. Other requests belong to
    /// [`Link::connect`] and are ignored here.
    pub fn halt(&mut self, request: Request, now: f64) {
        if !matches!(request, Request::Stop | Request::Estop) || self.phase == Phase::Closed {
            return;
        }
        self.queue_control(request);
        self.pending = Some(Pending {
            request,
            expected: expected(request),
            until: now + self.cfg.halt_timeout_s,
        });
    }

    /// Ends the session for good: no more cycles or frames.
    pub fn close(&mut self) {
        self.phase = Phase::Closed;
        self.pending = None;
        self.window_end = None;
    }

    /// Whether the session is closed.
    pub fn is_closed(&self) -> bool {
        self.phase == Phase::Closed
    }

    /// Whether the cyclic exchange runs.
    pub fn is_running(&self) -> bool {
        self.phase == Phase::Running
    }

    /// Whether a STOP / ESTOP awaits its answer.
    pub fn is_halting(&self) -> bool {
        self.pending.is_some()
    }

    /// The controller's last reported state.
    pub fn servo_state(&self) -> Option<ServoState> {
        self.servo
    }

    /// What the controller last said about a fault: its STATE fault code and its last
    /// ERROR frame (other than a refused request), e.g. "watchdog (ERROR watchdog, axis 0,
    /// detail 24)".
    pub fn controller_report(&self) -> Option<String> {
        let e = self.last_error.map(|e| {
            format!(
                "ERROR {:?} on axis {} (detail {})",
                e.code, e.axis, e.detail
            )
        });
        match (self.servo_fault, e) {
            (protocol::Fault::None, None) => None,
            (protocol::Fault::None, Some(e)) => Some(e),
            (f, None) => Some(format!("STATE fault {f:?}")),
            (f, Some(e)) => Some(format!("STATE fault {f:?}, {e}")),
        }
    }

    /// What the link counted.
    pub fn counters(&self) -> LinkCounters {
        self.asm.counters
    }

    /// Counts an error frame the bus reported (as malformed traffic).
    pub fn count_error_frame(&mut self) {
        self.asm.counters.malformed += 1;
    }

    /// The timing of the cycle started by the last call, once (for statistics).
    pub fn take_timing(&mut self) -> Option<CycleTiming> {
        self.timing.take()
    }

    /// Whether frames are awaited before the next timeout (a caller that sleeps otherwise
    /// must listen instead).
    pub fn expects_frames(&self) -> bool {
        self.window_end.is_some()
            || self.pending.is_some()
            || matches!(
                self.phase,
                Phase::Listening { .. } | Phase::Handshake { .. } | Phase::Priming { .. }
            )
    }

    /// When [`Link::handle_timeout`] must next be called, s; `None` when idle or closed.
    pub fn poll_timeout(&self) -> Option<f64> {
        let phase = match self.phase {
            Phase::Idle | Phase::Closed => return None,
            Phase::Listening { until } | Phase::Handshake { until, .. } => Some(until),
            Phase::Priming { .. } => self.window_end,
            Phase::Running => Some(self.window_end.unwrap_or(self.next_sync)),
        };
        match (phase, self.pending) {
            (Some(t), Some(p)) => Some(t.min(p.until)),
            (t, p) => t.or(p.map(|p| p.until)),
        }
    }

    /// The next frame to send.
    pub fn poll_transmit(&mut self) -> Option<Frame> {
        self.tx.pop_front()
    }

    /// Answers the cycle whose feedback just closed with six speed commands (rad/s).
    pub fn send_commands(&mut self, speeds: &[f64; 6]) {
        if self.phase == Phase::Running {
            self.tx.extend(command_frames(self.cycle, speeds));
        }
    }

    /// A bus-level failure seen by the caller at `now`.
    pub fn bus_failed(&mut self, error: LinkError) -> Option<LinkEvent> {
        if matches!(self.phase, Phase::Idle | Phase::Closed) {
            return None;
        }
        if self.phase != Phase::Running {
            self.phase = Phase::Idle;
        }
        self.pending = None;
        Some(LinkEvent::Failed(error))
    }

    /// Takes one received frame at `now` (s).
    pub fn handle(&mut self, frame: &Frame, now: f64) -> Option<LinkEvent> {
        let msg = match protocol::decode(frame) {
            Ok(m) => m,
            Err(_) => {
                self.asm.counters.malformed += 1;
                return None;
            }
        };
        match msg {
            Message::Feedback(f) => {
                if self.window_end.is_some() && self.asm.feedback(&f) {
                    return self.close_window(now);
                }
                if self.window_end.is_none() {
                    self.asm.counters.stale += 1;
                }
                None
            }
            Message::State { state, fault, .. } => {
                self.servo = Some(state);
                self.servo_fault = fault;
                self.on_state(state, now)
            }
            Message::Error { code, axis, detail } => {
                self.asm.counters.controller_errors += 1;
                if code != ErrorCode::Rejected {
                    self.last_error = Some(ControllerError { code, axis, detail });
                }
                if code == ErrorCode::Rejected {
                    return self.on_rejected();
                }
                None
            }
            _ => None,
        }
    }

    /// Acts on the time `now` (s) once [`Link::poll_timeout`] has passed; call again while
    /// it is still due.
    pub fn handle_timeout(&mut self, now: f64) -> Option<LinkEvent> {
        if let Some(p) = self.pending
            && now >= p.until
        {
            self.pending = None;
            return Some(LinkEvent::Failed(LinkError::NoAnswer {
                request: p.request,
                expected: p.expected,
                last: self.servo,
                timeout_ms: self.cfg.halt_timeout_s * 1e3,
            }));
        }
        match self.phase {
            Phase::Listening { until } if now >= until => {
                self.phase = Phase::Idle;
                Some(LinkEvent::Failed(LinkError::Silent {
                    timeout_s: self.cfg.listen_timeout_s,
                }))
            }
            Phase::Handshake { request, until } if now >= until => {
                self.phase = Phase::Idle;
                Some(LinkEvent::Failed(LinkError::NoAnswer {
                    request,
                    expected: expected(request),
                    last: self.servo,
                    timeout_ms: self.cfg.request_timeout_s * 1e3,
                }))
            }
            Phase::Priming { attempt } => match self.window_end {
                Some(end) if now >= end => {
                    self.window_end = None;
                    if attempt >= self.cfg.priming_attempts {
                        self.phase = Phase::Idle;
                        return Some(LinkEvent::Failed(LinkError::NoFeedback {
                            attempts: attempt,
                        }));
                    }
                    self.phase = Phase::Priming {
                        attempt: attempt + 1,
                    };
                    self.begin_sync(now, self.cfg.priming_wait_s);
                    None
                }
                _ => None,
            },
            Phase::Running => match self.window_end {
                Some(end) if now - end > self.window_s() => {
                    // judged more than a window late: the loop was paused (by the host), not
                    // listening, and the feedback may still be on its way; listen once more
                    // for a window from now rather than blame the controller
                    self.asm.counters.paused += 1;
                    self.window_end = Some(now + self.window_s());
                    None
                }
                Some(end) if now >= end => self.close_window(now),
                Some(_) => None,
                None if now >= self.next_sync => {
                    let late = now - self.next_sync;
                    let overrun = late > self.cfg.period_s;
                    self.next_sync = if overrun {
                        now + self.cfg.period_s // do not catch up a burst of missed cycles
                    } else {
                        self.next_sync + self.cfg.period_s
                    };
                    self.timing = Some(CycleTiming {
                        late_s: late,
                        overrun,
                    });
                    self.begin_sync(now, self.window_s());
                    None
                }
                None => None,
            },
            _ => None,
        }
    }

    fn begin_handshake(&mut self, request: Request, now: f64) {
        self.queue_control(request);
        self.phase = Phase::Handshake {
            request,
            until: now + self.cfg.request_timeout_s,
        };
    }

    /// How long a running cycle listens for its feedback, s.
    fn window_s(&self) -> f64 {
        self.cfg.feedback_window * self.cfg.period_s
    }

    fn begin_sync(&mut self, now: f64, window_s: f64) {
        self.cycle = self.cycle.wrapping_add(1);
        let sync = self.asm.begin(self.cycle, now);
        self.tx.push_back(sync);
        self.window_end = Some(now + window_s);
    }

    fn queue_control(&mut self, request: Request) {
        // encoding a CONTROL frame cannot fail
        if let Ok(f) = protocol::encode(&Message::Control {
            request,
            watchdog_ms: self.cfg.watchdog_ms,
        }) {
            self.tx.push_back(f);
        }
    }

    fn on_state(&mut self, state: ServoState, now: f64) -> Option<LinkEvent> {
        if let Some(p) = self.pending
            && state == p.expected
        {
            self.pending = None;
            return Some(LinkEvent::Acknowledged(p.request, state));
        }
        match self.phase {
            Phase::Listening { .. } => {
                match state {
                    ServoState::Fault => self.begin_handshake(Request::ResetFault, now),
                    _ => self.begin_handshake(Request::ReleaseBrakes, now),
                }
                None
            }
            Phase::Handshake { request, .. } if state == expected(request) => {
                match request {
                    Request::ResetFault => self.begin_handshake(Request::ReleaseBrakes, now),
                    Request::ReleaseBrakes => self.begin_handshake(Request::StartControl, now),
                    _ => {
                        self.phase = Phase::Priming { attempt: 1 };
                        self.begin_sync(now, self.cfg.priming_wait_s);
                    }
                }
                None
            }
            _ => None,
        }
    }

    fn on_rejected(&mut self) -> Option<LinkEvent> {
        if let Some(p) = self.pending.take() {
            return Some(LinkEvent::Failed(LinkError::Refused {
                request: p.request,
                state: self.servo,
            }));
        }
        if let Phase::Handshake { request, .. } = self.phase {
            self.phase = Phase::Idle;
            return Some(LinkEvent::Failed(LinkError::Refused {
                request,
                state: self.servo,
            }));
        }
        None
    }

    fn close_window(&mut self, now: f64) -> Option<LinkEvent> {
        self.window_end = None;
        let stamp_s = self.asm.stamp_s();
        let feedback = self.asm.finish();
        match self.phase {
            Phase::Priming { attempt } => match feedback {
                Some(js) => {
                    self.phase = Phase::Running;
                    // answer with zero speed so the controller's watchdog stays fed
                    self.tx.extend(command_frames(self.cycle, &[0.0; 6]));
                    self.next_sync = now + self.cfg.period_s;
                    Some(LinkEvent::Connected(js))
                }
                None => {
                    // not complete before its wait: the timeout starts the next attempt
                    self.phase = Phase::Priming { attempt };
                    self.window_end = Some(now);
                    None
                }
            },
            Phase::Running => Some(LinkEvent::Cycle { stamp_s, feedback }),
            _ => None,
        }
    }
}

/// Counters of what the link saw, for `status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
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

    /// Takes one FEEDBACK frame; true once all six axes of this cycle are in. Another
    /// cycle's feedback is counted as stale.
    pub fn feedback(&mut self, f: &protocol::Feedback) -> bool {
        if f.cycle != self.cycle || !(1..=6).contains(&f.axis) {
            self.counters.stale += 1;
            return self.complete();
        }
        let j = f.axis as usize - 1;
        self.state.q_motor[j] = f.angle_rad();
        self.state.current[j] = f.current_a();
        self.state.controller_fault |= f.status & status::FAULT != 0;
        self.seen |= 1 << j;
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
    use crate::can::protocol::{Fault, Feedback};
    use rand::{RngExt, SeedableRng};

    const PERIOD: f64 = 0.002;

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

    fn state(s: ServoState) -> Frame {
        protocol::encode(&Message::State {
            state: s,
            fault: Fault::None,
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
            let _ = l.handle(&Frame::new(id, &data).unwrap(), t);
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
}
