//! The client API: newline-delimited JSON over a Unix socket (`docs/api.md`).
//!
//! [`handle`] is the pure request handler (JSON in, JSON out, against the shared state);
//! [`serve`] is the thin tokio shell that accepts connections and moves lines. Every request
//! is validated and a refused one leaves the robot as it was.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::Deserialize;
use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::UnixListener;

use super::motion::Move;
use super::runtime::{Shared, lock};
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

/// Starts a planned move, or says why not.
fn start(
    ctl: &mut super::control::Controller,
    planned: Result<Move, super::motion::MoveError>,
    now: f64,
) -> Value {
    match planned {
        Ok(mv) => {
            let d = mv.duration();
            match ctl.start_move(mv, now) {
                Ok(()) => json!({ "ok": true, "duration_s": d }),
                Err(e) => err(e),
            }
        }
        Err(e) => err(e),
    }
}

/// Handles one request line; `Subscribe` is answered by [`serve`] and rejected here.
pub fn handle(shared: &Mutex<Shared>, line: &str) -> Value {
    let req: Request = match serde_json::from_str(line) {
        Ok(r) => r,
        Err(e) => return err(format!("bad request: {e}")),
    };
    let mut s = lock(shared);
    let now = s.now_s;
    let link_fault = s.fault.clone();
    let Some(ctl) = s.ctl.as_mut() else {
        return err(format!(
            "not ready: {}",
            link_fault.unwrap_or_else(|| "starting".into())
        ));
    };
    let limits_v = ctl.limits();
    match req {
        Request::Status | Request::Subscribe { .. } => json!({ "ok": true, "status": s.status() }),
        Request::MoveJoints { q } => {
            if let Some(f) = link_fault {
                return err(format!("faulted ({f}); send reset first"));
            }
            let planned = Move::joints(ctl.model(), ctl.setpoint().q, q, &limits_v.0, &limits_v.1);
            start(ctl, planned, now)
        }
        Request::MovePose {
            position,
            quaternion,
        } => {
            if let Some(f) = link_fault {
                return err(format!("faulted ({f}); send reset first"));
            }
            let n = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !position.iter().chain(&quaternion).all(|v| v.is_finite()) || (n - 1.0).abs() > 1e-3
            {
                return err(format!(
                    "position must be finite (m) and quaternion a unit [w, x, y, z] (norm {n})"
                ));
            }
            let target = frame_from_pose(position, quaternion);
            let planned = Move::cartesian(
                ctl.model(),
                ctl.setpoint().q,
                target,
                &limits_v.0,
                &limits_v.1,
            );
            start(ctl, planned, now)
        }
        Request::Stop => {
            ctl.stop();
            json!({ "ok": true })
        }
        Request::Estop => {
            s.estop = true;
            json!({ "ok": true })
        }
        Request::Reset => {
            ctl.reset();
            s.restart = true;
            json!({ "ok": true })
        }
        Request::SetPayload { newtons } => match ctl.set_payload(newtons) {
            Ok(()) => json!({ "ok": true }),
            Err(e) => err(e),
        },
        Request::LoadModel { path } => match Model::load(&path) {
            Ok(m) => match ctl.load_model(m) {
                Ok(()) => json!({ "ok": true }),
                Err(e) => err(e),
            },
            Err(e) => err(e),
        },
    }
}

/// Serves clients on `path` (created with `mode`) until `stop` turns true.
pub async fn serve(
    path: &Path,
    mode: u32,
    shared: Arc<Mutex<Shared>>,
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
        let shared = shared.clone();
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
                        let st = json!({ "ok": true, "status": lock(&shared).status() });
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
                    let r = handle(&shared, &line);
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
