//! `pa10d`: the PA10 control daemon.
//!
//! Today it validates its configuration (`--check-config FILE`, which touches no bus) and,
//! given `--config FILE`, validates it and then refuses to start with a clear message: the
//! control loop arrives with the rest of the `[daemon]` issue, and a service unit pointing at
//! this binary must fail loudly rather than pretend to control an arm.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use pa10::daemon::config::{Backend, Config};

/// pa10d: compensating control daemon for the Mitsubishi PA10-6CE.
#[derive(Debug, Parser)]
#[command(name = "pa10d", version, about)]
struct Cli {
    /// Daemon configuration (YAML), e.g. config/sim.yaml.
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with = "check_config",
        required_unless_present = "check_config"
    )]
    config: Option<PathBuf>,
    /// Validate a configuration (and its model file) without touching the bus, then exit.
    #[arg(long, value_name = "FILE")]
    check_config: Option<PathBuf>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let path = cli
        .check_config
        .as_ref()
        .or(cli.config.as_ref())
        .cloned()
        .unwrap_or_default();
    let loaded = match Config::load(&path) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("pa10d: error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let c = &loaded.config;
    if cli.check_config.is_some() {
        let bus = match c.bus.backend {
            Backend::Socketcan => {
                format!("socketcan on {}", c.bus.interface.as_deref().unwrap_or("?"))
            }
            Backend::Virtual => "virtual bus with the simulated controller".to_string(),
        };
        let stiff: Vec<String> = (0..6)
            .filter(|&j| loaded.model.stiffness(j).is_some())
            .map(|j| format!("J{}", j + 1))
            .collect();
        println!("{}: valid", path.display());
        println!("  bus: {bus}, {:.0} kbit/s", c.bus.bitrate / 1e3);
        println!(
            "  cycle: {} Hz, worst-case bus load {:.1} % (limit {:.1} %)",
            c.control.rate_hz,
            loaded.bus_load * 100.0,
            c.bus.max_load * 100.0
        );
        println!(
            "  model: {} ({})",
            loaded.model_path.display(),
            if stiff.is_empty() {
                "rigid joints: no compensation".to_string()
            } else {
                format!("compensating {}", stiff.join(", "))
            }
        );
        println!(
            "  torques from: {:?}; payload {} N",
            c.control.torque_source, c.payload_n
        );
        println!(
            "  api: {} (mode {:o})",
            c.api.socket.display(),
            loaded.socket_mode
        );
        return ExitCode::SUCCESS;
    }
    eprintln!(
        "pa10d: {} is valid, but the control loop is not implemented yet (tracked by the [daemon] issue); \
         refusing to start. Nothing was sent to any bus.",
        path.display()
    );
    ExitCode::FAILURE
}
