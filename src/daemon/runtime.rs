//! The real-time shell around the sans-IO [`Core`]: a control thread that moves frames
//! between the core and a [`CanBus`] and sleeps until the core's next deadline, and the
//! [`Daemon`] handle that starts and stops it.
//!
//! The thread owns the bus; clients reach the core through the same mutex the thread takes
//! for each event, held for microseconds (moves are planned and model files parsed outside
//! it, see `core`). Between cycles, when the core expects no frame, the thread sleeps with
//! `std::thread::sleep` (precise) and then drains what arrived; while it expects frames it
//! waits on the bus with an absolute deadline.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::config::Settings;
use super::core::{Command, Core};
use super::link::LinkError;
use crate::can::bus::{BusError, CanBus};

/// Why the daemon could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DaemonError {
    /// The bus failed.
    #[error("bus: {0}")]
    Bus(#[from] BusError),
    /// The servo controller did not reach control mode.
    #[error("servo controller: {0}")]
    Link(#[from] LinkError),
    /// No answer in time.
    #[error("servo controller: not in control mode within {0:.0} s")]
    Timeout(f64),
    /// The control thread could not be started.
    #[error("control thread: {0}")]
    Thread(String),
}

/// The core as the control thread and its clients share it: a priority-inheriting mutex (a
/// Linux PI futex). A client thread at normal priority that holds it when the SCHED_FIFO
/// control thread asks runs at the control thread's priority until it lets go, so a busy
/// host cannot preempt the holder and stall the loop behind it (a priority inversion: with
/// `std::sync::Mutex` a real-time run with hostile clients on a loaded host faulted on stale
/// feedback after 4 ms compute-time stalls). It does not poison: a panicked holder releases
/// it and the arm's supervision goes on.
pub type SharedCore = priority_inheriting_lock::PriorityInheritingLock<Core>;

/// A guard on [`SharedCore`].
pub type CoreGuard<'a> = priority_inheriting_lock::PriorityInheritingLockGuard<'a, Core>;

/// Shares `core` between the control thread and its clients.
pub fn share(core: Core) -> Arc<SharedCore> {
    Arc::new(SharedCore::new(core))
}

/// Locks the core (blocking; boosts the holder to the caller's priority meanwhile).
pub fn lock(m: &SharedCore) -> CoreGuard<'_> {
    m.lock()
}

/// Locks the core for the control thread and, when a client held it, records how long the
/// thread waited (`status.cycle.lock_wait_us`: the evidence that a client cannot stall the
/// loop).
fn lock_rt(m: &SharedCore) -> CoreGuard<'_> {
    if let Some(g) = m.try_lock() {
        return g;
    }
    let t = Instant::now();
    let mut g = m.lock();
    g.record_lock_wait(t.elapsed().as_secs_f64() * 1e6);
    g
}

/// A running daemon core on a real bus, in real time.
pub struct Daemon {
    /// The core (the API's handle).
    pub core: Arc<SharedCore>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// How long [`Daemon::start`] waits for control mode, s.
const START_TIMEOUT_S: f64 = 5.0;

impl Daemon {
    /// Starts the control thread on `bus` and waits until the servo controller is in control
    /// mode (or the start fails). The bus is first used on the control thread (a SocketCAN
    /// socket registers with that thread's reactor then).
    pub fn start<B: CanBus + 'static>(settings: &Settings, bus: B) -> Result<Self, DaemonError> {
        if settings.realtime.mlockall {
            match super::realtime::lock_memory() {
                Ok(()) => tracing::info!("memory locked (mlockall)"),
                Err(e) => tracing::warn!(error = %e, "mlockall not permitted; memory may page"),
            }
        }
        let core = share(Core::from_config(settings));
        let stop = Arc::new(AtomicBool::new(false));
        let prio = settings.realtime.sched_fifo_priority;
        let thread = {
            let (core, stop) = (core.clone(), stop.clone());
            std::thread::Builder::new()
                .name("pa10d-control".into())
                .spawn(move || control_thread(bus, core, stop, prio))
                .map_err(|e| DaemonError::Thread(e.to_string()))?
        };
        let mut d = Daemon {
            core,
            stop,
            thread: Some(thread),
        };
        let end = Instant::now() + Duration::from_secs_f64(START_TIMEOUT_S);
        loop {
            let (ready, failure) = {
                let core = lock(&d.core);
                (core.is_ready(), core.startup_failure().cloned())
            };
            if ready {
                return Ok(d);
            }
            if let Some(e) = failure {
                d.shutdown();
                return Err(e.into());
            }
            if d.thread.as_ref().is_some_and(|t| t.is_finished()) || Instant::now() > end {
                d.shutdown();
                return Err(DaemonError::Timeout(START_TIMEOUT_S));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Brings the arm to rest, stops the servo (brakes on) and joins the control thread.
    pub fn shutdown(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// How long a shutdown may take once asked, s (then the thread leaves regardless).
const SHUTDOWN_LIMIT_S: f64 = 10.0;

fn control_thread<B: CanBus>(
    mut bus: B,
    core: Arc<SharedCore>,
    stop: Arc<AtomicBool>,
    prio: Option<u8>,
) {
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            tracing::error!(error = %e, "control runtime");
            return;
        }
    };
    if let Some(prio) = prio {
        match super::realtime::set_fifo(prio) {
            Ok(()) => tracing::info!(priority = prio, "control thread runs SCHED_FIFO"),
            Err(e) => {
                tracing::warn!(priority = prio, error = %e, "SCHED_FIFO not permitted; running at normal priority")
            }
        }
    }
    let t0 = Instant::now();
    let secs = |t: Instant| t.duration_since(t0).as_secs_f64();
    lock_rt(&core).start(0.0);
    let mut shutdown_at: Option<Instant> = None;
    let mut cycle_start = Instant::now();
    loop {
        if shutdown_at.is_none() && stop.load(Ordering::SeqCst) {
            shutdown_at = Some(Instant::now());
            let _ = lock_rt(&core).submit(Command::Shutdown);
        }
        if shutdown_at.is_some_and(|t| t.elapsed().as_secs_f64() > SHUTDOWN_LIMIT_S) {
            tracing::error!("shutdown did not complete in time; leaving the control thread");
            return;
        }
        let (deadline, listen, cycles, syncs) = {
            let c = lock_rt(&core);
            if c.is_closed() {
                return;
            }
            (c.poll_timeout(), c.expects_frames(), c.cycles(), c.syncs())
        };
        let Some(deadline) = deadline else {
            // idle after a failed start: wait for a reset or the stop
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        let due = t0 + Duration::from_secs_f64(deadline.max(0.0));
        let woke;
        if listen {
            let wait = due.saturating_duration_since(Instant::now());
            let ev = rt.block_on(bus.recv(wait));
            woke = Instant::now();
            let now = secs(woke);
            let mut c = lock_rt(&core);
            if !matches!(ev, Err(BusError::Timeout)) {
                c.handle_bus(ev, now);
                // after a late wake-up (a host pause) the rest of the cycle's feedback is
                // already queued: take it before the deadline is judged, or the pause
                // would be blamed on the controller
                drain_ready(&rt, &mut bus, &mut c, now);
            }
            c.handle_timeout(now);
        } else {
            let now = Instant::now();
            if now < due {
                std::thread::sleep(due - now);
            }
            woke = Instant::now();
            let now = secs(woke);
            // what arrived while asleep (heartbeats, stray frames), then the deadline
            let mut c = lock_rt(&core);
            drain_ready(&rt, &mut bus, &mut c, now);
            c.handle_timeout(now);
        }
        flush(&rt, &mut bus, &core, secs(Instant::now()));
        let mut c = lock_rt(&core);
        if c.syncs() > syncs {
            cycle_start = woke;
        }
        if c.cycles() > cycles {
            // compute time: from the wake-up that sent the SYNC to the commands sent
            c.record_compute(cycle_start.elapsed().as_secs_f64() * 1e6);
        }
    }
}

/// Hands the core what the bus holds now (at most a burst's worth, so a flood cannot keep
/// the thread from its deadline).
fn drain_ready<B: CanBus>(rt: &tokio::runtime::Runtime, bus: &mut B, core: &mut Core, now: f64) {
    for _ in 0..64 {
        match rt.block_on(ready_now(bus)) {
            None => break,
            Some(ev) => core.handle_bus(ev, now),
        }
    }
}

/// A bus event that is ready now, without waiting: `bus.recv(Duration::ZERO)` would wait for
/// the timer's next tick (tokio's timers have a 1 ms resolution), a whole feedback window.
async fn ready_now<B: CanBus>(bus: &mut B) -> Option<Result<crate::can::bus::BusEvent, BusError>> {
    tokio::select! {
        biased;
        ev = bus.recv(Duration::from_secs(1)) => Some(ev),
        () = std::future::ready(()) => None,
    }
}

/// Sends what the core queued; a send error is the core's to judge.
fn flush<B: CanBus>(rt: &tokio::runtime::Runtime, bus: &mut B, core: &SharedCore, now: f64) {
    loop {
        // one lock for what is queued (a cycle's commands, a SYNC, a request), no allocation
        let mut out: [Option<crate::can::CanFrame>; 16] = [None; 16];
        {
            let mut c = lock_rt(core);
            for slot in out.iter_mut() {
                match c.poll_transmit() {
                    Some(f) => *slot = Some(f),
                    None => break,
                }
            }
        }
        if out[0].is_none() {
            return;
        }
        for f in out.into_iter().flatten() {
            if let Err(e) = rt.block_on(bus.send(f)) {
                lock_rt(core).handle_bus(Err(e), now);
            }
        }
    }
}
