//! The daemon's core, sans IO: the servo link ([`Link`]), the control cycle
//! ([`Controller`]), the commands clients send and the status they read, in one state machine
//! that takes frames and times and gives frames back.
//!
//! [`Core::handle_frame`], [`Core::handle_timeout`], [`Core::poll_timeout`] and
//! [`Core::poll_transmit`] are all the IO shell needs: the real-time control thread
//! (`runtime`) moves frames between them and a [`CanBus`](crate::can::CanBus) and sleeps; the
//! simulated-time harness (`sim::lockstep`) moves them to a simulated controller and advances
//! a clock. Every client command enters through [`Core::submit`] as a typed [`Command`] and
//! is refused with a typed [`CommandError`] that changes nothing. There is one fault: the
//! controller's [`Activity::Faulted`] (link failures and emergency stops are put there too),
//! or, before the first connection, the link's start-up failure.
//!
//! Slow work never happens here: a move is planned from a [`PlanBasis`] outside the lock the
//! control thread shares with the API, and handed over with [`Command::Start`]; a model file
//! is parsed outside it and handed over with [`Command::LoadModel`].

use std::sync::Arc;

pub use crate::daemon::wire::Status;
pub use commands::{ClientId, Command, LOCAL, PlanBasis};

mod commands;
mod status;

use super::config::Settings;
use super::control::{
    Activity, CommandError, Controller, Fault, JointState, LoopParams, check_payload,
};
use super::link::{Link, LinkConfig, LinkError, LinkEvent};
use super::timing::{CycleStats, Histogram};
use crate::can::bus::{BusError, BusEvent};
use crate::can::protocol::{CanFrame, Request, ServoState};
use crate::model::Model;
use crate::record::{CycleSample, Event, Record, RecordConfig, RecordTap, RecorderStats};

/// How far the shutdown has come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Exit {
    Running,
    /// Decelerating to rest before STOP.
    Stopping,
    /// STOP sent; closing on its answer.
    Halting,
}

/// The sans-IO daemon (see the module documentation).
#[derive(Debug)]
pub struct Core {
    link: Link,
    model: Arc<Model>,
    params: LoopParams,
    ctl: Option<Controller>,
    /// A start-up failure, before any controller exists.
    failure: Option<LinkError>,
    last: Option<JointState>,
    stats: CycleStats,
    jitter: Histogram,
    compute: Histogram,
    lock_wait: Histogram,
    now_s: f64,
    exit: Exit,
    /// A STOP or ESTOP went out since the last connection.
    stop_sent: bool,
    /// The link is re-running its handshake after a reset.
    restarting: bool,
    /// Cycles started.
    syncs: u64,
    /// The only directory `load_model` reads from.
    model_dir: std::path::PathBuf,
    /// The client holding the motion lease.
    lease: Option<ClientId>,
    /// The recording in progress.
    tap: Option<RecordTap>,
    /// The last recording's counters (kept after it stopped, for `status`).
    recorded: Option<Arc<RecorderStats>>,
    /// The activity of the last cycle (recordings log changes).
    last_mode: crate::record::Mode,
    /// Where and how recordings are written.
    record_cfg: RecordConfig,
    /// How late the last SYNC went out, µs.
    last_late_us: f64,
    /// The last cycle, as recorded.
    last_sample: Option<CycleSample>,
    /// The file the model in force came from, and when it came into force (s).
    model_file: (String, f64),
    /// The last refused request.
    last_refusal: Option<crate::daemon::wire::RefusalStatus>,
}

impl Core {
    /// A core for `model` with loop parameters `params` and link timing `link`;
    /// `bus_load` (0…1) is the configured rate's worst-case bus load, for `status`.
    pub fn new(
        model: impl Into<Arc<Model>>,
        params: LoopParams,
        link: LinkConfig,
        bus_load: f64,
    ) -> Self {
        Self {
            link: Link::new(link),
            model: model.into(),
            params,
            ctl: None,
            failure: None,
            last: None,
            stats: CycleStats {
                rate_hz: 1.0 / link.period_s,
                framing: link.framing,
                bus_load_pct: bus_load * 100.0,
                ..Default::default()
            },
            jitter: Histogram::default(),
            compute: Histogram::default(),
            lock_wait: Histogram::default(),
            now_s: 0.0,
            exit: Exit::Running,
            stop_sent: false,
            restarting: false,
            syncs: 0,
            model_dir: std::path::PathBuf::from(super::config::DEFAULT_MODEL_DIR),
            lease: None,
            tap: None,
            recorded: None,
            last_mode: crate::record::Mode::Holding,
            record_cfg: RecordConfig::default(),
            last_late_us: 0.0,
            last_sample: None,
            model_file: ("(built in)".into(), 0.0),
            last_refusal: None,
        }
    }

    /// The core validated settings describe.
    pub fn from_config(settings: &Settings) -> Self {
        let mut core = Self::new(
            settings.model.clone(),
            settings.control.clone(),
            settings.link,
            settings.bus_load,
        );
        core.model_dir = settings.api.model_dir.clone();
        core.record_cfg = settings.record.clone();
        core.model_file = (settings.model_path.display().to_string(), 0.0);
        core
    }

    /// The only directory `load_model` reads from.
    pub fn model_dir(&self) -> &std::path::Path {
        &self.model_dir
    }

    /// Where and how recordings are written.
    pub fn record_config(&self) -> &RecordConfig {
        &self.record_cfg
    }

    /// Ends the recording in progress (the writer then closes its file); its counters, to
    /// wait on `finished`.
    pub fn stop_recording(&mut self) -> Option<Arc<RecorderStats>> {
        self.tap.as_ref()?;
        self.log_event("recording", "stopped: the daemon is shutting down");
        self.tap = None;
        self.recorded.clone()
    }

    /// The counters of the recording in progress, or of the last one.
    pub fn recording_stats(&self) -> Option<Arc<RecorderStats>> {
        self.recorded.clone()
    }

    /// The last cycle, as a recording has it (the live view).
    pub fn last_sample(&self) -> Option<CycleSample> {
        self.last_sample
    }

    /// Whether a recording is in progress.
    pub fn is_recording(&self) -> bool {
        self.tap.is_some()
    }

    /// Records an event at the core's time (between cycles).
    fn log_event(&mut self, kind: &'static str, text: impl Into<std::borrow::Cow<'static, str>>) {
        self.log_event_at(self.now_s, kind, text);
    }

    /// Records an event stamped `stamp_s` (a cycle's: the file's log times never go back).
    fn log_event_at(
        &mut self,
        stamp_s: f64,
        kind: &'static str,
        text: impl Into<std::borrow::Cow<'static, str>>,
    ) {
        if let Some(tap) = self.tap.as_mut() {
            tap.push(Record::Event(Event {
                stamp_s,
                kind: kind.into(),
                text: text.into(),
            }));
        }
    }

    /// Starts the session at `now` (s).
    pub fn start(&mut self, now: f64) {
        self.now_s = now;
        self.link.connect(now);
    }

    /// Takes one frame received at `now` (s).
    pub fn handle_frame(&mut self, frame: &CanFrame, now: f64) {
        self.now_s = self.now_s.max(now);
        let ev = self.link.handle(frame, now);
        self.on(ev, now);
    }

    /// Takes a bus event other than a frame (or a bus error) at `now` (s).
    pub fn handle_bus(&mut self, event: Result<BusEvent, BusError>, now: f64) {
        self.now_s = self.now_s.max(now);
        let error = match event {
            Ok(BusEvent::Frame(f)) => return self.handle_frame(&f, now),
            Ok(BusEvent::ErrorFrame { .. }) => {
                self.link.count_error_frame();
                return;
            }
            Err(BusError::Timeout) => return,
            Ok(BusEvent::BusOff) | Err(BusError::BusOff) => LinkError::BusOff,
            Err(e) => LinkError::Bus(e.to_string()),
        };
        let ev = self.link.bus_failed(error);
        self.on(ev, now);
    }

    /// Acts on everything due at `now` (s).
    pub fn handle_timeout(&mut self, now: f64) {
        self.now_s = self.now_s.max(now);
        // a bounded loop: each pass consumes one due deadline
        for _ in 0..8 {
            match self.link.poll_timeout() {
                Some(t) if t <= now => {
                    let ev = self.link.handle_timeout(now);
                    if let Some(timing) = self.link.take_timing() {
                        self.syncs += 1;
                        self.jitter.record(timing.late_s * 1e6);
                        self.last_late_us = timing.late_s * 1e6;
                        self.stats.overruns += timing.overrun as u64;
                    }
                    self.on(ev, now);
                }
                _ => break,
            }
        }
    }

    /// When [`Core::handle_timeout`] must next be called, s; `None` once closed (or idle
    /// after a failed start).
    pub fn poll_timeout(&self) -> Option<f64> {
        self.link.poll_timeout()
    }

    /// Whether frames are awaited before the next timeout.
    pub fn expects_frames(&self) -> bool {
        self.link.expects_frames()
    }

    /// The next frame to send.
    pub fn poll_transmit(&mut self) -> Option<CanFrame> {
        self.link.poll_transmit()
    }

    /// Records the compute time of the cycle just answered (µs, measured by the shell).
    pub fn record_compute(&mut self, us: f64) {
        self.compute.record(us);
    }

    /// Records a wait of the control thread for the core's lock, µs (measured by the shell
    /// when a client held it).
    pub fn record_lock_wait(&mut self, us: f64) {
        self.lock_wait.record(us);
        self.stats.lock_waits += 1;
    }

    /// Cycles started (SYNC sent) so far.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// Cycles answered so far.
    pub fn cycles(&self) -> u64 {
        self.stats.cycles
    }

    /// Whether the link is closed (after a shutdown).
    pub fn is_closed(&self) -> bool {
        self.link.is_closed()
    }

    /// Whether the servo controller reached control mode (the controller exists).
    pub fn is_ready(&self) -> bool {
        self.ctl.is_some()
    }

    /// The start-up failure, when the first connection failed.
    pub fn startup_failure(&self) -> Option<&LinkError> {
        self.failure.as_ref().filter(|_| self.ctl.is_none())
    }

    /// The control cycle, once connected.
    pub fn controller(&self) -> Option<&Controller> {
        self.ctl.as_ref()
    }

    /// The last time the core saw, s.
    pub fn now_s(&self) -> f64 {
        self.now_s
    }

    /// The one fault: the controller's, or the start-up failure.
    pub fn fault(&self) -> Option<Fault> {
        match &self.ctl {
            Some(c) => match c.activity() {
                Activity::Faulted(f) => Some(f.clone()),
                _ => None,
            },
            None => self.failure.clone().map(Fault::Link),
        }
    }

    fn ready_controller(&self) -> Result<&Controller, CommandError> {
        if self.exit != Exit::Running {
            return Err(CommandError::ShuttingDown);
        }
        if self.restarting {
            return Err(CommandError::NotReady(
                "restarting the servo controller".into(),
            ));
        }
        self.ctl.as_ref().ok_or_else(|| {
            CommandError::NotReady(
                self.failure
                    .as_ref()
                    .map_or("starting".to_string(), |f| f.to_string()),
            )
        })
    }

    /// As [`Core::plan_basis`], refused when another client holds the motion lease.
    pub fn plan_basis_for(&self, client: ClientId) -> Result<PlanBasis, CommandError> {
        if self.lease.is_some_and(|holder| holder != client) {
            return Err(CommandError::Leased);
        }
        self.plan_basis()
    }

    /// What a move would be planned from now; refused unless a move could start.
    pub fn plan_basis(&self) -> Result<PlanBasis, CommandError> {
        let c = self.ready_controller()?;
        c.ready_for_move()?;
        Ok(PlanBasis {
            model: c.model_arc().clone(),
            from: c.setpoint().q,
            limits: *c.limits(),
        })
    }

    /// Applies an in-process command (as [`LOCAL`]); see [`Core::submit_from`].
    pub fn submit(&mut self, cmd: Command) -> Result<(), CommandError> {
        self.submit_from(LOCAL, cmd)
    }

    /// Applies `client`'s command at the core's current time; a refusal changes nothing.
    /// While another client holds the motion lease only `Stop`, `Estop`, `Shutdown` and
    /// the lease commands are accepted.
    pub fn submit_from(&mut self, client: ClientId, cmd: Command) -> Result<(), CommandError> {
        let name = cmd.name();
        let held = self.lease == Some(client);
        let r = self.apply(client, cmd);
        // streams at up to the cycle rate, and every polling client's goodbye, would flood
        // the event channel: a disconnection is news when it ends a lease
        let news = match name {
            "servo" | "jog" => false,
            "disconnected" => held,
            _ => true,
        };
        if r.is_ok() && news {
            self.log_event("command", name);
        }
        r
    }

    fn apply(&mut self, client: ClientId, cmd: Command) -> Result<(), CommandError> {
        let now = self.now_s;
        let always = matches!(
            cmd,
            Command::Stop
                | Command::Estop
                | Command::Shutdown
                | Command::Release
                | Command::Disconnected
        );
        if !always && self.lease.is_some_and(|holder| holder != client) {
            return Err(CommandError::Leased);
        }
        match cmd {
            Command::Start { mv, basis } => {
                self.ready_controller()?.ready_for_move()?;
                let Some(c) = self.ctl.as_mut() else {
                    return Err(CommandError::NotReady("starting".into()));
                };
                if !Arc::ptr_eq(&basis.model, c.model_arc()) || basis.from != c.setpoint().q {
                    return Err(CommandError::Stale);
                }
                c.start_move(mv, now)
            }
            Command::Stop => {
                if let Some(c) = self.ctl.as_mut() {
                    c.stop();
                }
                Ok(())
            }
            Command::Estop => {
                self.link.halt(Request::Estop, now);
                self.stop_sent = true;
                if let Some(c) = self.ctl.as_mut() {
                    c.halt(Fault::EmergencyStop);
                }
                Ok(())
            }
            Command::Reset => {
                if self.exit != Exit::Running {
                    return Err(CommandError::ShuttingDown);
                }
                if let Some(c) = self.ctl.as_mut() {
                    c.reset();
                }
                self.failure = None;
                let in_control = self.link.servo_state() == Some(ServoState::Control);
                if self.stop_sent || !in_control || !self.link.is_running() {
                    self.restarting = true;
                    self.link.connect(now);
                }
                Ok(())
            }
            Command::SetPayload { newtons, com } => match self.ctl.as_mut() {
                Some(c) => c.set_payload(newtons, com),
                None => {
                    check_payload(newtons, &com)?;
                    self.params.payload_n = newtons;
                    self.params.payload_com = com;
                    Ok(())
                }
            },
            Command::SetTool(tool) => {
                let model = match &self.ctl {
                    Some(c) => c.model_arc().clone(),
                    None => self.model.clone(),
                };
                let m = model
                    .with_tool(&tool)
                    .map_err(|e| CommandError::Invalid(format!("tool: {e}")))?;
                match self.ctl.as_mut() {
                    Some(c) => c.load_model(m),
                    None => {
                        self.model = Arc::new(m);
                        Ok(())
                    }
                }
            }
            Command::LoadModel { model, file } => {
                match self.ctl.as_mut() {
                    Some(c) => c.load_model(model)?,
                    None => self.model = model,
                }
                self.model_file = (file, now);
                Ok(())
            }
            Command::FollowTrajectory {
                points,
                tolerances,
                basis,
            } => {
                self.ready_controller()?;
                let c = self.controller_mut()?;
                if let Some(b) = basis
                    && (!Arc::ptr_eq(&b.model, c.model_arc()) || b.from != c.setpoint().q)
                {
                    return Err(CommandError::Stale);
                }
                c.start_trajectory(&points, tolerances).map(|_| ())
            }
            Command::SetSpeedScaling(f) => {
                self.ready_controller()?;
                self.controller_mut()?.set_speed_scaling(f)
            }
            Command::Stream(st) => {
                self.ready_controller()?;
                self.controller_mut()?.stream(st, now)
            }
            Command::Acquire => {
                self.lease = Some(client);
                Ok(())
            }
            Command::Release | Command::Disconnected => {
                if self.lease == Some(client) {
                    self.lease = None;
                    if matches!(cmd, Command::Disconnected)
                        && let Some(c) = self.ctl.as_mut()
                    {
                        c.stop();
                    }
                }
                Ok(())
            }
            Command::Record(tap) => {
                if self.tap.is_some() {
                    return Err(CommandError::Invalid(
                        "a recording is running; record_stop first".into(),
                    ));
                }
                self.recorded = Some(tap.stats.clone());
                self.tap = Some(*tap);
                self.log_event("recording", "started");
                Ok(())
            }
            Command::RecordStop => {
                self.log_event("recording", "stopped by a client");
                self.tap = None;
                Ok(())
            }
            Command::Shutdown => {
                match self.ctl.as_mut() {
                    Some(c) if self.link.is_running() => {
                        c.stop();
                        self.exit = Exit::Stopping;
                    }
                    _ => self.link.close(),
                }
                Ok(())
            }
        }
    }

    fn controller_mut(&mut self) -> Result<&mut Controller, CommandError> {
        self.ctl
            .as_mut()
            .ok_or_else(|| CommandError::NotReady("starting".into()))
    }

    /// The client holding the motion lease.
    pub fn lease(&self) -> Option<ClientId> {
        self.lease
    }

    fn on(&mut self, ev: Option<LinkEvent>, now: f64) {
        match ev {
            None => {}
            Some(LinkEvent::Connected(js)) => {
                self.last = Some(js);
                match self.ctl.as_mut() {
                    None => {
                        self.ctl = Some(Controller::new(
                            self.model.clone(),
                            self.params.clone(),
                            &js,
                        ))
                    }
                    Some(c) => c.resync(&js),
                }
                self.failure = None;
                self.stop_sent = false;
                self.restarting = false;
            }
            Some(LinkEvent::Cycle { stamp_s, feedback }) => self.cycle(stamp_s, feedback, now),
            Some(LinkEvent::Acknowledged(..)) if self.exit == Exit::Halting => self.link.close(),
            Some(LinkEvent::Acknowledged(..)) => {}
            Some(LinkEvent::Failed(e)) => {
                if self.exit == Exit::Halting {
                    self.link.close();
                    return;
                }
                tracing::error!(error = %e, "servo link");
                self.restarting = false;
                match self.ctl.as_mut() {
                    Some(c) => {
                        c.halt(Fault::Link(e));
                        if !self.stop_sent && self.link.is_running() {
                            self.link.halt(Request::Stop, now);
                            self.stop_sent = true;
                        }
                    }
                    None => self.failure = Some(e),
                }
            }
        }
    }

    /// One cycle: feedback in, the controller's speeds (or a STOP) out. No allocation.
    fn cycle(&mut self, stamp_s: f64, feedback: Option<JointState>, now: f64) {
        if let Some(js) = feedback {
            self.last = Some(js);
        }
        self.stats.cycles += 1;
        let Some(c) = self.ctl.as_mut() else {
            return;
        };
        if self.exit == Exit::Halting {
            return;
        }
        let speeds = c.step(stamp_s, feedback.as_ref());
        let faulted = matches!(c.activity(), Activity::Faulted(_));
        let still = matches!(c.activity(), Activity::Holding | Activity::Faulted(_));
        self.record_cycle(stamp_s, feedback.is_some());
        if self.exit == Exit::Stopping && still {
            self.exit = Exit::Halting;
            if self.stop_sent {
                self.link.close();
            } else {
                self.link.halt(Request::Stop, now);
            }
            return;
        }
        if faulted {
            if !self.stop_sent {
                // a controlled stop of the servo; the brakes follow
                self.link.halt(Request::Stop, now);
                self.stop_sent = true;
                if let Some(f) = self.fault() {
                    tracing::error!(fault = %f, "fault: the arm is stopped until reset");
                }
            }
        } else {
            self.link.send_commands(&speeds);
        }
    }
}

#[cfg(test)]
mod tests;
