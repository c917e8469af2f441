//! The linear motor model (paper eqs. 1–2, viscous friction only), and the weak-form
//! regression that gives every model kind its first estimate of the motor constants and of
//! the linear-in-parameter effects.
//!
//! Electrical equation, at the sample level (a voltage held over each interval `[t_j, t_j+1)`
//! of length `h`, the velocity changing linearly over it): the winding's exact step with
//! `a = h/τ`, `τ = L/R`, is `R·Ĩ_j = u_j − K_b·(β·ω_j + (1 − β)·ω_j+1) − losses`, with the
//! held-equivalent current `Ĩ_j = I_j+1 + (I_j+1 − I_j)/(e^a − 1)` and
//! `β = 1/a − 1/(e^a − 1)` (decision 0030). Tested with ψ over each window
//! (see [`crate::numerics::weak_form`]):
//! `∫ψ·u = R·∫ψ·Ĩ + K_b·(−∫φ'·θ + (½ − β)·h·∫φ''·θ) + v_d·∫ψ·sgn(Ĩ) − R·i0·∫ψ`.
//! For each τ the equation is linear in the rest; τ is found by the profile of the residual
//! over τ ([`winding_start`], decision 0032).
//! Mechanical equation, with K_t = K_b (SI units; the data fixes only K_t/J otherwise), the
//! torque of the current's exact mean over each interval `Ī_j = β·I_j + (1 − β)·I_j+1 +
//! K_b·(½ − β)/R·(ω_j+1 − ω_j)`:
//! `K_t·∫ψ·Ī = J·∫φ''·θ + b·(−∫φ'·θ) + f_c·∫φ·sgn(ω) + d_b·(−∫φ'·sgn(ω)) + Σ c_e·∫φ·g_e`,
//! where `d_b` (with a Coulomb term) takes the bristles' damping impulse at each reversal
//! (`σ1·Δz`, the LuGre state's swing `2·s/σ0` times σ1), which the steady friction curve
//! lacks and would otherwise be read as inertia.
//! Then every parameter is refined on the free-run simulation error.
use super::free_params::{effect_keys_of, Free, Slot};
use super::FitRequest;
use crate::effects::{self, Regressor, TorqueSignals, VoltageColumn, WeakTorque};
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind, Parameter};
use crate::numerics::differentiation::smooth_velocity;
use crate::numerics::least_squares::lstsq;
use crate::numerics::weak_form;
use crate::scales;
use anyhow::Result;
use control::effects::{smooth_sign, Effect, EffectKind, CURRENT_EPS, VELOCITY_EPS};

/// Model skeleton for a request: kind, plant, sample period, sensor chain, effects.
pub fn skeleton(req: &FitRequest, kind: ModelKind) -> Model {
    let first = &req.logs[0];
    let mut m = Model::new(kind, req.plant, first.sample_period());
    m.sensor.hall_resolution_rad = super::sensor_chain::hall_resolution(first);
    if let Some(pp) = first.meta_f64("pole_pairs") {
        m.sensor.pole_pairs = Some(pp as u32);
    }
    m.sign_width = sign_width(req.logs);
    m.data.fixed = req.constraints.fixed.clone();
    m.data.bounds = req
        .constraints
        .bounds
        .iter()
        .map(|(k, &(lo, hi))| (k.clone(), [lo, hi]))
        .collect();
    if req.plant == Plant::Torque {
        m.motor.r = 0.0;
        m.motor.l = 0.0;
        m.motor.kb = 0.0;
        m.motor.kt = 1.0;
    }
    for spec in req.adds {
        // The model's own friction law already has these terms.
        let dup = match (kind, spec.kind) {
            (ModelKind::Linear, EffectKind::Viscous) => true,
            (ModelKind::Lugre, k) => matches!(
                k,
                EffectKind::Viscous
                    | EffectKind::Coulomb
                    | EffectKind::Stribeck
                    | EffectKind::Presliding
            ),
            _ => false,
        };
        let mut spec = spec.clone();
        if spec.kind == EffectKind::Table {
            set_table_range(&mut spec, req.logs, req.plant);
        }
        if !dup && !m.effects.iter().any(|e| e == &spec.to_effect()) {
            m.effects.push(spec.to_effect());
        }
    }
    m
}

/// Width of the smooth sign of the Coulomb-like terms for these logs: the control crate's
/// [`VELOCITY_EPS`] (chosen for the paper's motor, below what one Hall step per sample
/// resolves) times the logs' [`scales::velocity_scale`], so that on a slow log or one in other
/// velocity units (a linear axis in m/s) the friction switches as sharply relative to the
/// speeds the data reaches.
pub fn sign_width(logs: &[MotorLog]) -> f64 {
    let w: Vec<f64> = logs.iter().flat_map(smooth_velocity).collect();
    VELOCITY_EPS * scales::velocity_scale(&w)
}

/// A table over ω or I spans the range the logs cover (from their 0.5th to their 99.5th
/// percentile, so that a few outliers do not waste nodes) unless the spec gives `lo` and
/// `hi`; a table over θ spans one revolution unless the spec gives the stroke `lo`..`hi`.
fn set_table_range(spec: &mut crate::effect_spec::EffectSpec, logs: &[MotorLog], plant: Plant) {
    use control::effects::TableVar;
    let var = spec.table_var();
    if var == TableVar::Theta || (spec.values.contains_key("lo") && spec.values.contains_key("hi"))
    {
        return;
    }
    let mut xs: Vec<f64> = Vec::new();
    for log in logs {
        match var {
            TableVar::Omega => xs.extend(smooth_velocity(log)),
            _ if plant == Plant::Voltage => xs.extend(log.i.iter().flatten().copied()),
            _ => xs.extend(log.u.iter().copied()),
        }
    }
    xs.retain(|x| x.is_finite());
    if xs.len() < 2 {
        return;
    }
    xs.sort_by(f64::total_cmp);
    let at = |q: f64| xs[((xs.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.005), at(0.995));
    if hi > lo {
        spec.values.insert("lo".into(), lo);
        spec.values.insert("hi".into(), hi);
    }
}

/// Mechanical regressors g_e of the linear-in-parameter effects: (effect index, key(s)).
pub(crate) enum EffCols {
    /// One key and its regressor (the torque per unit of the key).
    One(usize, &'static str, Regressor),
    /// A sine and a cosine of `h·θ` (amplitude and phase), h the periods per revolution.
    SinCos(usize, f64),
    /// A table's node torques, one column per node.
    Table(usize, usize),
}

impl EffCols {
    /// Number of regression columns (unknowns) of this group.
    pub(crate) fn width(&self) -> usize {
        match self {
            EffCols::One(..) => 1,
            EffCols::SinCos(..) => 2,
            EffCols::Table(_, n) => *n,
        }
    }

    /// Index of the effect in the model.
    pub(crate) fn effect(&self) -> usize {
        match *self {
            EffCols::One(k, ..) | EffCols::SinCos(k, _) | EffCols::Table(k, _) => k,
        }
    }
}

/// The rows of a weak-form regression: one column per unknown and the left-hand side, one
/// entry per window.
pub(crate) struct WeakRows {
    pub(crate) cols: Vec<Vec<f64>>,
    pub(crate) y: Vec<f64>,
}

impl WeakRows {
    pub(crate) fn new(unknowns: usize) -> WeakRows {
        WeakRows {
            cols: vec![Vec::new(); unknowns],
            y: Vec::new(),
        }
    }

    /// The least-squares coefficients, or None when there are no more rows than unknowns.
    pub(crate) fn solve(&self) -> Option<Vec<f64>> {
        if self.y.len() <= self.cols.len() {
            return None;
        }
        let refs: Vec<&[f64]> = self.cols.iter().map(|c| c.as_slice()).collect();
        Some(lstsq(&refs, &self.y).beta)
    }
}

/// The friction the weak-form regression reads.
#[derive(Debug, Clone, Copy, Default)]
pub struct WeakFriction {
    /// Viscous friction b [N·m·s/rad].
    pub viscous: f64,
    /// Coulomb friction fc [N·m] (0 unless asked for).
    pub coulomb: f64,
    /// The bristles' creep time σ1/σ0 [s]: the damping impulse at reversals over the
    /// Coulomb friction (`σ1·2s/σ0` over `2s`); None without a Coulomb term or when either
    /// is not positive.
    pub creep: Option<f64>,
}

/// Weak-form estimate of the motor constants, the viscous (and, with `coulomb`, Coulomb)
/// friction and the linear-in-parameter effects.
pub fn weak_estimate(m: &mut Model, logs: &[MotorLog], coulomb: bool) -> WeakFriction {
    if m.plant == Plant::Voltage {
        estimate_electrical(m, logs);
    }
    let out = estimate_mechanical(m, logs, coulomb);
    tracing::debug!(
        "weak-form start: R {:.4e} Ω, L {:.4e} H, Kb {:.4e} V·s/rad, J {:.4e} kg·m², {out:?}",
        m.motor.r,
        m.motor.l,
        m.motor.kb,
        m.motor.j
    );
    out
}

/// The electrical equation's regression: the winding's time constant τ by its profile
/// ([`winding_start`]), then at that τ R [Ω], L = τ·R [H], K_b = K_t [V·s/rad] and the
/// deadtime and current-offset effects; a motor constant estimated non-positive keeps the
/// paper motor's value (L, R) or the model's (K_b).
fn estimate_electrical(m: &mut Model, logs: &[MotorLog]) {
    let extra = electrical_effects(m);
    let Some(start) = winding_start(logs, &extra, 0.0) else {
        return;
    };
    tracing::debug!(
        "winding start: τ {:.4e} s ({}), profile {:.3e}..{:.3e} s at the 5 % level",
        start.tau,
        if start.at_slow_end {
            "at the search's slow end of 100 sample periods: the winding may be slower"
        } else if start.identified {
            "identified"
        } else {
            "not identified: the slowest the log allows"
        },
        start.interval.0,
        start.interval.1
    );
    set_electrical(m, &extra, &start.x, start.tau);
}

/// The effects with a term in the electrical equation (deadtime, current offset): (effect
/// index, its term), in the model's order.
pub(crate) fn electrical_effects(m: &Model) -> Vec<(usize, &'static effects::Voltage)> {
    m.effects
        .iter()
        .enumerate()
        .filter_map(|(k, e)| effects::of(e.kind()).voltage.as_ref().map(|v| (k, v)))
        .collect()
}

/// The winding's weights over an interval of `h` [s] for a time constant `tau` [s], with
/// `a = h/tau`: `(1/(e^a − 1), β = 1/a − 1/(e^a − 1))` (the module doc). β is ½ for a slow
/// winding (the trapezoid) and 0 for a fast one (the end current); its series below
/// `a = 0.01`, where the difference cancels.
pub(crate) fn winding_weights(h: f64, tau: f64) -> (f64, f64) {
    let a = h / tau;
    if !(a.is_finite() && a > 0.0) {
        return (0.0, 0.0);
    }
    let lag = (-a).exp() / -(-a).exp_m1();
    let beta = if a < 1e-2 {
        0.5 - a / 12.0 + a * a * a / 720.0
    } else {
        1.0 / a - lag
    };
    (lag, beta)
}

/// The held-equivalent current of each interval, `Ĩ_j = I_j+1 + (I_j+1 − I_j)·lag` (the
/// current a resistance alone would carry under that interval's voltage and back-EMF), and
/// the current's mean over it without its back-EMF term, `β·I_j + (1 − β)·I_j+1`; both one
/// per interval, padded with the last to the log's length.
pub(crate) fn interval_currents(i: &[f64], lag: f64, beta: f64) -> (Vec<f64>, Vec<f64>) {
    let n = i.len();
    let mut held = Vec::with_capacity(n);
    let mut mean = Vec::with_capacity(n);
    for j in 0..n.saturating_sub(1) {
        held.push(i[j + 1] + (i[j + 1] - i[j]) * lag);
        mean.push(beta * i[j] + (1.0 - beta) * i[j + 1]);
    }
    if let (Some(&h), Some(&m)) = (held.last(), mean.last()) {
        held.push(h);
        mean.push(m);
    }
    (held, mean)
}

/// Rows of the electrical equation over the windows of every log with a current, for the
/// winding time constant `tau` [s]: `∫ψ·u` [V·s] against ∫ψ·Ĩ (R), the back-EMF's
/// `−∫φ'·θ + (½ − β)·h·∫φ''·θ` (K_b), then ∫ψ·sgn(Ĩ − i0) or ∫ψ per effect of `extra`
/// (`i0` [A]: the current sensor's offset the model already holds, 0 for none).
pub(crate) fn electrical_rows(
    logs: &[MotorLog],
    extra: &[(usize, &effects::Voltage)],
    i0: f64,
    tau: f64,
) -> WeakRows {
    let mut rows = WeakRows::new(2 + extra.len());
    for log in logs {
        let Some(i) = &log.i else { continue };
        let h = log.sample_period();
        let (lag, beta) = winding_weights(h, tau);
        let (held, _) = interval_currents(i, lag, beta);
        let sgn_i: Vec<f64> = held
            .iter()
            .map(|&c| smooth_sign(c - i0, CURRENT_EPS))
            .collect();
        let ones = vec![1.0; log.len()];
        for w in weak_form::log_windows(log) {
            rows.y.push(w.int_zoh(&log.u));
            rows.cols[0].push(w.int_zoh(&held));
            rows.cols[1].push(-w.int_d(&log.theta) + (0.5 - beta) * h * w.int_dd(&log.theta));
            for (c, (_, v)) in extra.iter().enumerate() {
                rows.cols[2 + c].push(match v.column {
                    VoltageColumn::SignOfCurrent => w.int_zoh(&sgn_i),
                    VoltageColumn::One => w.int_zoh(&ones),
                });
            }
        }
    }
    rows
}

/// Upper quantile of χ² with one degree of freedom at the 5 % level: the profile
/// likelihood's interval of τ.
const CHI2_1_95: f64 = 3.841;
/// Profile grid of τ: quarter decades from a thousandth of the sample period (`e^(−1000)`:
/// a winding no sample can tell from an instant one) to a hundred sample periods (a winding
/// slow against every sample, where the regression is the trapezoid's).
const TAU_GRID: (i32, i32) = (-12, 8);

/// The start of the winding found by [`winding_start`].
pub(crate) struct WindingStart {
    /// Time constant L/R [s].
    pub tau: f64,
    /// Coefficients at `tau`: R, K_b, then one per effect.
    pub x: Vec<f64>,
    /// Whether the profile's interval closes above the grid's fast end.
    pub identified: bool,
    /// Whether the least residual lies at the grid's slow end (a hundred sample periods): the
    /// winding may be slower still, and the start's R and L are then not to be trusted.
    pub at_slow_end: bool,
    /// The τ the profile does not reject at the 5 % level [s].
    pub interval: (f64, f64),
}

/// The winding's time constant by the profile of the electrical regression's residual over
/// τ (for each τ the rest is linear): a quarter-decade grid ([`TAU_GRID`], in sample
/// periods), then a golden-section search between the best point's neighbours. The profile's
/// interval is the τ whose residual is within [`CHI2_1_95`] of the least in
/// `(windows/2)·ln(RSS/RSS_min)` (half-overlapping windows: about half as many independent
/// rows). Where that interval reaches the grid's fast end, the log does not show the
/// winding's lag (a winding much faster than the sample): the start is then the interval's
/// slow end, the slowest winding the log does not contradict, and `identified` is false.
pub(crate) fn winding_start(
    logs: &[MotorLog],
    extra: &[(usize, &effects::Voltage)],
    i0: f64,
) -> Option<WindingStart> {
    let h = logs
        .iter()
        .filter(|l| l.i.is_some())
        .map(|l| l.sample_period())
        .filter(|p| p.is_finite() && *p > 0.0)
        .min_by(f64::total_cmp)?;
    let fit = |tau: f64| -> Option<(Vec<f64>, f64, usize)> {
        let rows = electrical_rows(logs, extra, i0, tau);
        if rows.y.len() <= rows.cols.len() {
            return None;
        }
        let refs: Vec<&[f64]> = rows.cols.iter().map(|c| c.as_slice()).collect();
        let f = lstsq(&refs, &rows.y);
        f.rss.is_finite().then_some((f.beta, f.rss, rows.y.len()))
    };
    let grid: Vec<f64> = (TAU_GRID.0..=TAU_GRID.1)
        .map(|k| h * 10f64.powf(k as f64 / 4.0))
        .collect();
    let rss: Vec<f64> = grid
        .iter()
        .map(|&t| fit(t).map_or(f64::INFINITY, |f| f.1))
        .collect();
    let best = (0..grid.len()).min_by(|&a, &b| rss[a].total_cmp(&rss[b]))?;
    if !rss[best].is_finite() {
        return None;
    }
    // Golden section on ln τ between the best grid point's neighbours.
    let (mut lo, mut hi) = (
        grid[best.saturating_sub(1)].ln(),
        grid[(best + 1).min(grid.len() - 1)].ln(),
    );
    let cost = |lt: f64| fit(lt.exp()).map_or(f64::INFINITY, |f| f.1);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut fc, mut fd) = (cost(c), cost(d));
    for _ in 0..40 {
        if fc < fd {
            hi = d;
            (d, fd) = (c, fc);
            c = hi - g * (hi - lo);
            fc = cost(c);
        } else {
            lo = c;
            (c, fc) = (d, fd);
            d = lo + g * (hi - lo);
            fd = cost(d);
        }
    }
    let mut tau = (0.5 * (lo + hi)).exp();
    let (mut x, mut rss_min, rows) = fit(tau)?;
    if rss[best] < rss_min {
        (tau, rss_min) = (grid[best], rss[best]);
        x = fit(tau)?.0;
    }
    let rejected = |r: f64| 0.5 * rows as f64 * (r / rss_min).ln() > CHI2_1_95;
    // The interval's ends: bisection on ln τ between τ and the nearest rejected grid point.
    let edge = |out: f64| {
        let (mut inside, mut outside) = (tau.ln(), out.ln());
        for _ in 0..30 {
            let mid = 0.5 * (inside + outside);
            if rejected(cost(mid)) {
                outside = mid;
            } else {
                inside = mid;
            }
        }
        inside.exp()
    };
    let below = (0..grid.len())
        .rev()
        .find(|&k| grid[k] < tau && rejected(rss[k]));
    let above = (0..grid.len()).find(|&k| grid[k] > tau && rejected(rss[k]));
    let interval = (
        below.map_or(grid[0], |k| edge(grid[k])),
        above.map_or(grid[grid.len() - 1], |k| edge(grid[k])),
    );
    let identified = below.is_some();
    let at_slow_end = best == grid.len() - 1;
    if !identified {
        tau = interval.1;
        x = fit(tau)?.0;
    }
    Some(WindingStart {
        tau,
        x,
        identified,
        at_slow_end,
        interval,
    })
}

/// Stores the electrical coefficients `x` (R, K_b, then one per effect of `extra`) and
/// L = `tau`·R: the deadtime's v_d [V] as estimated, the current offset's i0 [A] from its
/// voltage −R·i0.
fn set_electrical(m: &mut Model, extra: &[(usize, &effects::Voltage)], x: &[f64], tau: f64) {
    let fallback = control::motor::MotorParams::<f64>::paper();
    m.motor.r = if x[0] > 0.0 { x[0] } else { fallback.r };
    m.motor.l = if x[0] > 0.0 && tau.is_finite() && tau > 0.0 {
        tau * x[0]
    } else {
        fallback.l
    };
    if x[1] > 0.0 {
        m.motor.kb = x[1];
        m.motor.kt = x[1];
    }
    for (c, (k, v)) in extra.iter().enumerate() {
        let value = (v.value)(x[2 + c], m.motor.r);
        Slot::Effect(*k, v.key).set(m, value);
    }
}

/// The mechanical equation's regression: J [kg·m²], the viscous friction b, with `coulomb`
/// the Coulomb friction fc and the bristles' impulse at reversals, and the
/// linear-in-parameter effects' keys (each clamped to its bounds). All friction 0 when the
/// logs give too few windows.
fn estimate_mechanical(m: &mut Model, logs: &[MotorLog], coulomb: bool) -> WeakFriction {
    let map = mechanical_effects(m);
    let rows = mechanical_rows(m, logs, coulomb, &map);
    let Some(x) = rows.solve() else {
        return WeakFriction::default();
    };
    if x[0] > 0.0 {
        m.motor.j = x[0];
    }
    let base = if coulomb { 4 } else { 2 };
    set_mechanical_effects(m, &map, &x[base..]);
    let fc = if coulomb { x[2].max(0.0) } else { 0.0 };
    WeakFriction {
        viscous: x[1].max(0.0),
        coulomb: fc,
        creep: (coulomb && fc > 0.0 && x[3] > 0.0).then(|| x[3] / fc),
    }
}

/// The regressor groups of the model's linear-in-parameter effects, in the model's order.
pub(crate) fn mechanical_effects(m: &Model) -> Vec<EffCols> {
    let mut map = Vec::new();
    for (k, e) in m.effects.iter().enumerate() {
        let d = effects::of(e.kind());
        match d.weak_torque {
            WeakTorque::None => {}
            WeakTorque::PerKey(keys) => {
                map.extend(keys.iter().map(|&(key, g)| EffCols::One(k, key, g)))
            }
            WeakTorque::Periodic => {
                if let Some(h) = (d.harmonic)(e) {
                    map.push(EffCols::SinCos(k, h))
                }
            }
            WeakTorque::Table => {
                if let Effect::Table { bins, .. } = *e {
                    map.push(EffCols::Table(k, bins as usize))
                }
            }
        }
    }
    map
}

/// The signals of one log the mechanical regressors are made of.
pub(crate) struct MechanicalSignals {
    /// Smoothed velocity [rad/s].
    pub(crate) ws: Vec<f64>,
    /// Smooth sign of `ws`, of the model's sign width.
    pub(crate) sgn: Vec<f64>,
    /// Current less the sensor offset [A] (voltage plant), or the torque command (torque
    /// plant).
    pub(crate) cur: Vec<f64>,
}

impl MechanicalSignals {
    /// The signals of `log`; None for a voltage-plant log without a current.
    pub(crate) fn of(m: &Model, log: &MotorLog) -> Option<MechanicalSignals> {
        let offset = control::effects::total_sensor_offset(&m.effects);
        let cur: Vec<f64> = match (m.plant == Plant::Voltage, &log.i) {
            (true, Some(i)) => i.iter().map(|c| c - offset).collect(),
            (true, None) => return None,
            (false, _) => log.u.clone(),
        };
        let ws = smooth_velocity(log);
        let sgn = ws.iter().map(|&w| smooth_sign(w, m.sign_width)).collect();
        Some(MechanicalSignals { ws, sgn, cur })
    }
}

/// Rows of the mechanical equation over the windows of every usable log: the torque of the
/// current's mean over each interval (the module doc; the model's R, L, K_t, K_b), or
/// `∫ψ·u` on a torque plant, [N·m·s] against ∫φ''·θ, −∫φ'·θ, with `coulomb` ∫φ·sgn(ω) and
/// −∫φ'·sgn(ω), then ∫φ·g for each regressor of `map`.
fn mechanical_rows(m: &Model, logs: &[MotorLog], coulomb: bool, map: &[EffCols]) -> WeakRows {
    let base = if coulomb { 4 } else { 2 };
    let mut rows = WeakRows::new(base + map.iter().map(EffCols::width).sum::<usize>());
    for log in logs {
        let Some(s) = MechanicalSignals::of(m, log) else {
            continue;
        };
        let g = effect_regressors(m, map, log, &s);
        let windows = weak_form::log_windows(log);
        let drive = drive_torques(m, log, &s, &windows);
        for (w, lhs) in windows.iter().zip(drive) {
            rows.y.push(lhs);
            rows.cols[0].push(w.int_dd(&log.theta));
            rows.cols[1].push(-w.int_d(&log.theta));
            if coulomb {
                rows.cols[2].push(w.int(&s.sgn));
                rows.cols[3].push(-w.int_d(&s.sgn));
            }
            for (c, gv) in g.iter().enumerate() {
                rows.cols[base + c].push(w.int(gv));
            }
        }
    }
    rows
}

/// The drive's torque over each of `windows` of `log` [N·m·s]: K_t times the current's exact
/// mean over each interval, `β·I_j + (1 − β)·I_j+1 + K_b·(½ − β)/R·(ω_j+1 − ω_j)` (the module
/// doc; the model's R, L, K_t, K_b), or `∫ψ·u` on a torque plant.
pub(crate) fn drive_torques(
    m: &Model,
    log: &MotorLog,
    s: &MechanicalSignals,
    windows: &[weak_form::Window],
) -> Vec<f64> {
    if m.plant != Plant::Voltage {
        return windows.iter().map(|w| w.int_zoh(&s.cur)).collect();
    }
    let h = log.sample_period();
    let (lag, beta) = winding_weights(h, m.motor.l / m.motor.r);
    let mean = interval_currents(&s.cur, lag, beta).1;
    // The mean current's back-EMF term, `K_b·(½ − β)/R` per unit of velocity change.
    let emf = if m.motor.r > 0.0 {
        m.motor.kb * (0.5 - beta) / m.motor.r
    } else {
        0.0
    };
    windows
        .iter()
        .map(|w| m.motor.kt * (w.int_zoh(&mean) + emf * h * w.int_dd(&log.theta)))
        .collect()
}

/// The torque regressors g of `map`'s effects on one log, sample by sample, one per
/// unknown in `map`'s order (a sine and a cosine per periodic effect, one per table node).
pub(crate) fn effect_regressors(
    m: &Model,
    map: &[EffCols],
    log: &MotorLog,
    s: &MechanicalSignals,
) -> Vec<Vec<f64>> {
    let mut g: Vec<Vec<f64>> = Vec::new();
    for c in map {
        match *c {
            EffCols::One(k, _, regressor) => g.push(regressor(&TorqueSignals {
                effect: &m.effects[k],
                kt: m.motor.kt,
                theta: &log.theta,
                ws: &s.ws,
                sgn: &s.sgn,
                cur: &s.cur,
            })),
            EffCols::SinCos(_, h) => {
                g.push(log.theta.iter().map(|t| (h * t).sin()).collect());
                g.push(log.theta.iter().map(|t| (h * t).cos()).collect());
            }
            EffCols::Table(k, _) => {
                g.extend(effects::table::columns(
                    &m.effects[k],
                    &log.theta,
                    &s.ws,
                    &s.cur,
                ));
            }
        }
    }
    g
}

/// Stores the effects' coefficients `x` (in `map`'s order): a key clamped to its bounds, a
/// periodic effect's sine and cosine as amplitude [N·m] and phase [rad], a table's node
/// torques clamped to ±10 N·m.
pub(crate) fn set_mechanical_effects(m: &mut Model, map: &[EffCols], x: &[f64]) {
    let mut c = 0;
    for e in map {
        match *e {
            EffCols::One(k, key, _) => {
                let (lo, hi) = bounds_of(&m.effects[k], key);
                Slot::Effect(k, key).set(m, x[c].clamp(lo, hi));
            }
            EffCols::SinCos(k, _) => {
                let (a, bb) = (x[c], x[c + 1]);
                Slot::Effect(k, "amp").set(m, a.hypot(bb));
                Slot::Effect(k, "phase").set(m, bb.atan2(a));
            }
            EffCols::Table(k, n) => {
                for node in 0..n {
                    let key = effects::table_value_key(node);
                    Slot::Effect(k, key).set(m, x[c + node].clamp(-10.0, 10.0));
                }
            }
        }
        c += e.width();
    }
}

fn bounds_of(e: &Effect<f64>, key: &str) -> (f64, f64) {
    effect_keys_of(e)
        .into_iter()
        .find(|(k, _, _)| *k == key)
        .map(|(_, lo, hi)| (lo, hi))
        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY))
}

/// The motor constants a fit moves, with bounds (generous physical ranges).
pub fn motor_free(plant: Plant) -> Vec<Free> {
    let f = |slot, lo, hi| Free { slot, lo, hi };
    match plant {
        Plant::Voltage => vec![
            f(Slot::R, 1e-4, 1e3),
            f(Slot::L, 1e-7, 1.0),
            f(Slot::Kb, 1e-5, 100.0),
            f(Slot::J, 1e-9, 1e3),
        ],
        Plant::Torque => vec![f(Slot::J, 1e-9, 1e6)],
    }
}

/// Every LuGre parameter ([`crate::model::LUGRE_KEYS`]) as a free parameter, bounded only to
/// be non-negative (up to 1e6, in its own unit).
pub fn lugre_free() -> Vec<Free> {
    crate::model::LUGRE_KEYS
        .into_iter()
        .map(|f| Free {
            slot: Slot::Lugre(f),
            lo: 0.0,
            hi: 1e6,
        })
        .collect()
}

/// The effects' continuous keys as free parameters.
pub fn effect_free(m: &Model) -> Vec<Free> {
    let mut out = Vec::new();
    for (k, e) in m.effects.iter().enumerate() {
        for (key, lo, hi) in effect_keys_of(e) {
            out.push(Free {
                slot: Slot::Effect(k, key),
                lo,
                hi,
            });
        }
    }
    out
}

/// Rows for numbers the fit did not move (fixed by assumption).
pub fn fixed_rows(m: &Model) -> Vec<Parameter> {
    let mut out = Vec::new();
    match m.plant {
        Plant::Voltage => {
            let mut p = Parameter::new("Kt", m.motor.kt, "N·m/A");
            p.note = "set equal to Kb (SI units): the data fixes only Kt/J".into();
            out.push(p);
        }
        Plant::Torque => {
            let mut p = Parameter::new("Kt", m.motor.kt, "1");
            p.note = "input gain fixed to 1: u is the torque/force command".into();
            out.push(p);
        }
    }
    for e in &m.effects {
        if let Effect::Cogging { harmonic, .. } = e {
            let mut p = Parameter::new("cogging.harmonic", *harmonic as f64, "1/rev");
            p.note = "structural, kept fixed".into();
            out.push(p);
        }
    }
    out
}

/// Fit the linear model.
pub fn fit(req: &FitRequest) -> Result<Model> {
    let mut m = skeleton(req, ModelKind::Linear);
    m.viscous = weak_estimate(&mut m, req.logs, false).viscous;
    let mut free = motor_free(req.plant);
    free.push(Free {
        slot: Slot::Viscous,
        lo: 0.0,
        hi: 100.0,
    });
    let mut rows = super::refine_free_run(&mut m, &free, req)?;
    rows.extend(fixed_rows(&m));
    m.parameters = rows;
    m.data.sample_period = m.sample_period;
    m.data.method = "weak-form regression, then bounded Levenberg–Marquardt on the free-run \
                     simulation error"
        .into();
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The winding `L·di/dt + R·i = u − K_b·ω` stepped over one interval of `h` with `u`
    /// held and ω linear from `w0` to `w1`, by `SUB` exact exponential sub-steps, each with
    /// its mid-point velocity: a reference independent of the weights under test.
    fn winding_step(i: f64, u: f64, w0: f64, w1: f64, (r, l, kb): (f64, f64, f64), h: f64) -> f64 {
        const SUB: usize = 4000;
        let dt = h / SUB as f64;
        let decay = (-dt * r / l).exp();
        let mut i = i;
        for k in 0..SUB {
            let w = w0 + (w1 - w0) * (k as f64 + 0.5) / SUB as f64;
            let target = (u - kb * w) / r;
            i = target + (i - target) * decay;
        }
        i
    }

    #[test]
    fn winding_weights_have_the_trapezoid_and_end_point_limits() {
        // Slow winding (a → 0): the trapezoid's ½; fast (a → ∞): the end current.
        let (lag, beta) = winding_weights(1e-3, 1e3);
        assert!(
            (beta - 0.5).abs() < 1e-6 && lag > 1e5,
            "slow: lag {lag}, β {beta}"
        );
        let (lag, beta) = winding_weights(1.0, 1e-2);
        assert!(
            beta.abs() < 1.1e-2 && lag < 1e-40,
            "fast: lag {lag}, β {beta}"
        );
        // The series below a = 0.01 meets the closed form there.
        let (_, below) = winding_weights(0.01 - 1e-12, 1.0);
        let (_, above) = winding_weights(0.01 + 1e-12, 1.0);
        assert!(
            (below - above).abs() < 1e-9,
            "β jumps at the series' switch: {below} {above}"
        );
        // No time constant or no interval: no weights, not a NaN.
        assert_eq!(winding_weights(0.012, 0.0), (0.0, 0.0));
        assert_eq!(winding_weights(0.0, 1e-3), (0.0, 0.0));
        assert_eq!(winding_weights(0.012, f64::NAN), (0.0, 0.0));
    }

    #[test]
    fn held_current_and_mean_are_the_exact_step_of_the_winding() {
        // For a held voltage and a linear velocity, R times the held-equivalent current is
        // the voltage less the back-EMF of the weighted velocity β·ω_j + (1 − β)·ω_j+1, and
        // the mean current over the interval is β·I_j + (1 − β)·I_j+1 plus the velocity's
        // term K_b·(½ − β)/R·(ω_j+1 − ω_j) (the module doc), from a slow winding to one far
        // faster than the sample.
        let (r, kb, h) = (0.2, 0.07, 0.012);
        for tau in [5e-1, 1.2e-2, 1.5e-3, 1e-4] {
            let (lag, beta) = winding_weights(h, tau);
            let (i0, u, w0, w1) = (1.3, 2.0, 10.0, 25.0);
            let i1 = winding_step(i0, u, w0, w1, (r, tau * r, kb), h);
            let (held, mean) = interval_currents(&[i0, i1], lag, beta);
            let emf = kb * (beta * w0 + (1.0 - beta) * w1);
            assert!(
                (r * held[0] - (u - emf)).abs() < 1e-6,
                "τ {tau}: R·Ĩ {} against u − emf {}",
                r * held[0],
                u - emf
            );
            // The mean by the same sub-steps, summed.
            const SUB: usize = 4000;
            let (mut i, mut sum) = (i0, 0.0);
            for k in 0..SUB {
                let w = w0 + (w1 - w0) * k as f64 / SUB as f64;
                let w_next = w0 + (w1 - w0) * (k + 1) as f64 / SUB as f64;
                let next = winding_step(i, u, w, w_next, (r, tau * r, kb), h / SUB as f64);
                sum += 0.5 * (i + next);
                i = next;
            }
            let exact_mean = sum / SUB as f64;
            let modelled = mean[0] + kb * (0.5 - beta) / r * (w1 - w0);
            assert!(
                (modelled - exact_mean).abs() < 1e-5 * exact_mean.abs().max(1.0),
                "τ {tau}: mean current {modelled} against {exact_mean}"
            );
        }
    }

    /// A log of the winding alone: random voltages held over `h`, a velocity linear between
    /// samples (a sum of slow sines), the current stepped exactly.
    fn winding_log(tau: f64, h: f64, seconds: f64) -> MotorLog {
        let (r, kb) = (0.2, 0.07);
        let n = (seconds / h) as usize;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * h).collect();
        let omega: Vec<f64> = t
            .iter()
            .map(|&t| 40.0 * (1.3 * t).sin() + 15.0 * (4.1 * t + 1.0).sin())
            .collect();
        let mut theta = vec![0.0; n];
        for k in 1..n {
            theta[k] = theta[k - 1] + 0.5 * h * (omega[k - 1] + omega[k]);
        }
        // A deterministic pseudo-random held voltage (a multiplicative congruential draw),
        // changing every sample, around the back-EMF.
        let mut state = 0x2545_f491u64;
        let u: Vec<f64> = omega
            .iter()
            .map(|w| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1);
                kb * w + 3.0 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
            })
            .collect();
        let mut i = vec![0.0; n];
        for k in 1..n {
            i[k] = winding_step(
                i[k - 1],
                u[k - 1],
                omega[k - 1],
                omega[k],
                (r, tau * r, kb),
                h,
            );
        }
        MotorLog {
            t,
            u,
            i: Some(i),
            theta,
            ..Default::default()
        }
    }

    #[test]
    fn the_winding_start_reads_r_kb_and_tau_from_an_exact_winding() {
        let h = 0.012;
        for tau in [6e-3, 1.2e-2, 4e-2] {
            let log = winding_log(tau, h, 30.0);
            let s = winding_start(std::slice::from_ref(&log), &[], 0.0).expect("a start");
            let (r, kb) = (s.x[0], s.x[1]);
            assert!(s.identified && !s.at_slow_end, "τ {tau}: not identified");
            assert!((r / 0.2 - 1.0).abs() < 0.01, "τ {tau}: R {r}");
            assert!((kb / 0.07 - 1.0).abs() < 0.01, "τ {tau}: K_b {kb}");
            assert!((s.tau / tau - 1.0).abs() < 0.05, "τ {tau}: read {}", s.tau);
            assert!(
                s.interval.0 <= tau && tau <= s.interval.1,
                "τ {tau} outside the interval {:?}",
                s.interval
            );
        }
    }

    #[test]
    fn the_winding_start_says_when_the_winding_is_beyond_the_profile() {
        let h = 0.012;
        // Far faster than a sample: the log cannot show the lag; the start is the slowest
        // winding the log does not contradict, and says it is not identified.
        let fast = winding_log(1e-6, h, 30.0);
        let s = winding_start(std::slice::from_ref(&fast), &[], 0.0).expect("a start");
        assert!(
            !s.identified,
            "a 1 µs winding called identified at τ {}",
            s.tau
        );
        assert!(s.tau < h, "fast winding started at τ {}", s.tau);
        assert!(
            (s.x[0] / 0.2 - 1.0).abs() < 0.01,
            "fast winding: R {}",
            s.x[0]
        );
        // Far slower than the profile's grid: the least residual sits at its slow end.
        let slow = winding_log(1e3 * h, h, 30.0);
        let s = winding_start(std::slice::from_ref(&slow), &[], 0.0).expect("a start");
        assert!(
            s.at_slow_end,
            "a winding of 1000 samples not flagged at τ {}",
            s.tau
        );
    }
}
