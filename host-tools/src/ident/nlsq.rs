//! Bounded nonlinear least squares: `min ½‖r(x)‖²` subject to `lo ≤ x ≤ hi`.
//!
//! Levenberg–Marquardt (Marquardt's diagonal scaling) with bounds by projection and an
//! active set: a variable sitting on a bound whose gradient pushes it outward is held there
//! for the step. The Jacobian is the caller's ([`solve_with_jacobian`]) or numeric (forward
//! differences, step relative to the variable's scale); the damped normal equations are
//! solved by Cholesky ([`solve_pd`]). The paper
//! used MATLAB's trust-region reflective method; LM with projected bounds reaches the same
//! minima on these small, well-scaled problems.
//!
//! A residual evaluation may fail (a trial model that diverges): the step is then rejected
//! like one that raises the cost.
//!
//! [`solve_parallel`] evaluates the Jacobian's columns on rayon's threads: each column is
//! one more residual evaluation (a free run of the model), and they are independent.
use crate::numerics::least_squares::{normal_inverse_diag, solve_pd};
use anyhow::{bail, Result};
use rayon::prelude::*;

/// Options of [`solve`].
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Iteration limit (one Jacobian per iteration).
    pub max_iter: usize,
    /// Stop when the relative cost decrease of an accepted step is below this.
    pub ftol: f64,
    /// Stop when the scaled step is below this.
    pub xtol: f64,
    /// Also stop when an accepted step lowers `‖r‖²` by less than the residual variance
    /// `σ̂² = ‖r‖²/(m − n)`: fitting one more parameter to pure noise lowers `‖r‖²` by σ² on
    /// average, so a smaller decrease is not a significant improvement of the model, only
    /// a creep along directions the data does not determine. (Residuals of a time series
    /// are correlated, so the true variance per independent sample is larger: the rule is on
    /// the cautious side.)
    pub noise_stop: bool,
    /// The damping λ follows the gain ratio ρ of each step (actual over predicted decrease
    /// of the cost), after Nielsen (Madsen, Nielsen & Tingleff, *Methods for non-linear
    /// least squares problems*, 2004, eq. 3.16; Ceres Solver's Levenberg–Marquardt strategy):
    /// an accepted step multiplies λ by `max(⅓, 1 − (2ρ − 1)³)`, so a step the linear model
    /// predicted well lowers it and a poor one keeps or raises it; a rejected step multiplies
    /// λ by ν, which doubles with every rejection in a row (2, 4, 8, ...). Otherwise λ is
    /// divided by 3 after an accepted step and multiplied by 4 after a rejected one
    /// (Marquardt's fixed factors): in a narrow valley those alternate, about one rejected
    /// trial for every accepted step.
    pub gain_ratio_damping: bool,
}

impl Default for Options {
    fn default() -> Self {
        // Defaults of MINPACK's lmdif order of magnitude, loosened: simulation residuals carry
        // quantisation noise, so cost changes below 1e-6 relative are not meaningful.
        Options {
            max_iter: 30,
            ftol: 1e-6,
            xtol: 1e-8,
            noise_stop: false,
            gain_ratio_damping: false,
        }
    }
}

/// The result of [`solve`].
#[derive(Debug, Clone)]
pub struct Solution {
    pub x: Vec<f64>,
    /// ½‖r‖² at x.
    pub cost: f64,
    /// Standard errors σ²·(JᵀJ)⁻¹ with σ² = ‖r‖²/(m − n); ∞ where the cost is flat in that
    /// direction (the parameter is not identifiable from this data). Residuals of a time
    /// series are correlated, so these are lower bounds.
    pub std_err: Vec<f64>,
    pub iterations: usize,
    pub evaluations: usize,
}

fn cost_of(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|v| v * v).sum::<f64>()
}

/// Residual evaluations as the solver needs them: one point, and the Jacobian at a point.
trait Residual {
    fn eval(&mut self, x: &[f64]) -> Result<Vec<f64>>;
    /// The residuals at a trial point, or `None` when their `½‖r‖²` is known to exceed
    /// `cost` (the point would be rejected) before they are all computed.
    fn eval_below(&mut self, x: &[f64], _cost: f64) -> Result<Option<Vec<f64>>> {
        self.eval(x).map(Some)
    }
    /// The Jacobian at x (residuals r there) into `jac` (column j = ∂r/∂x_j); returns the
    /// number of evaluations it took.
    fn jacobian(
        &mut self,
        x: &[f64],
        r: &[f64],
        hi: &[f64],
        scale: &[f64],
        jac: &mut [Vec<f64>],
    ) -> usize;
}

struct Serial<'a>(&'a mut dyn FnMut(&[f64]) -> Result<Vec<f64>>);

impl Residual for Serial<'_> {
    fn eval(&mut self, x: &[f64]) -> Result<Vec<f64>> {
        (self.0)(x)
    }
    fn jacobian(
        &mut self,
        x: &[f64],
        r: &[f64],
        hi: &[f64],
        scale: &[f64],
        jac: &mut [Vec<f64>],
    ) -> usize {
        let f = &mut self.0;
        forward_differences(x, r, hi, scale, jac, |xs| xs.iter().map(|x| f(x)).collect())
    }
}

struct Parallel<'a>(&'a (dyn Fn(&[f64]) -> Result<Vec<f64>> + Sync));

impl Residual for Parallel<'_> {
    fn eval(&mut self, x: &[f64]) -> Result<Vec<f64>> {
        (self.0)(x)
    }
    fn jacobian(
        &mut self,
        x: &[f64],
        r: &[f64],
        hi: &[f64],
        scale: &[f64],
        jac: &mut [Vec<f64>],
    ) -> usize {
        let f = self.0;
        forward_differences(x, r, hi, scale, jac, |xs| {
            xs.par_iter().map(|x| f(x)).collect()
        })
    }
}

/// A residual function: residuals at a point.
pub type ResidualFn<'a> = dyn Fn(&[f64]) -> Result<Vec<f64>> + Sync + 'a;
/// A Jacobian function: the columns `∂r/∂x_j` at a point.
pub type JacobianFn<'a> = dyn Fn(&[f64]) -> Result<Vec<Vec<f64>>> + Sync + 'a;

/// A residual function that may give up: the residuals at a point, or `None` once their
/// `½‖r‖²` is known to exceed the given cost.
pub type BoundedResidualFn<'a> = dyn Fn(&[f64], f64) -> Result<Option<Vec<f64>>> + Sync + 'a;

/// A residual function with its own (analytic) Jacobian.
pub struct WithJacobian<'a> {
    pub f: &'a ResidualFn<'a>,
    pub jac: &'a JacobianFn<'a>,
    /// For trial points: `f` that may stop early when the point cannot be accepted (its
    /// cost above the current one); `None`: `f`.
    pub f_below: Option<&'a BoundedResidualFn<'a>>,
}

impl Residual for WithJacobian<'_> {
    fn eval(&mut self, x: &[f64]) -> Result<Vec<f64>> {
        (self.f)(x)
    }
    fn eval_below(&mut self, x: &[f64], cost: f64) -> Result<Option<Vec<f64>>> {
        match self.f_below {
            Some(f) => f(x, cost),
            None => (self.f)(x).map(Some),
        }
    }
    fn jacobian(
        &mut self,
        x: &[f64],
        _r: &[f64],
        _hi: &[f64],
        _scale: &[f64],
        jac: &mut [Vec<f64>],
    ) -> usize {
        match (self.jac)(x) {
            Ok(cols) if cols.len() == jac.len() => {
                for (dst, src) in jac.iter_mut().zip(cols) {
                    if src.len() == dst.len() {
                        *dst = src;
                    } else {
                        dst.iter_mut().for_each(|v| *v = 0.0);
                    }
                }
            }
            _ => jac
                .iter_mut()
                .for_each(|c| c.iter_mut().for_each(|v| *v = 0.0)),
        }
        1
    }
}

/// Minimise `½‖f(x)‖²` within bounds from `x0`. `scale[j]` is the typical magnitude of x_j
/// (the finite-difference step is 1e-6·scale). `progress(iteration, cost)` is called after
/// each iteration.
pub fn solve(
    f: &mut dyn FnMut(&[f64]) -> Result<Vec<f64>>,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    scale: &[f64],
    opts: Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Solution> {
    solve_with(&mut Serial(f), x0, lo, hi, scale, opts, progress)
}

/// [`solve`] with the Jacobian's columns evaluated on rayon's threads (`f` is called
/// concurrently). The iterates are the same as [`solve`]'s.
pub fn solve_parallel(
    f: &(dyn Fn(&[f64]) -> Result<Vec<f64>> + Sync),
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    scale: &[f64],
    opts: Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Solution> {
    solve_with(&mut Parallel(f), x0, lo, hi, scale, opts, progress)
}

/// [`solve`] with the Jacobian given: `problem.jac(x)` returns its columns `∂f/∂x_j` (a
/// failure gives a zero Jacobian, which ends the iterations).
pub fn solve_with_jacobian(
    mut problem: WithJacobian,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    scale: &[f64],
    opts: Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Solution> {
    solve_with(&mut problem, x0, lo, hi, scale, opts, progress)
}

/// Forward-difference Jacobian at x (residuals r there) into `jac` (column j = ∂r/∂x_j),
/// the shifted points evaluated by `eval_all`; a column whose evaluation fails is zero.
/// Returns the number of evaluations.
fn forward_differences(
    x: &[f64],
    r: &[f64],
    hi: &[f64],
    scale: &[f64],
    jac: &mut [Vec<f64>],
    eval_all: impl FnOnce(&[Vec<f64>]) -> Vec<Result<Vec<f64>>>,
) -> usize {
    let n = x.len();
    let steps: Vec<f64> = (0..n)
        .map(|j| {
            let h = 1e-6 * scale[j].abs().max(1e-12);
            if x[j] + h > hi[j] {
                -h
            } else {
                h
            }
        })
        .collect();
    let points: Vec<Vec<f64>> = (0..n)
        .map(|j| {
            let mut xp = x.to_vec();
            xp[j] += steps[j];
            xp
        })
        .collect();
    for (j, rp) in eval_all(&points).into_iter().enumerate() {
        match rp {
            Ok(rp) => {
                for (i, v) in jac[j].iter_mut().enumerate() {
                    *v = (rp[i] - r[i]) / steps[j];
                }
            }
            Err(_) => jac[j].iter_mut().for_each(|v| *v = 0.0),
        }
    }
    n
}

fn solve_with(
    f: &mut dyn Residual,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    scale: &[f64],
    opts: Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Solution> {
    let n = x0.len();
    let mut x: Vec<f64> = (0..n).map(|j| x0[j].clamp(lo[j], hi[j])).collect();
    let mut r = f.eval(&x)?;
    let m = r.len();
    if m < n {
        bail!("nonlinear least squares: {m} residuals for {n} parameters");
    }
    let mut evals = 1;
    let mut cost = cost_of(&r);
    let mut lambda = 1e-3;
    // Nielsen's factor for the next rejected step (gain-ratio damping).
    let mut nu = 2.0;
    let mut jac = vec![vec![0.0; m]; n];
    let mut iterations = 0;
    // Whether `jac` is the Jacobian at the current x.
    let mut jac_at_x = false;
    for it in 0..opts.max_iter {
        iterations = it + 1;
        evals += f.jacobian(&x, &r, hi, scale, &mut jac);
        jac_at_x = true;
        let g: Vec<f64> = (0..n)
            .map(|j| (0..m).map(|i| jac[j][i] * r[i]).sum())
            .collect();
        let jtj = normal_matrix(&jac);
        // Active set: on a bound and the descent direction (−g) points outward.
        let active: Vec<bool> = (0..n)
            .map(|j| (x[j] <= lo[j] && g[j] > 0.0) || (x[j] >= hi[j] && g[j] < 0.0))
            .collect();
        let mut accepted = false;
        let mut small_step = false;
        for _ in 0..12 {
            let Some(step) = damped_step(&jtj, &g, &active, lambda) else {
                lambda *= 10.0;
                continue;
            };
            let xn: Vec<f64> = (0..n)
                .map(|j| (x[j] + step[j]).clamp(lo[j], hi[j]))
                .collect();
            let moved: f64 = (0..n)
                .map(|j| ((xn[j] - x[j]) / scale[j].abs().max(1e-300)).powi(2))
                .sum::<f64>()
                .sqrt();
            if moved < opts.xtol {
                small_step = true;
                break;
            }
            evals += 1;
            // A trial that cannot lower the cost may stop early: it is rejected either way.
            if let Ok(Some(rn)) = f.eval_below(&xn, cost) {
                let cn = cost_of(&rn);
                if cn.is_finite() && cn < cost {
                    let rel = (cost - cn) / cost.max(1e-300);
                    // Half the decrease of ‖r‖² against half its variance (cost = ½‖r‖²).
                    let insignificant = cost - cn < cn / (m - n).max(1) as f64;
                    lambda = if opts.gain_ratio_damping {
                        let s: Vec<f64> = (0..n).map(|j| xn[j] - x[j]).collect();
                        // A decrease the linear model did not predict counts as a good
                        // step (ρ = ∞).
                        let pred = predicted_decrease(&jtj, &g, &s);
                        let rho = if pred > 0.0 {
                            (cost - cn) / pred
                        } else {
                            f64::INFINITY
                        };
                        nu = 2.0;
                        lambda * gain_ratio_factor(rho)
                    } else {
                        lambda / 3.0
                    }
                    .max(1e-12);
                    x = xn;
                    r = rn;
                    cost = cn;
                    jac_at_x = false;
                    accepted = true;
                    small_step = rel < opts.ftol || (opts.noise_stop && insignificant);
                    break;
                }
            }
            if opts.gain_ratio_damping {
                lambda *= nu;
                nu *= 2.0;
            } else {
                lambda *= 4.0;
            }
        }
        tracing::trace!(
            "LM iteration {iterations}: cost {cost:.6e}, λ {lambda:.1e}, {evals} evaluations"
        );
        progress(iterations, cost);
        if !accepted || small_step {
            break;
        }
    }
    // Standard errors at the optimum (the Jacobian at the final x, unless the last
    // iteration ended without moving).
    if !jac_at_x {
        evals += f.jacobian(&x, &r, hi, scale, &mut jac);
    }
    let sigma2 = 2.0 * cost / ((m - n).max(1) as f64);
    let std_err = normal_inverse_diag(&normal_matrix(&jac), scale)
        .into_iter()
        .map(|v| (sigma2 * v).sqrt())
        .collect();
    Ok(Solution {
        x,
        cost,
        std_err,
        iterations,
        evaluations: evals,
    })
}

/// Nielsen's factor on λ after an accepted step of gain ratio `rho`:
/// `max(⅓, 1 − (2ρ − 1)³)`; ⅓ for a step the linear model predicted (ρ ≥ 1), 1 at ρ = ½, up
/// to 2 for a step that lowered the cost far less than predicted.
fn gain_ratio_factor(rho: f64) -> f64 {
    (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0)
}

/// The decrease of the cost `½‖r‖²` the linearised residual `r + J·s` predicts for the step
/// `s` (gradient `g = Jᵀr`, normal matrix `JᵀJ`): `−gᵀs − ½·sᵀJᵀJs`.
fn predicted_decrease(jtj: &[Vec<f64>], g: &[f64], s: &[f64]) -> f64 {
    let n = s.len();
    let gs: f64 = (0..n).map(|j| g[j] * s[j]).sum();
    let quad: f64 = (0..n)
        .map(|p| s[p] * (0..n).map(|q| jtj[p][q] * s[q]).sum::<f64>())
        .sum();
    -gs - 0.5 * quad
}

fn normal_matrix(jac: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = jac.len();
    let mut a = vec![vec![0.0; n]; n];
    for p in 0..n {
        for q in p..n {
            let v: f64 = jac[p].iter().zip(&jac[q]).map(|(a, b)| a * b).sum();
            a[p][q] = v;
            a[q][p] = v;
        }
    }
    a
}

/// Solve `(JᵀJ + λ·diag(JᵀJ))·δ = −g` over the inactive variables ([`solve_pd`]).
fn damped_step(jtj: &[Vec<f64>], g: &[f64], active: &[bool], lambda: f64) -> Option<Vec<f64>> {
    let idx: Vec<usize> = (0..g.len()).filter(|&j| !active[j]).collect();
    let k = idx.len();
    let mut step = vec![0.0; g.len()];
    if k == 0 {
        return Some(step);
    }
    // A variable the cost does not depend on (zero column) gets a floor on its damping, so
    // the system stays positive definite and its step is zero.
    let dmax = idx.iter().map(|&j| jtj[j][j]).fold(0.0, f64::max);
    let floor = (1e-12 * dmax).max(1e-300);
    let a = faer::Mat::<f64>::from_fn(k, k, |p, q| {
        let v = jtj[idx[p]][idx[q]];
        if p == q {
            let d = jtj[idx[p]][idx[p]].max(floor);
            v.max(floor) + lambda * d
        } else {
            v
        }
    });
    let b = faer::Mat::<f64>::from_fn(k, 1, |p, _| -g[idx[p]]);
    let sol = solve_pd(a.as_ref(), b.as_ref())?;
    for (&j, v) in idx.iter().zip(sol) {
        step[j] = v;
    }
    Some(step)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_an_exponential_with_a_bound_and_flags_a_flat_direction() {
        let t: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.7 * t).exp()).collect();
        // Third parameter does nothing: flat.
        let mut f = |x: &[f64]| -> Result<Vec<f64>> {
            Ok(t.iter()
                .zip(&y)
                .map(|(t, y)| x[0] * (-x[1] * t).exp() - y)
                .collect())
        };
        let sol = solve(
            &mut f,
            &[1.0, 0.1, 5.0],
            &[0.0, 0.0, 0.0],
            &[10.0, 10.0, 10.0],
            &[1.0, 1.0, 1.0],
            Options::default(),
            &mut |_, _| {},
        )
        .unwrap();
        // Noiseless data: the minimum is the truth, and on a zero-residual problem the
        // iterates converge quadratically, so the default stop (cost change 1e-6 relative)
        // ends far inside 1e-5.
        assert!(
            (sol.x[0] - 2.0).abs() < 1e-5 && (sol.x[1] - 0.7).abs() < 1e-5,
            "{:?}",
            sol.x
        );
        assert!(sol.std_err[2].is_infinite());
        // With an upper bound below the optimum, the answer sits on it.
        let sol = solve(
            &mut f,
            &[1.0, 0.1, 5.0],
            &[0.0, 0.0, 0.0],
            &[1.5, 10.0, 10.0],
            &[1.0, 1.0, 1.0],
            Options::default(),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(sol.x[0], 1.5);
        // The parallel Jacobian gives the same iterates.
        let g = |x: &[f64]| -> Result<Vec<f64>> {
            Ok(t.iter()
                .zip(&y)
                .map(|(t, y)| x[0] * (-x[1] * t).exp() - y)
                .collect())
        };
        let par = solve_parallel(
            &g,
            &[1.0, 0.1, 5.0],
            &[0.0, 0.0, 0.0],
            &[1.5, 10.0, 10.0],
            &[1.0, 1.0, 1.0],
            Options::default(),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(par.x, sol.x);
        assert_eq!(par.iterations, sol.iterations);
    }

    /// `n` samples every 0.1 s of y = 2·exp(−0.7·t) plus a deterministic ripple of 0.01, so
    /// that the cost at the minimum is not 0.
    fn rippled_decay(n: usize) -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let y = t
            .iter()
            .enumerate()
            .map(|(k, t)| 2.0 * (-0.7 * t).exp() + 0.01 * (k as f64 * 1.7).sin())
            .collect();
        (t, y)
    }

    /// Residuals of the model a·exp(−b·t), x = [a, b].
    fn decay_residuals(t: &[f64], y: &[f64], x: &[f64]) -> Vec<f64> {
        t.iter()
            .zip(y)
            .map(|(t, y)| x[0] * (-x[1] * t).exp() - y)
            .collect()
    }

    /// Jacobian columns of [`decay_residuals`]: ∂/∂a, ∂/∂b.
    fn decay_columns(t: &[f64], x: &[f64]) -> Vec<Vec<f64>> {
        let da = t.iter().map(|t| (-x[1] * t).exp()).collect();
        let db = t.iter().map(|t| -x[0] * t * (-x[1] * t).exp()).collect();
        vec![da, db]
    }

    #[test]
    fn standard_errors_use_the_jacobian_at_the_solution() {
        // Started where the first steps are rejected.
        let (t, y) = rippled_decay(60);
        let f = |x: &[f64]| Ok(decay_residuals(&t, &y, x));
        let columns = |x: &[f64]| decay_columns(&t, x);
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let jac = |x: &[f64]| -> Result<Vec<Vec<f64>>> {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Ok(columns(x))
        };
        // Ending on an accepted step (the cost tolerance) and on steps that no longer
        // lower the cost (no tolerance): the Jacobian at the solution is computed after
        // the iterations in the first case, kept from the last iteration in the second.
        let to_the_end = Options {
            ftol: 0.0,
            xtol: 0.0,
            max_iter: 100,
            ..Options::default()
        };
        let cases = [
            ([1.0, 0.1], Options::default(), 1),
            ([50.0, 9.0], Options::default(), 1),
            ([1.0, 0.1], to_the_end, 0),
        ];
        for (x0, opts, after) in cases {
            calls.store(0, std::sync::atomic::Ordering::Relaxed);
            let problem = WithJacobian {
                f: &f,
                jac: &jac,
                f_below: None,
            };
            let (lo, hi, scale) = ([0.0; 2], [100.0; 2], [1.0; 2]);
            let sol =
                solve_with_jacobian(problem, &x0, &lo, &hi, &scale, opts, &mut |_, _| {}).unwrap();
            // The ripple (0.01, half a percent of the amplitude) moves the least-squares
            // rate by much less than 1e-2.
            assert!((sol.x[1] - 0.7).abs() < 1e-2, "{:?}", sol.x);
            let n = calls.load(std::sync::atomic::Ordering::Relaxed);
            assert_eq!(n, sol.iterations + after, "Jacobians");
            let sigma2 = 2.0 * sol.cost / (t.len() - 2) as f64;
            let expected: Vec<f64> = normal_inverse_diag(&normal_matrix(&columns(&sol.x)), &scale)
                .into_iter()
                .map(|v| (sigma2 * v).sqrt())
                .collect();
            assert_eq!(sol.std_err, expected);
        }
    }

    #[test]
    fn trials_given_up_above_the_cost_keep_the_iterates() {
        // An exponential from a start whose first trial steps raise the cost; the bounded
        // evaluation gives up (None) whenever the trial costs more than the current point.
        let (t, y) = rippled_decay(80);
        let f = |x: &[f64]| Ok(decay_residuals(&t, &y, x));
        let jac = |x: &[f64]| Ok(decay_columns(&t, x));
        let given_up = std::sync::atomic::AtomicUsize::new(0);
        let f_below = |x: &[f64], cost: f64| -> Result<Option<Vec<f64>>> {
            let r = f(x)?;
            if cost_of(&r) > cost {
                given_up.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                return Ok(None);
            }
            Ok(Some(r))
        };
        let (x0, lo, hi, scale) = ([50.0, 9.0], [0.0; 2], [100.0; 2], [1.0; 2]);
        let run = |f_below: Option<&BoundedResidualFn>| {
            let problem = WithJacobian {
                f: &f,
                jac: &jac,
                f_below,
            };
            let opts = Options::default();
            solve_with_jacobian(problem, &x0, &lo, &hi, &scale, opts, &mut |_, _| {}).unwrap()
        };
        let (plain, bounded) = (run(None), run(Some(&f_below)));
        assert!(given_up.load(std::sync::atomic::Ordering::Relaxed) > 0);
        assert_eq!(plain.x, bounded.x);
        assert_eq!(plain.cost, bounded.cost);
        assert_eq!(plain.std_err, bounded.std_err);
        assert_eq!(
            (plain.iterations, plain.evaluations),
            (bounded.iterations, bounded.evaluations)
        );
    }

    /// Rosenbrock's valley as least squares, `r = (10·(b − a²), 1 − a)`, from the classic
    /// start (−1.2, 1), and the rippled exponential from a start whose first steps are
    /// rejected: both damping rules reach the same minimum. Nielsen's factor lowers λ by 3
    /// after a step the linear model predicted, keeps it at ρ = ½ and doubles it as ρ → 0.
    #[test]
    fn gain_ratio_damping_reaches_the_same_minimum() {
        assert_eq!(gain_ratio_factor(1.0), 1.0 / 3.0);
        assert_eq!(gain_ratio_factor(f64::INFINITY), 1.0 / 3.0);
        assert_eq!(gain_ratio_factor(0.5), 1.0);
        assert_eq!(gain_ratio_factor(0.0), 2.0);
        assert!(gain_ratio_factor(0.25) > 1.0 && gain_ratio_factor(0.75) < 1.0);
        let rosenbrock =
            |x: &[f64]| -> Result<Vec<f64>> { Ok(vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]) };
        let rosenbrock_jac = |x: &[f64]| -> Result<Vec<Vec<f64>>> {
            Ok(vec![vec![-20.0 * x[0], -1.0], vec![10.0, 0.0]])
        };
        let (t, y) = rippled_decay(60);
        let decay = |x: &[f64]| Ok(decay_residuals(&t, &y, x));
        let decay_jac = |x: &[f64]| Ok(decay_columns(&t, x));
        let problems: [(&ResidualFn, &JacobianFn, [f64; 2]); 2] = [
            (&rosenbrock, &rosenbrock_jac, [-1.2, 1.0]),
            (&decay, &decay_jac, [50.0, 9.0]),
        ];
        for (f, jac, x0) in problems {
            let run = |gain_ratio_damping| {
                let problem = WithJacobian {
                    f,
                    jac,
                    f_below: None,
                };
                let opts = Options {
                    max_iter: 200,
                    ftol: 1e-14,
                    xtol: 1e-14,
                    noise_stop: false,
                    gain_ratio_damping,
                };
                let (lo, hi, scale) = ([-100.0; 2], [100.0; 2], [1.0; 2]);
                solve_with_jacobian(problem, &x0, &lo, &hi, &scale, opts, &mut |_, _| {}).unwrap()
            };
            let (fixed, gain) = (run(false), run(true));
            // Both stop on a cost change of 1e-14; where the cost is quadratic that is within
            // about √1e-14 = 1e-7 of the minimiser, so 1e-6 in x and 1e-12 in the cost.
            for (a, b) in fixed.x.iter().zip(&gain.x) {
                assert!((a - b).abs() < 1e-6, "{:?} vs {:?}", fixed.x, gain.x);
            }
            assert!((gain.cost - fixed.cost).abs() <= 1e-12 * (1.0 + fixed.cost));
        }
    }

    #[test]
    fn the_noise_stop_ends_sooner_within_the_noise() {
        // A decaying exponential plus deterministic pseudo-noise (σ ≈ 0.02), started far off.
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 0.02).collect();
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(k, t)| {
                2.0 * (-0.7 * t).exp() + 0.02 * ((k as f64 * 12.9898).sin() * 43758.5453).fract()
            })
            .collect();
        let f = |x: &[f64]| -> Result<Vec<f64>> {
            Ok(t.iter()
                .zip(&y)
                .map(|(t, y)| x[0] * (-x[1] * t).exp() + x[2] - y)
                .collect())
        };
        let run = |noise_stop| {
            let opts = Options {
                noise_stop,
                ftol: 1e-15,
                xtol: 1e-15,
                ..Options::default()
            };
            let x0 = [0.3, 3.0, 0.5];
            let (lo, hi, scale) = ([0.0; 3], [10.0; 3], [1.0; 3]);
            solve_parallel(&f, &x0, &lo, &hi, &scale, opts, &mut |_, _| {}).unwrap()
        };
        let (plain, stopped) = (run(false), run(true));
        assert!(
            stopped.iterations < plain.iterations,
            "{} vs {}",
            stopped.iterations,
            plain.iterations
        );
        // Within a few residual variances of the minimum (cost = ½‖r‖²).
        let var = 2.0 * plain.cost / (t.len() - 3) as f64;
        assert!(
            stopped.cost - plain.cost < 2.0 * var,
            "{} vs {}",
            stopped.cost,
            plain.cost
        );
    }
}
