//! Temporary exploration of diagnose on emulated data (removed before delivery).
use control::effects::Effect;
use motorid::diagnose::{diagnose, Options, Structure};
use motorid::effect_spec::EffectSpec;
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use motorid::log::Plant;

fn lugre_structure() -> Vec<Effect<f64>> {
    let p = control::lugre::LugreParams::<f64>::paper();
    vec![
        Effect::Coulomb { fc: p.alpha0 },
        Effect::Stribeck { fs: p.alpha1, vs: p.v0 },
        Effect::Viscous { b: p.alpha2 },
        Effect::Presliding { sigma0: p.sigma0, sigma1: p.sigma1 },
    ]
}

#[test]
#[ignore]
fn explore() {
    let specs = std::env::var("SPECS").unwrap_or_else(|_| "none,cogging,position_load,offset,asymmetry,deadtime,current_offset,thermal,load_friction".into());
    let dur: f64 = std::env::var("DUR").ok().and_then(|s| s.parse().ok()).unwrap_or(60.0);
    for spec in specs.split(',') {
        let mut cfg = EmulatorConfig::paper();
        if spec != "none" {
            cfg.effects.push(EffectSpec::parse(spec).unwrap().to_effect());
        }
        let t0 = std::time::Instant::now();
        let mut sim = simulate_signal(&cfg, SignalKind::A, dur).unwrap();
        if std::env::var_os("TRUTH").is_some() {
            sim.log.theta = sim.truth.theta.clone();
            if std::env::var_os("TRUTHI").is_some() { sim.log.i = Some(sim.truth.i.clone()); }
        }
        let t1 = t0.elapsed();
        let st = Structure::with_effects(Plant::Voltage, lugre_structure());
        let d = diagnose(&sim.log, &st, &Options::default());
        println!("== {spec}: sim {:?} diag {:?}", t1, t0.elapsed() - t1);
        for f in &d.effects {
            println!("   FOUND {} score {:.3} p {:.2e} | {}", f.spec, f.score, f.p_value, f.explanation);
        }
        let mut t = d.tested.clone();
        t.sort_by(|a, b| b.explained.total_cmp(&a.explained));
        for x in t.iter().take(4) {
            println!("   tested {:<14} {:?} expl {:.4} p {:.2e} {}", x.name, x.equation, x.explained, x.p_value, x.spec);
        }
        for e in &d.equations {
            println!("   eq {:?} n_eff {:.0} rows {} acf_out {:.2}", e.equation, e.n_eff, e.base.len(), e.whiteness.acf_outside);
        }
    }
}

#[test]
#[ignore]
fn emulator_balance() {
    let cfg = EmulatorConfig::paper();
    let sim = simulate_signal(&cfg, SignalKind::A, 20.0).unwrap();
    let tr = &sim.truth;
    let m = control::motor::MotorParams::<f64>::paper();
    let p = control::lugre::LugreParams::<f64>::paper();
    let dt = 0.012;
    let i = sim.log.i.as_ref().unwrap();
    let mut stuck = 0;
    for k in (200..1600).step_by(1) {
        let acc = (tr.omega[k + 1] - tr.omega[k]) / dt;
        let zdot = (tr.z[k + 1] - tr.z[k]) / dt;
        let fr = p.sigma0 * tr.z[k + 1] + p.sigma1 * zdot + p.alpha2 * tr.omega[k + 1];
        let res = m.kt * tr.i[k + 1] - m.j * acc - fr;
        if tr.omega[k].abs() < 0.5 { stuck += 1; }
        if k % 25 == 0 {
            println!("k {k} u {:.2} w {:.3} i_true {:.3} i_meas {:.3} ktI {:.4} Jacc {:.4} fric {:.4} res {:.4} z {:.2e}", sim.log.u[k], tr.omega[k], tr.i[k], i[k], m.kt * tr.i[k + 1], m.j * acc, fr, res, tr.z[k]);
        }
    }
    println!("stuck samples {stuck}");
}
