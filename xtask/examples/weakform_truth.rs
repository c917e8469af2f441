//! Measures the weak-form torque-equation residual of the TRUE model on emulated data, to
//! see what a correct model leaves unexplained and why.
//!
//! The emulator is stepped one fine step (0.2 ms) at a time, so every integral can be taken
//! exactly on the fine grid; then the sample-level (12 ms) approximations the identification
//! uses are swapped in one at a time. Residuals are printed in N·m (window integral divided
//! by ∫φ), with their correlation with effect regressors.
//!
//! `cargo run --release -p xtask --example weakform_truth -- [a|b|steady] [seconds]`
//!
//! Environment variables:
//! - `MOVING=1`: keep only the windows where the true rotor speed stays at or above 1 rad/s
//!   throughout, as `diagnose` does.
//! - `HIDDEN=SPEC;SPEC...`: effects (in `--effect` syntax) the emulator adds for the final
//!   `diagnose` run, while the model structure stays the paper's LuGre one.
use control::lugre::LugreParams;
use motorid::diagnose::candidates::Signals;
use motorid::emulator::{signal, EmulatorConfig, Plant, SignalKind, SAMPLE_PERIOD};
use motorid::log::MotorLog;
use motorid::numerics::differentiation::smooth_velocity;
use motorid::numerics::statistics::correlation as corr;
use motorid::numerics::statistics::rms;
use motorid::numerics::weak_form::{windows, WeakForm, Window, HOP, WINDOW};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = SignalKind::from_name(args.get(1).map(|s| s.as_str()).unwrap_or("a")).unwrap();
    let dur: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(90.0);
    let run = FineRun::simulate(kind, dur);
    window_residuals(&run);
    bump_residuals(&run);
    diagnose_true(kind, dur);
}

/// The true states, one value per grid point.
#[derive(Default)]
struct Truth {
    t: Vec<f64>,
    theta: Vec<f64>,
    omega: Vec<f64>,
    i: Vec<f64>,
    friction: Vec<f64>,
    z: Vec<f64>,
}

impl Truth {
    fn push(&mut self, s: &motorid::emulator::TrueState) {
        self.t.push(s.t);
        self.theta.push(s.theta);
        self.omega.push(s.omega);
        self.i.push(s.i);
        self.friction.push(s.friction);
        self.z.push(s.z);
    }
}

/// The paper's emulated motor run with one signal, stepped [`FineRun::nf`] fine steps per
/// sample.
struct FineRun {
    cfg: EmulatorConfig,
    /// The input, one value per sample [V].
    u: Vec<f64>,
    /// Fine steps per sample, and the fine step [s].
    nf: usize,
    hf: f64,
    /// The sampled log: t, u, the Hall angle and the measured current.
    log: MotorLog,
    imeas: Vec<f64>,
    /// The true states at the samples and on the fine grid (one more point at the end).
    tru: Truth,
    fine: Truth,
}

impl FineRun {
    fn simulate(kind: SignalKind, dur: f64) -> FineRun {
        let cfg = EmulatorConfig::paper();
        let u = signal(kind, dur, cfg.seed);
        let nf = 60usize;
        let hf = SAMPLE_PERIOD / nf as f64;
        let mut plant = Plant::new(cfg.clone()).unwrap();
        let mut fine = Truth::default();
        let mut log = MotorLog::default();
        let mut imeas = vec![];
        let mut tru = Truth::default();
        for (k, &v) in u.iter().enumerate() {
            let s = plant.truth();
            log.t.push(k as f64 * SAMPLE_PERIOD);
            log.u.push(v);
            log.theta.push(plant.hall_angle());
            imeas.push(plant.measured_current());
            tru.push(&s);
            for _ in 0..nf {
                fine.push(&plant.truth());
                plant.apply(v, hf);
            }
        }
        fine.push(&plant.truth());
        log.i = Some(imeas.clone());
        FineRun {
            cfg,
            u,
            nf,
            hf,
            log,
            imeas,
            tru,
            fine,
        }
    }

    fn lugre(&self) -> LugreParams<f64> {
        self.cfg.lugre
    }

    fn steady(&self, w: &[f64]) -> Vec<f64> {
        let lg = self.lugre();
        w.iter().map(|&w| lg.steady_friction(w)).collect()
    }
}

fn sig(w: f64) -> f64 {
    if w > 0.0 {
        1.0
    } else if w < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The identification's sample windows, the same windows on the fine grid, the windows kept
/// and the effect regressors on them.
struct Windows {
    wins: Vec<Window>,
    fwins: Vec<Window>,
    fwin_off: Vec<usize>,
    norm: Vec<f64>,
    keep: Vec<bool>,
    reg_names: [&'static str; 5],
    regs: Vec<Vec<f64>>,
}

impl Windows {
    fn new(run: &FineRun) -> Windows {
        let (log, nf, tru, lg) = (&run.log, run.nf, &run.tru, run.lugre());
        let n = log.len();
        let wins = windows(&log.t, WINDOW, HOP);
        // The same windows on the fine grid.
        let fine_t: Vec<f64> = run.fine.t.clone();
        let fwins: Vec<Window> = wins
            .iter()
            .map(|w| {
                let a = w.start * nf;
                let b = (w.end - 1) * nf + 1;
                windows(&fine_t[a..b], b - a, b - a).remove(0)
            })
            .collect();
        let fwin_off: Vec<usize> = wins.iter().map(|w| w.start * nf).collect();
        let ones = vec![1.0; n];
        let norm: Vec<f64> = wins.iter().map(|w| w.int(&ones)).collect();
        let s_true = run.steady(&tru.omega);
        // Regressors (per window, ∫φ·g / ∫φ).
        let reg_names = ["1", "sgn(w)", "w", "|KtI|sgn(w)", "-(s1/s0)∫φ'S(w)"];
        let g_sgn: Vec<f64> = tru.omega.iter().map(|&w| sig(w)).collect();
        let kt = run.cfg.motor.kt;
        let g_lf: Vec<f64> = tru
            .omega
            .iter()
            .zip(&tru.i)
            .map(|(&w, &i)| (kt * i).abs() * sig(w))
            .collect();
        let per_window = |f: &dyn Fn(&Window) -> f64| -> Vec<f64> {
            wins.iter().zip(&norm).map(|(w, c)| f(w) / c).collect()
        };
        let regs: Vec<Vec<f64>> = vec![
            per_window(&|w| w.int(&ones)),
            per_window(&|w| w.int(&g_sgn)),
            per_window(&|w| w.int(&tru.omega)),
            per_window(&|w| w.int(&g_lf)),
            per_window(&|w| -lg.sigma1 / lg.sigma0 * w.int_d(&s_true)),
        ];
        // Windows where the rotor moves throughout (|ω_true| ≥ 1 rad/s), as diagnose keeps.
        let moving_only = std::env::var("MOVING").is_ok_and(|v| v == "1");
        let keep: Vec<bool> = wins
            .iter()
            .map(|w| !moving_only || tru.omega[w.start..w.end].iter().all(|v| v.abs() >= 1.0))
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
        Windows {
            wins,
            fwins,
            fwin_off,
            norm,
            keep,
            reg_names,
            regs,
        }
    }

    fn fint(&self, k: usize, g: &[f64]) -> f64 {
        self.fwins[k].int(&g[self.fwin_off[k]..])
    }

    fn fint_dd(&self, k: usize, g: &[f64]) -> f64 {
        self.fwins[k].int_dd(&g[self.fwin_off[k]..])
    }

    fn fint_d(&self, k: usize, g: &[f64]) -> f64 {
        self.fwins[k].int_d(&g[self.fwin_off[k]..])
    }

    /// One line: the residual's RMS and mean [N·m] over the kept windows, and its
    /// correlation with each regressor.
    fn report(&self, name: &str, r: Vec<f64>) {
        let r: Vec<f64> = r
            .iter()
            .zip(&self.norm)
            .zip(&self.keep)
            .filter(|(_, k)| **k)
            .map(|((a, b), _)| a / b)
            .collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        print!("{name:<58} rms {:.5} mean {:+.5} |", rms(&r), mean);
        for (nm, g) in self.reg_names.iter().zip(&self.regs) {
            print!(" {nm} {:+.2}", corr(&r, g));
        }
        println!();
    }
}

/// The residual of the true model on the identification's windows, each approximation of
/// the sample level swapped in one at a time.
fn window_residuals(run: &FineRun) {
    let w = Windows::new(run);
    let nw = w.wins.len();
    println!("{nw} windows; torque scale alpha0 = {}", run.lugre().alpha0);
    fine_grid_reports(run, &w);
    let m = run.cfg.motor;
    let ex_i: Vec<f64> = (0..nw).map(|k| m.kt * w.fint(k, &run.fine.i)).collect();
    let ex_th: Vec<f64> = (0..nw)
        .map(|k| m.j * w.fint_dd(k, &run.fine.theta))
        .collect();
    let ex_f: Vec<f64> = (0..nw).map(|k| w.fint(k, &run.fine.friction)).collect();
    let exact = Exact {
        i: ex_i,
        th: ex_th,
        f: ex_f,
    };
    sample_reports(run, &w, &exact);
    volts_reports(run, &w, &exact);
    println!("kept {} windows", w.keep.iter().filter(|k| **k).count());
}

/// Window integrals taken exactly on the fine grid: K_t∫φI, J∫φ''θ and ∫φF [N·m·s].
struct Exact {
    i: Vec<f64>,
    th: Vec<f64>,
    f: Vec<f64>,
}

/// Everything exact on the fine grid, with the friction in its LuGre and steady forms.
fn fine_grid_reports(run: &FineRun, w: &Windows) {
    let (m, lg, fine) = (run.cfg.motor, run.lugre(), &run.fine);
    let (kt, j) = (m.kt, m.j);
    let nw = w.wins.len();
    let sf_true = run.steady(&fine.omega);
    w.report(
        "fine: Kt∫φI − J∫φ''θ − ∫φF (all fine)",
        (0..nw)
            .map(|k| {
                kt * w.fint(k, &fine.i) - j * w.fint_dd(k, &fine.theta) - w.fint(k, &fine.friction)
            })
            .collect(),
    );
    w.report(
        "fine, F = sigma0 z + sigma1 zdot via -s1∫φ'z",
        (0..nw)
            .map(|k| {
                kt * w.fint(k, &fine.i)
                    - j * w.fint_dd(k, &fine.theta)
                    - lg.sigma0 * w.fint(k, &fine.z)
                    + lg.sigma1 * w.fint_d(k, &fine.z)
                    - lg.alpha2 * w.fint(k, &fine.omega)
            })
            .collect(),
    );
    w.report(
        "fine, F = steady S(w_true)",
        (0..nw)
            .map(|k| kt * w.fint(k, &fine.i) - j * w.fint_dd(k, &fine.theta) - w.fint(k, &sf_true))
            .collect(),
    );
    w.report(
        "fine, F = S(w) - (s1/s0)∫φ' S(w)",
        (0..nw)
            .map(|k| {
                kt * w.fint(k, &fine.i) - j * w.fint_dd(k, &fine.theta) - w.fint(k, &sf_true)
                    + lg.sigma1 / lg.sigma0 * w.fint_d(k, &sf_true)
            })
            .collect(),
    );
}

/// The sample-level current swapped in, with and without the input steps' share.
fn sample_reports(run: &FineRun, w: &Windows, ex: &Exact) {
    let (m, tru, log) = (run.cfg.motor, &run.tru, &run.log);
    let (kt, j) = (m.kt, m.j);
    let (wins, nw) = (&w.wins, w.wins.len());
    let s_meas = run.steady(&smooth_velocity(log));
    w.report(
        "samples: I_true, θ_true, F_true",
        wins.iter()
            .map(|w| kt * w.int(&tru.i) - j * w.int_dd(&tru.theta) - w.int(&tru.friction))
            .collect(),
    );
    w.report(
        "exact I,θ; F_true samples",
        (0..nw)
            .map(|k| ex.i[k] - ex.th[k] - wins[k].int(&tru.friction))
            .collect(),
    );
    w.report(
        "exact F,θ; I_true samples",
        (0..nw)
            .map(|k| kt * wins[k].int(&tru.i) - ex.th[k] - ex.f[k])
            .collect(),
    );
    let step_corr = step_correction(run);
    w.report(
        "exact F,θ; I_true samples + step correction",
        (0..nw)
            .map(|k| kt * (wins[k].int(&tru.i) + step_corr(&wins[k])) - ex.th[k] - ex.f[k])
            .collect(),
    );
    w.report(
        "exact F,θ; I_meas samples + step correction",
        (0..nw)
            .map(|k| kt * (wins[k].int(&run.imeas) + step_corr(&wins[k])) - ex.th[k] - ex.f[k])
            .collect(),
    );
    w.report(
        "effect_residual + step correction",
        wins.iter()
            .map(|w| {
                kt * (w.int(&run.imeas) + step_corr(w)) - j * w.int_dd(&log.theta) - w.int(&s_meas)
            })
            .collect(),
    );
    angle_and_friction_reports(run, w, ex);
}

/// The sample-level angle, then the friction from the true and the estimated velocity.
fn angle_and_friction_reports(run: &FineRun, w: &Windows, ex: &Exact) {
    let (m, lg, tru, log) = (run.cfg.motor, run.lugre(), &run.tru, &run.log);
    let (kt, j) = (m.kt, m.j);
    let (wins, nw) = (&w.wins, w.wins.len());
    let s_true = run.steady(&tru.omega);
    let s_meas = run.steady(&smooth_velocity(log));
    w.report(
        "exact I,F; θ_true samples",
        (0..nw)
            .map(|k| ex.i[k] - j * wins[k].int_dd(&tru.theta) - ex.f[k])
            .collect(),
    );
    w.report(
        "exact I,F; θ Hall",
        (0..nw)
            .map(|k| ex.i[k] - j * wins[k].int_dd(&log.theta) - ex.f[k])
            .collect(),
    );
    w.report(
        "exact I,θ; F = S(w_true) samples",
        (0..nw)
            .map(|k| ex.i[k] - ex.th[k] - wins[k].int(&s_true))
            .collect(),
    );
    w.report(
        "exact I,θ; F = S(smooth_velocity(Hall))",
        (0..nw)
            .map(|k| ex.i[k] - ex.th[k] - wins[k].int(&s_meas))
            .collect(),
    );
    w.report(
        "exact I,θ; F = S(w_true) - (s1/s0)∫φ'S",
        (0..nw)
            .map(|k| {
                ex.i[k] - ex.th[k] - wins[k].int(&s_true)
                    + lg.sigma1 / lg.sigma0 * wins[k].int_d(&s_true)
            })
            .collect(),
    );
    w.report(
        "exact I,θ; F = S(ws) - (s1/s0)∫φ'S(ws)",
        (0..nw)
            .map(|k| {
                ex.i[k] - ex.th[k] - wins[k].int(&s_meas)
                    + lg.sigma1 / lg.sigma0 * wins[k].int_d(&s_meas)
            })
            .collect(),
    );
    w.report(
        "as effect_residual: I_meas, θ Hall, S(ws)",
        wins.iter()
            .map(|w| kt * w.int(&run.imeas) - j * w.int_dd(&log.theta) - w.int(&s_meas))
            .collect(),
    );
    w.report(
        "effect_residual + -(s1/s0)∫φ'S(ws)",
        wins.iter()
            .map(|w| {
                kt * w.int(&run.imeas) - j * w.int_dd(&log.theta) - w.int(&s_meas)
                    + lg.sigma1 / lg.sigma0 * w.int_d(&s_meas)
            })
            .collect(),
    );
}

/// Trapezoid of the sampled current plus the input steps' share: the current jumps to its
/// new quasi-static value within L/R of each step, the trapezoid assumes a ramp.
fn step_correction(run: &FineRun) -> impl Fn(&Window) -> f64 + '_ {
    let m = run.cfg.motor;
    let tau = m.l / m.r;
    let u = &run.u;
    let du: Vec<f64> = (0..run.log.len())
        .map(|k| if k == 0 { 0.0 } else { (u[k] - u[k - 1]) / m.r })
        .collect();
    move |w: &Window| -> f64 {
        (w.start..w.end)
            .map(|k| w.w0[k - w.start] / SAMPLE_PERIOD * (0.5 * SAMPLE_PERIOD - tau) * du[k])
            .sum()
    }
}

/// The current through the voltage equation (what diagnose does): K_t∫φI =
/// (K_t/R)(∫φ_zoh u − K_b∫φω − L∫φİ), ∫φω = −∫φ'θ, ∫φİ = −∫φ'I.
fn volts_reports(run: &FineRun, w: &Windows, ex: &Exact) {
    let (m, log) = (run.cfg.motor, &run.log);
    let (wins, nw) = (&w.wins, w.wins.len());
    let s_meas = run.steady(&smooth_velocity(log));
    let i_volt: Vec<f64> = wins
        .iter()
        .map(|w| {
            m.kt / m.r
                * (w.int_zoh(&log.u) + m.kb * w.int_d(&log.theta) + m.l * w.int_d(&run.imeas))
        })
        .collect();
    w.report(
        "exact θ,F; I via volts (u zoh, θ Hall, I_meas)",
        (0..nw).map(|k| i_volt[k] - ex.th[k] - ex.f[k]).collect(),
    );
    w.report(
        "volts, θ Hall, S(ws)",
        (0..nw)
            .map(|k| i_volt[k] - m.j * wins[k].int_dd(&log.theta) - wins[k].int(&s_meas))
            .collect(),
    );
}

/// diagnose's bump (half-width 8 samples) on the samples and on the fine grid, at the rows
/// both grids share, kept as diagnose keeps them; torque form in N·m.
struct Bump {
    h: usize,
    wc: WeakForm,
    wfn: WeakForm,
    rows: Vec<usize>,
    sg: Signals,
    keep: Vec<bool>,
    norm: Vec<f64>,
    regs: [(&'static str, Vec<f64>); 4],
}

impl Bump {
    fn new(run: &FineRun) -> Bump {
        let (log, nf, fine) = (&run.log, run.nf, &run.fine);
        let kt = run.cfg.motor.kt;
        let n = log.len();
        let h = 8usize;
        let wc = WeakForm::new(n, SAMPLE_PERIOD, h, h);
        let wfn = WeakForm::new(fine.t.len(), run.hf, h * nf, h * nf);
        let rows: Vec<usize> = (0..wc.rows())
            .filter(|&r| wfn.centres.get(r) == Some(&(wc.centres[r] * nf)))
            .collect();
        let sg = Signals::from_log(log, motorid::log::Plant::Voltage, kt);
        let keep: Vec<bool> = rows
            .iter()
            .map(|&r| {
                let c = wc.centres[r];
                sg.omega[c.saturating_sub(h)..(c + h + 1).min(n)]
                    .iter()
                    .all(|w| w.abs() >= 1.0)
            })
            .collect();
        let ones = wc.integral(&vec![1.0; n]);
        let norm: Vec<f64> = rows.iter().map(|&r| ones[r]).collect();
        let g_ex_sgn = wfn.integral(&fine.omega.iter().map(|&w| sig(w)).collect::<Vec<_>>());
        let g_ex_lf = wfn.integral(
            &fine
                .omega
                .iter()
                .zip(&fine.i)
                .map(|(&w, &i)| (kt * i).abs() * sig(w))
                .collect::<Vec<_>>(),
        );
        let g_ex_w = wfn.integral(&fine.omega);
        let regs = [
            ("1", vec![1.0; rows.len()]),
            ("sgn", g_ex_sgn),
            ("w", g_ex_w),
            ("|KtI|sgn", g_ex_lf),
        ];
        Bump {
            h,
            wc,
            wfn,
            rows,
            sg,
            keep,
            norm,
            regs,
        }
    }

    /// The values of `v` at the shared rows.
    fn pick(&self, v: Vec<f64>) -> Vec<f64> {
        self.rows.iter().map(|&r| v[r]).collect()
    }

    /// `v` per unit ∫φ at the kept rows.
    fn kept(&self, v: &[f64]) -> Vec<f64> {
        v.iter()
            .zip(&self.norm)
            .zip(&self.keep)
            .filter(|(_, k)| **k)
            .map(|((a, b), _)| a / b)
            .collect()
    }

    /// One line: the residual's RMS and mean [N·m] over the kept rows, and its correlation
    /// with each regressor.
    fn rep(&self, name: &str, r: Vec<f64>) {
        let v = self.kept(&r);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        print!("D {name:<56} rms {:.5} mean {:+.5} |", rms(&v), mean);
        for (nm, g) in &self.regs {
            print!(" {nm} {:+.2}", corr(&v, &self.kept(g)));
        }
        println!();
    }
}

/// The bump's integrals taken exactly on the fine grid, at the shared rows: the drive
/// q(∫u − K_b∫ω − L∫İ) with q = K_t/R, J∫θ'' and ∫F.
struct BumpExact {
    volts: Vec<f64>,
    th: Vec<f64>,
    f: Vec<f64>,
    w: Vec<f64>,
    di: Vec<f64>,
}

/// The residual of the true model under diagnose's bump, each sample-level approximation
/// swapped in one at a time.
fn bump_residuals(run: &FineRun) {
    let b = Bump::new(run);
    let (m, fine, nf) = (run.cfg.motor, &run.fine, run.nf);
    let (kt, j, q) = (m.kt, m.j, m.kt / m.r);
    let n = run.log.len();
    let nfine = fine.t.len();
    let uf: Vec<f64> = (0..nfine).map(|j| run.u[(j / nf).min(n - 1)]).collect();
    let wfn = &b.wfn;
    let ex_u = wfn.integral_zoh(&uf);
    let ex_w = wfn.integral(&fine.omega);
    let ex_di = wfn.derivative(&fine.i);
    let ex_i = wfn.integral(&fine.i);
    let ex_th = wfn.second_derivative(&fine.theta);
    let ex_f = wfn.integral(&fine.friction);
    b.rep(
        "fine: Kt∫φI − J∫φ''θ − ∫φF",
        b.pick(
            (0..nfine.min(ex_i.len()))
                .map(|r| kt * ex_i[r] - j * ex_th[r] - ex_f[r])
                .collect(),
        ),
    );
    let ex_v: Vec<f64> = (0..ex_u.len())
        .map(|r| q * (ex_u[r] - m.kb * ex_w[r] - m.l * ex_di[r]))
        .collect();
    b.rep(
        "fine volts: q(∫u − Kb∫ω − L∫İ) − J∫θ'' − ∫F",
        b.pick(
            (0..ex_v.len())
                .map(|r| ex_v[r] - j * ex_th[r] - ex_f[r])
                .collect(),
        ),
    );
    let ex = BumpExact {
        volts: b.pick(ex_v),
        th: b.pick(ex_th).iter().map(|v| j * v).collect(),
        f: b.pick(ex_f),
        w: b.pick(ex_w),
        di: b.pick(ex_di),
    };
    bump_sample_reports(run, &b, &ex);
    println!(
        "D kept {} of {} rows",
        b.keep.iter().filter(|k| **k).count(),
        b.rows.len()
    );
}

/// Drive, inertia and friction terms from the samples in turn, then all of them, with the
/// sampled analytic φ'' weights for comparison.
fn bump_sample_reports(run: &FineRun, b: &Bump, ex: &BumpExact) {
    let (m, log, tru) = (run.cfg.motor, &run.log, &run.tru);
    let (j, q) = (m.j, m.kt / m.r);
    let wc = &b.wc;
    let nr = b.rows.len();
    let pu = b.pick(wc.integral_zoh(&log.u));
    let pw_h = b.pick(wc.derivative(&log.theta));
    let pw_t = b.pick(wc.integral(&tru.omega));
    let pdi = b.pick(wc.derivative(&run.imeas));
    let pdi_t = b.pick(wc.derivative(&tru.i));
    // The torque balance with the exact inertia and friction terms and one (u, ω, İ) choice.
    let with_drive = |u: &[f64], w: &[f64], di: &[f64]| -> Vec<f64> {
        (0..nr)
            .map(|r| q * (u[r] - m.kb * w[r] - m.l * di[r]) - ex.th[r] - ex.f[r])
            .collect()
    };
    b.rep("samples u zoh (else exact)", with_drive(&pu, &ex.w, &ex.di));
    b.rep(
        "∫ω from θ_Hall (else exact)",
        with_drive(&pu, &pw_h, &ex.di),
    );
    b.rep("∫ω from ω_true samples", with_drive(&pu, &pw_t, &ex.di));
    b.rep("L∫İ from I_true samples", with_drive(&pu, &ex.w, &pdi_t));
    b.rep("L∫İ from I_meas samples", with_drive(&pu, &ex.w, &pdi));
    let pth_h = b.pick(wc.second_derivative(&log.theta));
    let pth_t = b.pick(wc.second_derivative(&tru.theta));
    b.rep(
        "J∫θ'' θ_true samples",
        (0..nr)
            .map(|r| ex.volts[r] - j * pth_t[r] - ex.f[r])
            .collect(),
    );
    b.rep(
        "J∫θ'' θ_Hall",
        (0..nr)
            .map(|r| ex.volts[r] - j * pth_h[r] - ex.f[r])
            .collect(),
    );
    let pf_t = b.pick(wc.integral(&tru.friction));
    let pf_s = b.pick(wc.integral(&run.steady(&tru.omega)));
    let pf_sg = b.pick(wc.integral(&run.steady(&b.sg.omega)));
    b.rep(
        "F_true samples",
        (0..nr).map(|r| ex.volts[r] - ex.th[r] - pf_t[r]).collect(),
    );
    b.rep(
        "F = S(ω_true) samples",
        (0..nr).map(|r| ex.volts[r] - ex.th[r] - pf_s[r]).collect(),
    );
    b.rep(
        "F = S(ω_smoothed Hall) (diagnose's ω)",
        (0..nr).map(|r| ex.volts[r] - ex.th[r] - pf_sg[r]).collect(),
    );
    let all_new: Vec<f64> = (0..nr)
        .map(|r| q * (pu[r] - m.kb * pw_h[r] - m.l * pdi[r]) - j * pth_h[r] - pf_sg[r])
        .collect();
    b.rep(
        "all sample-level: u, θ_Hall, I_meas, S(ω_s)",
        all_new.clone(),
    );
    let old_acc = analytic_acceleration(b, &log.theta);
    let all_old: Vec<f64> = (0..nr)
        .map(|r| q * (pu[r] - m.kb * pw_h[r] - m.l * pdi[r]) - j * old_acc[r] - pf_sg[r])
        .collect();
    b.rep(
        "all sample-level, OLD analytic φ'' weights",
        all_old.clone(),
    );
    let th_int = b.kept(&b.pick(wc.integral(&log.theta)));
    for (nm, v) in [("new", &all_new), ("old", &all_old)] {
        println!(
            "D {nm}: corr(residual, window-mean θ) = {:+.3}",
            corr(&b.kept(v), &th_int)
        );
    }
}

/// ∫φ''θ at the shared rows with the sampled analytic φ'' as weights (their sum is not 0).
fn analytic_acceleration(b: &Bump, theta: &[f64]) -> Vec<f64> {
    let h = b.h;
    let big_t = h as f64 * SAMPLE_PERIOD;
    let w2_old: Vec<f64> = (-(h as isize)..=(h as isize))
        .map(|k| {
            let s = k as f64 / h as f64;
            let q = 1.0 - s * s;
            (-8.0 * q.powi(3) + 48.0 * s * s * q.powi(2)) / (big_t * big_t) * SAMPLE_PERIOD
        })
        .collect();
    b.rows
        .iter()
        .map(|&r| {
            let c = b.wc.centres[r];
            w2_old.iter().zip(&theta[c - h..]).map(|(a, b)| a * b).sum()
        })
        .collect()
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
