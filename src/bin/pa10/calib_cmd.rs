//! `pa10 calibrate`: load the data, fit, print and plot the report.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use pa10::calib::dataset::Dataset;
use pa10::calib::fit::{CalibOptions, Weighting, row_residual, settled_model_torques};
use pa10::calib::report::{self, ByLoad, Report};

use crate::model_cmds::ModelArg;

/// Row weighting choice on the command line.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum WeightingArg {
    /// From the noise the data show: reading noise, repeatable error, instrument and
    /// torque noise estimated from the repeats (default).
    Measured,
    /// Generalised least squares assuming a repeatable resolver error of the sidecar's σ.
    Gls,
    /// The paper's cost exactly.
    Paper,
}

/// Arguments of `pa10 calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Calibration dataset (CSV; a `.meta.yaml` sidecar beside it is read).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Straight-line moves along the robot's x and y axes (ids x0…, y0…) for the base-frame
    /// seed; without it the seed is a point fit.
    #[arg(long, value_name = "FILE")]
    base_seed: Option<PathBuf>,
    /// Validation dataset: configurations and loads outside the calibration set.
    #[arg(long, value_name = "FILE")]
    validate: Option<PathBuf>,
    /// Where to write the calibrated model (YAML).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Fit linear stiffness only (Kcub = 0).
    #[arg(long)]
    linear_only: bool,
    /// The paper's regularisation weight ε (it used 1.6e-4; see docs/calibration.md).
    #[arg(long, default_value_t = 0.0)]
    epsilon: f64,
    /// Row weighting.
    #[arg(long, value_enum, default_value = "measured")]
    weighting: WeightingArg,
    /// Number of starts (multi-start).
    #[arg(long, default_value_t = 4)]
    starts: usize,
    /// Seed of the random starts.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Inner-level configurations: `all` (every unloaded one) or a comma-separated id list;
    /// default: the sidecar's, else every unloaded one with the measured weighting and 8
    /// spread-out ones with the others.
    #[arg(long, value_name = "all|ID,…")]
    inner_configs: Option<String>,
    /// Motor current → joint torque constants, N·m/A, six comma-separated (for `i1..i6` data).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    torque_constants: Option<Vec<f64>>,
    /// Joint torques from the start model's statics (its bodies and each row's hung load, at
    /// the row's link angles: the resolvers' less the deflection, from a first fit's springs)
    /// instead of the data's torque or current columns: for a daemon that runs
    /// `torque_source: model`, so the springs are identified on the torques it will use and
    /// the currents' friction never enters the fit (docs/judge.md).
    #[arg(long)]
    model_torques: bool,
    /// Write residual plots (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
}

/// Loads a dataset (and its sidecar), naming the file in errors.
pub(crate) fn load(p: &Path) -> Result<Dataset> {
    Dataset::load(p).with_context(|| format!("loading {}", p.display()))
}

/// `--torque-constants` as six values, N·m/A.
pub(crate) fn torque_constants(v: &Option<Vec<f64>>) -> Result<Option<[f64; 6]>> {
    v.as_ref()
        .map(|v| {
            <[f64; 6]>::try_from(v.as_slice()).map_err(|_| {
                anyhow::anyhow!("--torque-constants takes six values, got {}", v.len())
            })
        })
        .transpose()
}

/// `pa10 calibrate`.
pub fn calibrate(a: &CalibrateArgs) -> Result<()> {
    let model = a.model.load()?;
    let mut data = load(&a.data)?;
    let lines = a.base_seed.as_deref().map(load).transpose()?;
    let mut val = a.validate.as_deref().map(load).transpose()?;
    let inner_configs = match a.inner_configs.as_deref() {
        None => None,
        Some("all") => {
            let mut ids: Vec<String> = data
                .rows
                .iter()
                .filter(|r| r.load_n == 0.0)
                .map(|r| r.config_id.clone())
                .collect();
            ids.dedup();
            ids.sort();
            ids.dedup();
            Some(ids)
        }
        Some(list) => Some(list.split(',').map(|s| s.trim().to_string()).collect()),
    };
    let torque_constants = torque_constants(&a.torque_constants)?;
    let opts = CalibOptions {
        epsilon: a.epsilon,
        linear_only: a.linear_only,
        starts: a.starts,
        seed: a.seed,
        inner_configs,
        torque_constants,
        weighting: match a.weighting {
            WeightingArg::Measured => Weighting::Measured,
            WeightingArg::Gls => Weighting::Gls,
            WeightingArg::Paper => Weighting::Paper,
        },
        ..Default::default()
    };
    if a.model_torques {
        let (d, placed) = settled_model_torques(&model, &data, lines.as_ref(), &opts)
            .with_context(|| format!("--model-torques on {}", a.data.display()))?;
        data = d;
        val = val
            .map(|v| v.with_model_torques(&placed))
            .transpose()
            .context("--model-torques on --validate")?;
    }
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bar = crate::progress::bar(opts.starts as u64, "starts", a.json);
    let outcome = report::run(&model, &data, lines.as_ref(), val.as_ref(), &opts, &|n| {
        bar.set_position(n as u64)
    })?;
    bar.finish_and_clear();
    if let Some(m) = &outcome.result.misfit {
        eprintln!("pa10: warning: {m}");
    }
    if let Some(m) = outcome
        .report
        .wrist
        .as_ref()
        .and_then(|w| w.warning.as_ref())
    {
        eprintln!("pa10: warning: {m}");
    }
    outcome
        .result
        .model
        .save(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    if let Some(dir) = &a.report {
        plots(dir, &outcome, &data, val.as_ref(), opts.r_max)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&outcome.report)?);
    } else {
        print_report(&outcome.report, &a.out)?;
    }
    Ok(())
}

fn sorted(m: &ByLoad) -> Vec<&pa10::calib::fit::ErrorSummary> {
    let mut v: Vec<_> = m.values().collect();
    v.sort_by(|a, b| a.load_n.total_cmp(&b.load_n));
    v
}

fn print_report(r: &Report, out: &Path) -> Result<()> {
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "calibration: {} rows, {} configurations, {} starts, weighting {:?}, ε = {}{} ({:.2} s)",
        r.rows,
        r.configurations,
        r.start_costs.len(),
        r.weighting,
        r.epsilon,
        if r.linear_only {
            ", linear stiffness only"
        } else {
            ""
        },
        r.elapsed_s
    )?;
    if let Some(n) = &r.noise {
        writeln!(o, "{}", n.summary())?;
        if let Some(a) = &n.assumption {
            writeln!(o, "  assumed: {a}")?;
        }
        writeln!(
            o,
            "  weights: {}",
            if n.structure.shares_offsets() {
                "GLS with the repeatable error the configuration means show"
            } else {
                "per row (no repeatable error shows between configurations)"
            }
        )?;
    }
    writeln!(
        o,
        "\ncalibration set      before (nominal)                 after"
    )?;
    writeln!(
        o,
        "  load [N]  rows   mean / peak [mm]  orient [deg]   mean / peak [mm]  orient [deg]"
    )?;
    for (b, a) in sorted(&r.before).iter().zip(sorted(&r.after)) {
        writeln!(
            o,
            "  {:8.1}  {:4}   {:6.3} / {:6.3}   {:8.4}       {:6.3} / {:6.3}   {:8.4}",
            b.load_n,
            b.rows,
            b.mean_mm,
            b.peak_mm,
            b.mean_orient_deg,
            a.mean_mm,
            a.peak_mm,
            a.mean_orient_deg
        )?;
    }
    if let Some(v) = &r.validation {
        writeln!(
            o,
            "\nvalidation set       nominal            linear stiffness    full model          resolver floor"
        )?;
        writeln!(
            o,
            "  load [N]  rows   mean / peak [mm]   mean / peak [mm]    mean / peak [mm]    mean [mm]"
        )?;
        for ((b, l), a) in sorted(&v.before)
            .iter()
            .zip(sorted(&v.linear))
            .zip(sorted(&v.after))
        {
            let floor = v
                .floor_mm
                .get(&format!("{}", a.load_n))
                .copied()
                .unwrap_or(f64::NAN);
            writeln!(
                o,
                "  {:8.1}  {:4}   {:6.3} / {:6.3}    {:6.3} / {:6.3}     {:6.3} / {:6.3}     {:6.3}",
                b.load_n,
                b.rows,
                b.mean_mm,
                b.peak_mm,
                l.mean_mm,
                l.peak_mm,
                a.mean_mm,
                a.peak_mm,
                floor
            )?;
        }
    }
    writeln!(o, "\nidentified parameters (± standard error)")?;
    for p in &r.params {
        let (scale, unit) = match p.unit.as_str() {
            "m" => (1e3, "mm"),
            "rad" => (1e3, "mrad"),
            u => (1.0, u),
        };
        match p.std_error {
            Some(se) => writeln!(
                o,
                "  {:8} {:+12.5e} ± {:10.3e} {unit}",
                p.name,
                p.value * scale,
                se * scale
            )?,
            None => writeln!(
                o,
                "  {:8} {:+12.5e}   (fixed)    {unit}",
                p.name,
                p.value * scale
            )?,
        }
    }
    let sv = &r.singular_values;
    writeln!(
        o,
        "\nidentification Jacobian (scaled): {} singular values, largest {:.3e}, smallest {:.3e}; {} structurally null; condition number of the rest {:.3e}",
        sv.len(),
        sv.first().copied().unwrap_or(0.0),
        sv.last().copied().unwrap_or(0.0),
        r.null_directions,
        r.condition_number
    )?;
    if !r.weak.is_empty() {
        writeln!(
            o,
            "warning: {} parameter combination(s) cannot be identified from this data; they were held near nominal/seed:",
            r.weak.len()
        )?;
        for w in &r.weak {
            let names: Vec<String> = w
                .params
                .iter()
                .map(|(n, l)| format!("{n} ({l:+.2})"))
                .collect();
            writeln!(
                o,
                "  std error {:7.2} (tolerances / log-units): {}",
                w.std_error,
                names.join(", ")
            )?;
        }
    }
    if let Some(m) = &r.misfit {
        writeln!(o, "\nwarning: {m}")?;
    }
    if let Some(w) = &r.wrist {
        writeln!(
            o,
            "\npredicted tool position 1σ without load (median): {:.3} mm at the campaign's configurations, {:.3} mm at the same poses with the other wrist ({} of them)",
            w.sigma_mm, w.other_wrist_sigma_mm, w.twins
        )?;
        if let Some(m) = &w.warning {
            writeln!(o, "warning: {m}")?;
        }
    }
    writeln!(o, "\nwrote {}", out.display())?;
    Ok(())
}

fn plots(
    dir: &Path,
    outcome: &report::Outcome,
    data: &Dataset,
    val: Option<&Dataset>,
    r_max: f64,
) -> Result<()> {
    let per_config = |model: &pa10::model::Model, d: &Dataset| -> Vec<(String, Vec<(f64, f64)>)> {
        let mut ids: Vec<&str> = Vec::new();
        let mut series: Vec<(String, Vec<(f64, f64)>)> = d
            .loads()
            .iter()
            .map(|l| (format!("{l} N"), Vec::new()))
            .collect();
        for r in &d.rows {
            let k = ids
                .iter()
                .position(|i| *i == r.config_id)
                .unwrap_or_else(|| {
                    ids.push(&r.config_id);
                    ids.len() - 1
                });
            let tau = match r.effort {
                pa10::calib::dataset::Effort::Torque(t) => t,
                pa10::calib::dataset::Effort::Current(_) => [0.0; 6],
            };
            let e = row_residual(model, &r.q, &tau, r.load_n, &r.pose, r_max)
                .fixed_rows::<3>(0)
                .norm()
                * r_max
                * 1e3;
            if let Some(s) = d.loads().iter().position(|l| *l == r.load_n) {
                series[s].1.push((k as f64, e));
            }
        }
        series
    };
    for (name, title, model, d) in [
        (
            "residuals-before.svg",
            "position error before calibration (nominal model), per configuration",
            &outcome.before_model,
            Some(data),
        ),
        (
            "residuals-after.svg",
            "position error after calibration, per configuration",
            &outcome.result.model,
            Some(data),
        ),
        (
            "validation-after.svg",
            "validation: position error of the calibrated model, per configuration",
            &outcome.result.model,
            val,
        ),
    ] {
        if let Some(d) = d {
            pa10::plot::series(
                &dir.join(name),
                title,
                "configuration (order of appearance)",
                "position error [mm]",
                &per_config(model, d),
            )?;
        }
    }
    Ok(())
}
