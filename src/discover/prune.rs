//! Backward elimination after the forward selection.
//!
//! Forward selection cannot take back an early pick that later effects make redundant (from
//! the rigid model, bending of the forearm looks like the J3 spring until the spring is in).
//! An effect whose removal — linearised at the final fit, the others refitted:
//! `Δχ² = xᵀ·S·x`, S the Schur complement of its block — is no longer significant (F test,
//! Bonferroni over the effects found) or fails ΔBIC is removed and the model refitted,
//! weakest first, until every effect holds.

use super::complete::{Settled, settle};
use super::*;

/// Removes the effects of `found` (and their `slots`) that no longer hold at the final fit
/// `st`, weakest first, refitting after each; returns the refitted model and what was
/// removed, with why.
pub(super) fn prune(
    lay: &Layout,
    prior_of: &dyn Fn(&[Slot]) -> fit::Prior,
    opts: &DiscoverOptions,
    found: &mut Vec<(Effect, f64)>,
    slots: &mut Vec<Slot>,
    mut st: Settled,
) -> Result<(Settled, Vec<String>), DiscoverError> {
    let ln_n = lay.ln_n();
    let mut pruned: Vec<String> = Vec::new();
    while found.len() > 1 {
        let mut plain = st.prob.clone();
        plain.dispersion = (1.0, 1.0);
        let lin = st.cur.lin.rewhitened(&plain);
        let rows = plain.white_rows(|b| b.train);
        let cols: Vec<usize> = (0..slots.len()).collect();
        let (mut a, mut g_unused) = fit::normal_eq(&lin, &rows, &cols);
        prior_of(slots).add_to(slots, &st.cur.state, &mut a, &mut g_unused, false);
        let dispersion = st.lof.between.ratio.min(st.lof.within.ratio).max(1.0);
        let df_pe = test_dof(&plain, &lin.raw, &st.noise);
        let m = found.len() as f64;
        let weakest = found
            .iter()
            .enumerate()
            .map(|(fi, (e, _))| {
                let mine: Vec<usize> = e
                    .slots()
                    .iter()
                    .filter_map(|sl| slots.iter().position(|s| s == sl))
                    .collect();
                let others: Vec<usize> =
                    cols.iter().copied().filter(|c| !mine.contains(c)).collect();
                let sub = |r: &[usize], c: &[usize]| {
                    DMatrix::from_fn(r.len(), c.len(), |i, j| a[(r[i], c[j])])
                };
                let schur = sub(&mine, &mine)
                    - sub(&mine, &others) * fit::pinv(&sub(&others, &others)) * sub(&others, &mine);
                let x = DVector::from_fn(mine.len(), |i, _| {
                    st.cur.state.get(slots[mine[i]]) / slots[mine[i]].scale()
                });
                let chi2 = (x.transpose() * schur * &x)[(0, 0)] / dispersion;
                let k = mine.len() as f64;
                let p = (stats::f_sf(chi2 / k, k, df_pe) * m).min(1.0);
                let bic = chi2 - k * ln_n;
                (fi, p, bic)
            })
            .filter(|&(_, p, bic)| p >= opts.alpha || bic <= opts.min_delta_bic)
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.2.total_cmp(&a.2)));
        let Some((fi, p, bic)) = weakest else { break };
        let (e, _) = found.remove(fi);
        pruned.push(format!(
            "{} (removing it costs ΔBIC {bic:.1}, p = {p:.2e}: the effects found after it explain it)",
            e.label()
        ));
        let mut start = st.cur.state.clone();
        for sl in e.slots() {
            start.set(sl, 0.0);
        }
        slots.retain(|sl| !e.slots().contains(sl));
        st = settle(lay, &start, slots, &prior_of(slots))?;
    }
    Ok((st, pruned))
}
