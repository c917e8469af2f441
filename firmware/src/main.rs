//! Firmware for ST's B-G431B-ESC1 (STM32G431CB): thin board glue around `control`.
//!
//! - [`board`]: clocks (170 MHz), pins and analog gains, with their sources.
//! - [`bridge`]: TIM1 centre-aligned complementary PWM, six-step commutation, duty = V/V_bus.
//! - [`hall_capture`]: Hall edges time-stamped by TIM4 input capture (1 MHz); the capture
//!   interrupt commutates the bridge at every edge.
//! - [`link`]: the serial protocol of `control::frame` on USART2 (ST-LINK virtual COM port),
//!   coefficient uploads into the two flash slots of `control::slots`.
//! - [`excitation`]: open-loop experiment signals a-d, steady, ramp.
//! - this file: start-up and the 12 ms control loop (`control::step::ControlStep`), faults.
//!
//! Safety: an invalid Hall state or impossible transition, over-current, bus under- or
//! over-voltage turn the bridge off and latch a fault (cleared by `ClearFault`, the bridge
//! stays off until a mode is set again). The independent watchdog resets the MCU when the
//! loop stops (TIM1's reset state has the outputs off); a panic or HardFault clears TIM1's
//! MOE first, logs over defmt and waits for the watchdog.
//!
//! TODO (needs the board to get right, not faked here): cycle-by-cycle over-current with
//! COMP + TIM1 break input (the 12 ms software check is only a backstop); ADC sampling
//! synchronised to the PWM centre; the flash ECC NMI on an interrupted write (see
//! `control::slots`).
#![no_std]
#![no_main]

mod board;
mod bridge;
mod excitation;
mod hall_capture;
mod link;

use core::sync::atomic::Ordering;

use control::blob::{Coefficients, HALL_INVALID};
use control::frame::{BoardMsg, Excitation, Fault, Mode, Sample, Warning};
use control::slots::Slots;
use control::step::{ControlStep, Faults, StepInputs};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcConfig, SampleTime};
use embassy_stm32::flash::Flash;
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::opamp::{OpAmp, OpAmpGain, OpAmpSpeed};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, peripherals};
use embassy_time::{Duration, Instant, Ticker};
use static_cell::StaticCell;

use crate::bridge::Bridge;
use crate::link::{Command, COMMANDS, MODE, NEW_COEFFS, OUTGOING};

bind_interrupts!(struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
});

/// Nominal bus voltage [V] when the measurement is missing: a 6S LiPo is 22.2 V nominal
/// (UM2516: up to 6S); the step uses the measured value whenever it is valid.
const V_BUS_NOMINAL: f32 = 22.2;
/// Samples averaged for the zero-current offset of each op-amp at boot (bridge off).
const ZERO_SAMPLES: u32 = 64;

/// What runs.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Run {
    Idle,
    Speed,
    Experiment {
        signal: Excitation,
        duration_s: f32,
        start: Instant,
    },
}

/// The coefficients' Hall table for the commutation (negative: invalid state).
fn hall_table_of(c: &Coefficients) -> [i8; 8] {
    let mut t = [-1i8; 8];
    for (s, &b) in t.iter_mut().zip(&c.hall_table) {
        *s = if b == HALL_INVALID { -1 } else { b as i8 };
    }
    t
}

fn fault_of(f: Faults) -> Option<Fault> {
    if f.contains(Faults::HALL_INVALID) {
        Some(Fault::InvalidHall)
    } else if f.contains(Faults::HALL_JUMP) || f.contains(Faults::EDGE_OVERFLOW) {
        Some(Fault::ImpossibleTransition)
    } else {
        None
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::config());
    defmt::info!("B-G431B-ESC1 firmware {}", env!("CARGO_PKG_VERSION"));

    // Bridge first, outputs off: TIM1 CH1-3 PA8/PA9/PA10, CH1N-3N PC13/PA12/PB15.
    let mut pwm = ComplementaryPwm::new(
        p.TIM1,
        Some(PwmPin::new(p.PA8, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PC13, OutputType::PushPull)),
        Some(PwmPin::new(p.PA9, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PA12, OutputType::PushPull)),
        Some(PwmPin::new(p.PA10, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB15, OutputType::PushPull)),
        None,
        None,
        Hertz(board::PWM_HZ),
        CountingMode::CenterAlignedBothInterrupts,
    );
    pwm.set_dead_time(board::DEAD_TIME_TICKS);
    let mut bridge = Bridge::new(pwm);

    let mut led = Output::new(p.PC6, Level::Low, Speed::Low);

    // Current sense: OPAMP1/2/3 as PGA ×16 with the board's bias on VINM0 (board.rs).
    let mut op1 = OpAmp::new(p.OPAMP1, OpAmpSpeed::HighSpeed);
    let mut op2 = OpAmp::new(p.OPAMP2, OpAmpSpeed::HighSpeed);
    let mut op3 = OpAmp::new(p.OPAMP3, OpAmpSpeed::HighSpeed);
    let mut i_u = op1.pga_biased_ext(p.PA1, p.PA3, p.PA2, OpAmpGain::Mul16);
    let mut i_v = op2.pga_biased_ext(p.PA7, p.PA5, p.PA6, OpAmpGain::Mul16);
    let mut i_w = op3.pga_biased_ext(p.PB0, p.PB2, p.PB1, OpAmpGain::Mul16);
    let mut adc1 = Adc::new(p.ADC1, AdcConfig::default());
    let mut adc2 = Adc::new(p.ADC2, AdcConfig::default());
    let mut vbus_pin = p.PA0;
    const ST_CURRENT: SampleTime = SampleTime::CYCLES24_5;
    const ST_VBUS: SampleTime = SampleTime::CYCLES247_5;

    // Zero-current offsets with the bridge off.
    let (mut zu, mut zv, mut zw) = (0u32, 0u32, 0u32);
    for _ in 0..ZERO_SAMPLES {
        zu += adc1.blocking_read(&mut i_u, ST_CURRENT) as u32;
        zv += adc2.blocking_read(&mut i_v, ST_CURRENT) as u32;
        zw += adc1.blocking_read(&mut i_w, ST_CURRENT) as u32;
    }
    let zero = [
        (zu / ZERO_SAMPLES) as u16,
        (zv / ZERO_SAMPLES) as u16,
        (zw / ZERO_SAMPLES) as u16,
    ];

    // Coefficients from flash: newest valid slot, or none (plain PI loop, a warning).
    let slots = Slots::new(
        Flash::new_blocking(p.FLASH),
        link::SLOTS_OFFSET,
        link::SLOT_SIZE,
    );
    let (slots, coeffs) = match slots {
        Ok(mut s) => {
            let c = link::load_coefficients(&mut s);
            (Some(s), c)
        }
        Err(_) => {
            defmt::error!("coefficient slots do not fit the flash: storage disabled");
            (None, None)
        }
    };
    if coeffs.is_none() {
        let _ = OUTGOING.try_send(BoardMsg::Warning(Warning::NoCoefficients));
    }
    let mut coeffs = coeffs.unwrap_or_default();
    let mut step = ControlStep::new(&coeffs.step_config(V_BUS_NOMINAL));
    let mut hall_table = hall_table_of(&coeffs);

    hall_capture::start(p.TIM4, p.PB6, p.PB7, p.PB8);

    // ST-LINK virtual COM port: USART2 TX PB3, RX PB4.
    static TX_BUF: StaticCell<[u8; 512]> = StaticCell::new();
    static RX_BUF: StaticCell<[u8; 256]> = StaticCell::new();
    let mut ucfg = usart::Config::default();
    ucfg.baudrate = board::BAUD;
    let uart = BufferedUart::new(
        p.USART2,
        p.PB4,
        p.PB3,
        TX_BUF.init([0; 512]),
        RX_BUF.init([0; 256]),
        Irqs,
        ucfg,
    );
    match (uart, slots) {
        (Ok(uart), Some(slots)) => {
            let (tx, rx) = uart.split();
            // Each task is spawned once: its pool (size 1) cannot be exhausted.
            if let Ok(t) = link::tx_task(tx) {
                spawner.spawn(t);
            }
            if let Ok(t) = link::rx_task(rx, slots) {
                spawner.spawn(t);
            }
        }
        _ => defmt::error!("serial link not started"),
    }

    let mut wdg = IndependentWatchdog::new(p.IWDG, board::WATCHDOG_US);
    wdg.unleash();

    let mut run = Run::Idle;
    let mut omega_ref = 0.0f32;
    let mut latched: Option<Fault> = None;
    let mut seq = 0u32;
    let mut run_start = Instant::now();
    let mut ticker = Ticker::every(Duration::from_micros(
        (control::CONTROL_PERIOD_S * 1.0e6) as u64,
    ));

    let period = Duration::from_micros((control::CONTROL_PERIOD_S * 1.0e6) as u64);
    let mut last_tick = Instant::now();
    loop {
        ticker.next().await;
        wdg.pet();
        // A tick more than one period late means the loop overran (the ticker catches up).
        let tick = Instant::now();
        let overrun = tick - last_tick > period + period;
        last_tick = tick;

        // New coefficients (only committed in Idle): rebuild the step.
        if let Some(c) = NEW_COEFFS.try_take() {
            coeffs = c;
            step = ControlStep::new(&coeffs.step_config(V_BUS_NOMINAL));
            hall_table = hall_table_of(&coeffs);
        }

        // Host commands.
        while let Ok(cmd) = COMMANDS.try_receive() {
            match cmd {
                Command::SetSpeed(w) if w.is_finite() => omega_ref = w,
                Command::SetSpeed(_) => {}
                Command::SetMode(Mode::Idle) | Command::Stop => run = Run::Idle,
                Command::SetMode(Mode::Speed) if latched.is_none() => {
                    step.reset();
                    run = Run::Speed;
                    run_start = Instant::now();
                    seq = 0;
                }
                Command::SetMode(Mode::Experiment) => {}
                Command::Start { signal, duration_s } if latched.is_none() => {
                    step.reset();
                    run_start = Instant::now();
                    seq = 0;
                    run = Run::Experiment {
                        signal,
                        duration_s,
                        start: run_start,
                    };
                }
                Command::ClearFault => latched = None,
                _ => {
                    // Start refused while a fault is latched: repeat the fault.
                    if let Some(f) = latched {
                        let _ = OUTGOING.try_send(BoardMsg::Fault(f));
                    }
                }
            }
        }

        // Measurements.
        let v_bus = board::vbus_from_raw(adc1.blocking_read(&mut vbus_pin, ST_VBUS));
        let last_step_k = bridge::last_step();
        let lo = bridge::low_phase(last_step_k);
        let raw = match lo {
            0 => adc1.blocking_read(&mut i_u, ST_CURRENT),
            1 => adc2.blocking_read(&mut i_v, ST_CURRENT),
            _ => adc1.blocking_read(&mut i_w, ST_CURRENT),
        };
        // Current leaves through the low phase's shunt; in the reversed steps (k ≥ 3) the
        // winding current is negative. ASSUMED sign convention: verify on the bench.
        let i_phase = board::current_from_raw(raw, zero[lo]);
        let i_meas = if bridge.is_on() {
            if last_step_k < 3 {
                -i_phase
            } else {
                i_phase
            }
        } else {
            0.0
        };
        let (edges, edges_overflow) = hall_capture::take_edges();
        let now = Instant::now();
        let v_override = match run {
            Run::Experiment {
                signal,
                duration_s,
                start,
            } => {
                let t = (now - start).as_micros() as f32 * 1.0e-6;
                if t >= duration_s {
                    run = Run::Idle;
                    None
                } else {
                    Some(excitation::voltage(signal, t))
                }
            }
            _ => None,
        };
        let inp = StepInputs {
            hall: hall_capture::hall_state(),
            edges,
            edges_overflow,
            now_ticks: hall_capture::now_ticks(),
            i_meas,
            v_bus,
            omega_ref,
            v_override,
        };
        let out = step.step(&inp);

        // Safety checks.
        let active = run != Run::Idle;
        let lim = &coeffs.limits;
        let fault = if i_meas.abs() > lim.i_max {
            Some(Fault::OverCurrent)
        } else if v_bus > lim.vbus_max {
            Some(Fault::OverVoltage)
        } else if active && v_bus < lim.vbus_min {
            Some(Fault::UnderVoltage)
        } else if active && overrun {
            Some(Fault::Overrun)
        } else if active {
            fault_of(out.faults)
        } else {
            None
        };
        if let Some(f) = fault {
            bridge.off();
            if latched.is_none() {
                defmt::error!("fault {}: bridge off", f as u8);
                let _ = OUTGOING.try_send(BoardMsg::Fault(f));
            }
            latched = Some(f);
            run = Run::Idle;
        }

        // Actuation: set the drive; the Hall-edge interrupt commutates between samples.
        let v_applied = match (run, step.decoder().sector()) {
            (Run::Idle, _) | (_, None) => {
                bridge.off();
                0.0
            }
            (_, Some(_)) => {
                let d = bridge::duty(out.v_cmd, v_bus);
                bridge::set_drive(bridge::Drive {
                    on: true,
                    reverse: out.v_cmd < 0.0,
                    duty: bridge.duty_counts(d),
                    table: hall_table,
                });
                bridge::commutate(hall_capture::hall_state());
                d * v_bus * if out.v_cmd < 0.0 { -1.0 } else { 1.0 }
            }
        };
        MODE.store(
            match run {
                Run::Idle => link::MODE_IDLE,
                Run::Speed => link::MODE_SPEED,
                Run::Experiment { .. } => link::MODE_EXPERIMENT,
            },
            Ordering::Relaxed,
        );
        led.set_level(if bridge.is_on() {
            Level::High
        } else {
            Level::Low
        });

        // Log sample every 12 ms while running.
        if run != Run::Idle {
            let t = (now - run_start).as_micros() as f32 * 1.0e-6;
            let _ = OUTGOING.try_send(BoardMsg::Sample(Sample {
                seq,
                t,
                u: v_applied,
                i: i_meas,
                theta: out.theta,
                omega: out.omega,
            }));
            seq = seq.wrapping_add(1);
        }
    }
}

/// Panic: interrupts off, bridge off, then log over defmt; the watchdog resets the MCU.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // No interrupt may commutate again (the Hall-edge handler sets MOE).
    cortex_m::interrupt::disable();
    bridge::force_off();
    // File and line only: formatting the message would link core::fmt (≈ 12 KiB).
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    loop {
        cortex_m::asm::nop();
    }
}

/// HardFault: bridge off, then wait for the watchdog.
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    bridge::force_off();
    loop {
        cortex_m::asm::nop();
    }
}
