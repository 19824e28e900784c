//! The ROS 2 bridge's end-to-end tests (feature `ros2`):
//! `cargo test --features ros2 --test ros2 daemon::ros2`. A test binary of its own, so that the
//! feature build compiles the daemon tests' module and not the whole suite again (CI's time);
//! the tests are `daemon::ros2_*` in tests/daemon.rs, beside the helpers (the `pa10d` binary on
//! the simulated arm, the Python runner) they share with the daemon's other end-to-end tests.

// the shared modules carry helpers only the main suite (tests/tests.rs) calls
#![allow(dead_code)]
#![allow(clippy::unwrap_used)]

mod common;
mod daemon;
