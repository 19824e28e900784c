//! Integration tests, built as one binary (see `autotests = false` in Cargo.toml).
#![allow(clippy::unwrap_used)]

mod accuracy;
mod calibration;
mod canfd;
mod cli;
mod common;
mod control;
mod daemon;
mod dbc;
mod discover;
mod hostile;
mod independent;
mod iso9283;
mod live;
mod model;
mod model_file;
mod pinocchio;
mod plan;
mod properties;
mod readme;
mod record;
mod servo;
mod trajectory;
mod urdf;
