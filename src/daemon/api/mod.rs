//! The client API: newline-delimited JSON over a Unix socket (`docs/api.md`).
//!
//! [`handle`] is the request handler (an [`ApiRequest`] in, a [`Reply`] out, against the
//! daemon's [`Core`](super::core::Core)); [`parse`] turns a line into a request or the refusal
//! that answers it; [`serve`] is the thin tokio shell that accepts connections and moves
//! lines; [`Client`] is the blocking client the `pa10` CLI and the ROS 2 bridge call the daemon
//! with. The types are [`super::wire`]'s. Every request is validated and a refused one leaves
//! the robot as it was.

use std::path::Path;
use std::sync::Arc;

use super::control::CommandError;
use super::control::{Stream, Tolerances};
use super::core::{ClientId, Command, LOCAL, PlanBasis};
use super::plan::{Move, MoveError, TrajectoryPoint, cartesian_waypoints};
use super::runtime::{SharedCore, lock};
use super::wire::{Answer, ApiRequest, RefusalStatus, Reply};
use crate::model::{Model, frame_from_pose};

pub use client::{CALL_TIMEOUT_S, Client, ClientError, Connection, MAX_REPLY_BYTES, Subscription};

pub use serve::{
    ApiHealth, IDLE_TIMEOUT_S, LOG_PER_WINDOW, LOG_WINDOW_S, LogLimiter, LogVerdict,
    MAX_LINE_BYTES, REQUEST_TIMEOUT_S, SocketLock, serve,
};

mod client;
mod serve;
pub mod sweep;

use crate::text::truncate;

/// The longest error text an answer carries, bytes: a hostile request is never echoed whole.
const MAX_ERROR_BYTES: usize = 300;

/// A refusal with `msg`, cut to [`MAX_ERROR_BYTES`].
fn err(msg: impl std::fmt::Display) -> Reply {
    Reply::Refused(truncate(&msg.to_string(), MAX_ERROR_BYTES))
}

fn answer(r: Result<Answer, CommandError>) -> Reply {
    r.map_or_else(err, Reply::Ok)
}

/// One request line as a request, or the refusal that answers it (`bad request: …`, naming
/// the key and column serde found wrong).
pub fn parse(line: &str) -> Result<ApiRequest, Reply> {
    serde_json::from_str(line).map_err(|e| err(format!("bad request: {e}")))
}

/// How long `record_stop` waits for the writer to close the file before answering, s (within
/// [`REQUEST_TIMEOUT_S`]).
pub const RECORD_CLOSE_S: f64 = 5.0;

/// The largest model file `load_model` reads, bytes.
pub const MAX_MODEL_BYTES: u64 = 1 << 20;

/// Reads a model file for `load_model`: `path` (relative ones in `dir`) must resolve, symlinks
/// followed, to a regular file inside `dir` of at most [`MAX_MODEL_BYTES`]; errors name the
/// path, the key and the line, never the content. Called outside the control lock.
pub fn read_model(dir: &Path, path: &Path) -> Result<Model, String> {
    use std::io::Read;
    let full = dir.join(path);
    let shown = full.display();
    // judged on the name before the file system is asked, so that a refusal never tells
    // whether something exists outside the directory
    if path
        .components()
        .any(|c| matches!(c, std::path::Component::ParentDir))
    {
        return Err(format!(
            "{} is refused: `..` could lead outside the model directory {} (api.model_dir)",
            path.display(),
            dir.display()
        ));
    }
    if !full.starts_with(dir) {
        return Err(format!(
            "{shown} is outside the model directory {} (api.model_dir)",
            dir.display()
        ));
    }
    let real = full.canonicalize().map_err(|e| format!("{shown}: {e}"))?;
    let dir_c = dir
        .canonicalize()
        .map_err(|e| format!("the model directory {}: {e}", dir.display()))?;
    if !real.starts_with(&dir_c) {
        return Err(format!(
            "{shown} is outside the model directory {} (api.model_dir)",
            dir_c.display()
        ));
    }
    let meta = std::fs::metadata(&real).map_err(|e| format!("{shown}: {e}"))?;
    if !meta.is_file() {
        return Err(format!("{shown} is not a regular file"));
    }
    if meta.len() > MAX_MODEL_BYTES {
        return Err(format!(
            "{shown}: {} bytes, more than the {MAX_MODEL_BYTES} a model file may have",
            meta.len()
        ));
    }
    let mut text = String::new();
    std::fs::File::open(&real)
        .and_then(|f| f.take(MAX_MODEL_BYTES).read_to_string(&mut text))
        .map_err(|e| format!("{shown}: {e}"))?;
    Model::from_yaml_str(&text, &shown.to_string()).map_err(|e| e.to_string())
}

/// Plans a move outside the lock (≈ 1 ms for a Cartesian one) from a basis taken under it,
/// then hands it over; refused if the setpoint or the model changed in between.
fn plan_and_start(
    core: &SharedCore,
    client: ClientId,
    plan: impl FnOnce(&PlanBasis) -> Result<Move, MoveError>,
) -> Result<Answer, CommandError> {
    let basis = lock(core).plan_basis_for(client)?;
    let mv = plan(&basis)?;
    let d = mv.duration();
    lock(core).submit_from(
        client,
        Command::Start {
            mv: Box::new(mv),
            basis,
        },
    )?;
    Ok(Answer::Moving { duration_s: d })
}

/// Handles one request; `Subscribe` is answered by [`serve`] (here: one status).
///
/// The lock on the core is held only to read a snapshot or to apply a command: planning a
/// move and parsing a model file happen outside it, so the 2 ms cycle never waits for them.
pub fn handle(core: &SharedCore, req: ApiRequest) -> Reply {
    handle_from(core, req, LOCAL)
}

/// The status reply: refused while the daemon starts (until its first cycle, unless the
/// start failed, which status then reports).
pub fn status_reply(core: &SharedCore) -> Reply {
    let c = lock(core);
    if !c.is_ready() && c.startup_failure().is_none() {
        return err(CommandError::NotReady("starting".into()));
    }
    Reply::Ok(Answer::Status(Box::new(c.status())))
}

/// As [`handle`], for the connection `client` (the motion lease is per connection). A
/// refusal is kept as `status.last_refusal`.
pub fn handle_from(core: &SharedCore, req: ApiRequest, client: ClientId) -> Reply {
    let cmd = req.name();
    let reply = reply_to(core, req, client);
    note_refusal(core, cmd, &reply);
    reply
}

/// Keeps `reply` as the core's last refusal when it is one (not a status poll refused while
/// the daemon starts: that is not news).
fn note_refusal(core: &SharedCore, cmd: &str, reply: &Reply) {
    if let Reply::Refused(error) = reply
        && cmd != "status"
        && cmd != "subscribe"
    {
        // built outside the lock
        let refusal = RefusalStatus {
            request: cmd.to_owned(),
            error: error.clone(),
            time_s: 0.0,
        };
        lock(core).note_refusal(refusal);
    }
}

/// The reply to one request.
fn reply_to(core: &SharedCore, req: ApiRequest, client: ClientId) -> Reply {
    let submit = |cmd| answer(lock(core).submit_from(client, cmd).map(|()| Answer::Done));
    use ApiRequest as Request;
    match req {
        Request::Status {} | Request::Subscribe { .. } => status_reply(core),
        Request::MoveJoints { q } => answer(plan_and_start(core, client, |b| {
            Move::joints(b.from, q, &b.limits)
        })),
        Request::MovePose {
            position,
            quaternion,
        } => {
            let target = match pose_target(position, quaternion) {
                Ok(t) => t,
                Err(e) => return e,
            };
            answer(plan_and_start(core, client, |b| {
                Move::cartesian(&b.model, b.from, target, &b.limits)
            }))
        }
        Request::Stop {} => submit(Command::Stop),
        Request::Estop {} => submit(Command::Estop),
        Request::Reset {} => submit(Command::Reset),
        Request::SetPayload {
            newtons,
            mass_kg,
            com,
        } => {
            let newtons = match (newtons, mass_kg) {
                (Some(n), None) => n,
                (None, Some(m)) => {
                    let g = lock(core)
                        .controller()
                        .map_or(crate::model::STANDARD_GRAVITY, |c| {
                            c.model().gravity().norm()
                        });
                    m * g
                }
                _ => return err("set_payload takes either \"newtons\" (N) or \"mass_kg\" (kg)"),
            };
            submit(Command::SetPayload {
                newtons,
                com: com.unwrap_or([0.0; 3]),
            })
        }
        Request::SetTool {
            translation,
            quaternion,
        } => match pose_target(translation, quaternion) {
            Ok(tool) => submit(Command::SetTool(Box::new(tool))),
            Err(e) => e,
        },
        Request::LoadModel { path } => {
            let dir = lock(core).model_dir().to_path_buf();
            match read_model(&dir, Path::new(&path)) {
                Ok(m) => submit(Command::LoadModel {
                    model: Arc::new(m),
                    file: dir.join(&path).display().to_string(),
                }),
                Err(e) => err(e),
            }
        }
        Request::FollowTrajectory {
            points,
            path_tolerance,
            goal_tolerance,
            goal_time_tolerance,
        } => {
            let tolerances = match tolerances(path_tolerance, goal_tolerance, goal_time_tolerance) {
                Ok(t) => t,
                Err(e) => return e,
            };
            follow(core, client, points, tolerances, None)
        }
        Request::FollowCartesian {
            points,
            path_tolerance,
            goal_tolerance,
            goal_time_tolerance,
        } => {
            let tolerances = match tolerances(path_tolerance, goal_tolerance, goal_time_tolerance) {
                Ok(t) => t,
                Err(e) => return e,
            };
            // the IK of every sample outside the lock, from the setpoint held now
            let basis = match lock(core).plan_basis_for(client) {
                Ok(b) => b,
                Err(e) => return err(e),
            };
            match cartesian_waypoints(&basis.model, &basis.limits, basis.from, &points) {
                Ok(joints) => follow(core, client, joints, tolerances, Some(basis)),
                Err(e) => err(format!("trajectory refused: {e}")),
            }
        }
        Request::Servo {
            positions,
            position,
            quaternion,
        } => match (positions, position, quaternion) {
            (Some(q), None, None) => submit(Command::Stream(Stream::Servo(q))),
            (None, Some(p), Some(o)) => {
                let target = match pose_target(p, o) {
                    Ok(t) => t,
                    Err(e) => return e,
                };
                // the IK outside the lock, from the setpoint it will continue
                let (model, from) = {
                    let c = lock(core);
                    match c.controller() {
                        Some(ctl) => (ctl.model_arc().clone(), ctl.setpoint().q),
                        None => return err(CommandError::NotReady("starting".into())),
                    }
                };
                match model.ik_nearest(&target, &from) {
                    Ok(q) => submit(Command::Stream(Stream::Servo(q))),
                    Err(e) => err(format!("servo pose: {e}")),
                }
            }
            _ => err(
                "servo takes either \"positions\" (6, rad) or \"position\" (3, m) with \"quaternion\" (4)",
            ),
        },
        Request::Jog {
            joint_velocities,
            tool_twist,
            frame,
        } => match (joint_velocities, tool_twist, frame) {
            (Some(v), None, None) => submit(Command::Stream(Stream::Jog(v))),
            (None, Some(twist), frame) => {
                let tool_frame = match frame.as_deref() {
                    None | Some("base") => false,
                    Some("tool") => true,
                    Some(_) => return err("jog: frame must be \"base\" or \"tool\""),
                };
                submit(Command::Stream(Stream::Twist { twist, tool_frame }))
            }
            _ => err(
                "jog takes \"joint_velocities\" (6, rad/s) or \"tool_twist\" (vx, vy, vz m/s, wx, wy, wz rad/s) with an optional \"frame\": \"base\" | \"tool\"",
            ),
        },
        Request::SetSpeedScaling { fraction } => submit(Command::SetSpeedScaling(fraction)),
        Request::RecordStart { file, duration_s } => {
            if let Some(d) = duration_s
                && !(d.is_finite() && d > 0.0 && d <= 86_400.0)
            {
                return err("duration_s must be within (0, 86400] s");
            }
            let (cfg, now, busy) = {
                let c = lock(core);
                (c.record_config().clone(), c.now_s(), c.is_recording())
            };
            if busy {
                return err("a recording is running; record_stop first");
            }
            let name = file.unwrap_or_else(|| {
                let t = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_secs());
                format!("pa10d-{t}.mcap")
            });
            // the file is created here, outside the control lock
            match crate::record::Recorder::start(&cfg, &name, duration_s.map(|d| now + d)) {
                Ok(tap) => {
                    let path = tap.stats.status(true).path;
                    match lock(core).submit_from(client, Command::Record(Box::new(tap))) {
                        Ok(()) => Reply::Ok(Answer::Recording { path }),
                        Err(e) => err(e),
                    }
                }
                Err(e) => err(e),
            }
        }
        Request::RecordStop {} => {
            let stopped = {
                let mut c = lock(core);
                let stats = c.recording_stats();
                c.submit_from(client, Command::RecordStop).map(|()| stats)
            };
            match stopped {
                // answered once the file is whole (its summary written), so that a reader
                // started next finds it closed; outside the lock
                Ok(stats) => {
                    if let Some(s) = stats
                        && !s.wait_finished(std::time::Duration::from_secs_f64(RECORD_CLOSE_S))
                    {
                        return err(format!(
                            "recording stopped, but its file is not closed after {RECORD_CLOSE_S} s (status.recording)"
                        ));
                    }
                    Reply::Ok(Answer::Done)
                }
                Err(e) => err(e),
            }
        }
        Request::Acquire {} => submit(Command::Acquire),
        Request::Release {} => submit(Command::Release),
    }
}

/// A trajectory request's tolerances with their defaults, or the refusal to answer with.
fn tolerances(
    path: Option<[f64; 6]>,
    goal: Option<[f64; 6]>,
    goal_time: Option<f64>,
) -> Result<Tolerances, Reply> {
    let d = Tolerances::default();
    let t = Tolerances {
        path: path.unwrap_or(d.path),
        goal: goal.unwrap_or(d.goal),
        goal_time_s: goal_time.unwrap_or(d.goal_time_s),
    };
    let ok = |v: &f64| v.is_finite() && *v >= 0.0;
    if t.path.iter().all(ok) && t.goal.iter().all(ok) && ok(&t.goal_time_s) {
        Ok(t)
    } else {
        Err(err(
            "tolerances must be finite and ≥ 0 (rad; goal_time_tolerance in s)",
        ))
    }
}

/// Hands a joint trajectory to the core: its id, or the refusal.
fn follow(
    core: &SharedCore,
    client: ClientId,
    points: Vec<TrajectoryPoint>,
    tolerances: Tolerances,
    basis: Option<PlanBasis>,
) -> Reply {
    let mut c = lock(core);
    let cmd = Command::FollowTrajectory {
        points,
        tolerances,
        basis,
    };
    match c.submit_from(client, cmd) {
        Ok(()) => Reply::Ok(Answer::Following {
            id: c.controller().map_or(0, |c| c.trajectory().id),
        }),
        Err(e) => err(e),
    }
}

/// A tool pose from a request: finite position (m) and a unit quaternion (w, x, y, z), or
/// the refusal to answer with.
fn pose_target(position: [f64; 3], quaternion: [f64; 4]) -> Result<crate::model::Frame, Reply> {
    let n = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !position.iter().chain(&quaternion).all(|v| v.is_finite()) || (n - 1.0).abs() > 1e-3 {
        return Err(err(format!(
            "position must be finite (m) and quaternion a unit [w, x, y, z] (norm {n})"
        )));
    }
    Ok(frame_from_pose(position, quaternion))
}
