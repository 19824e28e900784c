//! The vocabulary of a hung load's effects *outside the joints* — a link that bends under the
//! moment it carries, a tool or fixture that sags along gravity, an unaccounted mass at the
//! tool: [`LoadEffects`], read from a model file's records and range-checked. Their arithmetic
//! on a model is `loaded.rs`'s; this leaf holds only the data, so the model, the file and the
//! arithmetic can all name it.
//!
//! A model file carries them as `discovered` records that `pa10 discover` marked
//! `compensated: true` (`tool_sag.compliance` m/N, `link_bending[row].compliance`
//! rad/(N·m), `payload_mass_error.mass` kg); records marked otherwise are reports only.

use super::file::EffectRecord;

/// Largest accepted tool sag, m/N (9 mm at 90 N: anything larger is not a small effect).
pub const MAX_TOOL_SAG: f64 = 1e-4;
/// Largest accepted link bending compliance, rad/(N·m).
pub const MAX_BENDING: f64 = 1e-4;
/// Largest accepted unaccounted tool mass, kg (either sign).
pub const MAX_PAYLOAD_ERROR_KG: f64 = 20.0;

/// `v` within ±`max` (in `unit`) and finite, else `(key, reason)`.
fn within(key: String, v: f64, max: f64, unit: &str) -> Result<(), (String, String)> {
    if v.is_finite() && v.abs() <= max {
        Ok(())
    } else {
        Err((
            key,
            format!("must be finite and within ±{max:e} {unit}, got {v}"),
        ))
    }
}

/// Load effects outside the joints; all zero for a model without them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoadEffects {
    /// Sag of the tool point along gravity per newton of hung load, m/N.
    pub tool_sag: f64,
    /// Bending compliance per DH row (rotation about the link's midpoint per N·m of the
    /// bending moment it carries), rad/(N·m).
    pub bending: [f64; 6],
    /// Mass at the tool the declared payload lacks, kg (loads the bending links).
    pub payload_kg: f64,
}

impl LoadEffects {
    /// Whether every effect is zero (the model is rigid outside its joints).
    pub fn is_empty(&self) -> bool {
        self.tool_sag == 0.0 && self.payload_kg == 0.0 && self.bending.iter().all(|c| *c == 0.0)
    }

    /// Refuses a value out of its range (the limits above): `(key, reason)` naming the
    /// effect's parameter (`tool_sag.compliance`, `link_bending[row].compliance`,
    /// `payload_mass_error.mass`).
    pub fn check(&self) -> Result<(), (String, String)> {
        within(
            "tool_sag.compliance".into(),
            self.tool_sag,
            MAX_TOOL_SAG,
            "m/N",
        )?;
        within(
            "payload_mass_error.mass".into(),
            self.payload_kg,
            MAX_PAYLOAD_ERROR_KG,
            "kg",
        )?;
        for (j, c) in self.bending.iter().enumerate() {
            within(
                format!("link_bending[{}].compliance", j + 1),
                *c,
                MAX_BENDING,
                "rad/(N·m)",
            )?;
        }
        Ok(())
    }

    /// The compensated `discovered` records of a model file; a record's parameter out of
    /// range is refused as `(key, reason)` (`discovered[i].params.compliance`).
    pub fn from_records(records: &[EffectRecord]) -> Result<Self, (String, String)> {
        let mut out = Self::default();
        for (i, r) in records.iter().enumerate().filter(|(_, r)| r.compensated) {
            let param = |name: &str, max: f64, unit: &str| -> Result<f64, (String, String)> {
                let key = format!("discovered[{i}].params.{name}");
                let v = *r.params.get(name).ok_or_else(|| {
                    (
                        key.clone(),
                        format!("missing: a compensated `{}` needs it ({unit})", r.name),
                    )
                })?;
                within(key, v, max, unit).map(|()| v)
            };
            match r.name.as_str() {
                "tool_sag" => out.tool_sag = param("compliance", MAX_TOOL_SAG, "m/N")?,
                "payload_mass_error" => {
                    out.payload_kg = param("mass", MAX_PAYLOAD_ERROR_KG, "kg")?;
                }
                "link_bending" => {
                    let row = r.joint.filter(|j| (1..=6).contains(j)).ok_or_else(|| {
                        (
                            format!("discovered[{i}].joint"),
                            "a link_bending record names its DH row, 1…6".to_string(),
                        )
                    })?;
                    out.bending[row - 1] = param("compliance", MAX_BENDING, "rad/(N·m)")?;
                }
                _ => {}
            }
        }
        Ok(out)
    }
}
