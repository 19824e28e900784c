//! The daemon client: `pa10 status`, `pa10 move joints|pose`, `pa10 stop|estop|reset`,
//! `pa10 payload`, `pa10 load-model`, `pa10 watch` — one request per call over the daemon's
//! Unix socket (docs/api.md), in the protocol's types (`pa10::daemon::wire`).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use clap::{Args, Subcommand};
use pa10::daemon::api::Client;
use pa10::daemon::wire::{Answer, ApiRequest, Reply, State, Status};
use pa10::model::Model;

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
    pub(crate) json: bool,
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
    /// A client of that socket.
    pub fn client(&self) -> Client {
        Client::new(&self.socket)
    }
}

/// A way to send the daemon one request and get its reply, and the clock the daemon runs on
/// (real time, or the simulated time of `pa10 demo`).
pub trait Api {
    /// Sends `req`, returns the daemon's reply (a refusal included).
    fn send(&mut self, req: ApiRequest) -> Result<Reply>;
    /// Lets `d` pass on the daemon's clock.
    fn pause(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
    /// Hangs a weight of `newtons` at the tool point (0: takes it off): the simulation's
    /// weight rack, or on a real arm the operator, asked on the terminal.
    fn hang_weight(&mut self, newtons: f64) -> Result<()> {
        use std::io::BufRead;
        if newtons > 0.0 {
            eprintln!(
                "hang a known weight of {newtons} N ({:.3} kg) at the tool point, then press Enter",
                newtons / pa10::model::STANDARD_GRAVITY
            );
        } else {
            eprintln!("take the weight off the tool, then press Enter");
        }
        let mut line = String::new();
        let n = std::io::stdin().lock().read_line(&mut line)?;
        anyhow::ensure!(
            n > 0,
            "no operator to hang the weight: standard input is closed"
        );
        Ok(())
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
    fn send(&mut self, req: ApiRequest) -> Result<Reply> {
        Ok(self.0.client().send(&req)?)
    }
}

/// A daemon core and the simulated arm in simulated time, in this process (the demo): the
/// same request handler as the socket's; pauses run the simulation.
pub struct Simulated(pub pa10::sim::rig::Lockstep);

impl Api for Simulated {
    fn send(&mut self, req: ApiRequest) -> Result<Reply> {
        Ok(self.0.call(req))
    }
    fn pause(&mut self, d: Duration) {
        self.0.run_for(d.as_secs_f64());
    }
    fn clock_s(&self) -> f64 {
        self.0.now()
    }
    fn hang_weight(&mut self, newtons: f64) -> Result<()> {
        self.0.servo.set_load(newtons);
        Ok(())
    }
}

/// A `pa10` client connection as a sweep's session.
pub struct AsSession<'a>(pub &'a mut dyn Api);

impl pa10::daemon::api::sweep::Session for AsSession<'_> {
    fn send(&mut self, req: ApiRequest) -> std::result::Result<Reply, String> {
        self.0.send(req).map_err(|e| format!("{e:#}"))
    }
    fn pause(&mut self, seconds: f64) {
        self.0.pause(Duration::from_secs_f64(seconds));
    }
    fn clock_s(&self) -> f64 {
        self.0.clock_s()
    }
}

/// Sends `req`; a refusal is an error with the daemon's reason.
pub fn checked(api: &mut dyn Api, req: ApiRequest) -> Result<Answer> {
    match api.send(req)? {
        Reply::Ok(a) => Ok(a),
        Reply::Refused(e) => bail!("pa10d refused: {e}"),
    }
}

/// The daemon's status.
pub fn status_of(api: &mut dyn Api) -> Result<Status> {
    match checked(api, ApiRequest::Status {})? {
        Answer::Status(s) => Ok(*s),
        other => bail!("pa10d answered status with {other:?}"),
    }
}

/// The planned move's duration, s, from a move's answer.
pub fn duration_of(a: &Answer) -> Result<f64> {
    match a {
        Answer::Moving { duration_s } => Ok(*duration_s),
        other => bail!("pa10d answered a move with {other:?}"),
    }
}

/// Prints a reply as the socket carries it (`--json`).
pub fn print_json(reply: &Reply) -> Result<()> {
    println!("{}", serde_json::to_string(reply)?);
    Ok(())
}

fn print_status(c: &Conn, s: &Status) -> Result<()> {
    if c.json {
        return print_json(&Reply::Ok(Answer::Status(Box::new(s.clone()))));
    }
    print!("{}", crate::view::render(s, Model::nominal().limits()));
    Ok(())
}

/// `pa10 status`.
pub fn status(c: &Conn) -> Result<()> {
    let s = status_of(&mut Socket(c.clone()))?;
    print_status(c, &s)
}

/// How long [`wait_settled`] waits, once the daemon holds, for the motors to be in position
/// (`status.in_position`), s: a sticking drive winds up for seconds before it breaks away.
pub const IN_POSITION_WAIT_S: f64 = 5.0;

/// Polls `status` until the arm holds and then until it is in position (at most
/// [`IN_POSITION_WAIT_S`] more; said on stderr when it is not); returns that status. A fault,
/// or no rest within `timeout`, is an error.
pub fn wait_settled(api: &mut dyn Api, timeout: Duration) -> Result<Status> {
    let end = api.clock_s() + timeout.as_secs_f64();
    loop {
        let s = status_of(api)?;
        match s.state {
            State::Holding => return wait_in_position(api, s),
            State::Fault => bail!(
                "the move ended in a fault: {}",
                s.fault.as_deref().unwrap_or("(no fault text)")
            ),
            _ if api.clock_s() > end => {
                bail!("the move did not settle within {} s", timeout.as_secs())
            }
            _ => api.pause(Duration::from_millis(10)),
        }
    }
}

/// From a holding status `s`: polls until in position, a state other than holding, or
/// [`IN_POSITION_WAIT_S`]; the last status.
fn wait_in_position(api: &mut dyn Api, mut s: Status) -> Result<Status> {
    let end = api.clock_s() + IN_POSITION_WAIT_S;
    while !s.in_position && s.state == State::Holding && api.clock_s() < end {
        api.pause(Duration::from_millis(10));
        s = status_of(api)?;
    }
    if !s.in_position && s.state == State::Holding {
        eprintln!(
            "warning: holding but not in position after {IN_POSITION_WAIT_S} s (a motor still moving or outside its holding band: docs/daemon.md)"
        );
    }
    Ok(s)
}

/// `pa10 move …`.
pub fn move_cmd(c: &Conn, m: &MoveCmd) -> Result<()> {
    let six = |v: &[f64]| -> Result<[f64; 6]> {
        v.try_into()
            .map_err(|_| anyhow::anyhow!("6 joint angles, got {}", v.len()))
    };
    let (req, wait) = match m {
        MoveCmd::Joints { q, deg, wait } => {
            let q: Vec<f64> = q
                .iter()
                .map(|v| if *deg { v.to_radians() } else { *v })
                .collect();
            (ApiRequest::MoveJoints { q: six(&q)? }, *wait)
        }
        MoveCmd::Pose { pose, wait } => (
            ApiRequest::MovePose {
                position: [pose[0], pose[1], pose[2]],
                quaternion: [pose[3], pose[4], pose[5], pose[6]],
            },
            *wait,
        ),
    };
    let api = &mut Socket(c.clone());
    let a = checked(api, req)?;
    let d = duration_of(&a)?;
    if !wait {
        if c.json {
            print_json(&Reply::Ok(a))?;
        } else {
            println!("moving, {d:.2} s");
        }
        return Ok(());
    }
    let s = wait_settled(api, Duration::from_secs_f64(d + 10.0))?;
    print_status(c, &s)
}

/// `pa10 stop|estop|reset|payload|load-model`: one request, `ok` or the refusal.
pub fn simple(c: &Conn, req: ApiRequest) -> Result<()> {
    let a = checked(&mut Socket(c.clone()), req)?;
    if c.json {
        print_json(&Reply::Ok(a))
    } else {
        println!("ok");
        Ok(())
    }
}

/// `pa10 watch`: the status stream.
pub fn watch(c: &Conn, rate_hz: f64) -> Result<()> {
    use std::io::{IsTerminal, Write};
    let terminal = !c.json && std::io::stdout().is_terminal();
    let limits = *Model::nominal().limits();
    let mut last = String::new();
    for reply in c.client().subscribe(rate_hz)? {
        match reply? {
            Reply::Ok(Answer::Status(s)) if c.json => print_status(c, &s)?,
            Reply::Ok(Answer::Status(s)) if terminal => {
                // redraw in place: home, the view, clear what the last one left below
                let mut out = std::io::stdout().lock();
                write!(out, "\x1b[H{}\x1b[J", crate::view::render(&s, &limits))?;
                out.flush()?;
            }
            Reply::Ok(Answer::Status(s)) => {
                // piped: one line per change (the time alone is no change)
                let text = crate::view::line(&s);
                let body = text.split_once(" · ").map_or(text.as_str(), |(_, b)| b);
                if body != last {
                    last = body.to_string();
                    println!("{text}");
                }
            }
            Reply::Ok(other) => bail!("pa10d sent {other:?} in a status stream"),
            Reply::Refused(e) => bail!("pa10d refused: {e}"),
        }
    }
    Ok(())
}
