//! The daemon client: `pa10 status`, `pa10 move joints|pose`, `pa10 stop|estop|reset`,
//! `pa10 payload`, `pa10 load-model`, `pa10 watch` — one JSON request per call over the
//! daemon's Unix socket (docs/api.md).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use serde_json::{Value, json};

/// Where the daemon listens.
#[derive(Debug, Args, Clone)]
pub struct Conn {
    /// The daemon's API socket.
    #[arg(
        long,
        value_name = "PATH",
        env = "PA10D_SOCKET",
        default_value = "/run/pa10d/pa10d.sock",
        global = true
    )]
    socket: PathBuf,
    /// Print the daemon's JSON answer as is.
    #[arg(long, global = true)]
    json: bool,
}

/// `pa10 move …`
#[derive(Debug, Subcommand)]
pub enum MoveCmd {
    /// Joint move to link angles Q1 … Q6 (rad, or degrees with --deg).
    #[command(allow_negative_numbers = true)]
    Joints {
        /// Target angles.
        #[arg(num_args = 6, required = true)]
        q: Vec<f64>,
        /// Angles in degrees.
        #[arg(long)]
        deg: bool,
        /// Block until the move settles, then print the final pose.
        #[arg(long)]
        wait: bool,
    },
    /// Straight-line tool move to X Y Z (m) QW QX QY QZ (base frame).
    #[command(allow_negative_numbers = true)]
    Pose {
        /// Target pose.
        #[arg(num_args = 7, required = true)]
        pose: Vec<f64>,
        /// Block until the move settles, then print the final pose.
        #[arg(long)]
        wait: bool,
    },
}

impl Conn {
    /// The daemon's API socket.
    pub fn socket(&self) -> &std::path::Path {
        &self.socket
    }
}

fn send(c: &Conn, req: &Value) -> Result<Value> {
    let mut s = UnixStream::connect(&c.socket).with_context(|| {
        format!(
            "connecting to pa10d at {} (is it running?)",
            c.socket.display()
        )
    })?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    s.write_all(format!("{req}\n").as_bytes())?;
    let mut line = String::new();
    BufReader::new(s)
        .read_line(&mut line)
        .context("reading the daemon's answer")?;
    serde_json::from_str(&line).context("the daemon's answer is not JSON")
}

/// A way to send the daemon one JSON request and get its answer, and the clock the daemon
/// runs on (real time, or the simulated time of `pa10 demo`).
pub trait Api {
    /// Sends `req`, returns the daemon's answer (any `ok`).
    fn call(&mut self, req: Value) -> Result<Value>;
    /// Lets `d` pass on the daemon's clock.
    fn pause(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
    /// The daemon's clock, s (any origin).
    fn clock_s(&self) -> f64 {
        static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
        START.get_or_init(Instant::now).elapsed().as_secs_f64()
    }
}

/// The daemon behind its Unix socket.
pub struct Socket(pub Conn);

impl Api for Socket {
    fn call(&mut self, req: Value) -> Result<Value> {
        send(&self.0, &req)
    }
}

/// A daemon core and the simulated arm in simulated time, in this process (the demo): the
/// same request handler as the socket's; pauses run the simulation.
pub struct Simulated(pub pa10::sim::rig::Lockstep);

impl Api for Simulated {
    fn call(&mut self, req: Value) -> Result<Value> {
        Ok(self.0.call(&req))
    }
    fn pause(&mut self, d: Duration) {
        self.0.run_for(d.as_secs_f64());
    }
    fn clock_s(&self) -> f64 {
        self.0.now()
    }
}

/// Sends `req`; a refusal is an error with the daemon's reason.
pub fn checked(api: &mut dyn Api, req: Value) -> Result<Value> {
    let v = api.call(req)?;
    if v["ok"] != true {
        bail!(
            "pa10d refused: {}",
            v["error"].as_str().unwrap_or("unknown error")
        );
    }
    Ok(v)
}

fn print_status(c: &Conn, v: &Value) {
    if c.json {
        println!("{v}");
        return;
    }
    let s = &v["status"];
    println!(
        "state {} (servo {}){}",
        s["state"],
        s["servo"],
        s["fault"]
            .as_str()
            .map(|f| format!(": {f}"))
            .unwrap_or_default()
    );
    println!(
        "tool  position {} m, quaternion {}",
        s["tool_position"], s["tool_quaternion"]
    );
    println!("joints (setpoint, rad) {}", s["setpoint"]);
    println!("payload {} N; cycle {}", s["payload_n"], s["cycle"]);
}

/// `pa10 status`.
pub fn status(c: &Conn) -> Result<()> {
    let v = checked(&mut Socket(c.clone()), json!({"cmd": "status"}))?;
    print_status(c, &v);
    Ok(())
}

/// Polls `status` until the arm holds; returns that answer. A fault, or no rest within
/// `timeout`, is an error.
pub fn wait_settled(api: &mut dyn Api, timeout: Duration) -> Result<Value> {
    let end = api.clock_s() + timeout.as_secs_f64();
    loop {
        let v = checked(api, json!({"cmd": "status"}))?;
        match v["status"]["state"].as_str() {
            Some("holding") => return Ok(v),
            Some("fault") => bail!("the move ended in a fault: {}", v["status"]["fault"]),
            _ if api.clock_s() > end => {
                bail!("the move did not settle within {} s", timeout.as_secs())
            }
            _ => api.pause(Duration::from_millis(10)),
        }
    }
}

/// `pa10 move …`.
pub fn move_cmd(c: &Conn, m: &MoveCmd) -> Result<()> {
    let (req, wait) = match m {
        MoveCmd::Joints { q, deg, wait } => {
            let q: Vec<f64> = q
                .iter()
                .map(|v| if *deg { v.to_radians() } else { *v })
                .collect();
            (json!({"cmd": "move_joints", "q": q}), *wait)
        }
        MoveCmd::Pose { pose, wait } => (
            json!({"cmd": "move_pose", "position": &pose[..3], "quaternion": &pose[3..]}),
            *wait,
        ),
    };
    let api = &mut Socket(c.clone());
    let v = checked(api, req)?;
    let d = v["duration_s"].as_f64().unwrap_or(0.0);
    if !wait {
        if c.json {
            println!("{v}");
        } else {
            println!("moving, {d:.2} s");
        }
        return Ok(());
    }
    let v = wait_settled(api, Duration::from_secs_f64(d + 10.0))?;
    print_status(c, &v);
    Ok(())
}

/// `pa10 stop|estop|reset|payload|load-model`: one request, `ok` or the refusal.
pub fn simple(c: &Conn, req: Value) -> Result<()> {
    let v = checked(&mut Socket(c.clone()), req)?;
    if c.json {
        println!("{v}");
    } else {
        println!("ok");
    }
    Ok(())
}

/// `pa10 watch`: the status stream.
pub fn watch(c: &Conn, rate_hz: f64) -> Result<()> {
    let mut s = UnixStream::connect(&c.socket)
        .with_context(|| format!("connecting to {}", c.socket.display()))?;
    s.write_all(format!("{}\n", json!({"cmd": "subscribe", "rate_hz": rate_hz})).as_bytes())?;
    for line in BufReader::new(s).lines() {
        let v: Value = serde_json::from_str(&line?)?;
        if v["ok"] != true {
            bail!("pa10d refused: {}", v["error"]);
        }
        print_status(c, &v);
    }
    Ok(())
}
