//! Scoring candidates: the two-stratum lack-of-fit test, projections of candidate columns on
//! the current model, the held-out comparison, canonical correlations of look-alikes and
//! the bootstrap by configuration.

use super::*;

/// Identifiable fraction below which a candidate direction counts as absorbed (1 % of its
/// column norm left after projection).
pub(super) const IDENT_CUT: f64 = 1e-4;

/// Training RMS position residual, mm.
pub(super) fn train_rms_mm(p: &Problem, raw: &[Vector6<f64>]) -> f64 {
    let (mut ss, mut n) = (0.0, 0);
    for b in p.blocks.iter().filter(|b| b.train) {
        for &i in &b.rows {
            ss += raw[i].fixed_rows::<3>(0).norm_squared();
            n += 1;
        }
    }
    (ss / n.max(1) as f64).sqrt() * 1e3
}

/// The lack-of-fit test at `lin`, and the training normal matrix it was computed with.
pub(super) fn lack_of_fit(p: &Problem, lin: &Linearization) -> (LackOfFit, DMatrix<f64>) {
    let (ss_pe, df_pe) = p.pure_error(&lin.raw);
    let cols: Vec<usize> = (0..lin.jwhite.ncols()).collect();
    let train = p.white_rows(|b| b.train);
    let means: Vec<usize> = p
        .blocks
        .iter()
        .filter(|b| b.train)
        .flat_map(|b| b.offset..b.offset + 6)
        .collect();
    let (a, _) = fit::normal_eq(lin, &train, &cols);
    let (am, _) = fit::normal_eq(lin, &means, &cols);
    let ai = fit::pinv(&a);
    // Leverage of the parameters on each stratum: tr(A⁻¹·A_stratum).
    let lev_mean = (&ai * &am).trace();
    let lev_all = (&ai * &a).trace();
    let c_mean: f64 = means.iter().map(|&i| lin.white[i].powi(2)).sum();
    let c_all: f64 = train.iter().map(|&i| lin.white[i].powi(2)).sum();
    let n_all = train.len() as f64;
    let n_mean = means.len() as f64;
    let n_blocks = means.len() / 6;
    // The deviation rows hold 6 redundant entries per block (they sum to zero per block).
    let within_dof = n_all - n_mean - 6.0 * n_blocks as f64 - df_pe as f64 - (lev_all - lev_mean);
    let between = Stratum::new(c_mean, n_mean - lev_mean, None);
    let within = Stratum::new((c_all - c_mean - ss_pe).max(0.0), within_dof, Some(df_pe));
    let lof = LackOfFit {
        between,
        within,
        p_value: (2.0 * between.p_value.min(within.p_value)).min(1.0),
    };
    (lof, a)
}

/// The denominator degrees of freedom of the candidates' F tests: the pure error's, or
/// infinite (a χ² test) when the noise could not be measured and is assumed known from the
/// specification — a pure-error estimate from a handful of repeats would make every test
/// powerless, and none at all is no estimate.
pub(super) fn test_dof(p: &Problem, raw: &[Vector6<f64>], noise: &NoiseReport) -> f64 {
    if noise.model.structure == crate::noise::Structure::Assumed {
        f64::INFINITY
    } else {
        p.pure_error(raw).1.max(1) as f64
    }
}

/// The linearised drop of the whitened cost when the columns `r` join the first `nb` (whose
/// normal matrix inverse is `a_bb_inv`), counted over the directions with more than
/// [`IDENT_CUT`] of their column left after projecting out the first `nb`: (those
/// directions, the drop). `prior_diag`: the diagonal of the held directions' prior within
/// `a` (a column's size is its data's, not the hold's: a candidate coupled to a held offset,
/// `fit::Held::coupling`, carries the hold's precision on its diagonal).
pub(super) fn projected_drop(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    a_bb_inv: &DMatrix<f64>,
    g_b: &DVector<f64>,
    r: std::ops::Range<usize>,
    prior_diag: &DVector<f64>,
) -> (usize, f64) {
    let base: Vec<usize> = (0..a_bb_inv.nrows()).collect();
    let cols: Vec<usize> = r.collect();
    drop_given(a, g, &base, a_bb_inv, g_b, &cols, prior_diag)
}

fn sub(a: &DMatrix<f64>, rows: &[usize], cols: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), cols.len(), |i, j| a[(rows[i], cols[j])])
}

fn subv(g: &DVector<f64>, rows: &[usize]) -> DVector<f64> {
    DVector::from_fn(rows.len(), |i, _| g[rows[i]])
}

/// [`projected_drop`] of the columns `cols` given any set of columns `base` (`a_bb_inv`,
/// `g_b`: the inverse of their normal matrix and their gradient).
fn drop_given(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    base: &[usize],
    a_bb_inv: &DMatrix<f64>,
    g_b: &DVector<f64>,
    cols: &[usize],
    prior_diag: &DVector<f64>,
) -> (usize, f64) {
    let k = cols.len();
    let a_cb = sub(a, cols, base);
    let a_cc = sub(a, cols, cols);
    let schur = &a_cc - &a_cb * a_bb_inv * a_cb.transpose();
    let h = subv(g, cols) - &a_cb * (a_bb_inv * g_b);
    // Identifiable part: eigen-directions of the Schur complement normalised by the
    // columns' data (the prior of a coupled hold taken off their diagonal).
    let dn = DVector::from_fn(k, |i, _| {
        let v = a_cc[(i, i)] - prior_diag[cols[i]];
        if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }
    });
    let sn = DMatrix::from_fn(k, k, |i, j| schur[(i, j)] * dn[i] * dn[j]);
    let eig = nalgebra::SymmetricEigen::new(sn);
    let (mut ident, mut drop) = (0, 0.0);
    for (i, &ev) in eig.eigenvalues.iter().enumerate() {
        if ev > IDENT_CUT {
            ident += 1;
            let v = eig.eigenvectors.column(i);
            let hv: f64 = (0..k).map(|t| v[t] * dn[t] * h[t]).sum();
            drop += hv * hv / ev;
        }
    }
    (ident, drop)
}

/// The thresholds a candidate passes in a linearised selection: the F test (Bonferroni
/// over `m` candidates, against the pure error's `df_pe` degrees of freedom) and ΔBIC, on
/// the cost scaled by `dispersion`. The F test's critical values are computed once
/// ([`Gate::new`]): the bootstrap asks the question thousands of times.
#[derive(Debug, Clone)]
pub(super) struct Gate {
    min_delta_bic: f64,
    dispersion: f64,
    ln_n: f64,
    /// Critical `Δχ²/k` of the adjusted F test for k = 1…, index k − 1.
    crit: Vec<f64>,
}

impl Gate {
    /// The gate for candidates of up to `max_k` identifiable directions.
    pub(super) fn new(
        alpha: f64,
        min_delta_bic: f64,
        df_pe: f64,
        m: f64,
        dispersion: f64,
        ln_n: f64,
        max_k: usize,
    ) -> Self {
        let crit = (1..=max_k.max(1))
            .map(|k| {
                let k = k as f64;
                let p = |x: f64| (stats::f_sf(x, k, df_pe) * m).min(1.0);
                // p falls with x: bracket, then bisect to a relative 1e-9.
                let (mut lo, mut hi) = (0.0, 1.0);
                while p(hi) >= alpha && hi < 1e12 {
                    lo = hi;
                    hi *= 2.0;
                }
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if p(mid) >= alpha {
                        lo = mid
                    } else {
                        hi = mid
                    }
                    if hi - lo <= 1e-9 * hi {
                        break;
                    }
                }
                hi
            })
            .collect();
        Self {
            min_delta_bic,
            dispersion,
            ln_n,
            crit,
        }
    }

    fn passes(&self, ident: usize, drop: f64) -> Option<f64> {
        if ident == 0 {
            return None;
        }
        let chi2 = drop / self.dispersion;
        let bic = chi2 - ident as f64 * self.ln_n;
        let crit = self.crit.get(ident - 1).copied().unwrap_or(f64::INFINITY);
        (chi2 / ident as f64 > crit && bic > self.min_delta_bic).then_some(bic)
    }
}

/// Forward selection on linearised normal equations `a`, `g` (the first `nb` columns the
/// model's): at most `rounds` times, the candidate of `ranges` with the largest ΔBIC that
/// passes `gate` given the model and the candidates chosen before it joins. Returns the
/// chosen candidates in order.
pub(super) fn select(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    nb: usize,
    ranges: &[std::ops::Range<usize>],
    gate: &Gate,
    rounds: usize,
    prior_diag: &DVector<f64>,
) -> Vec<usize> {
    let mut base: Vec<usize> = (0..nb).collect();
    let mut chosen: Vec<usize> = Vec::new();
    for _ in 0..rounds {
        let inv = fit::pinv(&sub(a, &base, &base));
        let g_b = subv(g, &base);
        let mut best: Option<(usize, f64)> = None;
        for (ci, r) in ranges.iter().enumerate() {
            if chosen.contains(&ci) {
                continue;
            }
            let cols: Vec<usize> = r.clone().collect();
            let (ident, drop) = drop_given(a, g, &base, &inv, &g_b, &cols, prior_diag);
            if let Some(bic) = gate.passes(ident, drop)
                && best.is_none_or(|(_, b)| bic > b)
            {
                best = Some((ci, bic));
            }
        }
        let Some((ci, _)) = best else { break };
        chosen.push(ci);
        base.extend(ranges[ci].clone());
    }
    chosen
}

/// The largest canonical correlation between the column blocks `r1` and `r2` of the normal
/// matrix `a` after both are projected off the first `nb` columns (`a_bb_inv` their
/// inverse): 1 when some combination of one block is a combination of the other.
pub(super) fn canonical_correlation(
    a: &DMatrix<f64>,
    a_bb_inv: &DMatrix<f64>,
    r1: std::ops::Range<usize>,
    r2: std::ops::Range<usize>,
) -> f64 {
    let nb = a_bb_inv.nrows();
    let proj = |x: &std::ops::Range<usize>, y: &std::ops::Range<usize>| {
        let axy = a.view((x.start, y.start), (x.len(), y.len())).into_owned();
        let axb = a.view((x.start, 0), (x.len(), nb)).into_owned();
        let aby = a.view((0, y.start), (nb, y.len())).into_owned();
        axy - axb * a_bb_inv * aby
    };
    let (s11, s22, s12) = (proj(&r1, &r1), proj(&r2, &r2), proj(&r1, &r2));
    let m = fit::pinv(&s11) * &s12 * fit::pinv(&s22) * s12.transpose();
    let ev = m.complex_eigenvalues();
    ev.iter()
        .map(|c| c.re)
        .fold(0.0, f64::max)
        .clamp(0.0, 1.0)
        .sqrt()
}

/// Resamples for the stability check.
pub(super) const BOOTSTRAP: usize = 100;

/// Least share of resamples whose selection must hold a named effect (or a look-alike).
pub(super) const STABLE: f64 = 0.8;

/// Rounds of the linearised selection in each resample.
pub(super) const SELECT_ROUNDS: usize = 4;

/// The selected sets of [`BOOTSTRAP`] resamples by configuration: multiplicities drawn with
/// `rng` applied to each training block's normal equations `blocks` (plus `prior`), then a
/// linearised forward selection ([`select`]) over `ranges`. Stability is judged on these
/// sets — how often a candidate (or one of its look-alikes) is in the selection — not on
/// which single candidate ranks first: when several effects are missing at once they
/// compete for first place in every resample, and a first-place rule names none of them.
#[allow(clippy::too_many_arguments)]
pub(super) fn stability(
    blocks: &[(DMatrix<f64>, DVector<f64>)],
    prior: (&DMatrix<f64>, &DVector<f64>),
    nb: usize,
    ranges: &[std::ops::Range<usize>],
    gate: &Gate,
    rng: &mut Pcg64,
) -> Vec<Vec<usize>> {
    use rand::RngExt;
    use rayon::prelude::*;
    let n = blocks.len();
    // the multiplicities drawn in order from `rng`, the resamples' selections in parallel
    let draws: Vec<Vec<f64>> = (0..BOOTSTRAP)
        .map(|_| {
            let mut mult = vec![0.0; n];
            for _ in 0..n {
                mult[rng.random_range(0..n)] += 1.0;
            }
            mult
        })
        .collect();
    let prior_diag = prior.0.diagonal();
    draws
        .par_iter()
        .map(|mult| {
            let mut a = prior.0.clone();
            let mut g = prior.1.clone();
            for ((ab, gb), m) in blocks.iter().zip(mult) {
                if *m > 0.0 {
                    a += ab * *m;
                    g += gb * *m;
                }
            }
            select(&a, &g, nb, ranges, gate, SELECT_ROUNDS, &prior_diag)
        })
        .collect()
}

/// Share of `sets` that hold any candidate of `group`.
pub(super) fn share_holding(sets: &[Vec<usize>], group: &[usize]) -> f64 {
    let hits = sets
        .iter()
        .filter(|s| s.iter().any(|c| group.contains(c)))
        .count();
    hits as f64 / sets.len().max(1) as f64
}

/// Normal equations of every fold's blocks (all columns).
pub(super) struct FoldEqs {
    pub(super) a: Vec<DMatrix<f64>>,
    pub(super) g: Vec<DVector<f64>>,
    pub(super) a_train: DMatrix<f64>,
    pub(super) g_train: DVector<f64>,
}

impl FoldEqs {
    /// The training equations with `prior` (its held directions only) added, over the
    /// columns `slots` at `state`: every linearised refit then holds what the fits hold.
    pub(super) fn with_prior(
        mut self,
        prior: &fit::Prior,
        slots: &[Slot],
        state: &EffectState,
    ) -> Self {
        prior.add_to(slots, state, &mut self.a_train, &mut self.g_train, false);
        self
    }
}

/// The training normal equations and, per fold, what the fold takes out of them (its training
/// configurations; a holdout fold takes out nothing).
pub(super) fn fold_eqs(p: &Problem, lin: &Linearization, folds: &[Vec<usize>]) -> FoldEqs {
    let cols: Vec<usize> = (0..lin.jwhite.ncols()).collect();
    let rows = p.white_rows(|b| b.train);
    // the training equations and each fold's, independent: computed together
    let ((a_train, g_train), (a, g)) = rayon::join(
        || fit::normal_eq(lin, &rows, &cols),
        || fold_parts(p, lin, folds, &cols),
    );
    FoldEqs {
        a,
        g,
        a_train,
        g_train,
    }
}

/// What each fold takes out of the training normal equations.
#[allow(clippy::type_complexity)]
fn fold_parts(
    p: &Problem,
    lin: &Linearization,
    folds: &[Vec<usize>],
    cols: &[usize],
) -> (Vec<DMatrix<f64>>, Vec<DVector<f64>>) {
    use rayon::prelude::*;
    folds
        .par_iter()
        .map(|f| {
            let rows: Vec<usize> = f
                .iter()
                .filter(|&&b| p.blocks[b].train)
                .flat_map(|&b| {
                    let bl = &p.blocks[b];
                    bl.offset..bl.offset + 6 * (bl.rows.len() + 1)
                })
                .collect();
            if rows.is_empty() {
                (
                    DMatrix::zeros(cols.len(), cols.len()),
                    DVector::zeros(cols.len()),
                )
            } else {
                fit::normal_eq(lin, &rows, cols)
            }
        })
        .unzip()
}

/// Per configuration, how much `after` lowers `before` (the held-out cost drops a paired
/// comparison takes).
pub(super) fn drops(before: &[f64], after: &[f64]) -> Vec<f64> {
    before.iter().zip(after).map(|(b, a)| b - a).collect()
}

impl Score {
    /// `e`'s score before any test: `params` parameters, `identifiable` of them beyond the
    /// current model, no evidence yet.
    pub(super) fn untested(e: &Effect, params: usize, identifiable: usize) -> Self {
        Self {
            label: e.label(),
            name: e.kind.name(),
            joint: e.joint(),
            params,
            identifiable,
            delta_chi2: 0.0,
            delta_bic: f64::NEG_INFINITY,
            p_adjusted: 1.0,
            heldout_gain: None,
            paired_t: None,
            rank_p: None,
            heldout_gap_mm: None,
            stability: None,
            passed: false,
            note: String::new(),
        }
    }
}

/// The held-out comparison of two models over held-out configurations (`d`: per
/// configuration cost drop): a one-sided paired t-test with a positive mean gain, or a
/// Wilcoxon signed-rank test with a positive median gain, each at α/2 (Bonferroni). The
/// rank path asks for the median, not the mean: a few configurations that lose heavily
/// (a sticking run's held-out set, docs/judge.md §9) must not veto a gain every other
/// configuration shows, which is what the rank test is there for.
pub(super) struct Paired {
    pub(super) mean: f64,
    pub(super) t: f64,
    pub(super) t_crit: f64,
    pub(super) better: usize,
    pub(super) rank_p: f64,
    pub(super) pass: bool,
    /// Held-out configurations compared.
    pub(super) n: usize,
}

impl Paired {
    pub(super) fn new(d: &[f64], alpha: f64) -> Self {
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n.max(1.0);
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
        let t = if sd > 0.0 {
            mean / (sd / n.sqrt())
        } else {
            0.0
        };
        let t_crit = stats::t_quantile(1.0 - 0.5 * alpha, (n - 1.0).max(1.0));
        let better = d.iter().filter(|x| **x > 0.0).count();
        // Ranks cannot be fooled by a few heavy-tailed per-configuration gains, and use
        // their sizes where a sign test would count only their signs.
        let rank_p = stats::signed_rank_test(d);
        let median = stats::median(&mut d.to_vec()).unwrap_or(0.0);
        Self {
            mean,
            t,
            t_crit,
            better,
            rank_p,
            pass: (mean > 0.0 && t > t_crit) || (median > 0.0 && rank_p < 0.5 * alpha),
            n: d.len(),
        }
    }
}

/// A look-alike that passes every test, with its linearised held-out comparison with the
/// current model.
pub(super) struct Member {
    /// Index of the candidate.
    pub(super) cand: usize,
    /// The paired held-out test against the current model.
    pub(super) test: Paired,
    /// Held-out RMS position error with it, mm.
    pub(super) gap_mm: f64,
    /// Whitened held-out cost per held-out configuration with it.
    pub(super) costs: Vec<f64>,
}

/// Chooses among look-alikes `members` (candidates of `cands`; the first is the one that
/// led): the best held-out gain when a paired test over the held-out configurations (at
/// `alpha`) shows it better than the most plausible one ([`Kind::plausibility`]), else the
/// most plausible. Returns the index in `members` and, when there were several, why.
pub(super) fn choose_look_alike(
    members: &[Member],
    cands: &[Effect],
    alpha: f64,
) -> (usize, Option<String>) {
    if members.len() < 2 {
        return (0, None);
    }
    let best = (0..members.len())
        .max_by(|&x, &y| members[x].test.mean.total_cmp(&members[y].test.mean))
        .unwrap_or(0);
    // The most plausible kind; among equally plausible ones the fewest parameters.
    let plausible = (0..members.len())
        .min_by_key(|&k| {
            let e = &cands[members[k].cand];
            (e.kind.plausibility(), e.slots().len())
        })
        .unwrap_or(0);
    let d: Vec<f64> = members[plausible]
        .costs
        .iter()
        .zip(&members[best].costs)
        .map(|(p, b)| p - b)
        .collect();
    let apart = Paired::new(&d, alpha);
    let label = |k: usize| cands[members[k].cand].label();
    let others: Vec<String> = (0..members.len())
        .filter(|&k| k != best && k != plausible)
        .map(label)
        .collect();
    let rest = if others.is_empty() {
        String::new()
    } else {
        format!(" (also alike: {})", others.join(", "))
    };
    if best == plausible {
        let why = format!(
            "{} chosen among its look-alikes: the best held-out gain and the most plausible{rest}",
            label(best)
        );
        (best, Some(why))
    } else if apart.pass {
        let why = format!(
            "{} chosen over its look-alike {}: the held-out data tell them apart (paired t = {:.2}, {} of {} held-out configurations better){rest}",
            label(best),
            label(plausible),
            apart.t,
            apart.better,
            d.len()
        );
        (best, Some(why))
    } else {
        let (p, b) = (&cands[members[plausible].cand], &cands[members[best].cand]);
        let reason = if p.kind.plausibility() < b.kind.plausibility() {
            format!(
                "the physically more plausible one ({})",
                p.kind.plausibility_reason()
            )
        } else {
            format!(
                "the one with fewer parameters ({} against {})",
                p.slots().len(),
                b.slots().len()
            )
        };
        let why = format!(
            "{} chosen over its look-alike {}: the held-out data cannot tell them apart (paired t = {:.2}), so {reason}{rest}",
            label(plausible),
            label(best),
            apart.t,
        );
        (plausible, Some(why))
    }
}

/// The lack-of-fit test on the noise model's own weights (dispersion 1), at the fit `at`
/// (linearised on `p`'s observations).
pub(super) fn plain_lack_of_fit(p: &Problem, at: &fit::Fitted) -> (LackOfFit, DMatrix<f64>) {
    let mut plain = p.clone();
    plain.dispersion = (1.0, 1.0);
    lack_of_fit(&plain, &at.lin.rewhitened(&plain))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(cand: usize, base: &[f64], costs: Vec<f64>) -> Member {
        let d: Vec<f64> = base.iter().zip(&costs).map(|(a, b)| a - b).collect();
        Member {
            cand,
            test: Paired::new(&d, 0.01),
            gap_mm: 0.3,
            costs,
        }
    }

    /// Bending of the upper arm gains a little more on held-out data than the J3 spring, but
    /// not significantly: the spring, the more plausible, is taken and the reason said; when
    /// the bending is better on every held-out configuration by a clear margin, it is taken.
    #[test]
    fn look_alikes_are_told_apart_by_held_out_data_else_by_plausibility() {
        let cands = [
            Effect {
                kind: Kind::LinkBending,
                target: Some(1),
            },
            Effect {
                kind: Kind::JointComplianceLinear,
                target: Some(2),
            },
        ];
        let base = vec![10.0; 20];
        let spring: Vec<f64> = (0..20).map(|i| 5.0 + 0.5 * ((i % 2) as f64)).collect();
        let close: Vec<f64> = (0..20)
            .map(|i| 5.0 + 0.5 * (((i + 1) % 2) as f64) - 0.01)
            .collect();
        let (k, why) = choose_look_alike(
            &[member(0, &base, close), member(1, &base, spring.clone())],
            &cands,
            0.01,
        );
        assert_eq!(k, 1);
        assert!(why.unwrap().contains("cannot tell them apart"));
        let clearly: Vec<f64> = spring.iter().map(|c| c - 1.0).collect();
        let (k, why) = choose_look_alike(
            &[member(0, &base, clearly), member(1, &base, spring)],
            &cands,
            0.01,
        );
        assert_eq!(k, 0);
        assert!(why.unwrap().contains("tell them apart"));
        assert_eq!(
            choose_look_alike(&[member(1, &base, vec![5.0; 20])], &cands, 0.01),
            (0, None)
        );
    }

    /// Equally plausible look-alikes the held-out data cannot tell apart (a J3 transmission
    /// error of 8 parameters gaining a little more than a gear-ratio error of 1): the one
    /// with fewer parameters is taken, and the reason says so.
    #[test]
    fn equally_plausible_look_alikes_go_to_the_fewer_parameters() {
        let cands = [
            Effect {
                kind: Kind::TransmissionError,
                target: Some(2),
            },
            Effect {
                kind: Kind::GearRatioError,
                target: Some(2),
            },
        ];
        let base = vec![10.0; 20];
        let ratio: Vec<f64> = (0..20).map(|i| 5.0 + 0.5 * ((i % 2) as f64)).collect();
        let more: Vec<f64> = (0..20)
            .map(|i| 5.0 + 0.5 * (((i + 1) % 2) as f64) - 0.01)
            .collect();
        let (k, why) = choose_look_alike(
            &[member(0, &base, more), member(1, &base, ratio)],
            &cands,
            0.01,
        );
        assert_eq!(k, 1);
        assert!(why.unwrap().contains("fewer parameters (1 against 8)"));
    }

    /// A few held-out configurations that lose heavily do not veto a gain the others show
    /// consistently (stick seed 7 of docs/judge.md §9: three of 49 lose χ² 68–199, the mean
    /// is negative); a consistent loss with a few large gains passes neither test.
    #[test]
    fn a_few_heavy_losses_do_not_veto_a_consistent_gain() {
        let mut d: Vec<f64> = (0..46).map(|i| 1.0 + 0.2 * i as f64).collect();
        d.extend([-90.0, -200.0, -70.0]);
        let p = Paired::new(&d, 0.01);
        assert!(p.mean < 0.0 && p.t < 0.0, "mean {} t {}", p.mean, p.t);
        assert!(p.pass, "rank p {:.1e}", p.rank_p);
        let e: Vec<f64> = d.iter().map(|x| -x).collect();
        let q = Paired::new(&e, 0.01);
        assert!(q.mean > 0.0 && !q.pass, "t {} rank p {:.1e}", q.t, q.rank_p);
        // no gain at all passes nothing
        assert!(!Paired::new(&[0.0; 10], 0.01).pass);
    }

    /// The signed-rank test sees a consistent gain that a sign test misses: 14 of 20
    /// held-out configurations better, the better ones by more.
    #[test]
    fn the_rank_test_uses_the_sizes_of_the_gains() {
        let d: Vec<f64> = (0..20)
            .map(|i| {
                if i < 14 {
                    1.0 + i as f64
                } else {
                    -0.1 * (i as f64 - 13.0)
                }
            })
            .collect();
        let rank = stats::signed_rank_test(&d);
        let sign = stats::sign_test(14, 20);
        assert!(
            rank < 1e-3 && sign > 0.05,
            "rank {rank:.2e}, sign {sign:.2e}"
        );
    }
}
