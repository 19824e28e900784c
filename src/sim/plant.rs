//! The physics the simulated servo controller drives: motors, springs, links and a hung load,
//! behind one interface.
//!
//! [`ServoSim`](super::servo::ServoSim) owns the controller — the protocol's state machine, the
//! watchdog, the resolvers (repeatable error, noise, quantisation) and the current sensors'
//! noise — and asks a [`Plant`] for what those sensors see: motor angles, the torque the motor
//! current carries, and, for the judge only, the link angles and the tool pose. Two plants:
//! [`ModelPlant`] (the default, in-process: a first-order speed loop and the truth model's
//! statics) and [`MujocoPlant`](super::mujoco::MujocoPlant) (a physics engine we did not write,
//! in its own process: `tests/mujoco/plant.py`).

use crate::model::{ExternalLoad, Frame as Pose, Model, Torques};

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
        self.model.fk(&self.link_state().0)
    }

    fn set_load(&mut self, newtons: f64) {
        self.load_n = newtons.max(0.0);
    }
}
