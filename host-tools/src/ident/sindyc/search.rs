//! The structure-search stage: the STLSQ ladder on the weak-form normal equations gives a
//! start, then the paper's one-by-one hard thresholding judged by the free-run validation fit
//! ([`super::simulate::validation_fit`]), with divergent candidates rejected. Every candidate
//! examined is a row of the Pareto table (number of terms vs validation fit).
use super::embedding::HiddenState;
use super::simulate::{bounded_segments, evaluation_budget, validation_fit, Limits};
use super::{ParetoRow, SindycOptions, ZTerms};
use crate::ident::library::{Library, ACCEL, EQUATION_NAMES, IDOT, ZDOT};
use crate::ident::sensor_chain;
use crate::ident::stlsq::StlsqOptions;
use crate::log::{MotorLog, Plant};
use crate::numerics::least_squares::NormalEquations;
use control::sindy::{SindyModel, SparseEq, Term, MAX_TERMS};

/// Multipliers of the base STLSQ threshold tried for the starting model.
const THRESHOLD_LADDER: [f64; 5] = [1.0, 3.0, 10.0, 30.0, 100.0];
/// Bound on the free-run simulations one search may spend.
const MAX_SIMULATIONS: usize = 400;

/// Sparse coefficients of the three equations (normalised, one vector per equation).
#[derive(Clone)]
pub struct Candidate {
    xn: [Vec<f64>; 3],
}

impl Candidate {
    pub fn terms(&self) -> usize {
        self.xn
            .iter()
            .map(|x| x.iter().filter(|v| **v != 0.0).count())
            .sum()
    }
}

pub struct Search<'a> {
    lib: &'a Library,
    /// Normal equations per equation. The current equation is fitted in its inverse form
    /// `u = L·dI/dt + Σ c_k·θ_k` (see [`super::rows::normal_equations`]); its last column is `dI/dt`.
    nes: Vec<NormalEquations>,
    /// The current equation's pointwise rows over the held voltage
    /// ([`super::rows::held_current_normal`]), which give its coefficients once the weak
    /// form has chosen its terms.
    held: Option<NormalEquations>,
    /// Sample period (for the fallback inductance).
    dt: f64,
    plant: Plant,
    /// The validation runs (at most [`evaluation_budget`] samples).
    val: Vec<MotorLog>,
    val_omega: Vec<Vec<f64>>,
    /// Velocity-estimator window of the sensor chain.
    window: usize,
    limits: Limits,
    z_max: f64,
    z_terms: ZTerms,
    sims: usize,
}

impl<'a> Search<'a> {
    /// A search over the normal equations `nes` (see [`super::rows::normal_equations`]),
    /// judged on `val` (the fitting logs when empty). A free run counts as divergent beyond
    /// ten times the largest velocity and current of the data; `z` is clamped to 1.5 times
    /// its largest magnitude in the fitting data (the observer's bound).
    pub fn new(
        lib: &'a Library,
        nes: Vec<NormalEquations>,
        held: Option<NormalEquations>,
        fit_logs: &'a [MotorLog],
        val: &[MotorLog],
        hidden: &HiddenState,
        opts: &SindycOptions,
    ) -> Self {
        let val = if val.is_empty() { fit_logs } else { val };
        let val = bounded_segments(val, evaluation_budget(val));
        let val_omega: Vec<Vec<f64>> = val
            .iter()
            .map(|l| sensor_chain::measured_velocity(l, opts.velocity_window))
            .collect();
        let wmax = val_omega
            .iter()
            .chain(&hidden.xdot)
            .flatten()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let imax = fit_logs
            .iter()
            .chain(&val)
            .filter_map(|l| l.i.as_ref())
            .flatten()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        Search {
            lib,
            nes,
            held,
            dt: fit_logs[0].sample_period(),
            plant: opts.plant,
            val,
            val_omega,
            window: opts.velocity_window,
            limits: Limits {
                omega: 10.0 * wmax + 10.0,
                current: 10.0 * imax + 10.0,
            },
            z_max: 1.5 * hidden.z_peak.max(1e-9),
            z_terms: opts.z_terms,
            sims: 0,
        }
    }

    /// The divergence limits of every free run of this search.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    pub fn equations(&self) -> usize {
        if self.plant == Plant::Voltage {
            3
        } else {
            2
        }
    }

    pub fn model(&self, c: &Candidate) -> SindyModel<f64> {
        let mut m = SindyModel::empty(self.lib.a, self.lib.vs, 0.0);
        m.z_max = self.z_max;
        for e in 0..self.equations() {
            let mut coef = self.nes[e].denormalise(&c.xn[e]);
            if e == IDOT {
                coef = self.current_equation(&coef);
            }
            let mut eq = SparseEq::new();
            for (j, v) in coef.iter().enumerate().take(self.lib.len()) {
                if *v != 0.0 {
                    let _ = eq.push(self.lib.candidates[j].term, *v);
                }
            }
            match e {
                ACCEL => m.accel = eq,
                ZDOT => m.zdot = eq,
                _ => m.idot = eq,
            }
        }
        m
    }

    /// The current equation `dI/dt = u/L − Σ (c_k/L)·θ_k` on the terms the weak form chose
    /// (`weak`: the inverse form `u = L·dI/dt + Σ c_k·θ_k`, its last entry `L`).
    /// The coefficients `c_k` (with `R` for `I`) come from the held-voltage rows when they
    /// give a positive `R` (the current as it is sampled), else from the weak form. The
    /// time constant `L/R` is the weak form's when it resolves one shorter than a sample;
    /// otherwise (the current settles within a sample, so the data cannot resolve it) a
    /// tenth of the sample period: any value well below the period gives the same samples.
    fn current_equation(&self, weak: &[f64]) -> Vec<f64> {
        let p = self.lib.len();
        let pos = |t: Term| self.lib.candidates.iter().position(|c| c.term == t);
        let (j_i, j_u) = (pos(Term::I), pos(Term::U));
        let r_weak = j_i.map_or(0.0, |j| weak[j]);
        let tau_weak = weak[p] / r_weak;
        let tau = if tau_weak > 0.0 && tau_weak < self.dt {
            tau_weak
        } else {
            self.dt / 10.0
        };
        let held = self.held.as_ref().zip(j_i).and_then(|(ne, j_i)| {
            let mut support: Vec<bool> = weak[..p].iter().map(|c| *c != 0.0).collect();
            support[j_i] = true;
            if let Some(j) = j_u {
                support[j] = false;
            }
            let c = ne.solve(0, &support);
            (c[j_i] > 0.0 && c.iter().all(|v| v.is_finite())).then_some(c)
        });
        let (coef, l) = match held {
            Some(c) => {
                let l = c[j_i.unwrap_or(0)] * tau;
                (c, l)
            }
            None => {
                let mut l = weak[p];
                if !(l.is_finite() && l > 0.0) {
                    l = r_weak.abs().max(1e-6) * self.dt / 10.0;
                }
                (weak[..p].to_vec(), l)
            }
        };
        let mut out: Vec<f64> = coef.iter().map(|c| -c / l).collect();
        if let Some(j) = j_u {
            out[j] = 1.0 / l;
        }
        out
    }

    /// Mean validation fit on ẋ, None when the model diverges on any log.
    pub fn score(&mut self, c: &Candidate) -> Option<f64> {
        let m = self.model(c);
        self.score_model(&m)
    }

    /// [`Search::score`] of a model.
    pub fn score_model(&mut self, m: &SindyModel<f64>) -> Option<f64> {
        self.sims += 1;
        validation_fit(
            m,
            self.plant,
            &self.val,
            &self.val_omega,
            self.window,
            self.limits,
        )
    }

    /// Whether a candidate's acceleration or current equation has a term in `z` (only then
    /// does `z` change the free run).
    fn uses_z(&self, c: &Candidate) -> bool {
        [ACCEL, IDOT]
            .into_iter()
            .filter(|e| *e < self.equations())
            .any(|e| {
                self.lib
                    .candidates
                    .iter()
                    .zip(&c.xn[e])
                    .any(|(t, v)| *v != 0.0 && t.term.has_z())
            })
    }

    /// Remove term `j` from equation `e` and refit that equation.
    fn without(&self, c: &Candidate, e: usize, j: usize) -> Candidate {
        self.with_support(c, e, j, false)
    }

    /// Add term `j` to equation `e` and refit that equation (on the weak form).
    pub fn with_term(&self, c: &Candidate, e: usize, j: usize) -> Candidate {
        self.with_support(c, e, j, true)
    }

    /// Set whether term `j` is in equation `e` and refit that equation on its support.
    fn with_support(&self, c: &Candidate, e: usize, j: usize, on: bool) -> Candidate {
        let mut sup: Vec<bool> = c.xn[e].iter().map(|v| *v != 0.0).collect();
        sup[j] = on;
        let mut next = c.clone();
        next.xn[e] = self.nes[e].solve_normalised(0, &sup);
        // Keep the support exact (a refit may produce an exact zero only by accident).
        for (k, s) in sup.iter().enumerate() {
            if !s {
                next.xn[e][k] = 0.0;
            }
        }
        next
    }

    /// Which library columns each equation may use. With a measured current,
    /// `u ≈ R·I + K_b·ẋ` at 12 ms: `u` terms in the acceleration equation would make the
    /// split between `I` and `u` arbitrary and break the friction rule of eq. 47, so they
    /// are left to the current equation (with a torque plant `u` is the torque and stays).
    /// In the current equation's inverse form `u` is the target; its last column `dI/dt`
    /// is allowed when usable.
    pub fn allowed(&self) -> Vec<Vec<bool>> {
        let voltage = self.plant == Plant::Voltage;
        let lib = self.lib;
        (0..self.equations())
            .map(|e| {
                let usable = self.nes[e].usable();
                let mut v: Vec<bool> = lib
                    .candidates
                    .iter()
                    .zip(&usable)
                    .map(|(c, u)| {
                        *u && c.allowed[e]
                            && !(voltage && e == ACCEL && c.term.has_voltage())
                            && !(e == IDOT && c.term == Term::U)
                    })
                    .collect();
                if e == IDOT {
                    v.push(usable[lib.len()]);
                }
                v
            })
            .collect()
    }

    /// The STLSQ ladder: every threshold multiplier of [`THRESHOLD_LADDER`] on `base`,
    /// each with the whole library and without the z terms (then z stays 0: the extracted z
    /// only earns its terms if it predicts better; [`SindycOptions::z_terms`] may keep only
    /// one of the two). Returns the candidate with the best
    /// validation fit that does not diverge (or the first, when all diverge) and its fit;
    /// every try is a row of `pareto`.
    pub fn stlsq_start(
        &mut self,
        allowed: &[Vec<bool>],
        base: &StlsqOptions,
        pareto: &mut Vec<ParetoRow>,
    ) -> (Candidate, Option<f64>) {
        let mut best: Option<(Candidate, Option<f64>)> = None;
        let mut fallback: Option<(Candidate, Option<f64>)> = None;
        // Each threshold is tried with the whole library and without the z terms (then z stays
        // 0): the extracted z only earns its terms if it predicts better.
        let z_terms = self.z_terms;
        let ladder = THRESHOLD_LADDER
            .iter()
            .flat_map(|m| [(*m, false), (*m, true)])
            .filter(|(_, z_free)| match z_terms {
                ZTerms::Chosen => true,
                ZTerms::Without => *z_free,
                ZTerms::With => !*z_free,
            });
        for (mult, z_free) in ladder {
            let o = StlsqOptions {
                threshold: base.threshold * mult,
                ..*base
            };
            let mut c = Candidate {
                xn: [
                    vec![0.0; self.lib.len()],
                    vec![0.0; self.lib.len()],
                    vec![0.0; self.lib.len() + 1],
                ],
            };
            for (e, allowed_e) in allowed.iter().enumerate() {
                if z_free && e == ZDOT {
                    continue;
                }
                let mut sup = allowed_e.clone();
                if z_free {
                    for (k, c) in self.lib.candidates.iter().enumerate() {
                        sup[k] &= !c.term.has_z();
                    }
                }
                let mut xn = self.nes[e].stlsq_normalised(0, &sup, &o);
                // The firmware holds at most MAX_TERMS terms per equation: drop the smallest.
                while xn.iter().filter(|v| **v != 0.0).count() > MAX_TERMS {
                    let j = smallest(&xn);
                    let mut sup: Vec<bool> = xn.iter().map(|v| *v != 0.0).collect();
                    sup[j] = false;
                    xn = self.nes[e].solve_normalised(0, &sup);
                    for (k, s) in sup.iter().enumerate() {
                        if !s {
                            xn[k] = 0.0;
                        }
                    }
                }
                c.xn[e] = xn;
            }
            let fit = self.score(&c);
            pareto.push(ParetoRow {
                terms: c.terms(),
                fit,
                step: format!(
                    "STLSQ, threshold {:.3}{}",
                    o.threshold,
                    if z_free { ", without z" } else { "" }
                ),
                accepted: false,
            });
            // With `ZTerms::With` a start must use z; the best of the others is kept only for
            // a ladder where none does.
            let slot = if z_terms != ZTerms::With || self.uses_z(&c) {
                &mut best
            } else {
                &mut fallback
            };
            let better = match slot {
                None => true,
                Some((_, bf)) => fit.unwrap_or(f64::NEG_INFINITY) > bf.unwrap_or(f64::NEG_INFINITY),
            };
            if better {
                *slot = Some((c, fit));
            }
        }
        let (start, fit) = best.or(fallback).expect("the ladder is not empty");
        if let Some(row) = pareto
            .iter_mut()
            .find(|r| r.fit == fit && r.terms == start.terms())
        {
            row.accepted = true;
        }
        (start, fit)
    }

    /// The paper's one-by-one hard thresholding: try removing terms from the smallest
    /// contribution up, refitting that equation on its support and simulating the
    /// validation logs; keep the first removal whose validation fit stays within
    /// `tolerance` points of the best seen; stop when no removal qualifies or the budget
    /// of free runs is spent. While the current candidate diverges, the first removal that
    /// does not diverge is kept (and, when all diverge, the smallest term is dropped).
    pub fn threshold_one_by_one(
        &mut self,
        start: Candidate,
        start_fit: Option<f64>,
        tolerance: f64,
        pareto: &mut Vec<ParetoRow>,
    ) -> (Candidate, Option<f64>) {
        let (mut cur, mut cur_fit) = (start, start_fit);
        let mut best_fit = cur_fit.unwrap_or(f64::NEG_INFINITY);
        loop {
            if self.sims >= MAX_SIMULATIONS || cur.terms() <= 1 {
                break;
            }
            let mut order: Vec<(f64, usize, usize)> = Vec::new();
            for e in 0..self.equations() {
                let yn = self.nes[e].target_norm(0).max(f64::MIN_POSITIVE);
                for (j, v) in cur.xn[e].iter().enumerate() {
                    // The inductance column and the current's R·I stay: they make the equation.
                    let keep = e == IDOT
                        && (j == self.lib.len() || self.lib.candidates[j].term == Term::I);
                    if *v != 0.0 && !keep {
                        order.push((v.abs() / yn, e, j));
                    }
                }
            }
            order.sort_by(|a, b| a.0.total_cmp(&b.0));
            if order.is_empty() {
                break;
            }
            // Try the terms from the smallest contribution up; keep the first removal whose
            // validation fit stays within the tolerance of the best seen (or, while the current
            // model diverges, the first that does not diverge).
            let mut accepted = false;
            let mut first_rejected: Option<ParetoRow> = None;
            for &(_, e, j) in &order {
                if self.sims >= MAX_SIMULATIONS {
                    break;
                }
                let c = self.without(&cur, e, j);
                let fit = self.score(&c);
                let step = format!(
                    "removed {}: {}",
                    EQUATION_NAMES[e], self.lib.candidates[j].term
                );
                match fit {
                    Some(f) if cur_fit.is_none() || f >= best_fit - tolerance => {
                        pareto.push(ParetoRow {
                            terms: c.terms(),
                            fit: Some(f),
                            step,
                            accepted: true,
                        });
                        best_fit = if cur_fit.is_none() {
                            f
                        } else {
                            best_fit.max(f)
                        };
                        cur = c;
                        cur_fit = Some(f);
                        accepted = true;
                        break;
                    }
                    _ => {
                        if first_rejected.is_none() {
                            first_rejected = Some(ParetoRow {
                                terms: c.terms(),
                                fit,
                                step: format!("{step} (rejected)"),
                                accepted: false,
                            });
                        }
                    }
                }
            }
            if !accepted {
                pareto.extend(first_rejected);
                if cur_fit.is_some() || self.sims >= MAX_SIMULATIONS {
                    break;
                }
                // Every removal diverges too: drop the smallest term and go on.
                let (_, e, j) = order[0];
                cur = self.without(&cur, e, j);
            }
        }
        (cur, cur_fit)
    }
}

/// Index of the smallest nonzero entry (by magnitude).
fn smallest(xn: &[f64]) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (j, v) in xn.iter().enumerate() {
        if *v != 0.0 && v.abs() < best.0 {
            best = (v.abs(), j);
        }
    }
    best.1
}
