//! The model-discrepancy workflow: is anything missing from the model, what is it, and
//! does adding it close the gap to the noise floor?
//!
//! [`discover`] fits the given model (its departures, base frame, springs and joint errors),
//! tests its lack of fit against the noise floor (χ² of the whitened residuals net of the
//! pure error of repeats), then adds effects from the [`effects`] library by forward
//! selection: every candidate's Jacobian block is projected on what the current model can
//! already absorb (what is left is the only evidence; a block with nothing left is *not
//! identifiable* and is reported, never picked), scored by the linearised drop in cost,
//! a likelihood-ratio test with a Bonferroni correction, ΔBIC, and held-out data by
//! configuration (a holdout file, else k-fold cross-validation) with a paired t-test or a
//! signed-rank test over the held-out configurations, and a bootstrap by configuration (it,
//! or a look-alike, must be in the forward selection of 80 % of resamples). The best candidate that passes every test is
//! added and the model refitted (Levenberg–Marquardt); this repeats until nothing passes, the gap is at
//! the noise floor, or the effect budget is spent.
//!
//! Plain functions on plain data: no IO. The `pa10 discover` command wraps it.

mod complete;
pub mod effects;
mod fit;
pub mod forward;
mod heldout;
mod layout;
mod options;
mod prune;
mod report;
mod scoring;
mod verdict;
mod weights;

use heldout::*;
use layout::*;
pub use options::{DiscoverError, DiscoverOptions};
use options::{check, model_slots};
use report::evidence;
pub use report::{Discovery, Evidence, Found, LackOfFit, NoiseReport, Score, Step, Stratum};
use scoring::*;
use weights::*;

use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};

use nalgebra::{DMatrix, DVector, Vector6};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_pcg::Pcg64;
use serde::Serialize;

use crate::calib::dataset::{Dataset, Effort};
use crate::calib::fit::{CalibOptions, fit_base_only};
use crate::model::{EffectRecord, Model, ModelError, frame_from_pose};
use crate::stats;
use effects::{BASE_ABSORBED, Effect, Kind, Slot};
use fit::{Linearization, Problem};
use forward::{EffectState, Obs};

/// The held-out error, in noise floors, below which the gap counts as closed.
pub const GAP_CLOSED: f64 = 1.25;

/// A repeatable resolver error whose 95 % interval lies above this many times the
/// resolver's specified σ is reported as lack of fit that repeats per configuration.
pub const REPEATABLE_EXCESS: f64 = 2.0;

/// A joint whose training configurations span less than this (rad, 0.57°) is *still* on
/// the campaign: an effect of its angle (transmission error, eccentricity, gear ratio,
/// backlash, the generic basis) cannot be seen there, only its readings' noise, which such a
/// candidate would "explain" by ignoring the readings (issue #41: a J6 held at 0 ± 0.6 mrad
/// scored Δχ² ≈ 600 that way). Its candidates are reported not identifiable, never tried.
pub const STILL_SPAN_RAD: f64 = 0.01;

/// A named effect's estimate must differ from zero: the Wald test of its parameters at the
/// refit, p below this (one parameter: |estimate| ≥ 2σ).
pub const NONZERO_P: f64 = 0.0455;

/// Candidates a step compares again at their nonlinear refit when the linearised held-out
/// comparison fails (the strongest first).
const NONLINEAR_RETRIES: usize = 1;

/// The covariance of `slots` (in their scaled units) at a fit: the inverse of its normal
/// matrix `a_fit` with the prior, times the dispersion its lack of fit shows (at least 1).
fn covariance(
    a_fit: DMatrix<f64>,
    slots: &[Slot],
    state: &EffectState,
    prior: &fit::Prior,
    lof: &LackOfFit,
) -> DMatrix<f64> {
    let mut a = a_fit;
    let mut g_unused = DVector::zeros(slots.len());
    prior.add_to(slots, state, &mut a, &mut g_unused, true);
    fit::pinv(&a) * lof.between.ratio.min(lof.within.ratio).max(1.0)
}

/// The Wald statistic of the last `k` slots of `slots` at the settled fit `s` (their
/// estimates over their [`covariance`], as the final report's), and `k`.
fn wald_of_last(
    s: &complete::Settled,
    slots: &[Slot],
    prior: &fit::Prior,
    k: usize,
) -> (f64, usize) {
    let n = slots.len();
    let cov = covariance(s.a_fit.clone(), slots, &s.cur.state, prior, &s.lof);
    let idx: Vec<usize> = (n - k..n).collect();
    let c = DMatrix::from_fn(k, k, |i, j| cov[(idx[i], idx[j])]);
    let theta = DVector::from_fn(k, |i, _| {
        s.cur.state.get(slots[idx[i]]) / slots[idx[i]].scale()
    });
    let w = (theta.transpose() * fit::pinv(&c) * &theta)[(0, 0)];
    (w.max(0.0), k)
}

/// Runs the workflow on `data` (training) and optionally `holdout` (same instrument set-up),
/// starting from `model`.
pub fn discover(
    model: &Model,
    data: &Dataset,
    holdout: Option<&Dataset>,
    opts: &DiscoverOptions,
) -> Result<Discovery, DiscoverError> {
    check(opts)?;
    let mut m0 = model.clone();
    if let Some(t) = data.meta.as_ref().and_then(|m| m.tool) {
        m0 = m0.with_tool(&frame_from_pose(t.translation, t.quaternion))?;
    }
    let copts = CalibOptions {
        torque_constants: opts.torque_constants,
        ..Default::default()
    };
    let m0 = fit_base_only(&m0, data, None, &copts)?;
    let state0 = EffectState::from_model(&m0, opts.gear_ratio);
    let lay = layout(data, holdout, opts)?;
    let ln_n = lay.ln_n();
    let spans = lay.spans();
    // Why a candidate cannot be seen on these poses at all (a joint the campaign does not turn).
    let unseen = |e: &Effect| {
        e.angle_joint()
            .filter(|&j| spans[j] < STILL_SPAN_RAD)
            .map(|j| {
                format!(
                    "not identifiable from these poses: the training configurations turn J{} by {:.2} mrad only (an effect of its angle needs ≥ {:.0} mrad)",
                    j + 1,
                    spans[j] * 1e3,
                    STILL_SPAN_RAD * 1e3
                )
            })
    };
    let mut slots = model_slots(&m0);
    let base_slots = slots.clone();
    // Fit, re-estimate the noise model at the fit (it depends on the springs), fit again.
    let (mut p0, _) = problem(&lay, &state0, slots.len())?;
    // The combinations of the model's own parameters these data cannot determine are held
    // at their start values in every fit below (see `fit::Held`), and a candidate on a
    // joint's angle gives its constant part back to that joint's offset.
    let angle_cands = effects::angle_candidate_slots(&slots);
    let held = std::sync::Arc::new(fit::Held::at(&p0, &state0, &slots, &angle_cands)?);
    let prior_of = |slots: &[Slot]| fit::Prior::new(slots, &base_slots, &held);
    let first = fit::fit_balanced(&mut p0, &state0, &slots, &prior_of(&slots))?;
    let complete::Settled {
        mut prob,
        mut noise,
        mut cur,
        lof: lof0,
        mut a_fit,
        heldout: mut held_out,
    } = complete::settle(&lay, &first.state, &slots, &prior_of(&slots))?;
    let gap0 = held_out.gap_mm;
    let noise0 = noise.clone();
    let significant = lof0.p_value < opts.alpha;
    // Between-configuration variance is either a repeatable resolver error or an effect of
    // the configuration the model misses; the data alone cannot say which (the estimate
    // absorbs the effect, and the test of lack of fit then has nothing left to see). So a
    // significant repeatable component also opens the search: a candidate must then earn its
    // place by the same F, ΔBIC, held-out and bootstrap tests.
    let suspect = |lof: &LackOfFit, noise: &NoiseReport| {
        lof.p_value < opts.alpha || noise.model.repeatable_p < opts.alpha
    };
    let train0 = train_rms_mm(&prob, &cur.lin.raw);
    let raw_before = cur.lin.raw.clone();
    let mut steps = Vec::new();
    let mut found: Vec<(Effect, f64)> = Vec::new();
    // Effects whose nonlinear refit did not improve the held-out prediction of the current
    // model (tried again once an effect joins: a spring judged while a larger effect was
    // still missing may fail the held-out RMS on the misfit that effect leaves, 12-07).
    let mut rejected: Vec<Effect> = Vec::new();
    // What a free base frame absorbs exactly is not identifiable by construction (scoring
    // it numerically would only measure the curvature of the rotation group).
    let mut not_identifiable: Vec<String> = BASE_ABSORBED
        .iter()
        .map(|&i| {
            Effect {
                kind: Kind::GeometricDeparture,
                target: Some(i),
            }
            .label()
        })
        .collect();
    let mut gap = gap0;
    let mut lof = lof0;
    let mut go = suspect(&lof0, &noise);
    // Once no library candidate passes while the lack of fit stays significant, the generic
    // dictionary is searched with the same discipline.
    let mut generic = false;
    while go && found.len() < opts.max_effects {
        let pool = if generic {
            effects::generic_candidates(&slots)
        } else {
            effects::candidates(&slots, &[])
        };
        let cands: Vec<Effect> = pool
            .into_iter()
            .filter(|e| opts.only.as_ref().is_none_or(|o| o.contains(&e.kind)))
            .filter(|e| !rejected.contains(e))
            .collect();
        let mut all = slots.clone();
        let mut ranges = Vec::new();
        for e in &cands {
            let s = e.slots();
            ranges.push(all.len()..all.len() + s.len());
            all.extend(s);
        }
        // The current fit's columns, and the candidates' evaluated at its state.
        let lin = cur.lin.extended(&prob, &cur.state, &all[slots.len()..])?;
        let prior_all = prior_of(&all);
        let eqs = fold_eqs(&prob, &lin, &lay.folds).with_prior(&prior_all, &all, &cur.state);
        let prior_diag = prior_all.held_diag(&all, &cur.state);
        let nb = slots.len();
        let a = &eqs.a_train;
        let g = &eqs.g_train;
        let a_bb = a.view((0, 0), (nb, nb)).into_owned();
        let a_bb_inv = fit::pinv(&a_bb);
        let g_b = g.rows(0, nb).into_owned();
        // Scores are on the fit's weights (balanced while the model misfits grossly).
        let (lof_w, _) = lack_of_fit(&prob, &cur.lin);
        let dispersion = lof_w.between.ratio.min(lof_w.within.ratio).max(1.0);
        let df_pe = test_dof(&prob, &lin.raw, &noise);
        let mut scores: Vec<(Score, usize)> = Vec::new();
        for (ci, e) in cands.iter().enumerate() {
            let r = ranges[ci].clone();
            let k = r.len();
            if let Some(why) = unseen(e) {
                let mut score = Score::untested(e, k, 0);
                if steps.is_empty() {
                    not_identifiable.push(score.label.clone());
                }
                score.note = why;
                scores.push((score, ci));
                continue;
            }
            let (ident, drop) = projected_drop(a, g, &a_bb_inv, &g_b, r, &prior_diag);
            let mut score = Score::untested(e, k, ident);
            if ident == 0 {
                if steps.is_empty() {
                    not_identifiable.push(score.label.clone());
                }
                score.note = "not identifiable: the current model absorbs it on these poses".into();
            } else {
                score.delta_chi2 = drop / dispersion;
                score.delta_bic = score.delta_chi2 - ident as f64 * ln_n;
            }
            scores.push((score, ci));
        }
        let m = scores
            .iter()
            .filter(|s| s.0.identifiable > 0)
            .count()
            .max(1) as f64;
        for (s, _) in &mut scores {
            if s.identifiable > 0 {
                let k = s.identifiable as f64;
                s.p_adjusted = (stats::f_sf(s.delta_chi2 / k, k, df_pe) * m).min(1.0);
            }
        }
        scores.sort_by(|a, b| b.0.delta_bic.total_cmp(&a.0.delta_bic));
        let base_costs = heldout(&prob, &lin, &eqs, &lay.folds, &(0..nb).collect::<Vec<_>>()).costs;
        let gate = Gate::new(
            opts.alpha,
            opts.min_delta_bic,
            df_pe,
            m,
            dispersion,
            ln_n,
            ranges.iter().map(|r| r.len()).max().unwrap_or(1),
        );
        // The linearised held-out comparison of the model with and without candidate `ci`.
        let heldout_test = |ci: usize| {
            let cols: Vec<usize> = (0..nb).chain(ranges[ci].clone()).collect();
            let h = heldout(&prob, &lin, &eqs, &lay.folds, &cols);
            let d = drops(&base_costs, &h.costs);
            (Paired::new(&d, opts.alpha), h.gap_mm, h.costs)
        };
        // The linearised comparison trusts the model's first-order response to a candidate;
        // where that response is strongly nonlinear (a cubic stiffness started at zero
        // overshoots at loads beyond the training ones) a failed comparison is repeated at
        // the candidate's nonlinear refit, on the same weights.
        let nonlinear_test = |ci: usize| -> Option<(Paired, f64, Vec<f64>)> {
            let mut with = slots.clone();
            with.extend(cands[ci].slots());
            let h = refit_heldout(&prob, &cur.state, &with, &prior_of(&with), &lay).ok()?;
            let d = drops(&base_costs, &h.costs);
            Some((Paired::new(&d, opts.alpha), h.gap_mm, h.costs))
        };
        // At most NONLINEAR_RETRIES a step, for the strongest candidates (visited by ΔBIC):
        // each is a full refit.
        let retries = std::cell::Cell::new(0usize);
        let compare = |ci: usize| {
            let linear = heldout_test(ci);
            if linear.0.pass || retries.get() >= NONLINEAR_RETRIES {
                return linear;
            }
            retries.set(retries.get() + 1);
            nonlinear_test(ci).unwrap_or(linear)
        };
        let score_of = |scores: &[(Score, usize)], ci: usize| {
            scores.iter().position(|(_, c)| *c == ci).unwrap_or(0)
        };
        let significant =
            |sc: &Score| sc.p_adjusted < opts.alpha && sc.delta_bic > opts.min_delta_bic;
        let record_heldout = |sc: &mut Score, test: &Paired, gap_mm: f64| {
            sc.heldout_gain = Some(test.mean * base_costs.len() as f64);
            sc.paired_t = Some(test.t);
            sc.rank_p = Some(test.rank_p);
            sc.heldout_gap_mm = Some(gap_mm);
        };
        let mut accepted: Option<usize> = None;
        // The look-alike whose held-out test established the direction the pick shares.
        let mut leader: Option<usize> = None;
        let mut choice: Option<String> = None;
        let mut sets: Option<Vec<Vec<usize>>> = None;
        for idx in 0..scores.len() {
            let ci = scores[idx].1;
            let s = &mut scores[idx].0;
            if s.identifiable == 0 {
                continue;
            }
            if s.p_adjusted >= opts.alpha {
                s.note = format!(
                    "not significant (p = {:.2e} after Bonferroni × {m})",
                    s.p_adjusted
                );
                continue;
            }
            if s.delta_bic <= opts.min_delta_bic {
                s.note = format!("ΔBIC {:.1} ≤ {}", s.delta_bic, opts.min_delta_bic);
                continue;
            }
            if s.note.is_empty() && accepted.is_some() {
                s.note = "significant, but a better candidate was taken this step".into();
            }
            if accepted.is_some() {
                continue;
            }
            let (test, gap_c, costs_c) = compare(ci);
            record_heldout(s, &test, gap_c);
            if !test.pass {
                s.note = format!(
                    "held-out gain not significant: paired t = {:.2} ≤ {:.2}, {} of {} held-out configurations better (signed-rank p = {:.1e})",
                    test.t,
                    test.t_crit,
                    test.better,
                    base_costs.len(),
                    test.rank_p
                );
                continue;
            }
            // Its look-alikes: candidates whose columns beyond the model share a direction
            // with it (the data barely tell them apart).
            let group: Vec<usize> = std::iter::once(ci)
                .chain((0..cands.len()).filter(|&o| {
                    o != ci
                        && canonical_correlation(
                            a,
                            &a_bb_inv,
                            ranges[ci].clone(),
                            ranges[o].clone(),
                        ) >= 0.9
                }))
                .collect();
            // Would other samples of configurations have selected it (or a look-alike)?
            let sets = sets.get_or_insert_with(|| {
                let cols: Vec<usize> = (0..lin.jwhite.ncols()).collect();
                let blocks: Vec<_> = prob
                    .blocks
                    .par_iter()
                    .filter(|b| b.train)
                    .map(|b| {
                        let rows: Vec<usize> =
                            (b.offset..b.offset + 6 * (b.rows.len() + 1)).collect();
                        fit::normal_eq(&lin, &rows, &cols)
                    })
                    .collect();
                let (mut pa_, mut pg_) = (
                    DMatrix::zeros(all.len(), all.len()),
                    DVector::zeros(all.len()),
                );
                prior_all.add_to(&all, &cur.state, &mut pa_, &mut pg_, false);
                let mut rng = Pcg64::seed_from_u64(opts.seed ^ 0xb007 ^ steps.len() as u64);
                stability(&blocks, (&pa_, &pg_), nb, &ranges, &gate, &mut rng)
            });
            let st = share_holding(sets, &group);
            s.stability = Some(st);
            if st < STABLE {
                s.note = format!(
                    "uncertain: in the selection of only {:.0} % of {BOOTSTRAP} bootstrap resamples by configuration{}",
                    100.0 * st,
                    if group.len() > 1 {
                        " (it or a look-alike)"
                    } else {
                        ""
                    }
                );
                continue;
            }
            // Within the look-alikes that pass too: told apart by the held-out data, else by
            // physical plausibility (a harmonic drive's spring before a cast link's bending).
            // Each member's held-out comparison, computed once.
            let mut members = vec![Member {
                cand: ci,
                test,
                gap_mm: gap_c,
                costs: costs_c,
            }];
            // A look-alike joins when it passes on its own or predicts the held-out
            // configurations no worse than the leader (paired): the leader's test has shown
            // that the direction they share is real; which of them carries it is a choice.
            for &o in group.iter().skip(1) {
                if significant(&scores[score_of(&scores, o)].0) {
                    let (test, gap_mm, costs) = compare(o);
                    let worse = drops(&costs, &members[0].costs);
                    if test.pass || !Paired::new(&worse, opts.alpha).pass {
                        members.push(Member {
                            cand: o,
                            test,
                            gap_mm,
                            costs,
                        });
                    }
                }
            }
            let (k, why) = choose_look_alike(&members, &cands, opts.alpha);
            choice = why;
            let pick = members[k].cand;
            accepted = Some(pick);
            leader = Some(ci);
            let pi = score_of(&scores, pick);
            if pi != idx {
                let sc = &mut scores[pi].0;
                record_heldout(sc, &members[k].test, members[k].gap_mm);
                sc.stability = Some(st);
                scores[idx].0.note =
                    format!("a look-alike of {}, which was taken", cands[pick].label());
            }
            let sc = &mut scores[pi].0;
            sc.passed = true;
            sc.note = format!(
                "accepted (in the selection of {:.0} % of resamples{})",
                100.0 * st,
                if group.len() > 1 {
                    ", with its look-alikes"
                } else {
                    ""
                }
            );
        }
        let look_alikes = match accepted {
            None => Vec::new(),
            Some(pick) => (0..cands.len())
                .filter(|&ci| ci != pick)
                .filter_map(|ci| {
                    let r = canonical_correlation(
                        a,
                        &a_bb_inv,
                        ranges[pick].clone(),
                        ranges[ci].clone(),
                    );
                    (r >= 0.9).then(|| (cands[ci].label(), r))
                })
                .collect(),
        };
        let step = Step {
            step: steps.len() + 1,
            gap_train_mm: train_rms_mm(&prob, &cur.lin.raw),
            gap_heldout_mm: gap,
            lack_of_fit: lof,
            candidates: scores.into_iter().map(|(s, _)| s).collect(),
            accepted: accepted.map(|ci| cands[ci].label()),
            generic,
            completion: false,
            look_alikes,
            choice,
        };
        steps.push(step);
        let Some(ci) = accepted else {
            if !generic && suspect(&lof, &noise) {
                generic = true;
                continue;
            }
            break;
        };
        let e = cands[ci];
        // The refit's held-out test on its own: the whitened held-out cost; the RMS position
        // error (secondary, unweighted) may grow only as [`rms_allows`]. A look-alike taken by
        // choice carries a direction its leader's test established: its refit must gain on
        // held-out data, not gain significantly again.
        let passes_alone = |t: &Paired, g2: f64, g_prev: f64, rms_ok: bool| {
            (leader.is_some_and(|l| l != ci) && t.mean > 0.0 && g2 <= g_prev) || (t.pass && rms_ok)
        };
        // The others a linearised forward selection takes with it (not its look-alikes).
        let companions: Vec<usize> = select(a, g, nb, &ranges, &gate, SELECT_ROUNDS, &prior_diag)
            .into_iter()
            .filter(|&o| {
                o != ci
                    && canonical_correlation(a, &a_bb_inv, ranges[ci].clone(), ranges[o].clone())
                        < 0.9
            })
            .collect();
        let mut new_slots = slots.clone();
        new_slots.extend(e.slots());
        let pr = prior_of(&new_slots);
        // The refit, from three starts; any failure (a start outside the model's valid
        // range, a fit that cannot proceed) rejects this candidate, never the run.
        let attempt = || -> Result<_, DiscoverError> {
            // Start the new parameters at their linearised estimate (on the prior, so the
            // jump cannot run along the held directions).
            let cols: Vec<usize> = (0..nb).chain(ranges[ci].clone()).collect();
            let sub = DMatrix::from_fn(cols.len(), cols.len(), |i, j| a[(cols[i], cols[j])]);
            let subg = DVector::from_fn(cols.len(), |i, _| g[cols[i]]);
            let (d, _) = fit::damped_solve(&sub, &subg, 0.0);
            let mut jump = cur.state.clone();
            for (c, &col) in cols.iter().enumerate() {
                jump.set(all[col], cur.state.get(all[col]) + d[c] * all[col].scale());
            }
            // A missing effect can drag the geometry far from nominal while the model tries
            // to absorb it; refit also from the starting geometry with the effects'
            // estimates, and from the current fit with the effect at zero (never worse than
            // the current fit), and keep the best optimum on the first valid start's weights.
            let mut st2 = state0.clone();
            for &sl in new_slots.iter().filter(|s| !base_slots.contains(s)) {
                st2.set(sl, jump.get(sl));
            }
            // the three fits are independent: run together, judged in order
            let fits: Vec<Option<(Problem, fit::Fitted)>> = [jump, st2, cur.state.clone()]
                .into_par_iter()
                .map(|start| {
                    let mut pb = prob.clone();
                    // a fit whose model the model file would refuse (e.g. a joint error's
                    // slope beyond 0.5: not invertible) is no start at all
                    let alt = fit::fit_balanced(&mut pb, &start, &new_slots, &pr).ok()?;
                    alt.state.to_model().ok()?;
                    Some((pb, alt))
                })
                .collect();
            let mut best: Option<(Problem, fit::Fitted)> = None;
            for (pb, alt) in fits.into_iter().flatten() {
                match &mut best {
                    None => best = Some((pb, alt)),
                    Some((pa, refit)) => {
                        let alt_cost = fit::cost_at(pa, &alt.state, &new_slots, &pr)?;
                        if alt_cost < refit.cost {
                            *refit = fit::Fitted {
                                cost: alt_cost,
                                ..alt
                            };
                        }
                    }
                }
            }
            let Some((_, refit)) = best else {
                return Err(DiscoverError::Data(
                    "no start of the refit stays within the model's valid range".into(),
                ));
            };
            let s2 = complete::settle(&lay, &refit.state, &new_slots, &pr)?;
            // The refitted model must predict held-out configurations better than the model
            // before it, on the same weights: positive and significant (paired over held-out
            // configurations), whatever the linearised scores said.
            let lin_prev = cur.lin.rewhitened(&s2.prob);
            let eqs_prev = fold_eqs(&s2.prob, &lin_prev, &lay.folds).with_prior(
                &prior_of(&slots),
                &slots,
                &cur.state,
            );
            let cols_prev: Vec<usize> = (0..slots.len()).collect();
            let prev = heldout(&s2.prob, &lin_prev, &eqs_prev, &lay.folds, &cols_prev);
            let g_prev = prev.gap_mm;
            let d = drops(&prev.costs, &s2.heldout.costs);
            let worse = Paired::new(&drops(&s2.heldout.sq_mm2, &prev.sq_mm2), opts.alpha);
            let g2 = s2.heldout.gap_mm;
            // And judged among the others the data select with it, on the same weights: from
            // a grossly wrong model (several springs missing at once) one spring alone may
            // not predict held-out configurations better — the others' misfit dominates and
            // moves — while with them it does.
            // (Only asked when it fails alone: two more refits.)
            let test = Paired::new(&d, opts.alpha);
            let train = [&cur.lin.raw, &s2.cur.lin.raw].map(|r| train_rms_mm(&s2.prob, r));
            let alone = passes_alone(&test, g2, g_prev, rms_allows([g_prev, g2], train, &worse));
            let among = if alone || companions.is_empty() {
                None
            } else {
                let mut without = slots.clone();
                for &o in &companions {
                    without.extend(cands[o].slots());
                }
                let mut with = without.clone();
                with.extend(e.slots());
                let (r_without, r_with) = rayon::join(
                    || refit_heldout(&s2.prob, &cur.state, &without, &prior_of(&without), &lay),
                    || refit_heldout(&s2.prob, &s2.cur.state, &with, &prior_of(&with), &lay),
                );
                let (w_o, w) = (r_without?, r_with?);
                Some((drops(&w_o.costs, &w.costs), w.gap_mm, w_o.gap_mm))
            };
            Ok((s2, test, worse, alone, g_prev, among))
        };
        let label = e.label();
        let outcome = attempt();
        let reject = |steps: &mut Vec<Step>, note: String| {
            if let Some(step) = steps.last_mut() {
                step.accepted = None;
                if let Some(sc) = step.candidates.iter_mut().find(|c| c.label == label) {
                    sc.passed = false;
                    sc.note = note;
                }
            }
        };
        let (s2, test, worse, alone, g_prev, among) = match outcome {
            Ok(o) => o,
            Err(err) => {
                reject(&mut steps, format!("fit failed: {err}; skipped"));
                rejected.push(e);
                continue;
            }
        };
        let g2 = s2.heldout.gap_mm;
        let with_others = among
            .as_ref()
            .map(|(d, g_with, g_without)| (Paired::new(d, opts.alpha), *g_with, *g_without));
        let among_pass = with_others
            .as_ref()
            .is_some_and(|(t, g_with, g_without)| t.pass && *g_with <= 1.01 * *g_without);
        if !(alone || among_pass) {
            let others = match &with_others {
                None => String::new(),
                Some((t, g_with, g_without)) => format!(
                    "; with {}: {g_without:.3} → {g_with:.3} mm, paired t = {:.2}",
                    companions
                        .iter()
                        .map(|&o| cands[o].label())
                        .collect::<Vec<_>>()
                        .join(", "),
                    t.t
                ),
            };
            reject(
                &mut steps,
                rejected_note(g_prev, g2, &test, &worse, &others),
            );
            rejected.push(e);
            continue;
        }
        // A parameter indistinguishable from zero names nothing, whatever it moved elsewhere.
        let (wald, k) = wald_of_last(&s2, &new_slots, &pr, e.slots().len());
        let p_zero = stats::chi2_sf(wald, k as f64);
        if p_zero >= NONZERO_P {
            reject(
                &mut steps,
                format!(
                    "refused: its estimate is not different from zero (Wald χ² = {wald:.2} on {k} parameter{}, p = {p_zero:.2}); what it gained came from what its refit moved elsewhere",
                    if k == 1 { "" } else { "s" }
                ),
            );
            rejected.push(e);
            continue;
        }
        (prob, noise, cur, slots, lof, a_fit, held_out) = (
            s2.prob, s2.noise, s2.cur, new_slots, s2.lof, s2.a_fit, s2.heldout,
        );
        found.push((e, gap - g2));
        gap = g2;
        go = suspect(&lof, &noise);
        rejected.clear();
    }
    let settled = complete::Settled {
        prob,
        noise,
        cur,
        lof,
        a_fit,
        heldout: held_out,
    };
    let (settled, pruned) = prune::prune(&lay, &prior_of, opts, &mut found, &mut slots, settled)?;
    // Completion beyond the training torques (see `complete`): a spring without its cubic
    // term, judged on held-out data that reach larger torques than the training data.
    let complete::Settled {
        prob,
        noise,
        cur,
        lof,
        a_fit,
        heldout: HeldOut { gap_mm: gap, .. },
    } = complete::complete(
        &lay, &prior_of, opts, &mut found, &mut slots, &mut steps, settled,
    )?;
    // Uncertainties at the final fit.
    let cov = covariance(a_fit, &slots, &cur.state, &prior_of(&slots), &lof);
    let effects_out = report::found(&found, &slots, &cur.state, &cov, lay.per_kelvin);
    let evidence = found
        .iter()
        .map(|(e, _)| evidence(&prob, &cur.state, e, &raw_before, &cur.lin.raw))
        .collect::<Result<Vec<_>, _>>()?;
    // Nothing named: the starting model is written unchanged. Its refit under discovery's
    // weights is the baseline the candidates were measured against, not a better
    // calibration (on the MuJoCo judge's campaigns it moved the held-out error either way by
    // up to 0.13× the floor with nothing found).
    let model_out = if found.is_empty() {
        model.clone()
    } else {
        report::extended_model(&cur.state, model, &effects_out)?
    };
    let floor = noise_floor_mm(
        &prob,
        &cur.state,
        &cur.state.geometry()?,
        &lay.folds,
        noise.repeatable_used_rad,
    );
    // A repeatable component far above the resolver's specification is a finding, never a
    // weight (the weights use at most the specification).
    let spec_rad = lay.resolver_arcmin * crate::accuracy::ARCMIN;
    let excess = |n: &NoiseReport| {
        let r = n.model.repeatable_rad;
        (n.model.repeatable_p < opts.alpha && r.lo > REPEATABLE_EXCESS * spec_rad).then_some(r)
    };
    let (findings, gap_closed, verdict) = verdict::conclude(&verdict::Ending {
        found: found.len(),
        max_effects: opts.max_effects,
        lack_of_fit: lof,
        alpha: opts.alpha,
        gap_mm: gap,
        floor_mm: floor,
        generic,
        excess: [
            ("the starting model", excess(&noise0)),
            ("the final model", excess(&noise)),
        ],
        resolver_arcmin: lay.resolver_arcmin,
    });
    let slot_name = |sl: Slot| match sl {
        Slot::Dep(i) => crate::model::param_names()[i].to_string(),
        Slot::Base(k) => format!("base {}", ["x", "y", "z", "rx", "ry", "rz"][k]),
        other => format!("{other:?}"),
    };
    let held_out: Vec<String> = (0..held.dirs.len())
        .map(|k| held.describe(k, slot_name))
        .collect();
    Ok(Discovery {
        significant_gap_before: significant,
        gap_closed,
        library_exhausted: generic,
        verdict,
        gap_before_mm: gap0,
        gap_after_mm: gap,
        train_gap_before_mm: train0,
        train_gap_after_mm: train_rms_mm(&prob, &cur.lin.raw),
        noise_floor_mm: floor,
        heldout: if lay.holdout {
            format!(
                "holdout set ({} configurations) and {}-fold cross-validation by configuration over the training set",
                lay.holdout_len(),
                lay.folds.len() - 1
            )
        } else {
            format!("{}-fold cross-validation by configuration", lay.folds.len())
        },
        lack_of_fit_before: lof0,
        lack_of_fit_after: lof,
        noise: noise0,
        noise_after: noise,
        effects: effects_out,
        steps,
        not_identifiable,
        already_modelled: effects::modelled(&base_slots)
            .iter()
            .map(Effect::label)
            .collect(),
        pruned,
        held: held_out,
        findings,
        evidence,
        model: model_out,
    })
}
