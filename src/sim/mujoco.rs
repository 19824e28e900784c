//! A [`Plant`] that MuJoCo computes in another process: the judge's physics.
//!
//! [`MujocoPlant`] starts `tests/mujoco/plant.py` (a PA10-6C written from the robot's published
//! facts with hidden departures, rotor inertia, friction and flexible joints; it shares no code
//! with pa10) — or any command speaking the same protocol, `docs/plant-protocol.md` — and speaks
//! its stepped JSON-lines protocol over the child's stdin/stdout: `reset`
//! once, then `step` with the speed loop's reference and the brake, `load` for the weight rack.
//! The controller's time is cut into the plant's physics steps (0.5 ms); a call that does not
//! complete a step only accumulates time. A controlled stop ramps the speed reference down at
//! the stop deceleration, as a servo drive does.
//!
//! Limits: every answer line is at most [`MAX_LINE`] bytes, arrives within [`ANSWER_TIMEOUT`]
//! and must parse; the first failure (the process died or hung, an answer that is not the
//! protocol) freezes the plant and is reported by [`Plant::failure`] — a judge checks it before
//! it trusts a number.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
use std::time::Duration;

use serde::Deserialize;

use super::plant::{Drive, FrictionModel, HiddenEffects, MAX_FRICTION_SCALE, Plant, PlantConfig};
use crate::model::{Frame as Pose, frame_from_pose};

/// Longest answer line accepted from the plant process, bytes.
pub const MAX_LINE: usize = 64 * 1024;

/// Longest wait for one answer (a reset builds the model; a step is milliseconds).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(30);

/// Standard gravity the plant uses, m/s² (a load in N becomes a mass in kg).
const G: f64 = 9.80665;

/// How to start the MuJoCo plant.
#[derive(Debug, Clone, PartialEq)]
pub struct MujocoOptions {
    /// The program and its arguments (`python3 tests/mujoco/plant.py`).
    pub command: Vec<String>,
    /// The folder the command runs in (absent: this process's).
    pub dir: Option<PathBuf>,
    /// Seed of the plant's hidden departures (masses, centres, stiffness, geometry).
    pub seed: u64,
    /// Scale of the plant's friction (0: none, 1: the realistic level of docs/judge.md).
    pub friction: f64,
    /// How the dry friction behaves at rest.
    pub friction_model: FrictionModel,
    /// The tool point (and where a load hangs) in the flange frame, m.
    pub tool: [f64; 3],
    /// Link angles the arm starts at rest at, rad.
    pub q0: [f64; 6],
    /// Effects the plant hides (sent only when present; keys that are all zero left out).
    pub hidden: Option<HiddenEffects>,
}

impl MujocoOptions {
    /// `python3` and this crate's `tests/mujoco/plant.py`, the given seed, realistic
    /// friction, a tool 0.35 m along the flange axis (the campaigns' tooling ball).
    pub fn new(seed: u64, q0: [f64; 6]) -> Self {
        Self {
            command: vec!["python3".into(), Self::script()],
            dir: None,
            seed,
            friction: 1.0,
            friction_model: FrictionModel::Creep,
            tool: [0.0, 0.0, 0.35],
            q0,
            hidden: None,
        }
    }

    /// This build tree's `tests/mujoco/plant.py`.
    pub fn script() -> String {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/mujoco/plant.py")
            .display()
            .to_string()
    }

    /// The options a validated `sim.plant` section gives (its seed, else `sim_seed`), the arm
    /// at rest at `q0` (rad) with the tool point at `tool` in the flange frame (m).
    pub fn from_config(c: &PlantConfig, sim_seed: u64, tool: [f64; 3], q0: [f64; 6]) -> Self {
        let mut o = Self::new(c.seed.unwrap_or(sim_seed), q0);
        if let Some(cmd) = &c.command {
            o.command = cmd.clone();
        }
        o.dir = c.dir.clone();
        o.friction = c.friction.unwrap_or(1.0);
        o.friction_model = c.friction_model;
        o.hidden = c.hidden;
        o.tool = tool;
        o
    }

    /// `$PA10_PYTHON <script>` when that variable is set (the judges' interpreter), else the
    /// command as it is.
    pub fn honouring_pa10_python(mut self) -> Self {
        if let (Some(p), Some(script)) = (std::env::var_os("PA10_PYTHON"), self.command.get(1)) {
            self.command = vec![p.to_string_lossy().into_owned(), script.clone()];
        }
        self
    }
}

/// Why the MuJoCo plant could not start or went on.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MujocoError {
    /// The process could not be started or its pipes broke.
    #[error("MuJoCo plant process: {0}")]
    Io(#[from] std::io::Error),
    /// An answer that is not the protocol's.
    #[error("MuJoCo plant answered {0}")]
    Protocol(String),
    /// The plant refused a request (its own message).
    #[error("MuJoCo plant refused: {0}")]
    Refused(String),
    /// An option out of range.
    #[error("MuJoCo plant option {0}")]
    Option(String),
}

/// One answer of the plant (`tests/mujoco/plant.py`'s state).
#[derive(Debug, Clone, Default, Deserialize)]
struct State {
    t: f64,
    motor: [f64; 6],
    motor_speed: [f64; 6],
    link: [f64; 6],
    motor_torque: [f64; 6],
    #[serde(default)]
    spring_torque: Option<[f64; 6]>,
    tool: [f64; 7],
    #[serde(default)]
    dt: Option<f64>,
    #[serde(default)]
    error: Option<String>,
}

/// The MuJoCo plant process (see the module documentation).
#[derive(Debug)]
pub struct MujocoPlant {
    child: Child,
    input: ChildStdin,
    /// Answer lines from the reader thread (each at most [`MAX_LINE`] bytes, or why not).
    answers: Receiver<Result<String, String>>,
    state: State,
    step_s: f64,
    /// Simulated time not yet stepped, s.
    pending_s: f64,
    /// The speed loop's reference, rad/s.
    reference: [f64; 6],
    failure: Option<String>,
}

impl MujocoPlant {
    /// Starts the plant process and puts the arm at rest at `opts.q0`.
    pub fn start(opts: &MujocoOptions) -> Result<Self, MujocoError> {
        if !(0.0..=MAX_FRICTION_SCALE).contains(&opts.friction) {
            return Err(MujocoError::Option(format!(
                "friction {} (a scale 0…{MAX_FRICTION_SCALE})",
                opts.friction
            )));
        }
        if opts.q0.iter().chain(&opts.tool).any(|v| !v.is_finite()) {
            return Err(MujocoError::Option("q0/tool: finite rad and m".into()));
        }
        let Some((program, args)) = opts.command.split_first() else {
            return Err(MujocoError::Option("command: needs a program".into()));
        };
        let mut cmd = Command::new(program);
        cmd.args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        if let Some(d) = &opts.dir {
            cmd.current_dir(d);
        }
        let mut child = cmd.spawn().map_err(|e| {
            MujocoError::Option(format!("command {:?} could not start: {e}", opts.command))
        })?;
        let (Some(input), Some(output)) = (child.stdin.take(), child.stdout.take()) else {
            return Err(MujocoError::Protocol("no pipes".into()));
        };
        let (tx, answers) = sync_channel(1);
        std::thread::Builder::new()
            .name("pa10-plant-reader".into())
            .spawn(move || read_answers(output, tx))?;
        let mut plant = Self {
            child,
            input,
            answers,
            state: State::default(),
            step_s: 0.0,
            pending_s: 0.0,
            reference: [0.0; 6],
            failure: None,
        };
        let mut reset = serde_json::json!({
            "op": "reset", "q": opts.q0, "tool": opts.tool, "seed": opts.seed,
            "friction": opts.friction, "load_kg": 0.0, "friction_model": opts.friction_model,
        });
        if let Some(h) = &opts.hidden {
            h.validate()
                .map_err(|e| MujocoError::Option(format!("hidden: {e}")))?;
            reset["hidden"] = serde_json::json!(h);
        }
        plant.state = plant.request(&reset)?;
        plant.step_s = match plant.state.dt {
            Some(dt) if dt > 0.0 && dt <= 0.01 => dt,
            other => {
                return Err(MujocoError::Protocol(format!(
                    "a physics step of {other:?} s"
                )));
            }
        };
        Ok(plant)
    }

    /// Simulated time of the plant, s.
    pub fn time_s(&self) -> f64 {
        self.state.t
    }

    fn request(&mut self, req: &serde_json::Value) -> Result<State, MujocoError> {
        // one write of the whole line: `writeln!` on the unbuffered pipe wrote every piece of
        // the JSON apart (≈ 5 writes a request, each waking the plant's reader)
        let mut request = req.to_string();
        request.push('\n');
        self.input.write_all(request.as_bytes())?;
        self.input.flush()?;
        let line = match self.answers.recv_timeout(ANSWER_TIMEOUT) {
            Ok(Ok(line)) => line,
            Ok(Err(why)) => return Err(MujocoError::Protocol(why)),
            Err(RecvTimeoutError::Timeout) => {
                return Err(MujocoError::Protocol(format!(
                    "nothing within {} s",
                    ANSWER_TIMEOUT.as_secs()
                )));
            }
            Err(RecvTimeoutError::Disconnected) => {
                return Err(MujocoError::Protocol("nothing: the process ended".into()));
            }
        };
        let s: State = match serde_json::from_str(&line) {
            Ok(s) => s,
            Err(e) => {
                let err: Result<serde_json::Value, _> = serde_json::from_str(&line);
                if let Some(msg) = err.ok().and_then(|v| v["error"].as_str().map(String::from)) {
                    return Err(MujocoError::Refused(msg));
                }
                return Err(MujocoError::Protocol(format!("{e}: {}", line.trim())));
            }
        };
        match s.error {
            Some(e) => Err(MujocoError::Refused(e)),
            None => Ok(s),
        }
    }

    fn send(&mut self, req: serde_json::Value) {
        if self.failure.is_some() {
            return;
        }
        match self.request(&req) {
            Ok(s) => self.state = s,
            Err(e) => self.failure = Some(e.to_string()),
        }
    }
}

/// The reader thread: one answer line at a time (at most [`MAX_LINE`] bytes) to `tx`, until
/// the process ends, a line is too long, or nobody listens.
fn read_answers(output: impl Read, tx: SyncSender<Result<String, String>>) {
    let mut output = BufReader::new(output);
    loop {
        let mut line = String::with_capacity(1024);
        let msg = match (&mut output).take(MAX_LINE as u64 + 1).read_line(&mut line) {
            Ok(0) => Err("nothing: the process ended".to_string()),
            Ok(n) if n > MAX_LINE => Err(format!("a line over {MAX_LINE} bytes")),
            Ok(_) => Ok(line),
            Err(e) => Err(format!("unreadable output: {e}")),
        };
        let last = msg.is_err();
        if tx.send(msg).is_err() || last {
            return;
        }
    }
}

impl Plant for MujocoPlant {
    fn advance(&mut self, dt: f64, drive: &Drive) {
        for j in 0..6 {
            let lim = drive.speed_limit[j];
            self.reference[j] = match drive.stop_decel {
                _ if !drive.engaged => 0.0,
                Some(a) => 0.0f64.clamp(self.reference[j] - a * dt, self.reference[j] + a * dt),
                None => drive.speed[j].clamp(-lim, lim),
            };
        }
        self.pending_s += dt;
        let steps = (self.pending_s / self.step_s + 1e-9).floor();
        if steps < 1.0 {
            return;
        }
        self.pending_s -= steps * self.step_s;
        let req = serde_json::json!({
            "op": "step", "dt": steps * self.step_s, "speed": self.reference,
            "brake": !drive.engaged,
        });
        self.send(req);
    }

    fn motor_angles(&self) -> [f64; 6] {
        self.state.motor
    }

    fn motor_speeds(&self) -> [f64; 6] {
        self.state.motor_speed
    }

    fn link_state(&self) -> ([f64; 6], [f64; 6]) {
        (self.state.link, self.state.motor_torque)
    }

    fn spring_torques(&self) -> Option<[f64; 6]> {
        self.state.spring_torque
    }

    fn tool_pose(&self) -> Pose {
        let t = &self.state.tool;
        frame_from_pose([t[0], t[1], t[2]], [t[3], t[4], t[5], t[6]])
    }

    fn set_load(&mut self, newtons: f64) {
        self.send(serde_json::json!({"op": "load", "kg": newtons.max(0.0) / G}));
    }

    fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }
}

impl Drop for MujocoPlant {
    fn drop(&mut self) {
        let _ = writeln!(self.input, "{{\"op\": \"quit\"}}");
        let _ = self.input.flush();
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
