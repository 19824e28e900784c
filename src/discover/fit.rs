//! The least-squares machinery of discovery: whitened residuals, finite-difference
//! Jacobians over any list of [`Slot`]s, Levenberg–Marquardt, and linearised refits on
//! subsets of configurations (cross-validation).
//!
//! **Noise model (whitening).** Rows of one configuration share the resolver error of that
//! configuration (the servo holds the same resolver reading for every load and repeat), so
//! their residuals share a random offset with covariance `S_c = J_c·σ_r²·J_cᵀ` (`J_c` the
//! pose Jacobian there, `σ_r` the resolver error per joint) on top of independent instrument
//! noise `D_i` of each row (instrument noise plus the measured-torque noise seen through the
//! springs). For a configuration the covariance is `blockdiag(D_i) + 11ᵀ⊗S_c`; it is
//! whitened exactly by `(S_c + P⁻¹)^{-1/2}·m̂` (the precision-weighted mean
//! `m̂ = P⁻¹·Σ D_i⁻¹ r_i`, `P = Σ D_i⁻¹`) and `D_i^{-1/2}(r_i − m̂)` (the deviations), so the
//! sum of squares is the generalised least-squares cost and has a χ² distribution under a
//! correct model.

use nalgebra::{DMatrix, DVector, Matrix6, SymmetricEigen, Vector6};

use crate::noise::sym_pow as inv_pow;
use rayon::prelude::*;

use super::effects::{EffectState, Obs, Slot, residual};
use crate::model::{Model, ModelError};

/// One configuration's rows and whitening.
#[derive(Debug, Clone)]
pub(crate) struct Block {
    /// Observation indices.
    pub rows: Vec<usize>,
    /// Whether the fit uses it (false: held out).
    pub train: bool,
    /// Cells of repeats (same load, direction, temperature), observation indices.
    pub cells: Vec<Vec<usize>>,
    /// `(Σ D_i⁻¹)⁻¹`: covariance of the precision-weighted mean from row noise alone.
    pub p_inv: Matrix6<f64>,
    /// Whitening of the weighted mean: `(S_c + (Σ D_i⁻¹)⁻¹)^{-1/2}`.
    pub wmean: Matrix6<f64>,
    /// First whitened index of the block.
    pub offset: usize,
}

/// The data of a discovery run with its noise model.
#[derive(Debug, Clone)]
pub(crate) struct Problem {
    /// Every observation (training and held out).
    pub obs: Vec<Obs>,
    /// Configuration blocks.
    pub blocks: Vec<Block>,
    /// Per observation: `D_i` (row noise covariance).
    pub d: Vec<Matrix6<f64>>,
    /// Per observation: `D_i⁻¹` (row noise precision).
    pub d_inv: Vec<Matrix6<f64>>,
    /// Per observation: `D_i^{-1/2}`.
    pub d_inv_sqrt: Vec<Matrix6<f64>>,
    /// Length of the whitened vector.
    pub n_white: usize,
    /// Dispersion of the configuration means and of the deviations from them (1 for the
    /// noise model as estimated; larger while the model grossly misfits, see [`balanced`]).
    pub dispersion: (f64, f64),
}

impl Problem {
    /// Builds the whitening from each row's noise covariance `d` (6×6, instrument and
    /// torque noise) and the resolver error `sigma_resolver` (rad, per joint) through the
    /// pose Jacobian of `geom` at the link angles of `state`.
    pub fn new(
        obs: Vec<Obs>,
        blocks: Vec<super::layout::ConfigRows>,
        d: &[Matrix6<f64>],
        state: &EffectState,
        geom: &Model,
        sigma_resolver: f64,
    ) -> Self {
        let d_inv: Vec<Matrix6<f64>> = d.iter().map(|m| inv_pow(m, -1.0)).collect();
        let d_inv_sqrt: Vec<Matrix6<f64>> = d.iter().map(|m| inv_pow(m, -0.5)).collect();
        let mut offset = 0;
        let blocks = blocks
            .into_iter()
            .map(|super::layout::ConfigRows { rows, train, cells }| {
                let q = super::effects::link_angles(state, &obs[rows[0]]);
                let j = geom.jacobian(&q);
                let s = j * j.transpose() * (sigma_resolver * sigma_resolver);
                let p = rows.iter().map(|&i| d_inv[i]).sum::<Matrix6<f64>>();
                let p_inv = inv_pow(&p, -1.0);
                let wmean = inv_pow(&(s + p_inv), -0.5);
                let b = Block {
                    train,
                    cells,
                    p_inv,
                    wmean,
                    offset,
                    rows,
                };
                offset += 6 * (b.rows.len() + 1);
                b
            })
            .collect();
        Self {
            obs,
            blocks,
            d: d.to_vec(),
            d_inv,
            d_inv_sqrt,
            n_white: offset,
            dispersion: (1.0, 1.0),
        }
    }

    /// Raw residuals (pose errors, m and rad) of every observation at `state`.
    pub fn raw(&self, state: &EffectState) -> Result<Vec<Vector6<f64>>, ModelError> {
        let geom = state.geometry()?;
        Ok(self.raw_with(state, &geom))
    }

    fn raw_with(&self, state: &EffectState, geom: &Model) -> Vec<Vector6<f64>> {
        self.obs.iter().map(|o| residual(state, geom, o)).collect()
    }

    /// Precision-weighted mean of `raw` over `rows`, with `p_inv = (Σ D_i⁻¹)⁻¹`.
    fn weighted_mean(
        &self,
        raw: &[Vector6<f64>],
        rows: &[usize],
        p_inv: &Matrix6<f64>,
    ) -> Vector6<f64> {
        p_inv
            * rows
                .iter()
                .map(|&i| self.d_inv[i] * raw[i])
                .sum::<Vector6<f64>>()
    }

    /// Whitens per-observation vectors (residuals or a Jacobian column) into `out`:
    /// per block the whitened weighted mean, then every row's whitened deviation from it.
    pub fn whiten(&self, raw: &[Vector6<f64>], out: &mut [f64]) {
        self.whiten_with(raw, out, self.dispersion);
    }

    /// [`Problem::whiten`] with the strata scaled by `dispersion` instead of the problem's
    /// own.
    pub fn whiten_with(&self, raw: &[Vector6<f64>], out: &mut [f64], dispersion: (f64, f64)) {
        let (km, kd) = (1.0 / dispersion.0.sqrt(), 1.0 / dispersion.1.sqrt());
        for b in &self.blocks {
            let mean = self.weighted_mean(raw, &b.rows, &b.p_inv);
            let m = b.wmean * mean * km;
            out[b.offset..b.offset + 6].copy_from_slice(m.as_slice());
            for (k, &i) in b.rows.iter().enumerate() {
                let dv = self.d_inv_sqrt[i] * (raw[i] - mean) * kd;
                let o = b.offset + 6 * (k + 1);
                out[o..o + 6].copy_from_slice(dv.as_slice());
            }
        }
    }

    /// Whitened indices of the blocks selected by `pick`.
    pub fn white_rows(&self, pick: impl Fn(&Block) -> bool) -> Vec<usize> {
        self.blocks
            .iter()
            .filter(|b| pick(b))
            .flat_map(|b| b.offset..b.offset + 6 * (b.rows.len() + 1))
            .collect()
    }

    /// Sum of squares of the pure error (repeats within cells), whitened, and its degrees
    /// of freedom, over training blocks.
    pub fn pure_error(&self, raw: &[Vector6<f64>]) -> (f64, usize) {
        let (mut ss, mut dof) = (0.0, 0);
        for b in self.blocks.iter().filter(|b| b.train) {
            for c in &b.cells {
                if c.len() < 2 {
                    continue;
                }
                let p = c.iter().map(|&i| self.d_inv[i]).sum::<Matrix6<f64>>();
                let mean = self.weighted_mean(raw, c, &inv_pow(&p, -1.0));
                ss += c
                    .iter()
                    .map(|&i| (self.d_inv_sqrt[i] * (raw[i] - mean)).norm_squared())
                    .sum::<f64>();
                dof += 6 * (c.len() - 1);
            }
        }
        (ss, dof)
    }
}

/// The dispersions for fitting a model that misfits grossly: each stratum (the
/// configuration means, the deviations from them) scaled by its own whitened mean square
/// at `raw` on the noise model's weights (at least 1). A model missing a large effect
/// otherwise trades a huge within-configuration misfit (weighted by the instrument's micrometres) for a contorted
/// geometry that wrecks every prediction; balanced, the fit spreads the misfit as a
/// quasi-likelihood would. Tests and scores always use the unbalanced problem.
pub(crate) fn balanced(p: &Problem, raw: &[Vector6<f64>]) -> (f64, f64) {
    let mut white = vec![0.0; p.n_white];
    p.whiten_with(raw, &mut white, (1.0, 1.0));
    let (mut sm, mut nm, mut sd, mut nd) = (0.0, 0usize, 0.0, 0usize);
    for b in p.blocks.iter().filter(|b| b.train) {
        sm += white[b.offset..b.offset + 6]
            .iter()
            .map(|x| x * x)
            .sum::<f64>();
        nm += 6;
        sd += white[b.offset + 6..b.offset + 6 * (b.rows.len() + 1)]
            .iter()
            .map(|x| x * x)
            .sum::<f64>();
        nd += 6 * (b.rows.len() - 1);
    }
    (
        (sm / nm.max(1) as f64).max(1.0),
        (sd / nd.max(1) as f64).max(1.0),
    )
}

/// Levenberg–Marquardt on a [`balanced`] problem, re-balanced at each solution (three
/// rounds at most) until the dispersions settle below 1.5, when it is the plain
/// generalised least-squares fit. `p.dispersion` is left at the weights of the solution,
/// and the result is linearised on them: held-out refits and scores then agree with the
/// fit (a balanced solution is not an optimum of the original weights, and refitting on
/// those would walk back into the contorted optimum). Tests of lack of fit reset the
/// dispersion to 1.
pub(crate) fn fit_balanced(
    p: &mut Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &[f64],
) -> Result<Fitted, ModelError> {
    let mut st = state.clone();
    p.dispersion = (1.0, 1.0);
    for _ in 0..3 {
        let raw = p.raw(&st)?;
        let b = balanced(p, &raw);
        if b.0 < 1.5 && b.1 < 1.5 {
            break;
        }
        p.dispersion = b;
        st = fit(p, &st, slots, prior)?.state;
    }
    fit(p, &st, slots, prior)
}

/// The whitened training cost plus prior of `state` on `p`'s weights.
pub(crate) fn cost_at(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &[f64],
) -> Result<f64, ModelError> {
    let raw = p.raw(state)?;
    let mut white = vec![0.0; p.n_white];
    p.whiten(&raw, &mut white);
    let u = slots
        .iter()
        .zip(prior)
        .map(|(s, w)| w * (state.get(*s) / s.scale()).powi(2));
    Ok(p.white_rows(|b| b.train)
        .iter()
        .map(|&i| white[i].powi(2))
        .sum::<f64>()
        + u.sum::<f64>())
}

/// Residuals and scaled Jacobian at a state.
#[derive(Debug, Clone)]
pub(crate) struct Linearization {
    /// Raw residual per observation.
    pub raw: Vec<Vector6<f64>>,
    /// Whitened residuals (all blocks).
    pub white: DVector<f64>,
    /// Raw Jacobian columns per slot (d residual / d (value / scale)).
    pub jraw: Vec<Vec<Vector6<f64>>>,
    /// Whitened Jacobian (all blocks × slots).
    pub jwhite: DMatrix<f64>,
}

/// Residuals and finite-difference Jacobian of `slots` at `state` (columns in parallel).
pub(crate) fn linearise(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
) -> Result<Linearization, ModelError> {
    let geom = state.geometry()?;
    let raw = p.raw_with(state, &geom);
    let jraw: Vec<Vec<Vector6<f64>>> = slots
        .par_iter()
        .map(|&slot| {
            let h = 1e-3 * slot.scale();
            // Forward difference, backward when the forward point leaves the valid space.
            let mut out = None;
            for h in [h, -h] {
                let mut s = state.clone();
                s.set(slot, state.get(slot) + h);
                let g = if slot.geometric() {
                    match s.geometry() {
                        Ok(g) => g,
                        Err(_) => continue,
                    }
                } else {
                    geom.clone()
                };
                let r2 = p.raw_with(&s, &g);
                out = Some(
                    r2.iter()
                        .zip(&raw)
                        .map(|(a, b)| (a - b) * (slot.scale() / h))
                        .collect(),
                );
                break;
            }
            out.ok_or_else(|| ModelError::Invalid {
                key: format!("{slot:?}"),
                reason: "no valid finite-difference step".into(),
            })
        })
        .collect::<Result<_, ModelError>>()?;
    let mut white = DVector::zeros(p.n_white);
    p.whiten(&raw, white.as_mut_slice());
    let mut jwhite = DMatrix::zeros(p.n_white, slots.len());
    let mut col = vec![0.0; p.n_white];
    for (k, c) in jraw.iter().enumerate() {
        p.whiten(c, &mut col);
        jwhite.column_mut(k).copy_from_slice(&col);
    }
    Ok(Linearization {
        raw,
        white,
        jraw,
        jwhite,
    })
}

/// Normal equations `JᵀJ`, `Jᵀr` over whitened `rows` and columns `cols`.
pub(crate) fn normal_eq(
    lin: &Linearization,
    rows: &[usize],
    cols: &[usize],
) -> (DMatrix<f64>, DVector<f64>) {
    let k = cols.len();
    let mut a = DMatrix::zeros(k, k);
    let mut g = DVector::zeros(k);
    let mut jr = vec![0.0; k];
    for &i in rows {
        for (c, &col) in cols.iter().enumerate() {
            jr[c] = lin.jwhite[(i, col)];
        }
        let r = lin.white[i];
        for a_ in 0..k {
            let x = jr[a_];
            if x == 0.0 {
                continue;
            }
            g[a_] += x * r;
            for b_ in a_..k {
                a[(a_, b_)] += x * jr[b_];
            }
        }
    }
    for a_ in 0..k {
        for b_ in 0..a_ {
            a[(a_, b_)] = a[(b_, a_)];
        }
    }
    (a, g)
}

/// Solves `(A + λI)·δ = −g` on the eigen-subspace of `A` above a relative `1e-10` (the
/// directions the data do not see get no step). Returns δ and the rank used.
pub(crate) fn damped_solve(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    lambda: f64,
) -> (DVector<f64>, usize) {
    let e = SymmetricEigen::new(a.clone());
    let emax = e.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut d = DVector::zeros(g.len());
    let mut rank = 0;
    for (i, &ev) in e.eigenvalues.iter().enumerate() {
        if ev > 1e-10 * emax && ev > 0.0 {
            let v = e.eigenvectors.column(i);
            d -= v * (v.dot(g) / (ev + lambda));
            rank += 1;
        }
    }
    (d, rank)
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix (same cut as
/// [`damped_solve`]).
pub(crate) fn pinv(a: &DMatrix<f64>) -> DMatrix<f64> {
    let e = SymmetricEigen::new(a.clone());
    let emax = e.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut out = DMatrix::zeros(a.nrows(), a.ncols());
    for (i, &ev) in e.eigenvalues.iter().enumerate() {
        if ev > 1e-10 * emax && ev > 0.0 {
            let v = e.eigenvectors.column(i);
            out += v * v.transpose() / ev;
        }
    }
    out
}

/// A converged fit.
#[derive(Debug, Clone)]
pub(crate) struct Fitted {
    /// The fitted state.
    pub state: EffectState,
    /// Whitened training cost.
    pub cost: f64,
    /// Linearisation at the solution.
    pub lin: Linearization,
}

/// Standard deviation, in units of a slot's scale, of the weak prior that holds effect
/// parameters (not the model's own) at zero in directions the data barely see.
pub(crate) const EFFECT_PRIOR: f64 = 10.0;

/// Prior precision (normalised units) of each slot: zero for the model's own slots (`own`),
/// `1/EFFECT_PRIOR²` for effect slots.
pub(crate) fn prior(slots: &[Slot], own: &[Slot]) -> Vec<f64> {
    slots
        .iter()
        .map(|s| {
            if own.contains(s) {
                0.0
            } else {
                1.0 / (EFFECT_PRIOR * EFFECT_PRIOR)
            }
        })
        .collect()
}

/// Levenberg–Marquardt on the training blocks over `slots`, from `state`, with prior
/// precisions `prior` (normalised units, centred on zero).
pub(crate) fn fit(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &[f64],
) -> Result<Fitted, ModelError> {
    let rows = p.white_rows(|b| b.train);
    let cols: Vec<usize> = (0..slots.len()).collect();
    let norm =
        |st: &EffectState| -> Vec<f64> { slots.iter().map(|s| st.get(*s) / s.scale()).collect() };
    let prior_cost = |u: &[f64]| u.iter().zip(prior).map(|(u, w)| w * u * u).sum::<f64>();
    let cost_of =
        |lin_white: &DVector<f64>| rows.iter().map(|&i| lin_white[i].powi(2)).sum::<f64>();
    let with_prior = |a: &mut DMatrix<f64>, g: &mut DVector<f64>, u: &[f64]| {
        for k in 0..u.len() {
            a[(k, k)] += prior[k];
            g[k] += prior[k] * u[k];
        }
    };
    let mut st = state.clone();
    let mut lin = linearise(p, &st, slots)?;
    let mut u = norm(&st);
    let mut cost = cost_of(&lin.white) + prior_cost(&u);
    let (mut a, mut g) = normal_eq(&lin, &rows, &cols);
    with_prior(&mut a, &mut g, &u);
    let mut lambda = 1e-6 * (0..a.nrows()).map(|i| a[(i, i)]).fold(0.0, f64::max);
    let mut white = DVector::zeros(p.n_white);
    for _ in 0..40 {
        let (d, _) = damped_solve(&a, &g, lambda);
        let mut trial = st.clone();
        for (k, &s) in slots.iter().enumerate() {
            trial.set(s, st.get(s) + d[k] * s.scale());
        }
        // A step that leaves the valid model space (e.g. a departure beyond its bound)
        // counts as an increase.
        let ut = norm(&trial);
        let c = match p.raw(&trial) {
            Ok(raw) => {
                p.whiten(&raw, white.as_mut_slice());
                cost_of(&white) + prior_cost(&ut)
            }
            Err(_) => f64::INFINITY,
        };
        if c < cost {
            let gain = cost - c;
            st = trial;
            u = ut;
            cost = c;
            lin = linearise(p, &st, slots)?;
            (a, g) = normal_eq(&lin, &rows, &cols);
            with_prior(&mut a, &mut g, &u);
            lambda = (lambda / 10.0).max(1e-15);
            if gain < 1e-9 * cost.max(1.0) || d.norm() < 1e-9 {
                break;
            }
        } else {
            lambda = lambda.max(1e-12) * 10.0;
            if lambda > 1e12 || d.norm() < 1e-12 {
                break;
            }
        }
    }
    Ok(Fitted {
        state: st,
        cost,
        lin,
    })
}
