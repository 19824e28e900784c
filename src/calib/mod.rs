//! Calibration: measurement datasets and the seed paper's two-level Levenberg–Marquardt
//! identification of the flexible geometric model.

pub mod base;
pub mod collect;
pub mod dataset;
pub mod fit;
pub mod report;
pub(crate) mod weights;
