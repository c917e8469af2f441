//! The experiments of the look-alike table (`motorid::effects::LOOK_ALIKES`) run and tell
//! their pair apart: each member hidden in turn, on the emulator and on the independent
//! plant (`e2e::other_plant`: RK4, Karnopp friction) where it has the effect, in the signal
//! the row names; the model given to `diagnose` is the truth without the hidden effect.
//!
//! Asserted: the hidden member is named first, and the other member is not ranked above it.
//! Where `diagnose` has no term for what separates the pair (breakaway), the test reads the
//! separating quantity from the log itself, as the row tells the user to. Rows whose
//! experiment cannot separate the pair in a motor log say so in their text and have no test
//! here (a turning rotor's constant load against a Coulomb asymmetry, a locked rotor's
//! torque constant, a rest's resistance).
//!
//! Seeds: two per case; each run is a few seconds of CPU in release.
use control::effects::EffectKind;
use control::motor::MotorParams;
use e2e::other_plant::{Extra, OtherPlant};
use motorid::diagnose::{diagnose, Diagnosis, Options, Structure};
use motorid::effect_spec::EffectSpec;
use motorid::emulator::{signal, simulate_signal, EmulatorConfig, SignalKind};
use motorid::log::{MotorLog, Plant};

const TS: f64 = 0.012;
const SEEDS: [u64; 2] = [1, 2];

/// The emulator's log of `kind` over `seconds` with the effect `spec` hidden.
fn emulated(spec: &str, kind: SignalKind, seconds: f64, seed: u64) -> MotorLog {
    let mut cfg = EmulatorConfig::paper();
    cfg.seed = seed;
    cfg.effects = vec![EffectSpec::parse(spec).unwrap().to_effect()];
    simulate_signal(&cfg, kind, seconds).unwrap().log
}

/// `diagnose` of the emulator's own LuGre law (the truth without the hidden effect).
fn judge_emulated(log: &MotorLog) -> Diagnosis {
    diagnose(
        log,
        &Structure::lugre_paper(Plant::Voltage),
        &Options::default(),
    )
}

/// The independent plant's log of `kind` over `seconds` with `extra`.
fn other(extra: Extra, kind: SignalKind, seconds: f64, seed: u64) -> MotorLog {
    OtherPlant::new(extra).run(&signal(kind, seconds, seed), TS, seed)
}

/// `diagnose` of the independent plant's own constants without its extra physics: Coulomb
/// and viscous friction, the rigid inertia.
fn judge_other(log: &MotorLog) -> Diagnosis {
    let st = e2e::false_alarms::correct_structure(&OtherPlant::new(Extra::None));
    diagnose(log, &st, &Options::default())
}

fn findings(d: &Diagnosis) -> Vec<String> {
    d.effects.iter().map(|f| f.spec.clone()).collect()
}

/// `want` is the first finding and `other` is not ranked above it (it may be absent, or
/// named later, or be the look-alike `diagnose` prints beside it).
fn named_first(d: &Diagnosis, want: &str, other: &str, what: &str) {
    let rank = |n: &str| d.effects.iter().position(|f| f.name == n);
    let all = format!(
        "{what}: findings {:?}, look-alikes {:?}, carriers {:?}",
        findings(d),
        d.verdict
            .look_alikes
            .iter()
            .map(|l| l.names.clone())
            .collect::<Vec<_>>(),
        d.verdict
            .unexplained
            .iter()
            .map(|c| (c.variable, c.share))
            .collect::<Vec<_>>()
    );
    assert_eq!(rank(want), Some(0), "{all}");
    assert!(rank(other).is_none_or(|r| r > 0), "{all}");
    eprintln!("{all}");
}

/// Voltages [V] at which the rotor first turns a whole Hall step away from where it rested,
/// on each ramp of a `ramp` log (ramps start where the voltage leaves a rest at 0 V): the
/// mean magnitude forward and backward.
fn breakaway(log: &MotorLog) -> (f64, f64) {
    let (u, theta) = (&log.u, &log.theta);
    let hall = log
        .meta
        .get("hall_resolution_rad")
        .and_then(|h| h.parse::<f64>().ok())
        .unwrap();
    let (mut fwd, mut back) = (Vec::new(), Vec::new());
    for k in 1..u.len() {
        if u[k - 1] != 0.0 || u[k] == 0.0 {
            continue;
        }
        let start = theta[k];
        let moved = (k..u.len())
            .take_while(|&j| u[j] != 0.0)
            .find(|&j| (theta[j] - start).abs() >= 0.5 * hall);
        if let Some(j) = moved {
            if u[j] > 0.0 {
                fwd.push(u[j]);
            } else {
                back.push(-u[j]);
            }
        }
    }
    let mean = |v: &[f64]| {
        assert!(!v.is_empty(), "a ramp without breakaway");
        v.iter().sum::<f64>() / v.len() as f64
    };
    (mean(&fwd), mean(&back))
}

/// offset ~ asymmetry, its viscous part: constant speeds over a wide range each way
/// (`speeds`). A constant load is one torque at every speed, a viscous friction that differs
/// by direction grows with it.
#[test]
fn speeds_separate_an_offset_from_a_viscous_asymmetry() {
    for seed in SEEDS {
        let what = |s: &str| format!("{s}, seed {seed}");
        let d = judge_emulated(&emulated("offset:t0=0.03", SignalKind::Speeds, 96.0, seed));
        named_first(&d, "offset", "asymmetry", &what("emulator offset"));
        let d = judge_emulated(&emulated(
            "asymmetry:dv=0.0008",
            SignalKind::Speeds,
            96.0,
            seed,
        ));
        named_first(&d, "asymmetry", "offset", &what("emulator asymmetry"));
        // The plant's sizes: those of `diagnose_other_plant.rs` (a quarter of its Coulomb
        // level), and a viscous difference of half its viscous friction.
        let d = judge_other(&other(
            Extra::ConstantLoad { t0: 0.02 },
            SignalKind::Speeds,
            96.0,
            seed,
        ));
        named_first(&d, "offset", "asymmetry", &what("plant constant load"));
        let d = judge_other(&other(
            Extra::Directional {
                dfc: 0.0,
                db: 0.75e-3,
            },
            SignalKind::Speeds,
            96.0,
            seed,
        ));
        named_first(
            &d,
            "asymmetry",
            "offset",
            &what("plant directional viscous"),
        );
    }
}

/// offset ~ asymmetry, its Coulomb part: one torque while the rotor turns, told apart only
/// at breakaway. On slow ramps from rest (`ramp`) a constant load `t0` moves the forward
/// breakaway voltage up and the backward one down by R·t0/K_t each; a Coulomb level that
/// differs by direction acts only once the rotor slides. Each log's difference of the two
/// breakaway voltages is nearer its own prediction (2·R·t0/K_t, or 0) than the other's.
#[test]
fn ramps_separate_an_offset_from_a_coulomb_asymmetry_at_breakaway() {
    let motor = MotorParams::<f64>::paper();
    let plant = OtherPlant::new(Extra::None);
    let ramp = SignalKind::Ramp.default_duration();
    // One seed: the ramp is the same for every seed, and the seed moves only the current's
    // noise, which an open-loop voltage and the angle do not see.
    for seed in [1] {
        for (what, shift, load, asym) in [
            (
                "emulator",
                2.0 * motor.r * 0.03 / motor.kt,
                emulated("offset:t0=0.03", SignalKind::Ramp, ramp, seed),
                emulated("asymmetry:dv=0,dc=0.03", SignalKind::Ramp, ramp, seed),
            ),
            (
                "plant",
                2.0 * plant.r * 0.02 / plant.kt,
                other(
                    Extra::ConstantLoad { t0: 0.02 },
                    SignalKind::Ramp,
                    ramp,
                    seed,
                ),
                other(
                    Extra::Directional { dfc: 0.02, db: 0.0 },
                    SignalKind::Ramp,
                    ramp,
                    seed,
                ),
            ),
        ] {
            let (f, b) = breakaway(&load);
            let (fa, ba) = breakaway(&asym);
            eprintln!(
                "{what} seed {seed}: load {f:.3}/{b:.3} V, asymmetry {fa:.3}/{ba:.3} V, \
                 predicted shift {shift:.3} V"
            );
            assert!(
                (f - b - shift).abs() < 0.5 * shift,
                "{what} seed {seed}: load {f}/{b}"
            );
            assert!(
                (fa - ba).abs() < 0.5 * shift,
                "{what} seed {seed}: asymmetry {fa}/{ba}"
            );
        }
    }
}

/// load_friction ~ deadtime: voltage steps (`d`, three minutes), many of them down at speed.
/// Dead time is a voltage loss of one size in the current's equation; load friction a torque
/// in proportion to the current that differs from a lower K_t only while the drive brakes.
/// Length: that of `diagnose_emulated.rs`'s braking test (each held step is one cluster of
/// evidence; 60 s hold too few of them). Sizes on the plant: those of
/// `diagnose_other_plant.rs`.
#[test]
fn steps_separate_load_friction_from_dead_time() {
    for seed in SEEDS {
        let what = |s: &str| format!("{s}, seed {seed}");
        let d = judge_emulated(&emulated("load_friction", SignalKind::D, 180.0, seed));
        named_first(
            &d,
            "load_friction",
            "deadtime",
            &what("emulator load friction"),
        );
        let d = judge_emulated(&emulated("deadtime", SignalKind::D, 180.0, seed));
        named_first(&d, "deadtime", "load_friction", &what("emulator dead time"));
        let gear = Extra::GearFriction {
            mu: 0.25,
            j_load: 2.0e-4,
        };
        let d = judge_other(&other(gear, SignalKind::D, 180.0, seed));
        named_first(
            &d,
            "load_friction",
            "deadtime",
            &what("plant gear friction"),
        );
        // The plant's dead time passes through zero across a ±0.3 A ripple band, which the
        // steps cross in a few samples: `diagnose` names it on the multisine a (see
        // docs/other-plant.md) and on these steps only now and then. What the row promises
        // holds here too: the dead time is not taken for load friction.
        let dead = Extra::DeadTime {
            vd: 0.24,
            band: 0.3,
        };
        let d = judge_other(&other(dead, SignalKind::D, 180.0, seed));
        assert!(
            d.effects.iter().all(|f| f.name != "load_friction"),
            "{}: {:?}",
            what("plant dead time"),
            findings(&d)
        );
        eprintln!("{}: findings {:?}", what("plant dead time"), findings(&d));
    }
}

/// cogging ~ position_load: constant speeds over several revolutions (`speeds`), where the
/// error's periods per revolution are counted. Plant sizes: those of
/// `diagnose_other_plant.rs`.
#[test]
fn constant_speeds_separate_cogging_from_a_position_load() {
    for seed in SEEDS {
        let what = |s: &str| format!("{s}, seed {seed}");
        let d = judge_emulated(&emulated("cogging", SignalKind::Speeds, 96.0, seed));
        named_first(&d, "cogging", "position_load", &what("emulator cogging"));
        let d = judge_emulated(&emulated("position_load", SignalKind::Speeds, 96.0, seed));
        named_first(
            &d,
            "position_load",
            "cogging",
            &what("emulator position load"),
        );
        let slots = Extra::SlotCogging {
            slots: 6,
            a1: 0.010,
            p1: 0.7,
            a2: 0.004,
            p2: 2.1,
        };
        let d = judge_other(&other(slots, SignalKind::Speeds, 96.0, seed));
        named_first(&d, "cogging", "position_load", &what("plant slot cogging"));
        let unbalance = Extra::Unbalance {
            a1: 0.0196,
            p1: 1.1,
            a2: 0.005,
            p2: -0.4,
        };
        let d = judge_other(&other(unbalance, SignalKind::Speeds, 96.0, seed));
        named_first(&d, "position_load", "cogging", &what("plant unbalance"));
    }
}

/// current_offset ~ offset, current_offset ~ deadtime: rests at 0 V with the rotor still
/// (the 1 s rests of `ramp`), where only a sensor offset reads a current. The dead time is
/// the emulator's at a sixth of its default, so that the ramps' 0.4 V still turn the rotor
/// (breakaway 0.3 V); the plant's dead time (0.24 V) would hold its rotor still.
#[test]
fn rests_separate_a_current_offset_from_a_load_and_a_dead_time() {
    let ramp = SignalKind::Ramp.default_duration();
    for seed in SEEDS {
        let what = |s: &str| format!("{s}, seed {seed}");
        let d = judge_emulated(&emulated("current_offset", SignalKind::Ramp, ramp, seed));
        named_first(
            &d,
            "current_offset",
            "offset",
            &what("emulator current offset"),
        );
        assert!(
            d.effects.iter().all(|f| f.name != "deadtime"),
            "{:?}",
            findings(&d)
        );
        let d = judge_emulated(&emulated("deadtime:vd=0.05", SignalKind::Ramp, ramp, seed));
        named_first(
            &d,
            "deadtime",
            "current_offset",
            &what("emulator dead time"),
        );
        let d = judge_emulated(&emulated("offset:t0=0.03", SignalKind::Ramp, ramp, seed));
        assert!(
            d.effects.iter().all(|f| f.name != "current_offset"),
            "{}: {:?}",
            what("emulator offset"),
            findings(&d)
        );
        let d = judge_other(&other(
            Extra::SensorOffset { i0: 0.09 },
            SignalKind::Ramp,
            ramp,
            seed,
        ));
        named_first(&d, "current_offset", "offset", &what("plant sensor offset"));
        let d = judge_other(&other(
            Extra::ConstantLoad { t0: 0.02 },
            SignalKind::Ramp,
            ramp,
            seed,
        ));
        assert!(
            d.effects.iter().all(|f| f.name != "current_offset"),
            "{}: {:?}",
            what("plant constant load"),
            findings(&d)
        );
    }
}

/// The paper's LuGre law as effects, without the one of `kind`.
fn lugre_without(kind: EffectKind) -> Structure {
    let effects = control::lugre::LugreParams::<f64>::paper()
        .to_effects()
        .into_iter()
        .filter(|e| e.kind() != kind)
        .collect();
    Structure::with_effects(Plant::Voltage, effects)
}

/// coulomb ~ viscous ~ stribeck: constant speeds at many levels each way (`speeds`), the
/// friction curve. A model without one of the three is told that one, not another of them.
/// The Stribeck case hides the `stribeck` spec's default on a law without the paper's small
/// Stribeck excess (as `diagnose_emulated.rs` does); on the plant, its static friction above
/// Coulomb (sizes of `diagnose_other_plant.rs`).
#[test]
fn constant_speeds_separate_coulomb_viscous_and_stribeck_friction() {
    for seed in SEEDS {
        let what = |s: &str| format!("{s}, seed {seed}");
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = seed;
        let log = simulate_signal(&cfg, SignalKind::Speeds, 96.0).unwrap().log;
        let o = Options::default();
        let d = diagnose(&log, &lugre_without(EffectKind::Viscous), &o);
        named_first(
            &d,
            "viscous",
            "coulomb",
            &what("emulator, model without viscous"),
        );
        assert!(
            d.effects.iter().all(|f| f.name != "stribeck"),
            "{:?}",
            findings(&d)
        );
        let d = diagnose(&log, &lugre_without(EffectKind::Coulomb), &o);
        named_first(
            &d,
            "coulomb",
            "viscous",
            &what("emulator, model without Coulomb"),
        );
        assert!(
            d.effects.iter().all(|f| f.name != "stribeck"),
            "{:?}",
            findings(&d)
        );
        cfg.lugre.alpha1 = 0.0;
        cfg.effects = vec![EffectSpec::bare(EffectKind::Stribeck).to_effect()];
        let log = simulate_signal(&cfg, SignalKind::Speeds, 96.0).unwrap().log;
        let d = diagnose(&log, &lugre_without(EffectKind::Stribeck), &o);
        named_first(
            &d,
            "stribeck",
            "coulomb",
            &what("emulator, model without Stribeck"),
        );
        assert!(
            d.effects.iter().all(|f| f.name != "viscous"),
            "{:?}",
            findings(&d)
        );
        let d = judge_other(&other(
            Extra::Breakaway { fs: 0.025, vs: 2.5 },
            SignalKind::Speeds,
            96.0,
            seed,
        ));
        named_first(&d, "stribeck", "coulomb", &what("plant breakaway"));
    }
}
