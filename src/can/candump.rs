//! can-utils' candump log format (`(ts) iface ID#DATA`): writing traffic as it passes and
//! replaying a log onto a bus with its original timing.

use std::io::Write;
use std::path::Path;
use std::time::Duration;

use super::bus::{BusError, CanBus};
use super::protocol::{Frame, candump_line, parse_candump_line};

/// One logged frame: time (s), interface, frame.
pub type Entry = (f64, String, Frame);

/// Reads a candump log; a malformed line is an error naming it.
pub fn read_log(path: &Path) -> Result<Vec<Entry>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            parse_candump_line(l)
                .ok_or_else(|| format!("{}:{}: not a candump line: `{l}`", path.display(), i + 1))
        })
        .collect()
}

/// Writes frames as candump lines.
pub struct Logger<W: Write> {
    out: W,
    iface: String,
}

impl<W: Write> Logger<W> {
    /// A logger naming `iface` in every line.
    pub fn new(out: W, iface: &str) -> Self {
        Self {
            out,
            iface: iface.to_string(),
        }
    }
    /// Logs `frame` at `ts_s` seconds; IO errors are reported, not fatal to the caller's bus.
    pub fn log(&mut self, ts_s: f64, frame: &Frame) -> std::io::Result<()> {
        writeln!(self.out, "{}", candump_line(ts_s, &self.iface, frame))
    }
    /// The writer (e.g. to take an in-memory log).
    pub fn out_mut(&mut self) -> &mut W {
        &mut self.out
    }
    /// Flushes the writer.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Sends the logged frames onto `bus`, spaced as they were logged (first frame at once).
pub async fn replay<B: CanBus>(bus: &mut B, entries: &[Entry]) -> Result<usize, BusError> {
    let Some(first) = entries.first() else {
        return Ok(0);
    };
    let t0 = tokio::time::Instant::now();
    for (ts, _, f) in entries {
        let due = t0 + Duration::from_secs_f64((ts - first.0).max(0.0));
        tokio::time::sleep_until(due).await;
        bus.send(*f).await?;
    }
    Ok(entries.len())
}
