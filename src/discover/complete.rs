//! Completing the model's springs where the held-out data reach beyond the training torques.
//!
//! A hardening spring's cubic term `Kcub·δ³` grows with the cube of the torque: on training
//! data whose loads stop at half the held-out ones it can be too small to pass the training
//! tests, and still be what the held-out prediction at the larger loads misses. The forward
//! selection judges candidates first on the training data, so it cannot take such a term.
//! This round asks the question the held-out data can answer, and only that one: for every
//! joint whose linear spring the model has (named or modelled) without its cubic term, and
//! whose held-out torques exceed the training torques by more than [`BEYOND`], does the
//! model refitted with the cubic term predict the held-out configurations better (the paired
//! test of the selection, Bonferroni over the round's candidates, the held-out RMS no larger),
//! with a hardening (`Kcub > 0`) stiffness? Nothing else is taken this way: an effect outside
//! the spring's own hierarchy must earn its place on the training data first.

use super::*;

/// The held-out torques on a joint must exceed the training's largest by this factor before
/// its spring is completed on held-out data.
pub(super) const BEYOND: f64 = 1.1;

/// Per joint, the largest |τ| of the training and of the held-out observations, N·m.
pub(super) fn torque_reach(lay: &Layout) -> [(f64, f64); 6] {
    let mut out = [(0.0f64, 0.0f64); 6];
    for b in &lay.blocks {
        for &i in &b.rows {
            for (j, o) in out.iter_mut().enumerate() {
                let t = lay.obs[i].tau[j].abs();
                if b.train {
                    o.0 = o.0.max(t);
                } else {
                    o.1 = o.1.max(t);
                }
            }
        }
    }
    out
}

/// The cubic terms a completion round may try: joints with a linear spring among `slots`
/// and no cubic term, whose held-out torques reach beyond [`BEYOND`] × the training's.
/// Empty without a holdout set (cross-validation folds never leave the training range).
pub(super) fn candidates(slots: &[Slot], lay: &Layout, only: Option<&[Kind]>) -> Vec<Effect> {
    if !lay.holdout || only.is_some_and(|o| !o.contains(&Kind::JointComplianceCubic)) {
        return Vec::new();
    }
    let reach = torque_reach(lay);
    (0..6)
        .filter(|&j| slots.contains(&Slot::Compliance(j)) && !slots.contains(&Slot::Kcub(j)))
        .filter(|&j| reach[j].1 > BEYOND * reach[j].0)
        .map(|j| Effect {
            kind: Kind::JointComplianceCubic,
            target: Some(j),
        })
        .collect()
}

/// A model refitted on a layout's data with its noise model re-estimated at the fit.
pub(super) struct Settled {
    pub(super) prob: Problem,
    pub(super) noise: NoiseReport,
    pub(super) cur: fit::Fitted,
    pub(super) lof: LackOfFit,
    pub(super) a_fit: DMatrix<f64>,
    /// Its prediction of the held-out configurations.
    pub(super) heldout: HeldOut,
}

/// Refits `slots` from `start`: the noise model at `start`, a balanced fit, the plain lack
/// of fit and the held-out error at the fit.
pub(super) fn settle(
    lay: &Layout,
    start: &EffectState,
    slots: &[Slot],
    prior: &fit::Prior,
) -> Result<Settled, DiscoverError> {
    let (mut prob, noise) = problem(lay, start, slots.len())?;
    let cur = fit::fit_balanced(&mut prob, start, slots, prior)?;
    let (lof, a_fit) = plain_lack_of_fit(&prob, &cur);
    let eqs = fold_eqs(&prob, &cur.lin, &lay.folds).with_prior(prior, slots, &cur.state);
    let cols: Vec<usize> = (0..slots.len()).collect();
    let heldout = heldout(&prob, &cur.lin, &eqs, &lay.folds, &cols);
    Ok(Settled {
        prob,
        noise,
        cur,
        lof,
        a_fit,
        heldout,
    })
}

/// One completion round over `cands` at the settled fit `st` of `slots`: every candidate
/// refitted (nonlinear, on `st.prob`'s weights) and compared with the settled model on the
/// held-out configurations. Returns the
/// candidates' scores (best held-out t first) and the index into `cands` of the one taken,
/// if any.
pub(super) fn round(
    st: &Settled,
    lay: &Layout,
    slots: &[Slot],
    prior_of: &dyn Fn(&[Slot]) -> fit::Prior,
    cands: &[Effect],
    alpha: f64,
) -> Result<(Vec<Score>, Option<usize>), DiscoverError> {
    let (prob, cur) = (&st.prob, &st.cur);
    let (base_costs, base_gap) = (&st.heldout.costs, st.heldout.gap_mm);
    let reach = torque_reach(lay);
    let ln_n = lay.ln_n();
    let holdout_len = lay.holdout_len();
    let cost_before = fit::cost_at(prob, &cur.state, slots, &prior_of(slots))?;
    let m = cands.len().max(1) as f64;
    let mut scored: Vec<(Score, Option<f64>)> = Vec::new();
    for e in cands {
        let j = e.target.unwrap_or(0);
        let mut with = slots.to_vec();
        with.extend(e.slots());
        let pw = prior_of(&with);
        let mut score = Score::untested(e, 1, 1);
        let refit = fit::fit_balanced(&mut prob.clone(), &cur.state, &with, &pw).and_then(|f| {
            // the model file's own checks: a refit it would refuse is a failed fit
            f.state.to_model()?;
            let cost = fit::cost_at(prob, &f.state, &with, &pw)?;
            Ok((f, cost))
        });
        let (fitted, cost_with) = match refit {
            Ok(r) => r,
            Err(err) => {
                score.note = format!("fit failed: {err}; skipped");
                scored.push((score, None));
                continue;
            }
        };
        let lin = fitted.lin.rewhitened(prob);
        let eqs_w = fold_eqs(prob, &lin, &lay.folds).with_prior(&pw, &with, &fitted.state);
        let all: Vec<usize> = (0..with.len()).collect();
        let HeldOut {
            costs,
            gap_mm: gap_w,
            ..
        } = heldout(prob, &lin, &eqs_w, &lay.folds, &all);
        // judged on the holdout set alone (the last fold): only it reaches beyond the training
        // torques; the cross-validated training configurations would dilute the test
        let tail = |v: &[f64]| v[v.len().saturating_sub(holdout_len)..].to_vec();
        let test = Paired::new(&drops(&tail(base_costs), &tail(&costs)), alpha / m);
        score.delta_chi2 = cost_before - cost_with;
        score.delta_bic = score.delta_chi2 - ln_n;
        score.p_adjusted = (stats::chi2_sf(score.delta_chi2.max(0.0), 1.0) * m).min(1.0);
        score.heldout_gain = Some(test.mean * test.n as f64);
        score.paired_t = Some(test.t);
        score.rank_p = Some(test.rank_p);
        score.heldout_gap_mm = Some(gap_w);
        let kcub = fitted.state.get(Slot::Kcub(j));
        let beyond = format!(
            "held-out |τ{}| up to {:.1} N·m, training up to {:.1} N·m",
            j + 1,
            reach[j].1,
            reach[j].0
        );
        let ok = test.pass && gap_w <= base_gap && kcub > 0.0;
        score.note = if ok {
            format!(
                "completes the J{} spring on held-out data beyond the training torques ({beyond}): held-out RMS {base_gap:.3} → {gap_w:.3} mm, paired t = {:.2} > {:.2} (Bonferroni × {m})",
                j + 1,
                test.t,
                test.t_crit
            )
        } else if kcub <= 0.0 {
            format!(
                "not a hardening spring at its refit (Kcub = {kcub:.3e} N·m/rad³ ≤ 0; {beyond})"
            )
        } else {
            format!(
                "held-out gain not significant beyond the training torques ({beyond}): held-out RMS {base_gap:.3} → {gap_w:.3} mm, paired t = {:.2} ≤ {:.2}, {} of {} held-out configurations better",
                test.t, test.t_crit, test.better, test.n
            )
        };
        scored.push((score, ok.then_some(test.t)));
    }
    scored.sort_by(|a, b| {
        let key = |s: &(Score, Option<f64>)| s.1.unwrap_or(f64::NEG_INFINITY);
        key(b).total_cmp(&key(a)).then(
            b.0.paired_t
                .unwrap_or(f64::NEG_INFINITY)
                .total_cmp(&a.0.paired_t.unwrap_or(f64::NEG_INFINITY)),
        )
    });
    let pick = scored
        .first()
        .filter(|s| s.1.is_some())
        .and_then(|s| cands.iter().position(|e| e.label() == s.0.label));
    let mut scores: Vec<Score> = scored.into_iter().map(|(s, _)| s).collect();
    if let Some(first) = scores.first_mut().filter(|_| pick.is_some()) {
        first.passed = true;
    }
    for s in scores
        .iter_mut()
        .skip(1)
        .filter(|s| s.note.starts_with("completes"))
    {
        s.note = format!("{} — a stronger completion was taken this round", s.note);
    }
    Ok((scores, pick))
}

/// Completion rounds at the pruned fit `st` while one passes (within the effect budget):
/// each round is a [`Step`] with `completion: true`; a taken cubic joins `found` and `slots`.
pub(super) fn complete(
    lay: &Layout,
    prior_of: &dyn Fn(&[Slot]) -> fit::Prior,
    opts: &DiscoverOptions,
    found: &mut Vec<(Effect, f64)>,
    slots: &mut Vec<Slot>,
    steps: &mut Vec<Step>,
    mut st: Settled,
) -> Result<Settled, DiscoverError> {
    while found.len() < opts.max_effects {
        let cands = candidates(slots, lay, opts.only.as_deref());
        if cands.is_empty() {
            break;
        }
        let (scores, pick) = round(&st, lay, slots, &prior_of, &cands, opts.alpha)?;
        steps.push(Step {
            step: steps.len() + 1,
            gap_train_mm: train_rms_mm(&st.prob, &st.cur.lin.raw),
            gap_heldout_mm: st.heldout.gap_mm,
            lack_of_fit: st.lof,
            candidates: scores,
            accepted: pick.map(|ci| cands[ci].label()),
            generic: false,
            completion: true,
            look_alikes: Vec::new(),
            choice: None,
        });
        let Some(ci) = pick else { break };
        let e = cands[ci];
        let mut new_slots = slots.to_vec();
        new_slots.extend(e.slots());
        let settled = settle(lay, &st.cur.state, &new_slots, &prior_of(&new_slots));
        let s = match settled {
            Ok(s) if s.heldout.gap_mm <= st.heldout.gap_mm => s,
            other => {
                let why = match other {
                    Ok(s) => format!(
                        "rejected at its refit on its own weights: held-out RMS {:.3} → {:.3} mm",
                        st.heldout.gap_mm, s.heldout.gap_mm
                    ),
                    Err(err) => format!("fit failed: {err}; skipped"),
                };
                if let Some(step) = steps.last_mut() {
                    step.accepted = None;
                    if let Some(sc) = step.candidates.iter_mut().find(|c| c.label == e.label()) {
                        sc.passed = false;
                        sc.note = why;
                    }
                }
                break;
            }
        };
        found.push((e, st.heldout.gap_mm - s.heldout.gap_mm));
        st = s;
        *slots = new_slots;
    }
    Ok(st)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A layout of two training and one held-out configuration with the given |τ| on every
    /// joint, N·m (nothing but the torques matters to the candidate rule).
    fn lay(train_nm: f64, heldout_nm: f64, holdout: bool) -> Layout {
        let obs = |t: f64| Obs {
            q: [0.0; 6],
            tau: [t; 6],
            load_n: 0.0,
            dir: [0.0; 6],
            thermal: 1.0,
            meas: crate::model::Frame::identity(),
        };
        let block = |i: usize, train: bool| layout::ConfigRows {
            rows: vec![i],
            train,
            cells: vec![vec![i]],
        };
        Layout {
            obs: vec![obs(train_nm), obs(-train_nm), obs(heldout_nm)],
            blocks: vec![block(0, true), block(1, true), block(2, !holdout)],
            folds: vec![vec![2]],
            holdout,
            per_kelvin: false,
            resolver_arcmin: 0.64,
            meta_position_m: None,
        }
    }

    fn labels(c: &[Effect]) -> Vec<String> {
        c.iter().map(Effect::label).collect()
    }

    #[test]
    fn only_springs_without_their_cubic_beyond_the_training_torques() {
        let slots = [
            Slot::Compliance(1),
            Slot::Compliance(2),
            Slot::Kcub(2),
            Slot::Compliance(4),
        ];
        // J2 and J5 have a linear spring and no cubic; J3 has both; the others none.
        let beyond = lay(50.0, 90.0, true);
        assert_eq!(
            torque_reach(&beyond)[0],
            (50.0, 90.0),
            "training and held-out |τ|"
        );
        assert_eq!(
            labels(&candidates(&slots, &beyond, None)),
            ["joint_compliance_cubic[J2]", "joint_compliance_cubic[J5]"]
        );
        // Within the training range (10 % margin), without a holdout set, or restricted to
        // other kinds: nothing to complete.
        assert!(candidates(&slots, &lay(50.0, 54.0, true), None).is_empty());
        assert!(candidates(&slots, &lay(50.0, 90.0, false), None).is_empty());
        assert!(candidates(&slots, &beyond, Some(&[Kind::JointComplianceLinear])).is_empty());
        assert_eq!(
            candidates(&slots, &beyond, Some(&[Kind::JointComplianceCubic])).len(),
            2
        );
    }
}
