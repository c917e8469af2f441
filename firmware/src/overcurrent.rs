//! The hardware over-current stop: comparators on the three shunts into TIM1's break input,
//! so the bridge turns off within a PWM period, independent of the software.
//!
//! Wiring, as ST's own motor-control project for this board configures it (MCSDK
//! "ElectronicSpeedControl" for the B-G431B-ESC1: COMP1/COMP2/COMP4 on PA1/PA7/PB0,
//! non-inverted, output to a TIM1 break input): each comparator's non-inverting input is the
//! op-amp's non-inverting input of its phase (COMP1 INP0 = PA1 = phase U, COMP2 INP0 = PA7 =
//! phase V, COMP4 INP0 = PB0 = phase W), where the shunt voltage appears scaled by
//! `SENSE_GAIN / PGA_GAIN` (about 1.71 mV/A) on the bias network's zero level. A current
//! flowing down through a low-side shunt to ground (a winding current through the low
//! phase, a shoot-through, a short of two phases) raises that node. The inverting inputs
//! come from DAC3 (COMP1: DAC3_CH1; COMP2, COMP4: DAC3_CH2; RM0440 "COMP inverting input
//! assignment"), both channels set to the same threshold.
//!
//! The threshold is calibrated at boot with the bridge off: for each comparator a binary
//! search over the DAC code finds where its output flips (the node's zero-current level, in
//! DAC codes, so neither the bias network nor the DAC reference needs to be known exactly),
//! and the threshold is the highest of the three plus [`control::board::HW_TRIP_A`] in DAC
//! codes (the `trip-test` build: [`TRIP_TEST_A`], for checking the stop on the bench). The search doubles as a self-test: a comparator that does not flip, or that is
//! high at the threshold with no current, leaves the stop unarmed and [`arm`] says why.
//!
//! Once armed, a comparator output high clears TIM1's MOE through the break input (filter:
//! 8 timer clocks, 47 ns, against switching spikes); the outputs go to their idle level (low)
//! and stay there until software sets MOE again. `bridge::commutate` does not set MOE while
//! the break flag is set, and the flag is cleared only after the host's `ClearFault`
//! ([`bridge::rearm`](crate::bridge::rearm)).
use embassy_stm32::pac;
use embassy_stm32::pac::comp::vals::{Blanking, Hysteresis, Inm, Polarity};
use embassy_stm32::pac::dac::vals::Mode;
use embassy_stm32::pac::timer::vals::{Bkinp, Bkp, FilterValue};
use embassy_stm32::peripherals::DAC3;
use embassy_stm32::Peri;

use crate::board::{ADC_VREF, PGA_GAIN, SENSE_GAIN, SHUNT_OHM, SYSCLK_HZ};

/// Comparators on phases U, V, W.
const COMPS: [pac::comp::Comp; 3] = [pac::COMP1, pac::COMP2, pac::COMP4];
/// Index of each comparator's bit in TIM1_AF1 (BKCMPxE, BKCMPxP: COMP1 = 0 .. COMP4 = 3).
const BREAK_INDEX: [usize; 3] = [0, 1, 3];
/// Trip current of the `trip-test` build [A]: low enough to reach on the bench with a
/// current-limited supply (docs/bring-up.md), high enough above the zero-level spread of the
/// three inputs (a few amperes) not to trip at rest.
pub const TRIP_TEST_A: f32 = 8.0;
/// Trip current armed [A].
const TRIP_A: f32 = if cfg!(feature = "trip-test") {
    TRIP_TEST_A
} else {
    control::board::HW_TRIP_A
};
/// Largest 12-bit DAC code.
const DAC_MAX: u16 = 4095;
/// Settling time after a DAC or comparator change [µs] (DAC3 unbuffered settles within
/// about 1 µs, a comparator starts within 5 µs; STM32G431 datasheet DS12589).
const SETTLE_US: u32 = 10;

/// The armed stop.
#[derive(Debug, Clone, Copy, defmt::Format)]
pub struct Armed {
    /// Highest zero-current level of the three comparator inputs [DAC code].
    pub zero: u16,
    /// Threshold [DAC code].
    pub trip: u16,
}

fn settle() {
    cortex_m::asm::delay(SYSCLK_HZ / 1_000_000 * SETTLE_US);
}

/// Sets both DAC3 channels (the comparators' inverting inputs) to `code` and waits.
fn set_threshold(code: u16) {
    pac::DAC3.dhr12rd().write(|w| {
        w.set_dhr(0, code);
        w.set_dhr(1, code);
    });
    settle();
}

/// Smallest DAC code at which comparator `c` is low (its input at or below the threshold),
/// or `None` when it stays high at full scale.
#[inline(never)]
fn flip_code(c: pac::comp::Comp) -> Option<u16> {
    let high = |code| {
        set_threshold(code);
        c.csr().read().value()
    };
    if high(DAC_MAX) {
        return None;
    }
    if !high(0) {
        return Some(0);
    }
    let (mut lo, mut hi) = (0u16, DAC_MAX); // high at lo, low at hi
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if high(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(hi)
}

/// DAC codes per ampere of phase current at the comparator inputs.
fn codes_per_amp() -> f32 {
    SHUNT_OHM * libm::fabsf(SENSE_GAIN) / PGA_GAIN / ADC_VREF * DAC_MAX as f32
}

/// Calibrates and arms the stop; call with the bridge off and the op-amps running. On an
/// error the break input stays disabled (the software limit remains) and the reason is
/// returned.
pub fn arm(dac3: Peri<'static, DAC3>) -> Result<Armed, &'static str> {
    // The comparators are clocked with SYSCFG (RM0440, "COMP clocks").
    pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    // DAC3: both channels internal only, unbuffered (RM0440, "DAC_MCR"); HFSEL for an AHB
    // clock above 160 MHz. It keeps driving the threshold for as long as the firmware runs.
    let _dac3 = dac3;
    pac::RCC.ahb2enr().modify(|w| w.set_dac3en(true));
    pac::DAC3.mcr().write(|w| {
        w.set_hfsel(0b10);
        w.set_mode(0, Mode::NORMAL_INT_BUFDIS);
        w.set_mode(1, Mode::NORMAL_INT_BUFDIS);
    });
    pac::DAC3.cr().write(|w| {
        w.set_en(0, true);
        w.set_en(1, true);
    });
    for c in COMPS {
        c.csr().write(|w| {
            w.set_inpsel(false); // INP0: PA1, PA7, PB0
            w.set_inmsel(Inm::DACA); // DAC3_CH1 (COMP1), DAC3_CH2 (COMP2, COMP4)
            w.set_polarity(Polarity::NOT_INVERTED);
            w.set_hyst(Hysteresis::HYST10M);
            w.set_blanksel(Blanking::NO_BLANKING);
            w.set_en(true);
        });
    }
    settle();

    let mut zero = 0u16;
    for c in COMPS {
        let z = flip_code(c).ok_or("a comparator input sits above the DAC range")?;
        zero = zero.max(z);
    }
    let trip = zero as f32 + libm::roundf(TRIP_A * codes_per_amp());
    if trip > DAC_MAX as f32 {
        return Err("the trip threshold lies above the DAC range");
    }
    let trip = trip as u16;
    set_threshold(trip);
    if COMPS.iter().any(|c| c.csr().read().value()) {
        return Err("a comparator is high at the threshold with the bridge off");
    }

    let t = pac::TIM1;
    t.af1().modify(|w| {
        w.set_bkine(false);
        for k in BREAK_INDEX {
            w.set_bkcmpe(k, true);
            w.set_bkcmpp(k, Bkinp::NOT_INVERTED);
        }
    });
    crate::bridge::rearm();
    t.bdtr().modify(|w| {
        w.set_bkf(0, FilterValue::FCK_INT_N8);
        w.set_bkp(0, Bkp::ACTIVE_HIGH);
        w.set_bke(0, true);
    });
    Ok(Armed { zero, trip })
}
