//! The live view through a WebSocket client we did not write (tungstenite), against the
//! daemon core in simulated time: the Foxglove handshake, the advertised channel, the cycles
//! sent to a subscription, and refusals of what is not understood.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pa10::daemon::config::Config;
use pa10::model::Model;
use pa10::sim::rig::Lockstep;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::{self, Message, client::IntoClientRequest};

#[test]
fn foxglove_clients_see_the_cycles_live() {
    let dir = std::env::temp_dir().join(format!("pa10-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let loaded = Config::load(&crate::daemon::config(&dir, &Model::nominal())).unwrap();
    let mut ls = Lockstep::from_config(&loaded).unwrap();
    ls.run_until_ready(1.0).unwrap();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stop_rx) = tokio::sync::watch::channel(false);
    rt.spawn(pa10::daemon::live::serve(
        listener,
        ls.core.clone(),
        200.0,
        stop_rx,
    ));
    let done = Arc::new(AtomicBool::new(false));
    let client = {
        let done = done.clone();
        std::thread::spawn(move || {
            let mut req = format!("ws://{addr}").into_client_request().unwrap();
            req.headers_mut().insert(
                "Sec-WebSocket-Protocol",
                "foxglove.websocket.v1".parse().unwrap(),
            );
            let (mut ws, resp) = tungstenite::connect(req).unwrap();
            assert_eq!(
                resp.headers()["Sec-WebSocket-Protocol"],
                "foxglove.websocket.v1"
            );
            let text = |ws: &mut tungstenite::WebSocket<_>| -> Value {
                match ws.read().unwrap() {
                    Message::Text(t) => serde_json::from_str(&t).unwrap(),
                    m => panic!("{m:?}"),
                }
            };
            let info = text(&mut ws);
            assert_eq!(info["op"], "serverInfo");
            let adv = text(&mut ws);
            assert_eq!(adv["op"], "advertise");
            let ch = &adv["channels"][0];
            assert_eq!(ch["topic"], "/pa10/cycle");
            assert_eq!(ch["schemaEncoding"], "jsonschema");
            let id = ch["id"].as_u64().unwrap();
            // what is not understood is answered, the connection stays
            ws.send(Message::text(r#"{"op":"fly"}"#)).unwrap();
            assert_eq!(text(&mut ws)["op"], "status");
            let bad = json!({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 99}]});
            ws.send(Message::text(bad.to_string())).unwrap();
            assert!(
                text(&mut ws)["message"]
                    .as_str()
                    .unwrap()
                    .contains("unknown channel")
            );
            let sub = json!({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": id}]});
            ws.send(Message::text(sub.to_string())).unwrap();
            let mut cycles = Vec::new();
            while cycles.len() < 10 {
                if let Message::Binary(b) = ws.read().unwrap() {
                    assert_eq!(b[0], 1, "message data opcode");
                    assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 7);
                    let v: Value = serde_json::from_slice(&b[13..]).unwrap();
                    assert_eq!(v["q_motor"].as_array().unwrap().len(), 6);
                    cycles.push(v["cycle"].as_u64().unwrap());
                }
            }
            done.store(true, Ordering::SeqCst);
            cycles
        })
    };
    while !done.load(Ordering::SeqCst) && ls.now() < 30.0 {
        ls.run_for(0.005);
        std::thread::sleep(Duration::from_millis(2));
    }
    let cycles = client.join().unwrap();
    assert!(
        cycles.windows(2).all(|w| w[1] > w[0]),
        "new cycles only: {cycles:?}"
    );
    stop.send(true).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}
