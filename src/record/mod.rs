//! Recording every control cycle to MCAP, without ever stalling the loop.
//!
//! The daemon's core hands each cycle's [`CycleSample`] (fixed size, `Copy`) and the rare
//! [`Event`] (state changes, faults, client commands) to a bounded lock-free single-producer
//! single-consumer queue ([`rtrb`]); a writer thread ([`Recorder`]) drains it into MCAP files
//! (the robotics log container Foxglove, ROS 2 bags and the `mcap` CLI read) with JSON-schema
//! channels and zstd chunks, rotating by size within a disk budget. A full queue, a slow,
//! full or read-only disk drops records and counts them ([`RecorderStats`]); the core never
//! waits. [`read`] reads recordings back (info, CSV export, the still phases a calibration
//! campaign is cut from); [`recover`] rewrites one cut short by a crash as a whole MCAP file
//! the standard readers read.

mod mode;
pub mod read;
pub mod recover;

pub use mode::{Mode, describe_codes};

use std::borrow::Cow;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// One control cycle as recorded (link side unless said; SI units).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CycleSample {
    /// The cycle's time stamp (its SYNC), s since the daemon started.
    pub stamp_s: f64,
    /// Cycles answered so far.
    pub cycle: u64,
    /// What the loop was doing: a [`Mode`] code (0 holding, 1 moving, 2 following,
    /// 3 streaming, 4 stopping, 5 fault).
    pub activity: u8,
    /// Whether this cycle's feedback was complete.
    pub feedback: bool,
    /// Resolver (motor-side) angles, rad.
    pub q_motor: [f64; 6],
    /// Motor currents, A.
    pub current: [f64; 6],
    /// Joint torque estimate used for the compensation, N·m.
    pub tau: [f64; 6],
    /// Compensation per joint: motor target − link setpoint, rad.
    pub delta: [f64; 6],
    /// Link setpoint, rad.
    pub setpoint: [f64; 6],
    /// Motor target, rad.
    pub target: [f64; 6],
    /// Speed commands sent, rad/s.
    pub speeds: [f64; 6],
    /// How late the cycle's SYNC went out, µs.
    pub late_us: f64,
    /// Link counters: incomplete cycles, paused windows, stale and malformed frames.
    pub link: [u64; 4],
}

/// Something that happened, as recorded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// When, s since the daemon started.
    pub stamp_s: f64,
    /// `state`, `fault`, `command` or `recording`.
    pub kind: Cow<'static, str>,
    /// What: the new state, the fault's text, the command's name.
    pub text: Cow<'static, str>,
}

/// What goes through the queue.
#[derive(Debug, Clone, PartialEq)]
// cycles are nearly every record; boxing them would allocate every cycle
#[allow(clippy::large_enum_variant)]
pub enum Record {
    /// A cycle.
    Cycle(CycleSample),
    /// An event.
    Event(Event),
}

/// How a recording is written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordConfig {
    /// The folder recordings are written to (clients name files inside it only).
    #[serde(default = "default_dir")]
    pub dir: PathBuf,
    /// A file is closed and the next one opened beyond this size, MiB.
    #[serde(default = "default_file_mb")]
    pub max_file_mb: f64,
    /// Recording stops (records dropped and counted) once its files hold this much, MiB.
    #[serde(default = "default_budget_mb")]
    pub budget_mb: f64,
    /// Queue length, cycles (default 5000: 10 s at 500 Hz).
    #[serde(default = "default_queue")]
    pub queue: usize,
    /// Chunk compression: `zstd`, `lz4` or `none`.
    #[serde(default = "default_compression")]
    pub compression: String,
    /// Start recording when the daemon starts (to `pa10d-<unix time>.mcap`).
    #[serde(default)]
    pub autostart: bool,
}

fn default_dir() -> PathBuf {
    PathBuf::from("/var/lib/pa10d")
}
fn default_file_mb() -> f64 {
    256.0
}
fn default_budget_mb() -> f64 {
    4096.0
}
fn default_queue() -> usize {
    5000
}
fn default_compression() -> String {
    "zstd".into()
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            dir: default_dir(),
            max_file_mb: default_file_mb(),
            budget_mb: default_budget_mb(),
            queue: default_queue(),
            compression: default_compression(),
            autostart: false,
        }
    }
}

impl RecordConfig {
    /// Checks the numbers and the compression name; the reason otherwise.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.max_file_mb.is_finite() && self.max_file_mb >= 0.01) {
            return Err(format!(
                "record.max_file_mb must be ≥ 0.01, got {}",
                self.max_file_mb
            ));
        }
        if !(self.budget_mb.is_finite() && self.budget_mb >= self.max_file_mb) {
            return Err(format!(
                "record.budget_mb must be ≥ record.max_file_mb, got {}",
                self.budget_mb
            ));
        }
        if !(100..=1_000_000).contains(&self.queue) {
            return Err(format!(
                "record.queue must be within 100…1000000 cycles, got {}",
                self.queue
            ));
        }
        compression(&self.compression).map(|_| ())
    }
}

fn compression(name: &str) -> Result<Option<mcap::Compression>, String> {
    match name {
        "zstd" => Ok(Some(mcap::Compression::Zstd)),
        "lz4" => Ok(Some(mcap::Compression::Lz4)),
        "none" => Ok(None),
        _ => Err(format!(
            "record.compression must be zstd, lz4 or none, got {name:?}"
        )),
    }
}

/// Why a recording could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// The file name a client gave is not a plain name inside the recording folder.
    #[error("recording file {0:?}: give a plain file name (it is written inside record.dir)")]
    Name(String),
    /// The file exists already.
    #[error("recording file {0} exists; choose another name")]
    Exists(PathBuf),
    /// The folder or file cannot be written.
    #[error("recording file {path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        error: String,
    },
    /// The configuration is invalid.
    #[error("{0}")]
    Config(String),
}

/// Counters shared by the core (queue drops), the writer and `status`.
#[derive(Debug, Default)]
pub struct RecorderStats {
    /// Records written.
    pub written: AtomicU64,
    /// Records dropped because the queue was full (the writer fell behind).
    pub dropped_queue: AtomicU64,
    /// Records dropped because they could not be written (disk full, read-only, budget).
    pub dropped_write: AtomicU64,
    /// Bytes in the recording's files.
    pub bytes: AtomicU64,
    /// Files written.
    pub files: AtomicU64,
    /// The writer has closed the last file.
    pub finished: AtomicBool,
    /// The first write error, if any.
    pub error: Mutex<Option<String>>,
    /// The recording's first file.
    pub path: Mutex<PathBuf>,
}

/// The recording part of `status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RecordingStatus {
    /// Whether cycles are being handed to the writer.
    pub active: bool,
    /// The recording's first file.
    pub path: String,
    /// Records written.
    pub written: u64,
    /// Records dropped: queue full.
    pub dropped_queue: u64,
    /// Records dropped: not writable (disk, budget).
    pub dropped_write: u64,
    /// Bytes written.
    pub bytes: u64,
    /// Files written (rotation).
    pub files: u64,
    /// The first write error.
    pub error: Option<String>,
    /// Whether the writer has closed the last file.
    pub finished: bool,
}

impl RecorderStats {
    /// Waits (polling every 10 ms) until the writer has closed the last file, at most
    /// `limit`; whether it has.
    pub fn wait_finished(&self, limit: Duration) -> bool {
        let end = std::time::Instant::now() + limit;
        loop {
            if self.finished.load(Ordering::SeqCst) {
                return true;
            }
            if std::time::Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// A snapshot for `status`.
    pub fn status(&self, active: bool) -> RecordingStatus {
        RecordingStatus {
            active,
            path: self
                .path
                .lock()
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            written: self.written.load(Ordering::Relaxed),
            dropped_queue: self.dropped_queue.load(Ordering::Relaxed),
            dropped_write: self.dropped_write.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            files: self.files.load(Ordering::Relaxed),
            error: self.error.lock().ok().and_then(|e| e.clone()),
            finished: self.finished.load(Ordering::SeqCst),
        }
    }
}

/// The core's end of a recording: push records without waiting; stop by dropping it.
#[derive(Debug)]
pub struct RecordTap {
    producer: rtrb::Producer<Record>,
    /// Shared counters.
    pub stats: Arc<RecorderStats>,
    /// Stop handing records over at this time (s), if a duration was asked.
    pub until_s: Option<f64>,
}

impl RecordTap {
    /// Hands `r` to the writer; counts it as dropped when the queue is full. Never waits,
    /// never allocates (beyond what `r` holds).
    pub fn push(&mut self, r: Record) {
        if self.producer.push(r).is_err() {
            self.stats.dropped_queue.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Where the writer puts its bytes: a file, or (tests) anything else that may be slow or fail.
pub trait Sink: Write + Seek + Send {}
impl<T: Write + Seek + Send> Sink for T {}

/// Opens the `index`-th file of a recording (0 is the first).
pub type OpenSink = Box<dyn FnMut(usize) -> std::io::Result<(Box<dyn Sink>, PathBuf)> + Send>;

/// The JSON schema of the `/pa10/cycle` channel.
pub const CYCLE_SCHEMA: &str = r#"{"type":"object","title":"pa10.Cycle","properties":{
"stamp_s":{"type":"number","description":"s since the daemon started"},
"cycle":{"type":"integer"},
"activity":{"type":"integer","description":"0 holding, 1 moving, 2 following, 3 streaming, 4 stopping, 5 fault"},
"feedback":{"type":"boolean"},
"q_motor":{"type":"array","items":{"type":"number"},"description":"resolver angles, rad"},
"current":{"type":"array","items":{"type":"number"},"description":"motor currents, A"},
"tau":{"type":"array","items":{"type":"number"},"description":"torque estimate, N m"},
"delta":{"type":"array","items":{"type":"number"},"description":"compensation, motor target - link setpoint, rad"},
"setpoint":{"type":"array","items":{"type":"number"},"description":"link setpoint, rad"},
"target":{"type":"array","items":{"type":"number"},"description":"motor target, rad"},
"speeds":{"type":"array","items":{"type":"number"},"description":"speed commands, rad/s"},
"late_us":{"type":"number","description":"SYNC lateness, us"},
"link":{"type":"array","items":{"type":"integer"},"description":"incomplete, paused, stale, malformed"}}}"#;

/// The JSON schema of the `/pa10/event` channel.
pub const EVENT_SCHEMA: &str = r#"{"type":"object","title":"pa10.Event","properties":{
"stamp_s":{"type":"number"},"kind":{"type":"string","description":"state, fault, command, recording"},
"text":{"type":"string"}}}"#;

/// The writer thread of one recording.
pub struct Recorder;

impl Recorder {
    /// Starts a recording to `name` inside `cfg.dir` (a plain file name; `.mcap` added when
    /// missing): creates `cfg.dir` when it does not exist ([`RECORD_DIR_MODE`]), opens the
    /// first file (so a bad name or folder is refused now, not later), starts the writer
    /// thread and returns the core's tap.
    pub fn start(
        cfg: &RecordConfig,
        name: &str,
        until_s: Option<f64>,
    ) -> Result<RecordTap, RecordError> {
        cfg.validate().map_err(RecordError::Config)?;
        let base = file_in(&cfg.dir, name)?;
        create_dir(&cfg.dir)?;
        if base.exists() {
            return Err(RecordError::Exists(base));
        }
        let open: OpenSink = {
            let base = base.clone();
            Box::new(move |i| {
                let path = rotated(&base, i);
                let f = File::options().write(true).create_new(true).open(&path)?;
                Ok((
                    Box::new(BufWriter::with_capacity(SINK_BUFFER, f)) as Box<dyn Sink>,
                    path,
                ))
            })
        };
        Self::start_with(cfg, open, until_s, base)
    }

    /// As [`Recorder::start`] with a custom sink (tests: a slow or failing disk).
    pub fn start_with(
        cfg: &RecordConfig,
        mut open: OpenSink,
        until_s: Option<f64>,
        first: PathBuf,
    ) -> Result<RecordTap, RecordError> {
        cfg.validate().map_err(RecordError::Config)?;
        let (sink, path) = open(0).map_err(|e| RecordError::Io {
            path: first.clone(),
            error: e.to_string(),
        })?;
        let (producer, consumer) = rtrb::RingBuffer::new(cfg.queue);
        let stats = Arc::new(RecorderStats::default());
        if let Ok(mut p) = stats.path.lock() {
            *p = path;
        }
        let w = Writer {
            open,
            stats: stats.clone(),
            compression: compression(&cfg.compression).map_err(RecordError::Config)?,
            max_file: (cfg.max_file_mb * 1048576.0) as u64,
            budget: (cfg.budget_mb * 1048576.0) as u64,
        };
        std::thread::Builder::new()
            .name("pa10d-record".into())
            .spawn(move || w.run(consumer, sink))
            .map_err(|e| RecordError::Io {
                path: first,
                error: e.to_string(),
            })?;
        Ok(RecordTap {
            producer,
            stats,
            until_s,
        })
    }
}

/// `name` as a file inside `dir`: a plain name only (no folders, no `..`), `.mcap` added.
pub fn file_in(dir: &Path, name: &str) -> Result<PathBuf, RecordError> {
    let plain = !name.is_empty()
        && name.len() <= 200
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if !plain {
        return Err(RecordError::Name(crate::text::truncate(name, 64)));
    }
    let mut f = dir.join(name);
    if f.extension().is_none_or(|e| e != "mcap") {
        f.set_extension("mcap");
    }
    Ok(f)
}

/// Largest chunk the recorder writes, bytes of JSON before compression: a chunk reaches the
/// file when it closes, so a crash loses at most this much (≈ 160 cycles of ≈ 830 bytes, 0.3 s at 500 Hz,
/// docs/recording.md) plus what the queue held; `pa10 record recover` rewrites the rest.
pub const CHUNK_BYTES: u64 = 128 << 10;

/// The file's write buffer, bytes (compressed chunks): smaller than a chunk, so a closed chunk
/// is on its way to the disk rather than waiting in memory for the next ones.
const SINK_BUFFER: usize = 8 << 10;

/// Mode of a recording folder the recorder creates: the daemon's user and group read it.
pub const RECORD_DIR_MODE: u32 = 0o750;

/// Creates `dir` (and its parents) with [`RECORD_DIR_MODE`] unless it is a folder already.
fn create_dir(dir: &Path) -> Result<(), RecordError> {
    use std::os::unix::fs::DirBuilderExt;
    if dir.is_dir() {
        return Ok(());
    }
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(RECORD_DIR_MODE)
        .create(dir)
        .map_err(|e| RecordError::Io {
            path: dir.to_path_buf(),
            error: format!("record.dir could not be created: {e}"),
        })
}

/// The `i`-th file of a recording: `base` itself, then `base-001.mcap`, …
pub fn rotated(base: &Path, i: usize) -> PathBuf {
    if i == 0 {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    base.with_file_name(format!("{stem}-{i:03}.mcap"))
}

struct Writer {
    open: OpenSink,
    stats: Arc<RecorderStats>,
    compression: Option<mcap::Compression>,
    max_file: u64,
    budget: u64,
}

/// A sink that knows how far it was written, bytes.
struct Counted {
    inner: Box<dyn Sink>,
    pos: u64,
    end: Arc<AtomicU64>,
}

impl Write for Counted {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(b)?;
        self.pos += n as u64;
        self.end.fetch_max(self.pos, Ordering::Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, p: std::io::SeekFrom) -> std::io::Result<u64> {
        self.pos = self.inner.seek(p)?;
        Ok(self.pos)
    }
}

/// One open MCAP file and its channels.
struct Open {
    w: mcap::Writer<Counted>,
    size: Arc<AtomicU64>,
    cycle: u16,
    event: u16,
    seq: u32,
}

impl Writer {
    fn open_mcap(&self, sink: Box<dyn Sink>) -> Result<Open, mcap::McapError> {
        let size = Arc::new(AtomicU64::new(0));
        let mut w = mcap::WriteOptions::new()
            .compression(self.compression)
            .profile("")
            .library("pa10d")
            // chunks reach the file when closed: at most half a file, so rotation and the
            // budget see the size in time, and CHUNK_BYTES, what a crash can lose
            .chunk_size(Some(CHUNK_BYTES.min(self.max_file / 2).max(4096)))
            .create(Counted {
                inner: sink,
                pos: 0,
                end: size.clone(),
            })?;
        let none = std::collections::BTreeMap::new();
        let cs = w.add_schema("pa10.Cycle", "jsonschema", CYCLE_SCHEMA.as_bytes())?;
        let es = w.add_schema("pa10.Event", "jsonschema", EVENT_SCHEMA.as_bytes())?;
        let cycle = w.add_channel(cs, "/pa10/cycle", "json", &none)?;
        let event = w.add_channel(es, "/pa10/event", "json", &none)?;
        Ok(Open {
            w,
            size,
            cycle,
            event,
            seq: 0,
        })
    }

    fn fail(&self, e: impl std::fmt::Display) {
        if let Ok(mut slot) = self.stats.error.lock()
            && slot.is_none()
        {
            tracing::error!(error = %e, "recording: writing failed; records are dropped and counted");
            *slot = Some(crate::text::truncate(&e.to_string(), 300));
        }
    }

    fn run(mut self, mut rx: rtrb::Consumer<Record>, sink: Box<dyn Sink>) {
        let mut file = match self.open_mcap(sink) {
            Ok(f) => Some(f),
            Err(e) => {
                self.fail(e);
                None
            }
        };
        self.stats.files.store(1, Ordering::Relaxed);
        let mut index = 0usize;
        let mut closed_bytes = 0u64;
        let mut buf = Vec::with_capacity(2048);
        let mut since_check = 0u32;
        loop {
            let r = match rx.pop() {
                Ok(r) => r,
                Err(_) if rx.is_abandoned() => break,
                Err(_) => {
                    std::thread::sleep(Duration::from_millis(5));
                    continue;
                }
            };
            let Some(f) = file.as_mut() else {
                self.stats.dropped_write.fetch_add(1, Ordering::Relaxed);
                continue;
            };
            buf.clear();
            let (channel, stamp) = match &r {
                Record::Cycle(c) => (f.cycle, c.stamp_s),
                Record::Event(e) => (f.event, e.stamp_s),
            };
            let encoded = match &r {
                Record::Cycle(c) => serde_json::to_writer(&mut buf, c),
                Record::Event(e) => serde_json::to_writer(&mut buf, e),
            };
            let ns = (stamp.max(0.0) * 1e9) as u64;
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: f.seq,
                log_time: ns,
                publish_time: ns,
            };
            f.seq = f.seq.wrapping_add(1);
            match encoded.map_err(|e| e.to_string()).and_then(|()| {
                f.w.write_to_known_channel(&header, &buf)
                    .map_err(|e| with_sources(&e))
            }) {
                Ok(()) => {
                    self.stats.written.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    self.stats.dropped_write.fetch_add(1, Ordering::Relaxed);
                    self.fail(e);
                    file = None;
                    continue;
                }
            }
            // size: checked every 500 records (the position of the underlying writer)
            since_check += 1;
            if since_check >= 500 {
                since_check = 0;
                let size = f.size.load(Ordering::Relaxed);
                self.stats
                    .bytes
                    .store(closed_bytes + size, Ordering::Relaxed);
                if closed_bytes + size >= self.budget {
                    self.fail(format!(
                        "the disk budget (record.budget_mb, {} bytes) is used up; recording stopped",
                        self.budget
                    ));
                    if let Some(f) = file.take() {
                        let _ = finish(f);
                    }
                    continue;
                }
                if size >= self.max_file {
                    if let Some(f) = file.take() {
                        closed_bytes += finish(f).unwrap_or(size);
                    }
                    index += 1;
                    match (self.open)(index)
                        .map_err(|e| e.to_string())
                        .and_then(|(s, _)| self.open_mcap(s).map_err(|e| e.to_string()))
                    {
                        Ok(f) => {
                            file = Some(f);
                            self.stats.files.store(index as u64 + 1, Ordering::Relaxed);
                        }
                        Err(e) => self.fail(e),
                    }
                }
            }
        }
        if let Some(mut f) = file.take() {
            let stats = &self.stats;
            let mut counts = std::collections::BTreeMap::new();
            for (k, v) in [
                ("written", &stats.written),
                ("dropped_queue", &stats.dropped_queue),
                ("dropped_write", &stats.dropped_write),
            ] {
                counts.insert(k.to_string(), v.load(Ordering::Relaxed).to_string());
            }
            let _ = f.w.write_metadata(&mcap::records::Metadata {
                name: "pa10d.recorder".into(),
                metadata: counts,
            });
            match finish(f) {
                Ok(n) => {
                    self.stats.bytes.store(closed_bytes + n, Ordering::Relaxed);
                }
                Err(e) => self.fail(e),
            }
        }
        self.stats.finished.store(true, Ordering::SeqCst);
    }
}

/// An error with its causes ("writing: no space left on device").
fn with_sources(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cause = c.source();
    }
    s
}

/// Every file of the recording that starts with `first` (its rotations that exist), in order.
pub fn files_of(first: &Path) -> Vec<PathBuf> {
    (0..100_000)
        .map(|i| rotated(first, i))
        .take_while(|p| p.exists())
        .collect()
}

/// Writes the summary and closes the file; its size, bytes.
fn finish(mut f: Open) -> Result<u64, String> {
    f.w.finish().map_err(|e| with_sources(&e))?;
    let mut sink = f.w.into_inner();
    sink.flush().map_err(|e| e.to_string())?;
    Ok(sink.end.load(Ordering::Relaxed))
}
