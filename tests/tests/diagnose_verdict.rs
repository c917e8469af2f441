//! The verdict on a model as given, on data from a plant our emulator did not make
//! (`e2e::other_plant`): a correct model is adequate on the multisine a (at most one false
//! alarm in 20 seeds), a model with wrong parameters is told to refit, and physics outside
//! the effect list (a compliant coupling, a gap, creeping friction) is never "adequate" and
//! names the variable that carries it. (A falling torque constant is not named; the
//! parameter check tells the model to refit: see docs/diagnose-verdict.md.)
use control::effects::Effect;
use e2e::false_alarms::{correct_structure, Maker};
use e2e::other_plant::{Extra, OtherPlant};
use e2e::plant_cases::verdict_cases;
use motorid::diagnose::{diagnose, Diagnosis, Options, Structure};
use motorid::emulator::{signal, SignalKind};

const TS: f64 = 0.012;

fn run(p: &OtherPlant, st: &Structure, kind: SignalKind, seconds: f64, seed: u64) -> Diagnosis {
    let u = signal(kind, seconds, seed);
    let log = p.run(&u, TS, seed);
    diagnose(&log, st, &Options::default())
}

fn summary(d: &Diagnosis) -> String {
    let checks: Vec<String> = d
        .verdict
        .checks
        .iter()
        .map(|c| format!("{}:{:.1e}/{:.2}", c.name, c.p_value, c.share))
        .collect();
    let un: Vec<String> = d
        .verdict
        .unexplained
        .iter()
        .map(|u| format!("{}:{:.2}:{:.1e}:{:?}", u.variable, u.share, u.p_value, u.hz))
        .collect();
    let ef: Vec<String> = d
        .effects
        .iter()
        .map(|f| format!("{} {:.3} p {:.1e}", f.spec, f.score, f.p_value))
        .collect();
    format!(
        "adequate {} checks [{}] effects {:?} unexplained [{}]",
        d.verdict.adequate,
        checks.join(" "),
        ef,
        un.join(" ")
    )
}

fn carriers_of(d: &Diagnosis) -> Vec<&str> {
    d.verdict.unexplained.iter().map(|u| u.variable).collect()
}

/// The correct model is adequate on 20 seeds of the fitting signal, on the independent
/// plant (Karnopp stick-slip friction, RK4, its own noise) and on the built-in emulator (its
/// own LuGre law), but at most the stated level's share: with a family level of 1 %, one
/// false alarm in 20 has probability 0.18, two 0.017, so a second is taken for a defect.
#[test]
fn a_correct_model_is_adequate() {
    let opts = Options::default();
    for maker in [
        Maker::Other {
            hall: None,
            noise: None,
        },
        Maker::Emulator,
    ] {
        let mut alarms = Vec::new();
        for seed in 1..=20 {
            let d = e2e::false_alarms::correct_model(maker, SignalKind::A, seed, &opts);
            if !d.verdict.adequate {
                alarms.push(format!("seed {seed}: {}", summary(&d)));
            }
        }
        assert!(
            alarms.len() <= 1,
            "{maker:?} false alarms:\n{}",
            alarms.join("\n")
        );
    }
}

/// Coulomb friction doubled, inertia +50 %, resistance +39 %: the verdict says to refit, with
/// the refitted constants, whatever else it finds.
#[test]
fn wrong_parameters_are_told_to_refit() {
    for seed in [1, 2] {
        let p = OtherPlant::new(Extra::None);
        let mut st = correct_structure(&p);
        st.effects[0] = Effect::Coulomb { fc: 2.0 * p.fc };
        let m = st.motor.as_mut().unwrap();
        m.j *= 1.5;
        m.r *= 1.39;
        let d = run(&p, &st, SignalKind::A, 60.0, seed);
        assert!(!d.verdict.adequate, "seed {seed}: {}", summary(&d));
        let failed: Vec<&str> = d
            .verdict
            .checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.name)
            .collect();
        assert!(
            failed.contains(&"parameters"),
            "seed {seed}: {}",
            summary(&d)
        );
        // The refit recovers the true resistance and inertia within 10 %: it holds the
        // model's Coulomb and viscous law against the plant's Karnopp friction, and asks a
        // refit good enough to replace the wrong constants, not the estimator's precision
        // (seeds 1-8: R within 1 %, J within 3 %).
        let get = |n: &str| d.verdict.refit.iter().find(|r| r.0 == n).map(|r| r.1);
        let r = get("R").expect("refitted R");
        let j = get("J").expect("refitted J");
        assert!((r / p.r - 1.0).abs() < 0.1, "R {r} (true {})", p.r);
        assert!((j / p.j - 1.0).abs() < 0.1, "J {j} (true {})", p.j);
    }
}

/// Physics outside the list is never called adequate, and what `diagnose` reports first (a
/// named effect, else the variable that carries the residual) is one its physics predicts.
fn not_adequate_and_carried(extra: Extra, kind: SignalKind, expect: &[&str]) {
    for seed in [1, 2] {
        let p = OtherPlant::new(extra);
        let d = run(&p, &correct_structure(&p), kind, 60.0, seed);
        assert!(
            !d.verdict.adequate,
            "{extra:?} seed {seed}: {}",
            summary(&d)
        );
        let first = d
            .effects
            .first()
            .map(|f| f.name.as_str())
            .or_else(|| carriers_of(&d).first().copied());
        assert!(
            first.is_some_and(|v| expect.contains(&v)),
            "{extra:?} seed {seed}: {}",
            summary(&d)
        );
    }
}

/// A load twice the rotor's inertia on a lightly damped coupling (2.9 Hz against a fixed
/// rotor): named `compliance`, with the load's inertia within 30 % and the coupling's natural
/// frequency within the candidate grid's factor 1.4. The inertia is the coefficient of the
/// column at the nearest grid frequency and damping (ζ 0.05 or 0.3; this coupling's is 0.03),
/// not at the true ones, and that mismatch biases it low (seeds 1-8: 0.70-0.82 of the truth).
#[test]
fn a_compliant_coupling_is_named_with_its_inertia_and_frequency() {
    let (j2, k) = (6e-4, 0.2);
    for seed in [1, 2] {
        let p = OtherPlant::new(Extra::Coupling { j2, k, c: 6e-4 });
        let d = run(&p, &correct_structure(&p), SignalKind::A, 60.0, seed);
        assert!(!d.verdict.adequate);
        let top = d.effects.first().expect("a finding");
        assert_eq!(top.name, "compliance", "seed {seed}: {}", summary(&d));
        let spec = motorid::effect_spec::EffectSpec::parse(&top.spec).unwrap();
        let (ej2, ek) = (spec.get("j2"), spec.get("k"));
        assert!((ej2 / j2 - 1.0).abs() < 0.3, "seed {seed}: j2 {ej2}");
        let (f, ef) = ((k / j2).sqrt(), (ek / ej2).sqrt());
        assert!(
            (ef / f).max(f / ef) < 1.4,
            "seed {seed}: ω_n {ef} (true {f})"
        );
    }
}

#[test]
fn a_gap_is_not_adequate_and_named_as_a_coupling_or_carried_by_reversals() {
    // Half a radian of backlash at the rotor: 0.3° at the output of a 100:1 gear.
    not_adequate_and_carried(
        Extra::Gap { j2: 6e-4, gap: 0.5 },
        SignalKind::A,
        &["backlash", "reversal", "compliance"],
    );
}

/// A load engaged across a gap is named `backlash` (or reported with its look-alike, a
/// soft compliant coupling, and the experiment that separates them), and when named, with
/// the load's inertia within 30 % and the gap within the grid's factor 1.6. The inertia is the
/// coefficient of the column at the nearest grid gap, which biases it (seeds 1-8: 1.02-1.20
/// of the truth).
#[test]
fn a_gap_is_named_backlash_or_its_look_alike() {
    for seed in [1, 2] {
        let p = OtherPlant::new(Extra::Gap { j2: 6e-4, gap: 0.5 });
        let d = run(&p, &correct_structure(&p), SignalKind::A, 60.0, seed);
        let names: Vec<&str> = d.effects.iter().map(|f| f.name.as_str()).collect();
        let pair = d.verdict.look_alikes.iter().any(|l| {
            l.names.contains(&"backlash".to_string()) && l.names.contains(&"compliance".to_string())
        });
        assert!(
            names.first() == Some(&"backlash") || pair,
            "seed {seed}: {}",
            summary(&d)
        );
        if let Some(top) = d.effects.first().filter(|f| f.name == "backlash") {
            let spec = motorid::effect_spec::EffectSpec::parse(&top.spec).unwrap();
            let (j2, gap) = (spec.get("j2"), spec.get("gap"));
            assert!((j2 / 6e-4 - 1.0).abs() < 0.3, "seed {seed}: j2 {j2}");
            assert!((gap / 0.5).max(0.5 / gap) < 1.6, "seed {seed}: gap {gap}");
        }
    }
}

#[test]
fn creeping_friction_is_carried_by_time() {
    not_adequate_and_carried(
        Extra::CreepingCoulomb { per_minute: 1.0 },
        SignalKind::A,
        &["time"],
    );
}

/// A friction that differs by direction (Coulomb higher forward) is, on moving windows, the
/// same column as a constant load: `diagnose` names the offset, says that an asymmetry looks
/// alike, and names the experiment that separates them (a hold at standstill).
/// A winding that warms by up to 5 K over the minute of the multisine (R up to 2 % higher,
/// copper's 0.393 %/K) is not adequate on every seed: a `thermal` finding, or the voltage
/// equation's parameter check failed by a drift of its parameters along the log (a 1-2 %
/// resistance changes a one-minute free run too little for the refit's run to be closer,
/// so only the drift tells this model from one with the right constants). A resistance
/// off by 2 % all along is a constant error, and no check reads it as a drift.
#[test]
fn a_warming_winding_is_not_adequate_and_seen_drifting() {
    let has_drift = |d: &Diagnosis| {
        d.verdict
            .checks
            .iter()
            .filter(|c| c.drift.is_some())
            .map(|c| c.detail.clone())
            .collect::<Vec<_>>()
    };
    for seed in [1, 2, 3] {
        let p = OtherPlant::new(Extra::Heating {
            r_th: 10.0,
            c_th: 6.0,
        });
        let d = run(&p, &correct_structure(&p), SignalKind::A, 60.0, seed);
        assert!(!d.verdict.adequate, "seed {seed}: {}", summary(&d));
        let voltage_drift = d.verdict.checks.iter().any(|c| {
            c.name == "parameters"
                && !c.passed
                && c.drift.is_some()
                && c.detail.starts_with("voltage equation")
        });
        let named = d.effects.iter().any(|f| f.name == "thermal");
        assert!(voltage_drift || named, "seed {seed}: {}", summary(&d));

        let cold = OtherPlant::new(Extra::None);
        let mut st = correct_structure(&cold);
        st.motor.as_mut().unwrap().r *= 1.02;
        let d = run(&cold, &st, SignalKind::A, 60.0, seed);
        let drifts = has_drift(&d);
        assert!(drifts.is_empty(), "seed {seed}, R +2 %: {drifts:?}");
    }
}

#[test]
fn directional_friction_is_reported_with_its_look_alike() {
    for seed in [1, 2] {
        let p = OtherPlant::new(Extra::Directional { dfc: 0.02, db: 0.0 });
        let d = run(&p, &correct_structure(&p), SignalKind::A, 60.0, seed);
        assert!(!d.verdict.adequate);
        let names: Vec<&str> = d.effects.iter().map(|f| f.name.as_str()).collect();
        assert!(
            names.contains(&"offset") || names.contains(&"asymmetry"),
            "seed {seed}: {}",
            summary(&d)
        );
        let l = d
            .verdict
            .look_alikes
            .iter()
            .find(|l| l.names.contains(&"offset".to_string()))
            .unwrap_or_else(|| panic!("seed {seed}: no look-alike: {}", summary(&d)));
        assert!(l.names.contains(&"asymmetry".to_string()));
        // The experiment named is the breakaway in each direction: while the rotor turns
        // the two are one torque.
        assert!(l.experiment.contains("breakaway"), "{}", l.experiment);
    }
}

/// Regenerates `docs/diagnose-verdict.md`: what `diagnose` says on each case, 60 s of the
/// fitting signal (steps for the falling torque constant), seeds 1-3.
/// `cargo test -p e2e --test diagnose_verdict -- --ignored`
#[test]
#[ignore]
fn write_verdict_table() {
    let mut md = String::from(VERDICT_TABLE_HEAD);
    for (name, extra, kind) in verdict_cases() {
        for seed in 1..=3 {
            write_case_row(&mut md, name, extra, kind, seed);
        }
    }
    md.push_str(FALSE_ALARM_HEAD);
    write_false_alarm_rows(&mut md);
    md.push_str(VERDICT_LIMITS);
    let path = e2e::root().join("docs").join("diagnose-verdict.md");
    std::fs::write(&path, md).unwrap();
    eprintln!("wrote {}", path.display());
}

const VERDICT_TABLE_HEAD: &str = "# What `diagnose` says on a plant it did not make\n\n\
     Generated by `cargo test -p e2e --test diagnose_verdict -- --ignored`. The plant is \
     `tests/src/other_plant.rs` (RK4, Karnopp stick-slip friction, its own noise), 60 s at \
     12 ms; the model given to `diagnose` is the plant's own constants with Coulomb and \
     viscous friction (the rigid inertia J1 + J2 where there is a load). Checks: p-value / \
     share of the residual, mechanical equation; carriers: variable (share).\n\n\
     | case | signal | seed | adequate | failed checks | effects | carried by |\n\
     |---|---|---|---|---|---|---|\n";

/// One row of the verdict table: the diagnosis of the correct structure on one seed's log.
fn write_case_row(md: &mut String, name: &str, extra: Extra, kind: SignalKind, seed: u64) {
    use std::fmt::Write;
    let p = OtherPlant::new(extra);
    let d = run(&p, &correct_structure(&p), kind, 60.0, seed);
    let failed: Vec<String> = d
        .verdict
        .checks
        .iter()
        .filter(|c| !c.passed)
        .map(|c| {
            if c.p_value.is_nan() {
                format!("{} (cannot judge)", c.name)
            } else {
                format!("{} (p {:.0e}, {:.0} %)", c.name, c.p_value, 100.0 * c.share)
            }
        })
        .collect();
    let effects: Vec<String> = d
        .effects
        .iter()
        .map(|f| format!("{} ({:.0} %)", f.name, 100.0 * f.score))
        .collect();
    let carried: Vec<String> = d
        .verdict
        .unexplained
        .iter()
        .map(|u| format!("{} ({:.0} %)", u.variable, 100.0 * u.share))
        .collect();
    let _ = writeln!(
        md,
        "| {name} | {} | {seed} | {} | {} | {} | {} |",
        kind.name(),
        d.verdict.adequate,
        failed.join(", "),
        effects.join(", "),
        carried.join(", ")
    );
}

const FALSE_ALARM_HEAD: &str = "\n## A correct model, 20 seeds\n\n\
     How often the correct model is called not adequate (a failed check, a finding or a \
     carrier) and how often the log cannot judge it (an equation with too few usable \
     windows, nothing claimed), seeds 1-20, 60 s per signal. The family level of the checks \
     is 1 %, that of the findings 0.1 %. Per seed: \
     `cargo test --release -p e2e --test diagnose_false_alarm_scan -- --ignored --nocapture`.\n\n\
     | plant | signal | not adequate | cannot judge |\n|---|---|---|---|\n";

/// The false-alarm rows: each plant and signal, seeds 1-20.
fn write_false_alarm_rows(md: &mut String) {
    use std::fmt::Write;
    let opts = motorid::diagnose::Options::default();
    for (maker, plant) in [
        (Maker::Emulator, "emulator"),
        (
            Maker::Other {
                hall: None,
                noise: None,
            },
            "other plant",
        ),
    ] {
        for kind in [SignalKind::A, SignalKind::B, SignalKind::C, SignalKind::D] {
            let (alarms, unjudged) = e2e::false_alarms::count(maker, kind, 20, &opts);
            let _ = writeln!(
                md,
                "| {plant} | {} | {alarms}/20 | {unjudged}/20 |",
                kind.name()
            );
        }
    }
}

const VERDICT_LIMITS: &str =
    "\nThe parameter check tests the model's own residual, less the same on the model's \
     noise-free run, on the columns of its structure computed on that run, and stands only \
     when the refitted values also run closer to the log (decision 0019): the rigid model of \
     a plant with a compliant coupling (on two of three logs) and a constant K_t on voltage \
     steps are told to refit as well. \
     Limits seen here: a correct model's residual is far noisier in the windows of a slip \
     or an input step than at rest, and over one held voltage step the rotor turns at a \
     steady speed whose Hall rounding error beats slowly with the 12 ms sampling, one error \
     shared by every window of the hold. The checks, the carriers and the findings' entry \
     test therefore use the jackknifed cluster-robust Wald test (clustered by held input; \
     decision 0011). On the multisines a and b no named effect is found on a correct model; \
     what remains above the stated 1 % are the verdict's own checks and carriers (the input \
     check or a carrier of the voltage equation at p between 1e-4 and 5e-4 on a few logs, \
     and a time carrier at p = 3e-11 on one log of b). The robust entry test needs more \
     data than an F-test that takes every window for equally noisy: a load friction of \
     μ = 0.2 hidden in voltage steps is found on 180 s, not on 60 s, where the braking \
     windows that show it are also the noisiest. On voltage steps (d) the rounding drift \
     within a hold is serial correlation whatever the model, so whiteness cannot decide \
     there, and the carriers leave out what one hold decides alone: \"Cannot judge\" on most \
     logs, and not adequate on the rest, where the acceleration carries the drift. Judge a \
     model on a multisine. On the low-speed signal c the torque equation keeps too few \
     windows or held inputs for its tests (most windows touch a standstill or a reversal): \
     mostly \"Cannot judge\". A torque constant that falls 3 % by 10 A goes unseen on the \
     fitting signal a, whose current rarely leaves that range (the refitted values do not \
     run closer to the log, so the parameter check keeps the model's). A compliant coupling is named `compliance` with its load inertia and natural \
     frequency. A gap is named `backlash` with its load inertia and gap: the load coasts \
     across the gap whenever the rotor slows down and is caught again, which a soft \
     coupling (`compliance` near 1 to 2 Hz) imitates less well; where both explain about \
     equally, `diagnose` names both and the experiment that separates them (a slow reversal \
     at low speed: a gap is a dead band of free travel).\n";
