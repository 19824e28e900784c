//! What the studies on the independent generator (`tests/indep`) share: a generated set
//! written as a user's files and loaded back, calibrated from the nominal model, and
//! discovered from the calibrated model with the validation set held out.

use std::time::Instant;

use pa10::calib::dataset::Dataset;
use pa10::calib::fit::{CalibOptions, calibrate};
use pa10::discover::{DiscoverOptions, Discovery, discover};
use pa10::model::Model;

use crate::indep;

/// `set` written to a private temporary folder (named after `tag`) and loaded back as the
/// calibration and validation datasets; the folder is removed.
pub fn load(set: &indep::Set, tag: &str) -> anyhow::Result<(Dataset, Dataset)> {
    let dir = std::env::temp_dir().join(format!("pa10-study-{tag}-{}", std::process::id()));
    let (cal, val) = indep::write(set, &dir);
    let out = (Dataset::load(&cal)?, Dataset::load(&val)?);
    std::fs::remove_dir_all(&dir)?;
    Ok(out)
}

/// One set through the whole method, with the time each step took (s).
#[allow(dead_code)] // not every study reports the times
pub struct Run {
    pub discovery: Discovery,
    pub calibrate_s: f64,
    pub discover_s: f64,
}

/// `set` calibrated from the nominal model, then discovered from that model with its
/// validation set held out.
pub fn calibrate_and_discover(set: &indep::Set, tag: &str) -> anyhow::Result<Run> {
    let (cal, val) = load(set, tag)?;
    let t = Instant::now();
    let m = calibrate(
        &Model::nominal(),
        &cal,
        None,
        &CalibOptions::default(),
        &|_| {},
    )?
    .model;
    let calibrate_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let discovery = discover(&m, &cal, Some(&val), &DiscoverOptions::default())?;
    Ok(Run {
        discovery,
        calibrate_s,
        discover_s: t.elapsed().as_secs_f64(),
    })
}
