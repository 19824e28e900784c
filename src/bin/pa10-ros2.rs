//! `pa10-ros2`: a ROS 2 face for `pa10d`, as a separate process that is a client of its
//! socket (never inside the control process). Pure Rust DDS (ros2-client over RustDDS), no
//! ROS installation. Publishes `/joint_states` (sensor_msgs/JointState: the link estimate,
//! its velocity, the torque estimate; joints `pa10_joint_1…6`; reliable, keep-last 10) at the
//! status stream's rate (≤ 100 Hz). Domain from `ROS_DOMAIN_ID` (default 0).
//!
//! Not yet: the FollowJointTrajectory action, `~/stop` / `~/reset`, `/diagnostics`.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;

use anyhow::{Context as _, Result, bail};
use clap::Parser;
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions, QosProfile,
    builtin_interfaces::Time,
    qos::{Durability, History, WhenFull},
};
use serde::Serialize;

/// std_msgs/Header.
#[derive(Serialize, Clone, Debug)]
struct Header {
    stamp: Time,
    frame_id: String,
}

/// sensor_msgs/JointState.
#[derive(Serialize, Clone, Debug)]
struct JointState {
    header: Header,
    name: Vec<String>,
    position: Vec<f64>,
    velocity: Vec<f64>,
    effort: Vec<f64>,
}

#[derive(Parser)]
#[command(
    version,
    about = "A ROS 2 face for pa10d: /joint_states from its socket"
)]
struct Args {
    /// pa10d's API socket.
    #[arg(long, env = "PA10D_SOCKET", default_value = "/run/pa10d/pa10d.sock")]
    socket: PathBuf,
    /// Joint states per second (1…100: the daemon's status stream rate).
    #[arg(long, default_value_t = 100.0)]
    rate_hz: f64,
}

fn six(v: &serde_json::Value) -> Option<[f64; 6]> {
    serde_json::from_value(v.clone()).ok()
}

fn main() -> Result<()> {
    let args = Args::parse();
    if !(1.0..=100.0).contains(&args.rate_hz) {
        bail!("--rate-hz must be within 1…100, got {}", args.rate_hz);
    }
    let domain: u16 = match std::env::var("ROS_DOMAIN_ID") {
        Ok(d) => d.parse().context("ROS_DOMAIN_ID must be a number 0…232")?,
        Err(_) => 0,
    };
    let context = Context::with_options(ContextOptions::new().domain_id(domain))
        .map_err(|e| anyhow::anyhow!("DDS: {e:?}"))?;
    let mut node = context
        .new_node(
            NodeName::new("/", "pa10_driver").map_err(|e| anyhow::anyhow!("{e:?}"))?,
            NodeOptions::new(),
        )
        .map_err(|e| anyhow::anyhow!("node: {e:?}"))?;
    let executor = smol::Executor::new();
    executor
        .spawn(node.spinner().map_err(|e| anyhow::anyhow!("{e:?}"))?.spin())
        .detach();
    let qos = QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 });
    let topic = node
        .create_topic(
            &Name::new("/", "joint_states").map_err(|e| anyhow::anyhow!("{e:?}"))?,
            MessageTypeName::new("sensor_msgs", "JointState"),
            &qos,
        )
        .map_err(|e| anyhow::anyhow!("topic: {e:?}"))?;
    let publisher = node
        .create_publisher::<JointState>(&topic, None)
        .map_err(|e| anyhow::anyhow!("publisher: {e:?}"))?;
    let mut s = UnixStream::connect(&args.socket)
        .with_context(|| format!("connecting to pa10d at {}", args.socket.display()))?;
    s.write_all(format!("{{\"cmd\":\"subscribe\",\"rate_hz\":{}}}\n", args.rate_hz).as_bytes())?;
    let names: Vec<String> = (1..=6).map(|j| format!("pa10_joint_{j}")).collect();
    let mut last: Option<(f64, [f64; 6])> = None;
    smol::block_on(executor.run(async {
        for line in BufReader::new(s).lines() {
            let v: serde_json::Value = serde_json::from_str(&line?)?;
            if v["ok"] != true {
                bail!("pa10d: {}", v["error"]);
            }
            let st = &v["status"];
            // the link estimate (resolver minus the modelled deflection)
            let (Some(q), Some(tau)) = (six(&st["trajectory"]["actual"]), six(&st["tau"])) else {
                continue;
            };
            let t = st["time_s"].as_f64().unwrap_or(0.0);
            let velocity = match last {
                Some((t0, q0)) if t > t0 => (0..6).map(|j| (q[j] - q0[j]) / (t - t0)).collect(),
                _ => vec![0.0; 6],
            };
            last = Some((t, q));
            let msg = JointState {
                header: Header {
                    stamp: Time::now(),
                    frame_id: String::new(),
                },
                name: names.clone(),
                position: q.to_vec(),
                velocity,
                effort: tau.to_vec(),
            };
            publisher
                .async_publish(msg)
                .await
                .map_err(|e| anyhow::anyhow!("publish: {e:?}"))?;
        }
        anyhow::Ok(())
    }))
}
