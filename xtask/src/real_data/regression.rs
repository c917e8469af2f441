//! Ordinary least squares with the statistics the real-data reports need: parameter standard
//! deviations, relative standard deviations (as the EMPS IDIM-LS scripts print them), the
//! condition number, and the extra-sum-of-squares F-test for nested models of independent
//! points (for autocorrelated residuals use `diagnose::stats::f_test` with an effective n).
//!
//! The solve is a thin SVD from faer; the covariance is `σ²·V·S⁻²·Vᵀ` with
//! `σ² = ‖y − Xθ‖² / (n − p)`.
use anyhow::{bail, Result};
use faer::{Col, Mat};

/// The result of one least-squares fit `y ≈ X·θ`.
#[derive(Debug, Clone)]
pub struct Ols {
    /// Estimated parameters, one per column of X.
    pub theta: Vec<f64>,
    /// Standard deviation of each parameter.
    pub sigma: Vec<f64>,
    /// Residual sum of squares ‖y − Xθ‖².
    pub rss: f64,
    /// Number of rows.
    pub n: usize,
    /// Number of parameters.
    pub p: usize,
    /// Largest over smallest singular value of X.
    pub cond: f64,
    /// ‖y‖ (for relative errors).
    pub y_norm: f64,
}

impl Ols {
    /// Relative standard deviation of parameter `k` in percent (`100·σ/|θ|`).
    pub fn rel_sigma_pct(&self, k: usize) -> f64 {
        100.0 * self.sigma[k] / self.theta[k].abs()
    }

    /// Residual standard deviation `sqrt(rss / (n − p))`.
    pub fn residual_std(&self) -> f64 {
        (self.rss / (self.n - self.p) as f64).sqrt()
    }

    /// Relative error `100·‖y − Xθ‖/‖y‖` in percent (the IDIM-LS "relative error").
    pub fn rel_error_pct(&self) -> f64 {
        100.0 * self.rss.sqrt() / self.y_norm
    }

    /// Predictions `X·θ` for rows given as slices.
    pub fn predict(&self, row: &[f64]) -> f64 {
        row.iter().zip(&self.theta).map(|(a, b)| a * b).sum()
    }
}

/// Fit `y ≈ X·θ` where `cols[j]` is column j of X.
pub fn ols(cols: &[Vec<f64>], y: &[f64]) -> Result<Ols> {
    let n = y.len();
    let p = cols.len();
    if p == 0 || n <= p {
        bail!("least squares needs more rows ({n}) than parameters ({p})");
    }
    if cols.iter().any(|c| c.len() != n) {
        bail!("least squares: columns of unequal length");
    }
    if y.iter()
        .chain(cols.iter().flatten())
        .any(|v| !v.is_finite())
    {
        bail!("least squares: the data contain a value that is not finite");
    }
    let x = Mat::<f64>::from_fn(n, p, |i, j| cols[j][i]);
    let svd = x
        .thin_svd()
        .map_err(|e| anyhow::anyhow!("least squares: SVD failed: {e:?}"))?;
    let s: Vec<f64> = (0..p).map(|k| svd.S().column_vector()[k]).collect();
    let smax = s.iter().cloned().fold(0.0, f64::max);
    let smin = s.iter().cloned().fold(f64::INFINITY, f64::min);
    if smin <= smax * 1e-13 {
        bail!("least squares: the regressors are linearly dependent (rank deficient)");
    }
    let v = svd.V();
    // θ = V·S⁻¹·Uᵀ·y
    let yv = Col::<f64>::from_fn(n, |i| y[i]);
    let uty = svd.U().transpose() * &yv;
    let theta_col = v * Col::<f64>::from_fn(p, |k| uty[k] / s[k]);
    let theta: Vec<f64> = (0..p).map(|j| theta_col[j]).collect();
    let rss = (&yv - &x * &theta_col).squared_norm_l2();
    let s2 = rss / (n - p) as f64;
    let sigma = (0..p)
        .map(|j| {
            let var: f64 = (0..p).map(|k| (v[(j, k)] / s[k]).powi(2)).sum();
            (s2 * var).sqrt()
        })
        .collect();
    Ok(Ols {
        theta,
        sigma,
        rss,
        n,
        p,
        cond: smax / smin,
        y_norm: yv.norm_l2(),
    })
}

/// Extra-sum-of-squares F statistic of adding `q` parameters to a nested model:
/// `F = ((rss0 − rss1)/q) / (rss1/(n − p1))`, and its p-value.
pub fn f_test(rss0: f64, rss1: f64, q: usize, n: usize, p1: usize) -> (f64, f64) {
    let d2 = (n - p1) as f64;
    let f = ((rss0 - rss1).max(0.0) / q as f64) / (rss1 / d2);
    (f, f_sf(f, q as f64, d2))
}

/// Survival function of the F distribution, `P(F > f)` (statrs).
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, FisherSnedecor};
    match FisherSnedecor::new(d1, d2) {
        Ok(d) if f.is_finite() && f > 0.0 => d.sf(f),
        _ => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_exact_line_and_zero_error() {
        let x: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = x.iter().map(|v| 2.0 + 3.0 * v).collect();
        let fit = ols(&[vec![1.0; 50], x], &y).unwrap();
        assert!((fit.theta[0] - 2.0).abs() < 1e-10 && (fit.theta[1] - 3.0).abs() < 1e-10);
        assert!(fit.rss < 1e-18);
    }

    #[test]
    fn rank_deficiency_is_an_error() {
        let x: Vec<f64> = (0..10).map(|k| k as f64).collect();
        assert!(ols(&[x.clone(), x.iter().map(|v| 2.0 * v).collect()], &x).is_err());
    }

    #[test]
    fn f_distribution_matches_known_quantiles() {
        // F(1, 10) upper 5 % point is 4.9646; F(2, 30) upper 1 % point is 5.3903.
        assert!((f_sf(4.9646, 1.0, 10.0) - 0.05).abs() < 1e-4);
        assert!((f_sf(5.3903, 2.0, 30.0) - 0.01).abs() < 1e-4);
        // F(1, d) = t² : t(20) two-sided 5 % point 2.0860.
        assert!((f_sf(2.0860f64.powi(2), 1.0, 20.0) - 0.05).abs() < 1e-4);
    }
}
