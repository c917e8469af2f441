//! The excitation signals (commanded voltage, sampled at the control period) of the reference
//! paper's experiments, deterministic for a given seed.
//!
//! The paper describes its four identification signals only by amplitude and frequency
//! range (its excitation-signal section); the shapes below are ours:
//!
//! | kind | what | default duration |
//! |---|---|---|
//! | `a` | fitting signal: random-phase multisine, 0.1-1 Hz, amplitude slowly varying up to 12 V, both signs | 90 s |
//! | `b` | validation: lower amplitude (up to 6 V), 0.05-1 Hz weighted to low frequencies, slower amplitude variation | 90 s |
//! | `c` | validation at low speed (stick-slip region): multisine 0.25-1 Hz, up to 0.5 V | 60 s |
//! | `d` | validation: steps held 1-3 s, levels between −10 and 10 V | 60 s |
//! | `steady` | static LuGre parameters: constant 0.40 … 0.60 V in 0.02 V blocks, both signs | 66 s (3 s blocks) |
//! | `ramp` | dynamic LuGre parameters: slow ramps 0 → ±0.4 V at 9.5 and 12 mV/s | 155 s |
//! | `speeds` | friction curve over a wide speed range: constant 0.4 … 6 V, up and down each sign | 96 s (2 s blocks) |
//!
//! The multisines fade in over the first second, so the motor starts from rest smoothly.
//! `steady` and `speeds` stretch their blocks to the requested duration; `ramp` is cut or
//! repeated.
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;

/// The control period of the paper and the firmware: 12 ms (`control::CONTROL_PERIOD_S`,
/// written out here because that one is an `f32`).
pub const SAMPLE_PERIOD: f64 = 0.012;

/// Which excitation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum SignalKind {
    /// Fitting signal: multisine 0.1-1 Hz, amplitude slowly varying up to 12 V.
    A,
    /// Validation: up to 6 V, 0.05-1 Hz, slower variation.
    B,
    /// Validation at low speed: 0-0.5 V, 0.25-1 Hz.
    C,
    /// Validation: voltage steps between −10 and 10 V, held 1-3 s.
    D,
    /// Static-friction experiment: constant 0.40-0.60 V blocks, both signs.
    Steady,
    /// Dynamic-friction experiment: slow ramps 0 → ±0.4 V at 9.5 and 12 mV/s.
    Ramp,
    /// Friction curve over a wide speed range: constant 0.4-6 V blocks, up and down each sign.
    Speeds,
}

impl SignalKind {
    /// Every kind, in the order of the paper (then the static-parameter experiments).
    pub const ALL: [SignalKind; 7] = [
        SignalKind::A,
        SignalKind::B,
        SignalKind::C,
        SignalKind::D,
        SignalKind::Steady,
        SignalKind::Ramp,
        SignalKind::Speeds,
    ];

    /// Command-line name (`a`, `steady`, ...).
    pub fn name(self) -> &'static str {
        match self {
            SignalKind::A => "a",
            SignalKind::B => "b",
            SignalKind::C => "c",
            SignalKind::D => "d",
            SignalKind::Steady => "steady",
            SignalKind::Ramp => "ramp",
            SignalKind::Speeds => "speeds",
        }
    }

    /// Parse a command-line name.
    pub fn from_name(name: &str) -> Option<SignalKind> {
        SignalKind::ALL.iter().copied().find(|k| k.name() == name)
    }

    /// Default duration [s]. `a` is kept short enough (90 s = 7500 samples) that the whole
    /// demo stays fast; `ramp` is its natural length (four ramps to ±0.4 V).
    pub fn default_duration(self) -> f64 {
        match self {
            SignalKind::A | SignalKind::B => 90.0,
            SignalKind::C | SignalKind::D => 60.0,
            SignalKind::Steady => STEADY_LEVELS.len() as f64 * 2.0 * 3.0,
            SignalKind::Ramp => ramp_program_duration(),
            SignalKind::Speeds => speeds_blocks().len() as f64 * SPEEDS_BLOCK,
        }
    }

    /// One line for `--help`.
    pub fn describe(self) -> &'static str {
        match self {
            SignalKind::A => "fitting signal: multisine 0.1-1 Hz, amplitude slowly varying up to 12 V, both signs (90 s)",
            SignalKind::B => "validation: up to 6 V, 0.05-1 Hz, slower amplitude variation (90 s)",
            SignalKind::C => "validation at low speed (stick-slip): multisine 0.25-1 Hz, up to 0.5 V (60 s)",
            SignalKind::D => "validation: voltage steps between -10 and 10 V held 1-3 s (60 s)",
            SignalKind::Steady => "static friction: constant 0.40..0.60 V in 0.02 V blocks, both signs (66 s)",
            SignalKind::Ramp => "dynamic friction: slow ramps 0 -> +-0.4 V at 9.5 and 12 mV/s (155 s)",
            SignalKind::Speeds => "friction curve over a wide speed range: constant 0.4..6 V in 12 levels, up then down, each sign (96 s)",
        }
    }
}

/// Levels of the `steady` experiment: the paper's 0.4-0.6 V constant commands.
pub const STEADY_LEVELS: [f64; 11] = [
    0.40, 0.42, 0.44, 0.46, 0.48, 0.50, 0.52, 0.54, 0.56, 0.58, 0.60,
];
/// Ramp slopes [V/s] of the `ramp` experiment: the paper's 9.5 to 12 mV/s.
pub const RAMP_SLOPES: [f64; 2] = [9.5e-3, 12e-3];
/// End voltage of each ramp [V]: above breakaway (s(0)·R/K_t ≈ 0.3 V for the paper's motor).
pub const RAMP_END: f64 = 0.4;
/// Rest at 0 V before each ramp [s].
pub const RAMP_REST: f64 = 1.0;

/// Levels of the `speeds` experiment [V]: 12 levels from [`SPEEDS_LOW`] to [`SPEEDS_HIGH`],
/// evenly spaced in logarithm (each 28 % above the one before), so that low speeds, where a
/// Stribeck dip and a Coulomb level show, get as many blocks as high ones, where a viscous
/// slope does.
pub fn speeds_levels() -> [f64; SPEEDS_LEVELS] {
    let ratio = SPEEDS_HIGH / SPEEDS_LOW;
    core::array::from_fn(|k| SPEEDS_LOW * ratio.powf(k as f64 / (SPEEDS_LEVELS - 1) as f64))
}
/// Number of levels of `speeds` per sweep.
pub const SPEEDS_LEVELS: usize = 12;
/// Lowest level of `speeds` [V]: above breakaway (about 0.3 V for the paper's motor), the
/// lowest level of `steady`.
pub const SPEEDS_LOW: f64 = 0.4;
/// Highest level of `speeds` [V]: the middle of `d`'s range, about 80 rad/s on the paper's
/// motor, far into the speeds where viscous friction dominates.
pub const SPEEDS_HIGH: f64 = 6.0;
/// Seconds each level of `speeds` is held at its default duration: a hundred mechanical time
/// constants of the paper's motor (13 ms), several revolutions at the lowest speed.
pub const SPEEDS_BLOCK: f64 = 2.0;

/// The blocks of `speeds` in order: up through the levels and back down, forward, then the
/// same backward. Every change of level is one step of the ladder (at most 22 % of the top
/// level), never a jump from speed to rest or to the other direction at speed: the current a
/// step draws stays that of one step.
pub fn speeds_blocks() -> Vec<f64> {
    let levels = speeds_levels();
    let sweep: Vec<f64> = levels
        .iter()
        .copied()
        .chain(levels.iter().rev().copied())
        .collect();
    sweep
        .iter()
        .copied()
        .chain(sweep.iter().map(|v| -v))
        .collect()
}

fn ramp_program_duration() -> f64 {
    RAMP_SLOPES
        .iter()
        .map(|s| 2.0 * (RAMP_REST + RAMP_END / s))
        .sum()
}

/// The signal at the 12 ms control period.
pub fn signal(kind: SignalKind, duration: f64, seed: u64) -> Vec<f64> {
    signal_at(kind, duration, seed, SAMPLE_PERIOD)
}

/// The signal sampled every `ts` seconds: `round(duration/ts)` values (at least 2), the
/// voltage to hold from `k·ts` to `(k+1)·ts`.
pub fn signal_at(kind: SignalKind, duration: f64, seed: u64, ts: f64) -> Vec<f64> {
    let n = ((duration / ts).round() as usize).max(2);
    let t = |k: usize| k as f64 * ts;
    // A distinct stream per signal kind, so `a` and `b` with one seed are unrelated.
    let mut rng = StdRng::seed_from_u64(seed ^ (0x5eed_0000 + kind as u64));
    match kind {
        SignalKind::A => multisine(
            &mut rng,
            n,
            ts,
            Multisine {
                f_lo: 0.1,
                f_hi: 1.0,
                components: 12,
                tilt: 0.0,
                peak: 12.0,
                env_period: 30.0,
                env_min: 0.1,
            },
        ),
        SignalKind::B => multisine(
            &mut rng,
            n,
            ts,
            Multisine {
                f_lo: 0.05,
                f_hi: 1.0,
                components: 10,
                tilt: 0.5,
                peak: 6.0,
                env_period: 60.0,
                env_min: 0.2,
            },
        ),
        SignalKind::C => multisine(
            &mut rng,
            n,
            ts,
            Multisine {
                f_lo: 0.25,
                f_hi: 1.0,
                components: 8,
                tilt: 0.0,
                peak: 0.5,
                env_period: 20.0,
                env_min: 0.3,
            },
        ),
        SignalKind::D => {
            let mut u = Vec::with_capacity(n);
            let mut level = 0.0;
            let mut until = 1.0; // start at rest for 1 s
            for k in 0..n {
                if t(k) >= until {
                    let mag: f64 = rng.random_range(0.0..=10.0);
                    level = if rng.random_bool(0.5) { mag } else { -mag };
                    until += rng.random_range(1.0..=3.0);
                }
                u.push(level);
            }
            u
        }
        SignalKind::Steady => {
            let blocks: Vec<f64> = STEADY_LEVELS
                .iter()
                .copied()
                .chain(STEADY_LEVELS.iter().map(|v| -v))
                .collect();
            stretch(&blocks, n)
        }
        SignalKind::Speeds => stretch(&speeds_blocks(), n),
        SignalKind::Ramp => {
            // One program: for each slope, rest, ramp up to +END, rest, ramp down to −END.
            let mut segs: Vec<(f64, f64)> = Vec::new(); // (length s, slope V/s incl. sign)
            for s in RAMP_SLOPES {
                for sign in [1.0, -1.0] {
                    segs.push((RAMP_REST, 0.0));
                    segs.push((RAMP_END / s, sign * s));
                }
            }
            let total = ramp_program_duration();
            (0..n)
                .map(|k| {
                    let mut tau = t(k) % total;
                    for (len, slope) in &segs {
                        if tau < *len {
                            return slope * tau;
                        }
                        tau -= len;
                    }
                    0.0
                })
                .collect()
        }
    }
}

/// `n` samples of constant `blocks` of equal length.
fn stretch(blocks: &[f64], n: usize) -> Vec<f64> {
    let block = n as f64 / blocks.len() as f64;
    (0..n)
        .map(|k| blocks[((k as f64 / block) as usize).min(blocks.len() - 1)])
        .collect()
}

/// Shape of a random-phase multisine with a slowly varying envelope.
struct Multisine {
    f_lo: f64,
    f_hi: f64,
    components: usize,
    /// Amplitude of component k ∝ f_k^(−tilt) (0: flat spectrum).
    tilt: f64,
    /// Largest |u| [V].
    peak: f64,
    /// Period of the envelope [s].
    env_period: f64,
    /// Smallest envelope value (relative to 1).
    env_min: f64,
}

fn multisine(rng: &mut StdRng, n: usize, ts: f64, m: Multisine) -> Vec<f64> {
    let comps: Vec<(f64, f64, f64)> = (0..m.components)
        .map(|k| {
            let x = k as f64 / (m.components - 1).max(1) as f64;
            let f = m.f_lo * (m.f_hi / m.f_lo).powf(x); // log-spaced
            let amp = f.powf(-m.tilt);
            let phase = rng.random_range(0.0..2.0 * PI);
            (f, amp, phase)
        })
        .collect();
    let env_phase = rng.random_range(0.0..2.0 * PI);
    let raw: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * ts;
            let s: f64 = comps
                .iter()
                .map(|(f, a, p)| a * (2.0 * PI * f * t + p).sin())
                .sum();
            let env = m.env_min
                + (1.0 - m.env_min) * 0.5 * (1.0 + (2.0 * PI * t / m.env_period + env_phase).sin());
            let fade = if t < 1.0 {
                0.5 * (1.0 - (PI * t).cos())
            } else {
                1.0
            };
            s * env * fade
        })
        .collect();
    let max = raw.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let scale = if max > 0.0 { m.peak / max } else { 0.0 };
    raw.into_iter().map(|x| x * scale).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_match_the_paper() {
        for kind in SignalKind::ALL {
            let u = signal(kind, kind.default_duration(), 7);
            let max = u.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let want = match kind {
                SignalKind::A => 12.0,
                SignalKind::B => 6.0,
                SignalKind::C => 0.5,
                SignalKind::D => 10.0,
                SignalKind::Steady => 0.6,
                SignalKind::Ramp => RAMP_END,
                SignalKind::Speeds => SPEEDS_HIGH,
            };
            assert!(max <= want + 1e-9, "{kind:?}: max {max} > {want}");
            // Half the bound: over its default duration each signal comes near it; a wrong scale
            // falls far below.
            assert!(max > 0.5 * want, "{kind:?}: max {max} far below {want}");
            assert!(u.iter().any(|x| *x < 0.0) && u.iter().any(|x| *x > 0.0));
            let n = (kind.default_duration() / SAMPLE_PERIOD).round() as usize;
            assert_eq!(u.len(), n);
        }
    }

    #[test]
    fn deterministic_per_seed() {
        for kind in [SignalKind::A, SignalKind::D] {
            assert_eq!(signal(kind, 20.0, 3), signal(kind, 20.0, 3));
            assert_ne!(signal(kind, 20.0, 3), signal(kind, 20.0, 4));
        }
    }

    /// `speeds` holds each level of its ladder for one block, both signs, and never changes
    /// the voltage by more than one rung.
    #[test]
    fn speeds_climb_and_descend_one_rung_at_a_time() {
        let kind = SignalKind::Speeds;
        let u = signal(kind, kind.default_duration(), 0);
        let levels = speeds_levels();
        let top = levels[SPEEDS_LEVELS - 1];
        let rung = top - levels[SPEEDS_LEVELS - 2];
        let mut changes = 0;
        for w in u.windows(2) {
            let d = (w[1] - w[0]).abs();
            if d > 0.0 {
                changes += 1;
                // The one sign change (lowest level forward to lowest backward) is 2·SPEEDS_LOW.
                assert!(d <= rung.max(2.0 * SPEEDS_LOW) + 1e-12, "step {d} V");
            }
        }
        assert_eq!(changes, speeds_blocks().len() - 1 - 2);
        for v in levels {
            for sign in [1.0, -1.0] {
                let held = u.iter().filter(|x| (**x - sign * v).abs() < 1e-12).count();
                let want = 2.0 * SPEEDS_BLOCK / SAMPLE_PERIOD;
                // The top level is one block of twice the length (up, then straight down).
                assert!((held as f64 - want).abs() <= 2.0, "{v} V: {held} samples");
            }
        }
    }

    #[test]
    fn ramp_slopes_are_the_papers() {
        let u = signal(SignalKind::Ramp, ramp_program_duration(), 0);
        let slopes: Vec<f64> = u
            .windows(2)
            .map(|w| (w[1] - w[0]) / SAMPLE_PERIOD)
            .filter(|s| s.abs() > 1e-6 && s.abs() < 1.0)
            .collect();
        // Every difference is one of the two slopes, except at the few segment joins.
        let good = slopes
            .iter()
            .filter(|s| (s.abs() - 9.5e-3).abs() < 1e-6 || (s.abs() - 12e-3).abs() < 1e-6)
            .count();
        assert!(good + 8 >= slopes.len(), "{good} of {}", slopes.len());
        assert!(slopes.len() > 10_000);
    }

    #[test]
    fn multisine_band_is_respected() {
        // Energy of `a` outside 0.05..1.5 Hz is small: check with a plain DFT at a few bins.
        let u = signal(SignalKind::A, 60.0, 1);
        let n = u.len();
        let power = |f: f64| {
            let (mut re, mut im) = (0.0, 0.0);
            for (k, x) in u.iter().enumerate() {
                let w = 2.0 * PI * f * k as f64 * SAMPLE_PERIOD;
                re += x * w.cos();
                im += x * w.sin();
            }
            (re * re + im * im) / n as f64
        };
        let inband: f64 = [0.1, 0.2, 0.3, 0.5, 0.8, 1.0]
            .iter()
            .map(|f| power(*f))
            .sum();
        let outband: f64 = [3.0, 5.0, 10.0, 20.0].iter().map(|f| power(*f)).sum();
        // 1 % (20 dB): the multisine has no lines out of band, only the finite record's leakage
        // reaches these bins.
        assert!(outband < 0.01 * inband, "out {outband} vs in {inband}");
    }
}
