//! Free-run simulation of a model with a log's input.
//!
//! The model starts from the log's first samples (angle, velocity, current) and then runs on
//! the log's input alone, `u` held constant between samples (zero-order hold), as the board
//! applies it. The plant is stiff at the 12 ms sample period (L/R ≈ 1.4 ms, LuGre σ0 ≈ 300
//! N·m/rad; the paper's σ1 = 22 N·m·s/rad damps the rotor in presliding with J/σ1 ≈ 14 µs).
//! Each sample is split into [`SUBSTEPS`] implicit sub-steps: backward Euler for (θ, ω), the
//! bristle state updated *exactly* for the new velocity (`control::lugre::z_step`), and the
//! winding's current exact for the held voltage with the velocity linear over the sub-step
//! ([`WindingWeights`]; the rotor integrates the current's mean). Stable at any step for a
//! rotor whose electrical braking takes longer than a sub-step (`R·J/(K_t·K_b) ≥ h`; below
//! that, backward Euler's weights, L-stable), and exact at equilibria (stiction). Backward
//! Euler's current would read the back-EMF half a sub-step early, an extra inertia
//! `K_t·K_b/R·h/2` (4 % of the paper motor's J at 1 ms) that a fit takes out of J
//! (decision 0030). The unknown of a sub-step is the new velocity: the
//! residual `J·(ω' − ω)/h − K_t·Ī(ω') + F_f(ω') + loads(ω')` increases with ω', so Newton's
//! method on its exact slope, kept in a bracket, finds it in two or three evaluations. An exponential
//! Rosenbrock scheme would diverge at LuGre breakaway, where the bilinear |ω|·z term changes
//! within a step.
//!
//! # Loads behind a coupling (`compliance`, `backlash`)
//! Each such effect adds a load inertia `j2` with its own angle and speed (θ2, ω2), coupled to
//! the rotor by the torque of `emulator::plant` (a spring-damper `k`, `c`; or a gap of `gap`
//! with a stiff, critically damped contact beyond it that never pulls). The load takes the
//! rotor's backward-Euler step inside the same solve: for a trial new rotor velocity the
//! load's new speed solves `j2·(ω2' − ω2)/h = τ_c(θ1' − θ2 − h·ω2', ω1' − ω2')`, in closed
//! form (linear for the spring; piecewise linear for the gap, [`load_step`]), and the rotor
//! feels `j2·(ω2' − ω2)/h`. That torque never falls as the rotor's new velocity rises, so the
//! sub-step is still one increasing scalar residual in one unknown, stable at any stiffness.
//! The contact of a gap has the stiffness `μ·(10/h)²` and damping `2·μ·10/h` of the emulator
//! (μ = J·j2/(J + j2)) at the sub-step `h`: an inelastic impact settled within a sub-step.
//!
//! The run is generic in its number type ([`RunScalar`]): in `f64` it is the simulation; in
//! dual numbers ([`super::tangent`]) the same code carries the states' derivatives with
//! respect to the model's parameters, for the exact Jacobian of the simulation error.
//!
//! SINDYc models are simulated by `ident::sindyc` (the equations live there).
use super::tangent::{lift_effect, RunScalar};
use crate::emulator::scalar_root::find_root;
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use anyhow::{bail, Result};
use control::effects::{self, Effect, EffectInputs};
use control::lugre::{z_step, LugreParams};
use control::motor::MotorParams;
use echidna::DualVec;

/// A free-run prediction, one value per log sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Prediction {
    pub t: Vec<f64>,
    /// Rotor angle [rad] (the model's true state, not quantised).
    pub theta: Vec<f64>,
    /// Velocity [rad/s] (true state).
    pub omega: Vec<f64>,
    /// Current as the sensor would measure it [A] (with any `current_offset`); None for
    /// `--plant torque`.
    pub i: Option<Vec<f64>>,
    /// Bristle deflection [rad] (LuGre models).
    pub z: Option<Vec<f64>>,
}

/// Number of implicit sub-steps per sample: 1 ms at 12 ms. Against the emulator's 0.2 ms
/// steps the velocity fit of the true model stays within ~1 point (tests), at 1/5 of the
/// cost, which the parameter search needs.
pub const SUBSTEPS: usize = 12;

/// Most loads behind a coupling (`compliance`, `backlash`) a free run carries.
pub const MAX_LOADS: usize = 2;

/// States of a run: θ, ω, I, z, then (θ2, ω2) of each load behind a coupling. A run's
/// state array holds exactly the loads its model has (length `4 + 2·loads`, a const
/// generic `N` of the sub-step's functions), so a model without a load carries four.
const fn state_len(loads: usize) -> usize {
    4 + 2 * loads
}

/// Contact stiffness of a backlash over the sub-step, as a frequency times the step (as
/// the emulator's): the critically damped contact rings at `CONTACT_FREQUENCY_STEPS / h`.
const CONTACT_FREQUENCY_STEPS: f64 = 10.0;

/// The new (θ2, ω2) of the load of effect `e` (a `compliance` or `backlash`; `None` for any
/// other effect) over a backward-Euler sub-step of length `h`, from its state `th2`, `w2`,
/// when the rotor (inertia `j`) ends the step at `th1`, `w1`: the root of
/// `j2·(ω2' − ω2)/h = τ_c(θ1' − θ2 − h·ω2', ω1' − ω2')`, in closed form. The spring's is
/// linear in ω2'. The gap's is increasing and piecewise linear: the load coasts (ω2' = ω2)
/// when no face touches at that speed; otherwise the contact's linear branch, unless its
/// root falls back inside the gap, where the residual jumps across zero at the face itself
/// (the load ends the step on it). The branch is chosen on the values (`re`), so a run in
/// dual numbers takes the branch of its `f64` run. A load of no inertia (`j2 ≤ 0`, an effect
/// at zero magnitude) follows the rotor.
fn load_step<D: RunScalar>(
    e: &Effect<D>,
    j: D,
    th1: D,
    w1: D,
    th2: D,
    w2: D,
    h: f64,
) -> Option<(D, D)> {
    let hd = D::constant(h);
    let w2n = match *e {
        Effect::Compliance { j2, k, c } => {
            if j2.re() <= 0.0 {
                return Some((th1, w1));
            }
            (j2 * w2 / hd + k * (th1 - th2) + c * w1) / (j2 / hd + k * hd + c)
        }
        Effect::Backlash { j2, gap } => {
            if j2.re() <= 0.0 {
                return Some((th1, w1));
            }
            let half = D::constant(0.5) * gap;
            let mu = j * j2 / (j + j2);
            let wc = D::constant(CONTACT_FREQUENCY_STEPS / h);
            let (kc, cc) = (mu * wc * wc, D::constant(2.0) * mu * wc);
            // The deflection and its rate if the load kept its speed.
            let (x0, v0) = ((th1 - th2 - hd * w2).re(), (w1 - w2).re());
            let (kr, cr, hr) = (kc.re(), cc.re(), half.re());
            let pushes = x0 > hr && kr * (x0 - hr) + cr * v0 > 0.0;
            let pulls = x0 < -hr && kr * (x0 + hr) + cr * v0 < 0.0;
            if pushes || pulls {
                let face = if pushes { half } else { -half };
                let lin =
                    (j2 * w2 / hd + kc * (th1 - th2 - face) + cc * w1) / (j2 / hd + kc * hd + cc);
                let x = (th1 - th2 - hd * lin).re();
                if (pushes && x > hr) || (pulls && x < -hr) {
                    lin
                } else {
                    (th1 - th2 - face) / hd
                }
            } else {
                w2
            }
        }
        _ => return None,
    };
    Some((th2 + hd * w2n, w2n))
}

/// The number of loads behind a coupling among `effects`.
pub fn load_count<D>(effects: &[Effect<D>]) -> usize {
    effects
        .iter()
        .filter(|e| matches!(e, Effect::Compliance { .. } | Effect::Backlash { .. }))
        .count()
}

/// The numbers of a (non-SINDYc) model that its free run reads, in the number type the run
/// computes in (`f64`, or a dual number carrying sensitivities, [`super::tangent`]).
#[derive(Debug, Clone)]
pub struct RunParams<D> {
    pub motor: MotorParams<D>,
    /// The LuGre law; `None` for the other kinds (viscous friction).
    pub lugre: Option<LugreParams<D>>,
    /// Viscous friction of a linear model [N·m·s/rad].
    pub viscous: D,
    /// Width of the effects' smooth sign [rad/s] (`Model::sign_width`).
    pub sign_width: D,
    pub effects: Vec<Effect<D>>,
    pub plant: Plant,
}

impl<D: RunScalar> RunParams<D> {
    /// The numbers of `model` as constants.
    pub fn of(model: &Model) -> Self {
        RunParams {
            motor: model.motor,
            lugre: match (&model.lugre, model.kind) {
                (Some(l), ModelKind::Lugre) => Some(*l),
                _ => None,
            },
            viscous: model.viscous,
            sign_width: model.sign_width,
            effects: model.effects.clone(),
            plant: model.plant,
        }
        .lift()
    }
}

impl RunParams<f64> {
    /// The same numbers as constants of another number type.
    pub fn lift<D: RunScalar>(&self) -> RunParams<D> {
        let c = D::constant;
        let (m, l) = (&self.motor, &self.lugre);
        RunParams {
            motor: MotorParams {
                r: c(m.r),
                l: c(m.l),
                kt: c(m.kt),
                kb: c(m.kb),
                j: c(m.j),
            },
            lugre: l.map(|l| LugreParams {
                alpha0: c(l.alpha0),
                alpha1: c(l.alpha1),
                alpha2: c(l.alpha2),
                v0: c(l.v0),
                sigma0: c(l.sigma0),
                sigma1: c(l.sigma1),
            }),
            viscous: c(self.viscous),
            sign_width: c(self.sign_width),
            effects: self.effects.iter().map(lift_effect).collect(),
            plant: self.plant,
        }
    }
}

/// The residual of a sub-step of length `h` from state `x` (input `u`, heat state `h_th`)
/// at the new velocity `w`, and the new state: `J·(w − ω)/h − K_t·Ī(w) + F_f(w) + loads(w)`,
/// with the current's mean `Ī(w)` over the sub-step from the winding's exact step
/// ([`WindingWeights`]) and the bristle state updated
/// exactly for `w` (`control::lugre::z_step`). `re` holds the values of `p` (for the
/// winding's scalar root with a voltage loss, solved in `f64`); `w8` the winding's weights
/// over the sub-step ([`winding_of`]).
#[allow(clippy::too_many_arguments)]
fn substep_residual<D: RunScalar, const N: usize>(
    p: &RunParams<D>,
    re: &RunParams<f64>,
    x: &[D; N],
    u: f64,
    h_th: D,
    h: f64,
    w8: &WindingWeights<D>,
    w: D,
) -> (D, [D; N]) {
    let m = &p.motor;
    let hd = D::constant(h);
    // The winding's current at the end of the sub-step and its mean over it (what the
    // rotor's torque integrates), for a velocity changing linearly over the sub-step.
    let (current, mean_current) = match p.plant {
        Plant::Torque => (D::constant(u), D::constant(u)),
        Plant::Voltage => {
            let r = m.r * (D::one() + h_th);
            let a = w8.inductance + r;
            let emf_speed = w8.start * x[1] + (D::one() - w8.start) * w;
            let rhs = w8.inductance * x[2] + D::constant(u) - m.kb * emf_speed;
            let vloss_max: f64 = re.effects.iter().map(|e| e.voltage_loss(1e9).abs()).sum();
            let end = if vloss_max == 0.0 {
                rhs / a
            } else {
                let (ar, rr) = (a.re(), rhs.re());
                let i = find_root(
                    |i| ar * i + effects::total_voltage_loss(&re.effects, i) - rr,
                    rr / ar,
                    vloss_max / ar + 1e-12,
                    1e-12 * (1.0 + (rr / ar).abs()),
                );
                // The slope of the voltage loss in the current, exact (one dual lane).
                let id = DualVec::<f64, 1>::with_tangent(i, 0);
                let dloss: f64 = re
                    .effects
                    .iter()
                    .map(|e| lift_effect::<DualVec<f64, 1>>(e).voltage_loss(id).eps[0])
                    .sum();
                let ic = D::constant(i);
                let g = a * ic + effects::total_voltage_loss(&p.effects, ic) - rhs;
                D::root(i, g, ar + dloss)
            };
            // The mean over the sub-step: the weights of the two currents, and the
            // velocity's change through the back-EMF (exact for the held voltage and linear
            // velocity; with a voltage loss, the loss held at its end value as above).
            let mean =
                w8.start * x[2] + (D::one() - w8.start) * end + m.kb * (w - x[1]) * w8.emf_change;
            (end, mean)
        }
    };
    let (z, fric) = match &p.lugre {
        Some(l) => {
            let (z, zdot) = z_step(l, x[3], w, hd);
            (z, l.friction_at(w, z, zdot))
        }
        None => (x[3], p.viscous * w),
    };
    let theta = x[0] + hd * w;
    let inputs = EffectInputs {
        theta,
        omega: w,
        current: mean_current,
        kt: m.kt,
    };
    let mut load = effects::total_torque_with_width(&p.effects, &inputs, p.sign_width);
    let mut next = *x;
    next[..4].copy_from_slice(&[theta, w, current, z]);
    let mut slot = 4;
    for e in &p.effects {
        if slot >= N {
            break;
        }
        if let Some((th2, w2)) = load_step(e, m.j, theta, w, x[slot], x[slot + 1], h) {
            if let Effect::Compliance { j2, .. } | Effect::Backlash { j2, .. } = *e {
                if j2.re() > 0.0 {
                    load = load + j2 * (w2 - x[slot + 1]) / hd;
                }
            }
            next[slot] = th2;
            next[slot + 1] = w2;
            slot += 2;
        }
    }
    let resid = m.j * (w - x[1]) / hd - m.kt * mean_current + fric + load;
    (resid, next)
}

/// The winding's weights over a sub-step of `h` [s] of the model `p` at the heat state
/// `h_th` (its resistance `R·(1 + h_th)`); unused by a torque plant.
fn winding_of<D: RunScalar>(p: &RunParams<D>, h_th: D, h: f64) -> WindingWeights<D> {
    match p.plant {
        Plant::Voltage => {
            let m = &p.motor;
            let r = m.r * (D::one() + h_th);
            // The scheme's own limit: the rotor sees the back-EMF with the start velocity's
            // weight β while its inertia takes backward Euler's step, which a rotor whose
            // electrical braking settles it within a sub-step (`R·J/(K_t·K_b) < h`) can turn
            // into a growing oscillation. There backward Euler's weights, stable for any step.
            let braking = (m.kt * m.kb).re();
            if braking > 0.0 && (r * m.j).re() < h * braking {
                let hd = D::constant(h);
                return WindingWeights {
                    inductance: m.l / hd,
                    start: D::zero(),
                    emf_change: D::zero(),
                };
            }
            winding_weights(m.l, r, h)
        }
        Plant::Torque => WindingWeights {
            inductance: D::zero(),
            start: D::zero(),
            emf_change: D::zero(),
        },
    }
}

/// The weights of a sub-step's winding equation `c·(I' − I) + R·I' = u − K_b·ω_e` and of
/// the current's mean, exact for a held voltage `u` and a velocity changing linearly from
/// `ω` to `ω'`.
#[derive(Debug, Clone, Copy)]
struct WindingWeights<D> {
    /// `c` [Ω]: `R / (e^a − 1)` with `a = hR/L`, so that with a constant velocity the step is
    /// the winding's exact response `I' = I·e^(−a) + (1 − e^(−a))·I∞` (backward Euler's
    /// `L/h` is its first-order approximation).
    inductance: D,
    /// `β = 1/a − 1/(e^a − 1)`: the back-EMF's velocity is `ω_e = β·ω + (1 − β)·ω'` (½ each
    /// for a slow winding, the end velocity for a fast one), the same weights as those of
    /// the start and end currents in the current's mean when the velocity is constant.
    start: D,
    /// `(h/L)·(½ − β)/a` [1/Ω]: the mean current's share of the back-EMF's change over the
    /// sub-step, `Ī = β·I + (1 − β)·I' + K_b·(ω' − ω)·emf_change`.
    emf_change: D,
}

impl<D: RunScalar> WindingWeights<D> {
    /// Their values.
    fn values(&self) -> WindingWeights<f64> {
        WindingWeights {
            inductance: self.inductance.re(),
            start: self.start.re(),
            emf_change: self.emf_change.re(),
        }
    }
}

impl WindingWeights<f64> {
    /// The same weights as constants of another number type.
    fn lift<E: RunScalar>(&self) -> WindingWeights<E> {
        WindingWeights {
            inductance: E::constant(self.inductance),
            start: E::constant(self.start),
            emf_change: E::constant(self.emf_change),
        }
    }
}

/// [`WindingWeights`] of a winding `l` [H], `r` [Ω] over a sub-step of `h` [s]: the current
/// follows its held voltage exactly, so a sub-step longer than `L/R` keeps the current's
/// lag and the torque's impulse right where backward Euler's would smear them.
fn winding_weights<D: RunScalar>(l: D, r: D, h: f64) -> WindingWeights<D> {
    let hd = D::constant(h);
    let a = hd * r / l;
    // In `e^(−a)` (no overflow, nor an infinite slope, for a winding far faster than the
    // step): `R/(e^a − 1) = R·e^(−a)/(1 − e^(−a))`, `L/h` at a = 0. `1/a − 1/(e^a − 1)` and
    // `(½ − β)/a` cancel for small |a|: their series, with errors below a⁵/30240 and
    // a⁶/1.2e6.
    let decay = (-a).exp();
    let rest = -(-a).exp_m1();
    let inductance = if a.re() == 0.0 {
        l / hd
    } else {
        r * decay / rest
    };
    let start = if a.re().abs() < 1e-2 {
        D::constant(0.5) - a / D::constant(12.0) + a * a * a / D::constant(720.0)
    } else {
        D::one() / a - decay / rest
    };
    let a2 = a * a;
    let half_less_start = if a.re().abs() < 0.1 {
        D::constant(1.0 / 12.0) - a2 / D::constant(720.0) + a2 * a2 / D::constant(30240.0)
    } else {
        (D::constant(0.5) - start) / a
    };
    WindingWeights {
        inductance,
        start,
        emf_change: hd / l * half_less_start,
    }
}

/// The model's numbers in the one-lane dual number of the sub-step's Newton iteration (the
/// lane is the new velocity's: the residual's value and its exact slope in one evaluation).
type Slope = DualVec<f64, 1>;

/// The numbers of a run's model in the three number types its sub-steps compute in: the
/// run's own `p`, their values `re`, and those values as one-lane dual numbers `slope` (the
/// Newton iteration's residual and slope).
struct RunModel<'a, D> {
    p: &'a RunParams<D>,
    re: &'a RunParams<f64>,
    slope: &'a RunParams<Slope>,
}

/// One implicit sub-step of length `h` (z and the winding exact) of the model `m`, from state x with
/// input u and heat state h_th. The new velocity is the root of [`substep_residual`]
/// (increasing in it), found in `f64` by [`substep_velocity`] from `w_guess`; in dual
/// numbers the new state then carries the implicit function's derivatives
/// ([`RunScalar::on_root`]). The new velocity is taken from `roots` when it replays a tape.
#[allow(clippy::too_many_arguments)]
fn implicit_step<D: RunScalar, const N: usize>(
    m: &RunModel<D>,
    x: &[D; N],
    u: f64,
    h_th: D,
    h: f64,
    w8: &WindingWeights<D>,
    w_guess: f64,
    roots: &mut SubstepRoots,
) -> [D; N] {
    let w = match roots.replay() {
        Some(w) => w,
        None => {
            let xr = x.map(|v| v.re());
            let w = substep_velocity(m.re, m.slope, &xr, u, h_th.re(), h, &w8.values(), w_guess);
            roots.record(w);
            w
        }
    };
    let (g, s) = substep_residual(m.p, m.re, x, u, h_th, h, w8, D::unknown(w));
    s.map(|v| D::on_root(v, g))
}

/// The sub-steps' new velocities (the roots [`substep_velocity`] finds), in the order a run
/// takes them. A run in dual numbers computes its values with the same operations as the
/// `f64` run of the same parameters (the dual numbers' value parts round as `f64` does), so
/// it meets the same roots: replayed from the `f64` run's tape, it skips the root search,
/// most of a sub-step's cost.
#[derive(Debug)]
pub enum SubstepRoots<'a> {
    /// Search every root.
    Solve,
    /// Search every root and append it to the tape.
    Record(&'a mut Vec<f64>),
    /// Take the roots from the tape, from the position held on; past its end, search.
    Replay(&'a [f64], usize),
}

impl SubstepRoots<'_> {
    /// The next root of a replayed tape.
    fn replay(&mut self) -> Option<f64> {
        match self {
            SubstepRoots::Replay(tape, at) => {
                let w = tape.get(*at).copied();
                *at += 1;
                w
            }
            _ => None,
        }
    }

    fn record(&mut self, w: f64) {
        if let SubstepRoots::Record(tape) = self {
            tape.push(w);
        }
    }
}

/// The new velocity of a sub-step: the root of [`substep_residual`] to within
/// 1e-11·(1 + |ω|). Newton's method on the residual and its exact slope (one evaluation in
/// [`Slope`] numbers each), kept inside the bracket of the residual's signs seen so far
/// (bisection when a step leaves it): two or three evaluations from the previous
/// sub-steps' extrapolation. Where the slope is not positive (a residual that is not
/// increasing there) and no bracket is known, the bracketing search of the emulator
/// ([`find_root`]) takes over.
#[allow(clippy::too_many_arguments)]
fn substep_velocity<const N: usize>(
    re: &RunParams<f64>,
    slope: &RunParams<Slope>,
    x: &[f64; N],
    u: f64,
    h_th: f64,
    h: f64,
    w8: &WindingWeights<f64>,
    w_guess: f64,
) -> f64 {
    let xtol = 1e-11 * (1.0 + x[1].abs());
    let xs = x.map(Slope::constant);
    let hs = Slope::constant(h_th);
    let w8s = w8.lift::<Slope>();
    let eval = |w: f64| {
        let g = substep_residual(slope, re, &xs, u, hs, h, &w8s, Slope::unknown(w)).0;
        (g.re, g.eps[0])
    };
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut w = w_guess;
    let mut last_step = f64::INFINITY;
    for _ in 0..60 {
        let (g, dg) = eval(w);
        if g == 0.0 {
            return w;
        }
        if !g.is_finite() {
            break;
        }
        if g < 0.0 {
            lo = w;
        } else {
            hi = w;
        }
        let newton = w - g / dg;
        if dg > 0.0 && (newton - w).abs() <= xtol {
            return newton;
        }
        let bracketed = lo.is_finite() && hi.is_finite();
        // Newton while it stays in the bracket and, once there is one, converges (each
        // step under half the last one); else bisection.
        let shrinks = !bracketed || (newton - w).abs() <= 0.5 * last_step;
        let next = if dg > 0.0 && newton > lo && newton < hi && shrinks {
            newton
        } else if bracketed {
            0.5 * (lo + hi)
        } else {
            break;
        };
        last_step = (next - w).abs();
        if (next - w).abs() <= xtol || (hi - lo) <= xtol {
            return next;
        }
        w = next;
    }
    let g = |w: f64| substep_residual(re, re, x, u, h_th, h, w8, w).0;
    let step0 = g(w_guess).abs() * h / re.motor.j + 1e-9;
    find_root(g, w_guess, step0, xtol)
}

/// Matrix exponential of a small dense matrix: scaling and squaring with a degree-12 Taylor
/// polynomial after scaling the norm below 1/2 (truncation error < 1e-16 relative). Used by
/// the SINDYc simulator for its linear part. `None` when the matrix is not finite or its norm
/// is beyond [`EXPM_MAX_NORM`] (a time step far too long for the dynamics): the number of
/// squarings is bounded, never ~2³¹.
pub fn expm<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let norm = a
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    if !(norm.is_finite() && norm <= EXPM_MAX_NORM) {
        return None;
    }
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let mut b = *a;
    for r in b.iter_mut() {
        for v in r.iter_mut() {
            *v *= scale;
        }
    }
    // Horner: E = I + B(I + B/2(I + B/3(...))).
    let mut e = [[0.0; N]; N];
    for (i, r) in e.iter_mut().enumerate() {
        r[i] = 1.0;
    }
    for k in (1..=12).rev() {
        let mut t = matmul(&b, &e);
        for (i, r) in t.iter_mut().enumerate() {
            for v in r.iter_mut() {
                *v /= k as f64;
            }
            r[i] += 1.0;
        }
        e = t;
    }
    for _ in 0..s {
        e = matmul(&e, &e);
    }
    Some(e)
}

/// Largest norm of `h·A` [`expm`] accepts (at most 62 squarings); a physical model at a
/// physical sample period is many orders of magnitude below.
pub const EXPM_MAX_NORM: f64 = 1e18;

fn matmul<const N: usize>(a: &[[f64; N]; N], b: &[[f64; N]; N]) -> [[f64; N]; N] {
    let mut c = [[0.0; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i][k];
            for j in 0..N {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

/// Initial velocity from the data: the `omega` column, else the slope of θ over the first
/// few samples (a Hall-quantised angle gives no better).
pub fn initial_omega(log: &MotorLog) -> f64 {
    if let Some(w) = &log.omega {
        return w[0];
    }
    let n = log.len().min(10);
    if n < 2 {
        return 0.0;
    }
    (log.theta[n - 1] - log.theta[0]) / (log.t[n - 1] - log.t[0])
}

/// Free-run simulation of `model` with the input of `log`, starting from the log's first
/// samples. Errors (never NaN) when the model diverges.
pub fn simulate(model: &Model, log: &MotorLog) -> Result<Prediction> {
    simulate_with(model, log, SUBSTEPS)
}

/// [`simulate`] with a chosen number of sub-steps per sample.
pub fn simulate_with(model: &Model, log: &MotorLog, substeps: usize) -> Result<Prediction> {
    if model.kind == ModelKind::Sindyc {
        return super::sindyc_simulate(model, log);
    }
    if log.is_empty() {
        bail!(
            "{}: the log has no samples",
            crate::log::echo_path(&log.source)
        );
    }
    simulate_range(model, log, 0, log.len(), substeps)
}

/// Velocity at sample `k` from the data alone: the `omega` column, else the slope of θ over
/// ±5 samples (the first samples: over the next 10, as [`initial_omega`]).
fn omega_at(log: &MotorLog, k: usize) -> f64 {
    if let Some(w) = &log.omega {
        return w[k];
    }
    if k == 0 {
        return initial_omega(log);
    }
    let a = k.saturating_sub(5);
    let b = (k + 5).min(log.len() - 1);
    if b > a {
        (log.theta[b] - log.theta[a]) / (log.t[b] - log.t[a])
    } else {
        0.0
    }
}

/// The heat state of the thermal effects at sample `k`, from the measured current (the
/// winding heats with the current it carries, whatever the model predicts).
fn heat_at<D: RunScalar>(p: &RunParams<D>, log: &MotorLog, k: usize) -> D {
    let offset = effects::total_sensor_offset(&p.effects);
    let mut h = D::zero();
    if !p
        .effects
        .iter()
        .any(|e| matches!(e, effects::Effect::Thermal { .. }))
    {
        return h;
    }
    let Some(i) = &log.i else { return h };
    for (j, &c) in i.iter().enumerate().take(k) {
        for e in &p.effects {
            h = e.heat_step(
                h,
                D::constant(c) - offset,
                D::constant(log.t[j + 1] - log.t[j]),
            );
        }
    }
    h
}

/// A free run's states, one value per sample, in the number type it ran in.
#[derive(Debug, Clone)]
pub struct Run<D> {
    pub theta: Vec<D>,
    pub omega: Vec<D>,
    /// Current as the sensor would measure it (with any `current_offset`); None for
    /// `--plant torque`.
    pub i: Option<Vec<D>>,
    /// Bristle deflection (LuGre models).
    pub z: Option<Vec<D>>,
    /// The loads behind a coupling, per sample: each load's deflection θ1 − θ2 [rad] and
    /// speed ω2 [rad/s], in the order of the effects; empty without such a load.
    pub load: Vec<[D; 2 * MAX_LOADS]>,
}

/// Simulation of samples `start..end` of `log` from the measured state at `start` (angle,
/// velocity, current, the heat the measured current has put into the winding): one
/// segment of a multiple-shooting fit. `start = 0, end = len` is the free run.
pub fn simulate_range(
    model: &Model,
    log: &MotorLog,
    start: usize,
    end: usize,
    substeps: usize,
) -> Result<Prediction> {
    let p = RunParams::<f64>::of(model);
    let run = run_range(&p, &p, log, start, end, substeps, &mut SubstepRoots::Solve)?;
    Ok(Prediction {
        t: log.t[start..end.min(log.len())].to_vec(),
        theta: run.theta,
        omega: run.omega,
        i: run.i,
        z: run.z,
    })
}

/// The states of a run other than the angle (velocity, winding current without the sensor's
/// offset, bristle deflection, the loads' deflections and speeds): what a multiple-shooting
/// segment may take over from the run before it.
#[derive(Debug, Clone, Copy)]
pub struct Carried<D> {
    pub omega: D,
    pub current: D,
    pub z: D,
    /// Each load's deflection θ1 − θ2 [rad] and speed ω2 [rad/s] (see [`Run::load`]). A
    /// load's angle is never measured: a segment that restarts from the measured rotor angle
    /// keeps the deflection, the state the coupling's torque depends on.
    pub load: [D; 2 * MAX_LOADS],
}

impl<D: RunScalar> Run<D> {
    /// The states other than the angle at index `k` of this run (the current without the
    /// sensor offset of the model `p`).
    pub fn carried(&self, p: &RunParams<D>, k: usize) -> Carried<D> {
        let offset = effects::total_sensor_offset(&p.effects);
        Carried {
            omega: self.omega[k],
            current: self.i.as_ref().map_or(D::zero(), |i| i[k] - offset),
            z: self.z.as_ref().map_or(D::zero(), |z| z[k]),
            load: self
                .load
                .get(k)
                .copied()
                .unwrap_or([D::zero(); 2 * MAX_LOADS]),
        }
    }
}

/// The states other than the angle at sample `k` of `log` for a run of the model `p` that
/// starts there with the velocity `omega0` [rad/s]: the measured current (less the model's
/// sensor offset; a torque plant: the command), the bristles on the Stribeck curve
/// when sliding (at rest no deflection is known), and each load behind a coupling moving
/// with the rotor, undeflected. No load angle is measured; undeflected is the state at rest
/// (a spring relaxed, a load in the middle of its gap, as the emulated motor starts) and,
/// for a spring, the static deflection of a load with no friction of its own at constant
/// speed; a gap's load is at most half the gap off, which its first contact removes.
fn measured_state<D: RunScalar>(
    p: &RunParams<D>,
    log: &MotorLog,
    k: usize,
    omega0: f64,
) -> Carried<D> {
    let offset = effects::total_sensor_offset(&p.effects);
    let current = match (p.plant, &log.i) {
        (Plant::Voltage, Some(i)) => D::constant(i[k]) - offset,
        (Plant::Voltage, None) => D::zero(),
        (Plant::Torque, _) => D::constant(log.u[k]),
    };
    let z = match &p.lugre {
        Some(l) if l.sigma0.re() > 0.0 && omega0.abs() > 1e-9 => {
            let w0 = D::constant(omega0);
            l.s(w0) * D::constant(omega0.signum()) / l.sigma0
        }
        _ => D::zero(),
    };
    let mut load = [D::zero(); 2 * MAX_LOADS];
    for pair in load.chunks_mut(2) {
        pair[1] = D::constant(omega0);
    }
    Carried {
        omega: D::constant(omega0),
        current,
        z,
        load,
    }
}

/// [`simulate_range`] of the model `p` (whose values are `re`) in its number type, the
/// sub-steps' roots searched, recorded or replayed as `roots` says.
pub fn run_range<D: RunScalar>(
    p: &RunParams<D>,
    re: &RunParams<f64>,
    log: &MotorLog,
    start: usize,
    end: usize,
    substeps: usize,
    roots: &mut SubstepRoots,
) -> Result<Run<D>> {
    let from = RunFrom {
        substeps,
        carried: None,
        give_up: None,
    };
    let run = run_range_from(p, re, log, start..end, from, roots)?;
    run.ok_or_else(|| anyhow::anyhow!("a free run without a check was given up"))
}

/// How a run of [`run_range_from`] goes.
pub struct RunFrom<'a, D> {
    /// Backward-Euler sub-steps per sample.
    pub substeps: usize,
    /// The states other than the angle at the start; `None`: the measured ones (velocity,
    /// current, the bristles on the Stribeck curve).
    pub carried: Option<Carried<D>>,
    /// Sees the run so far after every sample; when it says so, the run stops there.
    pub give_up: Option<GiveUp<'a, D>>,
}

/// A check of a run so far ([`RunFrom::give_up`]): `true` stops the run.
pub type GiveUp<'a, D> = &'a mut dyn FnMut(&Run<D>) -> bool;

/// [`run_range`] over the samples `range`, from the measured angle at its start and the other
/// states as `from` says; `None` when `from.give_up` stopped it.
pub fn run_range_from<D: RunScalar>(
    p: &RunParams<D>,
    re: &RunParams<f64>,
    log: &MotorLog,
    range: std::ops::Range<usize>,
    from: RunFrom<D>,
    roots: &mut SubstepRoots,
) -> Result<Option<Run<D>>> {
    let RunFrom {
        substeps,
        carried,
        give_up,
    } = from;
    let start = range.start;
    let end = range.end.min(log.len());
    if start >= end {
        bail!(
            "{}: empty sample range {start}..{end}",
            crate::log::echo_path(&log.source)
        );
    }
    let n = end - start;
    let loads = load_count(&p.effects);
    if loads > MAX_LOADS {
        bail!(
            "the model has {loads} loads behind a coupling (compliance, backlash); a free run \
             carries at most {MAX_LOADS}"
        );
    }
    let c0 = carried.unwrap_or_else(|| measured_state(p, log, start, omega_at(log, start)));
    let run = RangeRun {
        p,
        re,
        log,
        start,
        n,
        loads,
        substeps,
    };
    // The state array as long as this model's loads need, chosen once per run.
    match loads {
        0 => run.states::<{ state_len(0) }>(c0, roots, give_up),
        1 => run.states::<{ state_len(1) }>(c0, roots, give_up),
        _ => run.states::<{ state_len(MAX_LOADS) }>(c0, roots, give_up),
    }
}

/// A run of [`run_range_from`]: the model, the log and its samples `start..start + n`.
struct RangeRun<'a, D> {
    p: &'a RunParams<D>,
    re: &'a RunParams<f64>,
    log: &'a MotorLog,
    start: usize,
    n: usize,
    /// Loads behind a coupling (at most `(N − 4)/2` of the state length `N`).
    loads: usize,
    substeps: usize,
}

impl<D: RunScalar> RangeRun<'_, D> {
    /// The run from the states `c0` (and the measured angle), in states of length `N`;
    /// `None` when `give_up` stops it.
    fn states<const N: usize>(
        &self,
        c0: Carried<D>,
        roots: &mut SubstepRoots,
        mut give_up: Option<GiveUp<D>>,
    ) -> Result<Option<Run<D>>> {
        let RangeRun {
            p,
            re,
            log,
            start,
            n,
            loads,
            substeps,
        } = *self;
        debug_assert!(state_len(loads) <= N);
        clear_upper_vector_state();
        let offset = effects::total_sensor_offset(&p.effects);
        let omega0 = c0.omega.re();
        let theta0 = D::constant(log.theta[start]);
        let mut x = [D::zero(); N];
        x[..4].copy_from_slice(&[theta0, c0.omega, c0.current, c0.z]);
        for l in 0..loads {
            x[4 + 2 * l] = theta0 - c0.load[2 * l];
            x[5 + 2 * l] = c0.load[2 * l + 1];
        }
        let mut h = heat_at(p, log, start);
        let mut w_prev = omega0;
        let slope = re.lift::<Slope>();
        let model = RunModel {
            p,
            re,
            slope: &slope,
        };
        let mut out = Run {
            theta: Vec::with_capacity(n),
            omega: Vec::with_capacity(n),
            i: (p.plant == Plant::Voltage).then(|| Vec::with_capacity(n)),
            z: p.lugre.is_some().then(|| Vec::with_capacity(n)),
            load: Vec::with_capacity(if loads > 0 { n } else { 0 }),
        };
        let sub = substeps.max(1);
        // The winding's weights over a sub-step change with its length and, through the
        // resistance, with the heat state: without a thermal effect they are kept for the
        // next sub-step of the same length.
        let heats = p
            .effects
            .iter()
            .any(|e| matches!(e, Effect::Thermal { .. }));
        let mut winding_at: Option<(f64, WindingWeights<D>)> = None;
        for k in 0..n {
            out.theta.push(x[0]);
            out.omega.push(x[1]);
            if let Some(i) = &mut out.i {
                i.push(x[2] + offset);
            }
            if let Some(z) = &mut out.z {
                z.push(x[3]);
            }
            if loads > 0 {
                let mut l = [D::zero(); 2 * MAX_LOADS];
                for j in 0..loads {
                    l[2 * j] = x[0] - x[4 + 2 * j];
                    l[2 * j + 1] = x[5 + 2 * j];
                }
                out.load.push(l);
            }
            if k + 1 == n {
                break;
            }
            if give_up.as_mut().is_some_and(|g| g(&out)) {
                return Ok(None);
            }
            let k = start + k;
            let u = log.u[k];
            if p.plant == Plant::Torque {
                x[2] = D::constant(u);
            }
            let dt = (log.t[k + 1] - log.t[k]) / sub as f64;
            for _ in 0..sub {
                let w = x[1].re();
                let guess = w + (w - w_prev);
                w_prev = w;
                let w8 = match winding_at {
                    Some((at, w8)) if at == dt => w8,
                    _ => {
                        let w8 = winding_of(p, h, dt);
                        if !heats {
                            winding_at = Some((dt, w8));
                        }
                        w8
                    }
                };
                x = implicit_step(&model, &x, u, h, dt, &w8, guess, roots);
                for e in &p.effects {
                    h = e.heat_step(h, x[2], D::constant(dt));
                }
            }
            let xr = x.map(|v| v.re());
            if !xr.iter().all(|v| v.is_finite()) || xr[1].abs() > 1e7 || xr[2].abs() > 1e7 {
                bail!(
                    "{}: the model diverged in free run at t = {} s (sample {}); its parameters \
                 are not physical",
                    crate::log::echo_path(&log.source),
                    log.t[k + 1],
                    k + 2
                );
            }
        }
        Ok(Some(out))
    }
}

/// Marks the upper halves of the AVX vector registers clean (`vzeroupper`), on CPUs that
/// have them. A run calls libm's `exp` millions of times, which glibc runs in VEX-encoded
/// (AVX) code between this crate's SSE code: while a thread's upper register state is dirty,
/// every such switch pays a state transition (docs/decisions/0022). Rayon's worker threads
/// were seen to carry a dirty state; this clears it at the start of every run. The upper
/// halves hold no value across a call (they are caller-saved), so no result changes.
fn clear_upper_vector_state() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above), which is all `vzeroupper` needs.
        unsafe { zero_upper() }
    }
}

/// `vzeroupper`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn zero_upper() {
    std::arch::x86_64::_mm256_zeroupper();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LugreParams;

    fn log_with(u: Vec<f64>, dt: f64) -> MotorLog {
        let n = u.len();
        MotorLog {
            t: (0..n).map(|k| k as f64 * dt).collect(),
            u,
            i: Some(vec![0.0; n]),
            theta: vec![0.0; n],
            ..Default::default()
        }
    }

    #[test]
    fn expm_matches_a_rotation() {
        let e = expm(&[[0.0, -3.0], [3.0, 0.0]]).unwrap();
        // 1e-13: the exponential of a rotation generator is exact up to float rounding.
        assert!((e[0][0] - 3f64.cos()).abs() < 1e-13);
        assert!((e[1][0] - 3f64.sin()).abs() < 1e-13);
    }

    #[test]
    fn linear_model_reaches_its_steady_state() {
        let mut m = Model::new(ModelKind::Linear, Plant::Voltage, 0.012);
        m.viscous = 0.001;
        let p = m.motor;
        let log = log_with(vec![6.0; 400], 0.012);
        let pr = simulate(&m, &log).unwrap();
        // ω_ss from K_t·I = b·ω, R·I + K_b·ω = V.
        let w_ss = 6.0 * p.kt / (p.r * m.viscous + p.kt * p.kb);
        // 1e-6 relative: 4.8 s is hundreds of mechanical time constants (J·R/(K_t·K_b) ≈
        // 12 ms), so the transient is gone and the exact exponential update leaves rounding.
        assert!(
            (pr.omega[399] - w_ss).abs() < 1e-6 * w_ss,
            "{}",
            pr.omega[399]
        );
    }

    #[test]
    fn lugre_sticks_below_breakaway_and_substeps_agree() {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(LugreParams::paper());
        // Below breakaway: K_t·V/R < α0 + α1 → the rotor only deflects the bristles.
        let v_small = 0.5 * (0.08 * m.motor.r / m.motor.kt);
        let pr = simulate(&m, &log_with(vec![v_small; 300], 0.012)).unwrap();
        // The bristles deflect by about torque/σ0 = 0.04/317 ≈ 1.3e-4 rad; 1e-3 rad (a
        // hundredth of a Hall step) allows that and no sliding.
        assert!(pr.theta[299].abs() < 1e-3, "{}", pr.theta[299]);
        // Signal a through the emulator (0.2 ms steps) and through this free run (1 ms): the
        // same physics, so the velocity agrees with the emulator's true velocity.
        let cfg = crate::emulator::EmulatorConfig::paper();
        let res =
            crate::emulator::simulate_signal(&cfg, crate::emulator::SignalKind::A, 30.0).unwrap();
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(cfg.lugre);
        m.motor = cfg.motor;
        let mut log = res.log.clone();
        log.omega = Some(res.truth.omega.clone());
        log.i = Some(res.truth.i.clone());
        let pr = simulate(&m, &log).unwrap();
        let fit = crate::ident::fitpct::fit_percent(&res.truth.omega, &pr.omega).unwrap();
        // 97 %: the two integrate the same equations with different steps, so only step
        // error and the stick-slip timing it shifts remain; a missing effect costs more
        // (the coupled loads below lose over a point without theirs).
        assert!(fit > 97.0, "fit {fit}");
    }

    /// A load behind a spring and behind a gap: the free run (1 ms sub-steps, the load in
    /// the rotor's root) follows the emulator's true velocity (0.2 ms steps) as closely as
    /// the rigid motor's does above, and far closer than the same model without the load.
    #[test]
    fn loads_behind_a_coupling_follow_the_emulator() {
        for load in [
            Effect::Compliance {
                j2: 6e-4,
                k: 0.2,
                c: 6e-4,
            },
            Effect::Backlash {
                j2: 6e-4,
                gap: 0.19,
            },
        ] {
            let cfg = crate::emulator::EmulatorConfig::paper().with_effects(vec![load]);
            let res = crate::emulator::simulate_signal(&cfg, crate::emulator::SignalKind::A, 30.0)
                .unwrap();
            let m = cfg.truth_model();
            let fit = |m: &Model| {
                let pr = simulate(m, &res.log).unwrap();
                crate::ident::fitpct::fit_percent(&res.truth.omega, &pr.omega).unwrap()
            };
            let with = fit(&m);
            let mut rigid = m.clone();
            rigid.effects.clear();
            let without = fit(&rigid);
            // 97 %: as for the rigid motor above; a point of fit is the least the load must
            // be worth on a log where it is large (its inertia is twice the rotor's).
            assert!(with > 97.0, "{load:?}: fit {with}");
            assert!(
                with > without + 1.0,
                "{load:?}: with {with}, without {without}"
            );
        }
    }
}
