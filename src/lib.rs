//! # pa10 — calibrated, compliance-compensating control for the Mitsubishi PA10-6CE
//!
//! The library behind the `pa10` tool and the `pa10d` daemon. It follows a
//! *pure core, IO at the edges* layout:
//!
//! - [`model`]: the 30-parameter flexible geometric model of the seed paper
//!   (standard DH with Hayati's β on the parallel joints 2–3, linear + cubic
//!   joint stiffness), forward and inverse kinematics, Jacobians, static joint
//!   torques and the per-cycle compensation `q_motor = q_link + δ(τ)`. Plain
//!   functions on plain data: no IO, no clocks, no allocation on the hot path.
//! - [`accuracy`]: the resolver-uncertainty bound (Monte Carlo and linearised).
//! - [`calib`]: datasets, the two-level calibration, gathering through the daemon.
//! - [`discover`]: is anything missing from the model, what, and does adding it help.
//! - [`noise`]: what the data's noise is — reading noise, repeatable resolver error,
//!   instrument and torque noise — estimated from the data as variance components.
//! - [`stats`]: the distribution functions the tests of calibration and discovery need.
//! - [`sim`]: the simulated PA10 (hidden truth and campaigns; with `daemon`, its servo
//!   controller and the rigs that run the daemon against it).
//! - [`can`]: the protocol codec and the bus abstraction.
//! - `daemon` (feature `daemon`): the control daemon's sans-IO core and its shells.
//! - `record` (feature `record`): recording every control cycle to MCAP, and reading
//!   recordings back.
//! - `ros2` (feature `daemon`): the ROS 2 messages of the `pa10-ros2` bridge and their
//!   translation to and from the daemon's requests (pure; the DDS side is the binary's).
//!
//! **Features.** `default = ["cli"]`: the command-line tools over the `daemon` (which needs
//! `record`) and its `live` view (the Foxglove WebSocket server); `ros2` adds the bridge's DDS
//! side. A program that embeds the daemon's core takes `daemon` alone (no WebSocket stack). With `default-features = false` the crate is
//! the science alone — [`model`], [`calib`], [`discover`], [`noise`], [`accuracy`], the
//! simulator's truth and campaigns — and compiles none of the daemon's IO (62 crates instead
//! of 172).
//!
//! Units are SI throughout: metres, radians, newtons, newton-metres, seconds.
//! Joint vectors are `[f64; 6]` ordered J1 … J6 (S1, S2, E1, E2, W1, W2).
//!
//! ```
//! use pa10::model::Model;
//! let model = Model::nominal();
//! // Zero pose: the arm stands straight up; the flange is 0.317 + 0.450 + 0.480 + 0.070 m high.
//! let flange = model.fk(&[0.0; 6]);
//! assert!((flange.translation.vector.z - 1.317).abs() < 1e-12);
//! ```
#![deny(missing_docs)]

pub mod accuracy;
pub mod calib;
pub mod can;
#[cfg(feature = "daemon")]
pub mod daemon;
pub mod discover;
pub mod model;
pub mod noise;
pub mod plot;
#[cfg(feature = "record")]
pub mod record;
#[cfg(feature = "daemon")]
pub mod ros2;
pub mod sim;
pub mod stats;
pub mod text;
