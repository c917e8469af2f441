//! Firmware for ST's B-G431B-ESC1 (STM32G431CB): thin board glue around `control`.
//!
//! - [`board`]: clocks (170 MHz), pins and analog gains, with their sources.
//! - [`bridge`]: TIM1 centre-aligned complementary PWM, six-step commutation applied on the
//!   PWM update event (all six gates at once), duty = V/V_bus.
//! - [`hall_capture`]: Hall edges time-stamped by TIM4 input capture (1 MHz); the capture
//!   interrupt commutates the bridge at every edge; edges beyond the queue are counted.
//! - [`link`]: the serial protocol of `control::frame` on USART2 (ST-LINK virtual COM port),
//!   coefficient uploads into the two flash slots of `control::slots`.
//! - [`storage`]: the flash behind those slots, a double ECC error (NMI) turned into a
//!   failed read.
//! - [`sense`]: the ADC readings of a period: bus voltage, NTC, the current along the
//!   applied vector (zero offsets measured at boot).
//! - [`overcurrent`]: comparators on the shunts into TIM1's break input, armed at boot: the
//!   bridge turns off within a PWM period above the board's 40 A rating.
//! - this file: start-up and the 12 ms control loop: measurements in, `control::board::Board`
//!   (the board's logic: commands, modes, limits, faults, commissioning, shared with the
//!   emulated board) in the middle, the bridge drive out. The loop's period and work are
//!   timed with the DWT cycle counter; the board logic turns them into one telemetry report
//!   a second (`control::telemetry`), printed through defmt and sent to the host during runs.
//!
//! Safety (in `control::board`): an invalid Hall state or impossible transition,
//! over-current, over-temperature (the board's NTC, which also lowers the current limit from
//! 80 °C), bus under- or over-voltage, overrun, stall, a current sense that reads the current
//! against its driving voltage (`CurrentSense`), over-speed and a model that disagrees with
//! the measured current (`ModelMismatch`) turn the bridge off and latch a fault (cleared by `ClearFault`, the bridge stays off until a mode is set again). The
//! independent watchdog runs before the flash is read and resets the MCU when the loop
//! stops (TIM1's reset state has the outputs off); a panic, HardFault or unexpected
//! interrupt clears TIM1's MOE first and waits for the watchdog. A flash ECC error in a
//! coefficient slot (an interrupted commit) makes that slot invalid ([`storage`]). The
//! option bytes are checked at boot (PB8 is Hall H3 and BOOT0, docs/bring-up.md).
//!
//! TODO (needs the board to get right, not faked here): ADC sampling synchronised to the
//! PWM centre.
#![no_std]
#![no_main]

mod board;
mod bridge;
mod hall_capture;
mod link;
mod overcurrent;
mod sense;
mod storage;

use core::sync::atomic::Ordering;

use control::board::{store_coefficients, Board, Drive, Measurements};
use control::frame::{BoardMsg, Mode, Warning};
use control::slots::Slots;
use cortex_m::peripheral::DWT;
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::adc::{Adc, AdcConfig};
use embassy_stm32::flash::Flash;
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::opamp::{OpAmp, OpAmpGain, OpAmpSpeed};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, pac, peripherals, Peri};
use embassy_time::{Duration, Ticker};
use static_cell::StaticCell;

use crate::bridge::Bridge;
use crate::link::{COMMANDS, MODE, NEW_COEFFS, OUTGOING, SLOTS};
use crate::sense::Sense;

bind_interrupts!(struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
});

/// Nominal bus voltage [V] when the measurement is missing: a 6S LiPo is 22.2 V nominal
/// (UM2516: up to 6S); the board logic uses the measured value whenever it is valid.
const V_BUS_NOMINAL: f32 = 22.2;

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::config());
    defmt::info!("B-G431B-ESC1 firmware {}", env!("CARGO_PKG_VERSION"));

    // Bridge first, outputs off: TIM1 CH1-3 PA8/PA9/PA10, CH1N-3N PC13/PA12/PB15.
    let mut bridge = start_bridge(p.TIM1, (p.PA8, p.PC13), (p.PA9, p.PA12), (p.PA10, p.PB15));
    let mut led = Output::new(p.PC6, Level::Low, Speed::Low);

    // Current sense: OPAMP1/2/3 as PGA ×16 with the board's bias on VINM0 (board.rs); the
    // zero-current offsets are measured now, with the bridge off.
    let mut op1 = OpAmp::new(p.OPAMP1, OpAmpSpeed::HighSpeed);
    let mut op2 = OpAmp::new(p.OPAMP2, OpAmpSpeed::HighSpeed);
    let mut op3 = OpAmp::new(p.OPAMP3, OpAmpSpeed::HighSpeed);
    let mut sense = Sense::new(
        (
            Adc::new(p.ADC1, AdcConfig::default()),
            Adc::new(p.ADC2, AdcConfig::default()),
        ),
        op1.pga_biased_ext(p.PA1, p.PA3, p.PA2, OpAmpGain::Mul16),
        op2.pga_biased_ext(p.PA7, p.PA5, p.PA6, OpAmpGain::Mul16),
        op3.pga_biased_ext(p.PB0, p.PB2, p.PB1, OpAmpGain::Mul16),
        p.PA0,
        p.PB14,
    );

    check_option_bytes();
    let hw_stop_armed = arm_hardware_stop(p.DAC3);
    // The watchdog runs from here on: a fault while reading the flash resets the MCU
    // instead of hanging it (TIM1's reset state has the outputs off).
    let mut wdg = IndependentWatchdog::new(p.IWDG, board::WATCHDOG_US);
    wdg.unleash();
    let mut board = Board::new(
        load_coefficients(p.FLASH),
        env!("CARGO_PKG_VERSION"),
        V_BUS_NOMINAL,
    );
    // Reported at every Identify; speed and experiment runs are refused without it.
    board.set_hardware_stop(hw_stop_armed, cfg!(feature = "run-without-hw-stop"));
    hall_capture::start(p.TIM4, p.PB6, p.PB7, p.PB8);
    start_link(spawner, p.USART2, p.PB4, p.PB3);
    wdg.pet();

    let mut timer = LoopTimer::start();
    let mut ticker = Ticker::every(Duration::from_micros(
        (control::CONTROL_PERIOD_S * 1.0e6) as u64,
    ));
    let mut send = |m: BoardMsg| link::send(m);
    loop {
        ticker.next().await;
        let timing = timer.begin();
        wdg.pet();
        take_host_messages(&mut board, &mut send);
        let m = measure(&mut sense, &bridge, timing);
        let drive = board.tick(&m, &mut send);
        store_if_idle(&mut board, &mut send);
        actuate(&mut bridge, drive, m.v_bus);
        publish(&mut board, &bridge, &mut led);
        timer.end();
    }
}

/// TIM1's complementary PWM on the three (high, low) gate pin pairs, outputs off.
fn start_bridge(
    tim: Peri<'static, peripherals::TIM1>,
    u: (
        Peri<'static, peripherals::PA8>,
        Peri<'static, peripherals::PC13>,
    ),
    v: (
        Peri<'static, peripherals::PA9>,
        Peri<'static, peripherals::PA12>,
    ),
    w: (
        Peri<'static, peripherals::PA10>,
        Peri<'static, peripherals::PB15>,
    ),
) -> Bridge<'static> {
    let mut pwm = ComplementaryPwm::new(
        tim,
        Some(PwmPin::new(u.0, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(u.1, OutputType::PushPull)),
        Some(PwmPin::new(v.0, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(v.1, OutputType::PushPull)),
        Some(PwmPin::new(w.0, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(w.1, OutputType::PushPull)),
        None,
        None,
        Hertz(board::PWM_HZ),
        CountingMode::CenterAlignedBothInterrupts,
    );
    pwm.set_dead_time(board::DEAD_TIME_TICKS);
    Bridge::new(pwm)
}

/// PB8 is both Hall H3 and BOOT0: unless the option bytes take BOOT0 from nBOOT0
/// (nSWBOOT0 = 0), a high H3 at reset boots the ROM. Programming option bytes from the
/// firmware could brick the board on a power cut: report, the engineer sets them once
/// (docs/bring-up.md).
fn check_option_bytes() {
    if pac::FLASH.optr().read().n_swboot0() {
        defmt::warn!(
            "option byte nSWBOOT0 = 1: BOOT0 follows PB8 = Hall H3; set nSWBOOT0 = 0, nBOOT0 = 1"
        );
        let _ = OUTGOING.try_send(BoardMsg::Warning(Warning::Boot0FromPin));
    }
}

/// Arms the hardware over-current stop, calibrated on the op-amps with the bridge off;
/// whether it is armed.
fn arm_hardware_stop(dac: Peri<'static, peripherals::DAC3>) -> bool {
    match overcurrent::arm(dac) {
        Ok(a) => {
            defmt::info!("hardware over-current stop armed: {}", a);
            #[cfg(feature = "trip-test")]
            defmt::warn!(
                "trip-test build: the stop trips at {=f32} A, not at the rating",
                overcurrent::TRIP_TEST_A
            );
            true
        }
        Err(why) => {
            defmt::error!("hardware over-current stop NOT armed: {=str}", why);
            let _ = OUTGOING.try_send(BoardMsg::Warning(Warning::NoHardwareStop));
            false
        }
    }
}

/// Coefficients from flash: the newest valid slot, or none (identify and commissioning
/// only, a warning). A slot with a flash ECC error counts as invalid (`storage`). The slots
/// go to the serial link's uploads.
fn load_coefficients(
    flash: Peri<'static, peripherals::FLASH>,
) -> Option<(control::blob::Coefficients, u32)> {
    let slots = Slots::new(
        storage::EccFlash(Flash::new_blocking(flash)),
        link::SLOTS_OFFSET,
        link::SLOT_SIZE,
    );
    let loaded = match slots {
        Ok(mut s) => {
            let c = link::load_coefficients(&mut s);
            SLOTS.lock(|cell| *cell.borrow_mut() = Some(s));
            c
        }
        Err(_) => {
            defmt::error!("coefficient slots do not fit the flash: storage disabled");
            None
        }
    };
    if loaded.is_none() {
        let _ = OUTGOING.try_send(BoardMsg::Warning(Warning::NoCoefficients));
    }
    loaded
}

/// The serial link on the ST-LINK virtual COM port: USART2 RX PB4, TX PB3.
fn start_link(
    spawner: Spawner,
    usart: Peri<'static, peripherals::USART2>,
    rx: Peri<'static, peripherals::PB4>,
    tx: Peri<'static, peripherals::PB3>,
) {
    static TX_BUF: StaticCell<[u8; 512]> = StaticCell::new();
    static RX_BUF: StaticCell<[u8; 256]> = StaticCell::new();
    let mut ucfg = usart::Config::default();
    ucfg.baudrate = board::BAUD;
    let uart = BufferedUart::new(
        usart,
        rx,
        tx,
        TX_BUF.init([0; 512]),
        RX_BUF.init([0; 256]),
        Irqs,
        ucfg,
    );
    match uart {
        Ok(uart) => {
            let (tx, rx) = uart.split();
            // Each task is spawned once: its pool (size 1) cannot be exhausted.
            if let Ok(t) = link::tx_task(tx) {
                spawner.spawn(t);
            }
            if let Ok(t) = link::rx_task(rx) {
                spawner.spawn(t);
            }
        }
        _ => defmt::error!("serial link not started"),
    }
}

/// The loop's period and work, timed by the DWT cycle counter (170 MHz; it wraps after
/// 25 s, far beyond one period, so wrapping differences are exact).
struct LoopTimer {
    last_start: Option<u32>,
    start: u32,
    /// Cycles the previous period's work took.
    step_cycles: u32,
}

/// The timing of the period that starts ([`LoopTimer::begin`]).
struct Timing {
    period_us: f32,
    overrun: bool,
    step_cycles: u32,
}

impl LoopTimer {
    const CYCLES_PER_US: f32 = (board::SYSCLK_HZ / 1_000_000) as f32;
    const PERIOD_CYCLES: u32 = (control::CONTROL_PERIOD_S * board::SYSCLK_HZ as f32) as u32;

    fn start() -> Self {
        // SAFETY: only DCB and DWT are touched, and nothing else in the firmware uses them.
        let mut core = unsafe { cortex_m::Peripherals::steal() };
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();
        LoopTimer {
            last_start: None,
            start: 0,
            step_cycles: 0,
        }
    }

    /// A period starts: its length since the last start; more than one period late means
    /// the loop overran (the ticker catches up).
    fn begin(&mut self) -> Timing {
        let start = DWT::cycle_count();
        let period_cycles = self.last_start.map(|s| start.wrapping_sub(s));
        self.last_start = Some(start);
        self.start = start;
        Timing {
            period_us: period_cycles.map_or(f32::NAN, |c| c as f32 / Self::CYCLES_PER_US),
            overrun: period_cycles.is_some_and(|c| c > 2 * Self::PERIOD_CYCLES),
            step_cycles: self.step_cycles,
        }
    }

    /// The period's work is done.
    fn end(&mut self) {
        self.step_cycles = DWT::cycle_count().wrapping_sub(self.start);
    }
}

/// New coefficients (only committed in Idle), then the host's commands: the board logic
/// answers them. A cleared fault re-arms the hardware over-current stop (while a fault is
/// latched the bridge is off, so a break flag set meanwhile is stale).
fn take_host_messages(board: &mut Board, send: &mut impl FnMut(BoardMsg)) {
    if let Ok((c, seq)) = NEW_COEFFS.try_receive() {
        board.load(c, seq);
    }
    while let Ok(msg) = COMMANDS.try_receive() {
        let faulted = board.fault().is_some();
        board.handle(&msg, send);
        if faulted && board.fault().is_none() {
            bridge::rearm();
        }
    }
}

/// This period's measurements for the board logic.
fn measure(sense: &mut Sense, bridge: &Bridge, timing: Timing) -> Measurements {
    let r = sense.read(bridge);
    let (edges, edges_overflow, edges_lost) = hall_capture::take_edges();
    Measurements {
        hall: hall_capture::hall_state(),
        edges,
        edges_overflow,
        edges_lost,
        period_us: timing.period_us,
        step_cycles: timing.step_cycles,
        now_ticks: hall_capture::now_ticks(),
        i_vector: r.i_vector,
        v_bus: r.v_bus,
        overrun: timing.overrun,
        hw_overcurrent: bridge::hw_tripped(),
        temperature_c: r.temperature_c,
    }
}

/// A commissioning result to store, once the board is idle (the bridge is off: erasing
/// stalls the CPU).
fn store_if_idle(board: &mut Board, send: &mut impl FnMut(BoardMsg)) {
    if board.mode() == Mode::Idle {
        SLOTS.lock(|cell| {
            if let Some(slots) = cell.borrow_mut().as_mut() {
                store_coefficients(board, slots, send);
            }
        });
    }
}

/// Sets the drive; the Hall-edge interrupt commutates between samples.
fn actuate(bridge: &mut Bridge, drive: Drive, v_bus: f32) {
    // (volts, reverse, Hall table, held centre vector's low phase) of a drive that turns the
    // bridge on.
    let on = match drive {
        Drive::Off => None,
        Drive::SixStep { volts, table } => Some((volts, volts < 0.0, table.sector, None)),
        Drive::Centre { low, volts } => Some((volts, false, [-1; 8], Some(low))),
    };
    match on {
        None => bridge.off(),
        Some((volts, reverse, table, hold)) => {
            bridge::set_drive(bridge::Drive {
                on: true,
                reverse,
                duty: bridge.duty_counts(bridge::duty(volts, v_bus)),
                table,
                hold,
            });
            bridge::commutate();
        }
    }
}

/// The mode for the link task, the LED (on while the bridge is), and the telemetry report
/// of a completed second through defmt.
fn publish(board: &mut Board, bridge: &Bridge, led: &mut Output) {
    MODE.store(
        if board.mode() == Mode::Idle {
            link::MODE_IDLE
        } else {
            link::MODE_RUNNING
        },
        Ordering::Relaxed,
    );
    led.set_level(if bridge.is_on() {
        Level::High
    } else {
        Level::Low
    });
    if let Some(t) = board.take_report() {
        defmt::info!(
            "loop: period {=f32} us, jitter {=f32} us, overruns {=u32}, step cycles max {=u32}, Hall edges lost {=u32}",
            t.period_us,
            t.jitter_us,
            t.overruns,
            t.step_cycles_max,
            t.edges_lost
        );
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
    cortex_m::interrupt::disable();
    bridge::force_off();
    loop {
        cortex_m::asm::nop();
    }
}

/// Any exception or interrupt without a handler of its own (the NMI has one, `storage`):
/// bridge off, then wait for the watchdog.
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(_irqn: i16) -> ! {
    // No interrupt of higher priority may commutate again (TIM1's update interrupt sets MOE).
    cortex_m::interrupt::disable();
    bridge::force_off();
    loop {
        cortex_m::asm::nop();
    }
}
