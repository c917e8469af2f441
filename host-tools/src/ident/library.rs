//! The SINDYc candidate library `Θ(x, ẋ, z, I, u)`: the reference paper's 17 terms (its
//! §4.4) plus the terms that physical effects add (`fit --add`), each allowed in some of the
//! three state equations (acceleration eq. 44, internal state eq. 45, current eq. 46).
//!
//! Terms are the firmware's [`control::sindy::Term`]s, so the board evaluates exactly the
//! equations identified here. Columns are evaluated with one tight loop per term (the 17
//! paper terms) or through [`Term::eval`] (effect terms); a test checks both agree.
//!
//! The terms each effect adds, and the equation they may appear in, are in its descriptor
//! ([`crate::effects`]): a Coulomb-like effect adds its sign term to the acceleration
//! equation, an electrical one its term to the current equation; effects without a term
//! (a second inertia, a table) refuse with the advice to fit a LuGre model.
//!
//! With `--plant torque` there is no current: terms containing `I` are left out and there is
//! no current equation.
use crate::effect_spec::EffectSpec;
use crate::log::Plant;
use crate::numerics::least_squares::NormalEquations;
use anyhow::Result;
use control::sindy::{Term, TermInputs};
use faer::Mat;

/// Index of the acceleration equation (eq. 44).
pub const ACCEL: usize = 0;
/// Index of the internal-state equation (eq. 45).
pub const ZDOT: usize = 1;
/// Index of the current equation (eq. 46).
pub const IDOT: usize = 2;
/// Equation names, by index.
pub const EQUATION_NAMES: [&str; 3] = ["d(xdot)/dt", "dz/dt", "di/dt"];

/// One library column: a term and the equations it may appear in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub term: Term,
    /// Allowed in (acceleration, internal state, current).
    pub allowed: [bool; 3],
}

/// The candidate library.
#[derive(Debug, Clone, PartialEq)]
pub struct Library {
    pub candidates: Vec<Candidate>,
    /// tanh gain `a` of `tanh(a·ẋ)`, `tanh(a·z)`.
    pub a: f64,
    /// Stribeck velocity [rad/s] of the Stribeck term.
    pub vs: f64,
}

/// The signals the library is evaluated on (same length; `i` absent for a torque plant).
#[derive(Debug, Clone, Copy)]
pub struct Signals<'a> {
    pub x: &'a [f64],
    pub xdot: &'a [f64],
    pub z: &'a [f64],
    pub i: Option<&'a [f64]>,
    pub u: &'a [f64],
}

impl Signals<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The samples `start..end`.
    pub fn slice(&self, start: usize, end: usize) -> Signals<'_> {
        Signals {
            x: &self.x[start..end],
            xdot: &self.xdot[start..end],
            z: &self.z[start..end],
            i: self.i.map(|i| &i[start..end]),
            u: &self.u[start..end],
        }
    }

    /// The term inputs at sample `k`.
    pub fn at(&self, k: usize) -> TermInputs<f64> {
        TermInputs {
            x: self.x[k],
            xdot: self.xdot[k],
            z: self.z[k],
            i: self.i.map_or(0.0, |i| i[k]),
            u: self.u[k],
        }
    }
}

impl Library {
    /// The paper's 17 terms, allowed in every equation (the current equation only exists
    /// for a voltage plant; terms with `I` only when there is a current).
    pub fn paper(plant: Plant, a: f64, vs: f64) -> Library {
        let mut lib = Library {
            candidates: Vec::new(),
            a,
            vs,
        };
        for t in Term::PAPER_LIBRARY {
            lib.add(t, [true, true, true], plant);
        }
        lib
    }

    /// The paper's library plus the terms of `adds` (see the module doc's table).
    pub fn with_effects(plant: Plant, a: f64, vs: f64, adds: &[EffectSpec]) -> Result<Library> {
        let mut lib = Self::paper(plant, a, vs);
        for spec in adds {
            let terms = (crate::effects::of(spec.kind).sindy)(spec)?;
            if let Some(vs) = terms.vs {
                lib.vs = vs;
            }
            for (term, allowed) in terms.terms {
                lib.add(term, allowed, plant);
            }
        }
        Ok(lib)
    }

    /// Add a term (merging the allowed equations when it is already there). Terms with `I`
    /// are skipped for a torque plant, as is the current equation.
    pub fn add(&mut self, term: Term, allowed: [bool; 3], plant: Plant) {
        if plant == Plant::Torque && term.has_current() {
            return;
        }
        let mut allowed = allowed;
        if plant == Plant::Torque {
            allowed[IDOT] = false;
        }
        if !allowed.iter().any(|a| *a) {
            return;
        }
        if let Some(c) = self.candidates.iter_mut().find(|c| c.term == term) {
            for (have, add) in c.allowed.iter_mut().zip(allowed) {
                *have |= add;
            }
        } else {
            self.candidates.push(Candidate { term, allowed });
        }
    }

    /// Number of columns.
    pub fn len(&self) -> usize {
        self.candidates.len()
    }

    /// True when the library has no terms.
    pub fn is_empty(&self) -> bool {
        self.candidates.is_empty()
    }

    /// The terms in column order.
    pub fn terms(&self) -> Vec<Term> {
        self.candidates.iter().map(|c| c.term).collect()
    }

    /// Evaluate one term on every sample into `out`.
    pub fn column(&self, term: Term, s: &Signals, out: &mut [f64]) {
        let a = self.a;
        let (x, v, z, u) = (s.x, s.xdot, s.z, s.u);
        let zero;
        let i = match s.i {
            Some(i) => i,
            None => {
                zero = vec![0.0; s.len()];
                &zero
            }
        };
        macro_rules! fill {
            (|$k:ident| $e:expr) => {
                for ($k, o) in out.iter_mut().enumerate() {
                    *o = $e;
                }
            };
        }
        match term {
            Term::X => out.copy_from_slice(x),
            Term::Xdot => out.copy_from_slice(v),
            Term::Z => out.copy_from_slice(z),
            Term::I => out.copy_from_slice(i),
            Term::U => out.copy_from_slice(u),
            Term::TanhXdot => fill!(|k| (a * v[k]).tanh()),
            Term::TanhZ => fill!(|k| (a * z[k]).tanh()),
            Term::AbsXdotXdot => fill!(|k| v[k].abs() * v[k]),
            Term::AbsXdotXdot2 => fill!(|k| v[k].abs() * v[k] * v[k]),
            Term::AbsZZ => fill!(|k| z[k].abs() * z[k]),
            Term::AbsZZ2 => fill!(|k| z[k].abs() * z[k] * z[k]),
            Term::ZXdot => fill!(|k| z[k] * v[k]),
            Term::Z2Xdot => fill!(|k| z[k] * z[k] * v[k]),
            Term::ZXdot2 => fill!(|k| z[k] * v[k] * v[k]),
            Term::ZU => fill!(|k| z[k] * u[k]),
            Term::Z2U => fill!(|k| z[k] * z[k] * u[k]),
            Term::ZU2 => fill!(|k| z[k] * u[k] * u[k]),
            Term::One => out.fill(1.0),
            t => fill!(|k| t.eval(&s.at(k), a, self.vs)),
        }
    }

    /// The library matrix `Θ` (`N × len()`, column-major).
    pub fn matrix(&self, s: &Signals) -> Mat<f64> {
        let mut m = Mat::<f64>::zeros(s.len(), self.len());
        self.matrix_into(s, &mut m);
        m
    }

    /// Evaluate the library into the first `s.len()` rows of `out` (a reusable buffer).
    pub fn matrix_into(&self, s: &Signals, out: &mut Mat<f64>) {
        let n = s.len();
        for (j, c) in self.candidates.iter().enumerate() {
            self.column(c.term, s, &mut out.col_as_slice_mut(j)[..n]);
        }
    }

    /// The normal equations of the library against pointwise `targets`, accumulated over
    /// blocks of rows: `Θ` (`N × p`) is never held in memory, so 10^6 samples cost one pass
    /// through the cache instead of a 136 MB matrix.
    pub fn normal(&self, s: &Signals, targets: &[&[f64]]) -> NormalEquations {
        /// Rows per block: 4096 × 17 f64 = 0.5 MB, about an L2 cache.
        const BLOCK: usize = 4096;
        let (n, p, t) = (s.len(), self.len(), targets.len());
        // Blocks of the library matrix are evaluated in parallel, a batch of them at a time
        // (the transcendental terms are most of the cost), and summed in their order.
        let batch = 2 * rayon::current_num_threads();
        let mut bufs: Vec<Mat<f64>> = (0..batch)
            .map(|_| Mat::<f64>::zeros(BLOCK.min(n.max(1)), p))
            .collect();
        let mut gtt = Mat::<f64>::zeros(p, p);
        let mut gty = Mat::<f64>::zeros(p, t);
        let mut yy = vec![0.0; t];
        let mut start = 0;
        while start < n {
            {
                use rayon::prelude::*;
                bufs.par_iter_mut().enumerate().for_each(|(b, buf)| {
                    let from = start + b * BLOCK;
                    if from < n {
                        self.matrix_into(&s.slice(from, (from + BLOCK).min(n)), buf);
                    }
                });
            }
            for buf in &bufs {
                if start >= n {
                    break;
                }
                let end = (start + BLOCK).min(n);
                let len = end - start;
                let blk = buf.as_ref().subrows(0, len);
                let y = Mat::<f64>::from_fn(len, t, |r, k| targets[k][start + r]);
                gtt += blk.transpose() * blk;
                gty += blk.transpose() * &y;
                for (k, acc) in yy.iter_mut().enumerate() {
                    *acc += targets[k][start..end].iter().map(|v| v * v).sum::<f64>();
                }
                start = end;
            }
        }
        NormalEquations::from_products(p, t, |i, j| gtt[(i, j)], |i, k| gty[(i, k)], yy)
    }
}

#[cfg(test)]
mod tests {
    // Tolerances of 1e-12 to 1e-9 (relative) compare the same numbers computed two ways, or
    // a noiseless fit with its exact answer: float rounding.
    use super::*;

    /// Sine waves `amp·sin(c·k)`, k < n, one per rate: x, xdot, z, i, u.
    fn sines(n: usize, amp: f64, rates: [f64; 5]) -> [Vec<f64>; 5] {
        rates.map(|c| (0..n).map(|k| (k as f64 * c).sin() * amp).collect())
    }

    fn signals(v: &[Vec<f64>; 5]) -> Signals<'_> {
        Signals {
            x: &v[0],
            xdot: &v[1],
            z: &v[2],
            i: Some(&v[3]),
            u: &v[4],
        }
    }

    #[test]
    fn columns_equal_the_firmware_terms() {
        let n = 257;
        let sig = sines(n, 3.0, [0.11, 0.07, 0.013, 0.05, 0.031]);
        let s = signals(&sig);
        let adds: Vec<EffectSpec> = [
            "coulomb",
            "stribeck:vs=3",
            "cogging:harmonic=7",
            "position_load",
            "offset",
            "asymmetry",
            "load_friction",
            "deadtime",
            "current_offset",
            "thermal",
        ]
        .iter()
        .map(|s| EffectSpec::parse(s).unwrap())
        .collect();
        let lib = Library::with_effects(Plant::Voltage, 4.0, 1.0, &adds).unwrap();
        assert_eq!(lib.vs, 3.0);
        // 17 + sgn, stribeck, sin7, cos7, sin1, cos1, 1, |xdot|, |sgn|, |i|sgn, sgn(i), i^2
        assert_eq!(lib.len(), 17 + 12);
        let one = lib.candidates.iter().find(|c| c.term == Term::One).unwrap();
        assert_eq!(one.allowed, [true, false, true]);
        let m = lib.matrix(&s);
        for (j, c) in lib.candidates.iter().enumerate() {
            for k in 0..n {
                let want = c.term.eval(&s.at(k), lib.a, lib.vs);
                assert!(
                    (m[(k, j)] - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{}",
                    c.term
                );
            }
        }
    }

    #[test]
    fn blockwise_normal_equations_equal_the_full_matrix() {
        let n = 10_000; // more than two blocks
        let sig = sines(n, 2.0, [0.011, 0.007, 0.0013, 0.005, 0.0031]);
        let s = signals(&sig);
        let (v, z, u) = (&sig[1], &sig[2], &sig[4]);
        let lib = Library::paper(Plant::Voltage, 5.0, 1.0);
        let y: Vec<f64> = (0..n)
            .map(|k| 3.0 * v[k] - 0.5 * u[k] + z[k] * u[k])
            .collect();
        let blockwise = lib.normal(&s, &[&y]);
        let th = lib.matrix(&s);
        let full = NormalEquations::new(th.as_ref(), Mat::from_fn(n, 1, |r, _| y[r]).as_ref());
        let sup = vec![true; lib.len()];
        let (a, b) = (blockwise.solve(0, &sup), full.solve(0, &sup));
        for j in 0..lib.len() {
            assert!(
                (a[j] - b[j]).abs() < 1e-9 * (1.0 + b[j].abs()),
                "{j}: {} {}",
                a[j],
                b[j]
            );
        }
        assert!(
            (a[1] - 3.0).abs() < 1e-9 && (a[13] + 0.5).abs() < 1e-9 && (a[14] - 1.0).abs() < 1e-9
        );
    }

    #[test]
    fn torque_plant_has_no_current_terms() {
        let adds = vec![EffectSpec::parse("deadtime").unwrap()];
        let lib = Library::with_effects(Plant::Torque, 4.0, 1.0, &adds).unwrap();
        assert_eq!(lib.len(), 16);
        assert!(lib
            .candidates
            .iter()
            .all(|c| !c.term.has_current() && !c.allowed[IDOT]));
    }
}
