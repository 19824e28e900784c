//! The held-out prediction: how a model (linearised or refitted) predicts the held-out
//! configurations — whitened cost per configuration, the RMS position error the verdict
//! judges and its per-configuration parts — and the rule that lets the RMS grow with a
//! significant whitened gain.

use super::*;

/// The model over `slots` (held by `prior`) refitted from `start` on `p`'s weights (`p` itself unchanged),
/// and its held-out evaluation ([`heldout`]).
pub(super) fn refit_heldout(
    p: &Problem,
    start: &EffectState,
    slots: &[Slot],
    prior: &fit::Prior,
    lay: &Layout,
) -> Result<HeldOut, DiscoverError> {
    let fitted = fit::fit_balanced(&mut p.clone(), start, slots, prior)?;
    let lin = fitted.lin.rewhitened(p);
    let eqs = fold_eqs(p, &lin, &lay.folds).with_prior(prior, slots, &fitted.state);
    let cols: Vec<usize> = (0..slots.len()).collect();
    Ok(heldout(p, &lin, &eqs, &lay.folds, &cols))
}

/// Whether block `b` of `folds` counts in the held-out gap: the holdout set's blocks when the
/// folds include one, else every fold's (a cross-validated training configuration is
/// predicted by a model fitted without it, the holdout set by the model itself).
pub(super) fn in_gap<'a>(p: &'a Problem, folds: &[Vec<usize>]) -> impl Fn(usize) -> bool + 'a {
    let any_holdout = folds.iter().flatten().any(|&b| !p.blocks[b].train);
    move |b| !(any_holdout && p.blocks[b].train)
}

/// A model's prediction of the held-out configurations ([`heldout`]).
pub(super) struct HeldOut {
    /// Whitened cost per held-out configuration (every fold's).
    pub(super) costs: Vec<f64>,
    /// RMS position error over the configurations [`in_gap`] counts, mm: the gap the verdict
    /// judges.
    pub(super) gap_mm: f64,
    /// Per configuration [`in_gap`] counts, in the same order: its mean squared position
    /// error, mm².
    pub(super) sq_mm2: Vec<f64>,
}

/// Held-out evaluation of a linearised refit over columns `cols`: per held-out block
/// whitened cost (every fold's), and the position error (mm) over the blocks [`in_gap`]
/// (the gap the verdict judges).
pub(super) fn heldout(
    p: &Problem,
    lin: &Linearization,
    eqs: &FoldEqs,
    folds: &[Vec<usize>],
    cols: &[usize],
) -> HeldOut {
    let sub =
        |m: &DMatrix<f64>| DMatrix::from_fn(cols.len(), cols.len(), |i, j| m[(cols[i], cols[j])]);
    let subv = |v: &DVector<f64>| DVector::from_fn(cols.len(), |i, _| v[cols[i]]);
    let mut costs = Vec::new();
    let mut sq_mm2 = Vec::new();
    let (mut ss, mut n) = (0.0, 0usize);
    let mut white = vec![0.0; 0];
    let counts = in_gap(p, folds);
    for (f, blocks) in folds.iter().enumerate() {
        let a = sub(&eqs.a_train) - sub(&eqs.a[f]);
        let g = subv(&eqs.g_train) - subv(&eqs.g[f]);
        let (d, _) = fit::damped_solve(&a, &g, 0.0);
        for &b in blocks {
            let bl = &p.blocks[b];
            let len = 6 * (bl.rows.len() + 1);
            white.clear();
            white.extend((0..len).map(|k| {
                let i = bl.offset + k;
                lin.white[i]
                    + cols
                        .iter()
                        .enumerate()
                        .map(|(c, &col)| lin.jwhite[(i, col)] * d[c])
                        .sum::<f64>()
            }));
            costs.push(white.iter().map(|x| x * x).sum());
            if !counts(b) {
                continue;
            }
            let mut block_ss = 0.0;
            for &i in &bl.rows {
                let mut r = lin.raw[i];
                for (c, &col) in cols.iter().enumerate() {
                    r += lin.jraw[col][i] * d[c];
                }
                block_ss += r.fixed_rows::<3>(0).norm_squared();
            }
            ss += block_ss;
            n += bl.rows.len();
            sq_mm2.push(block_ss / bl.rows.len().max(1) as f64 * 1e6);
        }
    }
    HeldOut {
        costs,
        gap_mm: (ss / n.max(1) as f64).sqrt() * 1e3,
        sq_mm2,
    }
}

/// Whether a refit's held-out RMS position error lets its whitened gain stand (`held_mm`:
/// before and after, mm): it may grow by 1 %; by more only where that growth is not
/// significant over the configurations the RMS counts (`worse`: per configuration, its mean
/// squared position error after − before, tested as a gain is) *and* the refit fits its own
/// training data better in position too (`train_mm`: that RMS before and after, mm).
///
/// The whitening takes each configuration's common offset as the repeatable resolver error
/// it expects; the RMS does not. So a spring that makes every configuration's error the same
/// at every load raises the RMS of the configurations whose offset its absence happened to
/// cancel at the large loads (docs/discovery.md) — while it fits the training positions
/// better. An effect whose refit makes the training positions worse as well buys whitened
/// cost with position error everywhere: the weights favour it, not the arm.
pub(super) fn rms_allows(held_mm: [f64; 2], train_mm: [f64; 2], worse: &Paired) -> bool {
    held_mm[1] <= 1.01 * held_mm[0] || (!worse.pass && train_mm[1] < train_mm[0])
}

/// Why a refit failed its held-out test alone (`others`: how it fared among its companions,
/// if asked), as the report prints it.
pub(super) fn rejected_note(
    g_prev: f64,
    g2: f64,
    test: &Paired,
    worse: &Paired,
    others: &str,
) -> String {
    let worse = if worse.pass {
        format!(" (significantly worse: paired t = {:.2})", worse.t)
    } else {
        String::new()
    };
    format!(
        "rejected after the nonlinear refit: held-out RMS {g_prev:.3} → {g2:.3} mm{worse}, paired t = {:.2}, {} of {} held-out configurations better{others}",
        test.t, test.better, test.n
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rms(ms: &[f64]) -> f64 {
        (ms.iter().sum::<f64>() / ms.len() as f64).sqrt()
    }

    /// MuJoCo's sticking-drive campaign, seed 4 (`mujoco_judge --keep`): with J4's spring 35 of
    /// 37 held-out configurations gain on the whitened cost, while the RMS over the ten of the
    /// holdout set grows 3 % (the linearised refit's errors; 5 % at the nonlinear one) — seven
    /// configurations worse by a little, one better by much: not a significant loss, so the
    /// gain stands. Every configuration 8 % worse is refused.
    #[test]
    fn the_rms_may_grow_only_where_that_is_not_significant() {
        let before = [
            0.0679, 0.0194, 0.0530, 0.0177, 0.0950, 0.5320, 0.0489, 0.1207, 0.1810, 0.0374,
        ];
        let after = [
            0.1083, 0.0294, 0.0754, 0.0159, 0.0891, 0.5869, 0.0528, 0.1470, 0.1035, 0.0457,
        ];
        let (b, a) = (rms(&before), rms(&after));
        assert!(a > 1.03 * b, "{b:.4} → {a:.4} mm");
        let worse = Paired::new(&drops(&after, &before), 0.01);
        assert!(
            !worse.pass,
            "t = {:.2}, rank p = {:.2}",
            worse.t, worse.rank_p
        );
        assert!(rms_allows([b, a], [0.237, 0.229], &worse));
        // The same held-out errors with the training positions worse (bending of link 4 on
        // currents that read zero, tests/cli.rs: training RMS 1.265 → 1.319 mm): refused.
        assert!(!rms_allows([b, a], [1.265, 1.319], &worse));

        let all_worse: Vec<f64> = before
            .iter()
            .enumerate()
            .map(|(i, m)| m * (1.08 + 0.01 * (i % 3) as f64))
            .collect();
        let worse = Paired::new(&drops(&all_worse, &before), 0.01);
        assert!(worse.pass);
        assert!(!rms_allows([b, rms(&all_worse)], [0.237, 0.229], &worse));
        // Within 1 %, whatever the test says.
        assert!(rms_allows([b, 1.009 * b], [1.265, 1.319], &worse));
    }
}
