//! The selection's inner loop: a criterion of `B + A` for one base `B` and many candidates
//! `A`, on flat arrays. `trace(W M⁻¹)` is `‖L⁻¹ V‖²_F` with `M = L Lᵀ` (Cholesky) and
//! `W = V Vᵀ` (factored once per plan): one Cholesky and one triangular solve with the
//! factor's columns, instead of the Cholesky, the inverse and the product a fresh `M⁻¹` costs.
//! `log det M` is the Cholesky alone.
//!
//! On x86-64 CPUs with AVX2 the same code is compiled a second time for 256-bit vectors and
//! chosen at run time; no fused multiply-add is used, so both give bit-identical results.

use nalgebra::SymmetricEigen;

use super::{DESIGN_COLS, Information};

const N: usize = DESIGN_COLS;

/// What the kernel scores.
#[derive(Debug, Clone)]
pub(super) enum Kernel {
    /// `log det M`.
    D,
    /// `−trace(W M⁻¹)`, `W = V Vᵀ`: `v` row-major, `N × r`.
    I {
        /// The factor.
        v: Vec<f64>,
        /// Its columns.
        r: usize,
    },
}

impl Kernel {
    /// The I kernel of workspace weight `w` (symmetric, positive semi-definite: its negative
    /// eigenvalues, rounding, count as zero).
    pub(super) fn i(w: &Information) -> Self {
        let e = SymmetricEigen::new(*w);
        let cols: Vec<usize> = (0..N).filter(|&k| e.eigenvalues[k] > 0.0).collect();
        let r = cols.len();
        let mut v = vec![0.0; N * r];
        for (c, &k) in cols.iter().enumerate() {
            let s = e.eigenvalues[k].sqrt();
            for i in 0..N {
                v[i * r + c] = e.eigenvectors[(i, k)] * s;
            }
        }
        Kernel::I { v, r }
    }

    /// The criterion of `b + a` (−∞ when it is not positive definite).
    pub(super) fn score(&self, b: &Information, a: &Information) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: `score_avx2` only needs AVX2, and the CPU has it (checked above).
            #[allow(unsafe_code)]
            unsafe {
                return score_avx2(self, b.as_slice(), a.as_slice());
            }
        }
        score_impl(self, b.as_slice(), a.as_slice())
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn score_avx2(k: &Kernel, b: &[f64], a: &[f64]) -> f64 {
    score_impl(k, b, a)
}

/// [`Kernel::score`] on the matrices' slices (column-major; symmetric, so row-major alike).
#[inline(always)]
fn score_impl(k: &Kernel, b: &[f64], a: &[f64]) -> f64 {
    let mut l = [0.0f64; N * N];
    for ((l, b), a) in l.iter_mut().zip(b).zip(a) {
        *l = b + a;
    }
    if !cholesky(&mut l) {
        return f64::NEG_INFINITY;
    }
    match k {
        Kernel::D => 2.0 * (0..N).map(|j| l[j * N + j].ln()).sum::<f64>(),
        Kernel::I { v, r } => -forward_norm2(&l, v, *r),
    }
}

/// The lower Cholesky factor of the symmetric `m` (row-major), in place (its upper triangle
/// left as it was); false when `m` is not positive definite.
#[inline(always)]
fn cholesky(m: &mut [f64; N * N]) -> bool {
    for j in 0..N {
        let (upto, below) = m.split_at_mut((j + 1) * N);
        let row_j = &mut upto[j * N..];
        let mut d = row_j[j];
        for x in &row_j[..j] {
            d -= x * x;
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        row_j[j] = d;
        let row_j = &upto[j * N..j * N + j];
        // column j below the diagonal
        for row_i in below.chunks_exact_mut(N) {
            let mut s = row_i[j];
            for (x, y) in row_i[..j].iter().zip(row_j) {
                s -= x * y;
            }
            row_i[j] = s / d;
        }
    }
    true
}

/// `‖L⁻¹ V‖²_F` for the lower factor `l` (row-major) and `v` (row-major, `N × r`).
#[inline(always)]
fn forward_norm2(l: &[f64; N * N], v: &[f64], r: usize) -> f64 {
    let mut x = [0.0f64; N * N];
    let x = &mut x[..N * r];
    let mut total = 0.0;
    for i in 0..N {
        let (solved, rest) = x.split_at_mut(i * r);
        let xi = &mut rest[..r];
        xi.copy_from_slice(&v[i * r..(i + 1) * r]);
        for k in 0..i {
            let lik = l[i * N + k];
            for (a, b) in xi.iter_mut().zip(&solved[k * r..(k + 1) * r]) {
                *a -= lik * b;
            }
        }
        let d = l[i * N + i];
        for a in xi.iter_mut() {
            *a /= d;
            total += *a * *a;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Cholesky;

    /// A symmetric positive definite matrix from a seed.
    fn spd(seed: u64) -> Information {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let r = nalgebra::SMatrix::<f64, 20, N>::from_fn(|_, _| next());
        r.transpose() * r * 10.0 + Information::identity()
    }

    #[test]
    fn the_kernel_scores_what_the_inverse_gives() {
        let (b, a, w0) = (spd(1), spd(2), spd(3));
        // a rank-deficient workspace weight, as a volume's can be
        let w = w0 - Information::identity();
        let m = b + a;
        let inv = Cholesky::new(m).unwrap().inverse();
        let want = -w.component_mul(&inv).sum();
        let got = Kernel::i(&w).score(&b, &a);
        assert!(((got - want) / want).abs() < 1e-10, "{got} vs {want}");
        let want = super::super::log_det(&m);
        let got = Kernel::D.score(&b, &a);
        assert!((got - want).abs() < 1e-10 * want.abs(), "{got} vs {want}");
        // not positive definite
        assert_eq!(
            Kernel::D.score(&(-b), &Information::zeros()),
            f64::NEG_INFINITY
        );
        // the vector and the plain build agree to the bit
        let k = Kernel::i(&w);
        assert_eq!(
            score_impl(&k, b.as_slice(), a.as_slice()).to_bits(),
            k.score(&b, &a).to_bits()
        );
    }
}
