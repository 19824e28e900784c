//! The simulated PA10: a hidden "true" robot and the physics of measuring it.
//!
//! [`TrueRobot`] owns the truth: geometry departures, joint springs, masses (tooling
//! included), the instrument's placement, and a repeatable resolver error per joint. Only
//! the simulator reads it; calibration, discovery and the daemon see measurements. The
//! [`experiment`] module builds the seed paper's measurement campaign on top of it.

pub mod experiment;
#[cfg(feature = "daemon")]
pub mod mujoco;
#[cfg(feature = "daemon")]
pub mod plant;
#[cfg(feature = "daemon")]
pub mod rig;
#[cfg(feature = "daemon")]
pub mod servo;

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use crate::accuracy::ARCMIN;
use crate::calib::dataset::{Effort, Row};
use crate::model::{Body, ExternalLoad, Frame, Model, ModelError, PoseData, Stiffness};

pub use crate::model::params::{PAPER_STIFFNESS, TOLERANCES};

/// Noise of the simulated sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimNoise {
    /// Instrument position noise, m (3-D rms; 12.1 µm for the paper's CMM).
    pub position_m: f64,
    /// Instrument orientation noise, rad (3-D rms; the ball triad's ~0.1 m span).
    pub orientation_rad: f64,
    /// Resolver error, rad (rms of the repeatable error function per joint).
    pub resolver_rad: f64,
    /// Servo settling scatter between repeats, rad (1σ).
    pub settle_rad: f64,
    /// Torque measurement noise: relative (1σ) and absolute (N·m, 1σ).
    pub torque_rel: f64,
    /// Absolute torque noise, N·m (1σ).
    pub torque_abs_nm: f64,
}

impl Default for SimNoise {
    fn default() -> Self {
        Self {
            position_m: 12.1e-6,
            orientation_rad: 12.1e-6 / 0.1,
            resolver_rad: 0.64 * ARCMIN,
            settle_rad: 1e-6,
            torque_rel: 0.01,
            torque_abs_nm: 0.2,
        }
    }
}

/// One harmonic of a resolver error: amplitude (rad), frequency (cycles per link radian ×
/// 2π), phase (rad).
type Harmonic = (f64, f64, f64);

/// Effects of the truth that a model file cannot hold (joint springs and joint errors go
/// in [`TrueRobot::model`]): thermal growth and bending of links, evaluated by the
/// simulator's own forward model (thermal growth changes the link lengths themselves).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthExtras {
    /// Thermal expansion coefficient per DH row, 1/K.
    pub thermal: [f64; 6],
    /// Bending compliance per DH row, rad/(N·m).
    pub bending: [f64; 6],
    /// Temperature at which the lengths are the model's, °C.
    pub t_ref_c: f64,
}

impl TruthExtras {
    fn active(&self) -> bool {
        self.thermal.iter().chain(&self.bending).any(|v| *v != 0.0)
    }
}

/// The conditions of one measurement beyond configuration and load.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Conditions {
    /// Direction each joint approached the configuration from (−1, 0, +1).
    pub direction: [i8; 6],
    /// Arm temperature, °C (`None`: the reference temperature, not recorded).
    pub temperature_c: Option<f64>,
}

/// A hidden true robot.
#[derive(Debug, Clone)]
pub struct TrueRobot {
    /// True geometry, springs, joint errors, masses (tooling included), tool and instrument
    /// placement.
    pub model: Model,
    /// Thermal growth and bending of the truth (zero unless a test hides them).
    pub extras: TruthExtras,
    /// Sensor noise levels.
    pub noise: SimNoise,
    resolver: [[Harmonic; 3]; 6],
}

fn gauss(rng: &mut Pcg64) -> f64 {
    StandardNormal.sample(rng)
}

impl TrueRobot {
    /// Draws a true robot from `seed`: departures uniform within the paper's tolerances,
    /// stiffness of J2, J3, J5 within ±10 % (linear) and ±20 % (cubic) of the paper's,
    /// link masses within ±10 % plus a 2.4 kg tooling apparatus, the instrument placed
    /// 0.5–1 m away at an arbitrary yaw with sub-degree tilts, and a repeatable resolver
    /// error per joint (three harmonics of the motor revolution, rms `noise.resolver_rad`).
    /// `tool` is the flange → target transform (known to the user too).
    pub fn draw(
        seed: u64,
        nominal: &Model,
        tool: &Frame,
        noise: SimNoise,
    ) -> Result<Self, ModelError> {
        let mut rng = Pcg64::seed_from_u64(seed);
        let mut d = nominal.data().clone();
        d.robot = format!("simulated PA10-6CE, truth drawn from seed {seed}");
        for (j, e) in d.departures.iter_mut().enumerate() {
            let mut u = |tol: f64| rng.random_range(-tol..tol);
            e.da = u(TOLERANCES[0]);
            e.dalpha = u(TOLERANCES[1]);
            if j == 1 {
                e.dbeta = u(TOLERANCES[3]);
                e.dd = 0.0;
            } else {
                e.dd = u(TOLERANCES[2]);
                e.dbeta = 0.0;
            }
            e.dtheta = u(TOLERANCES[4]);
        }
        for (k, &j) in crate::model::STIFF_JOINTS.iter().enumerate() {
            let (kl, kc) = PAPER_STIFFNESS[k];
            d.stiffness[j] = Some(Stiffness {
                klin: kl * rng.random_range(0.9..1.1),
                kcub: kc * rng.random_range(0.8..1.2),
            });
        }
        for b in &mut d.bodies {
            b.mass *= rng.random_range(0.9..1.1);
        }
        let tool_len = tool.translation.vector.norm();
        d.bodies.push(Body {
            name: "tooling apparatus".into(),
            frame: 6,
            mass: 2.4,
            com: [0.0, 0.0, 0.5 * tool_len],
            sigma: None,
        });
        d.tool = PoseData::from(tool);
        let yaw = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let rot = UnitQuaternion::from_euler_angles(
            rng.random_range(-0.01..0.01),
            rng.random_range(-0.01..0.01),
            yaw,
        );
        let dist = rng.random_range(0.5..1.0);
        let ang = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let t = Translation3::new(
            dist * ang.cos(),
            dist * ang.sin(),
            rng.random_range(-0.3..0.0),
        );
        d.base_from_instrument = PoseData::from(&Frame::from_parts(t, rot.to_rotation_matrix()));
        let model = Model::new(d)?;
        let resolver = resolver_harmonics(&mut rng, &noise);
        Ok(Self {
            model,
            extras: TruthExtras::default(),
            noise,
            resolver,
        })
    }

    /// What the instrument reports for the robot at link angles `q_link`: the true target pose
    /// in the instrument frame, with the instrument's position and orientation noise.
    pub fn observe(&self, q_link: &[f64; 6], rng: &mut Pcg64) -> Frame {
        self.observe_pose(&self.model.fk(q_link), rng)
    }

    /// What the instrument reports for a true target pose `pose` (robot base frame).
    pub fn observe_pose(&self, pose: &Frame, rng: &mut Pcg64) -> Frame {
        let m = &self.model;
        let truth = m.base_from_instrument().inverse() * pose;
        let s3 = 1.0 / 3f64.sqrt();
        let dp = Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * (self.noise.position_m * s3);
        let dr =
            Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * (self.noise.orientation_rad * s3);
        Frame::from_parts(
            Translation3::from(truth.translation.vector + dp),
            nalgebra::Rotation3::new(dr) * truth.rotation,
        )
    }

    /// The resolver reading (rad) of joint `j` at true motor angle `q`: the angle plus its
    /// repeatable error.
    pub fn resolver_reading(&self, j: usize, q: f64) -> f64 {
        q + self.resolver_error(j, q)
    }

    /// The same robot with exact resolvers: no repeatable error (their noise and
    /// quantisation stay, and so does `noise.resolver_rad`, the σ a floor is quoted for). A
    /// diagnostic, not a robot: it tells a method's bias apart from the resolvers' error
    /// realised at one campaign's angles (docs/judge.md §9).
    pub fn with_exact_resolvers(mut self) -> Self {
        self.resolver = [[(0.0, 0.0, 0.0); 3]; 6];
        self
    }

    /// Wraps a loaded truth model (e.g. a `truth.yaml`) with a resolver error drawn from
    /// `seed`.
    pub fn from_model(model: Model, noise: SimNoise, seed: u64) -> Self {
        let mut rng = Pcg64::seed_from_u64(seed ^ 0x7e50_1e7e);
        let resolver = resolver_harmonics(&mut rng, &noise);
        Self {
            model,
            extras: TruthExtras::default(),
            noise,
            resolver,
        }
    }

    /// The repeatable resolver error of joint `j` at true motor angle `q` (rad).
    pub fn resolver_error(&self, j: usize, q: f64) -> f64 {
        self.resolver[j]
            .iter()
            .map(|&(a, f, p)| a * (f * q + p).sin())
            .sum()
    }

    /// One static measurement: the servo holds the resolver reading at `q_cmd` (motor side,
    /// rad) with `load_n` newtons hung at the tool. Returns the dataset row the user would
    /// record: resolver angles, measured torques, the instrument's measurement of the target.
    pub fn measure(
        &self,
        config_id: &str,
        q_cmd: &[f64; 6],
        load_n: f64,
        rng: &mut Pcg64,
    ) -> Result<Row, ModelError> {
        self.measure_with(config_id, q_cmd, load_n, Conditions::default(), rng)
    }

    /// [`TrueRobot::measure`] after an approach in `cond.direction` at `cond.temperature_c`;
    /// the row records both.
    pub fn measure_with(
        &self,
        config_id: &str,
        q_cmd: &[f64; 6],
        load_n: f64,
        cond: Conditions,
        rng: &mut Pcg64,
    ) -> Result<Row, ModelError> {
        let m = &self.model;
        // The servo settles where the resolver reads q_cmd (plus a little scatter): the true
        // motor angle is q_cmd − e(true angle).
        let reading: [f64; 6] =
            std::array::from_fn(|j| q_cmd[j] + self.noise.settle_rad * gauss(rng));
        let mut motor = reading;
        for _ in 0..4 {
            motor = std::array::from_fn(|j| reading[j] - self.resolver_error(j, motor[j]));
        }
        let load = ExternalLoad::hung(load_n, &m.gravity());
        let dir = cond.direction.map(f64::from);
        let c = m.link_from_motor(&motor, crate::model::Torques::Gravity(&load), &dir)?;
        let (q_link, tau) = (c.q_link, c.tau);
        let tau_meas: [f64; 6] = std::array::from_fn(|j| {
            tau[j] * (1.0 + self.noise.torque_rel * gauss(rng))
                + self.noise.torque_abs_nm * gauss(rng)
        });
        let measured = if self.extras.active() {
            let pose = self.pose_with_extras(&q_link, load_n, cond.temperature_c)?;
            self.observe_pose(&pose, rng)
        } else {
            self.observe(&q_link, rng)
        };
        Ok(Row {
            config_id: config_id.to_string(),
            load_n,
            q: reading,
            effort: Effort::Torque(tau_meas),
            pose: measured,
            direction: cond.direction,
            temperature_c: cond.temperature_c,
            line: 0,
        })
    }
}

/// Resolver error harmonics: at 1, 2 and 4 motor revolutions per cycle of a 100:1 drive,
/// amplitudes scaled so the rms over an angle is `noise.resolver_rad`.
impl TrueRobot {
    /// The true tool pose (base frame) at link angles `q` with the extras: thermal growth
    /// as real changes of the link lengths (`a` or `d` of each DH row scaled by
    /// `1 + α·(T − T_ref)`), then each bending link turning everything distal of it about
    /// its midpoint by `c·M⊥` — `M⊥` the moment of the hung load and the distal bodies'
    /// weights about the link's proximal end, across the link. The simulator's own code:
    /// discovery's effect library is the judged, not the judge.
    fn pose_with_extras(
        &self,
        q: &[f64; 6],
        load_n: f64,
        temperature_c: Option<f64>,
    ) -> Result<Frame, ModelError> {
        let dt = temperature_c.map_or(0.0, |t| t - self.extras.t_ref_c);
        let grown;
        let m = if dt != 0.0 && self.extras.thermal.iter().any(|a| *a != 0.0) {
            let mut d = self.model.data().clone();
            for j in 0..6 {
                let growth = self.extras.thermal[j] * dt;
                let row = d.dh[j];
                if row.a != 0.0 {
                    d.departures[j].da += row.a * growth;
                } else if j != crate::model::params::HAYATI_JOINT {
                    d.departures[j].dd += row.d * growth;
                }
            }
            grown = Model::new(d)?;
            &grown
        } else {
            &self.model
        };
        let f = m.frames(q);
        let mut x = f[6] * *m.tool();
        let g = m.gravity();
        let load = ExternalLoad::hung(load_n, &g).force;
        let tip = x.translation.vector;
        for j in (0..6).rev() {
            let c = self.extras.bending[j];
            if c == 0.0 {
                continue;
            }
            let (start, end) = (f[j].translation.vector, f[j + 1].translation.vector);
            let along = (end - start).normalize();
            let mut moment = (tip - start).cross(&load);
            for b in m.data().bodies.iter().filter(|b| b.frame > j) {
                let centre = f[b.frame] * nalgebra::Point3::from(b.com);
                moment += (centre.coords - start).cross(&(g * b.mass));
            }
            let turn = nalgebra::Rotation3::new((moment - along * moment.dot(&along)) * c);
            let mid = 0.5 * (start + end);
            x = Frame::from_parts(
                Translation3::from(turn * (x.translation.vector - mid) + mid),
                turn * x.rotation,
            );
        }
        Ok(x)
    }
}

fn resolver_harmonics(rng: &mut Pcg64, noise: &SimNoise) -> [[Harmonic; 3]; 6] {
    let mut resolver = [[(0.0, 0.0, 0.0); 3]; 6];
    for h in resolver.iter_mut() {
        let w: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.2..1.0));
        let scale = noise.resolver_rad * (2.0 / w.iter().map(|x| x * x).sum::<f64>()).sqrt();
        for (k, slot) in h.iter_mut().enumerate() {
            *slot = (
                w[k] * scale,
                100.0 * (1 << k) as f64,
                rng.random_range(0.0..std::f64::consts::TAU),
            );
        }
    }
    resolver
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_resolvers_read_the_motor_angle_and_keep_the_quoted_sigma() {
        let t = TrueRobot::from_model(Model::nominal(), SimNoise::default(), 7);
        let qs: Vec<f64> = (0..2000).map(|i| -2.0 + 4.0 * i as f64 / 2000.0).collect();
        for j in 0..6 {
            // the drawn error: rms over the angles ≈ the specified σ (three harmonics)
            let rms = (qs
                .iter()
                .map(|&q| t.resolver_error(j, q).powi(2))
                .sum::<f64>()
                / qs.len() as f64)
                .sqrt();
            let s = t.noise.resolver_rad;
            assert!(
                rms > 0.7 * s && rms < 1.3 * s,
                "J{}: rms {rms} vs σ {s}",
                j + 1
            );
        }
        let e = t.clone().with_exact_resolvers();
        for j in 0..6 {
            for &q in &qs {
                assert_eq!(e.resolver_reading(j, q), q);
            }
        }
        assert_eq!(e.noise.resolver_rad, t.noise.resolver_rad);
        assert_eq!(e.model, t.model);
    }
}
