//! The daemon's motion interfaces from the command line: `pa10 trajectory FILE` (timed
//! waypoints from a CSV or JSON file), `pa10 servo` (setpoints streamed from stdin),
//! `pa10 jog J SPEED`, `pa10 speed F` (docs/motion.md).

use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use pa10::daemon::control::TrajectoryState;
use pa10::daemon::plan::TrajectoryPoint;
use pa10::daemon::wire::{Answer, ApiRequest};

use crate::client_cmd::{Conn, checked, status_of};

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

/// A JSON trajectory file: the points, or an object holding them.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum PointsFile {
    Points(Vec<TrajectoryPoint>),
    Object { points: Vec<TrajectoryPoint> },
}

/// Waypoints from `path` (CSV or JSON, see [`TrajectoryArgs`]).
pub fn read_points(path: &Path) -> Result<Vec<TrajectoryPoint>> {
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
        let file: PointsFile = serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not a JSON list of points (positions, time_from_start; velocities, accelerations optional)",
                path.display()
            )
        })?;
        return Ok(match file {
            PointsFile::Points(p) | PointsFile::Object { points: p } => p,
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
        let six = |k: usize| std::array::from_fn(|j| x[k + j]);
        points.push(TrajectoryPoint {
            positions: six(1),
            velocities: with_v.then(|| six(7)),
            accelerations: None,
            time_from_start: x[0],
        });
    }
    Ok(points)
}

/// `pa10 trajectory`.
pub fn trajectory(a: &TrajectoryArgs) -> Result<()> {
    let points = read_points(&a.file)?;
    let api = &mut crate::client_cmd::Socket(a.conn.clone());
    let answer = checked(
        api,
        ApiRequest::FollowTrajectory {
            points,
            path_tolerance: Some([a.path_tolerance; 6]),
            goal_tolerance: Some([a.goal_tolerance; 6]),
            goal_time_tolerance: Some(a.goal_time),
        },
    )?;
    let Answer::Following { id } = answer else {
        bail!("pa10d answered follow_trajectory with {answer:?}");
    };
    if !a.wait {
        println!("following trajectory {id}");
        return Ok(());
    }
    loop {
        let st = status_of(api)?;
        let t = st.trajectory;
        if t.id != id {
            bail!("trajectory {id} was replaced by {}", t.id);
        }
        match t.state {
            TrajectoryState::Executing => std::thread::sleep(Duration::from_millis(20)),
            TrajectoryState::Succeeded => {
                println!("trajectory {id} succeeded; final error {}", mrad(&t.error));
                return Ok(());
            }
            state => bail!(
                "trajectory {id} {}: {} (error {}; fault {})",
                serde_json::to_string(&state)?,
                serde_json::to_string(&t.result)?,
                mrad(&t.error),
                st.fault.as_deref().unwrap_or("none")
            ),
        }
    }
}

/// `pa10 servo`: one setpoint per stdin line, six link angles (rad) separated by spaces or
/// commas, sent as they come on one connection; the daemon stops the arm when they stop
/// coming (`servo.deadline_ms`).
pub fn servo(c: &Conn) -> Result<()> {
    let mut s = c.client().connect()?;
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
        let Ok(q) = <[f64; 6]>::try_from(q.as_slice()) else {
            bail!(
                "stdin line {}: {} values, 6 link angles (rad) needed",
                k + 1,
                q.len()
            );
        };
        s.call(&ApiRequest::Servo {
            positions: Some(q),
            position: None,
            quaternion: None,
        })?;
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
    let mut s = a.conn.client().connect()?;
    let end = Instant::now() + Duration::from_secs_f64(a.seconds);
    while Instant::now() < end {
        s.call(&ApiRequest::Jog {
            joint_velocities: Some(v),
            tool_twist: None,
            frame: None,
        })?;
        std::thread::sleep(Duration::from_millis(20));
    }
    s.call(&ApiRequest::Stop {})?;
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

/// Joint errors (rad) as `J1..J6 [mrad] +0.084 +0.053 …`.
fn mrad(e: &[f64; 6]) -> String {
    let v: Vec<String> = e.iter().map(|x| format!("{:+.3}", x * 1e3)).collect();
    format!("J1..J6 [mrad] {}", v.join(" "))
}
