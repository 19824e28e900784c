//! The few distribution functions calibration, the noise estimator and discovery need: the χ² and F upper tails (regularised
//! incomplete gamma and beta, series and continued fractions as in Numerical Recipes §6.2,
//! §6.4) and
//! normal / Student-t quantiles (Acklam's rational approximation, Cornish–Fisher for t).

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms; relative error ≈ 1e-15).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularised upper incomplete gamma `Q(a, x)`.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        // series for P
        let (mut ap, mut sum) = (a, 1.0 / a);
        let mut del = sum;
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - gln).exp()
    } else {
        // continued fraction for Q (modified Lentz)
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            let del = lentz_step(&mut d, &mut c, an, b);
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - gln).exp() * h
    }
}

/// P(χ²_k > x): the p-value of a χ² statistic with `k` degrees of freedom.
///
/// ```
/// use pa10::stats::chi2_sf;
/// assert!((chi2_sf(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-9);
/// assert!((chi2_sf(23.209_251_158_954_36, 10.0) - 0.01).abs() < 1e-9);
/// ```
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return 1.0;
    }
    gamma_q(0.5 * k, 0.5 * x).clamp(0.0, 1.0)
}

/// The `p` quantile of χ²_k: the `x` with P(χ²_k ≤ x) = p (bisection on [`chi2_sf`],
/// relative accuracy 1e-12).
///
/// ```
/// use pa10::stats::chi2_quantile;
/// assert!((chi2_quantile(0.95, 1.0) - 3.841_458_820_694_124).abs() < 1e-8);
/// assert!((chi2_quantile(0.01, 10.0) - 2.558_212_160_930_165).abs() < 1e-8);
/// ```
pub fn chi2_quantile(p: f64, k: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && k > 0.0) {
        return f64::NAN;
    }
    let (mut lo, mut hi) = (0.0, k.max(1.0));
    while chi2_sf(hi, k) > 1.0 - p {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_sf(mid, k) > 1.0 - p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Regularised incomplete beta `I_x(a, b)` (continued fraction, Numerical Recipes §6.4).
pub fn beta_i(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front =
        (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_cf(a, b, x) / a
    } else {
        1.0 - front * beta_cf(b, a, 1.0 - x) / b
    }
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 / nonzero(1.0 - qab * x / qap);
    let mut h = d;
    for m in 1..100_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        // the even and the odd step of the fraction
        h *= lentz_step(
            &mut d,
            &mut c,
            m * (b - m) * x / ((qam + m2) * (a + m2)),
            1.0,
        );
        let del = lentz_step(
            &mut d,
            &mut c,
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
            1.0,
        );
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Smallest magnitude the continued fractions' denominators are allowed.
const TINY: f64 = 1e-300;

fn nonzero(v: f64) -> f64 {
    if v.abs() < TINY { TINY } else { v }
}

/// One step of the modified Lentz method for a continued fraction `… aa/(b + …)`: updates
/// the running `d` and `c`, returns the factor that multiplies the fraction's value.
fn lentz_step(d: &mut f64, c: &mut f64, aa: f64, b: f64) -> f64 {
    *d = 1.0 / nonzero(b + aa * *d);
    *c = nonzero(b + aa / *c);
    *d * *c
}

/// P(F_{d1,d2} > x): the p-value of an F statistic (a ratio of two χ²/dof, the
/// denominator's variance estimated with `d2` degrees of freedom). An infinite `d2` is a
/// known variance: P(χ²_{d1} > d1·x).
///
/// ```
/// use pa10::stats::{chi2_sf, f_sf};
/// assert!((f_sf(2.0, 3.0, f64::INFINITY) - chi2_sf(6.0, 3.0)).abs() < 1e-15);
/// assert!((f_sf(2.0, 3.0, 1e7) - chi2_sf(6.0, 3.0)).abs() < 1e-5);
/// ```
pub fn f_sf(x: f64, d1: f64, d2: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if d2.is_infinite() {
        return chi2_sf(d1 * x, d1);
    }
    beta_i(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * x)).clamp(0.0, 1.0)
}

/// One-sided sign test: P(at least `k` of `n` fair coin flips come up heads).
pub fn sign_test(k: usize, n: usize) -> f64 {
    if k == 0 {
        return 1.0;
    }
    // Σ_{i ≥ k} C(n, i) / 2ⁿ in logs.
    let ln_c = |i: usize| {
        ln_gamma(n as f64 + 1.0) - ln_gamma(i as f64 + 1.0) - ln_gamma((n - i) as f64 + 1.0)
    };
    (k..=n)
        .map(|i| (ln_c(i) - n as f64 * std::f64::consts::LN_2).exp())
        .sum::<f64>()
        .min(1.0)
}

/// One-sided Wilcoxon signed-rank test: P(W⁺ ≥ observed) for paired differences `d` under
/// the null of a distribution symmetric about zero, W⁺ the sum of the ranks of |d| of the
/// positive ones. Zeros are dropped and ties take their mean rank. Exact (the rank sums of
/// all 2ⁿ sign patterns, counted) up to 300 non-zero differences, else the normal
/// approximation with the tie correction. Uses the sizes as well as the signs of the
/// differences, so it has more power than [`sign_test`] while a few huge differences still
/// weigh only by their rank.
///
/// ```
/// use pa10::stats::signed_rank_test;
/// assert!((signed_rank_test(&[1.0, 2.0, 3.0, 4.0, 5.0]) - 1.0 / 32.0).abs() < 1e-15);
/// // W⁺ = 13 of 15: the sign patterns whose negative ranks sum to ≤ 2 ({}, {1}, {2}).
/// assert!((signed_rank_test(&[1.0, -2.0, 3.0, 4.0, 5.0]) - 3.0 / 32.0).abs() < 1e-15);
/// assert_eq!(signed_rank_test(&[]), 1.0);
/// ```
pub fn signed_rank_test(d: &[f64]) -> f64 {
    let mut v: Vec<f64> = d
        .iter()
        .copied()
        .filter(|x| *x != 0.0 && x.is_finite())
        .collect();
    let n = v.len();
    if n == 0 {
        return 1.0;
    }
    v.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Doubled ranks (integers even with ties: a tie's mean rank is a half-integer).
    let mut rank2 = vec![0usize; n];
    let mut ties = 0.0;
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && v[j + 1].abs() == v[i].abs() {
            j += 1;
        }
        let t = (j - i + 1) as f64;
        ties += t * t * t - t;
        for r in &mut rank2[i..=j] {
            *r = i + j + 2; // 2 × mean of the ranks i + 1 … j + 1
        }
        i = j + 1;
    }
    let w2: usize = (0..n).filter(|&k| v[k] > 0.0).map(|k| rank2[k]).sum();
    if n <= 300 {
        let total: usize = rank2.iter().sum();
        let mut p = vec![0.0; total + 1];
        p[0] = 1.0;
        let mut top = 0;
        for &r in &rank2 {
            for s in (0..=top).rev() {
                let x = 0.5 * p[s];
                p[s] = x;
                p[s + r] += x;
            }
            top += r;
        }
        p[w2..].iter().sum::<f64>().min(1.0)
    } else {
        let nf = n as f64;
        let mean = nf * (nf + 1.0) / 4.0;
        let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - ties / 48.0;
        // Continuity-corrected z, and P(Z ≥ z) from χ²₁.
        let z = (0.5 * w2 as f64 - 0.5 - mean) / var.max(1e-300).sqrt();
        if z > 0.0 {
            0.5 * chi2_sf(z * z, 1.0)
        } else {
            1.0 - 0.5 * chi2_sf(z * z, 1.0)
        }
    }
}

/// Quantile of the standard normal distribution (Acklam; relative error < 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Quantile of Student's t with `nu` degrees of freedom (Cornish–Fisher expansion; within
/// 0.5 % for ν ≥ 5 at the 1 % level).
pub fn t_quantile(p: f64, nu: f64) -> f64 {
    let z = normal_quantile(p);
    let z3 = z * z * z;
    let z5 = z3 * z * z;
    let z7 = z5 * z * z;
    z + (z3 + z) / (4.0 * nu)
        + (5.0 * z5 + 16.0 * z3 + 3.0 * z) / (96.0 * nu * nu)
        + (3.0 * z7 + 19.0 * z5 + 17.0 * z3 - 15.0 * z) / (384.0 * nu * nu * nu)
}

/// The median of `v` (sorted in place; NaNs last), `None` when empty.
///
/// ```
/// assert_eq!(pa10::stats::median(&mut [3.0, 1.0, 2.0]), Some(2.0));
/// assert_eq!(pa10::stats::median(&mut [4.0, 1.0, 2.0, 3.0]), Some(2.5));
/// assert_eq!(pa10::stats::median(&mut []), None);
/// ```
pub fn median(v: &mut [f64]) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        assert!((normal_quantile(0.99) - 2.326_347_874).abs() < 1e-8);
        assert!((normal_quantile(0.025) + 1.959_963_985).abs() < 1e-8);
        // t(0.99, 9) = 2.821, t(0.99, 29) = 2.462
        assert!((t_quantile(0.99, 9.0) - 2.821).abs() < 0.01);
        assert!((t_quantile(0.99, 29.0) - 2.462).abs() < 0.005);
        // χ²: median of k=2 is 2 ln 2
        assert!((chi2_sf(2.0 * 2f64.ln(), 2.0) - 0.5).abs() < 1e-12);
        assert!((chi2_sf(3000.0, 3000.0) - 0.496_566_438_8).abs() < 1e-8);
        // sign test: 8 of 8 → 1/256; 5 of 10 → 0.623
        assert!((sign_test(8, 8) - 1.0 / 256.0).abs() < 1e-12);
        assert!((sign_test(5, 10) - 0.623_046_875).abs() < 1e-9);
        // signed rank: the exact count and the normal approximation agree at n = 300 / 301
        let d: Vec<f64> = (1..=301)
            .map(|k| if k % 3 == 0 { -(k as f64) } else { k as f64 })
            .collect();
        let (exact, approx) = (signed_rank_test(&d[..300]), signed_rank_test(&d));
        assert!(exact < 1e-6 && approx < 1e-6 && (exact.ln() - approx.ln()).abs() < 0.5);
        // F (scipy.stats.f.sf)
        assert!((f_sf(1.1, 2634.0, 480.0) - 0.092_319_620_06).abs() < 1e-8);
        assert!((f_sf(3.0, 3.0, 480.0) - 0.030_292_059_55).abs() < 1e-8);
    }
}
