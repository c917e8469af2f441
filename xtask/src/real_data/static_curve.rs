//! Static friction curves `τ(v)` fitted to steady-state (velocity, torque) points, and the
//! significance test that decides which terms the data support. The Stribeck velocity is
//! searched only where the Stribeck level comes out positive (breakaway above Coulomb).
//!
//! Model: `τ = Fc·sgn v + Fv·v [+ τ0] [+ Dv·|v|] [+ Fs·exp(−(v/vs)²)·sgn v]`, i.e. the
//! effects `coulomb`, `viscous`, `offset`, `asymmetry` (the |v| part; its
//! `|sgn v|` part equals the offset at non-zero speed) and `stribeck` (the same law as
//! `control::effects`). For a fixed Stribeck velocity `vs` the model is linear in the other
//! parameters, so `vs` is found by variable projection: a log-spaced scan of the residual, then
//! golden-section refinement of the best bracket.
//!
//! Selection uses the extra-sum-of-squares F-test (see [`motorid::numerics::statistics::f_test`]): starting
//! from Coulomb + viscous, the candidate with the smallest p-value is added while that p-value
//! is below `alpha`; a Stribeck term must also have `Fs > 0` (breakaway above Coulomb).
use anyhow::{bail, Result};
use motorid::numerics::least_squares::{ols, Ols};
use motorid::numerics::statistics::f_test;

/// Significance level of the term selection (1 %); the p-values are reported beside it.
pub const ALPHA: f64 = 0.01;

/// A term of the static curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Term {
    Coulomb,
    Viscous,
    Offset,
    Asymmetry,
    Stribeck,
}

impl Term {
    /// The effect's CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Term::Coulomb => "coulomb",
            Term::Viscous => "viscous",
            Term::Offset => "offset",
            Term::Asymmetry => "asymmetry",
            Term::Stribeck => "stribeck",
        }
    }

    /// Parameters the term adds (Stribeck: level and velocity).
    fn dof(self) -> usize {
        if self == Term::Stribeck {
            2
        } else {
            1
        }
    }
}

/// A fitted static curve.
#[derive(Debug, Clone)]
pub struct Curve {
    /// Terms, in the order of `coef` (Stribeck, if present, is last).
    pub terms: Vec<Term>,
    /// Linear coefficients: Fc, Fv, τ0, Dv, Fs as present.
    pub coef: Vec<f64>,
    /// Their standard deviations (conditional on `vs`).
    pub sigma: Vec<f64>,
    /// Stribeck velocity (same unit as v) when Stribeck is present.
    pub vs: Option<f64>,
    /// Residual sum of squares.
    pub rss: f64,
    /// Number of points.
    pub n: usize,
}

impl Curve {
    /// Total number of parameters (including vs).
    pub fn dof(&self) -> usize {
        self.terms.iter().map(|t| t.dof()).sum()
    }

    /// A coefficient by term (Fs for Stribeck).
    pub fn get(&self, t: Term) -> Option<f64> {
        self.terms
            .iter()
            .position(|&x| x == t)
            .map(|k| self.coef[k])
    }

    /// The curve at velocity `v`.
    pub fn eval(&self, v: f64) -> f64 {
        self.terms
            .iter()
            .zip(&self.coef)
            .map(|(&t, c)| c * column(t, v, self.vs.unwrap_or(1.0)))
            .sum()
    }

    /// Residual standard deviation.
    pub fn residual_std(&self) -> f64 {
        (self.rss / (self.n - self.dof()).max(1) as f64).sqrt()
    }
}

/// The sign of `v`, with `sgn 0 = 0` (unlike `f64::signum`), as the friction laws use it.
pub fn sgn(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn column(t: Term, v: f64, vs: f64) -> f64 {
    match t {
        Term::Coulomb => sgn(v),
        Term::Viscous => v,
        Term::Offset => 1.0,
        Term::Asymmetry => v.abs(),
        Term::Stribeck => (-(v / vs).powi(2)).exp() * sgn(v),
    }
}

fn fit_fixed(terms: &[Term], v: &[f64], tau: &[f64], vs: f64) -> Result<Ols> {
    let cols: Vec<Vec<f64>> = terms
        .iter()
        .map(|&t| v.iter().map(|&x| column(t, x, vs)).collect())
        .collect();
    ols(&cols, tau)
}

/// Fit the curve with the given terms (Stribeck's velocity by variable projection).
pub fn fit(terms: &[Term], v: &[f64], tau: &[f64]) -> Result<Curve> {
    let mut terms = terms.to_vec();
    terms.sort();
    terms.dedup();
    if v.len() != tau.len() || v.len() <= terms.iter().map(|t| t.dof()).sum::<usize>() {
        bail!(
            "static curve: {} points are too few for {} terms",
            v.len(),
            terms.len()
        );
    }
    let (fit, vs) = if terms.contains(&Term::Stribeck) {
        let speeds: Vec<f64> = v.iter().map(|x| x.abs()).filter(|x| *x > 0.0).collect();
        let lo = speeds.iter().cloned().fold(f64::INFINITY, f64::min) / 3.0;
        let hi = speeds.iter().cloned().fold(0.0, f64::max);
        if !(lo > 0.0 && hi > lo) {
            bail!("static curve: Stribeck needs points at several non-zero speeds");
        }
        // Stribeck is breakaway friction above Coulomb: only vs with Fs > 0 are admissible
        // (Fs is the last coefficient, Stribeck sorts last).
        let cost = |lv: f64| {
            fit_fixed(&terms, v, tau, lv.exp())
                .ok()
                .filter(|f| f.theta.last().is_some_and(|fs| *fs > 0.0))
                .map(|f| f.rss)
                .unwrap_or(f64::INFINITY)
        };
        let (a, b) = (lo.ln(), hi.ln());
        let m = 80;
        let grid: Vec<f64> = (0..=m).map(|k| a + (b - a) * k as f64 / m as f64).collect();
        let costs: Vec<f64> = grid.iter().map(|&g| cost(g)).collect();
        let best = (0..=m)
            .min_by(|&i, &j| costs[i].total_cmp(&costs[j]))
            .unwrap_or(0);
        let (mut x0, mut x1) = (grid[best.saturating_sub(1)], grid[(best + 1).min(m)]);
        let g = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..60 {
            let (c, d) = (x1 - g * (x1 - x0), x0 + g * (x1 - x0));
            if cost(c) < cost(d) {
                x1 = d;
            } else {
                x0 = c;
            }
        }
        if !costs[best].is_finite() {
            bail!("static curve: no Stribeck velocity gives a positive Stribeck level");
        }
        let vs = (0.5 * (x0 + x1)).exp();
        (fit_fixed(&terms, v, tau, vs)?, Some(vs))
    } else {
        (fit_fixed(&terms, v, tau, 1.0)?, None)
    };
    Ok(Curve {
        coef: fit.theta.clone(),
        sigma: fit.sigma.clone(),
        rss: fit.rss,
        n: fit.n,
        terms,
        vs,
    })
}

/// One step of the selection: a candidate term and its test against the current model.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub term: Term,
    /// F statistic and p-value of adding the term.
    pub f: f64,
    pub p: f64,
    /// Why it was not added although significant (e.g. Fs ≤ 0), if so.
    pub rejected: Option<String>,
    /// The curve with the term added.
    pub curve: Curve,
}

/// The result of the selection.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Coulomb + viscous.
    pub base: Curve,
    /// The final model.
    pub chosen: Curve,
    /// Every candidate tested against the final model's predecessor, in the order added,
    /// followed by the candidates that were not added (tested against the final model).
    pub tests: Vec<Candidate>,
}

impl Selection {
    /// True when the final model includes the term.
    pub fn has(&self, t: Term) -> bool {
        self.chosen.terms.contains(&t)
    }

    /// The last test of a term (p-value against the model it was tested against).
    pub fn test_of(&self, t: Term) -> Option<&Candidate> {
        self.tests.iter().rev().find(|c| c.term == t)
    }
}

/// Forward selection from Coulomb + viscous over offset, asymmetry and Stribeck.
pub fn select(v: &[f64], tau: &[f64], alpha: f64) -> Result<Selection> {
    let base = fit(&[Term::Coulomb, Term::Viscous], v, tau)?;
    let mut cur = base.clone();
    let mut pool = vec![Term::Offset, Term::Asymmetry, Term::Stribeck];
    let mut tests = Vec::new();
    loop {
        let mut cands = Vec::new();
        for &t in &pool {
            let mut terms = cur.terms.clone();
            terms.push(t);
            let c = match fit(&terms, v, tau) {
                Ok(c) => c,
                Err(_) => continue,
            };
            let test = f_test(cur.rss, c.rss, t.dof(), c.dof() - t.dof(), v.len() as f64);
            let (f, p) = (test.f, test.p_value);
            let rejected = (t == Term::Stribeck && c.get(Term::Stribeck).unwrap_or(0.0) <= 0.0)
                .then(|| "fitted Stribeck level Fs ≤ 0 (no breakaway above Coulomb)".to_string());
            cands.push(Candidate {
                term: t,
                f,
                p,
                rejected,
                curve: c,
            });
        }
        let best = cands
            .iter()
            .filter(|c| c.rejected.is_none())
            .min_by(|a, b| a.p.total_cmp(&b.p))
            .cloned();
        match best {
            Some(b) if b.p < alpha => {
                pool.retain(|&t| t != b.term);
                cur = b.curve.clone();
                tests.push(b);
            }
            _ => {
                tests.extend(cands);
                break;
            }
        }
        if pool.is_empty() {
            break;
        }
    }
    Ok(Selection {
        base,
        chosen: cur,
        tests,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn speeds() -> Vec<f64> {
        let mut v = Vec::new();
        for s in [
            0.1, 0.2, 0.4, 0.6, 0.8, 1.0, 1.5, 2.0, 3.0, 5.0, 8.0, 12.0, 16.0, 20.0,
        ] {
            v.push(s);
            v.push(-s);
        }
        v
    }

    /// Gaussian noise, unit variance, from a fixed seed.
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
    }

    #[test]
    fn recovers_stribeck_velocity_and_selects_it() {
        let v = speeds();
        let e = noise(v.len(), 1);
        let tau: Vec<f64> = v
            .iter()
            .enumerate()
            .map(|(k, &x)| {
                1.0 * sgn(x)
                    + 0.05 * x
                    + 0.4 * (-(x / 0.7f64).powi(2)).exp() * sgn(x)
                    + 0.003 * e[k]
            })
            .collect();
        let s = select(&v, &tau, ALPHA).unwrap();
        assert!(s.has(Term::Stribeck));
        let vs = s.chosen.vs.unwrap();
        assert!((vs - 0.7).abs() < 0.05, "vs = {vs}");
        assert!(
            !s.has(Term::Asymmetry),
            "{:#?}",
            s.tests.iter().map(|c| (c.term, c.p)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn does_not_claim_stribeck_on_a_plain_curve() {
        let v = speeds();
        let e = noise(v.len(), 2);
        let tau: Vec<f64> = v
            .iter()
            .enumerate()
            .map(|(k, &x)| 1.0 * sgn(x) + 0.05 * x + 0.2 + 0.01 * e[k])
            .collect();
        let s = select(&v, &tau, ALPHA).unwrap();
        assert!(s.has(Term::Offset));
        assert!(!s.has(Term::Stribeck), "{:?}", s.chosen.terms);
    }
}

/// Stribeck tested in one direction of motion only (points with `sign·v > 0`): a straight
/// line `c + Fv·v` against the line plus `Fs·exp(−(v/vs)²)·sgn v` with Fs > 0. Friction that
/// falls with speed in one direction but not in the other shows here while a symmetric
/// Stribeck term averages it away. Each direction then gets its own curve (its own Coulomb
/// level `c`, viscous slope and, where the test selects it, Stribeck term): the static curve
/// per direction, as the authors of the EMPS benchmark fit their asymmetric model.
#[derive(Debug, Clone)]
pub struct OneSided {
    /// +1 or −1.
    pub sign: f64,
    pub points: usize,
    /// F-test p-value, or None when no admissible Stribeck curve exists.
    pub p: Option<f64>,
    pub fs: Option<f64>,
    pub vs: Option<f64>,
    /// The curve of this direction the test selects: the line plus Stribeck when `p <`
    /// [`ALPHA`] with Fs > 0, else the line (None when even the line cannot be fitted).
    pub curve: Option<Curve>,
}

impl OneSided {
    /// True when this direction's curve has a Stribeck term.
    pub fn has_stribeck(&self) -> bool {
        self.curve
            .as_ref()
            .is_some_and(|c| c.terms.contains(&Term::Stribeck))
    }
}

/// [`OneSided`] tests for both directions.
pub fn one_sided_stribeck(v: &[f64], tau: &[f64]) -> Vec<OneSided> {
    [1.0, -1.0]
        .into_iter()
        .map(|sign| {
            let (vv, tt): (Vec<f64>, Vec<f64>) = v
                .iter()
                .zip(tau)
                .filter(|(x, _)| sign * **x > 0.0)
                .map(|(a, b)| (*a, *b))
                .unzip();
            let base = fit(&[Term::Offset, Term::Viscous], &vv, &tt);
            let with = fit(&[Term::Offset, Term::Viscous, Term::Stribeck], &vv, &tt);
            match (base, with) {
                (Ok(b), Ok(w)) => {
                    let p = f_test(b.rss, w.rss, 2, w.dof() - 2, vv.len() as f64).p_value;
                    let fs = w.get(Term::Stribeck);
                    let stribeck = p < ALPHA && fs.is_some_and(|f| f > 0.0);
                    OneSided {
                        sign,
                        points: vv.len(),
                        p: Some(p),
                        fs,
                        vs: w.vs,
                        curve: Some(if stribeck { w } else { b }),
                    }
                }
                (b, _) => OneSided {
                    sign,
                    points: vv.len(),
                    p: None,
                    fs: None,
                    vs: None,
                    curve: b.ok(),
                },
            }
        })
        .collect()
}
