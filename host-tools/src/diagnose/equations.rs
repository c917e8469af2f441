//! The stages of [`super::diagnose`]: the log's weak forms, the two equations' base and
//! candidate columns, forward selection in the voltage equation and then in the torque
//! equation (which takes the voltage equation's K_b and losses), and the residuals the
//! verdict judges.
use super::candidates::{self, Equation, Signals, Units, Variant};
use super::forward_select::{select, Selection};
use super::{
    min_torque, modelled_drive, presliding_candidates, presliding_pass, row_scale, select_rows,
    signals_of, viscous_of, weak_torque, Column, EqData, EquationResidual, Finding, Judged,
    Options, SampleColumn, Structure, Tested,
};
use crate::effect_spec::EffectSpec;
use crate::log::{MotorLog, Plant};
use crate::numerics::statistics;
use crate::numerics::weak_form::{self, WeakForm};
use control::effects::{Effect, EffectKind};

/// One log in weak form: its signals, the voltage equation's point weights `wf` and the
/// torque equation's interval weights `wf_m`.
pub(super) struct Forms {
    pub(super) s: Signals,
    pub(super) wf: WeakForm,
    pub(super) wf_m: WeakForm,
    /// Window half-width [samples].
    pub(super) h: usize,
    /// A voltage plant with a measured current: the voltage equation exists.
    pub(super) voltage: bool,
}

/// What the passes found so far.
#[derive(Default)]
pub(super) struct Outcome {
    pub(super) findings: Vec<Finding>,
    pub(super) tested: Vec<Tested>,
    pub(super) equations: Vec<EquationResidual>,
    pub(super) judged: Vec<Judged>,
}

/// What the selections of one diagnosis share: the options, the level of each entry test,
/// the units estimates are expressed in (the electrical pass refits R) and what the passes
/// have found so far.
pub(super) struct Pass<'a> {
    pub(super) opts: &'a Options,
    pub(super) alpha_per_test: f64,
    pub(super) units: Units,
    pub(super) acc: Outcome,
}

impl Pass<'_> {
    /// Forward selection on `data` at this diagnosis's level and units.
    fn select(&mut self, data: &EqData) -> Selection {
        select(data, self.opts, self.alpha_per_test, &mut self.units)
    }
}

/// The presliding candidates, tested apart on every window, and their nuisance columns.
#[derive(Default)]
pub(super) struct PreslidingTest {
    pub(super) cand: Vec<(Variant, Vec<Vec<f64>>)>,
    pub(super) nuisance: Vec<Vec<f64>>,
}

/// The log's weak forms.
pub(super) fn weak_forms(log: &MotorLog, st: &Structure, opts: &Options) -> Forms {
    let h = if opts.half_width == 0 {
        candidates::samples_for(weak_form::HALF_WIDTH_S, log.sample_period(), log.len() / 2)
    } else {
        opts.half_width
    }
    .max(2);
    let mut s = signals_of(log, st, h, opts.steady_angle);
    s.drive_model = modelled_drive(&s, st);
    let wf = WeakForm::new(s.len(), s.dt, h, h);
    let voltage = s.plant == Plant::Voltage && s.i.is_some();
    // The torque equation of a voltage plant integrates its held terms with the lag of the
    // model's own step response (`numerics::weak_form`, module doc); a torque plant, or a model without
    // motor constants (SINDYc), gets the plain interval weights.
    let wf_m = match (voltage, st.motor) {
        (true, Some(m)) => wf.held(weak_form::held_step_lag(
            m.r,
            m.l,
            m.kt,
            m.kb,
            m.j,
            viscous_of(&st.effects),
            s.dt,
        )),
        _ => wf.held(0.0),
    };
    Forms {
        s,
        wf,
        wf_m,
        h,
        voltage,
    }
}

/// The base of both equations: the model's own structure (R, L, K_b; the inertia; every
/// effect it has, each in the equation it acts in). Each column is defined once and computed
/// on the log and, as its instrument, on the model's own run `run` when there is one.
pub(super) fn base_equations(f: &Forms, run: Option<&Forms>, st: &Structure) -> (EqData, EqData) {
    let both = |def: &dyn Fn(&Forms) -> Vec<f64>| (def(f), run.map(def));
    let s = &f.s;
    // Electrical equation (voltage plant): V = R·I + L·İ + K_b·ω + losses, on the sample grid
    // (the current sampled at t_k answers the input held just before).
    let mut elec = EqData::new(
        Equation::Electrical,
        f.wf.integral(&s.u),
        super::verdict::hold_clusters(&s.raw_u, &f.wf.centres),
    );
    if f.voltage {
        let (c, z) = both(&|g| g.wf.integral(g.s.i.as_deref().unwrap_or(&[])));
        elec.push_base(Column::new("R", "Ω", false), c, z);
        // L·dI/dt just before a sample, where the current tracks the back-EMF
        // quasi-statically: −(L·K_b/R)·ω̇ (the sampled current's own derivative would carry
        // the input's steps, which the winding has settled from by then). Its coefficient
        // stands for the equation's own approximation, which the discrete windows do not
        // reproduce exactly: free in the parameter check (the model's L is judged in the
        // torque equation, through the exact increments of the measured current).
        let (c, z) = both(&|g| g.wf.second_derivative(&g.s.theta));
        let name = Column::new("L·K_b/R (quasi-static)", "H·V·s/(Ω·rad)", false);
        elec.push_base(name.free(), c, z);
        let (c, z) = both(&|g| g.wf.derivative(&g.s.theta));
        elec.push_base(Column::new("K_b", "V·s/rad", false), c, z);
    }
    // Mechanical equation. Voltage plant: the current is eliminated with the electrical
    // equation (L·İ ≈ 0 at this sample rate), `K_t·I = (K_t/R)·(V − K_b·ω − losses)`, so the
    // torque balance reads in volts: `V − K_b·ω = (R/K_t)·(J·θ̈ + Σ torques) + losses`. The
    // held input integrates exactly; no sampled current has to stand for its interval.
    let mut mech = EqData::new(
        Equation::Mechanical,
        vec![],
        super::verdict::hold_clusters(&s.raw_u, &f.wf.centres),
    );
    mech.min_torque = min_torque(st, s);
    let (c, z) = both(&|g| g.wf_m.second_derivative(&g.s.theta_torque));
    mech.push_base(Column::new("J", "kg·m²", true), c, z);
    for e in &st.effects {
        if matches!(e, Effect::Coulomb { fc } if *fc <= 0.0) {
            mech.coulomb_col = Some(mech.base_cols.len());
        }
        let cols = candidates::present_columns(e, s);
        let on_run = run.map(|g| candidates::present_columns(e, &g.s));
        let of = cols.len();
        for (k, (eq, col)) in cols.into_iter().enumerate() {
            let name = Column::of_effect(e, eq, k, of);
            let twin = on_run
                .as_ref()
                .and_then(|r| r.get(k))
                .filter(|(q, _)| *q == eq)
                .map(|(_, c)| c);
            if eq == Equation::Mechanical {
                let z = run.zip(twin).map(|(g, c)| weak_torque(&g.wf_m, &g.s, c));
                mech.push_base(name, weak_torque(&f.wf_m, s, &col), z);
            } else {
                let z = run.zip(twin).map(|(g, c)| g.wf.integral(c));
                elec.push_base(name.clone(), f.wf.integral(&col), z);
                mech.base_sample.push(SampleColumn {
                    col,
                    inst: twin.cloned(),
                    name,
                });
            }
        }
    }
    // Any Coulomb-like friction sticks at standstill (the smooth sign creeps below 0.05
    // rad/s, which no Hall sensor resolves): the stick column belongs to the base then.
    if !st.has(EffectKind::Coulomb)
        && (st.has(EffectKind::Presliding) || st.has(EffectKind::Stribeck))
    {
        let (c, z) = both(&|g| g.wf_m.integral(&g.s.stick_column()));
        let name = Column::new("friction at standstill", "N·m", true);
        mech.push_base(name, c, z);
    }
    (elec, mech)
}

/// Every effect of the list the model lacks, as candidate columns of the equation it acts in
/// (presliding apart: it is tested on every window). Returns the number of variants tested.
pub(super) fn add_candidates(
    f: &Forms,
    st: &Structure,
    elec: &mut EqData,
    mech: &mut EqData,
    pre: &mut PreslidingTest,
) -> usize {
    let s = &f.s;
    let mut n_variants = 0usize;
    for kind in EffectKind::ALL {
        if st.has(kind) {
            continue;
        }
        let vs = if kind == EffectKind::Presliding {
            let (nuisance, vs) = presliding_candidates(s, st);
            pre.nuisance = nuisance.iter().map(|c| f.wf_m.integral(c)).collect();
            vs
        } else {
            candidates::variants(kind, s)
        };
        for v in vs {
            let w = if v.equation == Equation::Mechanical {
                &f.wf_m
            } else {
                &f.wf
            };
            let cols: Vec<Vec<f64>> = v.columns.iter().map(|c| weak_torque(w, s, c)).collect();
            n_variants += 1;
            if v.kind == EffectKind::Presliding {
                pre.cand.push((v, cols));
            } else if v.equation == Equation::Mechanical {
                mech.cand.push((v, cols));
            } else if f.voltage {
                elec.cand.push((v, cols));
            }
        }
    }
    n_variants
}

/// One equation's residuals for the report: the windows `keep` marks (all without it).
fn residual_of(
    f: &Forms,
    eq: Equation,
    out: &Selection,
    unit: &'static str,
    keep: Option<&[bool]>,
) -> EquationResidual {
    let centres = &f.wf.centres;
    let idx: Vec<usize> = (0..centres.len())
        .filter(|&r| keep.is_none_or(|k| k[r]))
        .collect();
    let inp: Vec<f64> = idx.iter().map(|&r| f.s.u[centres[r]]).collect();
    EquationResidual {
        equation: eq,
        t: idx.iter().map(|&r| f.s.t[centres[r]]).collect(),
        centres: idx.iter().map(|&r| centres[r]).collect(),
        base: out.base_resid.clone(),
        after: out.final_resid.clone(),
        n_eff: out.n_eff_base,
        whiteness: statistics::whiteness(&out.base_resid, &inp, 30),
        unit,
    }
}

/// Forward selection in the voltage equation. Returns the refitted K_b; voltage losses found
/// there join the torque equation's base (written in volts, it carries them too).
pub(super) fn electrical_pass(
    f: &Forms,
    elec: &EqData,
    mech: &mut EqData,
    given: Option<Vec<f64>>,
    pass: &mut Pass,
) -> f64 {
    let out = pass.select(elec);
    let acc = &mut pass.acc;
    let kb = out
        .base_beta
        .get(2)
        .copied()
        .unwrap_or(control::motor::MotorParams::<f64>::paper().kb);
    for found in &out.findings {
        if let Some(v) = elec.cand.iter().find(|(v, _)| {
            Some(v.kind) == found.kind
                && EffectSpec::parse(&found.spec)
                    .is_ok_and(|sp| v.fixed.iter().all(|(k, x)| (sp.get(k) - x).abs() < 1e-9))
        }) {
            if v.0.kind != EffectKind::CurrentOffset {
                // Not a parameter of the model as given: free in its parameter check.
                let of = v.0.columns.len();
                for (k, col) in v.0.columns.iter().enumerate() {
                    let name = if of > 1 {
                        format!("{} [{}]", v.0.kind.name(), k + 1)
                    } else {
                        v.0.kind.name().to_string()
                    };
                    mech.base_sample.push(SampleColumn {
                        col: col.clone(),
                        inst: None,
                        name: Column::new(name, "V", false).free(),
                    });
                }
            }
        }
    }
    acc.equations
        .push(residual_of(f, Equation::Electrical, &out, "V·s", None));
    acc.judged.push(Judged {
        eq: Equation::Electrical,
        scale: None,
        keep: vec![true; f.wf.rows()],
        given,
        base: out.base_resid.clone(),
        after: out.final_resid.clone(),
        beta: out.base_beta.clone(),
        cols: elec.base_cols.clone(),
        instruments: elec.base_inst.clone(),
        names: elec.base_names.clone(),
        input: f.wf.integral(&f.s.u),
        small: out.small.clone(),
    });
    acc.findings.extend(out.findings);
    acc.tested.extend(out.first_round);
    kb
}

/// The torque equation's left side and the base columns that need K_b or act per sample
/// interval: `V − K_b·ω` (volts) or the held torque, the winding's L·dI/dt, the voltage
/// losses, the model's load friction and saturation; and the load-friction candidate's
/// interval column.
fn complete_torque_equation(
    (f, run): (&Forms, Option<&Forms>),
    st: &Structure,
    mech: &mut EqData,
    kb: f64,
    units: &mut Units,
) {
    let both = |def: &dyn Fn(&Forms) -> Vec<f64>| (def(f), run.map(def));
    let (s, wf_m) = (&f.s, &f.wf_m);
    if f.voltage {
        let zoh = wf_m.integral_zoh(&s.raw_u);
        let w = wf_m.derivative(&s.theta_torque);
        mech.y = zoh.iter().zip(&w).map(|(a, b)| a - kb * b).collect();
        units.mech_scale = st.kt / units.r;
        // The winding's L·dI/dt over each interval: its increments, exactly.
        let (c, z) = both(&|g| g.wf_m.derivative(g.s.i.as_deref().unwrap_or(&[])));
        mech.push_base(Column::new("L", "H", false), c, z);
        for sc in std::mem::take(&mut mech.base_sample) {
            // Current offsets do not reach the torque equation written in volts.
            let z = run.zip(sc.inst).map(|(g, c)| g.wf_m.integral(&c));
            mech.push_base(sc.name, wf_m.integral(&sc.col), z);
        }
    } else {
        mech.y = wf_m.integral_zoh(&s.raw_u);
        units.mech_scale = 1.0;
    }
    // Load friction per sample interval, with the held input and the angle increments
    // (the braking transients last about one sample; see `load_friction_intervals`): the
    // candidate's column, or the base's when the model has it.
    let r = units.r;
    let (lf_col, lf_torque) = s.load_friction_intervals(kb, r);
    if st.has(EffectKind::LoadFriction) {
        let z = run.map(|g| g.wf_m.integral_zoh(&g.s.load_friction_intervals(kb, r).0));
        let name = Column::new("load_friction", "N·m per N·m", false);
        mech.push_base(name, wf_m.integral_zoh(&lf_col), z);
    }
    // A model's saturation likewise per interval (its I³ weighs the step transients).
    if st.has(EffectKind::Saturation) && f.voltage {
        let (c, z) = both(&|g| g.wf_m.integral_zoh(&g.s.saturation_intervals(r)));
        mech.push_base(Column::new("saturation", "V", false), c, z);
    }
    // The saturation candidate's column on the model's own run (its descriptor says why);
    // without a run it is not tested.
    let sat = run
        .zip(st.motor)
        .filter(|_| f.voltage)
        .map(|(g, m)| g.s.saturation_intervals(m.r));
    mech.cand
        .retain(|(v, _)| v.kind != EffectKind::Saturation || sat.is_some());
    for (v, cols) in mech.cand.iter_mut() {
        if v.kind == EffectKind::LoadFriction {
            *cols = vec![wf_m.integral_zoh(&lf_col)];
            v.torque = Some(lf_torque.clone());
        }
        if let (EffectKind::Saturation, Some(c)) = (v.kind, &sat) {
            *cols = vec![wf_m.integral_zoh(c)];
            v.torque = Some(c.clone());
        }
    }
}

/// The torque equation's windows: those that touch neither a standstill nor a reversal.
///
/// At a standstill static friction is whatever balances the drive (an unknown per window),
/// and the Hall angle cannot tell creep from rest. A window that holds a reversal (a sign
/// change of the velocity estimate) is left out too: a fast reversal skips the stick band
/// between two samples, and when the friction switched inside those 12 ms is unknown
/// (±0.15 N·m of residual per window on voltage steps with the true constants). Kept, those
/// windows biased the refitted inertia, and with it any transient term; presliding is tested
/// on every window (`presliding_pass`).
fn moving_windows(f: &Forms) -> Vec<bool> {
    let s = &f.s;
    f.wf.centres
        .iter()
        .map(|&c| {
            let win = &s.omega[c.saturating_sub(f.h)..(c + f.h + 1).min(s.len())];
            win.iter().all(|w| w.abs() >= s.stick_speed())
                && win.iter().all(|w| w.signum() == win[0].signum())
        })
        .collect()
}

/// Every row of the equation (its left side, base and candidate columns) times `w`, or only
/// the rows `keep` marks.
fn map_rows(mech: &mut EqData, op: impl Fn(&[f64]) -> Vec<f64>) {
    mech.y = op(&mech.y);
    mech.base_cols = mech.base_cols.iter().map(|c| op(c)).collect();
    for z in mech.base_inst.iter_mut().flatten() {
        *z = op(z);
    }
    for (_, cols) in mech.cand.iter_mut() {
        *cols = cols.iter().map(|c| op(c)).collect();
    }
}

/// Rows weighted by their noise (with `steady_angle`): a first fit gives the residual whose
/// squares set the variance model ([`row_scale`]).
fn noise_weights(
    f: &Forms,
    st: &Structure,
    mech: &EqData,
    keep: &[bool],
    pass: &Pass,
) -> Option<Vec<f64>> {
    let m = st.motor.filter(|_| pass.opts.steady_angle)?;
    let b = viscous_of(&st.effects);
    let (a1, a2) = if f.voltage {
        let ratio = if m.kt != 0.0 { m.r / m.kt } else { 0.0 };
        (-(m.kb + ratio * b), -ratio * m.j)
    } else {
        (-b, -m.j)
    };
    let v = select_rows(
        &f.wf_m.angle_error_variance(a1, a2, &f.s.theta_torque_var),
        keep,
    );
    let first = select(
        mech,
        pass.opts,
        pass.alpha_per_test,
        &mut pass.units.clone(),
    );
    Some(row_scale(&first.base_resid, &v))
}

/// Forward selection in the torque equation on its moving windows, then presliding on every
/// window.
pub(super) fn mechanical_pass(
    forms: (&Forms, Option<&Forms>),
    st: &Structure,
    mut mech: EqData,
    pre: PreslidingTest,
    (kb, given): (f64, Option<Vec<f64>>),
    pass: &mut Pass,
) {
    let f = forms.0;
    complete_torque_equation(forms, st, &mut mech, kb, &mut pass.units);
    let mut all_rows = (mech.y.clone(), mech.base_cols.clone());
    all_rows.1.extend(pre.nuisance);
    let keep = moving_windows(f);
    map_rows(&mut mech, |c| select_rows(c, &keep));
    mech.cluster = std::mem::take(&mut mech.cluster)
        .into_iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(c, _)| c)
        .collect();
    let scale = noise_weights(f, st, &mech, &keep, pass);
    if let Some(w) = &scale {
        map_rows(&mut mech, |c| c.iter().zip(w).map(|(a, b)| a * b).collect());
    }
    candidates::saturation_beyond_run(&mut mech.cand, &mech.base_inst);
    let out = pass.select(&mech);
    let unit = if f.voltage { "V·s" } else { "u·s" };
    pass.acc.equations.push(residual_of(
        f,
        Equation::Mechanical,
        &out,
        unit,
        Some(&keep),
    ));
    let scaled = |x: Vec<f64>| -> Vec<f64> {
        match &scale {
            Some(w) => x.iter().zip(w).map(|(a, b)| a * b).collect(),
            None => x,
        }
    };
    pass.acc.judged.push(Judged {
        eq: Equation::Mechanical,
        scale: scale.clone(),
        given: given.map(|g| scaled(select_rows(&g, &keep))),
        input: scaled(select_rows(&f.wf_m.integral(&f.s.u), &keep)),
        keep,
        base: out.base_resid.clone(),
        after: out.final_resid.clone(),
        beta: out.base_beta.clone(),
        cols: mech.base_cols.clone(),
        instruments: mech.base_inst.clone(),
        names: mech.base_names.clone(),
        small: out.small.clone(),
    });
    if !pre.cand.is_empty() {
        let data = presliding_pass(&mech, &out.findings, all_rows, pre.cand, &f.wf_m, &f.s);
        let pout = pass.select(&data);
        if let Some(j) = pass.acc.judged.last_mut() {
            j.small.extend(pout.small);
        }
        pass.acc.findings.extend(pout.findings);
        pass.acc.tested.extend(pout.first_round);
    }
    pass.acc.findings.extend(out.findings);
    pass.acc.tested.extend(out.first_round);
}
