//! Measures the weak-form torque-equation residual of the TRUE model on emulated data, to
//! see what a correct model leaves unexplained and why.
//!
//! The emulator is stepped one fine step (0.2 ms) at a time, so every integral can be taken
//! exactly on the fine grid; then the sample-level (12 ms) approximations the identification
//! uses are swapped in one at a time. Residuals are printed in N·m (window integral divided
//! by ∫φ), with their correlation with effect regressors.
//!
//! `cargo run --release -p host-tools --example weakform_truth -- [a|b|steady] [seconds]`
use control::lugre::LugreParams;
use motorid::emulator::{signal, EmulatorConfig, Plant, SignalKind, SAMPLE_PERIOD};
use motorid::ident::sindyc::correlation as corr;
use motorid::log::MotorLog;
use motorid::numerics::differentiation::smooth_velocity;
use motorid::numerics::statistics::rms;
use motorid::numerics::weak_form::{windows, Window, HOP, WINDOW};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = SignalKind::from_name(args.get(1).map(|s| s.as_str()).unwrap_or("a")).unwrap();
    let dur: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(90.0);
    let cfg = EmulatorConfig::paper();
    let m = cfg.motor;
    let lg: LugreParams<f64> = cfg.lugre;
    let u = signal(kind, dur, cfg.seed);
    let nf = 60usize;
    let hf = SAMPLE_PERIOD / nf as f64;
    let mut plant = Plant::new(cfg.clone()).unwrap();
    // fine grid (state at t = j·hf), and samples
    let (mut tf, mut thf, mut wf, mut if_, mut ff, mut zf) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut log = MotorLog::default();
    let mut imeas = vec![];
    let mut tru = (vec![], vec![], vec![], vec![], vec![]); // theta, omega, i, F, z
    for (k, &v) in u.iter().enumerate() {
        let s = plant.truth();
        log.t.push(k as f64 * SAMPLE_PERIOD);
        log.u.push(v);
        log.theta.push(plant.hall_angle());
        imeas.push(plant.measured_current());
        tru.0.push(s.theta);
        tru.1.push(s.omega);
        tru.2.push(s.i);
        tru.3.push(s.friction);
        tru.4.push(s.z);
        for _ in 0..nf {
            let s = plant.truth();
            tf.push(s.t);
            thf.push(s.theta);
            wf.push(s.omega);
            if_.push(s.i);
            ff.push(s.friction);
            zf.push(s.z);
            plant.apply(v, hf);
        }
    }
    let s = plant.truth();
    tf.push(s.t);
    thf.push(s.theta);
    wf.push(s.omega);
    if_.push(s.i);
    ff.push(s.friction);
    zf.push(s.z);
    log.i = Some(imeas.clone());
    let n = log.len();
    let wins = windows(&log.t, WINDOW, HOP);
    // The same windows on the fine grid.
    let fine_t: Vec<f64> = tf.clone();
    let fwins: Vec<Window> = wins
        .iter()
        .map(|w| {
            let a = w.start * nf;
            let b = (w.end - 1) * nf + 1;
            windows(&fine_t[a..b], b - a, b - a).remove(0)
        })
        .collect();
    let fwin_off: Vec<usize> = wins.iter().map(|w| w.start * nf).collect();
    let fint = |k: usize, g: &[f64]| {
        let o = fwin_off[k];
        fwins[k].int(&g[o..])
    };
    let fint_dd = |k: usize, g: &[f64]| {
        let o = fwin_off[k];
        fwins[k].int_dd(&g[o..])
    };
    let fint_d = |k: usize, g: &[f64]| {
        let o = fwin_off[k];
        fwins[k].int_d(&g[o..])
    };
    let ones = vec![1.0; n];
    let norm: Vec<f64> = wins.iter().map(|w| w.int(&ones)).collect();
    let steady = |w: f64| lg.steady_friction(w);
    let s_true: Vec<f64> = tru.1.iter().map(|&w| steady(w)).collect();
    let ws = smooth_velocity(&log, 5);
    let s_meas: Vec<f64> = ws.iter().map(|&w| steady(w)).collect();
    let sf_true: Vec<f64> = wf.iter().map(|&w| steady(w)).collect();
    let z_f: Vec<f64> = zf.clone();
    let sig = |w: f64| {
        if w > 0.0 {
            1.0
        } else if w < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    // Regressors (per window, ∫φ·g / ∫φ).
    let reg_names = ["1", "sgn(w)", "w", "|KtI|sgn(w)", "-(s1/s0)∫φ'S(w)"];
    let g_sgn: Vec<f64> = tru.1.iter().map(|&w| sig(w)).collect();
    let g_lf: Vec<f64> = tru
        .1
        .iter()
        .zip(&tru.2)
        .map(|(&w, &i)| (m.kt * i).abs() * sig(w))
        .collect();
    let regs: Vec<Vec<f64>> = vec![
        wins.iter()
            .zip(&norm)
            .map(|(w, c)| w.int(&ones) / c)
            .collect(),
        wins.iter()
            .zip(&norm)
            .map(|(w, c)| w.int(&g_sgn) / c)
            .collect(),
        wins.iter()
            .zip(&norm)
            .map(|(w, c)| w.int(&tru.1) / c)
            .collect(),
        wins.iter()
            .zip(&norm)
            .map(|(w, c)| w.int(&g_lf) / c)
            .collect(),
        wins.iter()
            .zip(&norm)
            .map(|(w, c)| -lg.sigma1 / lg.sigma0 * w.int_d(&s_true) / c)
            .collect(),
    ];
    // Windows where the rotor moves throughout (|ω_true| ≥ 1 rad/s), as diagnose keeps.
    let moving_only = std::env::var("MOVING").is_ok_and(|v| v == "1");
    let keep: Vec<bool> = wins
        .iter()
        .map(|w| !moving_only || tru.1[w.start..w.end].iter().all(|v| v.abs() >= 1.0))
        .collect();
    let regs: Vec<Vec<f64>> = regs
        .iter()
        .map(|g| {
            g.iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(v, _)| *v)
                .collect()
        })
        .collect();
    let report = |name: &str, r: Vec<f64>| {
        let r: Vec<f64> = r
            .iter()
            .zip(&norm)
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|((a, b), _)| a / b)
            .collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        print!("{name:<58} rms {:.5} mean {:+.5} |", rms(&r), mean);
        for (nm, g) in reg_names.iter().zip(&regs) {
            print!(" {nm} {:+.2}", corr(&r, g));
        }
        println!();
    };
    let kt = m.kt;
    let j = m.j;
    let nw = wins.len();
    println!("{nw} windows; torque scale alpha0 = {}", lg.alpha0);
    // 0: everything exact on the fine grid.
    report(
        "fine: Kt∫φI − J∫φ''θ − ∫φF (all fine)",
        (0..nw)
            .map(|k| kt * fint(k, &if_) - j * fint_dd(k, &thf) - fint(k, &ff))
            .collect(),
    );
    report(
        "fine, F = sigma0 z + sigma1 zdot via -s1∫φ'z",
        (0..nw)
            .map(|k| {
                kt * fint(k, &if_) - j * fint_dd(k, &thf) - lg.sigma0 * fint(k, &z_f)
                    + lg.sigma1 * fint_d(k, &z_f)
                    - lg.alpha2 * fint(k, &wf)
            })
            .collect(),
    );
    report(
        "fine, F = steady S(w_true)",
        (0..nw)
            .map(|k| kt * fint(k, &if_) - j * fint_dd(k, &thf) - fint(k, &sf_true))
            .collect(),
    );
    report(
        "fine, F = S(w) - (s1/s0)∫φ' S(w)",
        (0..nw)
            .map(|k| {
                kt * fint(k, &if_) - j * fint_dd(k, &thf) - fint(k, &sf_true)
                    + lg.sigma1 / lg.sigma0 * fint_d(k, &sf_true)
            })
            .collect(),
    );
    // sample level, truth
    let ex_i: Vec<f64> = (0..nw).map(|k| kt * fint(k, &if_)).collect();
    let ex_th: Vec<f64> = (0..nw).map(|k| j * fint_dd(k, &thf)).collect();
    let ex_f: Vec<f64> = (0..nw).map(|k| fint(k, &ff)).collect();
    report(
        "samples: I_true, θ_true, F_true",
        wins.iter()
            .map(|w| kt * w.int(&tru.2) - j * w.int_dd(&tru.0) - w.int(&tru.3))
            .collect(),
    );
    report(
        "exact I,θ; F_true samples",
        (0..nw)
            .map(|k| ex_i[k] - ex_th[k] - wins[k].int(&tru.3))
            .collect(),
    );
    report(
        "exact F,θ; I_true samples",
        (0..nw)
            .map(|k| kt * wins[k].int(&tru.2) - ex_th[k] - ex_f[k])
            .collect(),
    );
    // Trapezoid of the sampled current plus the input steps' share: the current jumps to its
    // new quasi-static value within L/R of each step, the trapezoid assumes a ramp.
    let tau = m.l / m.r;
    let du: Vec<f64> = (0..n)
        .map(|k| if k == 0 { 0.0 } else { (u[k] - u[k - 1]) / m.r })
        .collect();
    let step_corr = |w: &Window| -> f64 {
        (w.start..w.end)
            .map(|k| w.w0[k - w.start] / SAMPLE_PERIOD * (0.5 * SAMPLE_PERIOD - tau) * du[k])
            .sum()
    };
    report(
        "exact F,θ; I_true samples + step correction",
        (0..nw)
            .map(|k| kt * (wins[k].int(&tru.2) + step_corr(&wins[k])) - ex_th[k] - ex_f[k])
            .collect(),
    );
    report(
        "exact F,θ; I_meas samples + step correction",
        (0..nw)
            .map(|k| kt * (wins[k].int(&imeas) + step_corr(&wins[k])) - ex_th[k] - ex_f[k])
            .collect(),
    );
    report(
        "effect_residual + step correction",
        wins.iter()
            .map(|w| {
                kt * (w.int(&imeas) + step_corr(w)) - j * w.int_dd(&log.theta) - w.int(&s_meas)
            })
            .collect(),
    );
    report(
        "exact I,F; θ_true samples",
        (0..nw)
            .map(|k| ex_i[k] - j * wins[k].int_dd(&tru.0) - ex_f[k])
            .collect(),
    );
    report(
        "exact I,F; θ Hall",
        (0..nw)
            .map(|k| ex_i[k] - j * wins[k].int_dd(&log.theta) - ex_f[k])
            .collect(),
    );
    report(
        "exact I,θ; F = S(w_true) samples",
        (0..nw)
            .map(|k| ex_i[k] - ex_th[k] - wins[k].int(&s_true))
            .collect(),
    );
    report(
        "exact I,θ; F = S(smooth_velocity(Hall))",
        (0..nw)
            .map(|k| ex_i[k] - ex_th[k] - wins[k].int(&s_meas))
            .collect(),
    );
    report(
        "exact I,θ; F = S(w_true) - (s1/s0)∫φ'S",
        (0..nw)
            .map(|k| {
                ex_i[k] - ex_th[k] - wins[k].int(&s_true)
                    + lg.sigma1 / lg.sigma0 * wins[k].int_d(&s_true)
            })
            .collect(),
    );
    report(
        "exact I,θ; F = S(ws) - (s1/s0)∫φ'S(ws)",
        (0..nw)
            .map(|k| {
                ex_i[k] - ex_th[k] - wins[k].int(&s_meas)
                    + lg.sigma1 / lg.sigma0 * wins[k].int_d(&s_meas)
            })
            .collect(),
    );
    report(
        "as effect_residual: I_meas, θ Hall, S(ws)",
        wins.iter()
            .map(|w| kt * w.int(&imeas) - j * w.int_dd(&log.theta) - w.int(&s_meas))
            .collect(),
    );
    report(
        "effect_residual + -(s1/s0)∫φ'S(ws)",
        wins.iter()
            .map(|w| {
                kt * w.int(&imeas) - j * w.int_dd(&log.theta) - w.int(&s_meas)
                    + lg.sigma1 / lg.sigma0 * w.int_d(&s_meas)
            })
            .collect(),
    );
    // Current through the voltage equation (what diagnose does): K_t∫φI =
    // (K_t/R)(∫φ_zoh u − K_b∫φω − L∫φİ), ∫φω = −∫φ'θ, ∫φİ = −∫φ'I.
    let i_volt: Vec<f64> = wins
        .iter()
        .map(|w| {
            kt / m.r * (w.int_zoh(&log.u) + m.kb * w.int_d(&log.theta) + m.l * w.int_d(&imeas))
        })
        .collect();
    report(
        "exact θ,F; I via volts (u zoh, θ Hall, I_meas)",
        (0..nw).map(|k| i_volt[k] - ex_th[k] - ex_f[k]).collect(),
    );
    report(
        "volts, θ Hall, S(ws)",
        (0..nw)
            .map(|k| i_volt[k] - j * wins[k].int_dd(&log.theta) - wins[k].int(&s_meas))
            .collect(),
    );
    println!("kept {} windows", keep.iter().filter(|k| **k).count());
    let _ = (&z_f, &fint_d);
    // diagnose's bump (half-width 8 samples), torque form in N·m, rows as diagnose keeps them.
    {
        use motorid::diagnose::candidates::Signals;
        use motorid::numerics::weak_form::WeakForm;
        let h = 8usize;
        let wc = WeakForm::new(n, SAMPLE_PERIOD, h, h);
        let nfine = tf.len();
        let wfn = WeakForm::new(nfine, hf, h * nf, h * nf);
        let uf: Vec<f64> = (0..nfine).map(|j| u[(j / nf).min(n - 1)]).collect();
        let rows: Vec<usize> = (0..wc.rows())
            .filter(|&r| wfn.centres.get(r) == Some(&(wc.centres[r] * nf)))
            .collect();
        let sg = Signals::from_log(&log, motorid::log::Plant::Voltage, kt);
        let keep: Vec<bool> = rows
            .iter()
            .map(|&r| {
                let c = wc.centres[r];
                sg.omega[c.saturating_sub(h)..(c + h + 1).min(n)]
                    .iter()
                    .all(|w| w.abs() >= 1.0)
            })
            .collect();
        let pick = |v: Vec<f64>| -> Vec<f64> { rows.iter().map(|&r| v[r]).collect() };
        let norm = pick(wc.integral(&ones));
        let ex_u = wfn.integral_zoh(&uf);
        let ex_w = wfn.integral(&wf);
        let ex_di = wfn.derivative(&if_);
        let ex_i = wfn.integral(&if_);
        let ex_th = wfn.second_derivative(&thf);
        let ex_f = wfn.integral(&ff);
        let g_ex_sgn = wfn.integral(&wf.iter().map(|&w| sig(w)).collect::<Vec<_>>());
        let g_ex_lf = wfn.integral(
            &wf.iter()
                .zip(&if_)
                .map(|(&w, &i)| (kt * i).abs() * sig(w))
                .collect::<Vec<_>>(),
        );
        let g_ex_w = wfn.integral(&wf);
        let regs = [
            ("1", vec![1.0; rows.len()]),
            ("sgn", g_ex_sgn),
            ("w", g_ex_w),
            ("|KtI|sgn", g_ex_lf),
        ];
        let rep = |name: &str, r: Vec<f64>| {
            let v: Vec<f64> = r
                .iter()
                .zip(&norm)
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|((a, b), _)| a / b)
                .collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            print!("D {name:<56} rms {:.5} mean {:+.5} |", rms(&v), mean);
            for (nm, g) in &regs {
                let gg: Vec<f64> = g
                    .iter()
                    .zip(&norm)
                    .zip(&keep)
                    .filter(|(_, k)| **k)
                    .map(|((a, b), _)| a / b)
                    .collect();
                print!(" {nm} {:+.2}", corr(&v, &gg));
            }
            println!();
        };
        let q = kt / m.r;
        rep(
            "fine: Kt∫φI − J∫φ''θ − ∫φF",
            pick(
                (0..nfine.min(ex_i.len()))
                    .map(|r| kt * ex_i[r] - j * ex_th[r] - ex_f[r])
                    .collect(),
            ),
        );
        let volts = |uu: &[f64], ww: &[f64], di: &[f64]| -> Vec<f64> {
            (0..uu.len())
                .map(|r| q * (uu[r] - m.kb * ww[r] - m.l * di[r]))
                .collect()
        };
        let ex_v = volts(&ex_u, &ex_w, &ex_di);
        rep(
            "fine volts: q(∫u − Kb∫ω − L∫İ) − J∫θ'' − ∫F",
            pick(
                (0..ex_v.len())
                    .map(|r| ex_v[r] - j * ex_th[r] - ex_f[r])
                    .collect(),
            ),
        );
        let c_u = wc.integral_zoh(&log.u);
        let c_w_true = wc.integral(&tru.1);
        let c_w_hall = wc.derivative(&log.theta);
        let c_di = wc.derivative(&imeas);
        let c_di_true = wc.derivative(&tru.2);
        let exv = pick(ex_v.clone());
        let exth: Vec<f64> = pick(ex_th.clone()).iter().map(|v| j * v).collect();
        let exf = pick(ex_f.clone());
        let pu = pick(c_u.clone());
        let pw_h = pick(c_w_hall.clone());
        let pw_t = pick(c_w_true.clone());
        let pdi = pick(c_di.clone());
        let pdi_t = pick(c_di_true.clone());
        let pexw = pick(ex_w.clone());
        let pexdi = pick(ex_di.clone());
        let nr = rows.len();
        // The torque balance with the exact inertia and friction terms and one (u, ω, İ) choice.
        let with_drive = |u: &[f64], w: &[f64], di: &[f64]| -> Vec<f64> {
            (0..nr)
                .map(|r| q * (u[r] - m.kb * w[r] - m.l * di[r]) - exth[r] - exf[r])
                .collect()
        };
        rep("samples u zoh (else exact)", with_drive(&pu, &pexw, &pexdi));
        rep(
            "∫ω from θ_Hall (else exact)",
            with_drive(&pu, &pw_h, &pexdi),
        );
        rep("∫ω from ω_true samples", with_drive(&pu, &pw_t, &pexdi));
        rep("L∫İ from I_true samples", with_drive(&pu, &pexw, &pdi_t));
        rep("L∫İ from I_meas samples", with_drive(&pu, &pexw, &pdi));
        let pth_h = pick(wc.second_derivative(&log.theta));
        let pth_t = pick(wc.second_derivative(&tru.0));
        rep(
            "J∫θ'' θ_true samples",
            (0..nr).map(|r| exv[r] - j * pth_t[r] - exf[r]).collect(),
        );
        rep(
            "J∫θ'' θ_Hall",
            (0..nr).map(|r| exv[r] - j * pth_h[r] - exf[r]).collect(),
        );
        let pf_t = pick(wc.integral(&tru.3));
        let s_w_true: Vec<f64> = tru.1.iter().map(|&w| steady(w)).collect();
        let s_sg: Vec<f64> = sg.omega.iter().map(|&w| steady(w)).collect();
        let pf_s = pick(wc.integral(&s_w_true));
        let pf_sg = pick(wc.integral(&s_sg));
        rep(
            "F_true samples",
            (0..nr).map(|r| exv[r] - exth[r] - pf_t[r]).collect(),
        );
        rep(
            "F = S(ω_true) samples",
            (0..nr).map(|r| exv[r] - exth[r] - pf_s[r]).collect(),
        );
        rep(
            "F = S(ω_smoothed Hall) (diagnose's ω)",
            (0..nr).map(|r| exv[r] - exth[r] - pf_sg[r]).collect(),
        );
        rep(
            "all sample-level: u, θ_Hall, I_meas, S(ω_s)",
            (0..nr)
                .map(|r| q * (pu[r] - m.kb * pw_h[r] - m.l * pdi[r]) - j * pth_h[r] - pf_sg[r])
                .collect(),
        );
        // The sampled analytic φ'' as weights (their sum is not 0), for comparison.
        let big_t = h as f64 * SAMPLE_PERIOD;
        let w2_old: Vec<f64> = (-(h as isize)..=(h as isize))
            .map(|k| {
                let s = k as f64 / h as f64;
                let q = 1.0 - s * s;
                (-8.0 * q.powi(3) + 48.0 * s * s * q.powi(2)) / (big_t * big_t) * SAMPLE_PERIOD
            })
            .collect();
        let old_acc: Vec<f64> = rows
            .iter()
            .map(|&r| {
                let c = wc.centres[r];
                w2_old
                    .iter()
                    .zip(&log.theta[c - h..])
                    .map(|(a, b)| a * b)
                    .sum()
            })
            .collect();
        let th_int = pick(wc.integral(&log.theta));
        let all_new: Vec<f64> = (0..nr)
            .map(|r| q * (pu[r] - m.kb * pw_h[r] - m.l * pdi[r]) - j * pth_h[r] - pf_sg[r])
            .collect();
        let all_old: Vec<f64> = (0..nr)
            .map(|r| q * (pu[r] - m.kb * pw_h[r] - m.l * pdi[r]) - j * old_acc[r] - pf_sg[r])
            .collect();
        rep(
            "all sample-level, OLD analytic φ'' weights",
            all_old.clone(),
        );
        for (nm, v) in [("new", &all_new), ("old", &all_old)] {
            let a: Vec<f64> = v
                .iter()
                .zip(&norm)
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|((a, b), _)| a / b)
                .collect();
            let b: Vec<f64> = th_int
                .iter()
                .zip(&norm)
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|((a, b), _)| a / b)
                .collect();
            println!(
                "D {nm}: corr(residual, window-mean θ) = {:+.3}",
                corr(&a, &b)
            );
        }
        println!(
            "D kept {} of {} rows",
            keep.iter().filter(|k| **k).count(),
            nr
        );
    }
    diagnose_true(kind, dur);
}

/// `diagnose` with the emulator's own LuGre structure on a simulated log: what the base
/// residual of the torque equation looks like and what the candidates explain.
fn diagnose_true(kind: SignalKind, dur: f64) {
    use motorid::diagnose::{diagnose, Options, Structure};
    let st = Structure::lugre_paper(motorid::log::Plant::Voltage);
    let mut cfg = EmulatorConfig::paper();
    // HIDDEN=spec;spec hides effects (the structure stays the true LuGre one).
    if let Ok(h) = std::env::var("HIDDEN") {
        cfg.effects = h
            .split(';')
            .filter(|s| !s.is_empty())
            .map(|s| {
                motorid::effect_spec::EffectSpec::parse(s)
                    .unwrap()
                    .to_effect()
            })
            .collect();
    }
    let log = motorid::emulator::simulate_signal(&cfg, kind, dur)
        .unwrap()
        .log;
    let d = diagnose(&log, &st, &Options::default());
    let m = cfg.motor;
    let dt = SAMPLE_PERIOD;
    let h = motorid::diagnose::candidates::samples_for(
        motorid::numerics::weak_form::HALF_WIDTH_S,
        dt,
        log.len() / 2,
    );
    let wfm = motorid::numerics::weak_form::WeakForm::new(log.len(), dt, h, h);
    let phi_int = wfm.integral(&vec![1.0; log.len()])[0];
    for e in &d.equations {
        let to_nm = if e.unit == "V·s" && format!("{:?}", e.equation) == "Mechanical" {
            m.kt / m.r / phi_int
        } else {
            1.0 / phi_int
        };
        let b: Vec<f64> = e.base.iter().map(|v| v * to_nm).collect();
        println!(
            "diagnose {:?}: {} rows, base rms {:.5} (N·m or V), n_eff {:.1}",
            e.equation,
            b.len(),
            rms(&b),
            e.n_eff
        );
    }
    for t in &d.tested {
        println!(
            "  tested {:<14} {:?} explained {:.3} p {:.2e} kept {} spec {}",
            t.name, t.equation, t.explained, t.p_value, t.kept, t.spec
        );
    }
    println!(
        "findings: {:?}",
        d.effects.iter().map(|f| f.spec.clone()).collect::<Vec<_>>()
    );
    // What would the load_friction candidate explain with other drive signals?
    let mech = d
        .equations
        .iter()
        .find(|e| format!("{:?}", e.equation) == "Mechanical")
        .unwrap();
    let sg =
        motorid::diagnose::candidates::Signals::from_log(&log, motorid::log::Plant::Voltage, m.kt);
    let eps = sg.velocity_eps();
    let stick = sg.stick_speed();
    let lf = |drive: &[f64], om: &[f64]| -> Vec<f64> {
        drive
            .iter()
            .zip(om)
            .map(|(d, w)| {
                if w.abs() < stick {
                    0.0
                } else {
                    d.abs() * control::effects::smooth_sign(*w, eps)
                }
            })
            .collect()
    };
    let i_meas = log.i.clone().unwrap();
    let cols = [
        (
            "as diagnose (drive = K_t·I_meas unmodelled)",
            sg.load_friction_column(),
        ),
        (
            "|K_t·I_meas|·sgn(ω_s)",
            lf(
                &i_meas.iter().map(|c| m.kt * c).collect::<Vec<_>>(),
                &sg.omega,
            ),
        ),
        (
            "|u|·sgn(ω_s)·K_t/R",
            lf(
                &log.u.iter().map(|c| m.kt / m.r * c).collect::<Vec<_>>(),
                &sg.omega,
            ),
        ),
    ];
    for (name, col) in cols {
        let wint = wfm.integral(&col);
        let cc: Vec<f64> = mech
            .centres
            .iter()
            .map(|&k| wint[wfm.centres.iter().position(|&x| x == k).unwrap()])
            .collect();
        let r = corr(&mech.base, &cc);
        println!(
            "  load_friction column {name:<44}: raw corr² with base residual (not partial) {:.3}",
            r * r
        );
    }
}
