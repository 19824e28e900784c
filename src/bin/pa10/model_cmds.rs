//! `pa10 fk`, `pa10 ik`, `pa10 model check`: the model from the command line.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use pa10::model::{ExternalLoad, Model, NO_DIRECTION, Torques, frame_from_pose, pose_parts};

/// Where the model comes from.
#[derive(Debug, Args)]
pub struct ModelArg {
    /// Model file (YAML); the compiled-in nominal PA10-6C model when absent.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
}

/// A pose given on the command line as X Y Z (m) QW QX QY QZ; `flag` names it in errors.
pub fn pose_arg(flag: &str, t: &[f64]) -> Result<pa10::model::Frame> {
    let [x, y, z, qw, qx, qy, qz] = <[f64; 7]>::try_from(t).map_err(|_| {
        anyhow::anyhow!("{flag} takes X Y Z QW QX QY QZ (7 values), got {}", t.len())
    })?;
    let n = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
    anyhow::ensure!(
        t.iter().all(|v| v.is_finite()) && (n - 1.0).abs() < 1e-6,
        "{flag}: X Y Z in metres and a unit quaternion QW QX QY QZ; its norm is {n}"
    );
    Ok(frame_from_pose([x, y, z], [qw, qx, qy, qz]))
}

/// `--tool X Y Z QW QX QY QZ` (flange → tool), or the campaigns' tooling ball 0.35 m along the
/// flange axis when absent.
pub fn tool_arg(t: Option<&[f64]>) -> Result<pa10::model::Frame> {
    match t {
        Some(t) => pose_arg("--tool", t),
        None => Ok(frame_from_pose([0.0, 0.0, 0.35], [1.0, 0.0, 0.0, 0.0])),
    }
}

impl ModelArg {
    pub fn load(&self) -> Result<Model> {
        match &self.model {
            Some(p) => Model::load(p).with_context(|| format!("loading model {}", p.display())),
            None => Ok(Model::nominal()),
        }
    }
}

/// Arguments of `pa10 fk`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct FkArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Print one JSON object `{"position":[x,y,z],"quaternion":[w,x,y,z]}`.
    #[arg(long)]
    json: bool,
    /// Joint angles are in degrees (default radians).
    #[arg(long)]
    deg: bool,
    /// The angles are resolver (motor-side) readings: deflect the links by gravity and
    /// `--load-n` through the model's joint stiffness before the forward kinematics.
    #[arg(long)]
    resolver: bool,
    /// Weight hung at the tool, newtons (with `--resolver`).
    #[arg(long, value_name = "N", default_value_t = 0.0, requires = "resolver")]
    load_n: f64,
    /// Joint angles J1 … J6 (link side unless `--resolver`).
    #[arg(value_name = "Q", num_args = 6, required = true)]
    q: Vec<f64>,
}

/// Arguments of `pa10 ik`.
#[derive(Debug, Args)]
#[command(allow_negative_numbers = true)]
pub struct IkArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Print one JSON object `{"solutions":[[q1..q6],…]}`, nearest first.
    #[arg(long)]
    json: bool,
    /// Print joint angles in degrees (and read `--near` in degrees).
    #[arg(long)]
    deg: bool,
    /// Reference configuration the solutions are sorted by, comma-separated (default 0s).
    #[arg(
        long,
        value_name = "Q1,..,Q6",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    near: Option<Vec<f64>>,
    /// Target tool pose in the base frame: X Y Z in metres, then the unit quaternion QW QX QY QZ.
    #[arg(value_name = "POSE", num_args = 7, required = true)]
    pose: Vec<f64>,
}

/// `pa10 model …`
#[derive(Debug, Subcommand)]
pub enum ModelCmd {
    /// Validate a model file and summarise it.
    Check {
        /// The model file (YAML).
        file: PathBuf,
    },
}

fn joints(v: &[f64], deg: bool, what: &str) -> Result<[f64; 6]> {
    let q: [f64; 6] = v
        .try_into()
        .map_err(|_| anyhow::anyhow!("{what}: expected 6 joint angles, got {}", v.len()))?;
    if let Some(j) = q.iter().position(|x| !x.is_finite()) {
        bail!("{what}: joint {} is not a finite number", j + 1);
    }
    Ok(if deg { q.map(f64::to_radians) } else { q })
}

/// `pa10 fk`.
pub fn fk(a: &FkArgs) -> Result<()> {
    let m = a.model.load()?;
    let q = joints(&a.q, a.deg, "joint angles")?;
    if !(a.load_n.is_finite() && a.load_n >= 0.0) {
        bail!("--load-n must be a finite weight ≥ 0 N, got {}", a.load_n);
    }
    let q_link = if a.resolver {
        let load = ExternalLoad::hung(a.load_n, &m.gravity());
        m.link_from_motor(&q, Torques::Gravity(&load), &NO_DIRECTION)
            .context("deflecting the links")?
            .q_link
    } else {
        q
    };
    let (p, quat) = pose_parts(&m.fk(&q_link));
    // Print −0.0 as 0.
    let (p, quat) = (p.map(|x| x + 0.0), quat.map(|x| x + 0.0));
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "position": p, "quaternion": quat })
        );
    } else {
        println!(
            "position   [m]  x {:+.9}  y {:+.9}  z {:+.9}",
            p[0], p[1], p[2]
        );
        println!(
            "quaternion      w {:+.9}  x {:+.9}  y {:+.9}  z {:+.9}",
            quat[0], quat[1], quat[2], quat[3]
        );
    }
    Ok(())
}

/// `pa10 ik`.
pub fn ik(a: &IkArgs) -> Result<()> {
    let m = a.model.load()?;
    let v = &a.pose;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        bail!("pose value {} is not a finite number", i + 1);
    }
    let quat = [v[3], v[4], v[5], v[6]];
    let norm = quat.iter().map(|x| x * x).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > 1e-3 {
        bail!("QW QX QY QZ must be a unit quaternion; its norm is {norm}");
    }
    let reference = match &a.near {
        Some(n) => joints(n, a.deg, "--near")?,
        None => [0.0; 6],
    };
    let target = frame_from_pose([v[0], v[1], v[2]], quat);
    let sols = m.ik(&target, &reference).context("inverse kinematics")?;
    let out: Vec<[f64; 6]> = sols
        .as_slice()
        .iter()
        .map(|q| if a.deg { q.map(f64::to_degrees) } else { *q }.map(|x| x + 0.0))
        .collect();
    if a.json {
        println!("{}", serde_json::json!({ "solutions": out }));
    } else {
        let unit = if a.deg { "deg" } else { "rad" };
        println!("{} solution(s), nearest first [{unit}]:", out.len());
        for q in &out {
            let cols: Vec<String> = q.iter().map(|x| format!("{x:+.9}")).collect();
            println!("  {}", cols.join("  "));
        }
    }
    Ok(())
}

/// `pa10 model …`.
pub fn model(c: &ModelCmd) -> Result<()> {
    match c {
        ModelCmd::Check { file } => {
            let m = Model::load(file)?;
            let d = m.data();
            let names = pa10::model::param_names();
            let p = m.params();
            let nonzero: Vec<&str> = (0..24).filter(|&i| p[i] != 0.0).map(|i| names[i]).collect();
            println!("{}: valid model of {}", file.display(), d.robot);
            println!(
                "  nominal lengths: d1 {} m, a2 {} m, d4 {} m, d6 {} m",
                d.dh[0].d, d.dh[1].a, d.dh[3].d, d.dh[5].d
            );
            println!(
                "  departures: {}",
                if nonzero.is_empty() {
                    "none (nominal geometry)".to_string()
                } else {
                    nonzero.join(", ")
                }
            );
            for (j, s) in d.stiffness.iter().enumerate() {
                if let Some(s) = s {
                    println!(
                        "  J{} stiffness: klin {:.4e} N·m/rad, kcub {:.4e} N·m/rad³",
                        j + 1,
                        s.klin,
                        s.kcub
                    );
                }
            }
            if d.stiffness.iter().all(Option::is_none) {
                println!("  stiffness: all joints rigid");
            }
            let mass: f64 = d.bodies.iter().map(|b| b.mass).sum();
            println!("  bodies: {} ({mass:.2} kg)", d.bodies.len());
            println!(
                "  tool: translation {:?} m, quaternion {:?}",
                d.tool.translation, d.tool.quaternion
            );
            Ok(())
        }
    }
}

/// Arguments of `pa10 urdf`.
#[derive(Debug, Args)]
pub struct UrdfArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Write here instead of stdout.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// The robot's name in the URDF.
    #[arg(long, default_value = "pa10")]
    name: String,
    /// The drives' torque limits J1..J6, N·m (the URDF's `effort`). The PA10's are not
    /// published (docs/references.md); the default is the simulated drives' (current limit ×
    /// torque constant: 450,900,450,150,150,60).
    #[arg(
        long,
        value_name = "N1,..,N6",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    effort: Option<Vec<f64>>,
}

/// `pa10 urdf`: the model's kinematics as a URDF.
pub fn urdf(a: &UrdfArgs) -> Result<()> {
    let m = a.model.load()?;
    let effort: [f64; 6] = match &a.effort {
        Some(e) => {
            let e: [f64; 6] = e
                .as_slice()
                .try_into()
                .map_err(|_| anyhow::anyhow!("--effort takes six torques, N·m"))?;
            if let Some(j) = e.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
                anyhow::bail!(
                    "--effort: joint {} torque {} N·m is not a positive number",
                    j + 1,
                    e[j]
                );
            }
            e
        }
        None => {
            let d = pa10::sim::servo::ServoConfig::default();
            std::array::from_fn(|j| d.current_limit_a[j] * d.torque_constants[j])
        }
    };
    let text = pa10::model::urdf::urdf(&m, &a.name, &effort);
    match &a.out {
        Some(p) => {
            std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?;
            println!("wrote {}", p.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}
