//! B-G431B-ESC1 board facts: clocks, pins, analog front-end gains, limits.
//!
//! Sources (say which where a value is set):
//! - [UM2516] ST UM2516 "Electronic speed controller Discovery kit for drones with
//!   STM32G431CB" (B-G431B-ESC1 user manual): board features (STM32G431CB, L6387ED gate
//!   drivers, STL180N6F7 MOSFETs, up to 6S LiPo, 40 A peak), user LED, button, ST-LINK VCP.
//! - [NuttX] Apache NuttX board support `boards/arm/stm32/b-g431b-esc1/` (`include/board.h`,
//!   `src/stm32_foc.c`, `src/b-g431b-esc1.h`), which transcribes the board schematic: 8 MHz
//!   crystal Y2, TIM1 pins, OPAMP pins, ADC channels, shunt 3 mΩ, sense gain −9.14, VBUS
//!   sense gain 0.0962, Hall inputs PB6/PB7/PB8, LED PC6, button PC10, pot PB12.
//!
//! Values marked ASSUMED could not be checked against the schematic here and must be
//! verified on the bench before running a motor.
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk,
};
use embassy_stm32::time::Hertz;

/// HSE crystal: 8 MHz (Y2) [NuttX include/board.h, STM32_BOARD_XTAL].
pub const HSE_HZ: u32 = 8_000_000;
/// System clock: 170 MHz, the STM32G431's maximum.
pub const SYSCLK_HZ: u32 = 170_000_000;

/// Clock tree: HSE 8 MHz / 2 × 85 = 340 MHz VCO, / 2 = 170 MHz SYSCLK (PLLR); AHB, APB1,
/// APB2 undivided, so TIM1 and TIM4 count at 170 MHz [NuttX include/board.h, HSE option].
/// Range-1 boost mode is required above 150 MHz (RM0440, PWR_CR5.R1MODE).
pub fn config() -> embassy_stm32::Config {
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    c.rcc.pll = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV2,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    c.rcc.sys = Sysclk::PLL1_R;
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV1;
    c.rcc.apb2_pre = APBPrescaler::DIV1;
    c.rcc.boost = true;
    // ADC12 kernel clock from SYSCLK (the HAL divides it to ≤ 60 MHz).
    c.rcc.mux.adc12sel = embassy_stm32::rcc::mux::Adcsel::SYS;
    c
}

/// PWM carrier: 20 kHz, centre-aligned (at or above 20 kHz: inaudible).
pub const PWM_HZ: u32 = control::board::PWM_HZ;
/// Dead time in TIM1 clock ticks: 85 × 5.88 ns = 500 ns, the value NuttX uses for this board
/// (`PWM_DEADTIME_NS 500` in src/stm32_foc.c). The L6387ED adds its own ≈ 320 ns interlock.
pub const DEAD_TIME_TICKS: u16 = 85;
// The board logic's dead-time drop (commissioning) assumes the same dead time: 170 MHz TIM1.
const _: () = assert!(DEAD_TIME_TICKS as u32 * 1000 / 170 == control::board::DEAD_TIME_NS);
/// Largest duty cycle: 95 %, so the bootstrap capacitors of the L6387ED high-side drivers
/// recharge every period [NuttX src/stm32_foc.c, MAX_DUTY_B16 = 0.95].
pub const MAX_DUTY: f32 = control::board::MAX_DUTY;

/// ADC reference: VDDA = 3.3 V [NuttX src/stm32_foc.c, ADC_REF_VOLTAGE].
pub const ADC_VREF: f32 = 3.3;
/// 12-bit ADC full scale.
pub const ADC_FULL_SCALE: f32 = 4095.0;
/// Bus voltage divider: V_adc = 0.0962 · V_bus on PA0 (ADC1_IN1) [NuttX src/stm32_foc.c,
/// "Vbus sense gain = 0.0962"].
pub const VBUS_GAIN: f32 = 0.0962;
/// Phase current sense: low-side shunt 3 mΩ, OPAMP in PGA ×16 with the board's bias network,
/// total gain −9.14 V/V (inverted) [NuttX src/stm32_foc.c]: I = −(V − V_0)/(0.003·9.14).
pub const SHUNT_OHM: f32 = 0.003;
/// Total current-sense amplification (sign included), see [`SHUNT_OHM`].
pub const SENSE_GAIN: f32 = -9.14;
/// Gain of the op-amps' programmable-gain amplifier [NuttX src/stm32_foc.c, "PGA gain = 16"]:
/// the op-amps' non-inverting inputs (PA1, PA7, PB0), which the over-current comparators
/// watch, carry the shunt voltage scaled by `|SENSE_GAIN| / PGA_GAIN` (4/7).
pub const PGA_GAIN: f32 = 16.0;

/// Board temperature sensor (NTC divider) on PB14 = ADC1_IN5, linearised as ST's motor
/// control project for this board does [MCSDK "ElectronicSpeedControl" for the
/// B-G431B-ESC1: TEMP_FDBK PB14 ADC1 channel 5, V0 = 1.055 V at T0 = 25 °C, dV/dT =
/// 0.023 V/°C]: T = T0 + (V − V0)/(dV/dT).
pub const NTC_V0: f32 = 1.055;
/// Temperature at which the NTC divider gives [`NTC_V0`] [°C].
pub const NTC_T0_C: f32 = 25.0;
/// Slope of the NTC divider [V/°C] near [`NTC_T0_C`].
pub const NTC_DV_DT: f32 = 0.023;

/// Board temperature [°C] from the raw PB14 reading.
pub fn ntc_celsius(raw: u16) -> f32 {
    NTC_T0_C + (adc_volts(raw) - NTC_V0) / NTC_DV_DT
}

/// Volts at an ADC pin for a raw reading.
pub fn adc_volts(raw: u16) -> f32 {
    raw as f32 * (ADC_VREF / ADC_FULL_SCALE)
}

/// Bus voltage [V] from the raw PA0 reading.
pub fn vbus_from_raw(raw: u16) -> f32 {
    adc_volts(raw) / VBUS_GAIN
}

/// Phase current [A] from a raw op-amp output reading and its zero-current reading (taken
/// with the bridge off at boot).
pub fn current_from_raw(raw: u16, zero: u16) -> f32 {
    (adc_volts(raw) - adc_volts(zero)) / (SHUNT_OHM * SENSE_GAIN)
}

// Pin map (checked against [NuttX]; names as in UM2516):
// - TIM1_CH1/CH2/CH3 = PA8/PA9/PA10 (U/V/W high side), TIM1_CH1N/CH2N/CH3N =
//   PC13/PA12/PB15 (U/V/W low side) [NuttX include/board.h, "TIM1 configuration"];
//   gate polarity active high for both (L6387ED) [NuttX src/stm32_foc.c].
// - Current sense: OPAMP1 VINP PA1, VINM(bias) PA3, VOUT PA2 = ADC1_IN3 (phase U);
//   OPAMP2 VINP PA7, VINM PA5, VOUT PA6 = ADC2_IN3 (phase V, not on ADC1);
//   OPAMP3 VINP PB0, VINM PB2, VOUT PB1 = ADC1_IN12 (phase W) [NuttX src/stm32_foc.c].
// - VBUS: PA0 = ADC1_IN1; potentiometer PB12 = ADC1_IN11 [NuttX src/stm32_foc.c].
// - Board temperature (NTC): PB14 = ADC1_IN5, see [`NTC_V0`].
// - Hall / encoder connector: H1 PB6 (TIM4_CH1), H2 PB7 (TIM4_CH2), H3 PB8 (TIM4_CH3)
//   [NuttX src/b-g431b-esc1.h, GPIO_HALL_PHA..C; include/board.h, TIM4 pins].
//   ASSUMED: open-collector sensors, so the internal pull-ups are enabled.
//   PB8 is also the STM32G431's BOOT0 pin (DS12589 pinout "PB8-BOOT0"): a Hall level high
//   at reset can start the ROM bootloader unless the option bytes take BOOT0 from nBOOT0
//   (nSWBOOT0 = 0, nBOOT0 = 1). The firmware checks them at boot (warning `Boot0FromPin`);
//   docs/bring-up.md gives the STM32CubeProgrammer and OpenOCD commands that set them.
// - USART2 (ST-LINK virtual COM port): TX PB3, RX PB4 [NuttX include/board.h; UM2516].
// - User LED LD2: PC6; user button: PC10 [NuttX src/b-g431b-esc1.h; UM2516].

/// Bit mask of the three Hall inputs in GPIOB's input register (PB6, PB7, PB8).
pub const HALL_SHIFT: u32 = 6;

/// Independent watchdog timeout [µs]. A stuck control loop stops feeding it and the MCU
/// resets with the bridge off (reset state of TIM1: outputs off). 100 ms = 8 control periods:
/// long enough for a coefficient commit (page erase up to 40 ms, STM32G431 datasheet
/// DS12589 flash characteristics, during which the single-bank flash stalls the CPU).
pub const WATCHDOG_US: u32 = 100_000;

/// Serial link speed on the ST-LINK virtual COM port.
pub const BAUD: u32 = 115_200;
