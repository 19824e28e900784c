//! The host side of the servo link, sans IO: one state machine ([`Link`]) for the whole
//! session — hearing the controller, the start-up handshake (RELEASE_BRAKES, START_CONTROL,
//! a first complete feedback), the cyclic exchange, STOP/ESTOP and the restart after a reset.
//!
//! In the manner of `quinn-proto`, the link never reads a clock or touches a socket: the
//! caller hands it received frames ([`Link::handle`]) and the time, asks it when it next needs
//! to be woken ([`Link::poll_timeout`], then [`Link::handle_timeout`]) and drains the frames
//! it wants sent ([`Link::poll_transmit`]). What happened comes back as a [`LinkEvent`].
//!
//! A cycle is `SYNC(n)` → six `FEEDBACK(n)` → six `COMMAND(n)` on classic CAN, `SYNC(n)` →
//! `FEEDBACK_FD(n)` → `COMMAND_FD(n)` on CAN FD ([`LinkConfig::framing`]; feedback of either
//! format is assembled, commands go out in the configured one). [`CycleAssembler`] keeps
//! only this cycle's feedback and counts everything else (other cycles, undecodable frames,
//! controller errors) instead of failing: a storm of malformed frames costs counters, never
//! the loop. Nothing here allocates once the link is built.

use std::collections::VecDeque;

use super::vocab::JointState;
pub use assembly::{CycleAssembler, LinkCounters, command_frame_fd, command_frames};

mod assembly;
use crate::can::protocol::{self, CanFrame, ErrorCode, Framing, Message, Request, ServoState};

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
    /// The cyclic frames' format: six classic COMMAND frames or one COMMAND_FD per cycle.
    pub framing: Framing,
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
            framing: Framing::Classic,
        }
    }

    /// The same timing with `framing`'s cyclic frames.
    pub fn with_framing(self, framing: Framing) -> Self {
        Self { framing, ..self }
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
    servo_fault: protocol::FaultCode,
    last_error: Option<ControllerError>,
    timing: Option<CycleTiming>,
    tx: VecDeque<CanFrame>,
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
            servo_fault: protocol::FaultCode::None,
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
            (protocol::FaultCode::None, None) => None,
            (protocol::FaultCode::None, Some(e)) => Some(e),
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
    pub fn poll_transmit(&mut self) -> Option<CanFrame> {
        self.tx.pop_front()
    }

    /// Answers the cycle whose feedback just closed with six speed commands (rad/s).
    pub fn send_commands(&mut self, speeds: &[f64; 6]) {
        if self.phase == Phase::Running {
            self.queue_commands(speeds);
        }
    }

    fn queue_commands(&mut self, speeds: &[f64; 6]) {
        match self.cfg.framing {
            Framing::Classic => self.tx.extend(command_frames(self.cycle, speeds)),
            Framing::Fd => self.tx.push_back(command_frame_fd(self.cycle, speeds)),
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
    pub fn handle(&mut self, frame: &CanFrame, now: f64) -> Option<LinkEvent> {
        let msg = match protocol::decode(frame) {
            Ok(m) => m,
            Err(_) => {
                self.asm.counters.malformed += 1;
                return None;
            }
        };
        match msg {
            Message::Feedback(f) => self.feedback(&[f], now),
            Message::FeedbackFd(axes) => self.feedback(&axes, now),
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

    /// One cycle's feedback frame (one axis, or all six).
    fn feedback(&mut self, axes: &[protocol::Feedback], now: f64) -> Option<LinkEvent> {
        if self.window_end.is_none() {
            self.asm.counters.stale += 1;
            return None;
        }
        if self.asm.feedback(axes) {
            return self.close_window(now);
        }
        None
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
                    self.queue_commands(&[0.0; 6]);
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

#[cfg(test)]
mod tests;
