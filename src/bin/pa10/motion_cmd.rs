//! The daemon's motion interfaces from the command line: `pa10 trajectory FILE` (timed
//! waypoints from a CSV or JSON file), `pa10 servo` (setpoints streamed from stdin),
//! `pa10 jog J SPEED`, `pa10 speed F` (docs/motion.md).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use serde_json::{Value, json};

use crate::client_cmd::{Conn, checked};

/// The largest trajectory file read, bytes.
const MAX_FILE_BYTES: u64 = 1 << 20;

/// `pa10 trajectory`.
#[derive(Debug, Args)]
pub struct TrajectoryArgs {
    #[command(flatten)]
    conn: Conn,
    /// Waypoints: a CSV with columns `time_from_start,q1,…,q6` (s, rad) and optionally
    /// `v1,…,v6` (rad/s), or a JSON array of `{"positions","velocities"?,"accelerations"?,
    /// "time_from_start"}` (or an object with `points`).
    file: PathBuf,
    /// Path tolerance on every joint, rad (0: unchecked).
    #[arg(long, default_value_t = 0.0)]
    path_tolerance: f64,
    /// Goal tolerance on every joint, rad.
    #[arg(long, default_value_t = 0.005)]
    goal_tolerance: f64,
    /// Time after the end the goal may still be reached, s.
    #[arg(long, default_value_t = 1.0)]
    goal_time: f64,
    /// Block until the trajectory ends; exit 1 unless it succeeded.
    #[arg(long)]
    wait: bool,
}

/// Waypoints from `path` (CSV or JSON, see [`TrajectoryArgs`]).
pub fn read_points(path: &Path) -> Result<Value> {
    let len = std::fs::metadata(path)
        .with_context(|| format!("{}", path.display()))?
        .len();
    if len > MAX_FILE_BYTES {
        bail!(
            "{}: {len} bytes, more than {MAX_FILE_BYTES}",
            path.display()
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    if text.trim_start().starts_with(['[', '{']) {
        let v: Value =
            serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
        return Ok(if v.is_object() {
            v["points"].clone()
        } else {
            v
        });
    }
    let mut points = Vec::new();
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().context("an empty file")?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let want: Vec<String> = std::iter::once("time_from_start".to_string())
        .chain((1..=6).map(|j| format!("q{j}")))
        .collect();
    if cols.len() < 7 || cols[..7] != want.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        bail!(
            "{}: the header must start with {} (then optionally v1,…,v6)",
            path.display(),
            want.join(",")
        );
    }
    let with_v = cols.len() >= 13;
    for (n, line) in lines {
        let x: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}:{}: not numbers", path.display(), n + 1))?;
        if x.len() != cols.len() {
            bail!(
                "{}:{}: {} values for {} columns",
                path.display(),
                n + 1,
                x.len(),
                cols.len()
            );
        }
        let mut p = json!({"time_from_start": x[0], "positions": &x[1..7]});
        if with_v {
            p["velocities"] = json!(&x[7..13]);
        }
        points.push(p);
    }
    Ok(Value::Array(points))
}

/// `pa10 trajectory`.
pub fn trajectory(a: &TrajectoryArgs) -> Result<()> {
    let points = read_points(&a.file)?;
    let api = &mut crate::client_cmd::Socket(a.conn.clone());
    let v = checked(
        api,
        json!({
            "cmd": "follow_trajectory",
            "points": points,
            "path_tolerance": vec![a.path_tolerance; 6],
            "goal_tolerance": vec![a.goal_tolerance; 6],
            "goal_time_tolerance": a.goal_time,
        }),
    )?;
    let id = v["id"].clone();
    if !a.wait {
        println!("following trajectory {id}");
        return Ok(());
    }
    loop {
        let st = checked(api, json!({"cmd": "status"}))?;
        let t = &st["status"]["trajectory"];
        if t["id"] != id {
            bail!("trajectory {id} was replaced by {}", t["id"]);
        }
        match t["state"].as_str() {
            Some("executing") => std::thread::sleep(Duration::from_millis(20)),
            Some("succeeded") => {
                println!("trajectory {id} succeeded; error [rad] {}", t["error"]);
                return Ok(());
            }
            _ => bail!(
                "trajectory {id} {}: {} (error [rad] {}; fault {})",
                t["state"],
                t["result"],
                t["error"],
                st["status"]["fault"]
            ),
        }
    }
}

/// One connection kept open (streams, the lease).
struct Session {
    w: UnixStream,
    r: BufReader<UnixStream>,
}

impl Session {
    fn open(c: &Conn) -> Result<Self> {
        let w = UnixStream::connect(c.socket())
            .with_context(|| format!("connecting to pa10d at {}", c.socket().display()))?;
        w.set_read_timeout(Some(Duration::from_secs(10)))?;
        let r = BufReader::new(w.try_clone()?);
        Ok(Self { w, r })
    }
    fn call(&mut self, req: &Value) -> Result<Value> {
        self.w.write_all(format!("{req}\n").as_bytes())?;
        let mut line = String::new();
        self.r.read_line(&mut line)?;
        let v: Value = serde_json::from_str(&line).context("the daemon's answer is not JSON")?;
        if v["ok"] != true {
            bail!(
                "pa10d refused: {}",
                v["error"].as_str().unwrap_or("unknown error")
            );
        }
        Ok(v)
    }
}

/// `pa10 servo`: one setpoint per stdin line, six link angles (rad) separated by spaces or
/// commas, sent as they come on one connection; the daemon stops the arm when they stop
/// coming (`servo.deadline_ms`).
pub fn servo(c: &Conn) -> Result<()> {
    let mut s = Session::open(c)?;
    let mut n = 0usize;
    for (k, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line?;
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        let q: Vec<f64> = line
            .split([' ', ',', '\t'])
            .filter(|s| !s.is_empty())
            .map(str::parse)
            .collect::<Result<_, _>>()
            .with_context(|| format!("stdin line {}: not numbers", k + 1))?;
        if q.len() != 6 {
            bail!(
                "stdin line {}: {} values, 6 link angles (rad) needed",
                k + 1,
                q.len()
            );
        }
        s.call(&json!({"cmd": "servo", "positions": q}))?;
        n += 1;
    }
    println!("{n} setpoints sent");
    Ok(())
}

/// `pa10 jog`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct JogArgs {
    #[command(flatten)]
    conn: Conn,
    /// Joint 1…6.
    joint: usize,
    /// Link speed, rad/s.
    speed: f64,
    /// For how long, s (the command is repeated within the daemon's deadline, then it stops).
    #[arg(long = "for", default_value_t = 1.0)]
    seconds: f64,
}

/// `pa10 jog`.
pub fn jog(a: &JogArgs) -> Result<()> {
    if !(1..=6).contains(&a.joint) {
        bail!("joint must be 1…6, got {}", a.joint);
    }
    if !(a.seconds.is_finite() && (0.0..=60.0).contains(&a.seconds)) {
        bail!("--for must be within 0…60 s, got {}", a.seconds);
    }
    let mut v = [0.0; 6];
    v[a.joint - 1] = a.speed;
    let mut s = Session::open(&a.conn)?;
    let end = Instant::now() + Duration::from_secs_f64(a.seconds);
    while Instant::now() < end {
        s.call(&json!({"cmd": "jog", "joint_velocities": v}))?;
        std::thread::sleep(Duration::from_millis(20));
    }
    s.call(&json!({"cmd": "stop"}))?;
    crate::client_cmd::wait_settled(
        &mut crate::client_cmd::Socket(a.conn.clone()),
        Duration::from_secs(10),
    )?;
    println!(
        "jogged joint {} at {} rad/s for {} s; at rest",
        a.joint, a.speed, a.seconds
    );
    Ok(())
}
