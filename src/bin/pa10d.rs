//! `pa10d`: the PA10 control daemon.
//!
//! Skeleton until the `[daemon]` issue lands: it parses its command line, checks that the
//! configuration file is readable and refuses to start with a clear message, so that a
//! service unit pointing at it fails loudly instead of pretending to control an arm.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

/// pa10d: compensating control daemon for the Mitsubishi PA10-6CE (not yet implemented).
#[derive(Debug, Parser)]
#[command(name = "pa10d", version, about)]
struct Cli {
    /// Daemon configuration (YAML), e.g. config/sim.yaml.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Err(e) = std::fs::metadata(&cli.config) {
        eprintln!(
            "pa10d: error: cannot read config {}: {e}",
            cli.config.display()
        );
        return ExitCode::FAILURE;
    }
    eprintln!(
        "pa10d: the control loop is not implemented yet (tracked by the [daemon] issue); \
         refusing to start with {}. Nothing was sent to any bus.",
        cli.config.display()
    );
    ExitCode::FAILURE
}
