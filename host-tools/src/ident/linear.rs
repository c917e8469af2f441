//! The linear motor model (paper eqs. 1–2, viscous friction only), and the weak-form
//! regression that gives every model kind its first estimate of the motor constants and of
//! the linear-in-parameter effects.
//!
//! Electrical equation, tested with φ over each window (see [`crate::numerics::weak_form`]):
//! `∫φ·u = L·(−∫φ'·I) + R·∫φ·I + K_b·(−∫φ'·θ) + v_d·∫φ·sgn(I) − R·i0·∫φ`.
//! Mechanical equation, with K_t = K_b (SI units; the data fixes only K_t/J otherwise):
//! `K_t·∫φ·I = J·∫φ''·θ + b·(−∫φ'·θ) + Σ c_e·∫φ·g_e(θ, ω, I)`.
//! Then every parameter is refined on the free-run simulation error.
use super::free_params::{effect_keys, effect_keys_of, Free, Slot};
use super::{nlsq, sim_error, FitRequest};
use crate::log::{MotorLog, Plant};
use crate::model::{LugreParams, Model, ModelKind, Parameter};
use crate::numerics::differentiation::smooth_velocity_of;
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
    let w: Vec<f64> = logs.iter().flat_map(smooth_velocity_of).collect();
    VELOCITY_EPS * scales::velocity_scale(&w)
}

/// A table over ω or I spans the range the logs cover (from their 0.5th to their 99.5th
/// percentile, so that a few outliers do not waste nodes) unless the spec gives `lo` and
/// `hi`; a table over θ spans one revolution and needs no range.
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
            TableVar::Omega => xs.extend(smooth_velocity_of(log)),
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

/// The hat functions of a table's nodes on one log: column k is `h_k(x)` (see
/// [`control::effects::table_nodes`]), x the table's variable (θ, the smoothed velocity
/// `ws`, or the current `cur`).
pub fn table_columns(e: &Effect<f64>, theta: &[f64], ws: &[f64], cur: &[f64]) -> Vec<Vec<f64>> {
    use control::effects::{table_nodes, TableVar};
    let Effect::Table {
        var, bins, lo, hi, ..
    } = *e
    else {
        return vec![];
    };
    let x = match var {
        TableVar::Theta => theta,
        TableVar::Omega => ws,
        TableVar::Current => cur,
    };
    let mut cols = vec![vec![0.0; x.len()]; bins as usize];
    for (k, &v) in x.iter().enumerate() {
        let (k0, k1, w) = table_nodes(var, bins, lo, hi, v);
        cols[k0][k] += 1.0 - w;
        cols[k1][k] += w;
    }
    cols
}

/// Mechanical regressors g_e of the linear-in-parameter effects: (effect index, key(s)).
enum EffCols {
    One(usize, &'static str),
    SinCos(usize, f64),
    /// A table's node torques, one column per node.
    Table(usize, usize),
}

/// The friction a weak-form estimate regresses on.
#[derive(Debug, Clone, Copy)]
pub enum WeakFriction<'a> {
    /// Viscous friction only.
    Viscous,
    /// Coulomb and viscous friction.
    CoulombViscous,
    /// A known Stribeck curve `s(ω)·sgn(ω)` (the LuGre law's steady state, from steady-state
    /// points) taken off the torque, and a viscous term. At every velocity reversal the
    /// Stribeck excess α1 pushes like an inertia would: regressed as Coulomb friction only,
    /// it leaves the inertia about 15 % low on the paper's motor.
    Stribeck(&'a LugreParams),
}

/// Weak-form estimate of the motor constants, the friction of `friction` and the
/// linear-in-parameter effects. Returns (b, fc) (fc 0 unless Coulomb friction is regressed).
pub fn weak_estimate(m: &mut Model, logs: &[MotorLog], friction: WeakFriction) -> (f64, f64) {
    let coulomb = matches!(friction, WeakFriction::CoulombViscous);
    let voltage = m.plant == Plant::Voltage;
    // Electrical equation, as it is sampled (see [`sampled_electrical_rows`]).
    if voltage {
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); 3];
        let mut extra: Vec<(usize, EffectKind)> = Vec::new();
        for (k, e) in m.effects.iter().enumerate() {
            if matches!(e.kind(), EffectKind::Deadtime | EffectKind::CurrentOffset) {
                extra.push((k, e.kind()));
                cols.push(Vec::new());
            }
        }
        let mut y = Vec::new();
        let mut period = Vec::new();
        for log in logs {
            let Some(i) = &log.i else { continue };
            let sgn_i: Vec<f64> = i.iter().map(|&c| smooth_sign(c, CURRENT_EPS)).collect();
            let ones = vec![1.0; log.len()];
            let rows = sampled_electrical_rows(log, i);
            period.push(log.sample_period());
            for (w, row) in weak_form::log_windows(log).iter().zip(rows) {
                y.push(row.voltage);
                cols[0].push(row.current);
                cols[1].push(row.current_step);
                cols[2].push(row.velocity);
                for (c, (_, kind)) in extra.iter().enumerate() {
                    cols[3 + c].push(match kind {
                        EffectKind::Deadtime => w.int(&sgn_i),
                        _ => w.int(&ones),
                    });
                }
            }
        }
        if y.len() > cols.len() {
            let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let x = lstsq(&refs, &y).beta;
            let fallback = control::motor::MotorParams::<f64>::paper();
            m.motor.r = if x[0] > 0.0 { x[0] } else { fallback.r };
            period.sort_by(f64::total_cmp);
            let ts = period[period.len() / 2];
            m.motor.l = inductance_of_sampled(m.motor.r, x[1], ts);
            tracing::debug!(
                "weak-form winding: R {}, current-step coefficient {}, L {}, Kb {}",
                x[0],
                x[1],
                m.motor.l,
                x[2]
            );
            if x[2] > 0.0 {
                m.motor.kb = x[2];
                m.motor.kt = x[2];
            }
            for (c, (k, kind)) in extra.iter().enumerate() {
                let v = x[3 + c];
                m.effects[*k] = match kind {
                    EffectKind::Deadtime => Effect::Deadtime { vd: v },
                    _ => Effect::CurrentOffset { i0: -v / m.motor.r },
                };
            }
        }
    }
    // Mechanical equation, integrated over the held intervals: the lag κ of the velocity's
    // step response depends on J, so the regression is repeated with κ of the last estimate.
    let ts = logs.first().map(MotorLog::sample_period).unwrap_or(0.0);
    let mut kappa = 0.0;
    let mut solved = None;
    for _ in 0..3 {
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); 2];
        let mut map: Vec<EffCols> = Vec::new();
        if coulomb {
            cols.push(Vec::new());
        }
        let base = cols.len();
        for (k, e) in m.effects.iter().enumerate() {
            match *e {
                Effect::Coulomb { .. } => map.push(EffCols::One(k, "fc")),
                Effect::Stribeck { .. } => map.push(EffCols::One(k, "fs")),
                Effect::Offset { .. } => map.push(EffCols::One(k, "t0")),
                Effect::LoadFriction { .. } => map.push(EffCols::One(k, "mu")),
                Effect::Saturation { .. } => map.push(EffCols::One(k, "k")),
                Effect::Viscous { .. } => map.push(EffCols::One(k, "b")),
                Effect::Asymmetry { .. } => {
                    map.push(EffCols::One(k, "dv"));
                    map.push(EffCols::One(k, "dc"));
                }
                Effect::Cogging { harmonic, .. } => map.push(EffCols::SinCos(k, harmonic as f64)),
                Effect::PositionLoad { .. } => map.push(EffCols::SinCos(k, 1.0)),
                Effect::Table { bins, .. } => map.push(EffCols::Table(k, bins as usize)),
                _ => {}
            }
        }
        for c in &map {
            match c {
                EffCols::One(..) => cols.push(Vec::new()),
                EffCols::SinCos(..) => cols.extend([Vec::new(), Vec::new()]),
                EffCols::Table(_, n) => cols.extend(std::iter::repeat_n(Vec::new(), *n)),
            }
        }
        let offset = control::effects::total_sensor_offset(&m.effects);
        let mut y = Vec::new();
        for log in logs {
            let ws = smooth_velocity_of(log);
            let sgn: Vec<f64> = ws.iter().map(|&w| smooth_sign(w, m.sign_width)).collect();
            let known: Option<Vec<f64>> = match friction {
                WeakFriction::Stribeck(l) => {
                    Some(ws.iter().zip(&sgn).map(|(&w, s)| l.s(w) * s).collect())
                }
                _ => None,
            };
            let cur: Vec<f64> = match (voltage, &log.i) {
                (true, Some(i)) => i.iter().map(|c| c - offset).collect(),
                (true, None) => continue,
                (false, _) => log.u.clone(),
            };
            let mut g: Vec<Vec<f64>> = Vec::new();
            for c in &map {
                match *c {
                    EffCols::One(k, key) => g.push(match (m.effects[k], key) {
                        (Effect::Stribeck { vs, .. }, _) => ws
                            .iter()
                            .zip(&sgn)
                            .map(|(w, s)| (-(w / vs).powi(2)).exp() * s)
                            .collect(),
                        (Effect::Offset { .. }, _) => vec![1.0; log.len()],
                        (Effect::LoadFriction { .. }, _) => cur
                            .iter()
                            .zip(&sgn)
                            .map(|(c, s)| (m.motor.kt * c).abs() * s)
                            .collect(),
                        // The torque a falling K_t loses, to first order in k: K_t·k·I³.
                        (Effect::Saturation { .. }, _) => {
                            cur.iter().map(|c| m.motor.kt * c * c * c).collect()
                        }
                        (Effect::Viscous { .. }, _) => ws.clone(),
                        (Effect::Asymmetry { .. }, "dv") => ws.iter().map(|w| w.abs()).collect(),
                        (Effect::Asymmetry { .. }, _) => sgn.iter().map(|s| s.abs()).collect(),
                        _ => sgn.clone(),
                    }),
                    EffCols::SinCos(_, h) => {
                        g.push(log.theta.iter().map(|t| (h * t).sin()).collect());
                        g.push(log.theta.iter().map(|t| (h * t).cos()).collect());
                    }
                    EffCols::Table(k, _) => {
                        g.extend(table_columns(&m.effects[k], &log.theta, &ws, &cur));
                    }
                }
            }
            let cur_held = held_current(&cur);
            for w in weak_form::log_windows(log) {
                let lhs = if voltage {
                    m.motor.kt * w.int_held(&cur_held, kappa)
                } else {
                    w.int_zoh(&cur)
                } - known.as_ref().map_or(0.0, |f| w.int(f));
                y.push(lhs);
                cols[0].push(w.int_dd(&log.theta));
                cols[1].push(-w.int_d(&log.theta));
                if coulomb {
                    cols[2].push(w.int(&sgn));
                }
                for (c, gv) in g.iter().enumerate() {
                    cols[base + c].push(w.int(gv));
                }
            }
        }
        if y.len() <= cols.len() {
            break;
        }
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        let x = lstsq(&refs, &y).beta;
        if voltage && x[0] > 0.0 {
            let mo = &m.motor;
            kappa = weak_form::held_step_lag(mo.r, mo.l, mo.kt, mo.kb, x[0], x[1].max(0.0), ts);
        }
        tracing::debug!(
            "weak-form inertia {} (step-response lag {kappa} samples)",
            x[0]
        );
        solved = Some((x, map, base));
    }
    let mut b = 0.0;
    let mut fc = 0.0;
    if let Some((x, map, base)) = solved {
        if x[0] > 0.0 {
            m.motor.j = x[0];
        }
        b = x[1].max(0.0);
        if coulomb {
            fc = x[2].max(0.0);
        }
        let mut c = base;
        for e in &map {
            match *e {
                EffCols::One(k, key) => {
                    let v = x[c];
                    let slot = Slot::Effect(k, key);
                    let (lo, hi) = bounds_of(m.effects[k].kind(), key);
                    slot.set(m, v.clamp(lo, hi));
                    c += 1;
                }
                EffCols::SinCos(k, _) => {
                    let (a, bb) = (x[c], x[c + 1]);
                    Slot::Effect(k, "amp").set(m, a.hypot(bb));
                    Slot::Effect(k, "phase").set(m, bb.atan2(a));
                    c += 2;
                }
                EffCols::Table(k, n) => {
                    for node in 0..n {
                        let key = crate::effect_spec::table_value_key(node);
                        Slot::Effect(k, key).set(m, x[c + node].clamp(-10.0, 10.0));
                    }
                    c += n;
                }
            }
        }
    }
    (b, fc)
}

/// One weak-form row of the winding equation as the board samples it: `voltage =
/// R·current + γ·current_step + K_b·velocity` (plus the effects' voltage terms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElectricalRow {
    /// `Σφ_k·u_{k−1}·dt`: the voltage held over the interval that ends at sample k [V·s].
    pub voltage: f64,
    /// `Σφ_k·I_k·dt` [A·s].
    pub current: f64,
    /// `Σφ_k·(I_k − I_{k−1})·dt` [A·s].
    pub current_step: f64,
    /// `Σφ_k·ω_k·dt = −∫φ'·θ dt` [rad].
    pub velocity: f64,
}

/// The winding equation `L·dI/dt = u − R·I − K_b·ω` under a voltage held over each sample
/// period T (zero-order hold), at the instants the current is sampled. Solved exactly over
/// an interval, with `a = exp(−R·T/L)` and the velocity slow against L/R:
/// `I_k = a·I_{k−1} + (1 − a)·(u_{k−1} − K_b·ω_k)/R`, i.e.
/// `u_{k−1} = R·I_k + γ·(I_k − I_{k−1}) + K_b·ω_k` with `γ = R·a/(1 − a)`.
/// The sampled current answers the voltage held *before* it, not the one held after: a
/// continuous-time regression `∫φ·u = L·∫φ·İ + R·∫φ·I + …` with the held input and the
/// trapezoid of the samples reads that half-sample shift as a winding time constant of about
/// T/2 (L ≈ R·T/2, four times the paper motor's). One row per fitting window
/// ([`weak_form::log_windows`]), the point weights φ_k·dt of [`weak_form::Window::int`].
pub fn sampled_electrical_rows(log: &MotorLog, i: &[f64]) -> Vec<ElectricalRow> {
    let n = log.len().min(i.len());
    let prev = |v: &[f64]| -> Vec<f64> { (0..n).map(|k| v[k.saturating_sub(1)]).collect() };
    let u_prev = prev(&log.u);
    let step: Vec<f64> = (0..n).map(|k| i[k] - i[k.saturating_sub(1)]).collect();
    weak_form::log_windows(log)
        .iter()
        .filter(|w| w.end <= n)
        .map(|w| ElectricalRow {
            voltage: w.int(&u_prev),
            current: w.int(i),
            current_step: w.int(&step),
            velocity: -w.int_d(&log.theta),
        })
        .collect()
}

/// The inductance [H] of a winding of resistance `r` [Ω] whose sampled equation has the
/// current-step coefficient `gamma` (= R·a/(1 − a), [`sampled_electrical_rows`]) at sample
/// period `ts` [s]: `L = R·T/ln(1 + R/γ)`. When γ is not positive the samples do not resolve
/// the winding's time constant (L/R far below T, the current algebraic at the samples):
/// then L/R = T/10, a start the simulation-error refinement moves from (it sees L through
/// the torque impulse `K_t·L/R·ΔI` of every voltage step).
pub fn inductance_of_sampled(r: f64, gamma: f64, ts: f64) -> f64 {
    let unresolved = r * ts / 10.0;
    if !(gamma > 0.0 && r > 0.0 && ts > 0.0) {
        return unresolved;
    }
    let l = r * ts / (1.0 + r / gamma).ln();
    if l.is_finite() && l > 0.0 {
        l
    } else {
        unresolved
    }
}

/// The winding current over each sample interval `[t_j, t_{j+1})` as the samples give it:
/// the one sampled at the interval's end, `I_{j+1}`. Under a held voltage the current
/// settles to `(u_j − K_b·ω)/R` within a few L/R, so where L/R is well below the period the
/// sample at `t_{j+1}` is the interval's level and the one at `t_j` the previous interval's;
/// the trapezoid of the two would lag the torque by half a sample. (The last interval has
/// no end sample and keeps the last one.)
pub fn held_current(i: &[f64]) -> Vec<f64> {
    (0..i.len())
        .map(|j| i[(j + 1).min(i.len().saturating_sub(1))])
        .collect()
}

fn bounds_of(kind: EffectKind, key: &str) -> (f64, f64) {
    effect_keys(kind)
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
    let (b, _) = weak_estimate(&mut m, req.logs, WeakFriction::Viscous);
    m.viscous = b;
    let mut free = motor_free(req.plant);
    free.push(Free {
        slot: Slot::Viscous,
        lo: 0.0,
        hi: 100.0,
    });
    let mut rows =
        sim_error::refine_with_effects(&mut m, &free, req.logs, nlsq::Options::default())?;
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
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    #[test]
    fn inductance_comes_back_from_the_sampled_coefficient() {
        let (r, ts): (f64, f64) = (0.2, 0.012);
        for l in [1e-4f64, 3e-4, 3e-3, 3e-2] {
            let a = (-r * ts / l).exp();
            let gamma = r * a / (1.0 - a);
            let back = inductance_of_sampled(r, gamma, ts);
            assert!((back - l).abs() < 1e-9 * l, "{l}: {back}");
        }
        // Not resolved: L/R a tenth of the period.
        assert!((inductance_of_sampled(r, -0.1, ts) - r * ts / 10.0).abs() < 1e-15);
        assert!((inductance_of_sampled(r, 0.0, ts) - r * ts / 10.0).abs() < 1e-15);
    }

    /// On the emulated paper motor (L/R = 1.4 ms at 12 ms) the sampled winding equation gives
    /// R and K_b, and no winding time constant of half a period: read as a continuous-time
    /// equation, the current's half-sample lag behind the held voltage reads as L ≈ R·T/2
    /// (1.3 mH).
    #[test]
    fn weak_estimate_reads_the_winding_as_sampled() {
        let cfg = EmulatorConfig::paper();
        let log = simulate_signal(&cfg, SignalKind::A, 30.0).unwrap().log;
        let mut m = Model::new(ModelKind::Linear, Plant::Voltage, 0.012);
        m.sign_width = sign_width(std::slice::from_ref(&log));
        weak_estimate(&mut m, &[log], WeakFriction::CoulombViscous);
        let truth = cfg.motor;
        assert!(
            (m.motor.r - truth.r).abs() < 0.03 * truth.r,
            "R {}",
            m.motor.r
        );
        assert!(
            (m.motor.kb - truth.kb).abs() < 0.01 * truth.kb,
            "Kb {}",
            m.motor.kb
        );
        assert!(m.motor.l < 0.25 * truth.r * 0.012, "L {}", m.motor.l);
        assert!(
            (m.motor.j - truth.j).abs() < 0.2 * truth.j,
            "J {}",
            m.motor.j
        );
    }
}
