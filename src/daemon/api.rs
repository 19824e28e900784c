//! The client API: newline-delimited JSON over a Unix socket (`docs/api.md`).
//!
//! [`handle`] is the request handler (JSON in, JSON out, against the daemon's [`Core`]);
//! [`serve`] is the thin tokio shell that accepts connections and moves lines. Every request
//! is validated and a refused one leaves the robot as it was.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::Deserialize;
use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::UnixListener;

use super::control::CommandError;
use super::core::{Command, Core, PlanBasis};
use super::motion::{Move, MoveError};
use super::runtime::lock;
use crate::model::{Model, frame_from_pose};

/// A client request.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// The daemon's state.
    Status,
    /// A joint move to `q` (link angles, rad).
    MoveJoints {
        /// Target, rad.
        q: [f64; 6],
    },
    /// A straight-line tool move to a pose (base frame, m, quaternion w, x, y, z).
    MovePose {
        /// Position, m.
        position: [f64; 3],
        /// Unit quaternion w, x, y, z.
        quaternion: [f64; 4],
    },
    /// Controlled stop.
    Stop,
    /// Immediate servo stop and brakes.
    Estop,
    /// Clears a fault.
    Reset,
    /// Sets the payload hung at the tool, N.
    SetPayload {
        /// Newtons.
        newtons: f64,
    },
    /// Hot-reloads a model file between moves.
    LoadModel {
        /// Path of the model YAML.
        path: String,
    },
    /// Streams `status` at `rate_hz` until the client disconnects.
    Subscribe {
        /// Hz (0.1…100).
        rate_hz: f64,
    },
}

fn err(msg: impl std::fmt::Display) -> Value {
    json!({ "ok": false, "error": msg.to_string() })
}

fn answer(r: Result<Value, CommandError>) -> Value {
    r.unwrap_or_else(err)
}

/// Plans a move outside the lock (≈ 1 ms for a Cartesian one) from a basis taken under it,
/// then hands it over; refused if the setpoint or the model changed in between.
fn plan_and_start(
    core: &Mutex<Core>,
    plan: impl FnOnce(&PlanBasis) -> Result<Move, MoveError>,
) -> Result<Value, CommandError> {
    let basis = lock(core).plan_basis()?;
    let mv = plan(&basis)?;
    let d = mv.duration();
    lock(core).submit(Command::Start {
        mv: Box::new(mv),
        basis,
    })?;
    Ok(json!({ "ok": true, "duration_s": d }))
}

fn submit(core: &Mutex<Core>, cmd: Command) -> Value {
    answer(lock(core).submit(cmd).map(|()| json!({ "ok": true })))
}

/// Handles one request line; `Subscribe` is answered by [`serve`] (here: one status).
///
/// The lock on the core is held only to read a snapshot or to apply a command: planning a
/// move and parsing a model file happen outside it, so the 2 ms cycle never waits for them.
pub fn handle(core: &Mutex<Core>, line: &str) -> Value {
    let req: Request = match serde_json::from_str(line) {
        Ok(r) => r,
        Err(e) => return err(format!("bad request: {e}")),
    };
    match req {
        Request::Status | Request::Subscribe { .. } => {
            let c = lock(core);
            if !c.is_ready() && c.startup_failure().is_none() {
                return err(CommandError::NotReady("starting".into()));
            }
            json!({ "ok": true, "status": c.status() })
        }
        Request::MoveJoints { q } => answer(plan_and_start(core, |b| {
            Move::joints(&b.model, b.from, q, &b.speed, &b.acceleration)
        })),
        Request::MovePose {
            position,
            quaternion,
        } => {
            let n = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !position.iter().chain(&quaternion).all(|v| v.is_finite()) || (n - 1.0).abs() > 1e-3
            {
                return err(format!(
                    "position must be finite (m) and quaternion a unit [w, x, y, z] (norm {n})"
                ));
            }
            let target = frame_from_pose(position, quaternion);
            answer(plan_and_start(core, |b| {
                Move::cartesian(&b.model, b.from, target, &b.speed, &b.acceleration)
            }))
        }
        Request::Stop => submit(core, Command::Stop),
        Request::Estop => submit(core, Command::Estop),
        Request::Reset => submit(core, Command::Reset),
        Request::SetPayload { newtons } => submit(core, Command::SetPayload(newtons)),
        Request::LoadModel { path } => match Model::load(&path) {
            Ok(m) => submit(core, Command::LoadModel(Arc::new(m))),
            Err(e) => err(e),
        },
    }
}

/// Serves clients on `path` (created with `mode`) until `stop` turns true.
pub async fn serve(
    path: &Path,
    mode: u32,
    core: Arc<Mutex<Core>>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> std::io::Result<()> {
    let _ = std::fs::remove_file(path);
    let listener = UnixListener::bind(path)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
    }
    loop {
        let (conn, _) = tokio::select! {
            c = listener.accept() => c?,
            _ = stop.changed() => break,
        };
        let core = core.clone();
        tokio::spawn(async move {
            let (r, mut w) = conn.into_split();
            let mut lines = BufReader::new(r).lines();
            while let Ok(Some(line)) = lines.next_line().await {
                if let Ok(Request::Subscribe { rate_hz }) = serde_json::from_str::<Request>(&line) {
                    if !(0.1..=100.0).contains(&rate_hz) {
                        let _ = w
                            .write_all(
                                format!("{}\n", err("rate_hz must be within 0.1…100 Hz"))
                                    .as_bytes(),
                            )
                            .await;
                        continue;
                    }
                    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz));
                    loop {
                        tick.tick().await;
                        let st = json!({ "ok": true, "status": lock(&core).status() });
                        if w.write_all(format!("{st}\n").as_bytes()).await.is_err() {
                            return;
                        }
                    }
                }
                let cmd = serde_json::from_str::<Value>(&line)
                    .ok()
                    .and_then(|v| v["cmd"].as_str().map(str::to_string))
                    .unwrap_or_default();
                let span = tracing::info_span!("request", cmd = %cmd);
                let resp = span.in_scope(|| {
                    let r = handle(&core, &line);
                    if r["ok"] == true {
                        // status is polled (often at 100 Hz): keep it out of the journal
                        if cmd == "status" {
                            tracing::debug!("done");
                        } else {
                            tracing::info!("done");
                        }
                    } else {
                        tracing::warn!(error = %r["error"], "refused");
                    }
                    r
                });
                if w.write_all(format!("{resp}\n").as_bytes()).await.is_err() {
                    return;
                }
            }
        });
    }
    let _ = std::fs::remove_file(path);
    Ok(())
}
