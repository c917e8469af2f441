//! A correct model judged by `diagnose`: the paper's signals on the built-in emulator (the
//! correct model is its own LuGre law with the paper's constants) and on the independent plant
//! of [`crate::other_plant`] (its constants with Coulomb and viscous friction).
use crate::other_plant::{Extra, OtherPlant};
use control::effects::Effect;
use control::motor::MotorParams;
use motorid::diagnose::{diagnose, Diagnosis, Options, Structure};
use motorid::emulator::{signal, simulate_signal, EmulatorConfig, SignalKind};
use motorid::log::Plant;

/// Which plant made the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Maker {
    /// The built-in emulator.
    Emulator,
    /// The independent plant; its Hall step [rad] and current noise [A] where given.
    Other {
        hall: Option<f64>,
        noise: Option<f64>,
    },
}

/// The diagnosis of a correct model on 60 s of `kind` made by `maker` with `seed`.
pub fn correct_model(maker: Maker, kind: SignalKind, seed: u64, opts: &Options) -> Diagnosis {
    let (hall, noise) = match maker {
        Maker::Emulator => {
            let mut cfg = EmulatorConfig::paper();
            cfg.seed = seed;
            let log = simulate_signal(&cfg, kind, 60.0).unwrap().log;
            return diagnose(&log, &Structure::lugre_paper(Plant::Voltage), opts);
        }
        Maker::Other { hall, noise } => (hall, noise),
    };
    let mut p = OtherPlant::new(Extra::None);
    if let Some(h) = hall {
        p.hall = h;
    }
    if let Some(n) = noise {
        p.current_noise = n;
    }
    let st = correct_structure(&p);
    let log = p.run(&signal(kind, 60.0, seed), 0.012, seed);
    diagnose(&log, &st, opts)
}

/// Not adequate only because some check could not decide on the log (too few windows or
/// held inputs; its p-value NaN): nothing is claimed.
pub fn cannot_judge(d: &Diagnosis) -> bool {
    !d.verdict.adequate
        && !d.verdict.judged
        && d.effects.is_empty()
        && d.verdict.unexplained.is_empty()
        && d.verdict
            .checks
            .iter()
            .all(|c| c.passed || c.p_value.is_nan())
}

/// Over seeds `1..=seeds`: how often a correct model is called not adequate (a claim of
/// missing structure or a failed check) and how often the log cannot judge it.
pub fn count(maker: Maker, kind: SignalKind, seeds: u64, opts: &Options) -> (usize, usize) {
    let (mut alarms, mut unjudged) = (0, 0);
    for seed in 1..=seeds {
        let d = correct_model(maker, kind, seed, opts);
        if cannot_judge(&d) {
            unjudged += 1;
        } else if !d.verdict.adequate {
            alarms += 1;
        }
    }
    (alarms, unjudged)
}

/// The correct model of `p` without its extra physics: its constants, Coulomb and viscous
/// friction, and the rigid inertia of rotor and load where a load hangs on a coupling or gap.
pub fn correct_structure(p: &OtherPlant) -> Structure {
    let load = match p.extra {
        Extra::Coupling { j2, .. } | Extra::Gap { j2, .. } => j2,
        _ => 0.0,
    };
    Structure {
        plant: Plant::Voltage,
        effects: vec![Effect::Coulomb { fc: p.fc }, Effect::Viscous { b: p.b }],
        kt: p.kt,
        motor: Some(MotorParams {
            r: p.r,
            l: p.l,
            kt: p.kt,
            kb: p.kt,
            j: p.j + load,
        }),
    }
}

/// A scan's setting from the environment variable `name`, when set and parseable.
pub fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().and_then(|s| s.parse().ok())
}

/// The signal a scan's letter names (`SIGS=abcd`).
pub fn signal_of(letter: char) -> SignalKind {
    SignalKind::from_name(&letter.to_string())
        .unwrap_or_else(|| panic!("SIGS: '{letter}' is not a signal (a, b, c or d)"))
}
