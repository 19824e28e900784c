//! `pa10`: the user's tool for the PA10-6CE — model queries, accuracy bounds, calibration,
//! discovery of missing effects, the simulator and the daemon client.
//!
//! Argument parsing and wiring only; the work is done by the `pa10` library.

mod accuracy_cmd;
mod calib_cmd;
mod client_cmd;
mod collect_cmd;
mod demo_cmd;
mod discover_cmd;
mod identify_cmd;
mod iso_cmd;
mod model_cmds;
mod motion_cmd;
mod plan_cmd;
mod progress;
mod record_cmd;
mod sim_cmd;
mod view;

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use pa10::daemon::wire::ApiRequest;

/// pa10: calibrated, compliance-compensating positioning for the Mitsubishi PA10-6CE.
#[derive(Debug, Parser)]
#[command(name = "pa10", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Forward kinematics: tool pose (base frame) for joint angles.
    Fk(model_cmds::FkArgs),
    /// Inverse kinematics: joint solutions for a tool pose, nearest first.
    Ik(model_cmds::IkArgs),
    /// Resolver-uncertainty accuracy bound: Monte Carlo and linearised, per plane.
    Accuracy(accuracy_cmd::AccuracyArgs),
    /// Identify the gravity model (bodies) and every joint's friction from the arm's own
    /// motion through the daemon: constant-speed sweeps both ways, currents fitted (no
    /// instrument needed); run it before `pa10 calibrate`.
    Identify(identify_cmd::IdentifyArgs),
    /// Calibrate the flexible geometric model on measurements (two-level LM, seed paper II-C).
    Calibrate(calib_cmd::CalibrateArgs),
    /// Design a calibration campaign: the poses to measure (I- or D-optimal) and the accuracy they predict.
    Plan(plan_cmd::PlanArgs),
    /// ISO 9283 pose accuracy and repeatability: the test poses of a cube, then AP/RP per pose.
    #[command(subcommand)]
    Iso9283(iso_cmd::IsoCmd),
    /// The whole story on a simulated PA10: gather through pa10d, calibrate, validate.
    Demo(demo_cmd::DemoArgs),
    /// Drive the daemon through a pose list and record a calibration dataset.
    #[command(subcommand)]
    Collect(collect_cmd::CollectCmd),
    /// Find what the model misses: name the missing effect, add it, show the gap shrink.
    Discover(discover_cmd::DiscoverArgs),
    /// Simulated PA10: the servo controller on a CAN interface, measurement campaigns, replay.
    Sim(sim_cmd::SimArgs),
    /// Daemon: its state (pose, joints, faults, cycle statistics).
    Status(client_cmd::Conn),
    /// Daemon: move the arm (joint or straight-line tool move).
    Move {
        #[command(flatten)]
        conn: client_cmd::Conn,
        #[command(subcommand)]
        cmd: client_cmd::MoveCmd,
    },
    /// Daemon: controlled stop.
    Stop(client_cmd::Conn),
    /// Daemon: immediate servo stop and brakes (a software stop: the hardware e-stop stays in charge).
    Estop(client_cmd::Conn),
    /// Daemon: clear a fault and bring the servo back to control mode.
    Reset(client_cmd::Conn),
    /// Daemon: set the payload: its weight (N, or --mass kg) and centre of mass (--com, tool frame, m).
    #[command(allow_negative_numbers = true)]
    Payload {
        #[command(flatten)]
        conn: client_cmd::Conn,
        /// Newtons.
        #[arg(required_unless_present = "mass", conflicts_with = "mass")]
        newtons: Option<f64>,
        /// Mass, kg (instead of newtons).
        #[arg(long)]
        mass: Option<f64>,
        /// Centre of mass in the tool frame, m.
        #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"])]
        com: Option<Vec<f64>>,
    },
    /// Daemon: set the tool transform (flange → tool): X Y Z (m) QW QX QY QZ.
    #[command(allow_negative_numbers = true)]
    Tool {
        #[command(flatten)]
        conn: client_cmd::Conn,
        /// Translation and unit quaternion.
        #[arg(num_args = 7, required = true)]
        pose: Vec<f64>,
    },
    /// Daemon: load a (calibrated) model file between moves.
    LoadModel {
        #[command(flatten)]
        conn: client_cmd::Conn,
        /// The model YAML (a path the daemon can read).
        file: std::path::PathBuf,
    },
    /// Daemon: follow a timed joint trajectory from a CSV or JSON file.
    Trajectory(motion_cmd::TrajectoryArgs),
    /// Daemon: stream setpoints from stdin (six link angles, rad, per line).
    Servo(client_cmd::Conn),
    /// Daemon: jog one joint at a link speed (rad/s) for a while.
    Jog(motion_cmd::JogArgs),
    /// Daemon: scale the speed of running and future trajectories (0 < F ≤ 1).
    Speed {
        #[command(flatten)]
        conn: client_cmd::Conn,
        /// Fraction of full speed.
        fraction: f64,
    },
    /// Recording every control cycle (MCAP): start/stop through the daemon, info, export.
    #[command(subcommand)]
    Record(record_cmd::RecordCmd),
    /// Daemon: stream its state.
    Watch {
        #[command(flatten)]
        conn: client_cmd::Conn,
        /// Updates per second.
        #[arg(long, default_value_t = 2.0)]
        rate_hz: f64,
    },
    /// Model files.
    #[command(subcommand)]
    Model(model_cmds::ModelCmd),
    /// The model's kinematics as a URDF (RViz, MoveIt): the calibrated geometry, limits, the tool.
    Urdf(model_cmds::UrdfArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fk(a) => model_cmds::fk(&a),
        Command::Ik(a) => model_cmds::ik(&a),
        Command::Model(c) => model_cmds::model(&c),
        Command::Urdf(a) => model_cmds::urdf(&a),
        Command::Accuracy(a) => accuracy_cmd::accuracy(&a),
        Command::Identify(a) => identify_cmd::identify_cmd(&a),
        Command::Calibrate(a) => calib_cmd::calibrate(&a),
        Command::Plan(a) => plan_cmd::run(&a),
        Command::Iso9283(c) => iso_cmd::run(&c),
        Command::Discover(a) => discover_cmd::run(&a),
        Command::Demo(a) => demo_cmd::run(&a),
        Command::Collect(c) => collect_cmd::run(&c),
        Command::Sim(c) => sim_cmd::sim(&c),
        Command::Status(c) => client_cmd::status(&c),
        Command::Move { conn, cmd } => client_cmd::move_cmd(&conn, &cmd),
        Command::Stop(c) => client_cmd::simple(&c, ApiRequest::Stop {}),
        Command::Estop(c) => client_cmd::simple(&c, ApiRequest::Estop {}),
        Command::Reset(c) => client_cmd::simple(&c, ApiRequest::Reset {}),
        Command::Payload {
            conn,
            newtons,
            mass,
            com,
        } => {
            let req = ApiRequest::SetPayload {
                newtons,
                // --newtons wins when both are given
                mass_kg: mass.filter(|_| newtons.is_none()),
                com: com.map(|c| [c[0], c[1], c[2]]),
            };
            client_cmd::simple(&conn, req)
        }
        Command::Tool { conn, pose } => client_cmd::simple(
            &conn,
            ApiRequest::SetTool {
                translation: [pose[0], pose[1], pose[2]],
                quaternion: [pose[3], pose[4], pose[5], pose[6]],
            },
        ),
        Command::LoadModel { conn, file } => {
            let path = std::fs::canonicalize(&file).unwrap_or(file);
            client_cmd::simple(
                &conn,
                ApiRequest::LoadModel {
                    path: path.display().to_string(),
                },
            )
        }
        Command::Watch { conn, rate_hz } => client_cmd::watch(&conn, rate_hz),
        Command::Trajectory(a) => motion_cmd::trajectory(&a),
        Command::Record(c) => record_cmd::run(&c),
        Command::Servo(c) => motion_cmd::servo(&c),
        Command::Jog(a) => motion_cmd::jog(&a),
        Command::Speed { conn, fraction } => {
            client_cmd::simple(&conn, ApiRequest::SetSpeedScaling { fraction })
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pa10: error: {}", pa10::text::error_chain(e.as_ref()));
            ExitCode::FAILURE
        }
    }
}
