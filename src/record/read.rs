//! Reading recordings back: what a file holds ([`info`]), every cycle and event
//! ([`cycles`], [`events`]), CSV export ([`export_csv`]) and the still phases a calibration
//! campaign is cut from ([`still_phases`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{CycleSample, Event};

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        error: String,
    },
    /// The file is not a valid MCAP file or a message does not decode.
    #[error("{path}: {error}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        error: String,
    },
}

/// The largest recording read into memory, bytes.
pub const MAX_READ_BYTES: u64 = 4 << 30;

/// Per-channel counts and the time span of a recording file.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Info {
    /// Messages per channel topic.
    pub channels: BTreeMap<String, u64>,
    /// First and last log time, s.
    pub span_s: [f64; 2],
    /// Cycles whose feedback was incomplete.
    pub incomplete: u64,
    /// The recorder's own counts at the end (written, dropped), from the file's metadata.
    pub recorder: BTreeMap<String, String>,
    /// Why the file ends early, when it does (a crash cut it short; the rest was read).
    pub truncated: Option<String>,
}

/// The bytes of `path`, at most [`MAX_READ_BYTES`].
pub(crate) fn load(path: &Path) -> Result<Vec<u8>, ReadError> {
    let io = |e: std::io::Error| ReadError::Io {
        path: path.to_path_buf(),
        error: e.to_string(),
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_READ_BYTES {
        return Err(ReadError::Io {
            path: path.to_path_buf(),
            error: format!("{len} bytes, more than the {MAX_READ_BYTES} read at once"),
        });
    }
    std::fs::read(path).map_err(io)
}

fn format(path: &Path, e: impl std::fmt::Display) -> ReadError {
    ReadError::Format {
        path: path.to_path_buf(),
        error: e.to_string(),
    }
}

/// Messages as read: (topic, log time s, JSON payload).
type Messages = Vec<(String, f64, Vec<u8>)>;

/// Every message of `path`, and why the file ended early when it did (a recording cut short
/// by a crash: what precedes the damage is read).
fn messages(path: &Path) -> Result<(Messages, Option<String>), ReadError> {
    let buf = load(path)?;
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&buf).map_err(|e| format(path, e))? {
        match m {
            Ok(m) => out.push((
                m.channel.topic.clone(),
                m.log_time as f64 * 1e-9,
                m.data.into_owned(),
            )),
            Err(e) if !out.is_empty() => return Ok((out, Some(e.to_string()))),
            Err(e) => return Err(format(path, e)),
        }
    }
    Ok((out, None))
}

/// The cycles recorded in `path`, in order.
pub fn cycles(path: &Path) -> Result<Vec<CycleSample>, ReadError> {
    messages(path)?
        .0
        .into_iter()
        .filter(|(t, ..)| t == "/pa10/cycle")
        .map(|(_, _, d)| serde_json::from_slice(&d).map_err(|e| format(path, e)))
        .collect()
}

/// The events recorded in `path`, in order.
pub fn events(path: &Path) -> Result<Vec<Event>, ReadError> {
    messages(path)?
        .0
        .into_iter()
        .filter(|(t, ..)| t == "/pa10/event")
        .map(|(_, _, d)| serde_json::from_slice(&d).map_err(|e| format(path, e)))
        .collect()
}

/// What `path` holds.
pub fn info(path: &Path) -> Result<Info, ReadError> {
    let (msgs, truncated) = messages(path)?;
    let mut channels = BTreeMap::new();
    let mut span = [f64::INFINITY, f64::NEG_INFINITY];
    let mut incomplete = 0;
    for (topic, t, d) in &msgs {
        *channels.entry(topic.clone()).or_insert(0u64) += 1;
        span = [span[0].min(*t), span[1].max(*t)];
        if topic == "/pa10/cycle" {
            let c: CycleSample = serde_json::from_slice(d).map_err(|e| format(path, e))?;
            incomplete += u64::from(!c.feedback);
        }
    }
    if msgs.is_empty() {
        span = [0.0, 0.0];
    }
    let buf = load(path)?;
    let mut recorder = BTreeMap::new();
    if let Ok(Some(summary)) = mcap::Summary::read(&buf) {
        for idx in &summary.metadata_indexes {
            if let Ok(m) = mcap::read::metadata(&buf, idx)
                && m.name == "pa10d.recorder"
            {
                recorder = m.metadata;
            }
        }
    }
    Ok(Info {
        channels,
        span_s: span,
        incomplete,
        recorder,
        truncated,
    })
}

/// Writes `cycles.csv` and `events.csv` of `path` into `dir`; the two files.
pub fn export_csv(path: &Path, dir: &Path) -> Result<[PathBuf; 2], ReadError> {
    let io = |p: &Path, e: std::io::Error| ReadError::Io {
        path: p.to_path_buf(),
        error: e.to_string(),
    };
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let c = dir.join("cycles.csv");
    let mut text = String::from("stamp_s,cycle,activity,feedback");
    for name in [
        "q_motor", "current", "tau", "delta", "setpoint", "target", "speeds",
    ] {
        for j in 1..=6 {
            text.push_str(&format!(",{name}{j}"));
        }
    }
    text.push_str(",late_us,incomplete,paused,stale,malformed\n");
    for s in cycles(path)? {
        text.push_str(&format!(
            "{},{},{},{}",
            s.stamp_s, s.cycle, s.activity, s.feedback as u8
        ));
        for v in [
            s.q_motor, s.current, s.tau, s.delta, s.setpoint, s.target, s.speeds,
        ] {
            for x in v {
                text.push_str(&format!(",{x}"));
            }
        }
        text.push_str(&format!(
            ",{},{},{},{},{}\n",
            s.late_us, s.link[0], s.link[1], s.link[2], s.link[3]
        ));
    }
    std::fs::write(&c, text).map_err(|e| io(&c, e))?;
    let e = dir.join("events.csv");
    let mut text = String::from("stamp_s,kind,text\n");
    for ev in events(path)? {
        text.push_str(&format!(
            "{},{},\"{}\"\n",
            ev.stamp_s,
            ev.kind,
            ev.text.replace('"', "\"\"")
        ));
    }
    std::fs::write(&e, text).map_err(|err| io(&e, err))?;
    Ok([c, e])
}

/// A stretch of a recording where the arm held still: the averages a calibration row needs.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StillPhase {
    /// Its start and end, s.
    pub span_s: [f64; 2],
    /// Cycles averaged.
    pub cycles: usize,
    /// Mean resolver angles, rad.
    pub q_motor: [f64; 6],
    /// Mean motor currents, A.
    pub current: [f64; 6],
    /// The link setpoint held, rad.
    pub setpoint: [f64; 6],
}

/// The still phases of `samples`: at least `min_s` of holding (the same setpoint, every speed
/// command below `speed_tol` rad/s); the first `settle_s` of each are skipped (the arm
/// settling) and the cycles with complete feedback among the rest averaged. A cycle whose
/// feedback was incomplete (a frame late on a loaded host) is left out of the mean but does
/// not end the phase: the arm did not move.
pub fn still_phases(
    samples: &[CycleSample],
    min_s: f64,
    settle_s: f64,
    speed_tol: f64,
) -> Vec<StillPhase> {
    let still = |s: &CycleSample| {
        s.activity == super::Mode::Holding.code() && s.speeds.iter().all(|v| v.abs() < speed_tol)
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i < samples.len() {
        if !still(&samples[i]) {
            i += 1;
            continue;
        }
        let start = i;
        while i < samples.len()
            && still(&samples[i])
            && samples[i].setpoint == samples[start].setpoint
        {
            i += 1;
        }
        let run = &samples[start..i];
        let t0 = run[0].stamp_s;
        let t1 = run[run.len() - 1].stamp_s;
        if t1 - t0 < min_s {
            continue;
        }
        let kept: Vec<&CycleSample> = run
            .iter()
            .filter(|s| s.feedback && s.stamp_s >= t0 + settle_s)
            .collect();
        if kept.is_empty() {
            continue;
        }
        let n = kept.len() as f64;
        let mean = |f: &dyn Fn(&CycleSample) -> [f64; 6]| -> [f64; 6] {
            std::array::from_fn(|j| kept.iter().map(|s| f(s)[j]).sum::<f64>() / n)
        };
        out.push(StillPhase {
            span_s: [t0, t1],
            cycles: kept.len(),
            q_motor: mean(&|s| s.q_motor),
            current: mean(&|s| s.current),
            setpoint: run[0].setpoint,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recording at 500 Hz: 1 s holding at `a`, with every 40th cycle's feedback
    /// incomplete (a stale resolver reading of 9 rad), then 0.5 s moving, then 1 s at `b`.
    fn recording() -> Vec<CycleSample> {
        let (a, b) = ([0.1; 6], [0.2; 6]);
        (0..1250)
            .map(|i| {
                let (activity, setpoint, speed) = match i {
                    0..500 => (0, a, 0.0),
                    500..750 => (1, a, 0.1),
                    _ => (0, b, 0.0),
                };
                let feedback = i % 40 != 7;
                CycleSample {
                    stamp_s: i as f64 * 0.002,
                    cycle: i,
                    activity,
                    feedback,
                    q_motor: if feedback { setpoint } else { [9.0; 6] },
                    setpoint,
                    speeds: [speed; 6],
                    ..Default::default()
                }
            })
            .collect()
    }

    #[test]
    fn an_incomplete_cycle_is_left_out_of_a_still_phase_but_does_not_end_it() {
        let phases = still_phases(&recording(), 0.5, 0.1, 0.01);
        assert_eq!(phases.len(), 2, "{phases:?}");
        assert_eq!(phases[0].setpoint, [0.1; 6]);
        assert_eq!(phases[1].setpoint, [0.2; 6]);
        for p in &phases {
            // the stale readings are not in the means
            assert!(
                (0..6).all(|j| (p.q_motor[j] - p.setpoint[j]).abs() < 1e-12),
                "{p:?}"
            );
            // 1 s less the 0.1 s settling, less one cycle in 40
            assert!(p.cycles > 420 && p.cycles < 450, "{p:?}");
        }
    }
}
