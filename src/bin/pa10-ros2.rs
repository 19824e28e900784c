//! `pa10-ros2`: a ROS 2 face for `pa10d`, as a separate process that is a client of its
//! socket (never inside the control process). Pure Rust DDS (ros2-client over RustDDS), no
//! ROS installation. Domain from `ROS_DOMAIN_ID` (default 0). It serves:
//!
//! - `/joint_states` (sensor_msgs/JointState: the link estimate, its velocity, the torque
//!   estimate; joints `pa10_joint_1…6`; reliable, keep-last 10) at the status stream's rate
//!   (≤ 100 Hz);
//! - the action `/pa10_controller/follow_joint_trajectory`
//!   (control_msgs/action/FollowJointTrajectory): every goal is accepted and ends with a
//!   result code — a goal the arm cannot follow as INVALID_GOAL / INVALID_JOINTS /
//!   OLD_HEADER_TIMESTAMP with the daemon's or the translation's words; feedback at 20 Hz; a
//!   cancel stops the arm (controlled stop) and ends the goal CANCELED; a newer goal replaces
//!   the running one (CANCELED, INVALID_GOAL, as ros2_controllers' joint_trajectory_controller);
//! - `std_srvs/Trigger` services `/pa10_driver/stop` and `/pa10_driver/reset`;
//! - `/diagnostics` (diagnostic_msgs/DiagnosticArray) once a second: faults, loop timing,
//!   link counters, bus load.
//!
//! The message types and translations are `pa10::ros2` (pure, unit-tested); this file is the
//! DDS and socket shell, one thread (smol's local executor).

use std::cell::RefCell;
use std::io::Write;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::rc::Rc;
use std::time::Duration;

use anyhow::{Context as _, Result, anyhow, bail};
use clap::{Parser, ValueEnum};
use pa10::daemon::api::{Client, ClientError};
use pa10::daemon::wire::{Answer, ApiRequest, Reply, Status};
use pa10::ros2::{
    DiagnosticArray, Ending, FollowJointTrajectoryFeedback, FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult, Header, JOINT_NAMES, JointStateMsg, Time, TriggerRequest,
    TriggerResponse, code,
};
use ros2_client::action::{
    ActionServerQosPolicies, AsyncActionServer, ExecutingGoalHandle, GoalEndStatus,
};
use ros2_client::{
    ActionTypeName, Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions,
    QosProfile, ServiceMapping, ServiceTypeName,
    qos::{Durability, History, WhenFull},
};
use smol::future::FutureExt as _;
use smol::io::AsyncBufReadExt as _;
use smol::{Async, LocalExecutor, Timer};

type Goal = FollowJointTrajectoryGoal;
type Server = AsyncActionServer<Goal, FollowJointTrajectoryResult, FollowJointTrajectoryFeedback>;

/// How request and reply of a service travel (the RMW of the ROS 2 side decides).
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Mapping {
    /// rmw_fastrtps (the default RMW of Humble and Jazzy) and rmw_connextdds.
    Enhanced,
    /// rmw_cyclonedds.
    Cyclone,
    /// The RPC-over-DDS basic mapping.
    Basic,
}

#[derive(Parser)]
#[command(
    version,
    about = "A ROS 2 face for pa10d: /joint_states, FollowJointTrajectory, ~/stop, ~/reset, /diagnostics"
)]
struct Args {
    /// pa10d's API socket.
    #[arg(long, env = "PA10D_SOCKET", default_value = "/run/pa10d/pa10d.sock")]
    socket: PathBuf,
    /// Joint states per second (1…100: the daemon's status stream rate).
    #[arg(long, default_value_t = 100.0)]
    rate_hz: f64,
    /// The service mapping of the ROS 2 side's RMW.
    #[arg(
        long,
        env = "PA10_ROS2_SERVICE_MAPPING",
        value_enum,
        default_value = "enhanced"
    )]
    service_mapping: Mapping,
}

/// How long a request to pa10d may take, s.
const CALL_TIMEOUT_S: u64 = 5;
/// Feedback period of a running goal (joint_trajectory_controller's action_monitor_rate 20 Hz).
const MONITOR_PERIOD: Duration = Duration::from_millis(50);
/// How long a finished goal waits for its client's result request.
const RESULT_WAIT: Duration = Duration::from_secs(60);

/// Requests to pa10d: a connection per request (goals, cancels and triggers are rare), so
/// the daemon's idle timeout (300 s) or a broken connection never leaves the bridge with a
/// dead one.
struct Daemon(Client);

impl Daemon {
    /// The daemon's answer to `req`, or its words (a refusal's, or why it could not answer).
    fn call(&self, req: &ApiRequest) -> Result<Answer, String> {
        self.0.call(req).map_err(|e| match e {
            ClientError::Refused(r) => r.0,
            e => e.to_string(),
        })
    }
}

/// The latest status the subscription brought, and the goal being followed.
#[derive(Default)]
struct Shared {
    status: Option<Status>,
    active: Option<Active>,
}

struct Active {
    handle: ExecutingGoalHandle<Goal>,
    /// The daemon's trajectory id.
    id: u64,
    canceling: bool,
}

fn now() -> Time {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    Time::from_secs(t.as_secs_f64())
}

fn name(ns: &str, base: &str) -> Result<Name> {
    Name::new(ns, base).map_err(|e| anyhow!("name {ns}/{base}: {e:?}"))
}

fn dds<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("{what}: {e:?}")
}

/// Counts the failed requests of one kind (a malformed goal from a DDS client, a reply DDS
/// could not send) and says so on stderr at the 1st, 2nd, 4th, 8th… of them: a client cannot
/// stop the bridge, nor flood its log.
#[derive(Default)]
struct Failures(std::cell::Cell<u64>);

impl Failures {
    /// `r`'s value, or None after counting (and perhaps logging) its error.
    fn check<T, E: std::fmt::Debug>(&self, what: &str, r: Result<T, E>) -> Option<T> {
        match r {
            Ok(v) => Some(v),
            Err(e) => {
                let n = self.0.get() + 1;
                self.0.set(n);
                if n.is_power_of_two() {
                    eprintln!("pa10-ros2: {what}: {e:?} ({n} so far)");
                }
                None
            }
        }
    }
}

/// After a failed receive, a pause before the next (a reader that fails at once every time
/// must not spin).
const AFTER_FAILURE: Duration = Duration::from_millis(10);

fn main() -> Result<()> {
    let args = Args::parse();
    if !(1.0..=100.0).contains(&args.rate_hz) {
        bail!("--rate-hz must be within 1…100, got {}", args.rate_hz);
    }
    let domain: u16 = match std::env::var("ROS_DOMAIN_ID") {
        Ok(d) => d.parse().context("ROS_DOMAIN_ID must be a number 0…232")?,
        Err(_) => 0,
    };
    let mapping = match args.service_mapping {
        Mapping::Enhanced => ServiceMapping::Enhanced,
        Mapping::Cyclone => ServiceMapping::Cyclone,
        Mapping::Basic => ServiceMapping::Basic,
    };
    let daemon = Rc::new(Daemon(
        Client::new(&args.socket).with_timeout(Duration::from_secs(CALL_TIMEOUT_S)),
    ));
    let context =
        Context::with_options(ContextOptions::new().domain_id(domain)).map_err(dds("DDS"))?;
    let mut node = context
        .new_node(
            NodeName::new("/", "pa10_driver").map_err(dds("node name"))?,
            NodeOptions::new(),
        )
        .map_err(dds("node"))?;
    let ex = Rc::new(LocalExecutor::new());
    ex.spawn(node.spinner().map_err(dds("spinner"))?.spin())
        .detach();
    let shared = Rc::new(RefCell::new(Shared::default()));
    let states = joint_states(&mut node, &args, shared.clone())?;
    let server = Rc::new(action_server(&mut node, mapping)?);
    let triggers = triggers(&mut node, mapping, daemon.clone())?;
    let diag = diagnostics(&mut node, shared.clone())?;
    let goals = goals(ex.clone(), server.clone(), daemon.clone(), shared.clone());
    let cancels = cancels(server.clone(), daemon.clone(), shared.clone());
    let monitor = monitor(ex.clone(), server, shared);
    eprintln!(
        "pa10-ros2: domain {domain}, pa10d at {}, service mapping {:?}",
        args.socket.display(),
        args.service_mapping
    );
    // every part runs until the daemon's connection ends or DDS fails; the first error ends all
    smol::block_on(
        ex.run(
            states
                .race(triggers)
                .race(diag)
                .race(goals)
                .race(cancels)
                .race(monitor),
        ),
    )
}

/// `/joint_states` from the daemon's status stream (which also keeps `shared.status` fresh).
fn joint_states(
    node: &mut Node,
    args: &Args,
    shared: Rc<RefCell<Shared>>,
) -> Result<impl std::future::Future<Output = Result<()>> + use<>> {
    let publisher = publisher::<JointStateMsg>(node, "joint_states", "sensor_msgs", "JointState")?;
    let mut s = UnixStream::connect(&args.socket)
        .with_context(|| format!("connecting to pa10d at {}", args.socket.display()))?;
    let mut line = serde_json::to_vec(&ApiRequest::Subscribe {
        rate_hz: args.rate_hz,
    })?;
    line.push(b'\n');
    s.write_all(&line)?;
    let stream = Async::new(s)?;
    Ok(async move {
        let names: Vec<String> = JOINT_NAMES.iter().map(|s| s.to_string()).collect();
        let mut last: Option<(f64, [f64; 6])> = None;
        let mut lines = smol::io::BufReader::new(stream).lines();
        while let Some(line) = smol::stream::StreamExt::next(&mut lines).await {
            let st = match serde_json::from_str::<Reply>(&line?)? {
                Reply::Ok(Answer::Status(st)) => *st,
                Reply::Ok(other) => bail!("pa10d sent {other:?} in the status stream"),
                Reply::Refused(e) => bail!("pa10d: {e}"),
            };
            let (t, tau, time_s) = (st.trajectory, st.tau, st.time_s);
            shared.borrow_mut().status = Some(st);
            // the link estimate (resolver minus the modelled deflection)
            let q = t.actual;
            let velocity = match last {
                Some((t0, q0)) if time_s > t0 => {
                    (0..6).map(|j| (q[j] - q0[j]) / (time_s - t0)).collect()
                }
                _ => vec![0.0; 6],
            };
            last = Some((time_s, q));
            let msg = JointStateMsg {
                header: Header {
                    stamp: now(),
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
                .map_err(dds("publish /joint_states"))?;
        }
        bail!("pa10d closed the status stream")
    })
}

/// Reliable, volatile, keep-last 10: ROS 2's default for topics and services (and what
/// drivers use for `/joint_states`).
fn reliable() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// A [`reliable`] publisher of `pkg/msg/ty` on `/topic`.
fn publisher<T: serde::Serialize>(
    node: &mut Node,
    topic: &str,
    pkg: &str,
    ty: &str,
) -> Result<ros2_client::Publisher<T>> {
    let t = node
        .create_topic(
            &name("/", topic)?,
            MessageTypeName::new(pkg, ty),
            &reliable(),
        )
        .map_err(dds("topic"))?;
    node.create_publisher::<T>(&t, None)
        .map_err(dds("publisher"))
}

fn action_server(node: &mut Node, mapping: ServiceMapping) -> Result<Server> {
    // as ROS 2's action defaults: services and feedback reliable + volatile, status
    // transient-local (a late client still learns the goals' states)
    let service = reliable();
    let status = QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 });
    let qos = ActionServerQosPolicies {
        goal_service: service.clone(),
        result_service: service.clone(),
        cancel_service: service.clone(),
        feedback_publisher: service,
        status_publisher: status,
    };
    let s = node
        .create_action_server::<Goal, FollowJointTrajectoryResult, FollowJointTrajectoryFeedback>(
            mapping,
            &name("/pa10_controller", "follow_joint_trajectory")?,
            &ActionTypeName::new("control_msgs", "FollowJointTrajectory"),
            qos,
        )
        .map_err(dds("action server"))?;
    Ok(AsyncActionServer::new(s))
}

/// Sends the result of a goal that ended, once its client asks (at most [`RESULT_WAIT`]).
fn finish(
    ex: &LocalExecutor<'static>,
    server: Rc<Server>,
    handle: ExecutingGoalHandle<Goal>,
    ending: Ending,
    result: FollowJointTrajectoryResult,
) {
    let status = match ending {
        Ending::Succeeded => GoalEndStatus::Succeeded,
        Ending::Aborted => GoalEndStatus::Aborted,
        Ending::Canceled => GoalEndStatus::Canceled,
    };
    eprintln!(
        "pa10-ros2: goal {:?} {status:?}: {} {}",
        handle.goal_id(),
        result.error_code,
        result.error_string
    );
    let id = handle.goal_id();
    ex.spawn(async move {
        let sent = server
            .send_result_response(handle, status, result)
            .or(async {
                Timer::after(RESULT_WAIT).await;
                Err(ros2_client::action::GoalError::NoSuchGoal)
            })
            .await;
        if let Err(e) = sent {
            eprintln!("pa10-ros2: the result of goal {id:?} was not delivered: {e:?}");
        }
    })
    .detach();
}

/// Takes every goal: accepted, translated, handed to the daemon — or ended at once with the
/// code and the words that refuse it.
async fn goals(
    ex: Rc<LocalExecutor<'static>>,
    server: Rc<Server>,
    daemon: Rc<Daemon>,
    shared: Rc<RefCell<Shared>>,
) -> Result<()> {
    let failed = Failures::default();
    loop {
        let Some(new) = failed.check("goal", server.receive_new_goal().await) else {
            Timer::after(AFTER_FAILURE).await;
            continue;
        };
        let Some(goal) = server.get_new_goal(new.clone()) else {
            continue;
        };
        let Some(accepted) = failed.check("accepting a goal", server.accept_goal(new).await) else {
            continue;
        };
        let Some(handle) = failed.check(
            "executing a goal",
            server.start_executing_goal(accepted).await,
        ) else {
            continue;
        };
        let current = shared.borrow().status.as_ref().map(|s| s.setpoint);
        let started = match current {
            None => Err((code::INVALID_GOAL, "no status from pa10d yet".to_string())),
            Some(current) => match pa10::ros2::goal_request(&goal, now(), &current) {
                Err(r) => Err((r.code, r.message)),
                Ok(req) => match daemon.call(&req) {
                    Ok(Answer::Following { id }) => Ok(id),
                    Ok(other) => Err((
                        code::INVALID_GOAL,
                        format!("pa10d answered without an id: {other:?}"),
                    )),
                    Err(e) => Err((code::INVALID_GOAL, e)),
                },
            },
        };
        match started {
            Err((error_code, error_string)) => finish(
                &ex,
                server.clone(),
                handle,
                Ending::Aborted,
                FollowJointTrajectoryResult {
                    error_code,
                    error_string,
                },
            ),
            Ok(id) => {
                let old = shared.borrow_mut().active.replace(Active {
                    handle,
                    id,
                    canceling: false,
                });
                if let Some(old) = old {
                    finish(
                        &ex,
                        server.clone(),
                        old.handle,
                        Ending::Canceled,
                        FollowJointTrajectoryResult {
                            error_code: code::INVALID_GOAL,
                            error_string: "replaced by a newer goal".into(),
                        },
                    );
                }
            }
        }
    }
}

/// A cancel of the running goal stops the arm (its result follows when it has stopped).
async fn cancels(
    server: Rc<Server>,
    daemon: Rc<Daemon>,
    shared: Rc<RefCell<Shared>>,
) -> Result<()> {
    let failed = Failures::default();
    loop {
        let Some(req) = failed.check("cancel", server.receive_cancel_request().await) else {
            Timer::after(AFTER_FAILURE).await;
            continue;
        };
        let target = shared
            .borrow()
            .active
            .as_ref()
            .map(|a| a.handle.goal_id())
            .filter(|id| req.contains_goal(id));
        let canceling = match target {
            Some(id) => match daemon.call(&ApiRequest::Stop {}) {
                Ok(_) => {
                    if let Some(a) = shared.borrow_mut().active.as_mut() {
                        a.canceling = true;
                    }
                    Some(id)
                }
                Err(e) => {
                    eprintln!("pa10-ros2: cancel: pa10d refused to stop: {e}");
                    None
                }
            },
            None => None,
        };
        failed.check(
            "cancel response",
            server
                .respond_to_cancel_requests(&req, canceling.into_iter())
                .await,
        );
    }
}

/// Follows the running goal in the daemon's status: feedback while it runs, the result when it
/// ends.
async fn monitor(
    ex: Rc<LocalExecutor<'static>>,
    server: Rc<Server>,
    shared: Rc<RefCell<Shared>>,
) -> Result<()> {
    loop {
        Timer::after(MONITOR_PERIOD).await;
        let (handle, ended, report) = {
            let mut sh = shared.borrow_mut();
            let Some(st) = sh.status.as_ref() else {
                continue;
            };
            let Some(a) = sh.active.as_ref() else {
                continue;
            };
            let t = st.trajectory;
            if t.id < a.id {
                continue; // the status stream has not seen it start yet
            }
            let ended = if t.id > a.id {
                Some((
                    Ending::Canceled,
                    FollowJointTrajectoryResult {
                        error_code: code::INVALID_GOAL,
                        error_string: "replaced by a newer trajectory, move or stream".into(),
                    },
                ))
            } else {
                pa10::ros2::goal_result(&t, a.canceling, st.fault.as_deref())
            };
            let handle = a.handle.clone();
            if ended.is_some() {
                sh.active = None;
            }
            (handle, ended, t)
        };
        match ended {
            Some((ending, result)) => finish(&ex, server.clone(), handle, ending, result),
            None => {
                if let Err(e) = server
                    .publish_feedback(handle, pa10::ros2::feedback(&report, now()))
                    .await
                {
                    eprintln!("pa10-ros2: feedback: {e:?}");
                }
            }
        }
    }
}

/// `/pa10_driver/stop` and `/pa10_driver/reset` (std_srvs/Trigger).
fn triggers(
    node: &mut Node,
    mapping: ServiceMapping,
    daemon: Rc<Daemon>,
) -> Result<impl std::future::Future<Output = Result<()>> + use<>> {
    let qos = reliable();
    let mut make = |base: &str| {
        node.create_server::<TriggerRequest, TriggerResponse>(
            mapping,
            &name("/pa10_driver", base)?,
            &ServiceTypeName::new("std_srvs", "Trigger"),
            qos.clone(),
            qos.clone(),
        )
        .map_err(dds("service"))
    };
    let (stop, reset) = (make("stop")?, make("reset")?);
    let serve = move |srv: ros2_client::Server<TriggerRequest, TriggerResponse>,
                      req: ApiRequest| {
        let daemon = daemon.clone();
        let cmd = req.name();
        async move {
            let failed = Failures::default();
            loop {
                let Some((id, _)) = failed.check(cmd, srv.async_receive_request().await) else {
                    Timer::after(AFTER_FAILURE).await;
                    continue;
                };
                let resp = match daemon.call(&req) {
                    Ok(_) => TriggerResponse {
                        success: true,
                        message: format!("pa10d: {cmd} done"),
                    },
                    Err(e) => TriggerResponse {
                        success: false,
                        message: e,
                    },
                };
                failed.check("trigger response", srv.async_send_response(id, resp).await);
            }
        }
    };
    Ok(serve(stop, ApiRequest::Stop {}).race(serve(reset, ApiRequest::Reset {})))
}

/// `/diagnostics` once a second from the latest status.
fn diagnostics(
    node: &mut Node,
    shared: Rc<RefCell<Shared>>,
) -> Result<impl std::future::Future<Output = Result<()>> + use<>> {
    let publisher =
        publisher::<DiagnosticArray>(node, "diagnostics", "diagnostic_msgs", "DiagnosticArray")?;
    Ok(async move {
        loop {
            Timer::after(Duration::from_secs(1)).await;
            let st = shared.borrow().status.clone();
            if let Some(st) = st {
                publisher
                    .async_publish(pa10::ros2::diagnostics(&st, now()))
                    .await
                    .map_err(dds("publish /diagnostics"))?;
            }
        }
    })
}
