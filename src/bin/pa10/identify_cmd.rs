//! `pa10 identify`: sweep the arm through the daemon at constant speeds, both ways, and
//! identify the gravity model (bodies) and every joint's friction from the currents
//! (`pa10::calib::identify`); write them into a model file.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use pa10::calib::identify::{self, SweepPlan};
use pa10::calib::torque_check;
use pa10::daemon::api::sweep;

use crate::client_cmd::{Api, AsSession, Conn, Simulated, Socket};
use crate::collect_cmd::set_payload;
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
    /// Check the torque constants against a known weight of this many newtons: the tour is
    /// driven again with it hung at the tool point (the simulation hangs it; on a real arm
    /// you are asked to) and the daemon told the payload (`pa10::calib::torque_check`).
    #[arg(long, value_name = "N")]
    known_weight: Option<f64>,
    /// With `--known-weight`: where the weight hangs, flange → tool point as X Y Z (m) QW QX
    /// QY QZ, replacing the model's tool (a model without a tool needs it: the weight's lever
    /// is the check's scale).
    #[arg(
        long,
        num_args = 7,
        allow_negative_numbers = true,
        value_name = "X Y Z QW QX QY QZ"
    )]
    tool: Option<Vec<f64>>,
}

/// `pa10 identify`.
pub fn identify_cmd(a: &IdentifyArgs) -> Result<()> {
    let mut model = a.model.load()?;
    if let Some(t) = &a.tool {
        anyhow::ensure!(
            a.known_weight.is_some(),
            "--tool is the known weight's point: give --known-weight too"
        );
        model = model.with_tool(&crate::model_cmds::pose_arg("--tool", t)?)?;
    } else if a.known_weight.is_some() && model.tool().translation.vector.norm() == 0.0 {
        bail!(
            "--known-weight: the model has no tool (its tool point is the flange); say where the weight hangs with --tool X Y Z QW QX QY QZ (--tool 0 0 0 1 0 0 0 for the flange)"
        );
    }
    sweep::check_speeds(&a.speeds).context("--speeds")?;
    if let Some(n) = a.known_weight {
        torque_check::check_weight(n).context("--known-weight")?;
    }
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
    let spin = crate::progress::spinner(
        "identifying: sweeping the tour through the daemon",
        a.conn.json,
    );
    let run = sweep::identify_through(&mut AsSession(api.as_mut()), &model, &kt, &plan, &a.speeds);
    spin.finish_and_clear();
    let run = run?;
    let (tour, samples, id, out) = (&run.tour, &run.samples, &run.identified, &run.model);
    let kt_check = match a.known_weight {
        Some(n) => {
            api.hang_weight(n)?;
            set_payload(api.as_mut(), n)?;
            let spin = crate::progress::spinner(
                "checking the torque constants: the tour again, loaded",
                a.conn.json,
            );
            let loaded = sweep::gather(&mut AsSession(api.as_mut()), tour, &a.speeds);
            spin.finish_and_clear();
            api.hang_weight(0.0)?;
            set_payload(api.as_mut(), 0.0)?;
            let with = identify::samples(&loaded?.polls, &kt, sweep::MIN_SAMPLE_SPEED);
            Some(torque_check::check(&model, samples, &with, n)?)
        }
        None => None,
    };
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
            "torque_constant_check": kt_check.as_ref().map(|c| serde_json::json!({
                "known_weight_n": a.known_weight,
                "configured": kt,
                "ratio": c.ratio.map(finite),
                "ratio_sigma": c.ratio_sigma.map(finite),
                "weight_torque_rms_nm": c.weight_torque_rms_nm,
                "seen": std::array::from_fn::<bool, 6, _>(|j| c.seen(j)),
                "off": std::array::from_fn::<bool, 6, _>(|j| c.off(j)),
                "corrected": c.corrected(&kt),
            })),
        });
        println!("{v}");
        return Ok(());
    }
    println!(
        "pa10 identify: {} constant-speed samples from {} sweeps ({} polls); wrote {}",
        samples.len(),
        2 * (tour.len() - 1),
        run.polls,
        a.out.display()
    );
    println!(
        "\n| joint | Coulomb [N·m] | viscous [N·m·s/rad] | breakaway [N·m] | residual RMS [N·m] | rows |"
    );
    println!("|---|---|---|---|---|---|");
    for j in 0..6 {
        let f = id.friction[j];
        let s = f.sigma.unwrap_or([0.0; 2]);
        println!(
            "| J{} | {:.2} ± {:.2} | {:.2} ± {:.2} | {} | {:.2} | {} |",
            j + 1,
            f.coulomb,
            s[0],
            f.viscous,
            s[1],
            out.data().friction[j]
                .and_then(|f| f.breakaway)
                .map_or_else(|| "—".to_string(), |b| format!("{b:.2}")),
            id.residual_rms[j],
            id.rows[j]
        );
    }
    if let Some(c) = &kt_check {
        print_check(c, &kt, a.known_weight.unwrap_or_default());
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

/// A ratio as JSON can carry it (an unseen joint's infinite σ as `null`).
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn print_check(c: &torque_check::TorqueConstantCheck, kt: &[f64; 6], newtons: f64) {
    println!(
        "\ntorque constants against a known {newtons} N weight (ratio = configured ÷ measured; 1 is right; \
         within {:.0} % the model's geometry cannot tell):",
        torque_check::RATIO_TOLERANCE * 100.0
    );
    println!(
        "\n| joint | configured [N·m/A] | ratio | measured [N·m/A] | weight's torque RMS [N·m] |"
    );
    println!("|---|---|---|---|---|");
    let fixed = c.corrected(kt);
    for j in 0..6 {
        if c.seen(j) {
            println!(
                "| J{} | {:.3} | {:.4} ± {:.4} | {:.3} | {:.1} |",
                j + 1,
                kt[j],
                c.ratio[j],
                c.ratio_sigma[j],
                fixed[j],
                c.weight_torque_rms_nm[j]
            );
        } else {
            println!(
                "| J{} | {:.3} | not seen (the weight loads this joint too little on this tour) | — | {:.1} |",
                j + 1,
                kt[j],
                c.weight_torque_rms_nm[j]
            );
        }
    }
    if (0..6).any(|j| c.off(j)) {
        println!(
            "\nthe configuration's torque_constants should read: [{}]",
            fixed.map(|k| format!("{k:.3}")).join(", ")
        );
    }
}
