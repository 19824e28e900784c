//! `pa10`: the user's tool for the PA10-6CE — model queries today, calibration, accuracy
//! bounds, discovery and the daemon client as their issues land.
//!
//! Argument parsing and wiring only; the work is done by the `pa10` library.

mod accuracy_cmd;
mod calib_cmd;
mod model_cmds;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

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
    /// Calibrate the flexible geometric model on measurements (two-level LM, seed paper II-C).
    Calibrate(calib_cmd::CalibrateArgs),
    /// Simulated PA10: the servo controller on a CAN interface, measurement campaigns, replay.
    Sim(calib_cmd::SimArgs),
    /// Model files.
    #[command(subcommand)]
    Model(model_cmds::ModelCmd),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fk(a) => model_cmds::fk(&a),
        Command::Ik(a) => model_cmds::ik(&a),
        Command::Model(c) => model_cmds::model(&c),
        Command::Accuracy(a) => accuracy_cmd::accuracy(&a),
        Command::Calibrate(a) => calib_cmd::calibrate(&a),
        Command::Sim(c) => calib_cmd::sim(&c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pa10: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
