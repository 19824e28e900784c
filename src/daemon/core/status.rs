//! What the core shows: each cycle kept as the last sample and handed to the recording, and
//! the [`Status`] snapshot clients read.

use super::*;
use crate::daemon::wire::{ModelKind, ModelStatus, RefusalStatus, State};
use crate::model::Model;
use crate::record::Mode;

impl Core {
    /// Keeps this cycle as the last sample (the live view) and hands it to the recording
    /// (no allocation but an event's text on a fault); ends the recording when its duration
    /// is reached.
    pub(super) fn record_cycle(&mut self, stamp_s: f64, complete: bool) {
        let Some(c) = self.ctl.as_ref() else {
            return;
        };
        let o = *c.output();
        let mode = c.mode();
        let sp = c.setpoint().q;
        let counters = self.link.counters();
        let js = self.last.unwrap_or(JointState {
            q_motor: [0.0; 6],
            current: [0.0; 6],
            stamp_s,
            controller_fault: false,
        });
        let sample = CycleSample {
            stamp_s,
            cycle: self.stats.cycles,
            activity: mode.code(),
            feedback: complete,
            q_motor: js.q_motor,
            current: js.current,
            tau: o.tau,
            delta: std::array::from_fn(|j| o.target[j] - sp[j]),
            setpoint: sp,
            target: o.target,
            speeds: o.speeds,
            late_us: self.last_late_us,
            link: [
                counters.incomplete,
                counters.paused,
                counters.stale,
                counters.malformed,
            ],
        };
        self.last_sample = Some(sample);
        let Some(tap) = self.tap.as_mut() else {
            return;
        };
        tap.push(Record::Cycle(sample));
        let done = tap.until_s.is_some_and(|end| stamp_s >= end);
        // events after the cycle, at its stamp
        if mode != self.last_mode {
            self.last_mode = mode;
            self.log_event_at(stamp_s, "state", mode.name());
            if mode == Mode::Faulted
                && let Some(f) = self.fault()
            {
                self.log_event_at(stamp_s, "fault", f.to_string());
            }
        }
        if done {
            self.log_event_at(stamp_s, "recording", "duration reached");
            self.tap = None;
        }
    }

    /// The status snapshot.
    pub fn status(&self) -> Status {
        let fault = self
            .fault()
            .map(|f| match (&f, self.link.controller_report()) {
                (Fault::Controller, Some(report)) => format!("{f}: {report}"),
                _ => f.to_string(),
            });
        let (state, setpoint, tool, payload) = match &self.ctl {
            None => (
                if self.failure.is_some() {
                    State::Fault
                } else {
                    State::Starting
                },
                [0.0; 6],
                None,
                self.params.payload_n,
            ),
            Some(c) => {
                let s = match c.mode() {
                    _ if self.link.is_closed() => State::Closed,
                    Mode::Faulted => State::Fault,
                    _ if self.restarting => State::Starting,
                    m => State::from(m),
                };
                (
                    s,
                    c.setpoint().q,
                    Some(c.model().fk(&c.setpoint().q)),
                    c.payload_n(),
                )
            }
        };
        let (p, q) = tool
            .map(|t| crate::model::pose_parts(&t))
            .unwrap_or(([0.0; 3], [1.0, 0.0, 0.0, 0.0]));
        Status {
            state,
            fault,
            servo: self.link.servo_state().map(|s| format!("{s:?}")),
            setpoint,
            q_motor: self.last.map(|s| s.q_motor).unwrap_or([0.0; 6]),
            current: self.last.map(|s| s.current).unwrap_or([0.0; 6]),
            time_s: self.now_s,
            tau: self.ctl.as_ref().map_or([0.0; 6], |c| c.output().tau),
            tool_position: p,
            tool_quaternion: q,
            position_sigma_mm: self.ctl.as_ref().and_then(|c| {
                c.model()
                    .position_uncertainty(&c.setpoint().q, &c.output().tau)
                    .map(|s| s * 1e3)
            }),
            payload_n: payload,
            payload_com: self
                .ctl
                .as_ref()
                .map_or(self.params.payload_com, |c| c.payload_com()),
            link: self.link.counters(),
            cycle: CycleStats {
                jitter_us: self.jitter.summary(),
                compute_us: self.compute.summary(),
                lock_wait_us: self.lock_wait.summary(),
                ..self.stats
            },
            trajectory: self
                .ctl
                .as_ref()
                .map(|c| *c.trajectory())
                .unwrap_or_default(),
            speed_scaling: self.ctl.as_ref().map_or(1.0, |c| c.speed_scaling().0),
            stream_end: self
                .ctl
                .as_ref()
                .and_then(|c| c.stream_end())
                .map(str::to_owned),
            leased: self.lease.is_some(),
            recording: self.recorded.as_ref().map(|r| r.status(self.tap.is_some())),
            model: Some(model_status(
                self.ctl.as_ref().map_or(&self.model, |c| c.model_arc()),
                &self.model_file.0,
                self.model_file.1,
            )),
            last_refusal: self.last_refusal.clone(),
            in_position: state == State::Holding
                && self.ctl.as_ref().is_some_and(|c| c.in_position()),
        }
    }

    /// Keeps `refusal` as the last one (`status.last_refusal`), stamped now.
    pub fn note_refusal(&mut self, mut refusal: RefusalStatus) {
        refusal.time_s = self.now_s;
        self.last_refusal = Some(refusal);
    }
}

/// What `model` (read from `file`, in force since `since_s`) holds, for `status.model`.
pub fn model_status(model: &Model, file: &str, since_s: f64) -> ModelStatus {
    let d = model.data();
    let joints =
        |has: &dyn Fn(usize) -> bool| (0..6u8).filter(|&j| has(j.into())).map(|j| j + 1).collect();
    let kind = if !d.discovered.is_empty() || d.joint_errors.iter().any(Option::is_some) {
        ModelKind::Extended
    } else if d.uncertainty.is_some() || d.departures.iter().any(|p| *p != Default::default()) {
        ModelKind::Calibrated
    } else {
        ModelKind::Nominal
    };
    ModelStatus {
        file: file.to_owned(),
        kind,
        springs: joints(&|j| d.stiffness[j].is_some()),
        friction: joints(&|j| d.friction[j].is_some()),
        discovered: d
            .discovered
            .iter()
            .map(|e| match e.joint {
                Some(j) => format!("{}[J{j}]", e.name),
                None => e.name.clone(),
            })
            .collect(),
        since_s,
    }
}
