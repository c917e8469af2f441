//! Open-loop excitations of experiment mode, computed on the board at each 12 ms sample (by
//! the firmware and the emulated board alike, through [`crate::board`]).
//!
//! The reference paper gives its signals only by amplitude and frequency range; these follow
//! the same table as the host emulator (`host-tools/src/emulator/signals.rs`). Each of
//! `a`-`d` has its paper peak `P` at the reference voltage limit of 24 V (the paper's
//! motor): `a` multisine 0.1-1 Hz up to 12 V, `b` up to 6 V 0.05-1 Hz, `c` up to 0.5 V
//! 0.25-1 Hz, `d` steps between ±10 V held 1-3 s. On the board a signal's peak [V] is the
//! smaller of two sizes:
//! - relative to the voltage limit: `P·u_max/24 V`;
//! - relative to the current limit: [`CURRENT_FRACTION`]`·R·i_max` (R [Ω], i_max [A], the
//!   blob's trip current). At standstill the signal then draws at most 0.35·i_max, and the
//!   largest step of `d` (between opposite levels, at speed) changes the current by at
//!   most 0.7·i_max, inside the standing current limit 0.8·i_max of [`crate::step`].
//!
//! Constant and ramp are in volts, bounded by ±u_max (the step's current window bounds their
//! current). The shapes are deterministic but not sample-identical to the host's (which uses
//! a seeded `StdRng`): the log records the voltage actually applied, which is what
//! identification uses.
//!
//! Multisines use Schroeder phases (low crest factor) and are scaled by the sum of their
//! amplitudes, so the peak never exceeds the stated amplitude; a slow envelope varies the
//! amplitude, and the first second fades in from rest.
use core::f32::consts::PI;

use crate::frame::Excitation;

/// The `u_max` [V] at which the signals a-d have the paper's amplitudes (its 24 V motor).
pub const U_MAX_REFERENCE: f32 = 24.0;
/// Largest peak of a-d as a fraction of `R·i_max` [V]: at most 0.35·i_max at standstill,
/// and twice that for a step between opposite levels (module docs).
pub const CURRENT_FRACTION: f32 = 0.35;

struct Multisine {
    f_lo: f32,
    f_hi: f32,
    n: u32,
    peak: f32,
    env_period: f32,
    env_min: f32,
}

fn multisine(m: &Multisine, t: f32) -> f32 {
    let mut s = 0.0;
    for k in 0..m.n {
        // Evenly spaced frequencies over [f_lo, f_hi].
        let r = k as f32 / (m.n - 1) as f32;
        let f = m.f_lo + (m.f_hi - m.f_lo) * r;
        let phase = -PI * (k * (k + 1)) as f32 / m.n as f32;
        s += crate::trig::sin(2.0 * PI * f * t + phase);
    }
    // 0.5·(1 − cos 2a) = sin²a: one transcendental function (sin) on the board, not two.
    let half = crate::trig::sin(PI * t / m.env_period);
    let env = m.env_min + (1.0 - m.env_min) * half * half;
    let fade = (t / 1.0).clamp(0.0, 1.0);
    m.peak * env * fade * s / m.n as f32
}

/// Deterministic pseudo-random number in [0, 1) from an integer (a 32-bit hash).
fn hash01(mut x: u32) -> f32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    (x >> 8) as f32 / (1u32 << 24) as f32
}

/// Steps between −10 and 10 V held 1-3 s, at rest for the first second (peak
/// [`STEPS_PEAK`]).
fn steps(t: f32) -> f32 {
    if t < 1.0 {
        return 0.0;
    }
    let mut start = 1.0;
    let mut k = 0u32;
    loop {
        let hold = 1.0 + 2.0 * hash01(2 * k + 1);
        if t < start + hold || k > 10_000 {
            let level = STEPS_PEAK * hash01(2 * k + 2);
            return if hash01(2 * k + 3 + 0x9e37) < 0.5 {
                level
            } else {
                -level
            };
        }
        start += hold;
        k += 1;
    }
}

/// Largest level of signal d at the reference voltage limit [V].
const STEPS_PEAK: f32 = 10.0;

const A: Multisine = Multisine {
    f_lo: 0.1,
    f_hi: 1.0,
    n: 12,
    peak: 12.0,
    env_period: 30.0,
    env_min: 0.1,
};
const B: Multisine = Multisine {
    f_lo: 0.05,
    f_hi: 1.0,
    n: 10,
    peak: 6.0,
    env_period: 60.0,
    env_min: 0.2,
};
const C: Multisine = Multisine {
    f_lo: 0.25,
    f_hi: 1.0,
    n: 8,
    peak: 0.5,
    env_period: 20.0,
    env_min: 0.3,
};

/// Voltage [V] of `signal` at time `t` [s] since the start, for the voltage limit `u_max`
/// [V] and the winding's drop at the current trip, `r_i_max = R·i_max` [V]: a-d peak at
/// `min(P·u_max/24 V, CURRENT_FRACTION·r_i_max)` (module docs). The result is within ±u_max.
pub fn voltage(signal: Excitation, t: f32, u_max: f32, r_i_max: f32) -> f32 {
    let (shape, peak) = match signal {
        Excitation::A => (multisine(&A, t), A.peak),
        Excitation::B => (multisine(&B, t), B.peak),
        Excitation::C => (multisine(&C, t), C.peak),
        Excitation::D => (steps(t), STEPS_PEAK),
        Excitation::Steady { volts } => return crate::pi::saturate(volts, -u_max, u_max),
        Excitation::Ramp { volts_per_s } => {
            return crate::pi::saturate(volts_per_s * t, -u_max, u_max)
        }
    };
    let by_voltage = u_max / U_MAX_REFERENCE;
    let by_current = CURRENT_FRACTION * r_i_max / peak;
    let scale = if by_current < by_voltage {
        by_current
    } else {
        by_voltage
    };
    crate::pi::saturate(shape * scale, -u_max, u_max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signals_peak_at_the_smaller_of_the_voltage_and_the_current_size() {
        // u_max 24 V: the paper's peaks; R·i_max 6.5 V (0.216 Ω, 30 A): at most 2.27 V.
        for (r_i_max, sizes) in [
            (1e3, [12.0, 6.0, 0.5, 10.0]),
            (6.5, [2.275, 2.275, 0.5, 2.275]),
        ] {
            for (signal, size) in [Excitation::A, Excitation::B, Excitation::C, Excitation::D]
                .into_iter()
                .zip(sizes)
            {
                let top = (0..10_000)
                    .map(|k| voltage(signal, k as f32 * 0.012, 24.0, r_i_max).abs())
                    .fold(0.0f32, f32::max);
                // 1e-6: f32 rounding of the scaling; 0.3: within 120 s each signal comes near its
                // size, so one scaled twice or stuck at 0 falls below.
                assert!(
                    top <= size * (1.0 + 1e-6) && top > 0.3 * size,
                    "{signal:?} at R·i_max {r_i_max} V: peak {top} V of {size} V"
                );
            }
        }
        // Constant and ramp stay in volts, within ±u_max.
        assert_eq!(
            voltage(Excitation::Steady { volts: 5.0 }, 1.0, 24.0, 1.0),
            5.0
        );
        assert_eq!(
            voltage(Excitation::Ramp { volts_per_s: -10.0 }, 3.0, 24.0, 1.0),
            -24.0
        );
    }
}
