//! Gathering a calibration dataset from a running daemon: the pose list it is driven
//! through, the robot-side samples it records (resolver angles and motor currents per pose),
//! and merging those with the instrument's measurements by pose id into a [`Dataset`].
//!
//! Plain data and text in, plain data out: the driving itself (`pa10 collect`, `pa10 demo`)
//! lives in the binary.
//!
//! File formats (CSV with a header, SI units):
//! - pose list: `config_id,load_n,q1..q6` — link-side joint targets, rad; the load hung at
//!   the tool while measuring, N;
//! - robot samples: `config_id,load_n,q1..q6,i1..i6` — resolver angles (rad) and motor
//!   currents (A), one row per sample;
//! - instrument: `config_id,load_n,x,y,z,qw,qx,qy,qz` — the target pose in the instrument
//!   frame, m and unit quaternion, one row per sample, in the same order as the robot's
//!   samples of that pose.

use std::collections::BTreeMap;

use super::dataset::{Dataset, Effort, Row};
use crate::model::{Frame, frame_from_pose, pose_parts};

/// One joint target of the pose list.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseTarget {
    /// Pose id.
    pub config_id: String,
    /// Load hung at the tool, N.
    pub load_n: f64,
    /// Link-side joint targets, rad.
    pub q: [f64; 6],
}

/// What the robot reported at one pose.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSample {
    /// Pose id.
    pub config_id: String,
    /// Load hung at the tool, N.
    pub load_n: f64,
    /// Resolver angles, rad.
    pub q: [f64; 6],
    /// Motor currents, A.
    pub current: [f64; 6],
}

/// What the instrument measured at one pose.
#[derive(Debug, Clone, PartialEq)]
pub struct InstrumentSample {
    /// Pose id.
    pub config_id: String,
    /// Load hung at the tool, N.
    pub load_n: f64,
    /// Target pose in the instrument frame.
    pub pose: Frame,
}

/// Why a file or a merge was rejected; nothing is written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CollectError {
    /// A line is malformed.
    #[error("{origin}:{line}: {reason}")]
    Malformed {
        /// The file.
        origin: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Robot and instrument samples do not pair up.
    #[error("pose `{config_id}` at {load_n} N: {reason}")]
    Unpaired {
        /// The pose id.
        config_id: String,
        /// Its load, N.
        load_n: f64,
        /// What does not match.
        reason: String,
    },
}

/// Reads a CSV with the named numeric columns after `config_id`; returns (line, id, values).
fn read_rows(
    text: &str,
    origin: &str,
    cols: &[String],
) -> Result<Vec<(usize, String, Vec<f64>)>, CollectError> {
    let bad = |line: usize, reason: String| CollectError::Malformed {
        origin: origin.to_string(),
        line,
        reason,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = rdr.headers().map_err(|e| bad(1, e.to_string()))?.clone();
    let pos = |n: &str| header.iter().position(|h| h == n);
    let id_col = pos("config_id").ok_or_else(|| bad(1, "missing column `config_id`".into()))?;
    let idx: Vec<usize> = cols
        .iter()
        .map(|c| pos(c).ok_or_else(|| bad(1, format!("missing column `{c}`"))))
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for rec in rdr.records() {
        let rec =
            rec.map_err(|e| bad(e.position().map_or(0, |p| p.line() as usize), e.to_string()))?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        let id = rec.get(id_col).unwrap_or("").to_string();
        if id.is_empty() {
            return Err(bad(line, "empty `config_id`".into()));
        }
        let mut v = Vec::with_capacity(idx.len());
        for (k, &i) in idx.iter().enumerate() {
            let s = rec.get(i).unwrap_or("");
            let x: f64 = s
                .parse()
                .map_err(|_| bad(line, format!("`{}`: `{s}` is not a number", cols[k])))?;
            if !x.is_finite() {
                return Err(bad(line, format!("`{}` must be finite", cols[k])));
            }
            v.push(x);
        }
        out.push((line, id, v));
    }
    if out.is_empty() {
        return Err(bad(2, "no data rows".into()));
    }
    Ok(out)
}

fn names(prefix: &str) -> Vec<String> {
    (1..=6).map(|j| format!("{prefix}{j}")).collect()
}

fn check_load(origin: &str, line: usize, load: f64) -> Result<f64, CollectError> {
    if (0.0..=500.0).contains(&load) {
        Ok(load)
    } else {
        Err(CollectError::Malformed {
            origin: origin.to_string(),
            line,
            reason: format!("`load_n` must be within 0…500 N, got {load}"),
        })
    }
}

/// Parses a pose list.
pub fn parse_poses(text: &str, origin: &str) -> Result<Vec<PoseTarget>, CollectError> {
    let mut cols = vec!["load_n".to_string()];
    cols.extend(names("q"));
    read_rows(text, origin, &cols)?
        .into_iter()
        .map(|(line, id, v)| {
            Ok(PoseTarget {
                config_id: id,
                load_n: check_load(origin, line, v[0])?,
                q: std::array::from_fn(|j| v[1 + j]),
            })
        })
        .collect()
}

/// Parses robot samples.
pub fn parse_robot(text: &str, origin: &str) -> Result<Vec<RobotSample>, CollectError> {
    let mut cols = vec!["load_n".to_string()];
    cols.extend(names("q"));
    cols.extend(names("i"));
    read_rows(text, origin, &cols)?
        .into_iter()
        .map(|(line, id, v)| {
            Ok(RobotSample {
                config_id: id,
                load_n: check_load(origin, line, v[0])?,
                q: std::array::from_fn(|j| v[1 + j]),
                current: std::array::from_fn(|j| v[7 + j]),
            })
        })
        .collect()
}

/// Parses instrument measurements.
pub fn parse_instrument(text: &str, origin: &str) -> Result<Vec<InstrumentSample>, CollectError> {
    let cols: Vec<String> = ["load_n", "x", "y", "z", "qw", "qx", "qy", "qz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    read_rows(text, origin, &cols)?
        .into_iter()
        .map(|(line, id, v)| {
            let n = (v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]).sqrt();
            if (n - 1.0).abs() > 1e-6 {
                return Err(CollectError::Malformed {
                    origin: origin.to_string(),
                    line,
                    reason: format!("qw,qx,qy,qz must be a unit quaternion; its norm is {n}"),
                });
            }
            Ok(InstrumentSample {
                config_id: id,
                load_n: check_load(origin, line, v[0])?,
                pose: frame_from_pose([v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]]),
            })
        })
        .collect()
}

/// CSV text: `header`, then per row its id and numbers (full precision).
fn csv<'a>(header: &str, rows: impl Iterator<Item = (&'a str, Vec<f64>)>) -> String {
    let mut s = String::from(header);
    for (id, nums) in rows {
        let nums: Vec<String> = nums.iter().map(|v| format!("{v:?}")).collect();
        s.push_str(&format!("{id},{}\n", nums.join(",")));
    }
    s
}

/// A pose list as CSV text (what [`parse_poses`] reads).
pub fn poses_csv(targets: &[PoseTarget]) -> String {
    let rows = targets.iter().map(|t| {
        let nums = std::iter::once(t.load_n).chain(t.q).collect();
        (t.config_id.as_str(), nums)
    });
    csv("config_id,load_n,q1,q2,q3,q4,q5,q6\n", rows)
}

/// Robot samples as CSV text.
pub fn robot_csv(samples: &[RobotSample]) -> String {
    let rows = samples.iter().map(|r| {
        let nums = std::iter::once(r.load_n)
            .chain(r.q)
            .chain(r.current)
            .collect();
        (r.config_id.as_str(), nums)
    });
    csv(
        "config_id,load_n,q1,q2,q3,q4,q5,q6,i1,i2,i3,i4,i5,i6\n",
        rows,
    )
}

/// Instrument samples as CSV text.
pub fn instrument_csv(samples: &[InstrumentSample]) -> String {
    let rows = samples.iter().map(|m| {
        let (p, q) = pose_parts(&m.pose);
        let nums = std::iter::once(m.load_n).chain(p).chain(q).collect();
        (m.config_id.as_str(), nums)
    });
    csv("config_id,load_n,x,y,z,qw,qx,qy,qz\n", rows)
}

/// Pairs the k-th robot sample of each (pose id, load) with the k-th instrument sample of
/// the same pose into dataset rows (currents as the effort). Every pose must have as many
/// instrument samples as robot samples.
pub fn merge(
    robot: &[RobotSample],
    instrument: &[InstrumentSample],
) -> Result<Dataset, CollectError> {
    let key = |id: &str, l: f64| (id.to_string(), l.to_bits());
    let mut meas: BTreeMap<(String, u64), Vec<&InstrumentSample>> = BTreeMap::new();
    for m in instrument {
        meas.entry(key(&m.config_id, m.load_n)).or_default().push(m);
    }
    let mut used: BTreeMap<(String, u64), usize> = BTreeMap::new();
    let mut rows = Vec::with_capacity(robot.len());
    for r in robot {
        let k = key(&r.config_id, r.load_n);
        let n = used.entry(k.clone()).or_insert(0);
        let Some(m) = meas.get(&k).and_then(|v| v.get(*n)) else {
            return Err(CollectError::Unpaired {
                config_id: r.config_id.clone(),
                load_n: r.load_n,
                reason: format!("robot sample {} has no instrument measurement", *n + 1),
            });
        };
        *n += 1;
        rows.push(Row {
            config_id: r.config_id.clone(),
            load_n: r.load_n,
            q: r.q,
            effort: Effort::Current(r.current),
            pose: m.pose,
            direction: [0; 6],
            temperature_c: None,
            line: 0,
        });
    }
    for (k, v) in &meas {
        let n = used.get(k).copied().unwrap_or(0);
        if v.len() != n {
            return Err(CollectError::Unpaired {
                config_id: k.0.clone(),
                load_n: f64::from_bits(k.1),
                reason: format!("{} instrument measurements but {n} robot samples", v.len()),
            });
        }
    }
    Ok(Dataset { rows, meta: None })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_pairs_by_pose_and_order_and_names_what_does_not_pair() {
        let robot = parse_robot(
            "config_id,load_n,q1,q2,q3,q4,q5,q6,i1,i2,i3,i4,i5,i6\n\
             a,0,0,0.1,1,0,1,0,0,1,0.5,0,0.1,0\n\
             a,0,0,0.1,1,0,1,0,0,1.1,0.5,0,0.1,0\n\
             b,22,0.2,0.1,1,0,1,0,0,2,0.5,0,0.1,0\n",
            "r",
        )
        .unwrap();
        let inst_text = "config_id,load_n,x,y,z,qw,qx,qy,qz\n\
                         b,22,0.5,0.1,0.2,1,0,0,0\n\
                         a,0,0.6,0.0,0.2,1,0,0,0\n\
                         a,0,0.6001,0.0,0.2,1,0,0,0\n";
        let inst = parse_instrument(inst_text, "i").unwrap();
        let d = merge(&robot, &inst).unwrap();
        assert_eq!(d.rows.len(), 3);
        assert!((d.rows[1].pose.translation.x - 0.6001).abs() < 1e-12);
        assert_eq!(
            d.rows[1].effort,
            Effort::Current([0.0, 1.1, 0.5, 0.0, 0.1, 0.0])
        );
        // round trip through text
        assert_eq!(parse_robot(&robot_csv(&robot), "r2").unwrap(), robot);
        let poses = vec![PoseTarget {
            config_id: "p01".into(),
            load_n: 22.0,
            q: [0.1, -0.2, 1.3, 0.0, 0.9, 1e-17],
        }];
        assert_eq!(parse_poses(&poses_csv(&poses), "p").unwrap(), poses);
        assert_eq!(
            parse_instrument(&instrument_csv(&inst), "i2")
                .unwrap()
                .len(),
            3
        );
        // one measurement short
        let err = merge(&robot, &inst[..2]).unwrap_err().to_string();
        assert!(err.contains("pose `a` at 0 N: robot sample 2"), "{err}");
        // one too many
        let mut extra = inst.clone();
        extra.push(inst[0].clone());
        let err = merge(&robot, &extra).unwrap_err().to_string();
        assert!(
            err.contains("2 instrument measurements but 1 robot samples"),
            "{err}"
        );
        // malformed lines name line and column
        let err = parse_poses(
            "config_id,load_n,q1,q2,q3,q4,q5,q6\nx,0,0,0,zero,0,0,0\n",
            "p",
        )
        .unwrap_err()
        .to_string();
        assert_eq!(err, "p:2: `q3`: `zero` is not a number");
        let err = parse_instrument(
            "config_id,load_n,x,y,z,qw,qx,qy,qz\nx,0,0,0,0,2,0,0,0\n",
            "m",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("unit quaternion"), "{err}");
    }
}
