//! can-utils' candump log format (`(ts) iface ID#DATA`, CAN FD frames `(ts) iface
//! ID##FDATA` with F the FD flags nibble: 1 = bit-rate switch): a typed [`LoggedFrame`] per line,
//! reading a log with precise errors, writing traffic as it passes, and replaying a log onto
//! a bus with its original timing.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::bus::{BusError, CanBus};
use super::protocol::CanFrame;

/// One logged frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedFrame {
    /// Time stamp, s.
    pub time_s: f64,
    /// Interface name (e.g. `vcan0`).
    pub iface: String,
    /// The frame.
    pub frame: CanFrame,
}

/// Why a candump line or log was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CandumpError {
    /// The log could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The log file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A line is not `(ts) iface ID#DATA` (≤ 8 bytes) or `(ts) iface ID##FDATA` (a CAN FD
    /// length) with a standard identifier.
    #[error("{path}:{line}: not a candump line ({reason}): `{text}`")]
    Line {
        /// The log file.
        path: PathBuf,
        /// Line number, from 1.
        line: usize,
        /// What is wrong.
        reason: &'static str,
        /// The line (at most 80 characters of it).
        text: String,
    },
    /// A log larger than [`MAX_LOG_BYTES`].
    #[error("{path}: {bytes} bytes, more than the {MAX_LOG_BYTES} a log may have")]
    TooLarge {
        /// The log file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
}

/// The largest log [`read_log`] reads, bytes (≈ 5 minutes of 500 Hz traffic).
pub const MAX_LOG_BYTES: u64 = 256 << 20;

impl LoggedFrame {
    /// Parses one line; the error says what is wrong.
    pub fn parse(line: &str) -> Result<Self, &'static str> {
        let rest = line.trim().strip_prefix('(').ok_or("no `(time)`")?;
        let (ts, rest) = rest.split_once(')').ok_or("no `(time)`")?;
        let time_s: f64 = ts.parse().map_err(|_| "time is not a number")?;
        if !time_s.is_finite() {
            return Err("time is not finite");
        }
        let mut parts = rest.split_whitespace();
        let iface = parts.next().ok_or("no interface")?.to_string();
        let (id, data) = parts
            .next()
            .and_then(|p| p.split_once('#'))
            .ok_or("no `ID#DATA`")?;
        if id.len() > 3 {
            return Err("not a standard (11-bit) identifier");
        }
        let id = u16::from_str_radix(id, 16).map_err(|_| "identifier is not hexadecimal")?;
        // CAN FD: `##`, one hex digit of flags (bit 0 BRS, bit 1 ESI, bit 2 FDF as newer
        // kernels and can-utils set it), then the data
        let (fd, data) = match data.strip_prefix('#') {
            Some(rest) => {
                let mut c = rest.chars();
                let flags = c
                    .next()
                    .and_then(|f| f.to_digit(16))
                    .ok_or("no CAN FD flags digit after `##`")?;
                if flags > 7 {
                    return Err("CAN FD flags must be 0…7 (BRS, ESI, FDF)");
                }
                (Some(flags & 1 == 1), c.as_str())
            }
            None => (None, data),
        };
        let max = if fd.is_some() { 128 } else { 16 };
        if data.len() % 2 != 0 || data.len() > max {
            return Err(if fd.is_some() {
                "data must be 0…64 whole bytes"
            } else {
                "data must be 0…8 whole bytes"
            });
        }
        if !data.is_ascii() {
            return Err("data is not hexadecimal");
        }
        let bytes = (0..data.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&data[i..i + 2], 16))
            .collect::<Result<Vec<u8>, _>>()
            .map_err(|_| "data is not hexadecimal")?;
        let frame = match fd {
            Some(brs) => CanFrame::new_fd(id, &bytes, brs)
                .ok_or("identifier beyond 11 bits or not a CAN FD length (0…8, 12, 16, 20, 24, 32, 48, 64)")?,
            None => CanFrame::new(id, &bytes).ok_or("identifier beyond 11 bits")?,
        };
        Ok(Self {
            time_s,
            iface,
            frame,
        })
    }
}

impl fmt::Display for LoggedFrame {
    /// `(ts) iface ID#DATA` (FD: `ID##FDATA`), the time with microseconds.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "({:.6}) {} {:03X}#",
            self.time_s,
            self.iface,
            self.frame.id()
        )?;
        if self.frame.is_fd() {
            write!(f, "#{}", u8::from(self.frame.brs()))?;
        }
        for b in self.frame.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// Reads a candump log; a malformed line is an error naming it. Blank lines are skipped.
pub fn read_log(path: &Path) -> Result<Vec<LoggedFrame>, CandumpError> {
    let io = |source| CandumpError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    if bytes > MAX_LOG_BYTES {
        return Err(CandumpError::TooLarge {
            path: path.to_path_buf(),
            bytes,
        });
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            LoggedFrame::parse(l).map_err(|reason| CandumpError::Line {
                path: path.to_path_buf(),
                line: i + 1,
                reason,
                text: l.chars().take(80).collect(),
            })
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
    pub fn log(&mut self, ts_s: f64, frame: &CanFrame) -> std::io::Result<()> {
        let r = LoggedFrame {
            time_s: ts_s,
            iface: std::mem::take(&mut self.iface),
            frame: *frame,
        };
        let result = writeln!(self.out, "{r}");
        self.iface = r.iface;
        result
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
pub async fn replay<B: CanBus>(bus: &mut B, records: &[LoggedFrame]) -> Result<usize, BusError> {
    let Some(first) = records.first() else {
        return Ok(0);
    };
    let t0 = tokio::time::Instant::now();
    for r in records {
        let due = t0 + Duration::from_secs_f64((r.time_s - first.time_s).max(0.0));
        tokio::time::sleep_until(due).await;
        bus.send(r.frame).await?;
    }
    Ok(records.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_bad_lines_say_why() {
        let f = CanFrame::new(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let r = LoggedFrame {
            time_s: 12.5,
            iface: "vcan0".into(),
            frame: f,
        };
        let l = r.to_string();
        assert_eq!(l, "(12.500000) vcan0 181#0102030405060708");
        assert_eq!(LoggedFrame::parse(&l), Ok(r));
        assert_eq!(
            LoggedFrame::parse("(1.0) can0 080#").map(|r| r.frame),
            Ok(CanFrame::new(0x80, &[]).unwrap())
        );
        // CAN FD, with and without the bit-rate switch
        let fd = LoggedFrame {
            time_s: 0.25,
            iface: "vcan0".into(),
            frame: CanFrame::new_fd(0x180, &[0xAB; 12], true).unwrap(),
        };
        assert_eq!(
            fd.to_string(),
            format!("(0.250000) vcan0 180##1{}", "AB".repeat(12))
        );
        assert_eq!(LoggedFrame::parse(&fd.to_string()), Ok(fd));
        let f = LoggedFrame::parse("(1.0) can0 100##0").unwrap().frame;
        assert!(f.is_fd() && !f.brs() && f.dlc() == 0);
        let f = LoggedFrame::parse("(1.0) can0 100##5AA").unwrap().frame;
        assert!(f.is_fd() && f.brs() && f.data() == [0xAA]);
        for (line, why) in [
            ("garbage", "time"),
            ("(1.0) can0 080#0", "whole bytes"),
            ("(x) can0 080#00", "not a number"),
            ("(1.0) can0 1FFFFFFF#00", "standard"),
            ("(1.0) can0 800#00", "11 bits"),
            ("(1.0) can0 080#0G", "hexadecimal"),
            ("(1.0) can0 080#001122334455667788", "whole bytes"),
            ("(inf) can0 080#00", "finite"),
            ("(1.0) can0 180##", "flags"),
            ("(1.0) can0 180##9", "0…7"),
            ("(1.0) can0 180##1001122334455667788", "CAN FD length"),
            ("(1.0) can0 180##1éé", "hexadecimal"),
            ("(1.0) can0 080#éé", "hexadecimal"),
        ] {
            let e = LoggedFrame::parse(line).unwrap_err();
            assert!(e.contains(why), "{line}: {e}");
        }
    }

    #[test]
    fn a_log_error_names_the_file_and_line() {
        let p = std::env::temp_dir().join(format!("pa10-candump-{}.log", std::process::id()));
        std::fs::write(&p, "(0.1) vcan0 080#00\n\n(0.2) vcan0 zz#00\n").unwrap();
        let e = read_log(&p).unwrap_err().to_string();
        std::fs::remove_file(&p).unwrap();
        assert!(e.contains(":3:") && e.contains("hexadecimal"), "{e}");
    }
}
