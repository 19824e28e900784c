//! Tracking judged by the simulator's true link angles, in simulated time: a timed trajectory
//! such as `docs/motion.md`'s six points (true link − desired, every cycle) and a `servo`
//! stream of a sine
//! (true link − streamed target). Shared by the MuJoCo judge (`examples/mujoco_judge.rs`) and
//! the loop-rate comparison (`examples/fd_tracking.rs`); `step` runs after every cycle (the
//! judge checks its plant there).

use pa10::daemon::wire::{ApiRequest, Reply};
use pa10::sim::rig::{HOME, Lockstep};
use serde_json::{Value, json};

/// RMS and peak of link − target, mrad.
#[derive(Default)]
struct Errors {
    sum: f64,
    peak: f64,
    n: usize,
}

impl Errors {
    fn add(&mut self, link: &[f64; 6], target: &[f64; 6]) {
        for j in 0..6 {
            let e = (link[j] - target[j]) * 1e3;
            self.sum += e * e;
            self.peak = self.peak.max(e.abs());
        }
        self.n += 6;
    }
    fn rms_peak(&self) -> (f64, f64) {
        ((self.sum / self.n.max(1) as f64).sqrt(), self.peak)
    }
}

/// Follows the trajectory `points` (`follow_trajectory` points, e.g. `six_points()`), a cycle
/// (`period_s`) at a time for at most `timeout_s`: RMS and peak (mrad) of the true link − the
/// desired positions, and how it ended ("succeeded", another trajectory state, or the
/// daemon's fault).
pub fn trajectory<E: From<String>>(
    ls: &mut Lockstep,
    points: &Value,
    period_s: f64,
    timeout_s: f64,
    mut step: impl FnMut(&Lockstep) -> Result<(), E>,
) -> Result<(f64, f64, String), E> {
    let r = ls.call_json(&json!({"cmd": "follow_trajectory", "points": points}));
    if r["ok"] != true {
        return Err(format!("follow_trajectory: {r}").into());
    }
    let end = ls.now() + timeout_s;
    let mut err = Errors::default();
    loop {
        ls.run_for(period_s);
        step(ls)?;
        let st = ls.call_json(&json!({"cmd": "status"}))["status"].clone();
        let t = &st["trajectory"];
        let desired: [f64; 6] = serde_json::from_value(t["desired"].clone())
            .map_err(|e| format!("status.trajectory.desired: {e}"))?;
        err.add(&ls.servo.link_state().0, &desired);
        if t["state"] != "executing" {
            let ended = match st["fault"].as_str() {
                Some(f) => f.to_string(),
                None => t["state"].as_str().unwrap_or("?").to_string(),
            };
            let (rms, peak) = err.rms_peak();
            return Ok((rms, peak, ended));
        }
        if ls.now() > end {
            return Err(format!("the trajectory did not end in {timeout_s} s").into());
        }
    }
}

/// Streams `servo` setpoints, one a cycle (`period_s`) for `seconds`: [`HOME`] plus `amp`
/// (rad) times a 0.2 Hz sine. RMS and peak (mrad) of the true link − the streamed target after
/// the first second. A refused setpoint (the daemon faulted) ends the stream early.
pub fn sine_stream<E>(
    ls: &mut Lockstep,
    period_s: f64,
    seconds: f64,
    amp: [f64; 6],
    mut step: impl FnMut(&Lockstep) -> Result<(), E>,
) -> Result<(f64, f64), E> {
    let mut err = Errors::default();
    for k in 0..(seconds / period_s).round() as usize {
        let t = k as f64 * period_s;
        let w = (std::f64::consts::TAU * 0.2 * t).sin();
        let target: [f64; 6] = std::array::from_fn(|j| HOME[j] + amp[j] * w);
        let servo = ApiRequest::Servo {
            positions: Some(target),
            position: None,
            quaternion: None,
        };
        if let Reply::Refused(_) = ls.call(servo) {
            break;
        }
        ls.run_for(period_s);
        step(ls)?;
        if t >= 1.0 {
            err.add(&ls.servo.link_state().0, &target);
        }
    }
    Ok(err.rms_peak())
}
