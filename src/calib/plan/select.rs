//! Choosing configurations: greedy forward, then exchange passes, for a concave criterion of
//! the information ([`Criterion`]: D or I). Every step asks "which candidate, added to this
//! information, scores best?" over all candidates; [`select_with`] answers it without scoring
//! most of them: a concave criterion lies below its tangent, so `f(B + Aᵢ) ≤ f(B) + ⟨∇f(B),
//! Aᵢ⟩` — a bound that costs one elementwise product per candidate against a Cholesky and an
//! inverse for the score itself. Candidates are scored in the order of their bounds until the
//! next bound falls below the best score found (less a rounding margin), so the answer is the
//! one scoring every candidate gives ([`select_by`], kept as the reference the tests and
//! `cargo bench --bench plan` compare against). [`greedy_order`] and [`exchange`] are its two
//! halves, so that designs of several sizes share one greedy pass (greedy is prefix-stable).

use nalgebra::Cholesky;
use rayon::prelude::*;

use super::kernel::Kernel;
use super::{Information, PlanError, log_det, prior};

/// A concave criterion of the information (larger is better).
#[derive(Debug, Clone, Copy)]
pub enum Criterion<'a> {
    /// D-optimality: `log det M`.
    D,
    /// I-optimality: `−trace(W M⁻¹)` with `W` the workspace weight ([`super::workspace_weight`]).
    I(&'a Information),
}

impl Criterion<'_> {
    /// The criterion at `m` (−∞ when `m` is singular).
    pub fn score(&self, m: &Information) -> f64 {
        match self {
            Criterion::D => log_det(m),
            Criterion::I(w) => super::i_score(m, w),
        }
    }

    /// Its scoring kernel.
    fn kernel(&self) -> Kernel {
        match self {
            Criterion::D => Kernel::D,
            Criterion::I(w) => Kernel::i(w),
        }
    }

    /// The criterion at `m` and its gradient there (`M⁻¹` for D, `M⁻¹ W M⁻¹` for I), or `None`
    /// when `m` is singular.
    fn tangent(&self, m: &Information) -> Option<(f64, Information)> {
        let ch = Cholesky::new(*m)?;
        let inv = ch.inverse();
        Some(match self {
            Criterion::D => (
                2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
                inv,
            ),
            Criterion::I(w) => (-w.component_mul(&inv).sum(), inv * *w * inv),
        })
    }
}

/// A chosen design.
#[derive(Debug, Clone, PartialEq)]
pub struct Design {
    /// Indices of the chosen candidates, in the order the greedy pass took them.
    pub chosen: Vec<usize>,
    /// `log det M` of the design (prior included).
    pub log_det: f64,
    /// The criterion's value (`log det M` for D).
    pub score: f64,
}

/// How many candidates' scores (or bounds) one parallel batch takes.
const BATCH: usize = 32;

/// Scores within this fraction of the best are never pruned on their bound: the bound and the
/// score are computed differently, and their rounding must not decide.
const PRUNE_MARGIN: f64 = 1e-6;

/// `⟨a, b⟩ = Σ aᵢⱼ bᵢⱼ`, in four fixed lanes (vectorised; the same sum on every machine).
fn dot(a: &Information, b: &Information) -> f64 {
    let (a, b) = (a.as_slice(), b.as_slice());
    let mut acc = [0.0f64; 4];
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// A second tangent bound on every candidate: `offset + dots[i]` bounds the score of
/// candidate i (from the tangent at the design an exchange starts from).
type Extra<'a> = Option<(f64, &'a [f64])>;

/// The candidate not in `chosen` whose information added to `m` scores best under `crit`,
/// and that score (ties: the lower index), when it scores above `floor`; otherwise some
/// candidate at or below it, or `(−∞, usize::MAX)`. Only candidates whose tangent bounds (at
/// `m`, and `extra`'s) could beat both `floor` and the best so far are scored, so the answer
/// above `floor` is the one scoring them all gives ([`select_by`]).
fn best_addition(
    infos: &[Information],
    m: &Information,
    chosen: &[usize],
    (crit, kernel): (&Criterion, &Kernel),
    floor: f64,
    extra: Extra,
) -> (f64, usize) {
    let tangent = crit.tangent(m);
    let mut bounds: Vec<(f64, usize)> = infos
        .par_iter()
        .enumerate()
        .filter(|(i, _)| !chosen.contains(i))
        .map(|(i, a)| {
            let at_m = tangent
                .as_ref()
                .map_or(f64::INFINITY, |(f0, g)| f0 + dot(g, a));
            let at_start = extra.map_or(f64::INFINITY, |(o, d)| o + d[i]);
            (at_m.min(at_start), i)
        })
        .collect();
    bounds.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut best = (f64::NEG_INFINITY, usize::MAX);
    for batch in bounds.chunks(BATCH) {
        let bar = best.0.max(floor);
        if batch[0].0 < bar - PRUNE_MARGIN * bar.abs() {
            break;
        }
        let b = batch
            .par_iter()
            .map(|&(_, i)| (kernel.score(m, &infos[i]), i))
            .reduce(|| (f64::NEG_INFINITY, usize::MAX), better);
        best = better(best, b);
    }
    best
}

/// The better of two (score, index) pairs: the higher score, on a tie the lower index.
fn better(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
        b
    } else {
        a
    }
}

/// Greedy forward selection of `n` candidates: each step `best(m, chosen)` names the one to
/// add to the information `m` so far (prior included).
fn greedy(
    infos: &[Information],
    n: usize,
    mut best: impl FnMut(&Information, &[usize]) -> (f64, usize),
) -> Vec<usize> {
    let mut chosen: Vec<usize> = Vec::with_capacity(n);
    let mut m = prior();
    for _ in 0..n {
        let b = best(&m, &chosen);
        chosen.push(b.1);
        m += infos[b.1];
    }
    chosen
}

/// Exchange passes (at most `max_passes`) from `chosen`, scored by `score`: each chosen
/// candidate `chosen[k]` in turn is swapped for the one `best(design, without, chosen, k,
/// floor)` names in its place (`without` the design less it; only an answer above `floor`, the
/// design's score plus 1e-9, can swap), until no swap raises the score by more than 1e-9.
fn exchange_by(
    infos: &[Information],
    mut chosen: Vec<usize>,
    max_passes: usize,
    score: impl Fn(&Information) -> f64,
    mut best: impl FnMut(&Information, &Information, &[usize], usize, f64) -> (f64, usize),
) -> Design {
    let mut m = prior();
    for &i in &chosen {
        m += infos[i];
    }
    let mut value = score(&m);
    for _ in 0..max_passes {
        let mut improved = false;
        for k in 0..chosen.len() {
            let without = m - infos[chosen[k]];
            let mut b = best(&m, &without, &chosen, k, value + 1e-9);
            if b.0 <= value + 1e-9 {
                b = (value, chosen[k]);
            }
            if b.1 != chosen[k] {
                chosen[k] = b.1;
                m = without + infos[b.1];
                value = b.0;
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    Design {
        chosen,
        log_det: log_det(&m),
        score: value,
    }
}

/// The candidates greedy forward selection takes, in order, up to `n` (each step the one that
/// scores best added to the prior and those before it).
pub fn greedy_order(
    infos: &[Information],
    n: usize,
    crit: &Criterion,
) -> Result<Vec<usize>, PlanError> {
    check_size(infos, n)?;
    let kernel = crit.kernel();
    Ok(greedy(infos, n, |m, chosen| {
        best_addition(infos, m, chosen, (crit, &kernel), f64::NEG_INFINITY, None)
    }))
}

/// The criterion at a design and `⟨∇f, Aᵢ⟩` there for every candidate i.
type DesignTangent = (f64, Vec<f64>);

/// Exchange passes (at most `max_passes`) from the design `start`: each chosen candidate in
/// turn is swapped for the one that scores best in its place, until no swap raises the score
/// by more than 1e-9.
pub fn exchange(
    infos: &[Information],
    start: &[usize],
    max_passes: usize,
    crit: &Criterion,
) -> Result<Design, PlanError> {
    check_size(infos, start.len())?;
    let kernel = crit.kernel();
    // the tangent at the design, f(M − Aₖ + Aᵢ) ≤ f(M) + ⟨∇f(M), Aᵢ − Aₖ⟩, with ⟨∇f(M), Aᵢ⟩
    // per candidate: computed again only when a swap changed the design
    let mut at_design: Option<(Information, Option<DesignTangent>)> = None;
    Ok(exchange_by(
        infos,
        start.to_vec(),
        max_passes,
        |m| kernel.score(m, &Information::zeros()),
        |m, without, chosen, k, floor| {
            if at_design.as_ref().is_none_or(|(at, _)| at != m) {
                let t = crit
                    .tangent(m)
                    .map(|(f, g)| (f, infos.par_iter().map(|a| dot(&g, a)).collect::<Vec<_>>()));
                at_design = Some((*m, t));
            }
            let extra = at_design
                .as_ref()
                .and_then(|(_, t)| t.as_ref())
                .map(|(f, d)| (f - d[chosen[k]], d.as_slice()));
            // nothing at or below `floor` can swap: it is not scored
            best_addition(infos, without, chosen, (crit, &kernel), floor, extra)
        },
    ))
}

/// Chooses `n` of the candidates' informations (`infos[i]` for candidate i, from
/// [`super::information`]) maximising `crit` of `prior + Σ chosen`: [`greedy_order`], then
/// [`exchange`].
pub fn select_with(
    infos: &[Information],
    n: usize,
    max_passes: usize,
    crit: &Criterion,
) -> Result<Design, PlanError> {
    let start = greedy_order(infos, n, crit)?;
    exchange(infos, &start, max_passes, crit)
}

/// [`select_with`] for D-optimality (`log det M`).
pub fn select(infos: &[Information], n: usize, max_passes: usize) -> Result<Design, PlanError> {
    select_with(infos, n, max_passes, &Criterion::D)
}

fn check_size(infos: &[Information], n: usize) -> Result<(), PlanError> {
    if n == 0 || n > infos.len() {
        return Err(PlanError::Invalid(format!(
            "configurations: 1…{} (the candidates), got {n}",
            infos.len()
        )));
    }
    Ok(())
}

/// The reference selection: [`select_with`]'s greedy and exchange passes with every candidate
/// scored at every step, for any criterion (larger is better). The tests and the benchmark
/// compare the fast path against it.
pub fn select_by(
    infos: &[Information],
    n: usize,
    max_passes: usize,
    score: &(dyn Fn(&Information) -> f64 + Sync),
) -> Result<Design, PlanError> {
    check_size(infos, n)?;
    let start = greedy(infos, n, |m, chosen| {
        best_addition_naive(infos, m, chosen, score)
    });
    Ok(exchange_by(
        infos,
        start,
        max_passes,
        score,
        |_, without, chosen, _, _| best_addition_naive(infos, without, chosen, score),
    ))
}

/// Every candidate not in `chosen` scored added to `m`: the best and its score (ties: the
/// lower index; in parallel, deterministic).
fn best_addition_naive(
    infos: &[Information],
    m: &Information,
    chosen: &[usize],
    score: &(dyn Fn(&Information) -> f64 + Sync),
) -> (f64, usize) {
    infos
        .par_iter()
        .enumerate()
        .filter(|(i, _)| !chosen.contains(i))
        .map(|(i, info)| (score(&(m + info)), i))
        .reduce(|| (f64::NEG_INFINITY, usize::MAX), better)
}

#[cfg(test)]
mod tests {
    use super::super::{PlanNoise, design_model, information, workspace_weight};
    use super::*;
    use crate::model::Model;
    use rand::{RngExt, SeedableRng};

    /// Candidates as `pa10 plan` draws them: joint angles uniform within the limits.
    fn candidates(seed: u64, n: usize) -> (Model, Vec<[f64; 6]>) {
        let model = design_model(&Model::nominal()).unwrap();
        let lim = *model.limits();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let qs = (0..n)
            .map(|_| {
                std::array::from_fn(|j| {
                    rng.random_range((lim.lower[j] + 0.2)..(lim.upper[j] - 0.2))
                })
            })
            .collect();
        (model, qs)
    }

    #[test]
    fn the_pruned_selection_chooses_what_scoring_every_candidate_chooses() {
        for seed in [1, 2] {
            let (model, qs) = candidates(seed, 240);
            let infos: Vec<Information> = qs
                .iter()
                .map(|q| information(&model, q, &[0.0, 22.0, 44.0], &PlanNoise::default()))
                .collect();
            let work: Vec<[f64; 6]> = qs.iter().step_by(4).copied().collect();
            let w = workspace_weight(&model, &work, &[0.0, 45.0, 90.0]);
            for n in [5, 12] {
                let fast = select_with(&infos, n, 4, &Criterion::I(&w)).unwrap();
                let slow = select_by(&infos, n, 4, &|m| super::super::i_score(m, &w)).unwrap();
                assert_eq!(
                    fast.chosen, slow.chosen,
                    "I, seed {seed}, {n} configurations"
                );
                assert!((fast.score - slow.score).abs() <= 1e-9 * slow.score.abs());
                let fast = select(&infos, n, 4).unwrap();
                let slow = select_by(&infos, n, 4, &log_det).unwrap();
                assert_eq!(
                    fast.chosen, slow.chosen,
                    "D, seed {seed}, {n} configurations"
                );
                assert!((fast.score - slow.score).abs() <= 1e-9 * slow.score.abs());
            }
            // designs of several sizes from one greedy pass: the prefixes of the longest
            let order = greedy_order(&infos, 12, &Criterion::I(&w)).unwrap();
            let five = select_with(&infos, 5, 0, &Criterion::I(&w)).unwrap();
            assert_eq!(order[..5], five.chosen[..]);
        }
    }
}
