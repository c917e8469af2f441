//! Statistics of model errors: the nested-model F-test with an effective sample size,
//! information criteria, residual whiteness and the cross-correlation of the residual with the
//! input, with confidence bands (as MATLAB's `resid`).
//!
//! The F and normal distributions come from `statrs`; least squares is in
//! [`super::least_squares`].
use statrs::distribution::{ContinuousCDF, FisherSnedecor, Normal};

/// Outcome of a nested-model F-test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FTest {
    /// F statistic computed with the effective sample size.
    pub f: f64,
    /// Its p-value (upper tail of F(q, n_eff − p_full)).
    pub p_value: f64,
    /// Fraction of the base model's residual sum of squares the added columns explain.
    pub explained: f64,
    /// Change of the Bayesian information criterion (negative: the larger model is better).
    pub delta_bic: f64,
}

/// Nested-model F-test: the base model has `p_base` columns and residual sum of squares
/// `rss0`; adding `q` columns gives `rss1`. `n_eff` is the effective number of independent
/// samples (see [`effective_n`]): with autocorrelated residuals the nominal count overstates
/// the evidence, so the statistic is computed with `n_eff`.
pub fn f_test(rss0: f64, rss1: f64, q: usize, p_base: usize, n_eff: f64) -> FTest {
    let p_full = (p_base + q) as f64;
    let d2 = (n_eff - p_full).max(1.0);
    let explained = if rss0 > 0.0 {
        ((rss0 - rss1) / rss0).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = if rss1 > 0.0 && q > 0 {
        ((rss0 - rss1).max(0.0) / q as f64) / (rss1 / d2)
    } else {
        0.0
    };
    let p_value = match FisherSnedecor::new(q.max(1) as f64, d2) {
        Ok(dist) if f.is_finite() => dist.sf(f),
        _ => 1.0,
    };
    FTest {
        f,
        p_value,
        explained,
        delta_bic: delta_bic(rss0, rss1, q, n_eff),
    }
}

/// Change of BIC `n·ln(RSS/n) + p·ln(n)` when `q` parameters are added, with `n = n_eff`.
pub fn delta_bic(rss0: f64, rss1: f64, q: usize, n_eff: f64) -> f64 {
    if rss0 <= 0.0 || rss1 <= 0.0 {
        return 0.0;
    }
    n_eff * (rss1 / rss0).ln() + q as f64 * n_eff.max(2.0).ln()
}

/// Lag-`k` autocorrelation coefficients `r_1..r_max_lag` (mean removed, biased estimator as
/// in Box–Jenkins).
pub fn autocorr(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; max_lag];
    }
    let m = x.iter().sum::<f64>() / n as f64;
    let c0: f64 = x.iter().map(|v| (v - m) * (v - m)).sum();
    (1..=max_lag)
        .map(|k| {
            if k >= n || c0 <= 0.0 {
                return 0.0;
            }
            let ck: f64 = (0..n - k).map(|t| (x[t] - m) * (x[t + k] - m)).sum();
            ck / c0
        })
        .collect()
}

/// Integrated autocorrelation time `τ = 1 + 2·Σ_{k≥1} ρ_k` of a series [samples]: the factor
/// by which its autocorrelation inflates the variance of a mean (`Var = σ²·τ/n`), so `n/τ` is
/// its effective number of independent samples. `ρ_k` (as [`autocorr`]) is evaluated on lags
/// growing by about √2 (1, 2, 3, 4, 6, 8, 11, ...) up to its first value ≤ 0 (the initial
/// positive sequence) and summed as a piecewise-linear curve between them: O(n·log τ) work
/// whether the series decorrelates in one sample or in thousands. Between 1 and `n`.
pub fn correlation_time(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 3 {
        return 1.0;
    }
    let m = x.iter().sum::<f64>() / n as f64;
    let c0: f64 = x.iter().map(|v| (v - m) * (v - m)).sum();
    if c0 <= 0.0 {
        return 1.0;
    }
    let rho = |k: usize| (0..n - k).map(|t| (x[t] - m) * (x[t + k] - m)).sum::<f64>() / c0;
    // Σ_{k≥1} ρ_k, with ρ_0 = 1 as the curve's first point.
    let (mut sum, mut k0, mut r0) = (0.0, 0usize, 1.0f64);
    let mut k = 1usize;
    while k < n / 2 {
        let r = rho(k);
        if r <= 0.0 {
            // The curve reaches 0 between k0 and k: the triangle up to that crossing.
            let cross = (k - k0) as f64 * r0 / (r0 - r);
            sum += 0.5 * r0 * cross;
            break;
        }
        // Lags k0+1 ..= k on the straight line from (k0, r0) to (k, r).
        let d = (k - k0) as f64;
        sum += d * 0.5 * (r0 + r) + 0.5 * (r - r0);
        (k0, r0) = (k, r);
        k = (k + 1).max((k as f64 * std::f64::consts::SQRT_2).round() as usize);
    }
    (1.0 + 2.0 * sum).clamp(1.0, n as f64)
}

/// Cross-correlation `r_xu(k)` for `k = −max_lag..=max_lag` (index `k + max_lag`):
/// correlation of `x(t)` with `u(t − k)`, means removed, normalised by both energies.
pub fn xcorr(x: &[f64], u: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len().min(u.len());
    let mx = x[..n].iter().sum::<f64>() / n.max(1) as f64;
    let mu = u[..n].iter().sum::<f64>() / n.max(1) as f64;
    let ex: f64 = x[..n].iter().map(|v| (v - mx) * (v - mx)).sum();
    let eu: f64 = u[..n].iter().map(|v| (v - mu) * (v - mu)).sum();
    let norm = (ex * eu).sqrt();
    (0..=2 * max_lag)
        .map(|idx| {
            let k = idx as isize - max_lag as isize;
            if norm <= 0.0 {
                return 0.0;
            }
            let mut s = 0.0;
            for t in 0..n as isize {
                let j = t - k;
                if j >= 0 && (j as usize) < n {
                    s += (x[t as usize] - mx) * (u[j as usize] - mu);
                }
            }
            s / norm
        })
        .collect()
}

/// Half-width of the confidence band of a correlation coefficient of white noise over `n`
/// samples: `z_{1−(1−level)/2}/√n` (MATLAB's `resid` draws the 99 % band).
pub fn correlation_band(n: usize, level: f64) -> f64 {
    let z = Normal::new(0.0, 1.0)
        .map(|d| d.inverse_cdf(0.5 + level / 2.0))
        .unwrap_or(2.576);
    z / (n.max(1) as f64).sqrt()
}

/// Effective number of independent samples of an autocorrelated residual, from its lag-1
/// autocorrelation ρ (AR(1) approximation, Bretherton et al. 1999): `n·(1 − ρ)/(1 + ρ)`,
/// never more than `n` and never less than 2.
pub fn effective_n(resid: &[f64]) -> f64 {
    let n = resid.len() as f64;
    let rho = autocorr(resid, 1)[0].clamp(0.0, 0.999);
    (n * (1.0 - rho) / (1.0 + rho)).clamp(2.0f64.min(n), n)
}

/// Residual whiteness and independence from the input, as MATLAB's `resid`.
#[derive(Debug, Clone)]
pub struct Whiteness {
    /// Autocorrelation of the residual at lags 1..=max_lag.
    pub acf: Vec<f64>,
    /// Cross-correlation residual/input at lags −max_lag..=max_lag.
    pub xcf: Vec<f64>,
    /// Half-width of the 99 % confidence band.
    pub band: f64,
    /// Fraction of autocorrelation lags outside the band (≈ 0.01 for white noise).
    pub acf_outside: f64,
    /// Fraction of cross-correlation lags outside the band.
    pub xcf_outside: f64,
}

/// Confidence level of the whiteness bands: 99 %, as MATLAB's `resid`.
pub const WHITENESS_LEVEL: f64 = 0.99;

/// Whiteness test of `resid` and its cross-correlation with the input `u`.
pub fn whiteness(resid: &[f64], u: &[f64], max_lag: usize) -> Whiteness {
    let acf = autocorr(resid, max_lag);
    let xcf = xcorr(resid, u, max_lag);
    let band = correlation_band(resid.len(), WHITENESS_LEVEL);
    let out =
        |v: &[f64]| v.iter().filter(|r| r.abs() > band).count() as f64 / v.len().max(1) as f64;
    Whiteness {
        acf_outside: out(&acf),
        xcf_outside: out(&xcf),
        acf,
        xcf,
        band,
    }
}

/// Root mean square.
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Cluster-robust score test that the columns `z` explain nothing of the residual `u` of the
/// null model (each column of `z` already residualised on the null model's columns; `q` the
/// number of free columns among them). With `s_g = Σ_{i∈g} u_i·z_i` the score of cluster `g`
/// (rows with one id in `cluster`, consecutive), `LM = 1ᵀS(SᵀS)⁻¹Sᵀ1`, the count of clusters
/// minus the residual sum of squares of 1 regressed on the scores, is χ²(q) under the null
/// whatever each row's variance and however the rows of one cluster are correlated (the
/// heteroscedasticity-robust LM test of Wooldridge, *Econometric Analysis of Cross Section
/// and Panel Data*, §4.2.3, summed over clusters). `p` is read from the Hotelling form
/// `F(q, G−q)` with `q` the numerical rank of the scores. Returns `(LM, p)`; `p = 1` when there
/// are not more clusters than columns.
pub fn robust_score_test(u: &[f64], z: &[Vec<f64>], cluster: &[usize], q: usize) -> (f64, f64) {
    let n = u.len().min(cluster.len());
    if z.is_empty() || q == 0 || z.iter().any(|c| c.len() < n) {
        return (0.0, 1.0);
    }
    let mut scores: Vec<Vec<f64>> = vec![Vec::new(); z.len()];
    for i in 0..n {
        let new = i == 0 || cluster[i] != cluster[i - 1];
        for (s, c) in scores.iter_mut().zip(z) {
            let v = u[i] * c[i];
            match s.last_mut() {
                Some(last) if !new => *last += v,
                _ => s.push(v),
            }
        }
    }
    let g = scores[0].len();
    let q = q.min(score_rank(&scores));
    if q == 0 || g <= q + 1 {
        return (0.0, 1.0);
    }
    let ones = vec![1.0; g];
    let refs: Vec<&[f64]> = scores.iter().map(|c| c.as_slice()).collect();
    let fit = super::least_squares::lstsq(&refs, &ones);
    let lm = (g as f64 - fit.rss).max(0.0);
    // LM ≤ G, so χ²(q) cannot reject with few clusters; the Hotelling form
    // F = (G−q)/q · LM/(G−LM) ~ F(q, G−q) is exact for Gaussian scores.
    let (gf, qf) = (g as f64, q as f64);
    if lm >= gf {
        return (lm, 0.0);
    }
    let f = (gf - qf) / qf * lm / (gf - lm);
    let p = statrs::distribution::FisherSnedecor::new(qf, gf - qf)
        .map(|d| d.sf(f))
        .unwrap_or(1.0);
    (lm, if p.is_finite() { p } else { 1.0 })
}

/// Numerical rank of the score columns: singular values above `1e-10 ×` the largest.
fn score_rank(scores: &[Vec<f64>]) -> usize {
    let (g, k) = (scores[0].len(), scores.len());
    let m = faer::Mat::<f64>::from_fn(g, k, |i, j| scores[j][i]);
    if m.col_iter()
        .flat_map(|c| c.iter().copied())
        .any(|v| !v.is_finite())
    {
        return 0;
    }
    let Ok(svd) = m.thin_svd() else {
        return 0;
    };
    let sv: Vec<f64> = (0..g.min(k)).map(|i| svd.S().column_vector()[i]).collect();
    let smax = sv.iter().cloned().fold(0.0, f64::max);
    sv.iter().filter(|&&v| v > smax * 1e-10 && v > 0.0).count()
}

/// `n` standard normal numbers from `seed` (for the statistics' tests).
#[cfg(test)]
pub(crate) fn white_noise(n: usize, seed: u64) -> Vec<f64> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| rng.sample(rand_distr::StandardNormal))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::least_squares::lstsq;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        white_noise(n, seed)
    }

    #[test]
    fn f_test_separates_signal_from_noise() {
        let n = 2000;
        let e = noise(n, 2);
        let x: Vec<f64> = noise(n, 3);
        let base = lstsq(&[], &e);
        let with = lstsq(&[&x], &e);
        let t = f_test(base.rss, with.rss, 1, 0, n as f64);
        assert!(t.p_value > 1e-3, "noise flagged: {t:?}");
        let y: Vec<f64> = (0..n).map(|k| e[k] + 0.3 * x[k]).collect();
        let base = lstsq(&[], &y);
        let with = lstsq(&[&x], &y);
        let t = f_test(base.rss, with.rss, 1, 0, n as f64);
        assert!(
            t.p_value < 1e-10 && t.explained > 0.05 && t.delta_bic < 0.0,
            "{t:?}"
        );
    }

    /// Rows of very unequal variance: the robust score test rejects a column that is
    /// nonzero only on the noisy rows at about its level, and still finds a real effect.
    #[test]
    fn robust_score_test_holds_its_level_under_unequal_variance() {
        let n = 400;
        let cluster: Vec<usize> = (0..n).collect();
        let z: Vec<f64> = (0..n)
            .map(|k| if k % 10 == 0 { 1.0 } else { 0.0 })
            .collect();
        let centred = |c: &[f64]| -> Vec<f64> {
            let m = c.iter().sum::<f64>() / c.len() as f64;
            c.iter().map(|v| v - m).collect()
        };
        let zc = vec![centred(&z)];
        let rejected = (0..200)
            .filter(|&seed| {
                let e = noise(n, seed);
                let u: Vec<f64> = (0..n)
                    .map(|k| e[k] * if k % 10 == 0 { 20.0 } else { 1.0 })
                    .collect();
                robust_score_test(&centred(&u), &zc, &cluster, 1).1 < 0.05
            })
            .count();
        assert!((2..=22).contains(&rejected), "{rejected} of 200 rejected");
        let e = noise(n, 1);
        let u: Vec<f64> = (0..n).map(|k| e[k] + 2.0 * z[k]).collect();
        assert!(robust_score_test(&centred(&u), &zc, &cluster, 1).1 < 1e-6);
    }

    /// Rows that share an error within a cluster: a column constant over each cluster is not
    /// taken for an effect when the clusters are given.
    #[test]
    fn robust_score_test_allows_an_error_shared_within_a_cluster() {
        let (n, size) = (600, 20);
        let cluster: Vec<usize> = (0..n).map(|k| k / size).collect();
        let rejected = (0..100)
            .filter(|&seed| {
                let shared = noise(n / size, seed + 1000);
                let e = noise(n, seed);
                let u: Vec<f64> = (0..n).map(|k| 3.0 * shared[k / size] + e[k]).collect();
                let z = noise(n / size, seed + 5000);
                let zc: Vec<f64> = (0..n).map(|k| z[k / size]).collect();
                let m = u.iter().sum::<f64>() / n as f64;
                let mz = zc.iter().sum::<f64>() / n as f64;
                let u: Vec<f64> = u.iter().map(|v| v - m).collect();
                let zc: Vec<f64> = zc.iter().map(|v| v - mz).collect();
                robust_score_test(&u, &[zc], &cluster, 1).1 < 0.05
            })
            .count();
        assert!(rejected <= 14, "{rejected} of 100 rejected");
    }

    /// Eight clusters: a strong effect is rejected at the 1 % level (the χ² reference could
    /// not reject at all, `LM ≤ G`), and the null is kept at about its 5 % level: with 100
    /// trials at 5 %, ≥ 14 rejections has binomial probability below 0.2 %.
    #[test]
    fn robust_score_test_with_eight_clusters_has_power_and_level() {
        let (n, size) = (400, 50);
        let cluster: Vec<usize> = (0..n).map(|k| k / size).collect();
        let centred = |c: &[f64]| -> Vec<f64> {
            let m = c.iter().sum::<f64>() / c.len() as f64;
            c.iter().map(|v| v - m).collect()
        };
        let z = vec![centred(&noise(n, 77))];
        let e = noise(n, 78);
        let u: Vec<f64> = (0..n).map(|k| e[k] + z[0][k]).collect();
        let (_, p) = robust_score_test(&centred(&u), &z, &cluster, 1);
        assert!(p < 0.01, "strong effect, p = {p}");
        let rejected = (0..100)
            .filter(|&seed| {
                let u = centred(&noise(n, seed + 300));
                robust_score_test(&u, &z, &cluster, 1).1 < 0.05
            })
            .count();
        assert!(rejected <= 13, "{rejected} of 100 rejected");
    }

    #[test]
    fn correlation_time_of_white_noise_and_ar1() {
        let e = noise(20000, 3);
        let tw = correlation_time(&e);
        assert!((0.8..1.3).contains(&tw), "white noise τ = {tw}");
        // AR(1) with φ = 0.99: τ = (1 + φ)/(1 − φ) = 199.
        let mut y = 0.0;
        let ar: Vec<f64> = e
            .iter()
            .map(|v| {
                y = 0.99 * y + v;
                y
            })
            .collect();
        let t = correlation_time(&ar);
        assert!((120.0..300.0).contains(&t), "AR(1) τ = {t}");
    }

    #[test]
    fn effective_n_shrinks_with_autocorrelation() {
        let e = noise(5000, 4);
        assert!(effective_n(&e) > 4000.0);
        let mut ar = vec![0.0; 5000];
        for k in 1..5000 {
            ar[k] = 0.9 * ar[k - 1] + e[k];
        }
        let ne = effective_n(&ar);
        assert!(ne > 100.0 && ne < 500.0, "{ne}");
    }

    #[test]
    fn whiteness_of_white_and_coloured_noise() {
        let e = noise(4000, 5);
        let u = noise(4000, 6);
        let w = whiteness(&e, &u, 25);
        assert!(w.acf_outside < 0.1 && w.xcf_outside < 0.1, "{w:?}");
        let coloured: Vec<f64> = (0..4000).map(|k| e[k] + 0.5 * u[k]).collect();
        let w = whiteness(&coloured, &u, 25);
        // The residual correlates with the input at lag 0.
        assert!(w.xcf[25] > 0.3);
        assert!((correlation_band(10_000, 0.99) - 0.02576).abs() < 1e-4);
    }

    /// Upper-tail p-values at tabulated quantiles: F(1, 10) 5 % point 4.9646, F(2, 30) 1 %
    /// point 5.3903, and F(1, 20) = t(20)² at the two-sided 5 % point 2.0860.
    #[test]
    fn f_test_p_values_match_tabulated_quantiles() {
        // With rss1 = d2 the statistic is rss0 − rss1 per added column.
        let p =
            |f: f64, q: usize, d2: f64| f_test(d2 + q as f64 * f, d2, q, 0, d2 + q as f64).p_value;
        assert!((p(4.9646, 1, 10.0) - 0.05).abs() < 1e-4);
        assert!((p(5.3903, 2, 30.0) - 0.01).abs() < 1e-4);
        assert!((p(2.0860f64.powi(2), 1, 20.0) - 0.05).abs() < 1e-4);
    }
}
