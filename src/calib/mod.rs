//! Calibration: measurement datasets and the seed paper's two-level Levenberg–Marquardt
//! identification of the flexible geometric model — `dataset` (the CSV and sidecar),
//! `base` (the inner level), `fit` (the outer level and its stages), `weights` (how rows are
//! weighed, from the measured noise), `evaluate` (errors per load, floors), `report`,
//! `collect` (gathering through the daemon), `identify` (gravity and friction from the arm's
//! own motion), `torque_check` (the torque constants against a known weight), `plan` (which configurations to measure, and the
//! accuracy they will give).

pub mod base;
pub mod collect;
pub mod dataset;
pub mod evaluate;
pub mod fit;
pub mod identify;
pub mod plan;
mod prepare;
pub mod report;
pub mod torque_check;
pub(crate) mod weights;
