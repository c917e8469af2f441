//! The three-phase bridge driven six-step from TIM1 (centre-aligned complementary PWM).
//!
//! Commutation step `k` (0..5) powers one phase pair: the "high" phase switches with duty
//! `d` (complementary, so its low side conducts in the off time: synchronous rectification),
//! the "low" phase has its low side on all the time (duty 0), the third phase floats (both
//! outputs disabled). Step `k + 3` is step `k` with the polarity reversed
//! (`control::board::six_step_pattern`, tested on the host). Which step drives
//! a rotor in a Hall sector is `control::board::commutation_step` (sector + 1 forward,
//! sector + 4 for a negative voltage), the same rule the emulated board uses.
//!
//! Commissioning holds a centre vector whatever the Hall state ([`Drive::hold`],
//! `control::board::centre_pattern`): the two phases other than the low one switch with
//! the same duty `d` (complementary), the low phase has its low side on (duty 0), all three
//! outputs enabled. Its field points at the middle of a Hall sector, between the fields of
//! the two six-step vectors that share its low phase.
//!
//! In both patterns the low phase's low-side switch conducts during the whole period, and
//! every other phase's current returns through it: its shunt carries the whole winding
//! current in both the on and the freewheel interval, so the firmware reads that one
//! phase's op-amp at any time, without synchronising the ADC to the PWM.
//!
//! Commutation follows the rotor at every Hall edge: the TIM4 capture interrupt calls
//! [`commutate`] (`hall_capture`), and the 12 ms control loop only sets the drive (on/off,
//! direction, duty) with [`set_drive`] and commutates once itself so a new duty applies at
//! once. Commutating only every 12 ms would energise the wrong phase pair for most of each
//! period above a few rad/s.
//!
//! A commutation is applied on TIM1's update event, atomically. [`commutate`] reads the
//! drive and the Hall state and stores the new pattern (compare values and output enables)
//! in one critical section, so the Hall interrupt and the loop cannot interleave a stale
//! state, and arms TIM1's update interrupt. That interrupt (the highest priority) runs at
//! the next counter extreme, within 25 µs (centre-aligned, an update at every overflow and
//! underflow): it writes the output enables into their preload registers (TIM1_CR2.CCPC =
//! 1), the three compare values (compare preload off, so they take effect at once), and
//! generates the commutation event (TIM1_EGR.COMG) that switches all six enables at once
//! (RM0440, "Six-step PWM generation"). The pattern therefore changes within a few
//! nanoseconds, at the counter's extreme, far from any compare match: an output enabled
//! with the compare value of the previous step (both low sides of two legs on, or the old
//! duty on the new low phase) never lasts longer than those few instructions.
//!
//! [`Bridge::off`] clears MOE with OSSI = idle level and OIS = 0, which forces all six gate
//! signals low (RM0440, "TIMx_BDTR", off-state selection); [`force_off`] does the same from
//! a panic or fault handler without the driver object. The hardware over-current stop
//! (`overcurrent`) clears MOE through TIM1's break input; [`commutate`] does not set MOE
//! again while the break flag is set, until [`rearm`]. While the core is halted by a
//! debugger, TIM1 stops with its outputs disabled (DBGMCU freeze), so a breakpoint never
//! leaves a phase pair conducting.
use core::cell::Cell;
use core::sync::atomic::{AtomicU8, Ordering};

use critical_section::Mutex;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM1;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, Ossi, Ossr};
use embassy_stm32::timer::Channel;

use crate::board::MAX_DUTY;

/// Phase order U, V, W as TIM1 channels 1, 2, 3.
const PHASES: [Channel; 3] = [Channel::Ch1, Channel::Ch2, Channel::Ch3];

/// A six-step or centre-vector pattern ready to apply on the next update event.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pattern {
    /// Compare values of phases U, V, W.
    ccr: [u16; 3],
    /// Outputs (both sides) enabled, per phase.
    enable: [bool; 3],
    /// The phase whose low side is on all the time (its shunt carries the current).
    low: u8,
}

/// The pattern the next update event applies.
static PENDING: Mutex<Cell<Option<Pattern>>> = Mutex::new(Cell::new(None));

/// Duty cycle for a voltage magnitude and the bus voltage: `|V|/V_bus`, saturated at
/// [`MAX_DUTY`]; zero when the bus voltage is not positive.
pub fn duty(v: f32, v_bus: f32) -> f32 {
    if v_bus.is_nan() || v_bus <= 0.0 || !v.is_finite() {
        return 0.0;
    }
    (v.abs() / v_bus).clamp(0.0, MAX_DUTY)
}

/// What the commutation applies (set by the control loop, read at every Hall edge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Outputs enabled.
    pub on: bool,
    /// Negative voltage: the reversed step (`k + 3`).
    pub reverse: bool,
    /// Compare value of the high phase, or of both high phases of a centre vector
    /// (0..=max duty counts).
    pub duty: u16,
    /// Hall state → sector (the coefficients' table; negative = invalid state).
    pub table: [i8; 8],
    /// Hold the centre vector with this low phase (0..2) whatever the Hall state
    /// (commissioning).
    pub hold: Option<u8>,
}

static DRIVE: Mutex<Cell<Drive>> = Mutex::new(Cell::new(Drive {
    on: false,
    reverse: false,
    duty: 0,
    table: [-1; 8],
    hold: None,
}));
/// Low phase of the pattern applied last (for the current measurement: its shunt).
static LAST_LOW: AtomicU8 = AtomicU8::new(1);

/// Sets what the next commutations apply.
pub fn set_drive(d: Drive) {
    critical_section::with(|cs| DRIVE.borrow(cs).set(d));
}

/// The low phase (0..2) of the pattern applied last: the one whose shunt to read.
pub fn last_low() -> usize {
    usize::from(LAST_LOW.load(Ordering::Relaxed) % 3)
}

/// The pattern of drive `d` for Hall state `state`; `None`: all off (drive off, invalid
/// state).
fn pattern(d: &Drive, state: u8) -> Option<Pattern> {
    let sector = d.table[(state & 7) as usize];
    let ((ccr, enable), low) = match d.hold {
        _ if !d.on => return None,
        Some(low) => (
            control::board::centre_pattern(low, d.duty),
            usize::from(low % 3),
        ),
        None if sector < 0 => return None,
        None => {
            let k = control::board::commutation_step(sector as u8, d.reverse);
            (
                control::board::six_step_pattern(k, d.duty),
                control::board::BRIDGE_STEPS[usize::from(k)].1,
            )
        }
    };
    Some(Pattern {
        ccr,
        enable,
        low: low as u8,
    })
}

/// Commutates for the Hall state now: schedules the step of its sector for the next PWM
/// update event, or turns the bridge off at once when the drive is off or the state is
/// invalid. Called from the TIM4 interrupt and the control loop; the drive and the Hall
/// state are read in the same critical section as the pattern is stored.
pub fn commutate() {
    critical_section::with(|cs| {
        let d = DRIVE.borrow(cs).get();
        match pattern(&d, crate::hall_capture::hall_state()) {
            None => {
                PENDING.borrow(cs).set(None);
                force_off();
            }
            Some(p) => {
                PENDING.borrow(cs).set(Some(p));
                // A stale update flag would fire the interrupt now, between two updates.
                clear_flags(|v| v.set_uif(false));
                pac::TIM1.dier().modify(|w| w.set_uie(true));
            }
        }
    });
}

/// TIM1 update (a counter extreme): applies the pending pattern, then disarms itself.
#[interrupt]
fn TIM1_UP_TIM16() {
    let t = pac::TIM1;
    t.dier().modify(|w| w.set_uie(false));
    clear_flags(|v| v.set_uif(false));
    let Some(p) = critical_section::with(|cs| PENDING.borrow(cs).take()) else {
        return;
    };
    if hw_tripped() {
        // The hardware stop cut the bridge: it stays off until the fault is cleared.
        force_off();
        return;
    }
    // Register access beside the ComplementaryPwm driver, which owns TIM1 but is only used
    // for the configuration: CCR1-3, CCER and MOE are written here and in `force_off` only.
    // Enables into their preload registers, compare values at once, then the commutation
    // event switches the enables together.
    t.ccer().modify(|w| {
        for (ph, &en) in p.enable.iter().enumerate() {
            w.set_cce(ph, en);
            w.set_ccne(ph, en);
        }
    });
    for (ph, &c) in p.ccr.iter().enumerate() {
        t.ccr(ph).write(|w| w.set_ccr(c));
    }
    t.egr().write(|w| w.set_comg(true));
    t.bdtr().modify(|w| w.set_moe(true));
    LAST_LOW.store(p.low, Ordering::Relaxed);
}

/// The bridge: owns TIM1 and its six pins, configured by embassy's `ComplementaryPwm`.
pub struct Bridge<'d> {
    pwm: ComplementaryPwm<'d, TIM1>,
}

impl<'d> Bridge<'d> {
    /// Takes the configured PWM (outputs still off).
    pub fn new(mut pwm: ComplementaryPwm<'d, TIM1>) -> Self {
        // A debugger halt stops TIM1 with its outputs disabled (RM0440, "DBGMCU_APB2FZR":
        // for advanced timers the outputs behave as with MOE = 0 while frozen).
        pac::DBGMCU.apb2fzr().modify(|w| w.set_tim1(true));
        // Commutation on the update event (module docs): output enables preloaded and
        // switched by the commutation event, generated by software only (CCUS = 0); compare
        // values written directly (compare preload off), at the counter's extreme.
        let t = pac::TIM1;
        t.cr2().modify(|w| {
            w.set_ccpc(true);
            w.set_ccus(false);
        });
        for ph in 0..3 {
            t.ccmr_output(ph / 2).modify(|w| w.set_ocpe(ph % 2, false));
        }
        interrupt::TIM1_UP_TIM16.set_priority(interrupt::Priority::P0);
        // SAFETY: the handler touches TIM1 and the critical-section pattern only.
        unsafe { interrupt::TIM1_UP_TIM16.enable() };
        pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
        pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
        let mut b = Bridge { pwm };
        b.off();
        b
    }

    /// All gates off, and no commutation until the drive is set again.
    pub fn off(&mut self) {
        critical_section::with(|cs| {
            let mut d = DRIVE.borrow(cs).get();
            d.on = false;
            DRIVE.borrow(cs).set(d);
            PENDING.borrow(cs).set(None);
        });
        self.pwm.set_master_output_enable(false);
        for ch in PHASES {
            self.pwm.set_duty(ch, 0);
            self.pwm.disable(ch);
        }
    }

    /// True while the outputs are enabled.
    pub fn is_on(&self) -> bool {
        pac::TIM1.bdtr().read().moe()
    }

    /// Compare value for duty `d` (0..=MAX_DUTY).
    pub fn duty_counts(&self, d: f32) -> u16 {
        let max = self.pwm.get_max_duty();
        ((d.clamp(0.0, MAX_DUTY) * max as f32) as u32).min(max) as u16
    }
}

/// Turns the bridge off by register access: for the panic and fault handlers.
pub fn force_off() {
    pac::TIM1.bdtr().modify(|w| w.set_moe(false));
}

/// True once the hardware over-current stop has cut the bridge (TIM1 break flag).
pub fn hw_tripped() -> bool {
    pac::TIM1.sr().read().bif(0)
}

/// Clears the break flag, so that [`commutate`] may turn the bridge on again.
pub fn rearm() {
    clear_flags(|v| v.set_bif(0, false));
}

/// Clears the TIM1_SR flags that `clear` sets false, leaving the others: the register is
/// write-zero-to-clear, so every other flag is written 1 (a read-modify-write would clear a
/// flag set between its read and its write).
fn clear_flags(clear: impl FnOnce(&mut pac::timer::regs::SrAdv)) {
    let mut v = pac::timer::regs::SrAdv(0);
    v.set_uif(true);
    for n in 0..4 {
        v.set_ccif(n, true);
        v.set_ccof(n, true);
    }
    v.set_comif(true);
    v.set_tif(true);
    v.set_bif(0, true);
    v.set_bif(1, true);
    v.set_sbif(true);
    v.set_ccif5(true);
    v.set_ccif6(true);
    v.set_idxif(true);
    v.set_dirif(true);
    v.set_ierrif(true);
    v.set_terrif(true);
    clear(&mut v);
    pac::TIM1.sr().write_value(v);
}
