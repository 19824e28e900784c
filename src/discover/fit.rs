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

use super::effects::Slot;
use super::forward::{EffectState, Near, Obs, residual, residual_near};
use crate::model::params::IDX_THETA;
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
                let q = super::forward::link_angles(state, &obs[rows[0]]);
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

    /// [`Problem::raw_with`], and what each observation's prediction computed ([`Near`]).
    fn raw_and_near(&self, state: &EffectState, geom: &Model) -> (Vec<Vector6<f64>>, Vec<Near>) {
        self.obs
            .iter()
            .map(|o| {
                let mut n = Near::none();
                (residual_near(state, geom, o, &mut n, 0), n)
            })
            .unzip()
    }

    /// [`Problem::raw_with`] at a state near the one `near` was computed at (with geometry
    /// `base`), reusing what did not change.
    fn raw_near(
        &self,
        state: &EffectState,
        geom: &Model,
        (near, base): (&[Near], &Model),
    ) -> Vec<Vector6<f64>> {
        let same = geom.first_joint_unlike(base);
        self.obs
            .iter()
            .zip(near)
            .map(|(o, n)| residual_near(state, geom, o, &mut n.clone(), same))
            .collect()
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
/// rounds at most) until the dispersions settle below 1.5. `p.dispersion` is left at the
/// weights of the solution, and the result is linearised on them: held-out refits and
/// scores then agree with the fit (a balanced solution is not an optimum of the original
/// weights, and refitting on those would walk back into the contorted optimum). A model that
/// fits from the start is the plain generalised least-squares fit. Tests of lack of fit
/// reset the dispersion to 1.
pub(crate) fn fit_balanced(
    p: &mut Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &Prior,
) -> Result<Fitted, ModelError> {
    p.dispersion = (1.0, 1.0);
    let mut last: Option<Fitted> = None;
    for _ in 0..3 {
        let b = match &last {
            Some(f) => balanced(p, &f.lin.raw),
            None => balanced(p, &p.raw(state)?),
        };
        if b.0 < 1.5 && b.1 < 1.5 {
            break;
        }
        p.dispersion = b;
        let from = last.as_ref().map_or(state, |f| &f.state);
        last = Some(fit(p, from, slots, prior)?);
    }
    // The last round's fit is on the weights `p` holds: it is the solution.
    match last {
        Some(f) => Ok(f),
        None => fit(p, state, slots, prior),
    }
}

/// The whitened training cost plus prior of `state` on `p`'s weights.
pub(crate) fn cost_at(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &Prior,
) -> Result<f64, ModelError> {
    let raw = p.raw(state)?;
    let mut white = vec![0.0; p.n_white];
    p.whiten(&raw, &mut white);
    Ok(p.white_rows(|b| b.train)
        .iter()
        .map(|&i| white[i].powi(2))
        .sum::<f64>()
        + prior.cost(slots, state))
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
    /// What each observation's prediction computed at the state.
    near: Vec<Near>,
}

/// Residuals and finite-difference Jacobian of `slots` at `state` (columns in parallel).
pub(crate) fn linearise(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
) -> Result<Linearization, ModelError> {
    let geom = state.geometry()?;
    let (raw, near) = p.raw_and_near(state, &geom);
    let jraw = columns(p, state, &geom, (&raw, &near), slots)?;
    Ok(Linearization::whitened(p, raw, jraw, near))
}

/// Forward-difference Jacobian columns of `slots` at `state` (whose geometry is `geom` and
/// raw residuals `raw`), in units of each slot's scale; backward where the forward point
/// leaves the model's valid space.
fn columns(
    p: &Problem,
    state: &EffectState,
    geom: &Model,
    (raw, near): (&[Vector6<f64>], &[Near]),
    slots: &[Slot],
) -> Result<Vec<Vec<Vector6<f64>>>, ModelError> {
    slots
        .par_iter()
        .map(|&slot| {
            let h = 1e-3 * slot.scale();
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
                let r2 = p.raw_near(&s, &g, (near, geom));
                return Ok(r2
                    .iter()
                    .zip(raw)
                    .map(|(a, b)| (a - b) * (slot.scale() / h))
                    .collect());
            }
            Err(ModelError::Invalid {
                key: format!("{slot:?}"),
                reason: "no valid finite-difference step".into(),
            })
        })
        .collect()
}

impl Linearization {
    /// Raw residuals and Jacobian columns whitened on `p`'s weights.
    fn whitened(
        p: &Problem,
        raw: Vec<Vector6<f64>>,
        jraw: Vec<Vec<Vector6<f64>>>,
        near: Vec<Near>,
    ) -> Self {
        let mut white = DVector::zeros(p.n_white);
        p.whiten(&raw, white.as_mut_slice());
        let mut jwhite = DMatrix::zeros(p.n_white, jraw.len());
        let mut col = vec![0.0; p.n_white];
        for (k, c) in jraw.iter().enumerate() {
            p.whiten(c, &mut col);
            jwhite.column_mut(k).copy_from_slice(&col);
        }
        Self {
            raw,
            white,
            jraw,
            jwhite,
            near,
        }
    }

    /// The same linearisation on the weights of `p`, a problem over the same observations
    /// (another noise model or dispersion): the raw residuals and Jacobian depend on the
    /// state and the observations alone, so nothing is evaluated again.
    pub fn rewhitened(&self, p: &Problem) -> Self {
        Self::whitened(p, self.raw.clone(), self.jraw.clone(), self.near.clone())
    }

    /// This linearisation (of some slots at `state`) with the columns of `more` slots
    /// appended, whitened on `p`'s weights: only the new columns are evaluated.
    pub fn extended(
        &self,
        p: &Problem,
        state: &EffectState,
        more: &[Slot],
    ) -> Result<Self, ModelError> {
        let geom = state.geometry()?;
        let mut jraw = self.jraw.clone();
        jraw.extend(columns(p, state, &geom, (&self.raw, &self.near), more)?);
        Ok(Self::whitened(p, self.raw.clone(), jraw, self.near.clone()))
    }
}

/// Normal equations `JᵀJ`, `Jᵀr` over whitened `rows` and columns `cols` (the rows
/// gathered once, the products by nalgebra's blocked matrix multiply; `JᵀJ` made exactly
/// symmetric from its upper triangle).
pub(crate) fn normal_eq(
    lin: &Linearization,
    rows: &[usize],
    cols: &[usize],
) -> (DMatrix<f64>, DVector<f64>) {
    let k = cols.len();
    // Jᵀ directly (k × rows): each row of J is a column here, read once.
    let mut jt = DMatrix::zeros(k, rows.len());
    for (n, &i) in rows.iter().enumerate() {
        for (c, &col) in cols.iter().enumerate() {
            jt[(c, n)] = lin.jwhite[(i, col)];
        }
    }
    let r = DVector::from_iterator(rows.len(), rows.iter().map(|&i| lin.white[i]));
    let mut a = &jt * jt.transpose();
    let g = &jt * r;
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

/// Standard error (in units of a slot's scale: 0.1 mm, 0.1 mrad) above which a combination
/// of the model's own parameters counts as not determined by the data, and is held.
pub(crate) const HELD_SE: f64 = 2.0;

/// Largest LM step, in units of the slots' scales (a step beyond it is shortened).
const MAX_STEP: f64 = 200.0;

/// The combinations of the model's own parameters that the data cannot determine (the
/// eigen-directions of their whitened normal matrix at the start with a standard error
/// above [`HELD_SE`]), held at their start values by a stiff prior: every refit of
/// discovery handles identifiability the way `pa10 calibrate` does, and cannot run along
/// them (from a missing effect, a linearised jump or an LM step would otherwise carry
/// e.g. `da5 − da6` to a quarter of a metre).
///
/// A candidate that acts on a joint's angle (a gear-ratio error `s·q`, a spring `c·τ`, a
/// periodic error) carries a constant part — its mean over the campaign — that the start
/// model's offset of that joint absorbed when it was calibrated without it. Adding the
/// candidate must give that part back to the offset; where the offset is in a held
/// direction the hold would forbid it and bias the candidate (12-07: a J3 ratio of 2e-3
/// hidden in MuJoCo's plant read 1.33e-3). So the hold is on the offset *plus* the
/// candidate's constant part (its least-squares projection on the offset's own signature,
/// [`Held::coupling`]): a candidate moves the joint's offset by exactly what it explains of
/// it, and nothing else in a held direction moves.
#[derive(Debug, Clone, Default)]
pub(crate) struct Held {
    /// The model's own slots the directions are over.
    pub slots: Vec<Slot>,
    /// Their start values, normalised (value / scale).
    pub centre: Vec<f64>,
    /// Unit directions over `slots`.
    pub dirs: Vec<DVector<f64>>,
    /// Standard error of each direction at the start, scale units.
    pub std_error: Vec<f64>,
    /// Precision of the hold (the largest eigenvalue of the normal matrix: as stiff as the
    /// best-determined direction), normalised units.
    pub precision: f64,
    /// Candidate slots that act on a joint's angle whose offset is among `slots`: (the
    /// candidate, the index of that offset in `slots`, the candidate's start value
    /// normalised, `k`) — `k` the least-squares coefficient of the offset's signature in the
    /// candidate's (normalised units), so the hold is on `offset + k·candidate`.
    pub coupling: Vec<(Slot, usize, f64, f64)>,
}

impl Held {
    /// The held directions of `own` at `state`, from the whitened Jacobian of `p` with
    /// unit dispersion, and their coupling to the candidate slots `cands` that act on a
    /// joint's angle (the others are ignored).
    pub fn at(
        p: &Problem,
        state: &EffectState,
        own: &[Slot],
        cands: &[Slot],
    ) -> Result<Self, ModelError> {
        let mut plain = p.clone();
        plain.dispersion = (1.0, 1.0);
        // (candidate, index of its joint's offset in `own`)
        let coupled: Vec<(Slot, usize)> = cands
            .iter()
            .filter(|c| !own.contains(c))
            .filter_map(|&c| {
                let j = c.link_angle_joint()?;
                let t = own.iter().position(|s| *s == Slot::Dep(IDX_THETA + j))?;
                Some((c, t))
            })
            .collect();
        let mut all = own.to_vec();
        all.extend(coupled.iter().map(|(c, _)| *c));
        let lin = linearise(&plain, state, &all)?;
        let rows = plain.white_rows(|b| b.train);
        let cols: Vec<usize> = (0..all.len()).collect();
        let (full, _) = normal_eq(&lin, &rows, &cols);
        let n = own.len();
        let coupling = coupled
            .iter()
            .enumerate()
            .filter(|(_, (_, t))| full[(*t, *t)] > 0.0)
            .map(|(i, &(c, t))| {
                (
                    c,
                    t,
                    state.get(c) / c.scale(),
                    full[(n + i, t)] / full[(t, t)],
                )
            })
            .collect();
        let a = full.view((0, 0), (n, n)).into_owned();
        let e = SymmetricEigen::new(a);
        let emax = e.eigenvalues.iter().cloned().fold(0.0, f64::max);
        let cut = 1.0 / (HELD_SE * HELD_SE);
        let mut dirs = Vec::new();
        let mut std_error = Vec::new();
        for (i, &ev) in e.eigenvalues.iter().enumerate() {
            if ev < cut {
                dirs.push(e.eigenvectors.column(i).into_owned());
                std_error.push(if ev > 0.0 {
                    ev.sqrt().recip()
                } else {
                    f64::INFINITY
                });
            }
        }
        Ok(Self {
            slots: own.to_vec(),
            centre: own.iter().map(|s| state.get(*s) / s.scale()).collect(),
            dirs,
            std_error,
            precision: emax.max(1.0),
            coupling,
        })
    }

    /// Direction `k` in words: its standard error and the slots with weights ≥ 0.2 in
    /// size, largest first (`name`: a slot's name).
    pub fn describe(&self, k: usize, name: impl Fn(Slot) -> String) -> String {
        let v = &self.dirs[k];
        let mut w: Vec<(Slot, f64)> = self
            .slots
            .iter()
            .zip(v.iter())
            .filter(|(_, w)| w.abs() >= 0.2)
            .map(|(s, w)| (*s, *w))
            .collect();
        w.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        let parts: Vec<String> = w
            .iter()
            .map(|(s, x)| format!("{} ({x:+.2})", name(*s)))
            .collect();
        let se = self.std_error[k];
        let se = if se.is_finite() {
            format!("{se:.3e}")
        } else {
            "∞".to_string()
        };
        format!("std error {se}: {}", parts.join(", "))
    }
}

/// The prior of a discovery fit: a weak one at zero on effect slots, and the [`Held`]
/// directions of the model's own slots at their start values.
#[derive(Debug, Clone)]
pub(crate) struct Prior {
    /// Precision per slot (normalised units) of the prior at zero.
    pub diag: Vec<f64>,
    /// The held directions.
    pub held: std::sync::Arc<Held>,
}

impl Prior {
    /// Zero for the model's own slots (`own`), `1/EFFECT_PRIOR²` for effect slots, and the
    /// held directions.
    pub fn new(slots: &[Slot], own: &[Slot], held: &std::sync::Arc<Held>) -> Self {
        Self {
            diag: slots
                .iter()
                .map(|s| {
                    if own.contains(s) {
                        0.0
                    } else {
                        1.0 / (EFFECT_PRIOR * EFFECT_PRIOR)
                    }
                })
                .collect(),
            held: held.clone(),
        }
    }

    /// Each held direction embedded in the columns `slots` (zero where a held slot is not
    /// among them), and its residual `wᵀ(u − u₀)` at `state`.
    fn held_rows(&self, slots: &[Slot], state: &EffectState) -> Vec<(DVector<f64>, f64)> {
        let h = &*self.held;
        let pos: Vec<Option<usize>> = h
            .slots
            .iter()
            .map(|s| slots.iter().position(|x| x == s))
            .collect();
        // the coupled candidates among `slots`: (column, offset's index in the held slots,
        // start value, k)
        let coupled: Vec<(usize, usize, f64, f64)> = h
            .coupling
            .iter()
            .filter_map(|&(c, t, x0, k)| Some((slots.iter().position(|x| *x == c)?, t, x0, k)))
            .collect();
        h.dirs
            .iter()
            .map(|w| {
                let mut e = DVector::zeros(slots.len());
                let mut r = 0.0;
                for (k, s) in h.slots.iter().enumerate() {
                    r += w[k] * (state.get(*s) / s.scale() - h.centre[k]);
                    if let Some(c) = pos[k] {
                        e[c] = w[k];
                    }
                }
                for &(col, t, x0, k) in &coupled {
                    r += w[t] * k * (state.get(slots[col]) / slots[col].scale() - x0);
                    e[col] += w[t] * k;
                }
                (e, r)
            })
            .collect()
    }

    /// The diagonal the held directions add to normal equations over `slots` (what
    /// [`Prior::add_to`] adds there without the effects' prior; `state` only completes the
    /// rows), normalised units.
    pub fn held_diag(&self, slots: &[Slot], state: &EffectState) -> DVector<f64> {
        let mut d = DVector::zeros(slots.len());
        for (e, _) in self.held_rows(slots, state) {
            d += e.component_mul(&e) * self.held.precision;
        }
        d
    }

    /// The prior's cost at `state` over `slots`.
    pub fn cost(&self, slots: &[Slot], state: &EffectState) -> f64 {
        let diag: f64 = slots
            .iter()
            .zip(&self.diag)
            .map(|(s, w)| w * (state.get(*s) / s.scale()).powi(2))
            .sum();
        let held: f64 = self
            .held_rows(slots, state)
            .iter()
            .map(|(_, r)| r * r)
            .sum();
        diag + self.held.precision * held
    }

    /// Adds the prior to normal equations `a`, `g` over `slots` at `state` (`diag`: whether
    /// the effects' prior at zero is added too, or only the held directions).
    pub fn add_to(
        &self,
        slots: &[Slot],
        state: &EffectState,
        a: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
        diag: bool,
    ) {
        if diag {
            for (k, s) in slots.iter().enumerate() {
                let w = self.diag.get(k).copied().unwrap_or(0.0);
                a[(k, k)] += w;
                g[k] += w * state.get(*s) / s.scale();
            }
        }
        let pi = self.held.precision;
        for (e, r) in self.held_rows(slots, state) {
            *a += &e * e.transpose() * pi;
            *g += &e * (pi * r);
        }
    }
}

/// Levenberg–Marquardt on the training blocks over `slots`, from `state`, with prior
/// precisions `prior` (normalised units, centred on zero).
pub(crate) fn fit(
    p: &Problem,
    state: &EffectState,
    slots: &[Slot],
    prior: &Prior,
) -> Result<Fitted, ModelError> {
    let rows = p.white_rows(|b| b.train);
    let cols: Vec<usize> = (0..slots.len()).collect();
    let cost_of =
        |lin_white: &DVector<f64>| rows.iter().map(|&i| lin_white[i].powi(2)).sum::<f64>();
    let mut st = state.clone();
    let mut lin = linearise(p, &st, slots)?;
    let mut cost = cost_of(&lin.white) + prior.cost(slots, &st);
    let (mut a, mut g) = normal_eq(&lin, &rows, &cols);
    prior.add_to(slots, &st, &mut a, &mut g, true);
    let mut lambda = 1e-6 * (0..a.nrows()).map(|i| a[(i, i)]).fold(0.0, f64::max);
    let mut white = DVector::zeros(p.n_white);
    for _ in 0..40 {
        let (mut d, _) = damped_solve(&a, &g, lambda);
        // Bounded steps: no single step moves the parameters further than MAX_STEP scales.
        let dn = d.norm();
        if dn > MAX_STEP {
            d *= MAX_STEP / dn;
        }
        let mut trial = st.clone();
        for (k, &s) in slots.iter().enumerate() {
            trial.set(s, st.get(s) + d[k] * s.scale());
        }
        // A step that leaves the valid model space (e.g. a departure beyond its bound)
        // counts as an increase.
        let c = match p.raw(&trial) {
            Ok(raw) => {
                p.whiten(&raw, white.as_mut_slice());
                cost_of(&white) + prior.cost(slots, &trial)
            }
            Err(_) => f64::INFINITY,
        };
        if c < cost {
            let gain = cost - c;
            st = trial;
            cost = c;
            lin = linearise(p, &st, slots)?;
            (a, g) = normal_eq(&lin, &rows, &cols);
            prior.add_to(slots, &st, &mut a, &mut g, true);
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
