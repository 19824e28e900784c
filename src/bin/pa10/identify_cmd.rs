//! `pa10 identify`: sweep the arm through the daemon at constant speeds, both ways, and
//! identify the gravity model (bodies) and every joint's friction from the currents
//! (`pa10::calib::identify`); write them into a model file.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use pa10::calib::identify::{self, SweepPlan};
use pa10::daemon::api::sweep::{self, Session};
use pa10::daemon::wire::{ApiRequest, Reply};

use crate::client_cmd::{Api, Conn, Simulated, Socket, status_of};
use crate::model_cmds::ModelArg;

/// Arguments of `pa10 identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    #[command(flatten)]
    conn: Conn,
    #[command(flatten)]
    model: ModelArg,
    /// Where to write the model with the identified bodies and friction (YAML).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Waypoints of the sweep tour (each segment driven there and back at one speed, the
    /// segments at the speeds in turn).
    #[arg(long, default_value_t = 10)]
    waypoints: usize,
    /// The two sweep speeds of the fastest joint, rad/s.
    #[arg(long, value_delimiter = ',', default_value = "0.15,0.3")]
    speeds: Vec<f64>,
    /// Fraction of each joint's range kept clear at both ends.
    #[arg(long, default_value_t = 0.25)]
    margin: f64,
    /// Lowest tool height (base frame z) allowed on the tour, m.
    #[arg(long, default_value_t = 0.3)]
    floor_z: f64,
    /// Seed of the tour.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Motor current → joint torque constants, N·m/A, six comma-separated (default with
    /// `--simulate`: the configuration's).
    #[arg(long, value_delimiter = ',')]
    torque_constants: Option<Vec<f64>>,
    /// No daemon to connect to: the daemon's core and the simulated arm of this configuration
    /// (its `sim` section, `sim.plant` included) in simulated time in this process.
    #[arg(long, value_name = "CONFIG")]
    simulate: Option<PathBuf>,
}

/// A `pa10` client connection as a sweep's session.
struct AsSession<'a>(&'a mut dyn Api);

impl Session for AsSession<'_> {
    fn send(&mut self, req: ApiRequest) -> std::result::Result<Reply, String> {
        self.0.send(req).map_err(|e| format!("{e:#}"))
    }
    fn pause(&mut self, seconds: f64) {
        self.0.pause(Duration::from_secs_f64(seconds));
    }
    fn clock_s(&self) -> f64 {
        self.0.clock_s()
    }
}

/// `pa10 identify`.
pub fn identify_cmd(a: &IdentifyArgs) -> Result<()> {
    let model = a.model.load()?;
    sweep::check_speeds(&a.speeds).context("--speeds")?;
    let plan = SweepPlan {
        waypoints: a.waypoints,
        margin: a.margin,
        floor_z: a.floor_z,
        seed: a.seed,
        ..SweepPlan::default()
    };
    let kt_arg = crate::calib_cmd::torque_constants(&a.torque_constants)?;
    let (mut api, kt): (Box<dyn Api>, [f64; 6]) = match &a.simulate {
        Some(config) => {
            let settings = pa10::daemon::config::Config::load(config)
                .with_context(|| format!("loading {}", config.display()))?;
            let mut ls = pa10::sim::rig::Lockstep::from_config(&settings)?;
            ls.run_until_ready(5.0)
                .map_err(|e| anyhow::anyhow!("the simulated servo controller: {e}"))?;
            let kt = kt_arg.unwrap_or(settings.control.torque_constants);
            (Box::new(Simulated(ls)), kt)
        }
        None => match kt_arg {
            Some(kt) => (Box::new(Socket(a.conn.clone())), kt),
            None => bail!(
                "--torque-constants: the daemon's six N·m/A (its configuration's torque_constants)"
            ),
        },
    };
    let start = status_of(api.as_mut())?.setpoint;
    let tour = identify::plan_sweep(&model, &start, &plan)?;
    let polls = sweep::gather(&mut AsSession(api.as_mut()), &tour, &a.speeds)?;
    let samples = identify::samples(&polls, &kt, sweep::MIN_SAMPLE_SPEED);
    let id = identify::identify(&model, &samples)?;
    let out = id.apply(&model)?;
    out.save(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    if a.conn.json {
        let v = serde_json::json!({
            "samples": samples.len(),
            "rows": id.rows,
            "residual_rms_nm": id.residual_rms,
            "friction": out.data().friction,
            "bodies": out.data().bodies,
            "out": a.out,
        });
        println!("{v}");
        return Ok(());
    }
    println!(
        "pa10 identify: {} constant-speed samples from {} sweeps ({} polls); wrote {}",
        samples.len(),
        2 * (tour.len() - 1),
        polls.len(),
        a.out.display()
    );
    println!("\n| joint | Coulomb [N·m] | viscous [N·m·s/rad] | residual RMS [N·m] | rows |");
    println!("|---|---|---|---|---|");
    for j in 0..6 {
        let f = id.friction[j];
        let s = f.sigma.unwrap_or([0.0; 2]);
        println!(
            "| J{} | {:.2} ± {:.2} | {:.2} ± {:.2} | {:.2} | {} |",
            j + 1,
            f.coulomb,
            s[0],
            f.viscous,
            s[1],
            id.residual_rms[j],
            id.rows[j]
        );
    }
    println!("\n| body | frame | mass [kg] | centre of mass [m] |");
    println!("|---|---|---|---|");
    for b in &out.data().bodies {
        let s = b
            .sigma
            .map_or([0.0; 4], |s| [s.mass, s.com[0], s.com[1], s.com[2]]);
        println!(
            "| {} | {} | {:.2} ± {:.2} | [{:+.3} ± {:.3}, {:+.3} ± {:.3}, {:+.3} ± {:.3}] |",
            b.name, b.frame, b.mass, s[0], b.com[0], s[1], b.com[1], s[2], b.com[2], s[3]
        );
    }
    Ok(())
}
