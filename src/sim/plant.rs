//! The physics the simulated servo controller drives: motors, springs, links and a hung load,
//! behind one interface.
//!
//! [`ServoSim`](super::servo::ServoSim) owns the controller — the protocol's state machine, the
//! watchdog, the resolvers (repeatable error, noise, quantisation) and the current sensors'
//! noise — and asks a [`Plant`] for what those sensors see: motor angles, the torque the motor
//! current carries, and, for the judge only, the link angles and the tool pose. Two plants:
//! [`ModelPlant`] (the default, in-process: a first-order speed loop and the truth model's
//! statics) and [`MujocoPlant`](super::mujoco::MujocoPlant) (a physics engine we did not write,
//! in its own process: `tests/mujoco/plant.py`, or any process speaking
//! `docs/plant-protocol.md`). [`PlantConfig`] is the `sim.plant` section that chooses one.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::model::{ExternalLoad, Frame as Pose, Model, Torques};

/// Which physics the simulated arm runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PlantKind {
    /// [`ModelPlant`]: in-process, the hidden truth model's statics (fast, no dynamics).
    #[default]
    Model,
    /// A process speaking the stepped plant protocol (`docs/plant-protocol.md`): by default
    /// this crate's MuJoCo PA10, `tests/mujoco/plant.py`.
    Mujoco,
}

/// How the drives' dry friction behaves at rest (the plant protocol's `friction_model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrictionModel {
    /// MuJoCo's `frictionloss`: a joint at rest creeps until no friction torque is held.
    #[default]
    Creep,
    /// A sticking harmonic drive: Stribeck curve in motion, breakaway at 1.6× Coulomb, and
    /// at rest a held torque the spring does not see.
    Stick,
}

/// The simulated robot behind the virtual backend.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// A hidden true robot (model YAML); drawn from `seed` when absent.
    #[serde(default)]
    pub truth: Option<PathBuf>,
    /// Seed of the drawn truth and of the sensor noise.
    #[serde(default)]
    pub seed: u64,
    /// The physics the simulated controller drives (`docs/plant-protocol.md`): the in-process
    /// model plant by default, or MuJoCo's (any process speaking the plant protocol).
    #[serde(default)]
    pub plant: PlantConfig,
}

/// Largest scale of a plant's dry friction (`tests/mujoco/plant.py` refuses more too).
pub const MAX_FRICTION_SCALE: f64 = 10.0;

/// Longest plant command accepted (program and arguments).
pub const MAX_COMMAND_ARGS: usize = 64;

/// The `sim.plant` section of the daemon's configuration: the physics of the simulated arm.
///
/// ```yaml
/// sim:
///   plant:
///     kind: mujoco                                  # model (default) | mujoco
///     command: [python3, ../tests/mujoco/plant.py]  # run in the config file's folder
///     seed: 1                                       # default: sim.seed
///     friction: 1.0                                 # scale of the dry friction, 0…10
///     friction_model: stick                         # creep (default) | stick
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PlantConfig {
    /// Which physics.
    #[serde(default)]
    pub kind: PlantKind,
    /// `mujoco`: the program and its arguments, started in [`PlantConfig::dir`] (the
    /// configuration file's folder); absent: `python3` and this build tree's
    /// `tests/mujoco/plant.py`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<Vec<String>>,
    /// `mujoco`: seed of the plant's hidden departures; absent: `sim.seed`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// `mujoco`: scale of the drives' dry friction (0: none, 1: the plant's realistic level),
    /// 0…10; absent: 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<f64>,
    /// `mujoco`: how the dry friction behaves at rest.
    #[serde(default)]
    pub friction_model: FrictionModel,
    /// `mujoco`: effects the plant hides from the daemon (none when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hidden: Option<HiddenEffects>,
    /// Where the command runs (set from the configuration file's folder when it is read).
    #[serde(skip)]
    pub dir: Option<PathBuf>,
}

/// The largest hidden gear-ratio error [`HiddenEffects`] accepts (relative).
pub const MAX_HIDDEN_GEAR: f64 = 0.01;
/// The largest hidden bearing amplitude [`HiddenEffects`] accepts, rad.
pub const MAX_HIDDEN_BEARING_RAD: f64 = 0.002;
/// The largest hidden link bending compliance [`HiddenEffects`] accepts, rad/(N·m).
pub const MAX_HIDDEN_BEND: f64 = 1e-4;
/// The DH rows (0-based, as `pa10 discover` counts them) that may bend: the upper arm (1) and
/// the forearm (3).
pub const BENDING_ROWS: [usize; 2] = [1, 3];
/// The largest hidden tool mass beyond the declared payload [`HiddenEffects`] accepts, kg.
pub const MAX_HIDDEN_PAYLOAD_KG: f64 = 10.0;

/// Whether every value of an array is zero (the protocol leaves such a key out).
fn all_zero<const N: usize, T: PartialEq + Default>(v: &[T; N]) -> bool {
    v.iter().all(|x| *x == T::default())
}

/// Whether a number is zero (the protocol leaves such a key out).
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Effects a plant hides from the daemon (the plant protocol's `hidden`,
/// `docs/plant-protocol.md`), for judging discovery on effects the daemon's model lacks; a real
/// arm has them unasked. Between the rotors and the resolvers' reading, which in link units is
/// `θ_r = (1 + gear_j)·θ − A_j·sin(θ + φ_j)` for the rotor's angle θ: a gear ratio off by a
/// relative `gear_j` and an output bearing's once-per-revolution error of amplitude `A_j`.
/// Outside the joints: a link that bends at its midpoint by `bend[row]` rad per N·m of the
/// bending moment it carries, and `payload_kg` at the tool that no declared payload includes.
/// Keys that are all zero are not sent, so a plant that knows only `gear` and `bearing` answers
/// as before.
///
/// ```yaml
/// sim:
///   plant:
///     kind: mujoco
///     hidden:
///       gear: [0, 0, 0.0005, 0, 0, 0]          # J3's ratio 0.05 % off
///       bearing: [[0, 0], [0.0002, 0.7], [0, 0], [0, 0], [0, 0], [0, 0]]  # J2: 0.2 mrad, φ 0.7 rad
///       bend: [0, 4.0e-6, 0, 0, 0, 0]          # the upper arm: 4 µrad per N·m at its midpoint
///       payload_kg: 0.5                        # a tool 0.5 kg heavier than declared
/// ```
///
/// ```
/// use pa10::sim::plant::HiddenEffects;
/// let mut h = HiddenEffects::default();
/// h.bend[2] = 1e-6; // J3's row holds no link that bends
/// assert!(h.validate().unwrap_err().contains("bend[2]"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HiddenEffects {
    /// Per joint, the gear ratio's relative error (|g| ≤ [`MAX_HIDDEN_GEAR`]).
    #[serde(default, skip_serializing_if = "all_zero")]
    pub gear: [f64; 6],
    /// Per joint, the bearing error's amplitude A (rad, |A| ≤ [`MAX_HIDDEN_BEARING_RAD`]) and
    /// phase φ (rad).
    #[serde(default, skip_serializing_if = "all_zero")]
    pub bearing: [[f64; 2]; 6],
    /// Per DH row, the link's bending compliance at its midpoint, rad/(N·m) (0 …
    /// [`MAX_HIDDEN_BEND`], only on [`BENDING_ROWS`]).
    #[serde(default, skip_serializing_if = "all_zero")]
    pub bend: [f64; 6],
    /// Mass at the tool beyond every declared payload, kg (0 … [`MAX_HIDDEN_PAYLOAD_KG`]).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub payload_kg: f64,
}

impl HiddenEffects {
    /// Checks every value: why it is refused.
    pub fn validate(&self) -> Result<(), String> {
        for (j, g) in self.gear.iter().enumerate() {
            if !(g.is_finite() && g.abs() <= MAX_HIDDEN_GEAR) {
                return Err(format!(
                    "gear[{j}]: a relative error within ±{MAX_HIDDEN_GEAR}, got {g}"
                ));
            }
        }
        for (j, [a, phi]) in self.bearing.iter().enumerate() {
            if !(a.is_finite() && a.abs() <= MAX_HIDDEN_BEARING_RAD && phi.is_finite()) {
                return Err(format!(
                    "bearing[{j}]: [amplitude within ±{MAX_HIDDEN_BEARING_RAD} rad, finite phase rad], got [{a}, {phi}]"
                ));
            }
        }
        for (r, c) in self.bend.iter().enumerate() {
            if !(c.is_finite() && (0.0..=MAX_HIDDEN_BEND).contains(c)) {
                return Err(format!(
                    "bend[{r}]: a compliance 0…{MAX_HIDDEN_BEND} rad/(N·m), got {c}"
                ));
            }
            if *c != 0.0 && !BENDING_ROWS.contains(&r) {
                return Err(format!(
                    "bend[{r}]: only the rows {BENDING_ROWS:?} (upper arm, forearm) hold a link that bends, got {c}"
                ));
            }
        }
        let m = self.payload_kg;
        if !(m.is_finite() && (0.0..=MAX_HIDDEN_PAYLOAD_KG).contains(&m)) {
            return Err(format!(
                "payload_kg: a mass 0…{MAX_HIDDEN_PAYLOAD_KG} kg, got {m}"
            ));
        }
        Ok(())
    }
}

impl PlantConfig {
    /// Checks every field: the offending key (below `sim.plant`) and why.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Some(f) = self.friction
            && !(f.is_finite() && (0.0..=MAX_FRICTION_SCALE).contains(&f))
        {
            return Err((
                "friction",
                format!("a scale 0…{MAX_FRICTION_SCALE} of the plant's dry friction, got {f}"),
            ));
        }
        if let Some(c) = &self.command {
            if c.is_empty() || c[0].trim().is_empty() {
                return Err((
                    "command",
                    "needs a program, e.g. [python3, plant.py]".into(),
                ));
            }
            if c.len() > MAX_COMMAND_ARGS {
                return Err((
                    "command",
                    format!("at most {MAX_COMMAND_ARGS} words, got {}", c.len()),
                ));
            }
            if c.iter().any(|w| w.contains('\0')) {
                return Err(("command", "a word holds a NUL byte".into()));
            }
        }
        if let Some(h) = &self.hidden {
            h.validate().map_err(|e| ("hidden", e))?;
        }
        if self.kind == PlantKind::Model
            && (self.command.is_some()
                || self.friction.is_some()
                || self.seed.is_some()
                || self.hidden.is_some()
                || self.friction_model != FrictionModel::Creep)
        {
            return Err((
                "kind",
                "command, seed, friction, friction_model and hidden are for `kind: mujoco` (the in-process model plant has no friction)".into(),
            ));
        }
        Ok(())
    }
}

/// What the servo controller's speed loop asks of the plant for one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Commanded motor speeds, rad/s (link units).
    pub speed: [f64; 6],
    /// Brakes released and the speed loop closed; `false`: the motors are held by the brakes.
    pub engaged: bool,
    /// A controlled stop: the motor speeds change by at most this much per second, rad/s²
    /// (`speed` is then zero).
    pub stop_decel: Option<f64>,
    /// Speed limits, rad/s.
    pub speed_limit: [f64; 6],
}

/// The physics behind a simulated servo controller. Angles rad, torques N·m (link side),
/// times s, loads N.
pub trait Plant: Send + std::fmt::Debug {
    /// Advances the plant by `dt` seconds under `drive`.
    fn advance(&mut self, dt: f64, drive: &Drive);
    /// True motor angles, rad (what the resolvers read, before their errors).
    fn motor_angles(&self) -> [f64; 6];
    /// True motor speeds, rad/s.
    fn motor_speeds(&self) -> [f64; 6];
    /// True link angles and the torques the motor currents carry, rad and N·m.
    fn link_state(&self) -> ([f64; 6], [f64; 6]);
    /// The exact tool pose, robot base frame (the judge's truth; never on the bus).
    fn tool_pose(&self) -> Pose;
    /// Hangs `newtons` at the tool (the weight rack).
    fn set_load(&mut self, newtons: f64);
    /// The torques the joint springs pass to the links, N·m (link side; at rest the links'
    /// gravity and load torques: the judges' truth for an identified gravity model), when the
    /// plant reports them.
    fn spring_torques(&self) -> Option<[f64; 6]> {
        None
    }
    /// Why the plant stopped computing (an external process that died), if it did.
    fn failure(&self) -> Option<&str> {
        None
    }
}

/// Motor speed above which a motion counts as an approach direction, rad/s.
const BACKLASH_SPEED: f64 = 2e-3;

/// The in-process plant: per axis a velocity loop (first-order lag `tau_s` towards the
/// commanded speed, speed-limited, a controlled stop decelerating at most at its rate), the
/// motor angle integrating the speed, the link at the motor angle minus the truth model's
/// spring deflection under its gravity and the hung load (with backlash on the side of the
/// last deliberate motion). Statics only: no inertia, friction or vibration.
#[derive(Debug, Clone)]
pub struct ModelPlant {
    model: Model,
    tau_s: f64,
    motor: [f64; 6],
    speed: [f64; 6],
    /// Direction each motor last moved in (−1, 0, +1): the side of any backlash.
    dir: [f64; 6],
    load_n: f64,
}

impl ModelPlant {
    /// The truth `model`'s arm with its motors at rest at `q0` (rad) and a speed loop of
    /// time constant `tau_s` (s).
    pub fn new(model: Model, tau_s: f64, q0: [f64; 6]) -> Self {
        Self {
            model,
            tau_s,
            motor: q0,
            speed: [0.0; 6],
            dir: [0.0; 6],
            load_n: 0.0,
        }
    }
}

impl Plant for ModelPlant {
    fn advance(&mut self, dt: f64, drive: &Drive) {
        for j in 0..6 {
            if !drive.engaged {
                self.speed[j] = 0.0;
                continue;
            }
            let mut v =
                self.speed[j] + (drive.speed[j] - self.speed[j]) * (1.0 - (-dt / self.tau_s).exp());
            if let Some(decel) = drive.stop_decel {
                let dv = decel * dt;
                v = v.clamp(self.speed[j] - dv, self.speed[j] + dv);
            }
            let lim = drive.speed_limit[j];
            self.speed[j] = v.clamp(-lim, lim);
            self.motor[j] += self.speed[j] * dt;
            // A deliberate motion (not the position loop's dither at rest) takes up the
            // backlash on its side.
            if self.speed[j].abs() > BACKLASH_SPEED {
                self.dir[j] = self.speed[j].signum();
            }
        }
    }

    fn motor_angles(&self) -> [f64; 6] {
        self.motor
    }

    fn motor_speeds(&self) -> [f64; 6] {
        self.speed
    }

    fn link_state(&self) -> ([f64; 6], [f64; 6]) {
        let load = ExternalLoad::hung(self.load_n, &self.model.gravity());
        self.model
            .link_from_motor(&self.motor, Torques::Gravity(&load), &self.dir)
            .map(|c| (c.q_link, c.tau))
            .unwrap_or((self.motor, [0.0; 6]))
    }

    fn tool_pose(&self) -> Pose {
        self.model.fk_loaded(&self.link_state().0, self.load_n)
    }

    fn spring_torques(&self) -> Option<[f64; 6]> {
        Some(self.link_state().1)
    }

    fn set_load(&mut self, newtons: f64) {
        self.load_n = newtons.max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_effects_are_read_checked_and_sent_only_where_set() {
        let c: PlantConfig = serde_yaml::from_str(
            "kind: mujoco\nhidden:\n  bend: [0, 4.0e-6, 0, 0, 0, 0]\n  payload_kg: 0.5\n",
        )
        .unwrap();
        assert!(c.validate().is_ok());
        let h = c.hidden.unwrap();
        assert_eq!((h.bend[1], h.payload_kg), (4.0e-6, 0.5));
        // what the plant is sent: only the keys set, so a plant that knows gear and bearing
        // alone reads a gear-only configuration as before
        let sent = serde_json::to_value(h).unwrap();
        assert_eq!(
            sent,
            serde_json::json!({"bend": [0.0, 4.0e-6, 0.0, 0.0, 0.0, 0.0], "payload_kg": 0.5})
        );
        let gear = HiddenEffects {
            gear: [0.0, 0.0, 5e-4, 0.0, 0.0, 0.0],
            ..Default::default()
        };
        assert_eq!(
            serde_json::to_value(gear).unwrap(),
            serde_json::json!({"gear": [0.0, 0.0, 5e-4, 0.0, 0.0, 0.0]})
        );
        // refusals name the key and change nothing
        for (h, key) in [
            (
                HiddenEffects {
                    bend: [0.0, -1e-6, 0.0, 0.0, 0.0, 0.0],
                    ..Default::default()
                },
                "bend[1]",
            ),
            (
                HiddenEffects {
                    bend: [0.0, 0.0, 0.0, 2.0 * MAX_HIDDEN_BEND, 0.0, 0.0],
                    ..Default::default()
                },
                "bend[3]",
            ),
            (
                HiddenEffects {
                    bend: [0.0, 0.0, 0.0, 0.0, 1e-6, 0.0],
                    ..Default::default()
                },
                "bend[4]",
            ),
            (
                HiddenEffects {
                    payload_kg: f64::NAN,
                    ..Default::default()
                },
                "payload_kg",
            ),
            (
                HiddenEffects {
                    payload_kg: -0.1,
                    ..Default::default()
                },
                "payload_kg",
            ),
        ] {
            let c = PlantConfig {
                hidden: Some(h),
                ..serde_yaml::from_str("kind: mujoco").unwrap()
            };
            let (k, why) = c.validate().unwrap_err();
            assert_eq!(k, "hidden");
            assert!(why.starts_with(key), "{why}");
        }
        assert!(serde_yaml::from_str::<PlantConfig>("kind: mujoco\nhidden: {bends: [0]}").is_err());
    }
}
