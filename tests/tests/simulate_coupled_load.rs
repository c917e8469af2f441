//! The emulated motor with a load behind a coupling (`compliance`, `backlash`) against
//! physics worked out by hand: the two-mass resonance, energy that never grows, the rigid
//! limit of a stiff coupling, and a load picked up across a gap.
use control::effects::Effect;
use control::lugre::LugreParams;
use control::motor::MotorParams;
use motorid::emulator::{EmulatorConfig, LoadInputs, Plant};

/// The paper's rotor inertia and winding with no torque from the winding and next to no
/// friction (K_t = K_b = 1e-9, static friction 2e-9 N·m, no bristle damping): what moves it is
/// the test's own torque `drive(t)` [N·m], applied through the extra load.
fn free_rotor(effect: Effect<f64>, drive: fn(f64) -> f64) -> EmulatorConfig {
    let motor = MotorParams {
        kt: 1e-9,
        kb: 1e-9,
        ..MotorParams::paper()
    };
    let lugre = LugreParams {
        alpha0: 1e-9,
        alpha1: 1e-9,
        alpha2: 0.0,
        sigma1: 0.0,
        ..LugreParams::paper()
    };
    EmulatorConfig {
        motor,
        lugre,
        current_noise: 0.0,
        ..EmulatorConfig::paper()
    }
    .with_effects(vec![effect])
    .with_extra_load(move |x: LoadInputs| -drive(x.t))
}

/// Times [s] where `x` crosses zero upwards, linearly interpolated between samples `h` apart.
fn upward_crossings(x: &[f64], h: f64) -> Vec<f64> {
    x.windows(2)
        .enumerate()
        .filter(|(_, w)| w[0] < 0.0 && w[1] >= 0.0)
        .map(|(k, w)| (k as f64 + w[0] / (w[0] - w[1])) * h)
        .collect()
}

/// One fine step at a time for `secs`, returning the rotor's and the load's (θ, ω) after each.
fn run(cfg: &EmulatorConfig, secs: f64) -> Vec<[f64; 4]> {
    let h = cfg.fine_step;
    let mut p = Plant::new(cfg.clone()).unwrap();
    (0..(secs / h).round() as usize)
        .map(|_| {
            p.apply(0.0, h);
            let (s, l) = (p.truth(), p.load_states()[0]);
            [s.theta, s.omega, l.theta, l.omega]
        })
        .collect()
}

#[test]
fn a_free_compliant_pair_rings_at_the_two_mass_frequency_and_never_gains_energy() {
    // A 1 ms push of 1 N·m, then nothing: the rotor's speed is the pair's common speed plus
    // the coupled mode at ω_c = √(k·(J + j2)/(J·j2)) (5.03 Hz for the default coupling).
    let (j2, k, c) = (6e-4, 0.2, 0.0);
    let cfg = free_rotor(Effect::Compliance { j2, k, c }, |t| {
        if t < 1.05e-3 {
            1.0
        } else {
            0.0
        }
    });
    let (j, h) = (cfg.motor.j, cfg.fine_step);
    let want = (k * (j + j2) / (j * j2)).sqrt();
    let xs = run(&cfg, 2.0);
    // The common speed: the momentum (J·ω1 + j2·ω2, kept after the push) over J + j2.
    let common = (j * xs[xs.len() - 1][1] + j2 * xs[xs.len() - 1][3]) / (j + j2);
    let osc: Vec<f64> = xs.iter().map(|x| x[1] - common).collect();
    // Crossings once the push is over (the rotor starts from rest, below the common speed).
    let up: Vec<f64> = upward_crossings(&osc, h)
        .into_iter()
        .filter(|t| *t > 2e-3)
        .collect();
    assert!(up.len() >= 9, "{} crossings", up.len());
    let span = up[up.len() - 1] - up[0];
    let measured = 2.0 * std::f64::consts::PI * (up.len() - 1) as f64 / span;
    // Each crossing is located within one step h: the period over `span` is within 2h/span;
    // backward Euler lowers the frequency by (ω_c·h)²/3 on top.
    let tol = 2.0 * h / span + (want * h).powi(2) / 3.0;
    assert!(
        (measured / want - 1.0).abs() < tol,
        "ω_c {measured} rad/s, two-mass {want} rad/s (tolerance {tol:.1e})"
    );

    // With a damper, the pair's kinetic plus spring energy never grows once the push is over,
    // and it falls: the coupled mode dies out.
    let cfg = free_rotor(Effect::Compliance { j2, k, c: 6e-4 }, |t| {
        if t < 1.05e-3 {
            1.0
        } else {
            0.0
        }
    });
    let xs = run(&cfg, 2.0);
    let energy = |x: &[f64; 4]| {
        0.5 * j * x[1] * x[1] + 0.5 * j2 * x[3] * x[3] + 0.5 * k * (x[0] - x[2]).powi(2)
    };
    let e: Vec<f64> = xs[10..].iter().map(energy).collect();
    // 1e-12: f64 rounding of the energy sum; any growth from the scheme would be far larger.
    for (n, w) in e.windows(2).enumerate() {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-12),
            "step {n}: {} -> {}",
            w[0],
            w[1]
        );
    }
    // What stays is the common motion, ½(J + j2)·ω̄².
    let x = xs[xs.len() - 1];
    let common = (j * x[1] + j2 * x[3]) / (j + j2);
    let rest = 0.5 * (j + j2) * common * common;
    // The push puts at least half as much again into the coupled mode as into the common
    // motion (so its decay is measurable), and the damper takes at least 80 % of it.
    assert!(e[0] > 1.5 * rest, "{} vs {rest}", e[0]);
    assert!(
        e[e.len() - 1] < rest + 0.2 * (e[0] - rest),
        "{} vs {rest}",
        e[e.len() - 1]
    );
}

#[test]
fn a_coupling_far_stiffer_than_the_step_moves_as_one_inertia() {
    // k = 1e6 N·m/rad: ω_c = 7.1e4 rad/s, 14 times 1/h at 0.2 ms and 850 times 1/h at the
    // 12 ms sample period. Under a constant 0.3 N·m the rotor must accelerate as J + j2.
    let (j2, k, c) = (6e-4, 1e6, 0.0);
    for fine_step in [0.2e-3, 0.012] {
        let cfg = EmulatorConfig {
            fine_step,
            ..free_rotor(Effect::Compliance { j2, k, c }, |_| 0.3)
        };
        let j = cfg.motor.j;
        let xs = run(&cfg, 0.6);
        // 1e3: five times the rigid motion's 200 rad/s at 0.6 s; an unstable mode grows past it.
        assert!(xs.iter().flatten().all(|v| v.is_finite() && v.abs() < 1e3));
        let at = |t: f64| xs[(t / fine_step).round() as usize - 1];
        let accel = (at(0.6)[1] - at(0.12)[1]) / 0.48;
        let rigid = 0.3 / (j + j2);
        // 0.1 %: the spring's deflection is j2·a/k = 2e-7 rad, the rigid motion exact under
        // backward Euler; a coupling that does not hold would give J alone, 3 times faster.
        assert!(
            (accel / rigid - 1.0).abs() < 1e-3,
            "step {fine_step}: {accel} rad/s² vs rigid {rigid}"
        );
        // The load keeps up with the rotor (0.1 %, as above).
        let x = at(0.6);
        assert!((x[1] - x[3]).abs() < 1e-3 * x[1], "{x:?}");
    }
}

#[test]
fn a_gap_turns_the_rotor_alone_then_picks_up_the_load() {
    // From rest, centred in a gap of 0.2 rad, under 0.01 N·m: the rotor alone (J) turns
    // 0.1 rad, reaching ω_hit = √(2·0.1·T/J); the contact merges the momenta,
    // ω = J·ω_hit/(J + j2); then the pair accelerates as J + j2.
    let (j2, gap, torque) = (6e-4, 0.2, 0.01);
    let cfg = free_rotor(Effect::Backlash { j2, gap }, |_| 0.01);
    let (j, h) = (cfg.motor.j, cfg.fine_step);
    let xs = run(&cfg, 0.4);
    let t_hit = (2.0 * 0.5 * gap * j / torque).sqrt();
    for (n, x) in xs.iter().enumerate() {
        let t = (n + 1) as f64 * h;
        if t < t_hit - 2e-3 {
            // Backward Euler on a constant acceleration: ω exact, θ ahead by ½·a·h·t.
            let a = torque / j;
            // (The 2e-9 N·m of friction left shows at 1e-5 of the motion.)
            assert!((x[1] / (a * t) - 1.0).abs() < 1e-5, "t {t}: ω {}", x[1]);
            let theta = 0.5 * a * t * (t + h);
            assert!((x[0] / theta - 1.0).abs() < 1e-5, "t {t}: θ {}", x[0]);
            assert_eq!((x[2], x[3]), (0.0, 0.0), "t {t}: the load moved");
        }
    }
    let w_hit = (2.0 * 0.5 * gap * torque / j).sqrt();
    let merged = j * w_hit / (j + j2);
    let at = |t: f64| xs[(t / h).round() as usize - 1];
    let after = at(t_hit + 3e-3);
    let want = merged + torque / (j + j2) * 3e-3;
    // 1 %: the contact takes a few fine steps; a contact that merged no momentum would
    // leave ω_hit, three times `merged`.
    assert!(
        (after[1] / want - 1.0).abs() < 0.01,
        "ω after contact {} vs {want}",
        after[1]
    );
    let accel = (at(0.4)[1] - at(0.2)[1]) / 0.2;
    let rigid = torque / (j + j2);
    // 0.1 %, as for the stiff coupling.
    assert!((accel / rigid - 1.0).abs() < 1e-3, "{accel} vs {rigid}");

    // No gap: one inertia J + j2 from the start.
    let cfg = free_rotor(Effect::Backlash { j2, gap: 0.0 }, |_| 0.01);
    let xs = run(&cfg, 0.2);
    for (n, x) in xs.iter().enumerate().skip(20) {
        let t = (n + 1) as f64 * h;
        let want = torque / (j + j2) * t;
        // 0.1 % after the first 20 steps, as for the stiff coupling.
        assert!(
            (x[1] / want - 1.0).abs() < 1e-3,
            "t {t}: ω {} vs {want}",
            x[1]
        );
    }
}
