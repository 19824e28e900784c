//! The end of a discovery in words: the findings a repeatable component far above the
//! resolver's specification makes, whether the gap counts as closed, and the one plain
//! sentence that says so and why. A pure function of the final numbers.

use super::LackOfFit;
use crate::noise::Interval;

/// What the verdict is made from.
pub(super) struct Ending<'a> {
    /// Effects found (after pruning).
    pub(super) found: usize,
    /// The effect budget (`--max-effects`).
    pub(super) max_effects: usize,
    /// The final lack of fit (its combined p, and each stratum's, tested at half the
    /// level), and the significance level.
    pub(super) lack_of_fit: LackOfFit,
    pub(super) alpha: f64,
    /// Held-out RMS position error and the noise floor there, mm.
    pub(super) gap_mm: f64,
    pub(super) floor_mm: f64,
    /// Whether the generic dictionary was searched.
    pub(super) generic: bool,
    /// The repeatable resolver error (rad) where it is significant *and* its 95 % interval
    /// lies above [`super::REPEATABLE_EXCESS`]× the specification: at the starting model
    /// and at the final model, each with the words for when.
    pub(super) excess: [(&'a str, Option<Interval>); 2],
    /// The resolver's specified σ, arcmin.
    pub(super) resolver_arcmin: f64,
}

/// The findings, whether the gap is closed, and the verdict sentence.
pub(super) fn conclude(e: &Ending) -> (Vec<String>, bool, String) {
    let arcmin = crate::accuracy::ARCMIN;
    let spec_rad = e.resolver_arcmin * arcmin;
    let findings: Vec<String> = e
        .excess
        .iter()
        .filter_map(|(when, r)| r.map(|r| (when, r)))
        .map(|(when, r)| {
            format!(
                "at {when} the configurations' mean residuals repeat like a resolver error of {:.2} arcmin (95 % interval from {:.2}), {:.1}× the resolver's specified {:.2} arcmin: the model misses something that repeats per configuration (weights and floor use at most the specification)",
                r.value / arcmin,
                r.lo / arcmin,
                r.value / spec_rad,
                e.resolver_arcmin
            )
        })
        .collect();
    let ratio = e.gap_mm / e.floor_mm;
    let lof = &e.lack_of_fit;
    let fits = lof.p_value >= e.alpha;
    let within_floor = e.gap_mm <= super::GAP_CLOSED * e.floor_mm;
    // Still there at the final model, the excess keeps the gap open.
    let gap_closed = fits && within_floor && e.excess[1].1.is_none();
    let verdict = if e.found == 0 && gap_closed {
        "nothing significant is missing: the model fits to the noise floor".to_string()
    } else if gap_closed {
        format!(
            "the gap is closed: held-out {:.3} mm, {ratio:.2}× the noise floor",
            e.gap_mm
        )
    } else {
        let why = if fits && within_floor {
            "the configurations still show a repeatable error far above the resolver's specification: the model misses something that repeats per configuration".to_string()
        } else if fits {
            format!(
                "the lack of fit is no longer significant, but the held-out error is still {ratio:.2}× the noise floor (more than {}×): the held-out data differ from the training data in a way the model does not capture (e.g. loads or configurations outside the training range)",
                super::GAP_CLOSED
            )
        } else if e.found >= e.max_effects {
            format!(
                "the lack of fit is still significant after the effect budget ({}) was spent",
                e.max_effects
            )
        } else if e.generic
            && lof.between.p_value >= e.alpha / 2.0
            && lof.within.p_value < e.alpha / 2.0
        {
            "the lack of fit is still significant, but only within configurations (between configurations the model fits): how the readings change with the load at one configuration is not what the model says — the torques it was given (a drive's friction held at rest in the currents), readings taken before the arm was still, or a load-dependent effect that neither the library nor the generic dictionary holds".to_string()
        } else if e.generic {
            "the lack of fit is still significant and neither the library nor the generic dictionary has a term that passes every test: something is missing that this tool cannot name".to_string()
        } else {
            "the lack of fit is still significant and no candidate passes every test".to_string()
        };
        format!("the gap is NOT closed: {why}")
    };
    (findings, gap_closed, verdict)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lack of fit with these p-values between and within configurations, combined as
    /// `scoring::lack_of_fit` combines them (twice the smaller).
    fn lof([between, within]: [f64; 2]) -> LackOfFit {
        let stratum = |p_value| crate::discover::Stratum {
            chi2: 0.0,
            dof: 1.0,
            ratio: 0.0,
            p_value,
        };
        LackOfFit {
            between: stratum(between),
            within: stratum(within),
            p_value: (2.0 * between.min(within)).min(1.0),
        }
    }

    fn ending(p: f64, gap: f64, excess_end: Option<Interval>) -> Ending<'static> {
        Ending {
            found: 2,
            max_effects: 8,
            lack_of_fit: lof([p, p]),
            alpha: 0.01,
            gap_mm: gap,
            floor_mm: 0.2,
            generic: true,
            excess: [
                ("the starting model", None),
                ("the final model", excess_end),
            ],
            resolver_arcmin: 0.64,
        }
    }

    /// Closed only when the model fits, the held-out error is within 1.25× the floor and no
    /// repeatable excess is left; each other ending says why not.
    #[test]
    fn the_gap_is_closed_only_when_every_condition_holds() {
        let (f, closed, v) = conclude(&ending(0.5, 0.24, None));
        assert!(closed && f.is_empty(), "{v}");
        assert!(v.starts_with("the gap is closed: held-out 0.240 mm, 1.20×"));
        let (_, closed, v) = conclude(&ending(0.5, 0.26, None));
        assert!(!closed && v.contains("1.30× the noise floor"), "{v}");
        let (_, closed, v) = conclude(&ending(1e-6, 0.2, None));
        assert!(!closed && v.contains("cannot name"), "{v}");
        // the misfit only between the loads of a configuration: said so, not "cannot name"
        let within_only = Ending {
            lack_of_fit: lof([0.3, 5e-7]),
            ..ending(1e-6, 0.2, None)
        };
        let (_, closed, v) = conclude(&within_only);
        assert!(!closed && v.contains("only within configurations"), "{v}");
        assert!(!v.contains("cannot name"), "{v}");
        // between configurations too (or only there): "cannot name" stays
        for strata_p in [[1e-4, 1e-4], [1e-6, 0.3]] {
            let (_, _, v) = conclude(&Ending {
                lack_of_fit: lof(strata_p),
                ..ending(1e-6, 0.2, None)
            });
            assert!(v.contains("cannot name"), "{strata_p:?}: {v}");
        }
        let rep = Interval {
            value: 2.0 * crate::accuracy::ARCMIN,
            lo: 1.5 * crate::accuracy::ARCMIN,
            hi: 2.5 * crate::accuracy::ARCMIN,
        };
        let (f, closed, v) = conclude(&ending(0.5, 0.2, Some(rep)));
        assert!(!closed && v.contains("repeats per configuration"), "{v}");
        assert_eq!(f.len(), 1);
        assert!(f[0].starts_with("at the final model") && f[0].contains("2.00 arcmin"));
        assert!(
            f[0].contains("3.1× the resolver's specified 0.64"),
            "{}",
            f[0]
        );
    }
}
