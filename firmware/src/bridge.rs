//! The three-phase bridge driven six-step from TIM1 (centre-aligned complementary PWM).
//!
//! Commutation step `k` (0..5) powers one phase pair: the "high" phase switches with duty
//! `d` (complementary, so its low side conducts in the off time: synchronous rectification),
//! the "low" phase has its low side on all the time (duty 0), the third phase floats (both
//! outputs disabled). Step `k + 3` is step `k` with the polarity reversed. Which step drives
//! a rotor in a Hall sector is `control::board::commutation_step` (sector + 1 forward,
//! sector + 4 for a negative voltage), the same rule the emulated board uses; commissioning
//! holds one step whatever the Hall state ([`Drive::hold`]).
//!
//! Because the low phase's low-side switch conducts during the whole period, its shunt
//! carries the winding current in both the on and the freewheel interval: the firmware
//! reads that phase's op-amp at any time, without synchronising the ADC to the PWM.
//!
//! Commutation follows the rotor at every Hall edge: the TIM4 capture interrupt calls
//! [`commutate`] with the new Hall state (`hall_capture`), and the 12 ms control loop only
//! sets the drive (on/off, direction, duty) with [`set_drive`] and commutates once itself so
//! a new duty applies at once. Commutating only every 12 ms would energise the wrong phase
//! pair for most of each period above a few rad/s.
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
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM1;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, Ossi, Ossr};
use embassy_stm32::timer::Channel;

use crate::board::MAX_DUTY;

/// Phase order U, V, W as TIM1 channels 1, 2, 3.
const PHASES: [Channel; 3] = [Channel::Ch1, Channel::Ch2, Channel::Ch3];

/// (high phase, low phase) of each commutation step.
const STEPS: [(usize, usize); 6] = [(0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1)];

/// The phase whose low-side switch is on in step `k`: the one whose shunt to read.
pub fn low_phase(k: u8) -> usize {
    STEPS[k as usize % 6].1
}

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
    /// Compare value of the high phase (0..=max duty counts).
    pub duty: u16,
    /// Hall state → sector (the coefficients' table; negative = invalid state).
    pub table: [i8; 8],
    /// Hold this step whatever the Hall state (commissioning).
    pub hold: Option<u8>,
}

static DRIVE: Mutex<Cell<Drive>> = Mutex::new(Cell::new(Drive {
    on: false,
    reverse: false,
    duty: 0,
    table: [-1; 8],
    hold: None,
}));
/// Step applied last (for the current measurement: its low phase's shunt).
static LAST_STEP: AtomicU8 = AtomicU8::new(0);

/// Sets what the next commutations apply.
pub fn set_drive(d: Drive) {
    critical_section::with(|cs| DRIVE.borrow(cs).set(d));
}

/// The commutation step applied last.
pub fn last_step() -> u8 {
    LAST_STEP.load(Ordering::Relaxed)
}

/// Applies the drive for Hall state `state`: the step of its sector, or all off when the
/// drive is off or the state is invalid. Called from the TIM4 interrupt and the control loop.
pub fn commutate(state: u8) {
    let d = critical_section::with(|cs| DRIVE.borrow(cs).get());
    let sector = d.table[(state & 7) as usize];
    let k = match d.hold {
        _ if !d.on => {
            force_off();
            return;
        }
        Some(k) => k % 6,
        None if sector < 0 => {
            force_off();
            return;
        }
        None => control::board::commutation_step(sector as u8, d.reverse),
    };
    let (hi, lo) = STEPS[k as usize];
    let t = pac::TIM1;
    if hw_tripped() {
        // The hardware stop cut the bridge: it stays off until the fault is cleared.
        force_off();
        return;
    }
    // Register access beside the ComplementaryPwm driver, which owns TIM1 but is only used
    // for the configuration: CCR1-3, CCER and MOE are written here and in `force_off` only.
    for p in 0..3 {
        t.ccr(p)
            .write(|w| w.set_ccr(if p == hi { d.duty } else { 0 }));
    }
    t.ccer().modify(|w| {
        for p in 0..3 {
            let en = p == hi || p == lo;
            w.set_cce(p, en);
            w.set_ccne(p, en);
        }
    });
    t.bdtr().modify(|w| w.set_moe(true));
    LAST_STEP.store(k, Ordering::Relaxed);
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
        pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
        pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
        let mut b = Bridge { pwm };
        b.off();
        b
    }

    /// All gates off, and no commutation until the drive is set again.
    pub fn off(&mut self) {
        let mut d = critical_section::with(|cs| DRIVE.borrow(cs).get());
        d.on = false;
        set_drive(d);
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

/// Clears the break flag, so that [`commutate`] may turn the bridge on again. Write-zero-
/// to-clear: every other flag of TIM1_SR is written 1, which leaves it as it is.
pub fn rearm() {
    let mut v = pac::timer::regs::SrAdv(0);
    v.set_uif(true);
    for n in 0..4 {
        v.set_ccif(n, true);
        v.set_ccof(n, true);
    }
    v.set_comif(true);
    v.set_tif(true);
    v.set_bif(1, true);
    v.set_sbif(true);
    v.set_ccif5(true);
    v.set_ccif6(true);
    v.set_idxif(true);
    v.set_dirif(true);
    v.set_ierrif(true);
    v.set_terrif(true);
    pac::TIM1.sr().write_value(v);
}
