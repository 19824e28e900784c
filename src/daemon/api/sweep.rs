//! Identification sweeps driven through the daemon's API: a [`Session`] is anything that
//! carries [`ApiRequest`]s to a daemon and lets its time pass (the socket client in real
//! time, the in-process lockstep rig in simulated time); [`gather`] drives a planned tour
//! (`calib::identify::plan_sweep`) out and back as constant-speed `follow_trajectory`s and
//! polls the status into the [`Poll`]s `calib::identify::samples` cuts samples from. The
//! fitting itself is pure and lives in `calib::identify`.

use crate::calib::identify::{self, Identified, IdentifyError, Poll, Sample, SweepPlan};
use crate::daemon::plan::TrajectoryPoint;
use crate::daemon::wire::{Answer, ApiRequest, Reply, State, Status};
use crate::model::Model;

/// A connection to a daemon whose clock the caller can let run.
pub trait Session {
    /// Sends `req`; the daemon's reply (a refusal included), or why it could not be asked.
    fn send(&mut self, req: ApiRequest) -> Result<Reply, String>;
    /// Lets `seconds` pass on the daemon's clock (sleeps, or runs the simulation).
    fn pause(&mut self, seconds: f64);
    /// The daemon's clock, s (any origin).
    fn clock_s(&self) -> f64;
}

/// Status poll interval of a sweep, s.
pub const POLL_S: f64 = 0.02;
/// Status poll interval over a sweep's first `calib::identify::START_WINDOW_S`, s (the
/// control cycle of the shipped configurations): the drives' breakaway peaks last a few
/// cycles.
pub const START_POLL_S: f64 = 0.002;
/// Acceleration of the fastest joint at the start and end of every sweep, rad/s² (within the
/// daemon's default limits of every joint).
pub const SWEEP_ACCEL: f64 = 0.4;
/// Slowest joint speed a polled sample counts for, rad/s (`calib::identify::samples`).
pub const MIN_SAMPLE_SPEED: f64 = 0.02;
/// The sweep speeds `pa10 identify` and the judges use by default, rad/s.
pub const DEFAULT_SPEEDS: [f64; 2] = [0.15, 0.3];
/// The longest one sweep may take, s.
pub const MAX_SWEEP_S: f64 = 600.0;

/// Why a sweep stopped.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The daemon could not be asked.
    #[error("asking pa10d: {0}")]
    Session(String),
    /// The daemon refused a request.
    #[error("pa10d refused: {0}")]
    Refused(String),
    /// The daemon answered something else than asked for.
    #[error("pa10d answered status with {0}")]
    Unexpected(String),
    /// The arm faulted during a sweep.
    #[error("the sweep ended in a fault: {0}")]
    Fault(String),
    /// A sweep did not end in time.
    #[error("a sweep took over {MAX_SWEEP_S} s")]
    Timeout,
    /// No sweep speed given, or one outside (0, 1] rad/s.
    #[error("sweep speeds: one or more in (0, 1] rad/s, got {0:?}")]
    Speeds(Vec<f64>),
    /// Planning the tour or fitting its samples failed.
    #[error(transparent)]
    Identify(#[from] IdentifyError),
}

/// What [`gather`] polled.
#[derive(Debug, Clone, Default)]
pub struct Gathered {
    /// Every [`POLL_S`] while the arm moved.
    pub polls: Vec<Poll>,
    /// Per sweep, every [`START_POLL_S`] over its first `calib::identify::START_WINDOW_S`
    /// (`calib::identify::breakaway`).
    pub starts: Vec<Vec<Poll>>,
}

/// What [`identify_through`] did and found.
#[derive(Debug, Clone)]
pub struct Identification {
    /// The tour's waypoints, rad (driven again for `calib::torque_check`).
    pub tour: Vec<[f64; 6]>,
    /// Status polls taken while the arm moved (every [`POLL_S`]).
    pub polls: usize,
    /// The constant-speed samples cut from them (torque constants applied).
    pub samples: Vec<Sample>,
    /// The fit.
    pub identified: Identified,
    /// `model` with the identified bodies and friction.
    pub model: Model,
}

/// `pa10 identify`'s steps through a daemon: a tour planned from where the arm stands
/// (`plan`, within `model`'s limits), driven with [`gather`] at `speeds` (rad/s), its
/// samples cut with the torque constants `kt` (N·m/A), gravity and friction fitted from
/// `model`'s bodies.
pub fn identify_through<S: Session + ?Sized>(
    s: &mut S,
    model: &Model,
    kt: &[f64; 6],
    plan: &SweepPlan,
    speeds: &[f64],
) -> Result<Identification, SweepError> {
    let tour = identify::plan_sweep(model, &status(s)?.setpoint, plan)?;
    let gathered = gather(s, &tour, speeds)?;
    let samples = identify::samples(&gathered.polls, kt, MIN_SAMPLE_SPEED);
    let mut identified = identify::identify(model, &samples)?;
    let fitted = identified.apply(model)?;
    // the breakaway against the identified gravity
    let breakaway = identify::breakaway(&fitted, &gathered.starts, kt);
    for (f, b) in identified.friction.iter_mut().zip(breakaway) {
        f.breakaway = b;
    }
    let model = identified.apply(model)?;
    Ok(Identification {
        tour,
        polls: gathered.polls.len(),
        samples,
        identified,
        model,
    })
}

/// Sends `req`; a refusal is an error with the daemon's reason.
pub fn checked<S: Session + ?Sized>(s: &mut S, req: ApiRequest) -> Result<Answer, SweepError> {
    match s.send(req).map_err(SweepError::Session)? {
        Reply::Ok(a) => Ok(a),
        Reply::Refused(e) => Err(SweepError::Refused(e)),
    }
}

/// The daemon's status.
pub fn status<S: Session + ?Sized>(s: &mut S) -> Result<Status, SweepError> {
    match checked(s, ApiRequest::Status {})? {
        Answer::Status(st) => Ok(*st),
        other => Err(SweepError::Unexpected(format!("{other:?}"))),
    }
}

/// Sweep speeds, rad/s: one or more, each in (0, 1].
pub fn check_speeds(speeds: &[f64]) -> Result<(), SweepError> {
    if speeds.is_empty()
        || !speeds
            .iter()
            .all(|v| v.is_finite() && *v > 0.0 && *v <= 1.0)
    {
        return Err(SweepError::Speeds(speeds.to_vec()));
    }
    Ok(())
}

/// The sweeps of [`gather`] in order, `(from, to, speed)` (rad, rad, rad/s): the tour out,
/// segment i at `speeds[i % len]`, then back the same way at the same speeds.
pub fn schedule(tour: &[[f64; 6]], speeds: &[f64]) -> Vec<([f64; 6], [f64; 6], f64)> {
    let n = if speeds.is_empty() {
        0
    } else {
        tour.len().saturating_sub(1)
    };
    let out = (0..n).map(|i| (tour[i], tour[i + 1], speeds[i % speeds.len()]));
    let back = (0..n)
        .rev()
        .map(|i| (tour[i + 1], tour[i], speeds[i % speeds.len()]));
    out.chain(back).collect()
}

/// Drives `tour` (joint angles, rad) out and back — every segment both ways at the same
/// speed, segment i at `speeds[i]`, cyclically (rad/s of the fastest joint) — and polls the
/// status every [`POLL_S`] while the arm moves (every [`START_POLL_S`] over each sweep's
/// first `calib::identify::START_WINDOW_S`, kept apart for the breakaway). The same speed both ways puts every
/// configuration in the data at +q̇ and −q̇: friction, whatever its shape, is odd in q̇ and
/// gravity even, so a friction law the fit does not know (a creeping drive's, one rising with
/// speed) cannot leak into the identified gravity; the speed levels across segments separate
/// Coulomb from viscous friction.
pub fn gather<S: Session + ?Sized>(
    s: &mut S,
    tour: &[[f64; 6]],
    speeds: &[f64],
) -> Result<Gathered, SweepError> {
    check_speeds(speeds)?;
    let mut out = Gathered::default();
    for (a, b, speed) in schedule(tour, speeds) {
        let Some(seg) = identify::sweep_segment(&a, &b, speed, SWEEP_ACCEL) else {
            continue;
        };
        let points = seg
            .into_iter()
            .map(|(t, positions, velocities)| TrajectoryPoint {
                positions,
                velocities: Some(velocities),
                accelerations: None,
                time_from_start: t,
            })
            .collect();
        checked(
            s,
            ApiRequest::FollowTrajectory {
                points,
                path_tolerance: None,
                goal_tolerance: None,
                goal_time_tolerance: None,
            },
        )?;
        let start = s.clock_s();
        let mut opening = Vec::new();
        let mut last_poll = start;
        loop {
            let starting = s.clock_s() - start < identify::START_WINDOW_S;
            s.pause(if starting { START_POLL_S } else { POLL_S });
            let st = status(s)?;
            match st.state {
                State::Fault => return Err(SweepError::Fault(st.fault.unwrap_or_default())),
                State::Holding if s.clock_s() - start > 0.1 => break,
                _ if s.clock_s() - start > MAX_SWEEP_S => return Err(SweepError::Timeout),
                _ => {}
            }
            let poll = Poll {
                t: st.time_s,
                setpoint: st.setpoint,
                current: st.current,
            };
            if starting {
                opening.push(poll);
            }
            // the steady cadence the constant-speed samples are cut at
            if s.clock_s() - last_poll >= POLL_S - 1e-9 {
                last_poll = s.clock_s();
                out.polls.push(poll);
            }
        }
        out.starts.push(opening);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_segment_is_swept_both_ways_at_one_speed_and_the_speeds_alternate() {
        let tour: Vec<[f64; 6]> = (0..4).map(|k| [0.1 * k as f64; 6]).collect();
        let s = schedule(&tour, &[0.15, 0.3]);
        assert_eq!(s.len(), 6);
        for (a, b, v) in &s[..3] {
            let back = s[3..]
                .iter()
                .find(|(c, d, _)| c == b && d == a)
                .expect("swept back");
            assert_eq!(back.2, *v, "the same speed both ways");
        }
        assert_eq!([s[0].2, s[1].2, s[2].2], [0.15, 0.3, 0.15]);
        assert!(schedule(&tour[..1], &[0.1]).is_empty());
        assert!(matches!(check_speeds(&[]), Err(SweepError::Speeds(_))));
        assert!(matches!(
            check_speeds(&[0.2, 1.5]),
            Err(SweepError::Speeds(_))
        ));
        assert!(check_speeds(&[0.2, 1.0]).is_ok());
    }
}
