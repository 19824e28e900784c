//! `pa10d`: the PA10 control daemon.
//!
//! Wiring only: read and validate the configuration, start the control core
//! ([`pa10::daemon::runtime::Daemon`]) on the configured bus, serve the client API on the
//! Unix socket, tell systemd (READY after the controller is in control mode; watchdog pings
//! only while the control loop makes progress), and on SIGTERM/SIGINT bring the arm to rest
//! and stop the servo before exiting.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use pa10::daemon::config::{Backend, Config};
use pa10::daemon::runtime::{Daemon, lock};
use pa10::sim::rig::SimulatedArm;
use sd_notify::NotifyState;

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
    let result = match (&cli.check_config, &cli.config) {
        (Some(p), _) => check(p),
        (None, Some(p)) => run(p),
        (None, None) => Ok(()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pa10d: error: {}", pa10::text::error_chain(e.as_ref()));
            ExitCode::FAILURE
        }
    }
}

fn check(path: &Path) -> Result<()> {
    let s = Config::load(path)?;
    let bus = match s.bus.backend {
        Backend::Socketcan => format!("socketcan on {}", s.bus.interface.as_deref().unwrap_or("?")),
        Backend::Virtual => "virtual bus with the simulated controller".to_string(),
    };
    let stiff: Vec<String> = (0..6)
        .filter(|&j| s.model.stiffness(j).is_some())
        .map(|j| format!("J{}", j + 1))
        .collect();
    println!("{}: valid", path.display());
    println!("  bus: {bus}, {}", s.bus.timing().describe());
    println!(
        "  cycle: {} Hz, worst-case bus load {:.1} % (limit {:.1} %)",
        s.rate_hz,
        s.bus_load * 100.0,
        s.bus.max_load * 100.0
    );
    println!(
        "  model: {} ({})",
        s.model_path.display(),
        if stiff.is_empty() {
            "rigid joints: no compensation".to_string()
        } else {
            format!("compensating {}", stiff.join(", "))
        }
    );
    println!(
        "  torques from: {:?}; payload {} N",
        s.control.torque_source, s.control.payload_n
    );
    println!("  api: {} (mode {:o})", s.api.socket.display(), s.api.mode);
    Ok(())
}

fn run(path: &Path) -> Result<()> {
    let loaded = Config::load(path)?;
    let filter = tracing_subscriber::EnvFilter::try_new(&loaded.log_level).context("log_level")?;
    // Lines go to stderr through a writer thread: the control thread never waits on the
    // stderr lock a client's log line holds (a priority inversion, as on the core's lock);
    // when the writer falls 128 000 lines behind, lines are dropped rather than waited for.
    let (stderr, _flush_on_exit) = tracing_appender::non_blocking(std::io::stderr());
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(stderr)
        .init();
    tracing::info!(
        config = %path.display(),
        rate_hz = loaded.rate_hz,
        bus = %loaded.bus.timing().describe(),
        bus_load_pct = loaded.bus_load * 100.0,
        "starting"
    );
    // One daemon per socket: claimed before the bus is touched.
    let _claim = pa10::daemon::api::SocketLock::claim(&loaded.api.socket)
        .map_err(anyhow::Error::msg)
        .context("claiming the API socket")?;
    // The simulated arm (virtual backend) lives as long as the daemon runs on it.
    let (mut daemon, _arm) = match loaded.bus.backend {
        Backend::Virtual => {
            let arm = SimulatedArm::from_config(&loaded).context("the simulated arm")?;
            let d = Daemon::start(&loaded, arm.host()).context("starting the control loop")?;
            (d, Some(arm))
        }
        Backend::Socketcan => {
            #[cfg(target_os = "linux")]
            {
                let iface = loaded.bus.interface.clone().unwrap_or_default();
                let framing = loaded.bus.timing().framing;
                let bus = pa10::can::socketcan_bus::SocketCanBus::open_with(&iface, framing)
                    .with_context(|| format!("opening {iface}"))?;
                let d = Daemon::start(&loaded, bus).context("starting the control loop")?;
                (d, None)
            }
            #[cfg(not(target_os = "linux"))]
            anyhow::bail!("SocketCAN needs Linux")
        }
    };
    let shared = daemon.core.clone();
    tracing::info!("servo controller in control mode");
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("API runtime")?;
    let socket = loaded.api.socket.clone();
    let mode = loaded.api.mode;
    let result = rt.block_on(async move {
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let api_shared = shared.clone();
        let health = std::sync::Arc::new(pa10::daemon::api::ApiHealth::default());
        let api_health = health.clone();
        let max_clients = loaded.api.max_clients;
        let live_stop = stop_rx.clone();
        let mut api = tokio::spawn(async move {
            pa10::daemon::api::serve(&socket, mode, max_clients, api_shared, api_health, stop_rx)
                .await
        });
        let live = &loaded.live;
        if live.enabled {
            // the live view: loopback only, off by default (docs/recording.md)
            let addr = std::net::SocketAddr::from(([127, 0, 0, 1], live.port));
            match tokio::net::TcpListener::bind(addr).await {
                Ok(l) => {
                    tracing::info!(%addr, "live view (Foxglove WebSocket) listening");
                    tokio::spawn(pa10::daemon::live::serve(
                        l,
                        shared.clone(),
                        live.rate_hz,
                        live_stop,
                    ));
                }
                Err(e) => tracing::error!(%addr, error = %e, "live view: cannot listen; running without it"),
            }
        }
        if loaded.record.autostart {
            use pa10::daemon::wire::{Answer, ApiRequest, Reply};
            let start = ApiRequest::RecordStart {
                file: None,
                duration_s: None,
            };
            match pa10::daemon::api::handle(&shared, start) {
                Reply::Ok(Answer::Recording { path }) => {
                    tracing::info!(%path, "recording every cycle (record.autostart)")
                }
                Reply::Refused(error) => {
                    tracing::error!(%error, "record.autostart: recording did not start")
                }
                Reply::Ok(other) => {
                    tracing::error!(?other, "record.autostart: an unexpected answer")
                }
            }
        }
        let _ = sd_notify::notify(&[
            NotifyState::Ready,
            NotifyState::Status("control loop running"),
        ]);
        // systemd watchdog: ping only while the loop advances and the API accepts clients
        let wd = sd_notify::watchdog_enabled();
        let mut last_cycles = 0u64;
        let mut tick = tokio::time::interval(wd.map(|d| d / 2).unwrap_or(Duration::from_secs(1)));
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .context("SIGTERM handler")?;
        loop {
            tokio::select! {
                _ = tick.tick() => {
                    let st = lock(&shared).status();
                    let progressed = st.cycle.cycles > last_cycles;
                    last_cycles = st.cycle.cycles;
                    let api_ok = !health.accept_failing.load(std::sync::atomic::Ordering::Relaxed);
                    if wd.is_some() && progressed && api_ok {
                        let _ = sd_notify::notify(&[NotifyState::Watchdog]);
                    }
                    let clients = health.clients.load(std::sync::atomic::Ordering::Relaxed);
                    let _ = sd_notify::notify(&[NotifyState::Status(&format!(
                        "{} ({} cycles, {clients} clients{})",
                        st.state,
                        st.cycle.cycles,
                        if api_ok { "" } else { ", API failing to accept" }
                    ))]);
                    if !progressed && last_cycles > 0 {
                        tracing::error!("control loop stalled");
                    }
                }
                r = &mut api => {
                    // the API ended without being asked: nothing can reach the arm any more,
                    // so stop it and exit with the reason (systemd restarts the service)
                    let why = match r {
                        Ok(Ok(())) => "the API server ended".to_string(),
                        Ok(Err(e)) => format!("the API server failed: {e}"),
                        Err(e) => format!("the API task failed: {e}"),
                    };
                    tracing::error!(reason = %why, "stopping the arm");
                    return Err(anyhow::anyhow!(why));
                }
                _ = tokio::signal::ctrl_c() => break,
                _ = term.recv() => break,
            }
        }
        tracing::info!("signal received: stopping the arm");
        let _ = sd_notify::notify(&[NotifyState::Stopping]);
        let _ = stop_tx.send(true);
        let _ = api.await;
        anyhow::Ok(())
    });
    daemon.shutdown();
    // a recording in progress is closed whole (its summary written) before the process ends
    let rec = lock(&daemon.core).stop_recording();
    if let Some(stats) = rec {
        stats.wait_finished(Duration::from_secs(10));
        tracing::info!(status = ?stats.status(false), "recording closed");
    }
    tracing::info!("stopped");
    result
}
