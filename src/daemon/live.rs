//! The live view: the Foxglove WebSocket protocol (`foxglove.websocket.v1`), so Foxglove shows
//! the joints and the compensation as the arm moves. Off by default (`live.enabled`), bound to
//! the loopback only, a thin tokio shell around the core's last cycle.
//!
//! The server advertises one channel, `/pa10/cycle` (JSON, the recording's `pa10.Cycle`
//! schema); a client subscribes to it and receives the core's latest cycle at `live.rate_hz`
//! as binary message frames (opcode 1, subscription id u32 LE, time ns u64 LE, JSON).
//! Hostile input: at most `MAX_CLIENTS` connections, client frames ≤ 16 KiB, ≤ 16
//! subscriptions per client; anything else is answered with a status message or closes.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde::Deserialize;
use serde_json::{Value, json};
use tokio::net::TcpListener;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::handshake::server::{Request, Response};
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;

pub use super::config::LiveConfig;
use super::runtime::{SharedCore, lock};
use crate::record::CYCLE_SCHEMA;

/// The WebSocket subprotocol Foxglove speaks.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Connections served at once.
pub const MAX_CLIENTS: usize = 8;
/// The largest frame a client may send, bytes.
const MAX_FRAME: usize = 16 << 10;
/// The one channel's id.
const CYCLE_CHANNEL: u64 = 1;

/// What a client may send.
#[derive(Debug, Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum ClientOp {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    Unsubscribe {
        #[serde(rename = "subscriptionIds")]
        subscription_ids: Vec<u32>,
    },
}

#[derive(Debug, Deserialize)]
struct Subscription {
    id: u32,
    #[serde(rename = "channelId")]
    channel_id: u64,
}

/// Serves the live view on `listener` (bind it to 127.0.0.1) until `stop` turns true.
pub async fn serve(
    listener: TcpListener,
    core: Arc<SharedCore>,
    rate_hz: f64,
    mut stop: tokio::sync::watch::Receiver<bool>,
) {
    let clients = Arc::new(AtomicUsize::new(0));
    loop {
        let accepted = tokio::select! {
            c = listener.accept() => c,
            _ = stop.changed() => return,
        };
        let Ok((tcp, peer)) = accepted else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        if clients.load(Ordering::Relaxed) >= MAX_CLIENTS {
            tracing::warn!(%peer, "live view: too many clients; refused");
            continue;
        }
        clients.fetch_add(1, Ordering::Relaxed);
        let (core, clients, stop) = (core.clone(), clients.clone(), stop.clone());
        tokio::spawn(async move {
            if let Err(e) = client(tcp, peer, core, rate_hz, stop).await {
                tracing::debug!(%peer, error = %e, "live view client ended");
            }
            clients.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

async fn client(
    tcp: tokio::net::TcpStream,
    peer: SocketAddr,
    core: Arc<SharedCore>,
    rate_hz: f64,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> Result<(), tokio_tungstenite::tungstenite::Error> {
    // the error type is tungstenite's (`Callback`), not ours
    #[allow(clippy::result_large_err)]
    let choose = |req: &Request, mut resp: Response| {
        let offered = req
            .headers()
            .get("Sec-WebSocket-Protocol")
            .and_then(|v| v.to_str().ok())
            .is_some_and(|v| v.split(',').any(|p| p.trim() == SUBPROTOCOL));
        if offered {
            resp.headers_mut().insert(
                "Sec-WebSocket-Protocol",
                HeaderValue::from_static(SUBPROTOCOL),
            );
        }
        Ok(resp)
    };
    let cfg = WebSocketConfig::default()
        .max_message_size(Some(MAX_FRAME))
        .max_frame_size(Some(MAX_FRAME));
    let handshake = tokio_tungstenite::accept_hdr_async_with_config(tcp, choose, Some(cfg));
    let ws = tokio::time::timeout(Duration::from_secs(5), handshake)
        .await
        .map_err(|_| tokio_tungstenite::tungstenite::Error::ConnectionClosed)??;
    tracing::info!(%peer, "live view client connected");
    let (mut tx, mut rx) = ws.split();
    tx.send(Message::text(
        json!({"op": "serverInfo", "name": "pa10d", "capabilities": [], "supportedEncodings": [],
               "metadata": {}, "sessionId": format!("{}", std::process::id())})
        .to_string(),
    ))
    .await?;
    tx.send(Message::text(
        json!({"op": "advertise", "channels": [{
            "id": CYCLE_CHANNEL, "topic": "/pa10/cycle", "encoding": "json",
            "schemaName": "pa10.Cycle", "schema": CYCLE_SCHEMA, "schemaEncoding": "jsonschema"}]})
        .to_string(),
    ))
    .await?;
    let mut subs: Vec<u32> = Vec::new();
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz));
    let mut last_cycle = u64::MAX;
    let mut frame = Vec::with_capacity(1024);
    loop {
        tokio::select! {
            _ = stop.changed() => return Ok(()),
            msg = rx.next() => {
                let Some(msg) = msg else { return Ok(()) };
                match msg? {
                    Message::Text(t) => {
                        let reply = match serde_json::from_str::<ClientOp>(&t) {
                            Ok(ClientOp::Subscribe { subscriptions }) => {
                                let mut bad = None;
                                for s in subscriptions {
                                    if s.channel_id != CYCLE_CHANNEL {
                                        bad = Some(format!("unknown channel {}", s.channel_id));
                                    } else if subs.len() >= 16 {
                                        bad = Some("at most 16 subscriptions".to_string());
                                    } else if !subs.contains(&s.id) {
                                        subs.push(s.id);
                                    }
                                }
                                bad
                            }
                            Ok(ClientOp::Unsubscribe { subscription_ids }) => {
                                subs.retain(|s| !subscription_ids.contains(s));
                                None
                            }
                            Err(e) => Some(format!("not understood: {}", crate::text::truncate(&e.to_string(), 200))),
                        };
                        if let Some(r) = reply {
                            let status = json!({"op": "status", "level": 1, "message": r});
                            tx.send(Message::text(status.to_string())).await?;
                        }
                    }
                    Message::Close(_) => return Ok(()),
                    _ => {}
                }
            }
            _ = tick.tick() => {
                if subs.is_empty() {
                    continue;
                }
                let Some(sample) = lock(&core).last_sample() else { continue };
                if sample.cycle == last_cycle {
                    continue;
                }
                last_cycle = sample.cycle;
                let payload: Value = serde_json::to_value(sample).unwrap_or(Value::Null);
                let body = payload.to_string();
                let ns = (sample.stamp_s.max(0.0) * 1e9) as u64;
                for id in &subs {
                    frame.clear();
                    frame.push(1u8);
                    frame.extend_from_slice(&id.to_le_bytes());
                    frame.extend_from_slice(&ns.to_le_bytes());
                    frame.extend_from_slice(body.as_bytes());
                    tx.send(Message::binary(frame.clone())).await?;
                }
            }
        }
    }
}
