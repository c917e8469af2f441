//! Linear least squares, once for the whole tool.
//!
//! - [`lstsq`]: `y ≈ X·β` by faer's QR on unit-RMS columns with a tiny ridge, so that
//!   collinear candidate columns stay finite: what model selection runs thousands of times.
//! - [`Gram`]: the same problem over many subsets of one set of columns (forward selection).
//! - [`ols`]: the reporting fit: faer's thin SVD, refusing a rank-deficient problem, with
//!   each parameter's standard deviation `σ²·V·S⁻²·Vᵀ`, `σ² = ‖y − Xβ‖²/(n − p)`, and the
//!   condition number, for tables of identified parameters.
//! - [`solve_spd`]: normal equations already formed (STLSQ), by Cholesky with a
//!   pseudo-inverse fallback for a singular system.
//! - [`normal_inverse_diag`]: the diagonal of `(JᵀJ)⁻¹`, a nonlinear fit's standard errors.
//! - [`solve_pd`]: a positive definite system (a damped Levenberg-Marquardt step), by
//!   Cholesky alone, reporting failure instead of falling back.
//! - [`leave_one_out_rss`]: the PRESS residual of a fit, each row predicted without itself.
use anyhow::{bail, Result};
use faer::linalg::solvers::SolveLstsq;
use faer::{Col, Mat, MatRef};

/// Result of a least-squares fit `y ≈ Σ beta_j·col_j`.
#[derive(Debug, Clone)]
pub struct LinFit {
    /// Coefficients, one per column (0 for a column that is identically zero).
    pub beta: Vec<f64>,
    /// Residual sum of squares.
    pub rss: f64,
    /// Residual `y − X·beta`.
    pub resid: Vec<f64>,
}

/// Relative ridge added to the (column-scaled) normal problem so that collinear columns give
/// finite coefficients instead of a blow-up: 1e-9 of a unit-RMS column's energy. It changes a
/// well-posed fit by less than a part per billion.
const RIDGE: f64 = 1e-9;

/// Least squares `y ≈ X·beta` with X given by columns. Columns are scaled to unit RMS and a
/// tiny ridge keeps collinear columns finite.
pub fn lstsq(cols: &[&[f64]], y: &[f64]) -> LinFit {
    let n = y.len();
    let p = cols.len();
    if p == 0 || n == 0 {
        let rss = y.iter().map(|v| v * v).sum();
        return LinFit {
            beta: vec![0.0; p],
            rss,
            resid: y.to_vec(),
        };
    }
    let scale: Vec<f64> = cols
        .iter()
        .map(|c| {
            let ms = c.iter().map(|v| v * v).sum::<f64>() / n as f64;
            if ms > 0.0 && ms.is_finite() {
                ms.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let ridge = (RIDGE * n as f64).sqrt();
    let a = Mat::<f64>::from_fn(n + p, p, |r, c| {
        if r < n {
            if scale[c] > 0.0 {
                cols[c][r] / scale[c]
            } else {
                0.0
            }
        } else if r - n == c {
            ridge
        } else {
            0.0
        }
    });
    let b = Mat::<f64>::from_fn(n + p, 1, |r, _| if r < n { y[r] } else { 0.0 });
    let x = a.qr().solve_lstsq(&b);
    let beta: Vec<f64> = (0..p)
        .map(|c| {
            if scale[c] > 0.0 {
                x[(c, 0)] / scale[c]
            } else {
                0.0
            }
        })
        .collect();
    let mut resid = y.to_vec();
    for (c, col) in cols.iter().enumerate() {
        if beta[c] != 0.0 {
            for (r, v) in resid.iter_mut().enumerate() {
                *v -= beta[c] * col[r];
            }
        }
    }
    let rss = resid.iter().map(|v| v * v).sum();
    LinFit { beta, rss, resid }
}

/// Gram matrix of a set of columns and a target, for many nested least-squares fits over
/// subsets of the same columns (each fit then costs O(p³) instead of O(n·p²)).
#[derive(Debug, Clone)]
pub struct Gram {
    /// `XᵀX` of the unit-RMS-scaled columns.
    xtx: Vec<Vec<f64>>,
    /// `Xᵀy` of the scaled columns.
    xty: Vec<f64>,
    /// `yᵀy`.
    yty: f64,
    /// RMS of each column (its scale; 0 for a zero column).
    scale: Vec<f64>,
    /// Number of rows.
    pub n: usize,
}

impl Gram {
    /// Gram matrix of `cols` (all of length `y.len()`) and `y`.
    pub fn new(cols: &[Vec<f64>], y: &[f64]) -> Gram {
        let n = y.len();
        let p = cols.len();
        let scale: Vec<f64> = cols
            .iter()
            .map(|c| {
                let ms = c.iter().map(|v| v * v).sum::<f64>() / n.max(1) as f64;
                if ms > 0.0 && ms.is_finite() {
                    ms.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let scaled: Vec<Vec<f64>> = cols
            .iter()
            .zip(&scale)
            .map(|(c, s)| {
                if *s > 0.0 {
                    c.iter().map(|v| v / s).collect()
                } else {
                    vec![0.0; n]
                }
            })
            .collect();
        let mut xtx = vec![vec![0.0; p]; p];
        for a in 0..p {
            for b in a..p {
                let d: f64 = scaled[a].iter().zip(&scaled[b]).map(|(x, y)| x * y).sum();
                xtx[a][b] = d;
                xtx[b][a] = d;
            }
        }
        let xty = scaled
            .iter()
            .map(|c| c.iter().zip(y).map(|(x, y)| x * y).sum())
            .collect();
        let yty = y.iter().map(|v| v * v).sum();
        Gram {
            xtx,
            xty,
            yty,
            scale,
            n,
        }
    }

    /// Least squares on the columns `subset`: returns (coefficients in the original units,
    /// residual sum of squares).
    pub fn fit(&self, subset: &[usize]) -> (Vec<f64>, f64) {
        let p = subset.len();
        if p == 0 {
            return (vec![], self.yty);
        }
        let ridge = RIDGE * self.n as f64;
        let a = Mat::<f64>::from_fn(p, p, |r, c| {
            self.xtx[subset[r]][subset[c]] + if r == c { ridge } else { 0.0 }
        });
        let b = Mat::<f64>::from_fn(p, 1, |r, _| self.xty[subset[r]]);
        let x = match a.llt(faer::Side::Lower) {
            Ok(llt) => {
                use faer::linalg::solvers::Solve;
                llt.solve(&b)
            }
            Err(_) => a.qr().solve_lstsq(&b),
        };
        let mut fitted = 0.0;
        let mut beta = Vec::with_capacity(p);
        for r in 0..p {
            fitted += x[(r, 0)] * self.xty[subset[r]];
            let s = self.scale[subset[r]];
            beta.push(if s > 0.0 { x[(r, 0)] / s } else { 0.0 });
        }
        (beta, (self.yty - fitted).max(0.0))
    }

    /// `yᵀy`, the residual sum of squares of the empty model.
    pub fn yty(&self) -> f64 {
        self.yty
    }
}
/// The normal equations of columns `Θ` (`N × p`) and targets `Y` (`N × t`), each column
/// scaled to unit norm: built once (one pass over the data), then every least-squares fit
/// on a subset of the columns is a `q × q` solve ([`solve_spd`]). Zero columns are left out
/// of every fit.
#[derive(Debug, Clone)]
pub struct NormalEquations {
    p: usize,
    t: usize,
    /// Normalised Gram matrix `D⁻¹ΘᵀΘD⁻¹`, row-major `p × p` (zero rows for zero columns).
    g: Vec<f64>,
    /// Normalised right-hand sides `D⁻¹Θᵀy`, one per target.
    b: Vec<Vec<f64>>,
    /// `yᵀy` per target.
    yy: Vec<f64>,
    /// Column norms `D` (0 for a zero column).
    d: Vec<f64>,
}

impl NormalEquations {
    /// Build from a library matrix and a target matrix with the same number of rows.
    pub fn new(theta: MatRef<'_, f64>, y: MatRef<'_, f64>) -> NormalEquations {
        assert_eq!(
            theta.nrows(),
            y.nrows(),
            "library and targets differ in length"
        );
        let p = theta.ncols();
        let t = y.ncols();
        let gtt: Mat<f64> = theta.transpose() * theta;
        let gty: Mat<f64> = theta.transpose() * y;
        let yy: Vec<f64> = (0..t).map(|k| y.col(k).squared_norm_l2()).collect();
        Self::from_products(p, t, |i, j| gtt[(i, j)], |i, k| gty[(i, k)], yy)
    }

    /// Build from the products directly: `gtt(i, j) = θ_iᵀθ_j`, `gty(i, k) = θ_iᵀy_k`,
    /// `yy[k] = y_kᵀy_k` (for callers that accumulate them themselves).
    pub fn from_products(
        p: usize,
        t: usize,
        gtt: impl Fn(usize, usize) -> f64,
        gty: impl Fn(usize, usize) -> f64,
        yy: Vec<f64>,
    ) -> NormalEquations {
        let d: Vec<f64> = (0..p)
            .map(|i| {
                let v = gtt(i, i);
                if v.is_finite() && v > 0.0 {
                    v.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let mut g = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                if d[i] > 0.0 && d[j] > 0.0 {
                    g[i * p + j] = gtt(i, j) / (d[i] * d[j]);
                }
            }
        }
        let b = (0..t)
            .map(|k| {
                (0..p)
                    .map(|i| if d[i] > 0.0 { gty(i, k) / d[i] } else { 0.0 })
                    .collect()
            })
            .collect();
        NormalEquations { p, t, g, b, yy, d }
    }

    /// Number of library terms.
    pub fn terms(&self) -> usize {
        self.p
    }

    /// Number of targets.
    pub fn targets(&self) -> usize {
        self.t
    }

    /// Norm of each library column.
    pub fn column_norms(&self) -> &[f64] {
        &self.d
    }

    /// `‖y_k‖`.
    pub fn target_norm(&self, k: usize) -> f64 {
        self.yy[k].max(0.0).sqrt()
    }

    /// Which columns are usable (non-zero).
    pub fn usable(&self) -> Vec<bool> {
        self.d.iter().map(|&d| d > 0.0).collect()
    }

    /// Least squares for target `k` on `support` (unusable columns are ignored).
    /// Returns the normalised coefficients (`‖θ_j ξ_j‖` up to sign; 0 outside the support).
    pub fn solve_normalised(&self, k: usize, support: &[bool]) -> Vec<f64> {
        let idx: Vec<usize> = (0..self.p)
            .filter(|&j| support[j] && self.d[j] > 0.0)
            .collect();
        let mut out = vec![0.0; self.p];
        if idx.is_empty() {
            return out;
        }
        let q = idx.len();
        let a = Mat::<f64>::from_fn(q, q, |r, c| self.g[idx[r] * self.p + idx[c]]);
        let rhs = Mat::<f64>::from_fn(q, 1, |r, _| self.b[k][idx[r]]);
        let sol = solve_spd(a.as_ref(), rhs.as_ref());
        for (r, &j) in idx.iter().enumerate() {
            out[j] = sol[r];
        }
        out
    }

    /// Least squares for target `k` on `support`, coefficients in the library's units.
    pub fn solve(&self, k: usize, support: &[bool]) -> Vec<f64> {
        self.denormalise(&self.solve_normalised(k, support))
    }

    /// Normalised coefficients to the library's units.
    pub fn denormalise(&self, xn: &[f64]) -> Vec<f64> {
        xn.iter()
            .zip(&self.d)
            .map(|(x, d)| if *d > 0.0 { x / d } else { 0.0 })
            .collect()
    }

    /// Squared residual `‖y_k − Θξ‖²` of normalised coefficients, from the normal equations.
    pub fn residual2(&self, k: usize, xn: &[f64]) -> f64 {
        let p = self.p;
        let mut quad = 0.0;
        let mut lin = 0.0;
        for i in 0..p {
            if xn[i] == 0.0 {
                continue;
            }
            lin += xn[i] * self.b[k][i];
            for j in 0..p {
                quad += xn[i] * self.g[i * p + j] * xn[j];
            }
        }
        (self.yy[k] - 2.0 * lin + quad).max(0.0)
    }
}

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

/// Leave-one-out (PRESS) residual sum of squares of the least-squares fit of `y` on `cols`:
/// `Σ (e_r / (1 − h_r))²`, each row's residual as predicted by the fit *without* that row
/// (`h_r` its leverage). Columns are scaled to unit RMS first; all-zero columns and directions
/// below 1e-10 of the largest singular value are dropped.
pub fn leave_one_out_rss(cols: &[&[f64]], y: &[f64]) -> f64 {
    let n = y.len();
    let scaled: Vec<Vec<f64>> = cols
        .iter()
        .filter_map(|c| {
            let ms = c.iter().take(n).map(|v| v * v).sum::<f64>() / n.max(1) as f64;
            (ms > 0.0 && ms.is_finite()).then(|| c.iter().take(n).map(|v| v / ms.sqrt()).collect())
        })
        .collect();
    let p = scaled.len();
    if p == 0 || n <= p {
        return y.iter().map(|v| v * v).sum();
    }
    let a = faer::Mat::<f64>::from_fn(n, p, |i, j| scaled[j][i]);
    let Ok(svd) = a.thin_svd() else {
        return f64::INFINITY;
    };
    let s = svd.S().column_vector();
    let smax = (0..p).map(|k| s[k]).fold(0.0, f64::max);
    let u = svd.U();
    let keep: Vec<usize> = (0..p).filter(|&k| s[k] > 1e-10 * smax).collect();
    // Fitted values and leverages from the orthonormal basis U of the column space.
    let uy: Vec<f64> = keep
        .iter()
        .map(|&k| (0..n).map(|i| u[(i, k)] * y[i]).sum())
        .collect();
    (0..n)
        .map(|i| {
            let (mut fit, mut lev) = (0.0, 0.0);
            for (&k, c) in keep.iter().zip(&uy) {
                fit += u[(i, k)] * c;
                lev += u[(i, k)] * u[(i, k)];
            }
            let e = if lev < MAX_LEVERAGE {
                (y[i] - fit) / (1.0 - lev)
            } else {
                // A row the fit can follow on its own: refit without it.
                let others: Vec<usize> = (0..n).filter(|&r| r != i).collect();
                let sub: Vec<Vec<f64>> = cols
                    .iter()
                    .map(|c| others.iter().map(|&r| c[r]).collect())
                    .collect();
                let refs: Vec<&[f64]> = sub.iter().map(|c| c.as_slice()).collect();
                let ys: Vec<f64> = others.iter().map(|&r| y[r]).collect();
                let f = lstsq(&refs, &ys);
                y[i] - cols.iter().zip(&f.beta).map(|(c, b)| b * c[i]).sum::<f64>()
            };
            e * e
        })
        .sum()
}

/// Leverage above which [`leave_one_out_rss`] refits without the row instead of dividing by
/// `1 − h` (which loses its digits as `h → 1`).
const MAX_LEVERAGE: f64 = 0.99;

/// Solve `A x = b` (one right-hand side) by faer's Cholesky alone, for an `A` that is
/// positive definite by construction (a damped normal matrix): `None` when the factorisation
/// fails or the solution is not finite, so the caller can react (damp more) instead of
/// taking a fallback's answer.
pub fn solve_pd(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Option<Vec<f64>> {
    use faer::linalg::solvers::Solve;
    let x = a.llt(faer::Side::Lower).ok()?.solve(b);
    let v: Vec<f64> = (0..a.nrows()).map(|i| x[(i, 0)]).collect();
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// Solve `A x = b` (one right-hand side) for a symmetric positive semi-definite `A` with
/// unit-ish diagonal, such as the normal equations of unit-norm columns: faer's Cholesky, or
/// when it fails or a pivot is below 1e-12 of the largest diagonal entry, the minimum-norm
/// solution from the self-adjoint eigen-decomposition (eigenvalues below 1e-12 of the
/// largest dropped). Never panics; all zeros if nothing finite comes out.
pub fn solve_spd(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Vec<f64> {
    use faer::linalg::solvers::Solve;
    use faer::Side;
    let q = a.nrows();
    let amax = (0..q).map(|i| a[(i, i)].abs()).fold(0.0, f64::max);
    if let Ok(llt) = a.llt(Side::Lower) {
        let l = llt.L();
        let min_piv = (0..q)
            .map(|i| l[(i, i)] * l[(i, i)])
            .fold(f64::INFINITY, f64::min);
        if min_piv > 1e-12 * amax {
            let x = llt.solve(b);
            let v: Vec<f64> = (0..q).map(|i| x[(i, 0)]).collect();
            if v.iter().all(|x| x.is_finite()) {
                return v;
            }
        }
    }
    // Pseudo-inverse: x = Σ_{λ_i > cut} u_i (u_iᵀ b) / λ_i.
    let mut x = vec![0.0; q];
    let Ok(evd) = a.self_adjoint_eigen(Side::Lower) else {
        return x;
    };
    let s = evd.S().column_vector();
    let u = evd.U();
    let lmax = (0..q).map(|i| s[i].abs()).fold(0.0, f64::max);
    let cut = 1e-12 * lmax.max(f64::MIN_POSITIVE);
    for c in 0..q {
        if s[c] > cut {
            let proj: f64 = (0..q).map(|r| u[(r, c)] * b[(r, 0)]).sum::<f64>() / s[c];
            for r in 0..q {
                x[r] += u[(r, c)] * proj;
            }
        }
    }
    if x.iter().all(|v| v.is_finite()) {
        x
    } else {
        vec![0.0; q]
    }
}

/// Diagonal of `(JᵀJ)⁻¹` from the normal matrix `jtj` (a nonlinear fit's parameter
/// covariance over σ²), by faer's thin SVD of the matrix scaled to unit diagonal, so that the
/// rank test is scale-free: ∞ for a parameter that moves along a direction the cost is flat
/// in, or whose column is zero (below 1e-300 of its `scale`).
pub fn normal_inverse_diag(jtj: &[Vec<f64>], scale: &[f64]) -> Vec<f64> {
    let n = jtj.len();
    // Scale to unit diagonal so the rank test is scale-free.
    let d: Vec<f64> = (0..n).map(|j| jtj[j][j].sqrt()).collect();
    let mut out = vec![f64::INFINITY; n];
    let live: Vec<usize> = (0..n)
        .filter(|&j| d[j] > 1e-300 * scale[j].abs().max(1.0))
        .collect();
    if live.is_empty() {
        return out;
    }
    let k = live.len();
    let a = faer::Mat::<f64>::from_fn(k, k, |p, q| {
        jtj[live[p]][live[q]] / (d[live[p]] * d[live[q]])
    });
    let Ok(svd) = a.thin_svd() else {
        return out;
    };
    let s = svd.S().column_vector();
    let v = svd.V();
    let smax = (0..k).map(|i| s[i]).fold(0.0, f64::max);
    for (p, &j) in live.iter().enumerate() {
        let mut acc = 0.0;
        let mut flat = false;
        for c in 0..k {
            if s[c] <= 1e-12 * smax {
                if v[(p, c)].abs() > 1e-6 {
                    flat = true;
                }
                continue;
            }
            acc += v[(p, c)].powi(2) / s[c];
        }
        out[j] = if flat {
            f64::INFINITY
        } else {
            acc / (d[j] * d[j])
        };
    }
    out
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;
    use crate::numerics::statistics::white_noise as noise;

    #[test]
    fn lstsq_recovers_coefficients() {
        let n = 500;
        let x1: Vec<f64> = (0..n).map(|k| (k as f64 * 0.1).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|k| k as f64 / n as f64).collect();
        let e = noise(n, 1);
        let y: Vec<f64> = (0..n)
            .map(|k| 2.0 * x1[k] - 0.5 * x2[k] + 1e-3 * e[k])
            .collect();
        let fit = lstsq(&[&x1, &x2], &y);
        // 1e-3: about ten standard errors (noise 1e-3 over 500 samples: σ/√Σx² ≈ 1e-4).
        assert!((fit.beta[0] - 2.0).abs() < 1e-3);
        assert!((fit.beta[1] + 0.5).abs() < 1e-3);
        // A duplicated column stays finite.
        let fit2 = lstsq(&[&x1, &x1, &x2], &y);
        assert!(fit2.beta.iter().all(|b| b.is_finite()));
        assert!(
            fit2.rss <= fit.rss * 1.01 + 1e-12,
            "{} vs {}",
            fit2.rss,
            fit.rss
        );
    }

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

    /// A regressor that is non-zero in one row only fits that row exactly: in-sample it
    /// explains the row's whole error, left out it predicts nothing. A harmonic spread over
    /// every row keeps its gain.
    #[test]
    fn leave_one_out_discounts_a_fit_carried_by_one_row() {
        let n = 200;
        let noise: Vec<f64> = (0..n)
            .map(|k| 0.01 * (((k * 7919) % 101) as f64 / 50.0 - 1.0))
            .collect();
        let spread: Vec<f64> = (0..n).map(|k| (0.3 * k as f64).sin()).collect();
        let mut y: Vec<f64> = noise
            .iter()
            .zip(&spread)
            .map(|(e, s)| e + 0.01 * s)
            .collect();
        y[50] += 0.2; // one outlier row
        let spike: Vec<f64> = (0..n).map(|k| if k == 50 { 1.0 } else { 0.0 }).collect();
        let ones = vec![1.0; n];
        let rss = |cols: &[&[f64]]| {
            let f = lstsq(cols, &y);
            f.rss
        };
        let (r0, l0) = (rss(&[&ones]), leave_one_out_rss(&[&ones], &y));
        let (rs, ls) = (
            rss(&[&ones, &spike]),
            leave_one_out_rss(&[&ones, &spike], &y),
        );
        let (rh, lh) = (
            rss(&[&ones, &spread]),
            leave_one_out_rss(&[&ones, &spread], &y),
        );
        // In-sample, the spike wins by far; left out, only the spread harmonic gains.
        assert!(r0 - rs > 3.0 * (r0 - rh), "{r0} {rs} {rh}");
        assert!(
            l0 - ls < 0.05 * (l0 - l0.min(lh)).max(1e-12),
            "{l0} {ls} {lh}"
        );
        assert!(lh < l0, "{l0} {lh}");
        // With no column left (all zero), the sum of squares of y.
        let zero = vec![0.0; n];
        let yy: f64 = y.iter().map(|v| v * v).sum();
        assert!((leave_one_out_rss(&[&zero], &y) - yy).abs() < 1e-12 * yy);
    }
    /// A well-conditioned system is solved to rounding; a singular one (two equal columns)
    /// gets the minimum-norm solution, which splits the weight equally between them.
    #[test]
    fn solve_spd_is_exact_or_minimum_norm() {
        let a = Mat::<f64>::from_fn(3, 3, |r, c| if r == c { 2.0 } else { 0.5 });
        let x_true = [1.0, -2.0, 0.5];
        let b = Mat::<f64>::from_fn(3, 1, |r, _| (0..3).map(|c| a[(r, c)] * x_true[c]).sum());
        let x = solve_spd(a.as_ref(), b.as_ref());
        for (got, want) in x.iter().zip(x_true) {
            // A 3×3 solve with condition number 2: rounding only.
            assert!((got - want).abs() < 1e-12, "{x:?}");
        }
        // Columns 0 and 1 identical (1e-9: the eigen path rounds at 1e-15 relative): A = [[1,1,0],[1,1,0],[0,0,1]], b from x = (2, 0, 3).
        let a = Mat::<f64>::from_fn(
            3,
            3,
            |r, c| if r < 2 && c < 2 || r == c { 1.0 } else { 0.0 },
        );
        let b = Mat::<f64>::from_fn(3, 1, |r, _| [2.0, 2.0, 3.0][r]);
        let x = solve_spd(a.as_ref(), b.as_ref());
        assert!(
            (x[0] - 1.0).abs() < 1e-9 && (x[1] - 1.0).abs() < 1e-9,
            "{x:?}"
        );
        assert!((x[2] - 3.0).abs() < 1e-9, "{x:?}");
        // A zero matrix: no direction to solve along, all zeros.
        let z = Mat::<f64>::zeros(2, 2);
        let b = Mat::<f64>::from_fn(2, 1, |_, _| 1.0);
        assert_eq!(solve_spd(z.as_ref(), b.as_ref()), vec![0.0, 0.0]);
    }

    #[test]
    fn solve_pd_solves_a_definite_system_and_refuses_a_singular_one() {
        let a = Mat::<f64>::from_fn(3, 3, |r, c| if r == c { 2.0 } else { 0.5 });
        let x_true = [1.0, -2.0, 0.5];
        let b = Mat::<f64>::from_fn(3, 1, |r, _| (0..3).map(|c| a[(r, c)] * x_true[c]).sum());
        let x = solve_pd(a.as_ref(), b.as_ref()).expect("positive definite");
        for (got, want) in x.iter().zip(x_true) {
            // A 3×3 solve with condition number 2: rounding only.
            assert!((got - want).abs() < 1e-12, "{x:?}");
        }
        // Indefinite (eigenvalues 3 and −1): no Cholesky factor, so no answer.
        let a = Mat::<f64>::from_fn(2, 2, |r, c| if r == c { 1.0 } else { 2.0 });
        let b = Mat::<f64>::from_fn(2, 1, |_, _| 1.0);
        assert_eq!(solve_pd(a.as_ref(), b.as_ref()), None);
    }

    #[test]
    fn normal_inverse_diag_is_the_inverse_or_infinite_where_flat() {
        // [[4, 2], [2, 3]]⁻¹ = [[3, −2], [−2, 4]] / 8: diagonal 3/8 and 1/2 (rounding only).
        let jtj = vec![vec![4.0, 2.0], vec![2.0, 3.0]];
        let d = normal_inverse_diag(&jtj, &[1.0, 1.0]);
        assert!(
            (d[0] - 0.375).abs() < 1e-12 && (d[1] - 0.5).abs() < 1e-12,
            "{d:?}"
        );
        // Two identical columns: neither is determined on its own; a zero column neither.
        let jtj = vec![
            vec![1.0, 1.0, 0.0, 0.0],
            vec![1.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 2.0, 0.0],
            vec![0.0, 0.0, 0.0, 0.0],
        ];
        let d = normal_inverse_diag(&jtj, &[1.0; 4]);
        assert!(
            d[0].is_infinite() && d[1].is_infinite() && d[3].is_infinite(),
            "{d:?}"
        );
        assert!((d[2] - 0.5).abs() < 1e-12, "{d:?}");
    }
}
