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
            // The curve reaches 0 between k0 and k: the integer lags strictly before the
            // crossing, on the line (none when k = k0 + 1: white noise sums to 0, not to the
            // triangle under ρ_0 = 1, which would make its τ 2).
            let d = (k - k0) as f64;
            for j in 1..k - k0 {
                let rj = r0 + (r - r0) * j as f64 / d;
                if rj <= 0.0 {
                    break;
                }
                sum += rj;
            }
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

/// Root mean square of `a − b` over their common length.
pub fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n as f64).sqrt()
}

/// A cluster-robust test of added columns ([`robust_wald_test`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustTest {
    /// Hotelling's `T²` of the columns' coefficients.
    pub t2: f64,
    /// Its p-value, read from `F(r, G − r)` ([`small_sample_test_beyond`]: from
    /// `F(r, η − r + 1)`).
    pub p_value: f64,
    /// Numerical rank `r` of the tested columns' cluster scores.
    pub rank: usize,
    /// Number of clusters `G`.
    pub clusters: usize,
    /// Share of `u`'s sum of squares in the directions left out because one cluster decides
    /// them alone ([`CLUSTER_LEVERAGE_CAP`]): what the test could not look at.
    pub dropped_share: f64,
    /// Degrees of freedom of the variance estimate `SᵀS`: `G` for [`robust_wald_test`], the
    /// effective number of clusters `η ≤ G` for [`small_sample_test_beyond`].
    pub effective_clusters: f64,
}

/// Cluster-robust Wald test that the columns `z` explain nothing of `u`, the residual of the
/// null model (each column of `z` residualised on the null model's columns, so that `u` is
/// orthogonal to them). `u` is regressed on `z`; the coefficients' covariance is the sandwich
/// built from the residuals `e` of that regression summed per cluster (rows with one id in
/// `cluster`, consecutive), in its jackknife form: each cluster's score as it would be with
/// the coefficients fitted without that cluster (CR3; HC3 of MacKinnon and White,
/// *J. Econometrics* 29, 1985, when every row is its own cluster), which keeps the level
/// where a few rows or clusters have large leverage or variance. With `a = zᵀu` and `S` the matrix
/// of cluster scores, `T² = (G−1)/G · aᵀ(SᵀS)⁻¹a`, read as Hotelling's
/// `F = (G−r)/(r(G−1)) · T² ~ F(r, G−r)` (Cameron, Gelbach and Miller, *Rev. Econ. Stat.* 90,
/// 2008, on few clusters). It holds its level whatever each row's variance and however the
/// rows of one cluster are correlated; the sandwich is built from the alternative's
/// residuals, so a real effect does not inflate its own variance (a score test built on `u`
/// loses most of its power there). The test is invariant to any invertible mix of the
/// columns, and runs on an orthonormal basis of their span: `r` is the span's numerical rank
/// (singular values above [`RANK_TOLERANCE`] of the largest), so that a column the null
/// model already spans is not tested as rounding noise, less the directions one cluster
/// decides alone ([`CLUSTER_LEVERAGE_CAP`]; their share of `u` is reported, for the caller
/// to weigh what the test could not see). The rank is judged against the largest singular
/// value, so the columns should be of like scale. `None` when the test cannot reject
/// whatever the data: no direction left, or not more clusters than `r + 1`.
pub fn robust_wald_test(u: &[f64], z: &[Vec<f64>], cluster: &[usize]) -> Option<RobustTest> {
    robust_wald_test_capped(u, z, cluster, CLUSTER_LEVERAGE_CAP)
}

/// [`robust_wald_test`] leaving out the directions on which one cluster has a leverage above
/// `cap` instead of [`CLUSTER_LEVERAGE_CAP`] (see [`ENTRY_LEVERAGE_CAP`]).
pub fn robust_wald_test_capped(
    u: &[f64],
    z: &[Vec<f64>],
    cluster: &[usize],
    cap: f64,
) -> Option<RobustTest> {
    wald_test_beyond_basis(u, z, &[], cluster, (cap, Form::Jackknife))
}

/// [`robust_wald_test_capped`] of `u` and `z` that are residuals after the null model whose
/// columns span the orthonormal basis `null` (empty: no null model). A cluster's
/// leave-one-out score then takes the null model's leverage on that cluster into account as
/// well as the tested columns' (the full model is refitted without the cluster).
fn wald_test_beyond_basis(
    u: &[f64],
    z: &[Vec<f64>],
    null: &[Vec<f64>],
    cluster: &[usize],
    (cap, form): (f64, Form),
) -> Option<RobustTest> {
    let n = u.len().min(cluster.len());
    if null.iter().any(|c| c.len() < n) {
        return None;
    }
    if z.is_empty() || n == 0 || z.iter().any(|c| c.len() < n) {
        return None;
    }
    let u = &u[..n];
    if !u.iter().all(|v| v.is_finite()) {
        return None;
    }
    let bounds = cluster_bounds(&cluster[..n]);
    let (q, dropped) = without_decided_directions(orthonormal_span(z, n)?, &bounds, cap)?;
    let uu: f64 = u.iter().map(|v| v * v).sum();
    let dropped_share = if uu > 0.0 {
        dropped
            .iter()
            .map(|d| d.iter().zip(u).map(|(x, y)| x * y).sum::<f64>().powi(2))
            .sum::<f64>()
            / uu
    } else {
        0.0
    };
    let a: Vec<f64> = q
        .iter()
        .map(|c| c.iter().zip(u).map(|(x, y)| x * y).sum())
        .collect();
    let scores = jackknife_scores(u, &q, null, &a, &bounds, form)?;
    let mut t = match form {
        Form::Jackknife => hotelling(&a, &scores)?,
        Form::SmallSample => approximate_hotelling(&a, &scores, effective_clusters(&q, &bounds))?,
    };
    t.dropped_share = dropped_share;
    Some(t)
}

/// How [`wald_test_beyond_basis`] adjusts each cluster's score and reads its statistic.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Form {
    /// The leave-one-cluster-out score `(I − H_g)⁻¹e_g` (CR3), read against `F(r, G − r)`.
    Jackknife,
    /// The score `(I − H_g)^(−1/2) e_g` (CR2, Bell and McCaffrey, *Surv. Methodol.* 28, 2002),
    /// whose `SᵀS` is unbiased for the coefficients' variance when the rows are independent
    /// with one variance, read as Hotelling's `T²` with the effective number of clusters `η`
    /// of that estimate as its degrees of freedom ([`small_sample_test_beyond`]).
    SmallSample,
}

/// Effective number of clusters of the variance estimate on the orthonormal directions `q`:
/// `η = r(r+1) / Σ_g (tr(A_g²) + tr(A_g)²)`, `A_g = Q_gᵀQ_g` the cluster's leverage. With
/// independent rows of one variance `σ²` the CR2 estimate is `Σ_g s_g s_gᵀ` with
/// `s_g ~ N(0, σ²A_g)`, and `η` is the number of degrees of freedom of the Wishart matrix of
/// the same mean (`σ²I`) and the same total variance of its entries (Pustejovsky and Tipton,
/// *J. Bus. Econ. Stat.* 36, 2018). `η = G` when every cluster holds the same share of every
/// direction, and falls towards the number of clusters that hold them when a few do. The
/// paper computes the variance from the adjusted residuals, which the fit correlates; this
/// count leaves that out, a correlation that grows with a cluster's leverage (which the
/// leverage cap keeps at most a half on the tested directions).
fn effective_clusters(q: &[Vec<f64>], bounds: &[(usize, usize)]) -> f64 {
    let r = q.len();
    let total: f64 = bounds
        .iter()
        .map(|&bd| {
            let a = cluster_leverage(q, bd);
            let trace: f64 = (0..r).map(|i| a[(i, i)]).sum();
            let square: f64 = (0..r)
                .flat_map(|i| (0..r).map(move |j| (i, j)))
                .map(|(i, j)| a[(i, j)] * a[(i, j)])
                .sum();
            square + trace * trace
        })
        .sum();
    if total > 0.0 {
        (r * (r + 1)) as f64 / total
    } else {
        bounds.len() as f64
    }
}

/// `[lo, hi)` row ranges of the consecutive runs of one id in `cluster`.
fn cluster_bounds(cluster: &[usize]) -> Vec<(usize, usize)> {
    let mut bounds: Vec<(usize, usize)> = Vec::new();
    for i in 0..cluster.len() {
        if i == 0 || cluster[i] != cluster[i - 1] {
            bounds.push((i, i + 1));
        } else if let Some(last) = bounds.last_mut() {
            last.1 = i + 1;
        }
    }
    bounds
}

/// Orthonormal basis of the span of the first `n` rows of the columns `z` (thin SVD), one
/// column per singular value above [`RANK_TOLERANCE`] of the largest; `None` for non-finite
/// entries or no free direction.
fn orthonormal_span(z: &[Vec<f64>], n: usize) -> Option<Vec<Vec<f64>>> {
    let k = z.len();
    let zm = faer::Mat::<f64>::from_fn(n, k, |i, j| z[j][i]);
    if !zm
        .col_iter()
        .flat_map(|c| c.iter().copied())
        .all(|v| v.is_finite())
    {
        return None;
    }
    let svd = zm.thin_svd().ok()?;
    let sv: Vec<f64> = (0..k.min(n)).map(|i| svd.S().column_vector()[i]).collect();
    let smax = sv.iter().cloned().fold(0.0, f64::max);
    let q: Vec<Vec<f64>> = (0..sv.len())
        .filter(|&j| sv[j] > smax * RANK_TOLERANCE && sv[j] > 0.0)
        .map(|j| (0..n).map(|i| svd.U()[(i, j)]).collect())
        .collect();
    (!q.is_empty()).then_some(q)
}

/// Leverage of the rows `[lo, hi)` on the orthonormal basis `q`: `A = Q_gᵀQ_g`.
fn cluster_leverage(q: &[Vec<f64>], (lo, hi): (usize, usize)) -> faer::Mat<f64> {
    let r = q.len();
    faer::Mat::<f64>::from_fn(r, r, |c1, c2| {
        (lo..hi).map(|i| q[c1][i] * q[c2][i]).sum::<f64>()
    })
}

/// Orthonormal columns (one `Vec` per column).
type Basis = Vec<Vec<f64>>;

/// The basis `q` less every direction on which one cluster has a leverage above `cap`
/// (the variance there would rest on that cluster alone), and the directions left out. Each
/// round rotates the basis onto the worst cluster's eigenvectors (still orthonormal) and
/// drops the top one, so the loop ends after at most `r` rounds. `None` when no direction is
/// left.
fn without_decided_directions(
    mut q: Basis,
    bounds: &[(usize, usize)],
    cap: f64,
) -> Option<(Basis, Basis)> {
    let mut dropped: Basis = Vec::new();
    loop {
        let r = q.len();
        if r == 0 {
            return None;
        }
        let mut worst: Option<(f64, faer::Mat<f64>)> = None;
        for &bd in bounds {
            // The largest eigenvalue is at most the trace, the cluster's summed leverage.
            let trace: f64 = (bd.0..bd.1)
                .map(|i| q.iter().map(|c| c[i] * c[i]).sum::<f64>())
                .sum();
            if trace <= cap {
                continue;
            }
            let evd = cluster_leverage(&q, bd)
                .self_adjoint_eigen(faer::Side::Lower)
                .ok()?;
            // faer sorts the eigenvalues ascending: the last is the largest.
            let top = evd.S().column_vector()[r - 1];
            if top > cap && worst.as_ref().is_none_or(|w| top > w.0) {
                worst = Some((top, evd.U().to_owned()));
            }
        }
        let Some((_, vecs)) = worst else {
            return Some((q, dropped));
        };
        let n = q[0].len();
        let mut rotated: Basis = (0..r)
            .map(|m| {
                (0..n)
                    .map(|i| (0..r).map(|c| q[c][i] * vecs[(c, m)]).sum())
                    .collect()
            })
            .collect();
        dropped.extend(rotated.pop());
        q = rotated;
    }
}

/// Each cluster's score `Q_gᵀ (I − H_g)⁻¹ e_g`, with `e = u − Q·a` the residual after the
/// columns and `H_g = F_g F_gᵀ` the cluster's block of the hat matrix of the full model, whose
/// orthonormal basis `F = [N, Q]` joins the null model's `null` and the tested `q`: the score
/// the cluster would have with every coefficient fitted without it (the jackknife; for a
/// one-row cluster, HC3's `q_i·e_i/(1 − h_i)`). By Woodbury,
/// `(I − F_g F_gᵀ)⁻¹ = I + F_g (I − F_gᵀF_g)⁻¹ F_gᵀ`. One column per tested direction, one
/// row per cluster. A leave-out fit that a cluster decides alone (an eigenvalue of
/// `F_gᵀF_g` within [`LEAVE_OUT_FLOOR`] of one) gives that cluster a large score, which only
/// weakens the test.
fn jackknife_scores(
    u: &[f64],
    q: &[Vec<f64>],
    null: &[Vec<f64>],
    a: &[f64],
    bounds: &[(usize, usize)],
    form: Form,
) -> Option<Vec<Vec<f64>>> {
    let r = q.len();
    let e: Vec<f64> = (0..u.len())
        .map(|i| u[i] - q.iter().zip(a).map(|(c, ac)| c[i] * ac).sum::<f64>())
        .collect();
    let full: Vec<&[f64]> = null.iter().chain(q).map(|c| c.as_slice()).collect();
    let f = full.len();
    let mut scores: Vec<Vec<f64>> = vec![Vec::with_capacity(bounds.len()); r];
    for &(lo, hi) in bounds {
        if hi - lo == 1 {
            // One row: `(I − h_i)⁻¹` is the scalar `1/(1 − h_i)` of the full model's leverage.
            let h: f64 = full.iter().map(|c| c[lo] * c[lo]).sum();
            let left = (1.0 - h).max(LEAVE_OUT_FLOOR);
            let inv = match form {
                Form::Jackknife => 1.0 / left,
                Form::SmallSample => 1.0 / left.sqrt(),
            };
            for (col, c) in scores.iter_mut().zip(q) {
                col.push(c[lo] * e[lo] * inv);
            }
            continue;
        }
        let bf: Vec<f64> = full
            .iter()
            .map(|c| (lo..hi).map(|i| c[i] * e[i]).sum())
            .collect();
        let leverage = faer::Mat::<f64>::from_fn(f, f, |c1, c2| {
            (lo..hi).map(|i| full[c1][i] * full[c2][i]).sum::<f64>()
        });
        let evd = leverage.self_adjoint_eigen(faer::Side::Lower).ok()?;
        let (lam, vecs) = (evd.S().column_vector(), evd.U());
        // t = g(F_gᵀF_g)·F_gᵀ e_g, with (I − F_gF_gᵀ)^p = I + F_g·g(F_gᵀF_g)·F_gᵀ for the
        // power p = −1 (CR3: g(λ) = 1/(1 − λ)) or −1/2 (CR2: g(λ) = ((1 − λ)^(−1/2) − 1)/λ,
        // 1/2 at λ = 0).
        let mut t = vec![0.0; f];
        for m in 0..f {
            let left = (1.0 - lam[m]).max(LEAVE_OUT_FLOOR);
            let gain = match form {
                Form::Jackknife => 1.0 / left,
                Form::SmallSample if lam[m] > 1e-12 => (1.0 / left.sqrt() - 1.0) / lam[m],
                Form::SmallSample => 0.5,
            };
            let vb: f64 = (0..f).map(|c| vecs[(c, m)] * bf[c]).sum::<f64>() * gain;
            for c in 0..f {
                t[c] += vecs[(c, m)] * vb;
            }
        }
        // s_g = Q_gᵀe_g + Q_gᵀF_g·t; Q_gᵀe_g is the tail of F_gᵀe_g, Q_gᵀF_g the tail rows of
        // F_gᵀF_g.
        let k0 = f - r;
        for (j, col) in scores.iter_mut().enumerate() {
            let row = k0 + j;
            let v = bf[row] + (0..f).map(|c| leverage[(row, c)] * t[c]).sum::<f64>();
            col.push(v);
        }
    }
    Some(scores)
}

/// Smallest `1 − λ` a leave-one-cluster-out fit divides by: a cluster that holds all of a
/// direction's information (λ = 1) leaves no fit without it, and its score is then bounded
/// instead of infinite (a large score only weakens the test).
const LEAVE_OUT_FLOOR: f64 = 1e-9;

/// Hotelling's `T² = (G−1)/G · aᵀ(SᵀS)⁻¹a` of the projections `a` against the cluster scores
/// `S` (one column per direction), and its p-value from `F = (G−r)/(r(G−1))·T² ~ F(r, G−r)`.
/// `None` when it cannot decide: not more clusters than `r + 1`, scores of lower rank than
/// the basis (every cluster's score on one line), or a non-finite result.
fn hotelling(a: &[f64], scores: &[Vec<f64>]) -> Option<RobustTest> {
    let r = scores.len();
    let g = scores.first()?.len();
    if g <= r + 1 {
        return None;
    }
    let sm = faer::Mat::<f64>::from_fn(g, r, |i, j| scores[j][i]);
    let ssvd = sm.thin_svd().ok()?;
    let ss: Vec<f64> = (0..r).map(|i| ssvd.S().column_vector()[i]).collect();
    let smax = ss.iter().cloned().fold(0.0, f64::max);
    if !(smax > 0.0 && smax.is_finite()) || ss.iter().any(|&sj| sj <= smax * RANK_TOLERANCE) {
        return None;
    }
    // aᵀ(SᵀS)⁻¹a = Σ_j (v_jᵀa)² / σ_j².
    let v = ssvd.V();
    let w: f64 = ss
        .iter()
        .enumerate()
        .map(|(j, &sj)| {
            let va: f64 = (0..r).map(|m| v[(m, j)] * a[m]).sum();
            va * va / (sj * sj)
        })
        .sum();
    let (gf, rf) = (g as f64, r as f64);
    let t2 = w * (gf - 1.0) / gf;
    let f = (gf - rf) / (rf * (gf - 1.0)) * t2;
    let p = statrs::distribution::FisherSnedecor::new(rf, gf - rf)
        .ok()?
        .sf(f);
    p.is_finite().then_some(RobustTest {
        t2,
        p_value: p,
        rank: r,
        clusters: g,
        dropped_share: 0.0,
        effective_clusters: gf,
    })
}

/// Hotelling's `T²(r, η)` of the projections `a` against the CR2 cluster scores `S`:
/// `W = aᵀ(SᵀS)⁻¹a`, `(η − r + 1)/(η·r)·W ~ F(r, η − r + 1)` ([`small_sample_test_beyond`]);
/// `t2` is `W`. `None` when `η ≤ r + 1` or as [`hotelling`].
fn approximate_hotelling(a: &[f64], scores: &[Vec<f64>], eta: f64) -> Option<RobustTest> {
    let r = scores.len();
    let eta = eta.min(scores.first()?.len() as f64);
    let rf = r as f64;
    if eta.is_nan() || eta <= rf + 1.0 {
        return None;
    }
    let base = hotelling(a, scores)?;
    let g = base.clusters as f64;
    let wald = base.t2 * g / (g - 1.0);
    let f = (eta - rf + 1.0) / (eta * rf) * wald;
    let p = FisherSnedecor::new(rf, eta - rf + 1.0).ok()?.sf(f);
    p.is_finite().then_some(RobustTest {
        t2: wald,
        p_value: p,
        effective_clusters: eta,
        ..base
    })
}

/// A direction of the tested columns on which one cluster has more leverage than this (one
/// half: more than all other clusters together) is dropped from [`robust_wald_test`]: its
/// variance would rest on that one cluster, whose residual the fit has absorbed, and a
/// single outlying window would read as an effect.
pub const CLUSTER_LEVERAGE_CAP: f64 = 0.5;

/// The leverage cap of the entry test of a named effect (`diagnose::forward_select`): 0.9.
/// The level needs no cap: a cluster's jackknifed score is its error with the whole model
/// fitted without it, so a direction one cluster decides alone gets a score as large as its
/// projection and a T² near one, which cannot reject. The cap bounds the leave-out inflation
/// `1/(1 − h)` at ten, for numerical stability. An effect's column is one physical law over
/// the whole log, often largest in a few windows (cogging in the slowest ones, a braking
/// drive at the steps), so a lower cap would drop the directions that hold it. The verdict's
/// checks keep [`CLUSTER_LEVERAGE_CAP`]: their flexible columns can follow one window, and
/// the share left out decides "cannot judge" there (decision 0011).
pub const ENTRY_LEVERAGE_CAP: f64 = 0.9;

/// Singular values below this fraction of the largest count as zero in
/// [`robust_wald_test`]: 1e-7, above the rounding of a column residualised on a span that
/// contains it (the least-squares ridge leaves about 1e-9 of it) and far below any column
/// that carries data.
pub const RANK_TOLERANCE: f64 = 1e-7;

/// [`robust_wald_test_capped`] (leverage cap `cap`) of the columns `cols` on `y`, both taken
/// beyond the null model's columns `null` (a constant or its weak-form integral; a model's
/// own columns). Returns the test and the share of `y`'s sum of squares, beyond the null
/// model, that the columns explain.
pub fn robust_test_beyond(
    y: &[f64],
    null: &[&[f64]],
    cols: &[Vec<f64>],
    cluster: &[usize],
    cap: f64,
) -> (Option<RobustTest>, f64) {
    test_beyond(y, null, cols, cluster, (cap, Form::Jackknife))
}

/// [`robust_test_beyond`] in the small-sample form of Pustejovsky and Tipton (*J. Bus. Econ.
/// Stat.* 36, 2018): the CR2 scores (each cluster's residual times `(I − H_g)^(−1/2)`, `H_g`
/// its block of the full model's hat matrix) and `W = aᵀ(SᵀS)⁻¹a` read as Hotelling's
/// `T²(r, η)`, `(η − r + 1)/(η·r)·W ~ F(r, η − r + 1)`, with the effective number of
/// clusters `η` ([`RobustTest::effective_clusters`]) in place of `G`. `F(r, G − r)` takes
/// the variance estimate to have `G − 1` degrees of freedom, which holds only when every
/// cluster holds about the same share of the tested directions; where a few clusters hold
/// most of one (a parameter seen only at the reversals, or in the few holds of a step
/// input), the estimate rests on those few and the test rejects too often, more so the
/// further out in its tail it is read. The jackknife's CR3 scores correct that in part by
/// inflating the few clusters' scores, and with `η` as well would correct it twice. `None`
/// when `η ≤ r + 1`, or as [`robust_test_beyond`].
pub fn small_sample_test_beyond(
    y: &[f64],
    null: &[&[f64]],
    cols: &[Vec<f64>],
    cluster: &[usize],
    cap: f64,
) -> (Option<RobustTest>, f64) {
    test_beyond(y, null, cols, cluster, (cap, Form::SmallSample))
}

fn test_beyond(
    y: &[f64],
    null: &[&[f64]],
    cols: &[Vec<f64>],
    cluster: &[usize],
    (cap, form): (f64, Form),
) -> (Option<RobustTest>, f64) {
    let base = super::least_squares::lstsq(null, y);
    // Each column scaled to unit norm before it is residualised, so that the rank is judged
    // on columns of like scale ([`robust_wald_test`]) and a column the null model spans
    // stays at the rounding of the residualisation.
    let z: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| {
            let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
            let unit: Vec<f64> = if norm > 0.0 && norm.is_finite() {
                c.iter().map(|v| v / norm).collect()
            } else {
                c.clone()
            };
            residualise(&unit, null)
        })
        .collect();
    let zr: Vec<&[f64]> = z.iter().map(|c| c.as_slice()).collect();
    let beyond = super::least_squares::lstsq(&zr, &base.resid);
    let share = if base.rss > 0.0 {
        ((base.rss - beyond.rss) / base.rss).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let n = y.len();
    if null.iter().any(|c| c.len() < n) {
        return (None, share);
    }
    let null_cols: Vec<Vec<f64>> = null.iter().map(|c| c[..n].to_vec()).collect();
    let null_basis = orthonormal_span(&null_cols, n).unwrap_or_default();
    (
        wald_test_beyond_basis(&base.resid, &z, &null_basis, cluster, (cap, form)),
        share,
    )
}

/// `c` minus its least-squares projection on `null` (the null model's columns).
pub fn residualise(c: &[f64], null: &[&[f64]]) -> Vec<f64> {
    if null.is_empty() {
        return c.to_vec();
    }
    super::least_squares::lstsq(null, c).resid
}

/// `n` standard normal numbers from `seed` (for the statistics' tests).
/// Pearson correlation of two equally long series (0 when one is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

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
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
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
        // 1e-3: a pure-noise column is flagged at that level once in a thousand draws.
        assert!(t.p_value > 1e-3, "noise flagged: {t:?}");
        let y: Vec<f64> = (0..n).map(|k| e[k] + 0.3 * x[k]).collect();
        let base = lstsq(&[], &y);
        let with = lstsq(&[&x], &y);
        let t = f_test(base.rss, with.rss, 1, 0, n as f64);
        // 0.3·x on unit noise explains 0.09/1.09 = 8 % of the variance: F ≈ 180 on 2000
        // samples, p far below 1e-10; 5 % leaves room for the draw.
        assert!(
            t.p_value < 1e-10 && t.explained > 0.05 && t.delta_bic < 0.0,
            "{t:?}"
        );
    }

    /// Rows of very unequal variance: the robust Wald test rejects a column that is
    /// nonzero only on the noisy rows at about its level, and still finds a real effect.
    #[test]
    fn robust_wald_test_holds_its_level_under_unequal_variance() {
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
                robust_wald_test(&centred(&u), &zc, &cluster)
                    .unwrap()
                    .p_value
                    < 0.05
            })
            .count();
        // 2 to 22 of 200 at the 5 % level: the binomial count (mean 10) falls outside with
        // probability 6e-4.
        assert!((2..=22).contains(&rejected), "{rejected} of 200 rejected");
        let e = noise(n, 1);
        let u: Vec<f64> = (0..n).map(|k| e[k] + 2.0 * z[k]).collect();
        assert!(
            robust_wald_test(&centred(&u), &zc, &cluster)
                .unwrap()
                .p_value
                < 1e-6
        );
    }

    /// Rows that share an error within a cluster: a column constant over each cluster is not
    /// taken for an effect when the clusters are given.
    #[test]
    fn robust_wald_test_allows_an_error_shared_within_a_cluster() {
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
                robust_wald_test(&u, &[zc], &cluster).unwrap().p_value < 0.05
            })
            .count();
        // At most 14 of 100 at the 5 % level: the binomial count (mean 5) exceeds it with
        // probability 1.4e-4.
        assert!(rejected <= 14, "{rejected} of 100 rejected");
    }

    /// Eight clusters: a strong effect is rejected at the 1 % level (the χ² reference could
    /// not reject at all, `LM ≤ G`), and the null is kept at about its 5 % level: with 100
    /// trials at 5 %, ≥ 14 rejections has binomial probability below 0.2 %.
    #[test]
    fn robust_wald_test_with_eight_clusters_has_power_and_level() {
        let (n, size) = (400, 50);
        let cluster: Vec<usize> = (0..n).map(|k| k / size).collect();
        let centred = |c: &[f64]| -> Vec<f64> {
            let m = c.iter().sum::<f64>() / c.len() as f64;
            c.iter().map(|v| v - m).collect()
        };
        let z = vec![centred(&noise(n, 77))];
        let e = noise(n, 78);
        let u: Vec<f64> = (0..n).map(|k| e[k] + z[0][k]).collect();
        let p = robust_wald_test(&centred(&u), &z, &cluster)
            .unwrap()
            .p_value;
        assert!(p < 0.01, "strong effect, p = {p}");
        let rejected = (0..100)
            .filter(|&seed| {
                let u = centred(&noise(n, seed + 300));
                robust_wald_test(&u, &z, &cluster).unwrap().p_value < 0.05
            })
            .count();
        // At most 13 of 100 at the 5 % level: the binomial count (mean 5) exceeds it with
        // probability 5e-4.
        assert!(rejected <= 13, "{rejected} of 100 rejected");
    }

    /// Twelve harmonics of an angle on 200 rows of very unequal variance: the test holds its
    /// level (with 200 trials at 5 %, more than 22 rejections has binomial probability below
    /// 0.02 %), and a periodic error that explains about a third of the residual is found at
    /// the 1e-6 level: the sandwich is built from the residuals after the columns, so the
    /// effect does not count as noise.
    #[test]
    fn robust_wald_test_with_many_columns_has_level_and_power() {
        let n = 200;
        let cluster: Vec<usize> = (0..n).collect();
        let theta = noise(n, 900);
        let z: Vec<Vec<f64>> = (1..=6)
            .flat_map(|k| {
                let kf = k as f64;
                [
                    theta
                        .iter()
                        .map(|x| (3.0 * kf * x).sin())
                        .collect::<Vec<f64>>(),
                    theta.iter().map(|x| (3.0 * kf * x).cos()).collect(),
                ]
            })
            .collect();
        let ones = vec![1.0; n];
        let z: Vec<Vec<f64>> = z.iter().map(|c| residualise(c, &[&ones])).collect();
        let sd = |k: usize| if k.is_multiple_of(7) { 6.0 } else { 1.0 };
        let rejected = (0..200)
            .filter(|&seed| {
                let e = noise(n, seed + 2000);
                let u: Vec<f64> = (0..n).map(|k| e[k] * sd(k)).collect();
                let u = residualise(&u, &[&ones]);
                robust_wald_test(&u, &z, &cluster).unwrap().p_value < 0.05
            })
            .count();
        // At most 22 of 200 at the 5 % level: the binomial count (mean 10) exceeds it with
        // probability 2e-4.
        assert!(rejected <= 22, "{rejected} of 200 rejected");
        let e = noise(n, 5);
        let u: Vec<f64> = (0..n)
            .map(|k| e[k] * sd(k) + 1.5 * (z[0][k] - 0.5 * z[5][k]))
            .collect();
        let u = residualise(&u, &[&ones]);
        let t = robust_wald_test(&u, &z, &cluster).unwrap();
        assert!(t.p_value < 1e-6, "{t:?}");
        assert_eq!(t.rank, 12);
    }

    /// A column the null model already spans is not tested as rounding noise, and too few
    /// clusters make the test undecidable rather than passed.
    #[test]
    fn jackknife_scores_are_the_leave_one_cluster_out_residuals_of_the_full_model() {
        // A null column concentrated in the first clusters (as an inertia column is in the
        // windows of a voltage step) and two tested columns, on clusters of 1 to 6 rows.
        let n = 60;
        let noise = white_noise(4 * n, 7);
        let draw = |k: usize, i: usize| noise[k * n + i];
        let cluster: Vec<usize> = (0..n)
            .map(|i| if i < 6 { i } else { 6 + (i - 6) / 6 })
            .collect();
        let ncol: Vec<f64> = (0..n)
            .map(|i| {
                if i < 12 {
                    3.0 + draw(0, i)
                } else {
                    0.1 * draw(0, i)
                }
            })
            .collect();
        let ones = vec![1.0; n];
        let null_cols = vec![ones.clone(), ncol.clone()];
        let nb = orthonormal_span(&null_cols, n).unwrap();
        let raw: Vec<Vec<f64>> = (1..3)
            .map(|k| (0..n).map(|i| draw(k, i)).collect())
            .collect();
        let z: Vec<Vec<f64>> = raw
            .iter()
            .map(|c| residualise(c, &[&ones, &ncol]))
            .collect();
        let q = orthonormal_span(&z, n).unwrap();
        let y: Vec<f64> = (0..n).map(|i| draw(3, i)).collect();
        let u = residualise(&y, &[&ones, &ncol]);
        let a: Vec<f64> = q
            .iter()
            .map(|c| c.iter().zip(&u).map(|(x, v)| x * v).sum())
            .collect();
        let bounds = cluster_bounds(&cluster);
        let scores = jackknife_scores(&u, &q, &nb, &a, &bounds, Form::Jackknife).unwrap();
        for (g, &(lo, hi)) in bounds.iter().enumerate() {
            // Refit y on [1, ncol, q] without the cluster; its residuals on the cluster.
            let keep: Vec<usize> = (0..n).filter(|&i| i < lo || i >= hi).collect();
            let cols: Vec<Vec<f64>> = [&ones, &ncol, &q[0], &q[1]]
                .iter()
                .map(|c| keep.iter().map(|&i| c[i]).collect())
                .collect();
            let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let yk: Vec<f64> = keep.iter().map(|&i| y[i]).collect();
            let fit = crate::numerics::least_squares::lstsq(&refs, &yk);
            for (j, qj) in q.iter().enumerate() {
                let s: f64 = (lo..hi)
                    .map(|i| {
                        let pred = fit.beta[0]
                            + fit.beta[1] * ncol[i]
                            + fit.beta[2] * q[0][i]
                            + fit.beta[3] * q[1][i];
                        qj[i] * (y[i] - pred)
                    })
                    .sum();
                assert!(
                    (scores[j][g] - s).abs() < 1e-6 * (1.0 + s.abs()),
                    "cluster {g} direction {j}: {} vs {s}",
                    scores[j][g]
                );
            }
        }
    }

    /// The CR2 score of each cluster is `Q_gᵀ(I − H_g)^(−1/2)e_g`, the inverse square root
    /// taken here by the eigenvalues of the cluster's own `I − H_g` (rows × rows) rather
    /// than through the columns' Gram matrix as [`jackknife_scores`] does.
    #[test]
    fn small_sample_scores_use_the_inverse_square_root_of_the_clusters_hat() {
        let n = 60;
        let cluster: Vec<usize> = (0..n).map(|i| (i / 3 + i / 7) % 17).collect();
        let cluster: Vec<usize> = {
            // Consecutive runs of unequal length: ids increase at each change.
            let mut id = 0;
            (0..n)
                .map(|i| {
                    if i > 0 && cluster[i] != cluster[i - 1] {
                        id += 1;
                    }
                    id
                })
                .collect()
        };
        let draw = |k: u64| noise(n, 500 + k);
        let ncol: Vec<f64> = draw(0)
            .iter()
            .enumerate()
            .map(|(i, v)| if i < 9 { 3.0 + v } else { 0.1 * v })
            .collect();
        let nb = orthonormal_span(std::slice::from_ref(&ncol), n).unwrap();
        let z: Vec<Vec<f64>> = (1..3).map(|k| residualise(&draw(k), &[&ncol])).collect();
        let q = orthonormal_span(&z, n).unwrap();
        let u = residualise(&draw(3), &[&ncol]);
        let a: Vec<f64> = q
            .iter()
            .map(|c| c.iter().zip(&u).map(|(x, v)| x * v).sum())
            .collect();
        let e: Vec<f64> = (0..n)
            .map(|i| u[i] - q.iter().zip(&a).map(|(c, ac)| c[i] * ac).sum::<f64>())
            .collect();
        let bounds = cluster_bounds(&cluster);
        let scores = jackknife_scores(&u, &q, &nb, &a, &bounds, Form::SmallSample).unwrap();
        let full: Vec<&Vec<f64>> = nb.iter().chain(&q).collect();
        for (g, &(lo, hi)) in bounds.iter().enumerate() {
            let m = hi - lo;
            let left = faer::Mat::<f64>::from_fn(m, m, |i, j| {
                let h: f64 = full.iter().map(|c| c[lo + i] * c[lo + j]).sum();
                if i == j {
                    1.0 - h
                } else {
                    -h
                }
            });
            let evd = left.self_adjoint_eigen(faer::Side::Lower).unwrap();
            let (lam, v) = (evd.S().column_vector(), evd.U());
            let adjusted: Vec<f64> = (0..m)
                .map(|i| {
                    (0..m)
                        .map(|k| {
                            let proj: f64 = (0..m).map(|j| v[(j, k)] * e[lo + j]).sum();
                            v[(i, k)] * proj / lam[k].sqrt()
                        })
                        .sum()
                })
                .collect();
            for (j, qj) in q.iter().enumerate() {
                let s: f64 = (0..m).map(|i| qj[lo + i] * adjusted[i]).sum();
                assert!(
                    (scores[j][g] - s).abs() < 1e-9 * (1.0 + s.abs()),
                    "cluster {g} direction {j}: {} vs {s}",
                    scores[j][g]
                );
            }
        }
    }

    /// The effective number of clusters is `G` when every cluster holds the same share of
    /// the tested direction, and the number of clusters that hold it when only some do.
    #[test]
    fn effective_clusters_count_the_clusters_that_hold_the_direction() {
        let (n, size) = (400, 10);
        let bounds: Vec<(usize, usize)> =
            (0..n / size).map(|g| (g * size, g * size + size)).collect();
        let even: Vec<f64> = (0..n)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let q = orthonormal_span(&[even], n).unwrap();
        assert!((effective_clusters(&q, &bounds) - 40.0).abs() < 1e-9);
        let few: Vec<f64> = (0..n)
            .map(|i| if i < 4 * size { 1.0 } else { 0.0 })
            .collect();
        let q = orthonormal_span(&[few], n).unwrap();
        assert!((effective_clusters(&q, &bounds) - 4.0).abs() < 1e-9);
    }

    /// A column that lives mostly in 5 of 40 clusters (ten times the amplitude there): under
    /// the null the small-sample test holds its level at 5 % and 1 % over 400 draws (more
    /// than 32 or 10 rejections have binomial probability below 0.1 %), where the variance
    /// estimate rests on about 5 clusters and `F(1, G − 1)` reads it as if on 39.
    #[test]
    fn small_sample_test_holds_its_level_where_few_clusters_hold_the_column() {
        let (n, size) = (400, 10);
        let cluster: Vec<usize> = (0..n).map(|k| k / size).collect();
        let col: Vec<f64> = noise(n, 900)
            .iter()
            .enumerate()
            .map(|(i, v)| if i < 5 * size { 3.0 * v } else { 0.3 * v })
            .collect();
        let ones = vec![1.0; n];
        let (mut at5, mut at1) = (0, 0);
        for seed in 0..400 {
            let y = noise(n, 1000 + seed);
            let (t, _) = small_sample_test_beyond(
                &y,
                &[&ones],
                std::slice::from_ref(&col),
                &cluster,
                CLUSTER_LEVERAGE_CAP,
            );
            let t = t.unwrap();
            assert!(t.effective_clusters < 10.0, "η = {}", t.effective_clusters);
            at5 += usize::from(t.p_value < 0.05);
            at1 += usize::from(t.p_value < 0.01);
        }
        assert!(at5 <= 32 && at1 <= 10, "{at5} at 5 %, {at1} at 1 % of 400");
        // Not the trivial way: a strong effect is still found.
        let e = noise(n, 77);
        let y: Vec<f64> = (0..n).map(|i| e[i] + 0.5 * col[i]).collect();
        let (t, _) = small_sample_test_beyond(
            &y,
            &[&ones],
            std::slice::from_ref(&col),
            &cluster,
            CLUSTER_LEVERAGE_CAP,
        );
        assert!(t.unwrap().p_value < 1e-3);
    }

    #[test]
    fn robust_wald_test_drops_spanned_columns_and_refuses_too_few_clusters() {
        let n = 300;
        let x = noise(n, 31);
        let e = noise(n, 32);
        let u = residualise(&e, &[&x]);
        let spanned = residualise(&x, &[&x]);
        let free = residualise(&noise(n, 33), &[&x]);
        let each: Vec<usize> = (0..n).collect();
        let t = robust_wald_test(&u, &[spanned, free.clone()], &each).unwrap();
        assert_eq!(t.rank, 1);
        let two: Vec<usize> = (0..n).map(|k| k / 150).collect();
        assert!(robust_wald_test(&u, &[free], &two).is_none());
    }

    #[test]
    fn correlation_time_of_white_noise_and_ar1() {
        // White noise: τ = 1 whatever the sign of its first sample correlation (about half
        // the series draw ρ_1 < 0). The estimate is biased up a little (a chance run of
        // positive ρ_k is summed, a negative one stops the sum): over 400 simulated series of
        // 20,000 its mean was 1.013 and its 99th percentile 1.10. The mean of 40 lies within
        // 0.95..1.10 (its standard error is about 0.005); counting the triangle under ρ_0 = 1
        // at a crossing would put it near 1.5.
        let mean_w = (0..40)
            .map(|seed| correlation_time(&noise(20000, 100 + seed)))
            .sum::<f64>()
            / 40.0;
        assert!(
            (0.95..1.10).contains(&mean_w),
            "white noise mean τ = {mean_w}"
        );
        // Differenced white noise (ρ_1 = −1/2, the rest 0) has τ = 0: clamped to 1.
        let w = noise(20001, 5);
        let diff: Vec<f64> = w.windows(2).map(|p| p[1] - p[0]).collect();
        let td = correlation_time(&diff);
        assert!(td < 1.05, "differenced noise τ = {td}");
        let e = noise(20000, 3);
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
        // White noise: n_eff ≈ n = 5000; AR(0.9): n·(1 − ρ)/(1 + ρ) = 263, the bounds below a
        // factor of two either way for the estimate's spread.
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
        // 0.1: white noise leaves 1 % of lags outside the 99 % band; 3 or more of 25 happen with
        // probability 2e-3.
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
        // 1e-4: the tables' quantiles are given to five digits.
        assert!((p(4.9646, 1, 10.0) - 0.05).abs() < 1e-4);
        assert!((p(5.3903, 2, 30.0) - 0.01).abs() < 1e-4);
        assert!((p(2.0860f64.powi(2), 1, 20.0) - 0.05).abs() < 1e-4);
    }
}
