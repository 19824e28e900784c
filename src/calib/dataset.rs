//! Measurement datasets: the CSV format of DESIGN.md and its `*.meta.yaml` sidecar.
//!
//! One row per measurement:
//! `config_id,load_n,q1..q6,(i1..i6 | tau1..tau6),x,y,z,qw,qx,qy,qz` — resolver (motor-side)
//! joint angles in rad, motor currents in A or joint torques in N·m, the measured target pose
//! in the instrument frame (m, unit quaternion), and the load hung at the tool (N). Rows with
//! the same `config_id` and load are repeats. A malformed file is rejected whole, with the
//! file, line, column and reason: nothing is half-loaded.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::model::{Frame, PoseData, frame_from_pose, pose_parts};

/// Where a row's joint torques come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Effort {
    /// Joint torques, N·m (columns `tau1..tau6`).
    Torque([f64; 6]),
    /// Motor currents, A (columns `i1..i6`); a model's torque constants convert them.
    Current([f64; 6]),
}

/// One measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Configuration name; equal names and loads are repeats.
    pub config_id: String,
    /// Weight hung at the tool, N (≥ 0).
    pub load_n: f64,
    /// Resolver (motor-side) joint angles, rad.
    pub q: [f64; 6],
    /// Joint torques or motor currents.
    pub effort: Effort,
    /// Measured target pose in the instrument frame.
    pub pose: Frame,
    /// Direction each joint last moved in before this measurement (−1, 0, +1; 0 when
    /// unknown): columns `dir1..dir6`, or derived from a previous configuration
    /// `prev_q1..prev_q6` (rad). Selects the side of any backlash.
    pub direction: [i8; 6],
    /// Temperature of the arm, °C (column `temp_c`), when recorded.
    pub temperature_c: Option<f64>,
    /// 1-based line number in its file (0 for rows made in memory).
    pub line: usize,
}

/// Noise levels the instrument and resolvers are known to have.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Instrument position uncertainty, m (3-D rms).
    pub position_m: f64,
    /// Resolver uncertainty, arcmin (1σ per joint).
    pub resolver_arcmin: f64,
}

/// The sidecar `cal.meta.yaml` beside `cal.csv`: what the rows do not carry.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// Free text naming the instrument.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<String>,
    /// Flange → measured target; overrides the model's tool when present.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool: Option<PoseData>,
    /// Known noise levels (noise floors, weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<Noise>,
    /// Configurations the inner (base-frame) level uses; chosen automatically when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inner_configs: Option<Vec<String>>,
}

/// A loaded dataset.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Dataset {
    /// The rows, in file order.
    pub rows: Vec<Row>,
    /// The sidecar, if one was found.
    pub meta: Option<Meta>,
}

/// Why a dataset was rejected. Nothing of it was loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A row or the header is malformed.
    #[error("{origin}:{line}{}: {reason}", column.as_ref().map(|c| format!(": column `{c}`")).unwrap_or_default())]
    Malformed {
        /// The file.
        origin: String,
        /// 1-based line.
        line: usize,
        /// The offending column, when one is.
        column: Option<String>,
        /// What is wrong.
        reason: String,
    },
    /// The sidecar is malformed.
    #[error("{path}: {message}")]
    Meta {
        /// The sidecar file.
        path: PathBuf,
        /// The parser's or validator's message.
        message: String,
    },
}

const POSE_COLS: [&str; 7] = ["x", "y", "z", "qw", "qx", "qy", "qz"];

/// Largest resolver angle accepted, rad (beyond any PA10 joint range).
const MAX_ANGLE: f64 = 2.0 * std::f64::consts::TAU;
/// Largest torque accepted, N·m, current, A, and instrument coordinate, m.
const MAX_TORQUE: f64 = 1e4;
const MAX_CURRENT: f64 = 1e3;
const MAX_COORD: f64 = 100.0;

impl Dataset {
    /// The dataset with every row's effort replaced by `model`'s static joint torques (its
    /// bodies and the row's hung load, N) at the row's *link* angles — the resolver angles
    /// less the deflection those torques cause (`Model::link_from_motor` with
    /// `Torques::Gravity`, the row's approach direction): the counterpart of pa10d's
    /// `torque_source: model`, which evaluates the same statics at the link setpoint. At the
    /// resolver angles instead, a tool sagging 5 mrad under 44 N tilts the load's lever arms
    /// by as much, and the fit would take the torque errors (≈ 0.1 N·m on J5, 0.25 N·m on J3)
    /// for stiffness (docs/judge.md §9). A stiffness identified on these torques deflects the
    /// links by what the daemon computes at run time, and the motor currents' friction (a
    /// harmonic drive's stiction holds anything within ±its Coulomb level at rest,
    /// docs/judge.md) never enters the fit; the model's mass errors are absorbed into the
    /// identified stiffness instead.
    ///
    /// # Errors
    /// A row whose link angles do not converge under `model` (joints too compliant for its
    /// load), with the row's line.
    pub fn with_model_torques(
        &self,
        model: &crate::model::Model,
    ) -> Result<Self, crate::model::ModelError> {
        let g = model.gravity();
        let mut out = self.clone();
        for r in &mut out.rows {
            let load = crate::model::ExternalLoad::hung(r.load_n, &g);
            let dir = r.direction.map(f64::from);
            let c = model
                .link_from_motor(&r.q, crate::model::Torques::Gravity(&load), &dir)
                .map_err(|e| crate::model::ModelError::Invalid {
                    key: format!("row {} ({}, {} N)", r.line, r.config_id, r.load_n),
                    reason: e.to_string(),
                })?;
            r.effort = Effort::Torque(c.tau);
        }
        Ok(out)
    }

    /// Reads `path` and, when it exists, the sidecar `<stem>.meta.yaml` beside it.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut d = Self::parse(&text, &path.display().to_string())?;
        let meta_path = meta_path(path);
        if meta_path.exists() {
            let t = std::fs::read_to_string(&meta_path).map_err(|source| DatasetError::Io {
                path: meta_path.clone(),
                source,
            })?;
            d.meta = Some(parse_meta(&t, &meta_path)?);
        }
        Ok(d)
    }

    /// Parses CSV text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, DatasetError> {
        let bad = |line: usize, column: Option<&str>, reason: String| DatasetError::Malformed {
            origin: origin.to_string(),
            line,
            column: column.map(str::to_string),
            reason,
        };
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let header = rdr
            .headers()
            .map_err(|e| bad(1, None, e.to_string()))?
            .clone();
        let find = |name: &str| header.iter().position(|h| h == name);
        let mut need = vec!["config_id".to_string(), "load_n".to_string()];
        need.extend((1..=6).map(|j| format!("q{j}")));
        need.extend(POSE_COLS.iter().map(|s| s.to_string()));
        for n in &need {
            if find(n).is_none() {
                return Err(bad(1, Some(n), "missing column".into()));
            }
        }
        let has_tau = (1..=6).all(|j| find(&format!("tau{j}")).is_some());
        let has_i = (1..=6).all(|j| find(&format!("i{j}")).is_some());
        let effort_prefix = match (has_tau, has_i) {
            (true, _) => "tau",
            (false, true) => "i",
            (false, false) => {
                return Err(bad(
                    1,
                    None,
                    "needs joint torques `tau1..tau6` (N·m) or motor currents `i1..i6` (A)".into(),
                ));
            }
        };
        for (k, h) in header.iter().enumerate() {
            if header.iter().take(k).any(|p| p == h) {
                return Err(bad(1, Some(h), "duplicate column".into()));
            }
        }
        let idx = |name: &str| find(name).unwrap_or(usize::MAX);
        let has_dir = (1..=6).all(|j| find(&format!("dir{j}")).is_some());
        let has_prev = (1..=6).all(|j| find(&format!("prev_q{j}")).is_some());
        if !has_dir && (1..=6).any(|j| find(&format!("dir{j}")).is_some()) {
            return Err(bad(
                1,
                None,
                "approach directions need all of `dir1..dir6`".into(),
            ));
        }
        if !has_prev && (1..=6).any(|j| find(&format!("prev_q{j}")).is_some()) {
            return Err(bad(
                1,
                None,
                "previous configurations need all of `prev_q1..prev_q6` (rad)".into(),
            ));
        }
        let has_temp = find("temp_c").is_some();
        let mut rows = Vec::new();
        for rec in rdr.records() {
            let rec = rec.map_err(|e| {
                let line = e.position().map(|p| p.line() as usize).unwrap_or(0);
                bad(line, None, e.to_string())
            })?;
            let line = rec.position().map(|p| p.line() as usize).unwrap_or(0);
            if rec.len() != header.len() {
                return Err(bad(
                    line,
                    None,
                    format!("{} fields, the header has {}", rec.len(), header.len()),
                ));
            }
            let num = |name: &str, unit: &str, max: f64| -> Result<f64, DatasetError> {
                let s = rec.get(idx(name)).unwrap_or("");
                let v: f64 = s.parse().map_err(|_| {
                    bad(line, Some(name), format!("`{s}` is not a number ({unit})"))
                })?;
                if !v.is_finite() || v.abs() > max {
                    return Err(bad(
                        line,
                        Some(name),
                        format!("{v} {unit} is not finite or beyond ±{max} {unit}"),
                    ));
                }
                Ok(v)
            };
            let config_id = rec.get(idx("config_id")).unwrap_or("").to_string();
            if config_id.is_empty() {
                return Err(bad(
                    line,
                    Some("config_id"),
                    "empty configuration id".into(),
                ));
            }
            let load_n = num("load_n", "N", 1e5)?;
            if load_n < 0.0 {
                return Err(bad(
                    line,
                    Some("load_n"),
                    format!("a hung load is ≥ 0 N, got {load_n}"),
                ));
            }
            let mut q = [0.0; 6];
            for j in 0..6 {
                q[j] = num(&format!("q{}", j + 1), "rad", MAX_ANGLE)?;
            }
            let mut e = [0.0; 6];
            for j in 0..6 {
                e[j] = if effort_prefix == "tau" {
                    num(&format!("tau{}", j + 1), "N·m", MAX_TORQUE)?
                } else {
                    num(&format!("i{}", j + 1), "A", MAX_CURRENT)?
                };
            }
            let effort = if effort_prefix == "tau" {
                Effort::Torque(e)
            } else {
                Effort::Current(e)
            };
            let mut p = [0.0; 7];
            for (k, c) in POSE_COLS.iter().enumerate() {
                p[k] = num(c, if k < 3 { "m" } else { "" }, MAX_COORD)?;
            }
            let norm = (p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]).sqrt();
            if (norm - 1.0).abs() > 1e-6 {
                return Err(bad(
                    line,
                    Some("qw"),
                    format!("qw,qx,qy,qz must be a unit quaternion; its norm is {norm}"),
                ));
            }
            let mut direction = [0i8; 6];
            if has_dir {
                for (j, d) in direction.iter_mut().enumerate() {
                    let name = format!("dir{}", j + 1);
                    let v = num(&name, "", 1.0)?;
                    if v != v.round() {
                        return Err(bad(
                            line,
                            Some(&name),
                            format!("a direction is -1, 0 or 1, got {v}"),
                        ));
                    }
                    *d = v as i8;
                }
            } else if has_prev {
                for (j, d) in direction.iter_mut().enumerate() {
                    let prev = num(&format!("prev_q{}", j + 1), "rad", MAX_ANGLE)?;
                    let step = q[j] - prev;
                    *d = if step > 1e-9 {
                        1
                    } else if step < -1e-9 {
                        -1
                    } else {
                        0
                    };
                }
            }
            let temperature_c = if has_temp {
                let t = num("temp_c", "°C", 1e3)?;
                if !(-50.0..=150.0).contains(&t) {
                    return Err(bad(
                        line,
                        Some("temp_c"),
                        format!("{t} °C is outside -50…150 °C"),
                    ));
                }
                Some(t)
            } else {
                None
            };
            rows.push(Row {
                config_id,
                load_n,
                q,
                effort,
                pose: frame_from_pose([p[0], p[1], p[2]], [p[3], p[4], p[5], p[6]]),
                direction,
                temperature_c,
                line,
            });
        }
        if rows.is_empty() {
            return Err(bad(2, None, "no data rows".into()));
        }
        Ok(Self { rows, meta: None })
    }

    /// The CSV text of this dataset (torques as `tau*`, currents as `i*`; all rows must agree).
    pub fn to_csv(&self) -> String {
        let currents = matches!(
            self.rows.first().map(|r| r.effort),
            Some(Effort::Current(_))
        );
        let p = if currents { "i" } else { "tau" };
        let dirs = self.rows.iter().any(|r| r.direction != [0; 6]);
        let temps = !self.rows.is_empty() && self.rows.iter().all(|r| r.temperature_c.is_some());
        let mut s = format!(
            "config_id,load_n,q1,q2,q3,q4,q5,q6,{p}1,{p}2,{p}3,{p}4,{p}5,{p}6,x,y,z,qw,qx,qy,qz{}{}\n",
            if dirs {
                ",dir1,dir2,dir3,dir4,dir5,dir6"
            } else {
                ""
            },
            if temps { ",temp_c" } else { "" },
        );
        for r in &self.rows {
            let e = match r.effort {
                Effort::Torque(t) | Effort::Current(t) => t,
            };
            let (pos, quat) = pose_parts(&r.pose);
            let nums: Vec<String> = std::iter::once(r.load_n)
                .chain(r.q)
                .chain(e)
                .chain(pos)
                .chain(quat)
                .map(|v| format!("{v:?}"))
                .collect();
            s.push_str(&r.config_id);
            s.push(',');
            s.push_str(&nums.join(","));
            if dirs {
                for d in r.direction {
                    s.push_str(&format!(",{d}"));
                }
            }
            if let (true, Some(t)) = (temps, r.temperature_c) {
                s.push_str(&format!(",{t:?}"));
            }
            s.push('\n');
        }
        s
    }

    /// Writes the CSV and, when there is one, the sidecar beside it.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_csv()).map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if let Some(meta) = &self.meta {
            let mp = meta_path(path);
            let text = serde_yaml::to_string(meta).unwrap_or_default();
            std::fs::write(&mp, text).map_err(|source| DatasetError::Io { path: mp, source })?;
        }
        Ok(())
    }

    /// Row indices grouped by (configuration, load), in first-appearance order.
    pub fn groups(&self) -> Vec<Vec<usize>> {
        let mut order: Vec<(String, u64)> = Vec::new();
        let mut map: BTreeMap<(String, u64), Vec<usize>> = BTreeMap::new();
        for (i, r) in self.rows.iter().enumerate() {
            let key = (r.config_id.clone(), r.load_n.to_bits());
            if !map.contains_key(&key) {
                order.push(key.clone());
            }
            map.entry(key).or_default().push(i);
        }
        order.into_iter().filter_map(|k| map.remove(&k)).collect()
    }

    /// Distinct loads, ascending, N.
    pub fn loads(&self) -> Vec<f64> {
        let mut l: Vec<f64> = self.rows.iter().map(|r| r.load_n).collect();
        l.sort_by(f64::total_cmp);
        l.dedup();
        l
    }

    /// Pooled scatter of repeat measurements: the rms distance of measured positions from
    /// their (configuration, load) group mean, m (`None` without repeats).
    pub fn repeat_scatter_m(&self) -> Option<f64> {
        let (mut ss, mut dof) = (0.0, 0usize);
        for g in self.groups() {
            if g.len() < 2 {
                continue;
            }
            let mean = g
                .iter()
                .map(|&i| self.rows[i].pose.translation.vector)
                .sum::<nalgebra::Vector3<f64>>()
                / g.len() as f64;
            ss += g
                .iter()
                .map(|&i| (self.rows[i].pose.translation.vector - mean).norm_squared())
                .sum::<f64>();
            dof += g.len() - 1;
        }
        (dof > 0).then(|| (ss / dof as f64).sqrt())
    }
}

/// `cal.csv` → `cal.meta.yaml`.
pub fn meta_path(csv: &Path) -> PathBuf {
    let stem = csv
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    csv.with_file_name(format!("{stem}.meta.yaml"))
}

/// Reads a sidecar (`<stem>.meta.yaml`) on its own, checked as [`Dataset::load`] checks it.
pub fn load_meta(path: &Path) -> Result<Meta, DatasetError> {
    let t = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_meta(&t, path)
}

fn parse_meta(text: &str, path: &Path) -> Result<Meta, DatasetError> {
    let m: Meta = serde_yaml::from_str(text).map_err(|e| DatasetError::Meta {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if let Some(t) = &m.tool {
        crate::model::robot::frame_from_data("tool", t).map_err(|e| DatasetError::Meta {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    }
    if let Some(n) = &m.noise
        && !(n.position_m.is_finite()
            && n.position_m >= 0.0
            && n.resolver_arcmin.is_finite()
            && n.resolver_arcmin >= 0.0)
    {
        return Err(DatasetError::Meta {
            path: path.to_path_buf(),
            message: "noise: position_m must be ≥ 0 m and resolver_arcmin ≥ 0 arcmin".into(),
        });
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str =
        "config_id,load_n,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6,x,y,z,qw,qx,qy,qz\n";
    const ROW: &str = "c01,22,0.1,0.5,1.2,0,0.8,0,0,-90,-20,0,-3,0,0.6,0.1,0.4,1,0,0,0\n";

    fn err(text: &str) -> String {
        Dataset::parse(text, "cal.csv").unwrap_err().to_string()
    }

    #[test]
    fn model_torques_replace_the_currents_and_carry_the_hung_load_at_the_tool() {
        // the nominal bodies on the seed paper's springs (J2, J3, J5), N·m/rad and N·m/rad³
        let mut d = crate::model::Model::nominal().data().clone();
        for (j, klin, kcub) in [
            (1, 1.98e4, 3.35e7),
            (2, 1.27e4, 1.46e7),
            (4, 2.56e3, 3.83e7),
        ] {
            d.stiffness[j] = Some(crate::model::Stiffness { klin, kcub });
        }
        let m = crate::model::Model::new(d).unwrap();
        let g = m.gravity();
        // the link where the model puts it: the resolvers read it plus the deflection
        let q_link = [0.0, 0.5, 1.2, 0.0, 0.8, 0.0];
        let row = |load_n: f64| {
            let load = crate::model::ExternalLoad::hung(load_n, &g);
            let c = m
                .compensate(&q_link, crate::model::Torques::Gravity(&load), &[0.0; 6])
                .unwrap();
            Row {
                config_id: "c".into(),
                load_n,
                q: c.q_motor,
                effort: Effort::Current([9.0; 6]),
                pose: Frame::identity(),
                direction: [0; 6],
                temperature_c: None,
                line: 0,
            }
        };
        let d = Dataset {
            rows: vec![row(0.0), row(44.0)],
            ..Default::default()
        }
        .with_model_torques(&m)
        .unwrap();
        let (Effort::Torque(t0), Effort::Torque(t44)) = (d.rows[0].effort, d.rows[1].effort) else {
            panic!("torques expected: {:?}", d.rows[0].effort);
        };
        // at the link angles, not at the resolvers' (which sag by the deflection)
        for (t, load_n) in [(t0, 0.0), (t44, 44.0)] {
            let at_link = m.static_torques(&q_link, &crate::model::ExternalLoad::hung(load_n, &g));
            for j in 0..6 {
                assert!(
                    (t[j] - at_link[j]).abs() < 1e-6,
                    "{load_n} N, J{}: {t:?}",
                    j + 1
                );
            }
        }
        // the resolvers' angles are mrad away: there the J5 torque of 44 N would be off
        let at_motor = m.static_torques(&row(44.0).q, &crate::model::ExternalLoad::hung(44.0, &g));
        assert!((at_motor[4] - t44[4]).abs() > 1e-3, "{at_motor:?} {t44:?}");
        // 44 N more at the tool: J2 carries 44 N × the tool's horizontal reach from its axis
        let tip = m.fk(&q_link).translation.vector;
        let reach = (tip.x * tip.x + tip.y * tip.y).sqrt();
        assert!(
            ((t44[1] - t0[1]).abs() - 44.0 * reach).abs() < 1e-6,
            "{t0:?} {t44:?}"
        );
    }

    #[test]
    fn a_good_file_parses_and_round_trips() {
        let d = Dataset::parse(&format!("{HEAD}{ROW}{ROW}"), "cal.csv").unwrap();
        assert_eq!(d.rows.len(), 2);
        assert_eq!(d.rows[1].line, 3);
        assert_eq!(d.groups(), vec![vec![0, 1]]);
        assert_eq!(
            Dataset::parse(&d.to_csv(), "again").unwrap().rows[0].effort,
            d.rows[0].effort
        );
        // columns in any order, currents instead of torques
        let alt = "x,y,z,qw,qx,qy,qz,config_id,load_n,q1,q2,q3,q4,q5,q6,i1,i2,i3,i4,i5,i6\n0.6,0.1,0.4,1,0,0,0,a,0,0,0,0,0,0,0,1,2,3,4,5,6\n";
        let d = Dataset::parse(alt, "alt.csv").unwrap();
        assert_eq!(
            d.rows[0].effort,
            Effort::Current([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        );
    }

    #[test]
    fn malformed_rows_name_file_line_column_and_reason() {
        assert_eq!(
            err(&format!("{HEAD}{ROW}{}", ROW.replace("0.5,1.2", "0.5,abc"))),
            "cal.csv:3: column `q3`: `abc` is not a number (rad)"
        );
        assert!(
            err(&format!("{HEAD}{}", ROW.replace(",22,", ",-22,")))
                .contains("cal.csv:2: column `load_n`: a hung load is ≥ 0 N")
        );
        assert!(
            err(&format!(
                "{HEAD}{}",
                ROW.replace("1,0,0,0\n", "1,0.1,0,0\n")
            ))
            .contains("column `qw`: qw,qx,qy,qz must be a unit quaternion")
        );
        assert!(err(&format!("{HEAD}{}", ROW.replace(",0.8,", ",NaN,"))).contains("column `q5`"));
        assert!(err(&format!("{HEAD}c,1,2\n")).contains("cal.csv:2"));
        assert!(err(&HEAD.replace("q4,", "")).contains("column `q4`: missing column"));
        assert!(err(&HEAD.replace("tau", "torque")).contains("tau1..tau6"));
        assert!(err(HEAD).contains("no data rows"));
        assert!(
            err(&format!("{HEAD}{}", ROW.replace("c01", ""))).contains("empty configuration id")
        );
        assert!(
            err(&format!("{HEAD}{}", ROW.replace(",-90,", ",-9e9,"))).contains("column `tau2`")
        );
    }

    #[test]
    fn sidecar_is_read_beside_the_csv_and_validated() {
        let dir = std::env::temp_dir().join(format!("pa10-ds-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("cal.csv");
        std::fs::write(&csv, format!("{HEAD}{ROW}")).unwrap();
        std::fs::write(dir.join("cal.meta.yaml"), "instrument: CMM\ntool:\n  translation: [0.0, 0.0, 0.35]\n  quaternion: [1.0, 0.0, 0.0, 0.0]\nnoise: {position_m: 12.1e-6, resolver_arcmin: 0.64}\n").unwrap();
        let d = Dataset::load(&csv).unwrap();
        let m = d.meta.unwrap();
        assert_eq!(m.tool.unwrap().translation, [0.0, 0.0, 0.35]);
        assert_eq!(m.noise.unwrap().position_m, 12.1e-6);
        std::fs::write(
            dir.join("cal.meta.yaml"),
            "tool: {translation: [0, 0, 0.35], quaternion: [2, 0, 0, 0]}\n",
        )
        .unwrap();
        assert!(
            Dataset::load(&csv)
                .unwrap_err()
                .to_string()
                .contains("unit quaternion")
        );
        std::fs::write(dir.join("cal.meta.yaml"), "instrumnet: CMM\n").unwrap();
        assert!(
            Dataset::load(&csv)
                .unwrap_err()
                .to_string()
                .contains("unknown field `instrumnet`")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
