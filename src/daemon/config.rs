//! The daemon's configuration (`config/pa10d.yaml`, `config/sim.yaml`), read once and
//! validated once: the file's plain data ([`Config`], serde_yaml with `deny_unknown_fields`)
//! becomes [`Settings`] — every value checked (each error names its key and the reason), the
//! model loaded, every path resolved against the file's folder, every time in seconds, and
//! the loop's ([`LoopParams`]) and the link's ([`LinkConfig`]) parameters built. Nothing
//! after it reads the file's form again. Validating touches no bus: `pa10d --check-config
//! FILE` is this module.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::control::LoopParams;
use super::link::LinkConfig;
use super::vocab::Limits;
use crate::can::BusTiming;
use crate::can::timing::RateError;
use crate::model::Model;
use crate::record::RecordConfig;

pub use super::vocab::TorqueSource;

/// Which bus backend the daemon drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Linux SocketCAN (a real adapter, or vcan).
    Socketcan,
    /// The in-process virtual bus with the simulated servo controller.
    Virtual,
}

/// The CAN bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusConfig {
    /// Backend.
    pub backend: Backend,
    /// SocketCAN interface (e.g. `can0`); required with `socketcan`.
    #[serde(default)]
    pub interface: Option<String>,
    /// Bit rate, bit/s (the interface's, configured by the system); on CAN FD the nominal
    /// (arbitration-phase) rate.
    #[serde(default = "default_bitrate")]
    pub bitrate: f64,
    /// CAN FD: one COMMAND_FD and one FEEDBACK_FD frame a cycle instead of six of each
    /// (`docs/protocol.md`); the interface must be in FD mode (MTU 72). Default false.
    #[serde(default)]
    pub fd: bool,
    /// CAN FD data-phase bit rate, bit/s (frames switch to it after arbitration); only with
    /// `fd: true`; absent: `bitrate` (no faster data phase).
    #[serde(default)]
    pub data_bitrate: Option<f64>,
    /// Largest accepted worst-case bus load of the cyclic traffic, 0…1.
    #[serde(default = "default_max_load")]
    pub max_load: f64,
}

fn default_bitrate() -> f64 {
    1e6
}

impl BusConfig {
    /// The bus's framing and bit rates.
    pub fn timing(&self) -> BusTiming {
        if self.fd {
            BusTiming::fd(self.bitrate, self.data_bitrate.unwrap_or(self.bitrate))
        } else {
            BusTiming::classic(self.bitrate)
        }
    }
}
fn default_max_load() -> f64 {
    0.9
}

/// Real-time options of the control thread.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Realtime {
    /// SCHED_FIFO priority of the control thread (1…99); absent: normal scheduling.
    #[serde(default)]
    pub sched_fifo_priority: Option<u8>,
    /// Lock the daemon's memory (mlockall) when permitted.
    #[serde(default)]
    pub mlockall: bool,
}

/// The control loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// Cycle rate, Hz (checked against the bus budget).
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// Position-loop gain, 1/s (speed command = feed-forward + gain × motor-angle error).
    #[serde(default = "default_gain")]
    pub position_gain: f64,
    /// Torque source of the compensation.
    #[serde(default = "default_torque_source")]
    pub torque_source: TorqueSource,
    /// Low-pass cut-off of the measured torques, Hz.
    #[serde(default = "default_filter")]
    pub current_filter_hz: f64,
    /// Holding, a joint whose motor-angle error (link side) is below this gets no position
    /// correction, rad (0 … 1e-3; 0: off). On sticking drives a loop that keeps correcting
    /// within the stuck band winds the speed loop up to breakaway, slips past and hunts
    /// (docs/judge.md §8); a band of a few resolver counts (one count is 7.7 µrad link side)
    /// lets the joint stop.
    #[serde(default)]
    pub hold_deadband: f64,
    /// Holding, this × the motor speed the resolvers show is taken off the speed command
    /// (dimensionless, 0 … 10; 0: off). A sticking drive breaks away with its speed loop
    /// wound up to the static level and slips far past the target (hundreds of µrad on the
    /// MuJoCo plant's J2): the term brakes it at once (docs/judge.md §8).
    #[serde(default)]
    pub hold_damping: f64,
    /// The shoulder's (J2's) inertia up to which the position gain applies in full, kg·m²
    /// (link side: the model's bodies as point masses and the payload at the tool); above it
    /// the gain falls in proportion, `position_gain × min(1, this / I₂(q, payload))`. Absent,
    /// the gain is constant. A payload at a metre's reach triples the inertia the shoulder's
    /// drive moves, its speed loop slows in proportion, and a position loop as fast as the bare
    /// arm's then drives the arm's link mode: on MuJoCo's arm gain 20 faulted a 90 N sweep in a
    /// 3 Hz limit cycle at I₂ ≈ 20 kg·m² (docs/judge.md §8). The limit is the drive's: measure
    /// it on the arm with a heavy payload stretched out.
    #[serde(default)]
    pub gain_inertia_kgm2: Option<f64>,
    /// Real-time options.
    #[serde(default)]
    pub realtime: Realtime,
}

fn default_rate() -> f64 {
    500.0
}
fn default_gain() -> f64 {
    20.0
}
fn default_torque_source() -> TorqueSource {
    TorqueSource::Measured
}
fn default_filter() -> f64 {
    20.0
}

/// The `limits` section: motion and safety limits (link side). Validated into the loop's
/// [`Limits`] (with the model's position limits) and time limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitsConfig {
    /// Speed limits for moves, rad/s (each ≤ the model's).
    pub speed: [f64; 6],
    /// Acceleration limits, rad/s².
    pub acceleration: [f64; 6],
    /// Shortest acceleration ramp of a move, s (0…[`MAX_MIN_RAMP_S`], default 0: none): at
    /// least the period of the loaded arm's lowest mode, so small moves do not ring it.
    #[serde(default)]
    pub min_ramp_s: f64,
    /// Largest tolerated |setpoint − measured| per joint, rad.
    pub following_error: f64,
    /// Feedback older than this stops the arm, ms.
    pub feedback_timeout_ms: f64,
    /// The command watchdog asked of the servo controller, ms (1…255): with no command for
    /// this long it stops the arm by itself (the daemon died or its host stalled). Default
    /// 50 ms: a loaded host without real-time priority can pause the loop for 20–30 ms.
    #[serde(default = "default_controller_watchdog")]
    pub controller_watchdog_ms: f64,
}

fn default_controller_watchdog() -> f64 {
    50.0
}

/// The `servo` section: streamed commands (`servo`, `jog`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StreamConfig {
    /// With no new servo setpoint or jog command for this long the arm makes a controlled
    /// stop, ms (two cycles … 10 s; default 100).
    #[serde(default = "default_servo_deadline")]
    pub deadline_ms: f64,
}

fn default_servo_deadline() -> f64 {
    100.0
}

fn default_servo() -> StreamConfig {
    StreamConfig {
        deadline_ms: default_servo_deadline(),
    }
}

/// The client API socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ApiConfig {
    /// Unix socket path.
    #[serde(default = "default_socket")]
    pub socket: PathBuf,
    /// Socket file mode, octal text (e.g. "0660").
    #[serde(default = "default_mode")]
    pub mode: String,
    /// The only directory `load_model` reads from (relative paths are taken in it; symlinks
    /// out of it are refused).
    #[serde(default = "default_model_dir")]
    pub model_dir: PathBuf,
    /// Clients connected at once (1…1000); one more is refused with a reason.
    #[serde(default = "default_max_clients")]
    pub max_clients: usize,
}

fn default_socket() -> PathBuf {
    PathBuf::from("/run/pa10d/pa10d.sock")
}
fn default_mode() -> String {
    "0660".into()
}
fn default_max_clients() -> usize {
    64
}
/// The only directory `load_model` reads from unless the configuration names another.
pub const DEFAULT_MODEL_DIR: &str = "/etc/pa10d";

fn default_model_dir() -> PathBuf {
    PathBuf::from(DEFAULT_MODEL_DIR)
}

pub use crate::sim::plant::SimConfig;

/// Everything `pa10d` reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// CAN bus.
    pub bus: BusConfig,
    /// Control loop.
    #[serde(default = "default_control")]
    pub control: ControlConfig,
    /// Model file (nominal or calibrated), relative to the config file's folder.
    pub model: PathBuf,
    /// Motor current → link torque constants, N·m/A.
    pub torque_constants: [f64; 6],
    /// Weight hung at the tool, N.
    #[serde(default)]
    pub payload_n: f64,
    /// Motion and safety limits.
    pub limits: LimitsConfig,
    /// Client API.
    #[serde(default = "default_api")]
    pub api: ApiConfig,
    /// Streamed commands.
    #[serde(default = "default_servo")]
    pub servo: StreamConfig,
    /// Recording every cycle (MCAP).
    #[serde(default)]
    pub record: RecordConfig,
    /// The live view (Foxglove WebSocket, loopback only; off by default).
    #[serde(default)]
    pub live: LiveConfig,
    /// Log filter (tracing syntax, e.g. `info`, `pa10=debug`).
    #[serde(default = "default_log")]
    pub log_level: String,
    /// The simulated robot (virtual backend only).
    #[serde(default)]
    pub sim: Option<SimConfig>,
}

/// The widest `control.hold_deadband`, rad (≈ 1 mm at the tool).
pub const MAX_HOLD_DEADBAND: f64 = 1e-3;

/// The longest `limits.min_ramp_s`, s.
pub const MAX_MIN_RAMP_S: f64 = 2.0;

/// The range of `control.gain_inertia_kgm2`, kg·m².
pub const MIN_GAIN_INERTIA_KGM2: f64 = 0.01;
/// See [`MIN_GAIN_INERTIA_KGM2`].
pub const MAX_GAIN_INERTIA_KGM2: f64 = 1000.0;

/// The largest `control.hold_damping` (dimensionless).
pub const MAX_HOLD_DAMPING: f64 = 10.0;

fn default_control() -> ControlConfig {
    ControlConfig {
        rate_hz: default_rate(),
        position_gain: default_gain(),
        torque_source: default_torque_source(),
        current_filter_hz: default_filter(),
        hold_deadband: 0.0,
        hold_damping: 0.0,
        gain_inertia_kgm2: None,
        realtime: Realtime::default(),
    }
}
fn default_api() -> ApiConfig {
    ApiConfig {
        socket: default_socket(),
        mode: default_mode(),
        model_dir: default_model_dir(),
        max_clients: default_max_clients(),
    }
}
fn default_log() -> String {
    "info".into()
}

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Malformed YAML, unknown or mistyped key (the message has line and column).
    #[error("{origin}: {message}")]
    Parse {
        /// Where the text came from.
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A value is out of range.
    #[error("invalid `{key}`: {reason}")]
    Invalid {
        /// The key, e.g. `limits.speed[2]`.
        key: String,
        /// Why, with units.
        reason: String,
    },
}

/// `value` within `0…max` (`unit` appended to the bound in the refusal), or the refusal naming
/// `key`.
fn within(key: &str, value: f64, max: f64, unit: &str) -> Result<(), ConfigError> {
    if value.is_finite() && (0.0..=max).contains(&value) {
        Ok(())
    } else {
        Err(invalid(
            key,
            format!("must be within 0…{max}{unit}, got {value}"),
        ))
    }
}

fn invalid(key: impl Into<String>, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        reason: reason.into(),
    }
}

/// A validated configuration: what the daemon, its shell and the simulated arm are built
/// from. Paths are resolved against the configuration file's folder, times are in seconds,
/// and the loop's and the link's parameters are built; the file's form is not kept.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The CAN bus as configured.
    pub bus: BusConfig,
    /// The cyclic traffic's worst-case bus load at the configured rate, 0…1.
    pub bus_load: f64,
    /// Cycle rate, Hz.
    pub rate_hz: f64,
    /// The control loop's parameters (period, gain, torques, payload, limits, time limits).
    pub control: LoopParams,
    /// The servo link's timing (period, the controller's command watchdog).
    pub link: LinkConfig,
    /// Real-time options of the control thread.
    pub realtime: Realtime,
    /// The model file, resolved.
    pub model_path: PathBuf,
    /// The model.
    pub model: Model,
    /// The client API.
    pub api: ApiSettings,
    /// Recording every cycle, its folder resolved.
    pub record: RecordConfig,
    /// The live view.
    pub live: LiveConfig,
    /// Log filter (tracing syntax).
    pub log_level: String,
    /// The simulated robot (virtual backend only), its truth file resolved.
    pub sim: Option<SimConfig>,
}

/// The client API, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiSettings {
    /// Unix socket path.
    pub socket: PathBuf,
    /// Socket file mode (e.g. `0o660`).
    pub mode: u32,
    /// The only directory `load_model` reads from, resolved.
    pub model_dir: PathBuf,
    /// Clients connected at once.
    pub max_clients: usize,
}

/// The settings of the shipped simulation configuration `config/sim.yaml` as it reads (the
/// unit tests' and examples' fixture). Panics when that file is invalid: it is the
/// repository's, not a user's.
#[cfg(test)]
pub(crate) fn shipped_sim() -> Settings {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config");
    Config::load(&dir.join("sim.yaml")).expect("config/sim.yaml is valid")
}

impl Config {
    /// Parses YAML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        serde_yaml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.into(),
            message: e.to_string(),
        })
    }

    /// Reads, validates and loads the model of a configuration file.
    pub fn load(path: &Path) -> Result<Settings, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let config = Self::parse(&text, &path.display().to_string())?;
        // a bare file name's parent is "": its folder is the working directory
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
        config.validate(folder.unwrap_or(Path::new(".")))
    }

    /// Validates every value and loads the model (`base`: folder relative paths start from).
    pub fn validate(self, base: &Path) -> Result<Settings, ConfigError> {
        let c = &self;
        if c.bus.backend == Backend::Socketcan
            && c.bus.interface.as_deref().is_none_or(str::is_empty)
        {
            return Err(invalid(
                "bus.interface",
                "the socketcan backend needs an interface name, e.g. can0",
            ));
        }
        if !(c.bus.max_load > 0.0 && c.bus.max_load <= 1.0) {
            return Err(invalid(
                "bus.max_load",
                format!("must be within (0, 1], got {}", c.bus.max_load),
            ));
        }
        if c.bus.data_bitrate.is_some() && !c.bus.fd {
            return Err(invalid(
                "bus.data_bitrate",
                "is CAN FD's data-phase rate: set bus.fd: true, or remove it",
            ));
        }
        let timing = c.bus.timing();
        timing.validate().map_err(|e| {
            let key = match e {
                RateError::DataBitrate { .. } => "bus.data_bitrate",
                _ => "bus.bitrate",
            };
            invalid(key, e.to_string())
        })?;
        let bus_load = timing
            .check_rate(c.control.rate_hz, c.bus.max_load)
            .map_err(|r| invalid("control.rate_hz", r))?;
        if !(c.control.position_gain.is_finite()
            && c.control.position_gain > 0.0
            && c.control.position_gain < c.control.rate_hz / 2.0)
        {
            return Err(invalid(
                "control.position_gain",
                format!(
                    "must be > 0 and below half the cycle rate ({} 1/s), got {}",
                    c.control.rate_hz / 2.0,
                    c.control.position_gain
                ),
            ));
        }
        within(
            "control.hold_deadband",
            c.control.hold_deadband,
            MAX_HOLD_DEADBAND,
            " rad",
        )?;
        within(
            "limits.min_ramp_s",
            c.limits.min_ramp_s,
            MAX_MIN_RAMP_S,
            " s",
        )?;
        within(
            "control.hold_damping",
            c.control.hold_damping,
            MAX_HOLD_DAMPING,
            "",
        )?;
        if let Some(h) = c.control.gain_inertia_kgm2
            && !(h.is_finite() && (MIN_GAIN_INERTIA_KGM2..=MAX_GAIN_INERTIA_KGM2).contains(&h))
        {
            return Err(invalid(
                "control.gain_inertia_kgm2",
                format!(
                    "an inertia of {MIN_GAIN_INERTIA_KGM2}…{MAX_GAIN_INERTIA_KGM2} kg·m² (or absent: a constant gain), got {h}"
                ),
            ));
        }
        if !(c.control.current_filter_hz.is_finite()
            && c.control.current_filter_hz > 0.0
            && c.control.current_filter_hz < c.control.rate_hz / 2.0)
        {
            return Err(invalid(
                "control.current_filter_hz",
                format!(
                    "must be > 0 Hz and below the Nyquist rate {} Hz",
                    c.control.rate_hz / 2.0
                ),
            ));
        }
        if let Some(p) = c.control.realtime.sched_fifo_priority
            && !(1..=99).contains(&p)
        {
            return Err(invalid(
                "control.realtime.sched_fifo_priority",
                format!("must be 1…99, got {p}"),
            ));
        }
        for (j, k) in c.torque_constants.iter().enumerate() {
            if !(k.is_finite() && *k > 0.0) {
                return Err(invalid(
                    format!("torque_constants[{j}]"),
                    format!("must be > 0 N·m/A, got {k}"),
                ));
            }
        }
        if !(c.payload_n.is_finite() && c.payload_n >= 0.0 && c.payload_n <= 500.0) {
            return Err(invalid(
                "payload_n",
                format!("must be within 0…500 N, got {}", c.payload_n),
            ));
        }
        let model_path = base.join(&c.model);
        let model = Model::load(&model_path).map_err(|e| invalid("model", e.to_string()))?;
        let l = &c.limits;
        for j in 0..6 {
            let vmax = model.limits().velocity[j];
            if !(l.speed[j].is_finite() && l.speed[j] > 0.0 && l.speed[j] <= vmax) {
                return Err(invalid(
                    format!("limits.speed[{j}]"),
                    format!(
                        "must be within (0, {vmax}] rad/s (the model's limit), got {}",
                        l.speed[j]
                    ),
                ));
            }
            if !(l.acceleration[j].is_finite()
                && l.acceleration[j] > 0.0
                && l.acceleration[j] <= 50.0)
            {
                return Err(invalid(
                    format!("limits.acceleration[{j}]"),
                    format!("must be within (0, 50] rad/s², got {}", l.acceleration[j]),
                ));
            }
        }
        if !(l.following_error.is_finite() && l.following_error > 0.0 && l.following_error <= 0.5) {
            return Err(invalid(
                "limits.following_error",
                format!("must be within (0, 0.5] rad, got {}", l.following_error),
            ));
        }
        let period_ms = 1e3 / c.control.rate_hz;
        // a time limit of at least two cycles, at most `max` ms
        let within = |key: &str, v: f64, max: f64, note: &str| {
            if v.is_finite() && v >= 2.0 * period_ms && v <= max {
                Ok(())
            } else {
                Err(invalid(
                    key,
                    format!(
                        "must be within [{:.1}, {max}] ms (at least two cycles{note}), got {v}",
                        2.0 * period_ms
                    ),
                ))
            }
        };
        within(
            "limits.feedback_timeout_ms",
            l.feedback_timeout_ms,
            1000.0,
            "",
        )?;
        within(
            "limits.controller_watchdog_ms",
            l.controller_watchdog_ms,
            255.0,
            "; the protocol's field is one byte",
        )?;
        within("servo.deadline_ms", c.servo.deadline_ms, 10_000.0, "")?;
        if !(1..=1000).contains(&c.api.max_clients) {
            return Err(invalid(
                "api.max_clients",
                format!("must be within 1…1000, got {}", c.api.max_clients),
            ));
        }
        let socket_mode = u32::from_str_radix(c.api.mode.trim_start_matches("0o"), 8)
            .ok()
            .filter(|m| *m <= 0o777)
            .ok_or_else(|| {
                invalid(
                    "api.mode",
                    format!(
                        "must be an octal file mode like \"0660\", got {:?}",
                        c.api.mode
                    ),
                )
            })?;
        if c.api.socket.as_os_str().is_empty() {
            return Err(invalid("api.socket", "needs a path"));
        }
        self.live
            .validate()
            .map_err(|e| invalid("live.rate_hz", e))?;
        if c.log_level.trim().is_empty() {
            return Err(invalid("log_level", "needs a filter such as `info`"));
        }
        match (c.bus.backend, &c.sim) {
            (Backend::Socketcan, Some(_)) => {
                return Err(invalid(
                    "sim",
                    "only the virtual backend has a simulated robot",
                ));
            }
            (Backend::Virtual, Some(SimConfig { truth: Some(t), .. }))
                if !base.join(t).exists() =>
            {
                return Err(invalid(
                    "sim.truth",
                    format!("{} does not exist", base.join(t).display()),
                ));
            }
            (_, Some(sim)) => sim
                .plant
                .validate()
                .map_err(|(key, reason)| invalid(format!("sim.plant.{key}"), reason))?,
            _ => {}
        }
        self.record.validate().map_err(|e| invalid("record", e))?;
        let Config {
            bus,
            control,
            torque_constants,
            payload_n,
            limits,
            api,
            servo,
            mut record,
            live,
            log_level,
            sim,
            model: _,
        } = self;
        record.dir = base.join(&record.dir);
        let period_s = 1.0 / control.rate_hz;
        let framing = bus.timing().framing;
        let loop_params = LoopParams {
            period_s,
            gain: control.position_gain,
            torque_source: control.torque_source,
            filter_hz: control.current_filter_hz,
            hold_deadband: control.hold_deadband,
            hold_damping: control.hold_damping,
            gain_inertia_kgm2: control.gain_inertia_kgm2,
            torque_constants,
            payload_n,
            payload_com: [0.0; 3],
            limits: Limits {
                lower: model.limits().lower,
                upper: model.limits().upper,
                speed: limits.speed,
                acceleration: limits.acceleration,
                min_ramp_s: limits.min_ramp_s,
            },
            following_error: limits.following_error,
            feedback_timeout_s: limits.feedback_timeout_ms * 1e-3,
            stream_deadline_s: servo.deadline_ms * 1e-3,
        };
        // within 1…255 ms (checked above): the protocol's one-byte field
        let watchdog_ms = limits.controller_watchdog_ms.round().clamp(1.0, 255.0) as u8;
        Ok(Settings {
            bus,
            bus_load,
            rate_hz: control.rate_hz,
            control: loop_params,
            link: LinkConfig::new(period_s, watchdog_ms).with_framing(framing),
            realtime: control.realtime,
            model_path,
            model,
            api: ApiSettings {
                socket: api.socket,
                mode: socket_mode,
                model_dir: base.join(&api.model_dir),
                max_clients: api.max_clients,
            },
            record,
            live,
            log_level,
            sim: sim.map(|s| SimConfig {
                truth: s.truth.map(|t| base.join(t)),
                seed: s.seed,
                plant: crate::sim::plant::PlantConfig {
                    dir: Some(base.to_path_buf()),
                    ..s.plant
                },
            }),
        })
    }
}

#[cfg(test)]
mod tests;

/// The live view's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveConfig {
    /// Serve it (default no).
    #[serde(default)]
    pub enabled: bool,
    /// TCP port on 127.0.0.1 (default 8765, Foxglove's).
    #[serde(default = "default_live_port")]
    pub port: u16,
    /// Cycles sent per second to each subscriber (1…500, default 50).
    #[serde(default = "default_live_rate")]
    pub rate_hz: f64,
}

fn default_live_port() -> u16 {
    8765
}
fn default_live_rate() -> f64 {
    50.0
}

impl Default for LiveConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            port: default_live_port(),
            rate_hz: default_live_rate(),
        }
    }
}

impl LiveConfig {
    /// Checks the rate; the reason otherwise.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.rate_hz.is_finite() && (1.0..=500.0).contains(&self.rate_hz)) {
            return Err(format!("must be within 1…500 Hz, got {}", self.rate_hz));
        }
        Ok(())
    }
}
