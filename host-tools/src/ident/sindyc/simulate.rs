//! Free run of a SINDYc model: states `(x, ẋ, z, I)`, `u` held between samples (zero-order
//! hold, as the board applies it). Steps are exponential Rosenbrock–Euler (exact for the
//! linear part, stable however stiff the current or `z` equation), [`SUBSTEPS`] sub-steps per
//! sample; `z` is clamped to `±z_max` after each step as the firmware's observer does. A
//! non-finite state or a velocity/current beyond [`Limits`] is a divergence: an error, never
//! a NaN.
use crate::ident::freerun::{self, Prediction};
use crate::ident::{fitpct, sensor_chain};
use crate::log::{MotorLog, Plant};
use anyhow::{anyhow, bail, Result};
use control::effects::{CURRENT_EPS, VELOCITY_EPS};
use control::sindy::{SindyModel, Term, TermInputs};

/// Sub-steps per sample of the free run. The exponential Rosenbrock–Euler step is exact for
/// the linear part of the equations, so one step a sample leaves only the frozen-Jacobian
/// error of the nonlinear terms. On the emulated paper motor (fit on signal a) two sub-steps
/// change the validation fit on ẋ by less than 0.3 points and the current's on the voltage
/// steps of signal d by about 4 (the current follows the velocity within a sample), at
/// twice the cost of every free run; docs/performance-sindyc.md has the figures.
pub const SUBSTEPS: usize = 1;

/// Limits beyond which a free run counts as divergent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub omega: f64,
    pub current: f64,
}

impl Default for Limits {
    /// Limits for scoring a finished model: only a runaway (1e7) is a divergence.
    fn default() -> Self {
        Limits {
            omega: 1e7,
            current: 1e7,
        }
    }
}

/// Free-run simulation of a SINDYc model with the input of `log` from its first samples.
/// Errors when the model diverges (never returns non-finite values).
pub fn simulate(
    model: &SindyModel<f64>,
    plant: Plant,
    log: &MotorLog,
    limits: Limits,
) -> Result<Prediction> {
    simulate_substeps(model, plant, log, limits, SUBSTEPS)
}

/// [`simulate`] with `sub` sub-steps per sample.
pub fn simulate_substeps(
    model: &SindyModel<f64>,
    plant: Plant,
    log: &MotorLog,
    limits: Limits,
    sub: usize,
) -> Result<Prediction> {
    let sub = sub.max(1);
    let n = log.len();
    if n == 0 {
        bail!(
            "{}: the log has no samples",
            crate::log::echo_path(&log.source)
        );
    }
    let voltage = plant == Plant::Voltage;
    let i0 = match (&log.i, voltage) {
        (Some(i), true) => i[0],
        _ => 0.0,
    };
    let start = [log.theta[0], freerun::initial_omega(log), 0.0, i0];
    let zb = model.z_bound();
    let rhs = |s: &[f64; 4], u: f64| -> [f64; 4] {
        let p = TermInputs {
            x: s[0],
            xdot: s[1],
            z: s[2],
            i: s[3],
            u,
        };
        let di = if voltage { model.idot_rhs(&p) } else { 0.0 };
        [s[1], model.accel_rhs(&p), model.zdot_rhs(&p), di]
    };
    let deps = state_dependencies(model, voltage);
    let kinks = sign_kinks(model, voltage);
    // The state after sample k from the one at k. With `incs`, the angle enters at -0 and
    // the increments of a halved step's parts but the last are pushed on `incs` (see
    // `advance`; one sub-step a sample): the angle's entry of the result is the last part's
    // increment, exactly (`-0 + x = x`). A run whose steps do not depend on the angle gives
    // the same other states either way.
    let step = |k: usize, s: &[f64; 4], mut incs: Option<&mut Vec<f64>>| -> Result<[f64; 4]> {
        let u = log.u[k];
        let dt = (log.t[k + 1] - log.t[k]) / sub as f64;
        let mut r = *s;
        if incs.is_some() {
            r[0] = -0.0;
        }
        for _ in 0..sub {
            let mut splits = MAX_SPLITS;
            r = advance(
                &rhs,
                &deps,
                &kinks,
                &r,
                u,
                dt,
                zb,
                &mut splits,
                incs.as_deref_mut(),
            )
            .ok_or_else(|| {
                anyhow!(
                    "{}: time step {} s before sample {} is too long for the SINDYc model, or \
                     the model's coefficients too large (its matrix exponential is out of \
                     range)",
                    crate::log::echo_path(&log.source),
                    log.t[k + 1] - log.t[k],
                    k + 2
                )
            })?;
        }
        if !r.iter().all(|v| v.is_finite())
            || r[1].abs() > limits.omega
            || r[3].abs() > limits.current
        {
            bail!(
                "{}: the SINDYc model diverged in free run at t = {} s (sample {})",
                crate::log::echo_path(&log.source),
                log.t[k + 1],
                k + 2
            );
        }
        Ok(r)
    };
    let states = if deps[0] || sub > 1 || n < 2 * super::pieces::MIN_PIECE {
        let mut states = Vec::with_capacity(n);
        states.push(start);
        for k in 0..n - 1 {
            let next = step(k, &states[k], None)?;
            states.push(next);
        }
        states
    } else {
        // In pieces, a step returns the angle's increment, and NaN in its place when the
        // step was halved: the increments of its parts, which are added to the angle one
        // after the other (each sum rounded), are kept by sample (a re-run's after the
        // guessed run's). The angles are then summed in order.
        let parts = std::sync::Mutex::new(Vec::<(usize, Vec<f64>)>::new());
        let inc = |k: usize, s: &[f64; 4]| -> Result<[f64; 4]> {
            let mut incs = Vec::new();
            let mut r = step(k, s, Some(&mut incs))?;
            if !incs.is_empty() {
                incs.push(r[0]);
                r[0] = f64::NAN;
                parts
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .push((k, incs));
            }
            Ok(r)
        };
        let mut states = run_in_pieces(log, voltage, start, &inc)?;
        let parts: std::collections::HashMap<usize, Vec<f64>> = parts
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .into_iter()
            .collect();
        for k in 1..n {
            let mut theta = states[k - 1][0];
            match parts.get(&(k - 1)).filter(|_| states[k][0].is_nan()) {
                Some(incs) => incs.iter().for_each(|d| theta += d),
                None => theta += states[k][0],
            }
            if !theta.is_finite() {
                bail!(
                    "{}: the SINDYc model diverged in free run at t = {} s (sample {})",
                    crate::log::echo_path(&log.source),
                    log.t[k],
                    k + 1
                );
            }
            states[k][0] = theta;
        }
        states
    };
    Ok(Prediction {
        t: log.t.clone(),
        theta: states.iter().map(|s| s[0]).collect(),
        omega: states.iter().map(|s| s[1]).collect(),
        i: voltage.then(|| states.iter().map(|s| s[3]).collect()),
        z: Some(states.iter().map(|s| s[2]).collect()),
    })
}

/// The states of a free run whose steps do not depend on the angle (see [`simulate`]),
/// computed in parallel pieces ([`super::pieces`]) when the log is long: the same states to
/// the bit as one run from the start. A piece starts from the log's measured velocity
/// (centred slope of the angle over ±5 samples, or its `omega` column) and current.
fn run_in_pieces(
    log: &MotorLog,
    voltage: bool,
    start: [f64; 4],
    step: &(impl Fn(usize, &[f64; 4]) -> Result<[f64; 4]> + Sync),
) -> Result<Vec<[f64; 4]>> {
    let n = log.len();
    let guess = |k: usize| {
        let w = match &log.omega {
            Some(w) => w[k],
            None => {
                let (a, b) = (k.saturating_sub(5), (k + 5).min(n - 1));
                (log.theta[b] - log.theta[a]) / (log.t[b] - log.t[a])
            }
        };
        let i = match (&log.i, voltage) {
            (Some(i), true) => i[k],
            _ => 0.0,
        };
        [0.0, w, 0.0, i]
    };
    super::pieces::run(n, start, step, &guess, 2 * rayon::current_num_threads())
}

/// Most halvings of one (sub-)step by [`advance`]: enough to resolve a start from rest
/// under full voltage (about 10 levels on the paper's motor), while a candidate model that
/// chatters about zero velocity cannot make a sample cost more than this many extra steps.
const MAX_SPLITS: usize = 64;

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
fn sign_kinks(model: &SindyModel<f64>, voltage: bool) -> Vec<(usize, f64)> {
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
/// angle reaches is its angle plus each increment in turn.
#[allow(clippy::too_many_arguments)]
fn advance(
    rhs: &impl Fn(&[f64; 4], f64) -> [f64; 4],
    deps: &[bool; 4],
    kinks: &[(usize, f64)],
    s: &[f64; 4],
    u: f64,
    h: f64,
    zb: f64,
    splits: &mut usize,
    mut incs: Option<&mut Vec<f64>>,
) -> Option<[f64; 4]> {
    let mut next = rosenbrock_step(rhs, deps, s, u, h)?;
    next[2] = next[2].clamp(-zb, zb);
    let crosses = kinks.iter().any(|&(j, w)| {
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
    let mut mid = advance(
        rhs,
        deps,
        kinks,
        s,
        u,
        h / 2.0,
        zb,
        splits,
        incs.as_deref_mut(),
    )?;
    if let Some(v) = incs.as_deref_mut() {
        v.push(mid[0]);
        mid[0] = -0.0;
    }
    advance(rhs, deps, kinks, &mid, u, h / 2.0, zb, splits, incs)
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

/// One exponential Rosenbrock–Euler step `s⁺ = s + h·φ1(h·A)·f(s)` (A: the Jacobian by
/// forward differences over the states in `deps`), with [`phi1_times`].
fn rosenbrock_step(
    rhs: &impl Fn(&[f64; 4], f64) -> [f64; 4],
    deps: &[bool; 4],
    s: &[f64; 4],
    u: f64,
    dt: f64,
) -> Option<[f64; 4]> {
    let f0 = rhs(s, u);
    let mut a = [[0.0; 4]; 4];
    for j in (0..4).filter(|j| deps[*j]) {
        // Forward differences: the Jacobian only shapes the step's stability and its
        // O(dt²) error, so 1e-7 relative accuracy is plenty.
        let d = 1e-7 * s[j].abs().max(1e-2);
        let mut sp = *s;
        sp[j] += d;
        let fp = rhs(&sp, u);
        for i in 0..4 {
            a[i][j] = (fp[i] - f0[i]) / d * dt;
        }
    }
    let b = f0.map(|f| f * dt);
    let step = phi1_times(&a, &b)?;
    let mut out = *s;
    for i in 0..4 {
        out[i] += step[i];
    }
    Some(out)
}

type M4 = [[f64; 4]; 4];

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

/// `φ1(A)·b` with `φ1(A) = Σ_k A^k/(k+1)!`: the last column of the exponential of the
/// augmented matrix `[[A, b], [0, 0]]` ([`freerun::expm`]), computed without forming it.
/// Scaling and squaring: `A` and `b` are scaled by `2^−s` so that `‖A‖∞ ≤ 1/2` (the
/// augmented column does not enter the norm: the result is linear in `b`), `φ1` of the
/// scaled matrix is its Taylor polynomial of degree 11 (truncation < 4e-14 relative)
/// evaluated by Paterson–Stockmeyer in powers of `A⁴` (6 products of 4×4 matrices instead
/// of 11), and each squaring of the augmented matrix maps `(E, g)` to `(E², E·g + g)`.
/// `None` when `A` or `b` is not finite or `‖A‖` is beyond [`freerun::EXPM_MAX_NORM`].
pub fn phi1_times(a: &M4, b: &[f64; 4]) -> Option<[f64; 4]> {
    let norm = a
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let finite = a.iter().flatten().chain(b).all(|v| v.is_finite());
    if !(finite && norm <= freerun::EXPM_MAX_NORM) {
        return None;
    }
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

/// Duration [s] of log a set of free runs that judges candidate models may hold (the
/// structure search's validation runs, the refinement's fitting runs): 8192 samples at
/// 12 ms, more than the paper's 90 s signals, which are therefore used whole. A
/// computational budget, not a physical constant: it bounds the cost of every model
/// evaluation whatever the length of the logs, so that identification is linear in the data
/// (one pass for the embedding and the weak form) plus a fixed cost for the search.
pub const EVALUATION_SECONDS: f64 = 98.304;
/// Most samples [`evaluation_budget`] gives, whatever the sample rate (eight times the
/// budget at 12 ms): a fast log is judged on a shorter stretch of time rather than at a
/// cost that grows with its rate.
pub const EVALUATION_MAX_SAMPLES: usize = 65_536;

/// Samples of `logs` a set of free runs that judges candidate models may hold:
/// [`EVALUATION_SECONDS`] at the first log's sample period, at most
/// [`EVALUATION_MAX_SAMPLES`].
pub fn evaluation_budget(logs: &[MotorLog]) -> usize {
    let total: usize = logs.iter().map(MotorLog::len).sum();
    let dt = logs.first().map_or(0.0, MotorLog::sample_period);
    crate::scales::samples_for(EVALUATION_SECONDS, dt, total).min(EVALUATION_MAX_SAMPLES)
}
/// Number of segments [`bounded_segments`] spreads its budget over.
const EVALUATION_SEGMENTS: usize = 4;

/// Up to `budget` samples of `logs` to simulate candidate models on: the logs themselves
/// when they hold no more, else [`EVALUATION_SEGMENTS`] segments of `budget /
/// EVALUATION_SEGMENTS` samples spread evenly over the logs (first and last samples
/// included), each a free run of its own from the measured state at its start (as the
/// segments of a multiple-shooting fit). A log shorter than a segment is taken whole.
pub fn bounded_segments(logs: &[MotorLog], budget: usize) -> Vec<MotorLog> {
    let total: usize = logs.iter().map(MotorLog::len).sum();
    if total <= budget {
        return logs.to_vec();
    }
    let seg = (budget / EVALUATION_SEGMENTS).max(1);
    let mut picked: Vec<(usize, usize, usize)> = Vec::new();
    for k in 0..EVALUATION_SEGMENTS {
        let global = k * (total - seg) / (EVALUATION_SEGMENTS - 1);
        // The log holding sample `global` of the concatenation, and the offset in it.
        let (mut idx, mut offset) = (0, global);
        while offset >= logs[idx].len() {
            offset -= logs[idx].len();
            idx += 1;
        }
        let len = logs[idx].len();
        let range = if len <= seg {
            (idx, 0, len)
        } else {
            let start = offset.min(len - seg);
            (idx, start, start + seg)
        };
        if !picked.contains(&range) {
            picked.push(range);
        }
    }
    picked
        .into_iter()
        .map(|(idx, start, end)| sub_log(&logs[idx], start, end))
        .collect()
}

/// Samples `start..end` of a log as a log of its own (metadata kept, extra columns dropped).
fn sub_log(log: &MotorLog, start: usize, end: usize) -> MotorLog {
    MotorLog {
        source: format!("{} (samples {}..{})", log.source.display(), start + 1, end).into(),
        meta: log.meta.clone(),
        t: log.t[start..end].to_vec(),
        u: log.u[start..end].to_vec(),
        i: log.i.as_ref().map(|v| v[start..end].to_vec()),
        theta: log.theta[start..end].to_vec(),
        omega: log.omega.as_ref().map(|v| v[start..end].to_vec()),
        extra: Vec::new(),
        units: log.units.clone(),
    }
}

/// Mean validation fit on ẋ of a model's free run **through the sensor chain** (the
/// `fit_sensor` of `compare`: the model's angle Hall-quantised with the log's resolution and
/// differentiated by the firmware's moving average, against the measured velocity
/// `omegas[k]` of `logs[k]`); `None` when the model diverges on any log. The logs (the
/// segments of [`bounded_segments`]) run in parallel.
pub fn validation_fit(
    m: &SindyModel<f64>,
    plant: Plant,
    logs: &[MotorLog],
    omegas: &[Vec<f64>],
    window: usize,
    limits: Limits,
) -> Option<f64> {
    use rayon::prelude::*;
    let fits: Option<Vec<f64>> = logs
        .par_iter()
        .zip(omegas)
        .map(|(log, w)| {
            let pred = simulate(m, plant, log, limits).ok()?;
            let res = sensor_chain::hall_resolution(log);
            let (_, wq) = sensor_chain::through_sensor(&pred.t, &pred.theta, res, window);
            fitpct::fit_percent(w, &wq).ok()
        })
        .collect();
    Some(fits?.iter().sum::<f64>() / logs.len().max(1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::sindy::{SparseEq, Term};

    /// A log of `n` samples at `dt` with input `u(k)` (angle and current zero).
    fn log_with_input(n: usize, dt: f64, u: impl Fn(usize) -> f64) -> MotorLog {
        MotorLog {
            t: (0..n).map(|k| k as f64 * dt).collect(),
            u: (0..n).map(u).collect(),
            theta: vec![0.0; n],
            i: Some(vec![0.0; n]),
            ..MotorLog::default()
        }
    }

    #[test]
    fn a_linear_model_follows_its_exact_step_response() {
        // dẋ/dt = −ẋ/τ + g·u, dI/dt = −I/τe + u/L: both first order, u held at 1.
        let (tau, g, tau_e, l) = (0.013, 80.0, 0.0014, 3e-4);
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -1.0 / tau), (Term::U, g)]).unwrap();
        m.idot = SparseEq::from_slice(&[(Term::I, -1.0 / tau_e), (Term::U, 1.0 / l)]).unwrap();
        let dt = 0.012;
        let log = log_with_input(200, dt, |_| 1.0);
        let p = simulate(&m, Plant::Voltage, &log, Limits::default()).unwrap();
        for k in [1, 5, 50, 199] {
            let t = k as f64 * dt;
            let w = g * tau * (1.0 - (-t / tau).exp());
            let i = tau_e / l * (1.0 - (-t / tau_e).exp());
            assert!(
                (p.omega[k] - w).abs() < 1e-6 * w.abs().max(1.0),
                "ω[{k}] {} vs {w}",
                p.omega[k]
            );
            assert!((p.i.as_ref().unwrap()[k] - i).abs() < 1e-6 * i, "I[{k}]");
        }
        // The angle integrates the velocity (second order in the step: within 1 %).
        let t = 199.0 * dt;
        let x = g * tau * (t - tau * (1.0 - (-t / tau).exp()));
        assert!(
            (p.theta[199] - x).abs() < 1e-2 * x,
            "{} vs {x}",
            p.theta[199]
        );
    }

    #[test]
    fn a_start_from_rest_under_a_sign_like_friction_follows_the_exact_response() {
        // dẋ/dt = −ẋ/τ + g·u − c·tanh(a·ẋ), u held at 1 from rest. Beyond a few 1/a the tanh
        // is 1: ẋ(t) = τ·(g − c)·(1 − e^(−t/τ)), up to the microseconds spent crossing its
        // kink. A step that froze the tanh's slope at ẋ = 0 (a·c = 2000 1/s of damping)
        // over the whole first sample would land far below.
        let (tau, g, c, a) = (0.013, 1000.0, 250.0, 8.0);
        let mut m = SindyModel::empty(a, 1.0, 1.0);
        m.accel =
            SparseEq::from_slice(&[(Term::Xdot, -1.0 / tau), (Term::U, g), (Term::TanhXdot, -c)])
                .unwrap();
        let dt = 0.012;
        let log = log_with_input(20, dt, |_| 1.0);
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        for k in [1, 2, 10] {
            let t = k as f64 * dt;
            let w = tau * (g - c) * (1.0 - (-t / tau).exp());
            assert!(
                (p.omega[k] - w).abs() < 5e-3 * w,
                "ω[{k}] {} vs {w}",
                p.omega[k]
            );
        }
        assert_eq!(sign_kinks(&m, false), vec![(1, 1.0 / a)]);
    }

    #[test]
    fn the_evaluation_budget_is_a_duration_of_the_log() {
        // 8192 samples at 12 ms; the same 98 s at 24 ms; at 1 ms the cap.
        let budget = |dt: f64, n: usize| evaluation_budget(&[log_with_input(n, dt, |_| 0.0)]);
        assert_eq!(budget(0.012, 100_000), 8192);
        assert_eq!(budget(0.024, 100_000), 4096);
        assert_eq!(budget(0.001, 100_000), EVALUATION_MAX_SAMPLES);
        // Never more than the logs hold.
        assert_eq!(budget(0.012, 500), 500);
    }

    #[test]
    fn a_divergent_model_is_an_error_not_a_nan() {
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.accel = SparseEq::from_slice(&[(Term::Xdot, 50.0), (Term::U, 1.0)]).unwrap();
        let log = log_with_input(500, 0.012, |_| 1.0);
        let limits = Limits {
            omega: 1e3,
            current: 1e3,
        };
        let e = simulate(&m, Plant::Voltage, &log, limits)
            .unwrap_err()
            .to_string();
        assert!(e.contains("diverged"), "{e}");
        assert!(
            validation_fit(&m, Plant::Voltage, &[log], &[vec![0.0; 500]], 10, limits).is_none()
        );
    }

    #[test]
    fn the_hidden_state_stays_within_its_bound() {
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.z_max = 2.0;
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -10.0), (Term::U, 10.0)]).unwrap();
        m.zdot = SparseEq::from_slice(&[(Term::Xdot, 100.0)]).unwrap();
        let log = log_with_input(300, 0.012, |k| if k < 150 { 1.0 } else { -1.0 });
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        let z = p.z.unwrap();
        assert!(z.iter().all(|z| z.abs() <= 2.0 + 1e-12));
        assert!(z.iter().any(|z| z.abs() > 1.9));
        assert!(p.i.is_none());
    }

    #[test]
    fn a_bristle_turns_over_at_a_reversal_within_its_bound() {
        // dẋ/dt = −ẋ/τ + g·u + c·w − d·(ẋ − |ẋ|·w), dw/dt = (ẋ − |ẋ|·w)/z_ss: Coulomb
        // friction carried by the bristle w, whose damping d (a time constant of 5 µs while
        // it turns over) holds the rotor at the reversal. In sliding w = sgn ẋ and
        // ẋ = τ·(g·u + c·w).
        let (tau, g, c, d, zss) = (0.013, 1000.0, -250.0, 1e5, 1e-3);
        let mut m = SindyModel::empty(100.0, 1.0, 1.0);
        m.z_max = 1.0;
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -1.0 / tau - d),
            (Term::U, g),
            (Term::Z, c),
            (Term::AbsXdotZ, d),
        ])
        .unwrap();
        m.zdot =
            SparseEq::from_slice(&[(Term::Xdot, 1.0 / zss), (Term::AbsXdotZ, -1.0 / zss)]).unwrap();
        let log = log_with_input(100, 0.012, |k| if k < 50 { 1.0 } else { -1.0 });
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        let z = p.z.as_ref().unwrap();
        assert!(z.iter().all(|z| z.abs() <= 1.0));
        let slide = tau * (g + c);
        for (k, sign) in [(49, 1.0), (99, -1.0)] {
            assert!((z[k] - sign).abs() < 1e-9, "w[{k}] = {}", z[k]);
            let w = p.omega[k];
            assert!((w - sign * slide).abs() < 1e-6 * slide, "ẋ[{k}] = {w}");
        }
        // The split steps agree with 32 sub-steps a sample (the convergence of the step,
        // to a hundredth of the sliding speed).
        let fine = simulate_substeps(&m, Plant::Torque, &log, Limits::default(), 32).unwrap();
        for (a, b) in p.omega.iter().zip(&fine.omega) {
            assert!((a - b).abs() < 1e-2 * slide, "{a} vs {b}");
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

    #[test]
    fn segments_bound_the_samples_and_cover_both_ends() {
        let long = log_with_input(50_000, 0.012, |k| k as f64);
        let short = log_with_input(300, 0.012, |k| -(k as f64));
        // Within the budget: the logs themselves.
        let whole = bounded_segments(std::slice::from_ref(&short), 1000);
        assert_eq!(whole.len(), 1);
        assert_eq!(whole[0].u, short.u);
        let logs = [short.clone(), long.clone()];
        let segs = bounded_segments(&logs, 4000);
        let n: usize = segs.iter().map(MotorLog::len).sum();
        assert!(n <= 4000, "{n}");
        // The short log comes whole; the last segment ends at the last sample.
        assert_eq!(segs[0].u, short.u);
        let last = segs.last().unwrap();
        assert_eq!(last.u.last(), long.u.last());
        assert_eq!(last.len(), 1000);
        // Each segment is a contiguous piece of its log, time included.
        for s in &segs[1..] {
            let k = s.u[0] as usize;
            assert_eq!(s.t[0], long.t[k]);
            assert!(s.u.windows(2).all(|w| w[1] == w[0] + 1.0));
        }
    }
}
