//! `pa10 discover` and `pa10 sim discovery`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use pa10::discover::effects::Kind;
use pa10::discover::{DiscoverOptions, Discovery, discover};
use pa10::sim::experiment::{DiscoverySpec, discovery_campaign, paper_model, scenarios};

use crate::calib_cmd::load;
use crate::model_cmds::ModelArg;

/// Arguments of `pa10 discover`.
#[derive(Debug, Args)]
pub struct DiscoverArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Measurements (CSV; a `.meta.yaml` sidecar beside it is read). Repeats of a
    /// configuration give the noise floor; `dir1..dir6` and `temp_c` columns let
    /// direction- and temperature-dependent effects show.
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Held-out measurements from the same instrument set-up (other configurations); k-fold
    /// cross-validation by configuration when absent.
    #[arg(long, value_name = "FILE")]
    holdout: Option<PathBuf>,
    /// Write the extended model (a model file `pa10d` loads) here.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Write residual plots against each found effect's regressor (SVG) and the JSON here.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Folds of the cross-validation by configuration (without `--holdout`).
    #[arg(long, default_value_t = 5)]
    folds: usize,
    /// Significance level of every test.
    #[arg(long, default_value_t = 0.01)]
    alpha: f64,
    /// Largest number of effects to add.
    #[arg(long, default_value_t = 8)]
    max_effects: usize,
    /// Wave-generator revolutions per output revolution for transmission-error candidates.
    #[arg(long, default_value_t = pa10::model::DEFAULT_GEAR_RATIO)]
    gear_ratio: f64,
    /// Resolver error per joint (1σ), arcmin (default: the sidecar's, else 0.64).
    #[arg(long)]
    resolver_arcmin: Option<f64>,
    /// Motor current → joint torque constants, N·m/A, six comma-separated (for `i1..i6` data).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    torque_constants: Option<Vec<f64>>,
    /// Joint torques from the start model's statics (its bodies and each row's hung load at
    /// the row's link angles under its springs) instead of the data's torque or current columns, in both
    /// sets: as `pa10 calibrate --model-torques`, for data gathered on drives whose currents
    /// at rest carry held friction (docs/judge.md).
    #[arg(long)]
    model_torques: bool,
    /// Consider only these kinds of effect (comma-separated machine names).
    #[arg(long, value_delimiter = ',')]
    only: Option<Vec<String>>,
}

/// `pa10 discover`.
pub fn run(a: &DiscoverArgs) -> Result<()> {
    let model = a.model.load()?;
    let mut data = load(&a.data)?;
    let mut holdout = a.holdout.as_deref().map(load).transpose()?;
    if a.model_torques {
        data = data
            .with_model_torques(&model)
            .with_context(|| format!("--model-torques on {}", a.data.display()))?;
        holdout = holdout
            .map(|h| h.with_model_torques(&model))
            .transpose()
            .context("--model-torques on --holdout")?;
    }
    let torque_constants = crate::calib_cmd::torque_constants(&a.torque_constants)?;
    let only = match &a.only {
        None => None,
        Some(names) => Some(
            names
                .iter()
                .map(|n| {
                    Kind::from_name(n.trim()).ok_or_else(|| {
                        let all: Vec<&str> = Kind::ALL.iter().map(|k| k.name()).collect();
                        anyhow::anyhow!("--only: unknown effect `{n}`; known: {}", all.join(", "))
                    })
                })
                .collect::<Result<Vec<_>>>()?,
        ),
    };
    let opts = DiscoverOptions {
        folds: a.folds,
        alpha: a.alpha,
        max_effects: a.max_effects,
        gear_ratio: a.gear_ratio,
        resolver_arcmin: a.resolver_arcmin,
        torque_constants,
        only,
        ..Default::default()
    };
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let spin = crate::progress::spinner(
        "discovering: every candidate effect refitted and cross-validated",
        a.json,
    );
    let d = discover(&model, &data, holdout.as_ref(), &opts);
    spin.finish_and_clear();
    let d = d?;
    if let Some(out) = &a.out {
        d.model
            .save(out)
            .with_context(|| format!("writing {}", out.display()))?;
    }
    if let Some(dir) = &a.report {
        report(dir, &d)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&d)?);
    } else {
        print(&d, a.out.as_deref());
    }
    Ok(())
}

fn report(dir: &Path, d: &Discovery) -> Result<()> {
    std::fs::write(dir.join("discovery.json"), serde_json::to_string_pretty(d)?)
        .with_context(|| "writing discovery.json")?;
    for (k, ev) in d.evidence.iter().enumerate() {
        let before: Vec<(f64, f64)> = ev.points.iter().map(|p| (p.0, p.1)).collect();
        let after: Vec<(f64, f64)> = ev.points.iter().map(|p| (p.0, p.2)).collect();
        let name = format!(
            "effect{}-{}.svg",
            k + 1,
            ev.label.replace(['[', ']', ' '], "_").trim_end_matches('_')
        );
        pa10::plot::series(
            &dir.join(&name),
            &format!(
                "{}: residual along its signature, before and after",
                ev.label
            ),
            &ev.regressor,
            "residual (mm)",
            &[("before".to_string(), before), ("after".to_string(), after)],
        )?;
    }
    Ok(())
}

fn print(d: &Discovery, out: Option<&Path>) {
    let n = &d.noise_after;
    println!("{}", n.model.summary());
    if let Some(a) = &n.model.assumption {
        println!("  assumed: {a}");
    }
    println!(
        "  weights and floor use a repeatable resolver error of {:.2} arcmin (the estimate, at most the resolver's specified σ)",
        n.repeatable_used_rad / pa10::accuracy::ARCMIN
    );
    let l = &d.lack_of_fit_before;
    println!(
        "starting model: lack of fit between configurations χ²/dof {:.2} ({:.0} dof, p {:.1e}), within {:.2} ({:.0} dof, p {:.1e}) → {}",
        l.between.ratio,
        l.between.dof,
        l.between.p_value,
        l.within.ratio,
        l.within.dof,
        l.within.p_value,
        if d.significant_gap_before {
            "something is missing"
        } else {
            "nothing significant is missing"
        }
    );
    println!("held-out by {}", d.heldout);
    println!();
    if d.steps.is_empty() {
        println!("no candidate tried: the model already fits to the noise floor");
    } else {
        println!(
            "{:>4} {:>34} {:>4} {:>10} {:>9} {:>9} {:>8}  result",
            "step", "candidate", "k", "Δχ²", "ΔBIC", "p (adj)", "t"
        );
    }
    for s in &d.steps {
        if s.generic && s.step > 1 && !d.steps[s.step - 2].generic {
            println!(
                "     — no library effect passes while the data still show unexplained variance: searching generic terms per joint (q², q³, sin/cos of q and 2q, approach direction) —"
            );
        }
        if s.completion && (s.step == 1 || !d.steps[s.step - 2].completion) {
            println!(
                "     — the held-out data reach torques beyond the training data: springs without their cubic term completed on the held-out data (Δχ², ΔBIC, p: training, not required) —"
            );
        }
        for c in s.candidates.iter().filter(|c| c.identifiable > 0).take(5) {
            println!(
                "{:>4} {:>34} {:>4} {:>10.1} {:>9.1} {:>9.1e} {:>8}  {}",
                s.step,
                c.label,
                c.identifiable,
                c.delta_chi2,
                c.delta_bic,
                c.p_adjusted,
                c.paired_t.map_or("-".to_string(), |t| format!("{t:.2}")),
                c.note
            );
        }
    }
    for s in &d.steps {
        if let Some(c) = &s.choice {
            println!("\nstep {}: {c}", s.step);
        }
        if let (Some(a), false) = (&s.accepted, s.look_alikes.is_empty()) {
            let l: Vec<String> = s
                .look_alikes
                .iter()
                .map(|(n, r)| format!("{n} (r = {r:.3})"))
                .collect();
            println!(
                "\nstep {}: on these poses {a} shares a direction with {} (r: largest canonical correlation beyond the model); the data cannot tell those parts apart (docs/discovery.md)",
                s.step,
                l.join(", ")
            );
        }
    }
    if !d.not_identifiable.is_empty() {
        println!(
            "\nnot identifiable from these poses (absorbed by the model): {}",
            d.not_identifiable.join(", ")
        );
    }
    for p in &d.pruned {
        println!("\nremoved at the end: {p}");
    }
    if !d.held.is_empty() {
        println!(
            "\nheld at their start values (these data cannot determine them): {}",
            d.held.join("; ")
        );
    }
    for f in &d.findings {
        println!("\nfinding: {f}");
    }
    println!();
    if d.effects.is_empty() {
        println!("named: nothing");
    }
    for e in &d.effects {
        println!(
            "{}: {} — {} (held-out gain {:.3} mm{})",
            if e.form.is_some() {
                "localised (unnamed)"
            } else {
                "named"
            },
            e.label,
            e.form.as_deref().unwrap_or(e.description),
            e.gain_mm,
            if e.run_time {
                ", compensated by pa10d"
            } else {
                ", not compensated at run time"
            }
        );
        for (k, v) in &e.params {
            println!(
                "    {k} = {v:.4e} ± {:.1e} {}",
                e.stderr.get(k).copied().unwrap_or(f64::NAN),
                e.units.get(k).copied().unwrap_or("")
            );
        }
    }
    println!(
        "\nRMS position error, mm: held-out {:.3} → {:.3}, training {:.3} → {:.3}; noise floor {:.3} ({:.2}×)",
        d.gap_before_mm,
        d.gap_after_mm,
        d.train_gap_before_mm,
        d.train_gap_after_mm,
        d.noise_floor_mm,
        d.gap_after_mm / d.noise_floor_mm
    );
    println!("{}", d.verdict);
    if let Some(o) = out {
        println!("extended model written to {}", o.display());
    }
}

/// Arguments of `pa10 sim discovery`.
#[derive(Debug, Args)]
pub struct SimDiscoveryArgs {
    /// A named scenario (what is hidden): none, cubic-j2, compliance-j4, transmission-j3,
    /// backlash-j1, thermal-forearm, j4-and-backlash.
    #[arg(long, default_value = "none")]
    scenario: String,
    /// Seed of the hidden truth and of every measurement.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of configurations of the training set (the holdout set has a third as many).
    #[arg(long, default_value_t = 60)]
    configs: usize,
    /// Output directory: cal.csv, holdout.csv (with sidecars), start.yaml (the model to
    /// start from) and truth.yaml (hidden).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// `pa10 sim discovery`.
pub fn sim(a: &SimDiscoveryArgs) -> Result<()> {
    let all = scenarios();
    let Some(sc) = all.iter().find(|s| s.name == a.scenario) else {
        let names: Vec<&str> = all.iter().map(|s| s.name).collect();
        bail!(
            "--scenario: unknown `{}`; known: {}",
            a.scenario,
            names.join(", ")
        );
    };
    let spec = DiscoverySpec {
        seed: a.seed,
        configs: a.configs,
        hidden: sc.hidden.clone(),
        ..Default::default()
    };
    let cal = discovery_campaign(&spec)?;
    let hold = discovery_campaign(&DiscoverySpec {
        pose_seed: 1,
        configs: (a.configs / 3).max(8),
        ..spec
    })?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    cal.data.save(a.out.join("cal.csv"))?;
    hold.data.save(a.out.join("holdout.csv"))?;
    paper_model(sc.linear_only)?.save(a.out.join("start.yaml"))?;
    let x = &cal.truth.extras;
    let truth = format!(
        "# HIDDEN TRUTH of the simulated robot (pa10 sim discovery --scenario {} --seed {}): {}.\n# Discovery never reads this file.\n# Not expressible in a model file: thermal expansion per DH row (1/K, T_ref {} °C) {:?}, bending per DH row (rad/(N·m)) {:?}\n{}",
        sc.name,
        a.seed,
        sc.description,
        x.t_ref_c,
        x.thermal,
        x.bending,
        cal.truth.model.to_yaml()
    );
    std::fs::write(a.out.join("truth.yaml"), truth).with_context(|| "writing truth.yaml")?;
    println!(
        "wrote {}: cal.csv ({} rows), holdout.csv ({} rows), sidecars, start.yaml, truth.yaml (hidden: {})",
        a.out.display(),
        cal.data.rows.len(),
        hold.data.rows.len(),
        sc.description
    );
    Ok(())
}
