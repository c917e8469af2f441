//! The three-phase bridge driven six-step from TIM1 (centre-aligned complementary PWM).
//!
//! Commutation step `k` (0..5) powers one phase pair: the "high" phase switches with duty
//! `d` (complementary, so its low side conducts in the off time: synchronous rectification),
//! the "low" phase has its low side on all the time (duty 0), the third phase floats (both
//! outputs disabled). Step `k + 3` is step `k` with the polarity reversed, which is how a
//! negative voltage is applied.
//!
//! Because the low phase's low-side switch conducts during the whole period, its shunt
//! carries the winding current in both the on and the freewheel interval: the firmware
//! reads that phase's op-amp at any time, without synchronising the ADC to the PWM.
//!
//! [`Bridge::off`] clears MOE with OSSI = idle level and OIS = 0, which forces all six gate
//! signals low (RM0440, "TIMx_BDTR", off-state selection); [`force_off`] does the same from
//! a panic or fault handler without the driver object.
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

/// Commutation step for Hall sector `sector` and the sign of the voltage.
pub fn step_for(sector: u8, v: f32) -> u8 {
    if v >= 0.0 {
        sector % 6
    } else {
        (sector + 3) % 6
    }
}

/// Duty cycle for a voltage magnitude and the bus voltage: `|V|/V_bus`, saturated at
/// [`MAX_DUTY`]; zero when the bus voltage is not positive.
pub fn duty(v: f32, v_bus: f32) -> f32 {
    if v_bus.is_nan() || v_bus <= 0.0 || !v.is_finite() {
        return 0.0;
    }
    (v.abs() / v_bus).clamp(0.0, MAX_DUTY)
}

/// The bridge.
pub struct Bridge<'d> {
    pwm: ComplementaryPwm<'d, TIM1>,
    on: bool,
}

impl<'d> Bridge<'d> {
    /// Takes the configured PWM (outputs still off).
    pub fn new(mut pwm: ComplementaryPwm<'d, TIM1>) -> Self {
        pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
        pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
        let mut b = Bridge { pwm, on: true };
        b.off();
        b
    }

    /// All gates off.
    pub fn off(&mut self) {
        self.pwm.set_master_output_enable(false);
        for ch in PHASES {
            self.pwm.set_duty(ch, 0);
            self.pwm.disable(ch);
        }
        self.on = false;
    }

    /// True while the outputs are enabled.
    pub fn is_on(&self) -> bool {
        self.on
    }

    /// Applies commutation step `k` with duty `d` (0..=MAX_DUTY).
    pub fn apply(&mut self, k: u8, d: f32) {
        let (hi, lo) = STEPS[k as usize % 6];
        let max = self.pwm.get_max_duty();
        let counts = ((d.clamp(0.0, MAX_DUTY)) * max as f32) as u32;
        for (p, ch) in PHASES.iter().enumerate() {
            if p == hi {
                self.pwm.set_duty(*ch, counts.min(max));
                self.pwm.enable(*ch);
            } else if p == lo {
                self.pwm.set_duty(*ch, 0);
                self.pwm.enable(*ch);
            } else {
                self.pwm.disable(*ch);
            }
        }
        self.pwm.set_master_output_enable(true);
        self.on = true;
    }
}

/// Turns the bridge off by register access: for the panic and fault handlers.
pub fn force_off() {
    pac::TIM1.bdtr().modify(|w| w.set_moe(false));
}
