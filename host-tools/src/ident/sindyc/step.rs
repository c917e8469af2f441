//! One step of the SINDYc free run: an exponential Rosenbrock–Euler step `s⁺ = s + h·φ1(h·A)·f(s)`
//! (A: the Jacobian by forward differences), halved while it carries a state across the kink
//! of a sign-like term. The step is the free run's whole cost, so three things are shared
//! without changing a bit of the result:
//! - **The terms' factors across the Jacobian's lanes.** Every term is `g(x, ẋ, I, u)·h(z)`;
//!   a lane that perturbs one state re-evaluates only the factors that depend on it (the
//!   current's lane recomputes no `tanh` nor `exp`), and sums the equations in the same
//!   order as a full evaluation.
//! - **The structure of `A`.** Its columns are zero but for the states the model depends
//!   on, and so are those of its powers; [`phi1_structured`] computes only the products
//!   that are not zero by construction. A skipped product is `±0`, and a sum that starts at
//!   `+0` is unchanged by adding `±0`, so the result is [`phi1_times`]'s to the bit whenever
//!   the matrices stay finite (when a squaring overflows, [`phi1_times`] itself is used).
//! - **A halved step from the same state.** Its slope is the full step's, and `h/2·A`
//!   scaled by `2^−(s−1)` is the full step's scaled matrix exactly: its `φ1` is the full
//!   step's after one squaring fewer, which [`Phi`] keeps.
use crate::ident::freerun;
use control::effects::{CURRENT_EPS, VELOCITY_EPS};
use control::sindy::{SindyModel, Term, TermInputs};

/// Most halvings of one (sub-)step by [`Stepper::advance`]: enough to resolve a start from rest
/// under full voltage (about 10 levels on the paper's motor), while a candidate model that
/// chatters about zero velocity cannot make a sample cost more than this many extra steps.
pub(super) const MAX_SPLITS: usize = 64;

/// Largest change of a bristle state (`|ẋ|·z` in the model) in one step, as a fraction of
/// its bound `z_max`: while the bristle turns over at a reversal its equation's slope in
/// `ẋ` falls from `2/z_ss` to 0 and the rotor's presliding damping with it, so a step
/// whose Jacobian is frozen at its start must see only a small part of the turn. A
/// twentieth keeps a whole turnover within about 40 steps, inside [`MAX_SPLITS`];
/// docs/performance-sindyc.md compares the result with sub-steps.
const BRISTLE_TURN: f64 = 0.05;

/// Distance of a bristle state from saturation, as a fraction of `z_max`, below which its
/// damping is spent and a step may close it at once.
const BRISTLE_GAP: f64 = 1e-4;

/// Multiple of a sign-like term's width beyond which it is flat (`tanh(3) > 0.995`).
const KINK_REACH: f64 = 3.0;

/// The sign-like terms of a model as `(state, width)`: the state `(x, ẋ, z, I)` the term
/// switches on and the width over which it does (`1/a` for `tanh(a·ẋ)` and `tanh(a·z)`,
/// [`VELOCITY_EPS`] for the smooth signs of the velocity, the Stribeck velocity `vs`, and
/// [`CURRENT_EPS`] for the smooth sign of the current). A bristle state (`|ẋ|·z`) adds the
/// zero velocity and, as `(2, ∞)`, its own turnover ([`BRISTLE_TURN`]).
pub(super) fn sign_kinks(model: &SindyModel<f64>, voltage: bool) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64)> = Vec::new();
    let eqs = [&model.accel, &model.zdot];
    let terms = eqs
        .into_iter()
        .chain(voltage.then_some(&model.idot))
        .flat_map(|e| e.terms.iter().map(|(t, _)| *t));
    for t in terms {
        if t == Term::AbsXdotZ {
            // The bristle (`--add presliding`): `|ẋ|` switches at zero velocity, and the
            // step's frozen Jacobian holds only while the bristle turns over a little.
            for k in [(1, VELOCITY_EPS), (2, f64::INFINITY)] {
                if !out.contains(&k) {
                    out.push(k);
                }
            }
            continue;
        }
        let kink = match t {
            Term::TanhXdot => Some((1, 1.0 / model.a)),
            Term::TanhZ => Some((2, 1.0 / model.a)),
            Term::SgnXdot | Term::AbsSgnXdot | Term::AbsISgnXdot => Some((1, VELOCITY_EPS)),
            Term::StribeckXdot => Some((1, VELOCITY_EPS.min(model.vs))),
            Term::SgnI => Some((3, CURRENT_EPS)),
            _ => None,
        };
        if let Some((j, w)) = kink.filter(|(_, w)| w.is_finite() && *w > 0.0) {
            if !out.contains(&(j, w)) {
                out.push((j, w));
            }
        }
    }
    out
}

/// A term of the model's right-hand side and its coefficient.
#[derive(Debug, Clone, Copy)]
struct Slot {
    term: Term,
    coef: f64,
}

/// Most terms of a model's right-hand side (three equations).
const SLOTS: usize = 3 * control::sindy::MAX_TERMS;
/// Terms of a model whose step's scratch is small (the structure search's and refinement's
/// models have 5–16).
const FEW_SLOTS: usize = 16;

/// The states `(x, ẋ, z, I)` a term's z-free factor ([`Term::z_free_factor`]) depends on.
fn factor_dependencies(t: Term) -> [bool; 4] {
    let (x, xdot, i) = match t {
        Term::X | Term::SinTheta(_) | Term::CosTheta(_) => (true, false, false),
        Term::Xdot
        | Term::ZXdot
        | Term::Z2Xdot
        | Term::AbsXdotXdot
        | Term::AbsXdotXdot2
        | Term::ZXdot2
        | Term::AbsXdot
        | Term::AbsXdotZ
        | Term::TanhXdot
        | Term::SgnXdot
        | Term::AbsSgnXdot
        | Term::StribeckXdot => (false, true, false),
        Term::AbsISgnXdot => (false, true, true),
        Term::I | Term::SgnI | Term::ISquared | Term::ICubed => (false, false, true),
        Term::Z
        | Term::TanhZ
        | Term::AbsZZ
        | Term::AbsZZ2
        | Term::One
        | Term::U
        | Term::ZU
        | Term::Z2U
        | Term::ZU2 => (false, false, false),
    };
    [x, xdot, false, i]
}

/// The right-hand side `f(s)` at a state and its Jacobian's difference quotients
/// `(f(s + d·e_j) − f(s))/d` (columns of the states the model depends on; the others 0).
#[derive(Debug, Clone, Copy)]
pub(super) struct Slope {
    f0: [f64; 4],
    q: M4,
}

/// Most squarings whose results [`Phi`] keeps (a scaled norm up to `2^15`).
const PHI_KEEP: usize = 16;

/// A `φ1(A)·b` computation: the scaled matrix and vector, and the result after each number
/// of squarings (`g[k]` after `k`), so that a step with the same scaled inputs and fewer
/// squarings takes its result from here. `g` is empty when nothing is kept.
pub(super) struct Phi {
    m1: M4,
    c: [f64; 4],
    g: heapless::Vec<[f64; 4], PHI_KEEP>,
}

impl Phi {
    fn empty() -> Self {
        Phi {
            m1: [[0.0; 4]; 4],
            c: [0.0; 4],
            g: heapless::Vec::new(),
        }
    }

    /// The result after `s` squarings when the scaled inputs are `m1` and `c` and it was
    /// kept.
    fn after(&self, m1: &M4, c: &[f64; 4], s: usize) -> Option<[f64; 4]> {
        let same = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits());
        let g = self.g.get(s)?;
        (same(m1.as_flattened(), self.m1.as_flattened()) && same(c, &self.c)).then_some(*g)
    }
}

/// What every step of one free run shares: the model's terms, the states its right-hand
/// side depends on, the sign-like kinks a step must not jump, and the bound on `z`.
pub(super) struct Stepper {
    /// The terms, equation after equation (`ẋ`, `z`, `I`).
    slots: Vec<Slot>,
    /// The slots of each equation (`ẋ`, `z`, `I`).
    ranges: [std::ops::Range<usize>; 3],
    /// For each state `(x, ẋ, z, I)`, the slots whose value depends on it.
    lanes: [Vec<usize>; 4],
    a: f64,
    vs: f64,
    deps: [bool; 4],
    /// `deps` as bits (`ẋ` always).
    mask: u8,
    kinks: Vec<(usize, f64)>,
    zb: f64,
    /// `1/(k+1)!` for `k = 0..11`.
    coef: [f64; 12],
}

impl Stepper {
    pub(super) fn new(model: &SindyModel<f64>, voltage: bool) -> Self {
        let mut slots = Vec::new();
        let mut ranges = [0..0, 0..0, 0..0];
        let mut lanes: [Vec<usize>; 4] = Default::default();
        let eqs = [
            Some(&model.accel),
            Some(&model.zdot),
            voltage.then_some(&model.idot),
        ];
        for (range, e) in ranges.iter_mut().zip(eqs) {
            let start = slots.len();
            for &(term, coef) in e.iter().flat_map(|e| &e.terms) {
                let mut deps = factor_dependencies(term);
                deps[2] = term.has_z();
                for (lane, _) in lanes.iter_mut().zip(deps).filter(|(_, d)| *d) {
                    lane.push(slots.len());
                }
                slots.push(Slot { term, coef });
            }
            *range = start..slots.len();
        }
        let mut coef = [0.0; 12];
        let mut f = 1.0;
        for (k, c) in coef.iter_mut().enumerate() {
            f *= (k + 1) as f64;
            *c = 1.0 / f;
        }
        let deps = state_dependencies(model, voltage);
        Stepper {
            slots,
            ranges,
            lanes,
            a: model.a,
            vs: model.vs,
            deps,
            mask: deps
                .iter()
                .enumerate()
                .fold(0, |m, (j, d)| m | (u8::from(*d) << j)),
            kinks: sign_kinks(model, voltage),
            zb: model.z_bound(),
            coef,
        }
    }

    /// Whether the right-hand side depends on the angle.
    pub(super) fn uses_angle(&self) -> bool {
        self.deps[0]
    }

    /// The right-hand side `[ẋ, f_ẋ, f_z, f_I]` from each term's value: each equation the
    /// sum of its terms in order (as [`control::sindy::SparseEq::eval`] sums them).
    fn sums(&self, xdot: f64, values: &[f64]) -> [f64; 4] {
        let eq = |r: &std::ops::Range<usize>| {
            self.slots[r.clone()]
                .iter()
                .zip(&values[r.clone()])
                .fold(0.0, |acc, (sl, v)| acc + sl.coef * v)
        };
        [
            xdot,
            eq(&self.ranges[0]),
            eq(&self.ranges[1]),
            eq(&self.ranges[2]),
        ]
    }

    /// `f(s)` and the Jacobian's difference quotients (forward differences: the Jacobian
    /// only shapes the step's stability and its O(h²) error, so 1e-7 relative accuracy is
    /// plenty). A perturbed state's lane re-evaluates only the factors that depend on it.
    pub(super) fn slope(&self, s: &[f64; 4], u: f64) -> Slope {
        // Scratch on the stack, sized for the model (most have a few terms).
        if self.slots.len() <= FEW_SLOTS {
            self.slope_in::<FEW_SLOTS>(s, u)
        } else {
            self.slope_in::<SLOTS>(s, u)
        }
    }

    /// [`Self::slope`] for at most `N` terms.
    fn slope_in<const N: usize>(&self, s: &[f64; 4], u: f64) -> Slope {
        let (a, vs) = (self.a, self.vs);
        let inputs = |s: &[f64; 4]| TermInputs {
            x: s[0],
            xdot: s[1],
            z: s[2],
            i: s[3],
            u,
        };
        let p = inputs(s);
        // Each term's factors g and h(z), and its value g·h.
        let (mut g, mut h, mut v) = ([0.0; N], [0.0; N], [0.0; N]);
        for (k, sl) in self.slots.iter().enumerate() {
            g[k] = sl.term.z_free_factor(&p, a, vs);
            h[k] = sl.term.z_part().eval(p.z, a);
            v[k] = g[k] * h[k];
        }
        let f0 = self.sums(s[1], &v);
        let mut q = [[0.0; 4]; 4];
        for j in (0..4).filter(|j| self.deps[*j]) {
            let d = 1e-7 * s[j].abs().max(1e-2);
            let mut sp = *s;
            sp[j] += d;
            let pp = inputs(&sp);
            let mut w = v;
            for &k in &self.lanes[j] {
                let t = self.slots[k].term;
                w[k] = if j == 2 {
                    g[k] * t.z_part().eval(sp[2], a)
                } else {
                    t.z_free_factor(&pp, a, vs) * h[k]
                };
            }
            let fp = self.sums(sp[1], &w);
            for i in 0..4 {
                q[i][j] = (fp[i] - f0[i]) / d;
            }
        }
        Slope { f0, q }
    }

    /// One step of length `h` from `s`, halved (recursively, at most `splits` times in all)
    /// while it carries a state across the kink of a sign-like term: the step's Jacobian is
    /// frozen at its start, and a sign's slope at zero (`a` = 5 s/rad makes `tanh(a·ẋ)` a
    /// damping of hundreds of 1/s) would act over the whole step although the term saturates
    /// as soon as the velocity leaves the kink. A step counts as crossing a kink of width `w`
    /// when the state moves by more than `w` and the range it covers reaches within
    /// [`KINK_REACH`]·`w` of zero. `z` is clamped to `±zb` after every step.
    /// With `incs` (a run whose steps do not depend on the angle, started at angle -0), the
    /// angle restarts at -0 after every halved step but the last, whose increment is pushed on
    /// `incs`: the returned angle is the last one's increment, so the angle a run from the true
    /// angle reaches is its angle plus each increment in turn. `known`: the slope at `s` and
    /// a `φ1` computation of a longer step from `s`, when a halving already made them.
    pub(super) fn advance(
        &self,
        s: &[f64; 4],
        u: f64,
        h: f64,
        splits: &mut usize,
        mut incs: Option<&mut Vec<f64>>,
        known: Option<(&Slope, &Phi)>,
    ) -> Option<[f64; 4]> {
        let own;
        let slope = match known {
            Some((sl, _)) => sl,
            None => {
                own = self.slope(s, u);
                &own
            }
        };
        let mut phi = Phi::empty();
        let mut next = self.rosenbrock(s, slope, h, known.map(|k| k.1), &mut phi)?;
        let zb = self.zb;
        next[2] = next[2].clamp(-zb, zb);
        let crosses = self.kinks.iter().any(|&(j, w)| {
            let (a, b) = (s[j], next[j]);
            if j == 2 && w.is_infinite() {
                // The turn, and its end: the bristle's damping is proportional to its distance
                // from saturation, which a step must not close by more than half at once.
                let (ga, gb) = (zb - a.abs(), zb - b.abs());
                return (b - a).abs() > BRISTLE_TURN * zb
                    || (ga - gb).abs() > 0.5 * ga.max(gb) && ga.max(gb) > BRISTLE_GAP * zb;
            }
            (b - a).abs() > w && a.min(b) < KINK_REACH * w && a.max(b) > -KINK_REACH * w
        });
        if !crosses || *splits == 0 {
            return Some(next);
        }
        *splits -= 1;
        let longer = match known {
            Some((_, p)) if phi.g.is_empty() => p,
            _ => &phi,
        };
        let first = (slope, longer);
        let mut mid = self.advance(s, u, h / 2.0, splits, incs.as_deref_mut(), Some(first))?;
        if let Some(v) = incs.as_deref_mut() {
            v.push(mid[0]);
            mid[0] = -0.0;
        }
        self.advance(&mid, u, h / 2.0, splits, incs, None)
    }

    /// `s + h·φ1(h·A)·f(s)` from the slope at `s`; `None` when `φ1` is out of range
    /// ([`phi1_times`]). The `φ1` computation is kept in `phi` when it was made here, and
    /// taken from `longer` when that one's scaled inputs are this step's.
    fn rosenbrock(
        &self,
        s: &[f64; 4],
        slope: &Slope,
        h: f64,
        longer: Option<&Phi>,
        phi: &mut Phi,
    ) -> Option<[f64; 4]> {
        let mut a = [[0.0; 4]; 4];
        for j in (0..4).filter(|j| self.deps[*j]) {
            for (row, q) in a.iter_mut().zip(&slope.q) {
                row[j] = q[j] * h;
            }
        }
        let b = slope.f0.map(|f| f * h);
        let step = match self.mask {
            0b0010 => phi1_structured::<0b0010>(&a, &b, &self.coef, longer, phi),
            0b0011 => phi1_structured::<0b0011>(&a, &b, &self.coef, longer, phi),
            0b0110 => phi1_structured::<0b0110>(&a, &b, &self.coef, longer, phi),
            0b0111 => phi1_structured::<0b0111>(&a, &b, &self.coef, longer, phi),
            0b1010 => phi1_structured::<0b1010>(&a, &b, &self.coef, longer, phi),
            0b1011 => phi1_structured::<0b1011>(&a, &b, &self.coef, longer, phi),
            0b1110 => phi1_structured::<0b1110>(&a, &b, &self.coef, longer, phi),
            _ => phi1_structured::<0b1111>(&a, &b, &self.coef, longer, phi),
        }?;
        let mut out = *s;
        for i in 0..4 {
            out[i] += step[i];
        }
        Some(out)
    }
}

/// `⌈log2 x⌉` for a finite `x > 1` as `x.log2().ceil()` gives it: from the exponent alone
/// where the mantissa is far enough from 1 and 2 that the logarithm's rounding cannot reach
/// an integer, else by the logarithm.
fn ceil_log2(x: f64) -> i32 {
    const NEAR: u64 = 1 << 32;
    const FRAC: u64 = (1 << 52) - 1;
    let bits = x.to_bits();
    let frac = bits & FRAC;
    if frac > NEAR && frac < FRAC - NEAR {
        ((bits >> 52) & 0x7ff) as i32 - 1022
    } else {
        x.log2().ceil() as i32
    }
}

/// The columns in `MASK` in ascending order, and how many they are.
struct Columns<const MASK: u8>;

impl<const MASK: u8> Columns<MASK> {
    const LIST: ([usize; 4], usize) = {
        let mut list = [0; 4];
        let mut n = 0;
        let mut k = 0;
        while k < 4 {
            if (MASK >> k) & 1 == 1 {
                list[n] = k;
                n += 1;
            }
            k += 1;
        }
        (list, n)
    };
    const IDX: [usize; 4] = Self::LIST.0;
    const N: usize = Self::LIST.1;

    const fn has(k: usize) -> bool {
        (MASK >> k) & 1 == 1
    }
}

/// `a·b` where `a`'s columns outside `MASK` are zero and so are `b`'s entries in rows
/// inside `MASK` and columns outside it: the columns outside `MASK` of the product are zero.
#[inline(always)]
fn mul_masked<const MASK: u8>(a: &M4, b: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for jj in 0..Columns::<MASK>::N {
            let j = Columns::<MASK>::IDX[jj];
            let mut v = 0.0;
            for kk in 0..Columns::<MASK>::N {
                let k = Columns::<MASK>::IDX[kk];
                v += a[i][k] * b[k][j];
            }
            c[i][j] = v;
        }
    }
    c
}

/// `e·e` where `e`'s columns outside `MASK` are columns of the identity: they stay so, and
/// in the others only the products with `e[i][k]` not zero by construction are summed
/// (`k` in `MASK`, or `k = i`), in ascending `k`.
#[inline(always)]
fn square_masked<const MASK: u8>(e: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for (i, row) in c.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            if !Columns::<MASK>::has(j) {
                *v = if i == j { 1.0 } else { 0.0 };
            }
        }
    }
    for i in 0..4 {
        for jj in 0..Columns::<MASK>::N {
            let j = Columns::<MASK>::IDX[jj];
            let mut sum = 0.0;
            for (k, (eik, ek)) in e[i].iter().zip(e).enumerate() {
                if Columns::<MASK>::has(k) || k == i {
                    sum += eik * ek[j];
                }
            }
            c[i][j] = sum;
        }
    }
    c
}

/// [`phi1_times`] for an `a` whose columns outside `MASK` are zero, with the same
/// operations on every entry that is not zero by construction: the same result to the bit
/// (see the module doc). With `longer` (a computation from the same slope for a step 2^k
/// times as long) whose scaled inputs are this one's, its result after this one's number of
/// squarings is returned; else the computation is kept in `phi`.
#[inline(always)]
fn phi1_structured<const MASK: u8>(
    a: &M4,
    b: &[f64; 4],
    coef: &[f64; 12],
    longer: Option<&Phi>,
    phi: &mut Phi,
) -> Option<[f64; 4]> {
    let norm = phi_norm(a, b)?;
    let s = if norm > 0.5 { ceil_log2(norm / 0.5) } else { 0 };
    // 2^−s exactly (s ≤ 61 for a norm within EXPM_MAX_NORM).
    let scale = f64::from_bits(((1023 - s) as u64) << 52);
    let s = s as usize;
    let m1 = a.map(|r| r.map(|v| v * scale));
    let c = b.map(|v| v * scale);
    if let Some(g) = longer.and_then(|p| p.after(&m1, &c, s)) {
        return Some(g);
    }
    let m2 = mul_masked::<MASK>(&m1, &m1);
    let m3 = mul_masked::<MASK>(&m2, &m1);
    let m4 = mul_masked::<MASK>(&m2, &m2);
    // The Taylor blocks: the columns outside MASK hold the identity's multiple only.
    let block = |j: usize| -> M4 {
        let mut q = [[0.0; 4]; 4];
        for (r, row) in q.iter_mut().enumerate() {
            for cc in 0..Columns::<MASK>::N {
                let col = Columns::<MASK>::IDX[cc];
                row[col] = coef[4 * j + 1] * m1[r][col]
                    + coef[4 * j + 2] * m2[r][col]
                    + coef[4 * j + 3] * m3[r][col];
            }
            row[r] += coef[4 * j];
        }
        q
    };
    let add_masked = |x: &mut M4, y: &M4| {
        for (xr, yr) in x.iter_mut().zip(y) {
            for cc in 0..Columns::<MASK>::N {
                let col = Columns::<MASK>::IDX[cc];
                xr[col] += yr[col];
            }
        }
    };
    let (q0, q1, q2) = (block(0), block(1), block(2));
    let inner = mul_masked::<MASK>(&m4, &q2);
    let mut mid = q1;
    add_masked(&mut mid, &inner);
    let outer = mul_masked::<MASK>(&m4, &mid);
    let mut p = q0;
    add_masked(&mut p, &outer);
    let mut g = mul4v(&p, &c);
    let keep = s < PHI_KEEP;
    phi.g.clear();
    if keep {
        phi.m1 = m1;
        phi.c = c;
        let _ = phi.g.push(g);
    }
    if s > 0 {
        let mut e = mul_masked::<MASK>(&m1, &p);
        for (r, row) in e.iter_mut().enumerate() {
            row[r] += 1.0;
        }
        for k in 0..s {
            let eg = mul4v(&e, &g);
            for (gi, v) in g.iter_mut().zip(eg) {
                *gi += v;
            }
            if keep {
                let _ = phi.g.push(g);
            }
            if k + 1 < s {
                e = square_masked::<MASK>(&e);
            }
        }
        // A non-finite entry stays so through every later squaring (its product with the
        // diagonal is summed), so a finite last power means every product skipped was a
        // finite one with a zero; otherwise the plain computation.
        if !e.iter().flatten().all(|v| v.is_finite()) {
            phi.g.clear();
            return phi1_times(a, b);
        }
    }
    Some(g)
}

/// Which states `(x, ẋ, z, I)` the right-hand side depends on: `ẋ` always (`dx/dt = ẋ`),
/// `x`, `z` and `I` only when a term of the model contains them (`I` only for a voltage
/// plant: with a torque plant it stays 0). The Jacobian's other columns are zero.
fn state_dependencies(model: &SindyModel<f64>, voltage: bool) -> [bool; 4] {
    let terms = || {
        model
            .accel
            .terms
            .iter()
            .chain(&model.zdot.terms)
            .chain(model.idot.terms.iter().filter(|_| voltage))
            .map(|(t, _)| *t)
    };
    [
        terms().any(|t| matches!(t, Term::X | Term::SinTheta(_) | Term::CosTheta(_))),
        true,
        terms().any(Term::has_z),
        voltage && terms().any(Term::has_current),
    ]
}

pub(super) type M4 = [[f64; 4]; 4];

fn mul4(a: &M4, b: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for k in 0..4 {
            let aik = a[i][k];
            for j in 0..4 {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

/// [`mul4`] for a finite `b`, skipping the zeros of `a` (a Jacobian's columns of the states
/// the model does not depend on, and their powers): a skipped term is `±0`, and a sum that
/// starts at `+0` is never `−0`, so adding it changes no bit of the product.
fn mul4_sparse(a: &M4, b: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for k in 0..4 {
            let aik = a[i][k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..4 {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

fn mul4v(a: &M4, v: &[f64; 4]) -> [f64; 4] {
    let mut out = [0.0; 4];
    for (o, r) in out.iter_mut().zip(a) {
        *o = r[0] * v[0] + r[1] * v[1] + r[2] * v[2] + r[3] * v[3];
    }
    out
}

/// The ∞-norm of `A` (largest absolute row sum), or `None` when `A` or `b` is not finite
/// or the norm is beyond [`freerun::EXPM_MAX_NORM`]: the input check of both φ1 products.
fn phi_norm(a: &M4, b: &[f64; 4]) -> Option<f64> {
    let norm = a
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let finite = a.iter().flatten().chain(b).all(|v| v.is_finite());
    (finite && norm <= freerun::EXPM_MAX_NORM).then_some(norm)
}

/// `φ1(A)·b` with `φ1(A) = Σ_k A^k/(k+1)!`: the last column of the exponential of the
/// augmented matrix `[[A, b], [0, 0]]` ([`freerun::expm`]), computed without forming it.
/// Scaling and squaring: `A` and `b` are scaled by `2^−s` so that `‖A‖∞ ≤ 1/2` (the
/// augmented column does not enter the norm: the result is linear in `b`), `φ1` of the
/// scaled matrix is its Taylor polynomial of degree 11 (truncation < 4e-14 relative)
/// evaluated by Paterson–Stockmeyer in powers of `A⁴` (6 products of 4×4 matrices instead
/// of 11), and each squaring of the augmented matrix maps `(E, g)` to `(E², E·g + g)`.
/// `None` when `A` or `b` is not finite or `‖A‖` is beyond [`freerun::EXPM_MAX_NORM`].
pub fn phi1_times(a: &M4, b: &[f64; 4]) -> Option<[f64; 4]> {
    let norm = phi_norm(a, b)?;
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let m1 = a.map(|r| r.map(|v| v * scale));
    let c = b.map(|v| v * scale);
    let m2 = mul4_sparse(&m1, &m1);
    let m3 = mul4_sparse(&m2, &m1);
    let m4 = mul4_sparse(&m2, &m2);
    // 1/(k+1)! for k = 0..11.
    let mut coef = [0.0; 12];
    let mut f = 1.0;
    for (k, c) in coef.iter_mut().enumerate() {
        f *= (k + 1) as f64;
        *c = 1.0 / f;
    }
    let block = |j: usize| -> M4 {
        let mut q = [[0.0; 4]; 4];
        for (r, row) in q.iter_mut().enumerate() {
            for (col, v) in row.iter_mut().enumerate() {
                *v = coef[4 * j + 1] * m1[r][col]
                    + coef[4 * j + 2] * m2[r][col]
                    + coef[4 * j + 3] * m3[r][col];
            }
            row[r] += coef[4 * j];
        }
        q
    };
    let (q0, q1, q2) = (block(0), block(1), block(2));
    let inner = mul4_sparse(&m4, &q2);
    let mut mid = q1;
    for (r, row) in mid.iter_mut().enumerate() {
        for (v, w) in row.iter_mut().zip(inner[r]) {
            *v += w;
        }
    }
    let outer = mul4_sparse(&m4, &mid);
    let mut p = q0;
    for (r, row) in p.iter_mut().enumerate() {
        for (v, w) in row.iter_mut().zip(outer[r]) {
            *v += w;
        }
    }
    let mut g = mul4v(&p, &c);
    if s == 0 {
        return Some(g);
    }
    // E = exp(B) = I + B·φ1(B).
    let mut e = mul4_sparse(&m1, &p);
    for (r, row) in e.iter_mut().enumerate() {
        row[r] += 1.0;
    }
    for k in 0..s {
        let eg = mul4v(&e, &g);
        for (gi, v) in g.iter_mut().zip(eg) {
            *gi += v;
        }
        if k + 1 < s {
            e = mul4(&e, &e);
        }
    }
    Some(g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::sindy::SparseEq;
    use proptest::prelude::*;

    /// The right-hand side as the firmware's equations evaluate it, term after term.
    fn plain_rhs(m: &SindyModel<f64>, voltage: bool, s: &[f64; 4], u: f64) -> [f64; 4] {
        let p = TermInputs {
            x: s[0],
            xdot: s[1],
            z: s[2],
            i: s[3],
            u,
        };
        let di = if voltage { m.idot_rhs(&p) } else { 0.0 };
        [s[1], m.accel_rhs(&p), m.zdot_rhs(&p), di]
    }

    /// The step as one plain computation: the Jacobian from full evaluations of the
    /// right-hand side and [`phi1_times`].
    fn plain_step(
        m: &SindyModel<f64>,
        voltage: bool,
        s: &[f64; 4],
        u: f64,
        h: f64,
    ) -> Option<[f64; 4]> {
        let deps = state_dependencies(m, voltage);
        let f0 = plain_rhs(m, voltage, s, u);
        let mut a = [[0.0; 4]; 4];
        for j in (0..4).filter(|j| deps[*j]) {
            let d = 1e-7 * s[j].abs().max(1e-2);
            let mut sp = *s;
            sp[j] += d;
            let fp = plain_rhs(m, voltage, &sp, u);
            for i in 0..4 {
                a[i][j] = (fp[i] - f0[i]) / d * h;
            }
        }
        let g = phi1_times(&a, &f0.map(|f| f * h))?;
        Some([s[0] + g[0], s[1] + g[1], s[2] + g[2], s[3] + g[3]])
    }

    fn term() -> impl Strategy<Value = Term> {
        prop_oneof![
            proptest::sample::select(Term::FIXED.to_vec()),
            (1u16..8).prop_map(Term::SinTheta),
            (1u16..8).prop_map(Term::CosTheta),
        ]
    }

    fn equation() -> impl Strategy<Value = SparseEq<f64>> {
        proptest::collection::vec((term(), -300.0..300.0f64), 0..6)
            .prop_map(|t| SparseEq::from_slice(&t).unwrap())
    }

    fn model() -> impl Strategy<Value = SindyModel<f64>> {
        (
            equation(),
            equation(),
            equation(),
            0.5..100.0f64,
            0.5..20.0f64,
        )
            .prop_map(|(accel, zdot, idot, a, vs)| {
                let mut m = SindyModel::empty(a, vs, 1.0);
                m.z_max = 3.0;
                m.accel = accel;
                m.zdot = zdot;
                m.idot = idot;
                m
            })
    }

    #[test]
    fn the_factors_depend_on_no_state_but_those_listed() {
        // Near zero velocity and current, where the smooth signs are not saturated.
        let base = [0.3, 0.004, 0.4, 0.002];
        for t in Term::FIXED
            .into_iter()
            .chain([Term::SinTheta(3), Term::CosTheta(2)])
        {
            let deps = factor_dependencies(t);
            let g = |s: &[f64; 4]| {
                let p = TermInputs {
                    x: s[0],
                    xdot: s[1],
                    z: s[2],
                    i: s[3],
                    u: 1.5,
                };
                t.z_free_factor(&p, 5.0, 2.0)
            };
            for j in 0..4 {
                let mut s = base;
                s[j] += 0.25;
                assert_eq!(g(&s) != g(&base), deps[j], "{t} in state {j}");
            }
        }
    }

    #[test]
    fn ceil_log2_is_the_logarithm_s() {
        let mut x = 1.0f64;
        while x < 1e19 {
            for y in [
                x,
                x * (1.0 + 1e-16),
                x * 1.3,
                x * 1.999999,
                x * 2.0 * (1.0 - 1e-16),
            ] {
                let y = if y > 1.0 { y } else { 1.0 + f64::EPSILON };
                assert_eq!(ceil_log2(y), y.log2().ceil() as i32, "{y:e}");
            }
            x *= 2.0;
        }
    }

    proptest! {
        #[test]
        fn ceil_log2_agrees_with_the_logarithm(x in 1.0000001f64..1e18) {
            prop_assert_eq!(ceil_log2(x), x.log2().ceil() as i32);
        }

        #[test]
        fn a_step_is_the_plain_computation_s_to_the_bit(
            m in model(),
            voltage: bool,
            s in proptest::array::uniform4(-5.0..5.0f64),
            u in -10.0..10.0f64,
            h in prop_oneof![Just(0.012), 1e-5..0.1f64],
        ) {
            let stepper = Stepper::new(&m, voltage);
            let slope = stepper.slope(&s, u);
            // The full step, then its halves from the same state with the full one's φ1 kept.
            let mut phi = Phi::empty();
            let full = stepper.rosenbrock(&s, &slope, h, None, &mut phi);
            let want = plain_step(&m, voltage, &s, u, h);
            prop_assert_eq!(full.map(|v| v.map(f64::to_bits)), want.map(|v| v.map(f64::to_bits)));
            for k in 1..4 {
                let hk = h / f64::from(1 << k);
                let mut own = Phi::empty();
                let half = stepper.rosenbrock(&s, &slope, hk, Some(&phi), &mut own);
                let want = plain_step(&m, voltage, &s, u, hk);
                prop_assert_eq!(half.map(|v| v.map(f64::to_bits)), want.map(|v| v.map(f64::to_bits)));
            }
        }

        #[test]
        fn structured_phi1_is_phi1_times_to_the_bit(
            mask in prop_oneof![Just(0b0010u8), Just(0b1010), Just(0b0110), Just(0b1111)],
            entries in proptest::array::uniform16(-1.0..1.0f64),
            b in proptest::array::uniform4(-1e3..1e3f64),
            scale in prop_oneof![Just(1e-3), Just(1.0), Just(30.0), Just(1e4), Just(1e12)],
        ) {
            let mut a = [[0.0; 4]; 4];
            for (k, v) in entries.iter().enumerate() {
                let (i, j) = (k / 4, k % 4);
                if (mask >> j) & 1 == 1 {
                    a[i][j] = v * scale;
                }
            }
            let stepper = Stepper::new(&SindyModel::empty(1.0, 1.0, 1.0), false);
            let mut phi = Phi::empty();
            let got = match mask {
                0b0010 => phi1_structured::<0b0010>(&a, &b, &stepper.coef, None, &mut phi),
                0b1010 => phi1_structured::<0b1010>(&a, &b, &stepper.coef, None, &mut phi),
                0b0110 => phi1_structured::<0b0110>(&a, &b, &stepper.coef, None, &mut phi),
                _ => phi1_structured::<0b1111>(&a, &b, &stepper.coef, None, &mut phi),
            };
            let want = phi1_times(&a, &b);
            prop_assert_eq!(got.map(|v| v.map(f64::to_bits)), want.map(|v| v.map(f64::to_bits)));
        }
    }

    #[test]
    fn phi1_times_is_the_last_column_of_the_augmented_exponential() {
        // Stiff and oscillatory matrices, norms from 0.1 to 300.
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for scale in [0.1, 1.0, 7.0, 40.0, 300.0] {
            let mut a = [[0.0; 4]; 4];
            for r in a.iter_mut() {
                for v in r.iter_mut() {
                    *v = scale * rnd();
                }
            }
            // A stable stiff diagonal, as the current equation's.
            for (k, r) in a.iter_mut().enumerate() {
                r[k] -= scale * k as f64;
            }
            let b = [rnd(), 10.0 * rnd(), rnd(), 100.0 * rnd()];
            let mut m = [[0.0; 5]; 5];
            for i in 0..4 {
                m[i][..4].copy_from_slice(&a[i]);
                m[i][4] = b[i];
            }
            let Some(e) = freerun::expm(&m) else { continue };
            let g = phi1_times(&a, &b).unwrap();
            // 1e-10: two evaluations of the same matrix function (scaling and squaring of
            // different sizes): rounding grows with the norm but stays far below this.
            for i in 0..4 {
                let want = e[i][4];
                assert!(
                    (g[i] - want).abs() <= 1e-10 * want.abs().max(1.0),
                    "norm {scale}, row {i}: {} vs {want}",
                    g[i]
                );
            }
        }
        assert!(phi1_times(&[[f64::NAN; 4]; 4], &[0.0; 4]).is_none());
    }
}
