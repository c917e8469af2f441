//! Hall edges time-stamped by TIM4 input capture.
//!
//! TIM4 runs free at 1 MHz ([`TICK_HZ`], 170 MHz / 170). Its "XOR" input (TI1S = 1: TI1 is
//! H1 ⊕ H2 ⊕ H3, RM0440 "Interfacing with Hall sensors") toggles on every Hall edge, and
//! channel 1 captures the counter on both edges. The TIM4 interrupt extends the 16-bit count
//! to 32 bits with the overflow count, reads the Hall state from GPIOB and queues
//! `(ticks, state)`; the control task takes the queue every 12 ms and hands it to
//! `control::step` (which decodes and counts the edges and runs the edge-timing estimator),
//! and commutates the bridge for the new Hall state (`bridge::commutate`, applied at the
//! next PWM update). The queue holds `control::step::MAX_EDGES` edges, one period at the
//! rated speed with margin; edges beyond are counted ([`take_edges`]) and reported in the
//! telemetry.
//! An input filter of 8 samples at f_DTS/8 rejects switching noise shorter than ≈ 0.4 µs.
//!
//! Register access goes through the PAC (`unstable-pac`): embassy-stm32 0.6 has no
//! XOR/Hall-interface capture driver.
use core::cell::RefCell;

use control::step::{HallEdge, MAX_EDGES};
use critical_section::Mutex;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals;

use crate::board::{HALL_SHIFT, SYSCLK_HZ};

/// Capture timer rate [Hz] (`control::blob::Coefficients::CAPTURE_TICK_HZ`).
pub const TICK_HZ: u32 = 1_000_000;

struct Queue {
    /// Upper 16 bits of the 32-bit time.
    high: u32,
    edges: heapless::Vec<HallEdge, MAX_EDGES>,
    overflow: bool,
    /// Edges dropped since boot because the queue was full (`MAX_EDGES` in one period).
    lost: u32,
}

static QUEUE: Mutex<RefCell<Queue>> = Mutex::new(RefCell::new(Queue {
    high: 0,
    edges: heapless::Vec::new(),
    overflow: false,
    lost: 0,
}));

/// Present Hall state: bit 0 = H1 (PB6), bit 1 = H2 (PB7), bit 2 = H3 (PB8).
pub fn hall_state() -> u8 {
    ((pac::GPIOB.idr().read().0 >> HALL_SHIFT) & 0b111) as u8
}

/// Configures PB6/PB7/PB8 as TIM4_CH1..3 inputs (AF2, pull-up) and starts TIM4.
///
/// Takes the pins to prove nobody else uses them.
pub fn start(
    _tim: embassy_stm32::Peri<'static, embassy_stm32::peripherals::TIM4>,
    _h1: embassy_stm32::Peri<'static, embassy_stm32::peripherals::PB6>,
    _h2: embassy_stm32::Peri<'static, embassy_stm32::peripherals::PB7>,
    _h3: embassy_stm32::Peri<'static, embassy_stm32::peripherals::PB8>,
) {
    use pac::gpio::vals::{Moder, Pupdr};
    // GPIOB clock is on (embassy enables all GPIO clocks at init).
    let gpio = pac::GPIOB;
    for pin in 6..=8usize {
        gpio.pupdr().modify(|w| w.set_pupdr(pin, Pupdr::PULL_UP));
        // AF2 = TIM4 on PB6/PB7/PB8 (STM32G431 datasheet DS12589, alternate function table).
        gpio.afr(pin / 8).modify(|w| w.set_afr(pin % 8, 2));
        gpio.moder().modify(|w| w.set_moder(pin, Moder::ALTERNATE));
    }

    pac::RCC.apb1enr1().modify(|w| w.set_tim4en(true));
    let t = pac::TIM4;
    t.cr1().modify(|w| {
        w.set_cen(false);
        w.set_urs(vals::Urs::COUNTER_ONLY);
    });
    t.psc().write_value((SYSCLK_HZ / TICK_HZ - 1) as u16);
    t.arr().write(|w| w.set_arr(0xFFFF));
    t.cr2().modify(|w| w.set_ti1s(vals::Ti1s::XOR));
    // CC1 as input on TI1 (CC1S = 01), filter N = 8 at f_DTS/8 (ICF = 1001 binary).
    t.ccmr_input(0).modify(|w| {
        w.set_ccs(0, vals::CcmrInputCcs::from_bits(0b01));
        w.set_icf(0, vals::FilterValue::FDTS_DIV8_N8);
    });
    // Both edges: CC1P = 1, CC1NP = 1.
    t.ccer().modify(|w| {
        w.set_ccp(0, true);
        w.set_ccnp(0, true);
        w.set_cce(0, true);
    });
    t.egr().write(|w| w.set_ug(true));
    t.sr().write_value(pac::timer::regs::SrGp16(0));
    t.dier().modify(|w| {
        w.set_uie(true);
        w.set_ccie(0, true);
    });
    t.cr1().modify(|w| w.set_cen(true));

    interrupt::TIM4.set_priority(interrupt::Priority::P1);
    // SAFETY: the handler below only touches TIM4, GPIOB input and the critical-section queue.
    unsafe { interrupt::TIM4.enable() };
}

/// 32-bit time from the overflow count and a 16-bit value read while `uif` may be pending.
fn extend(high: u32, low: u16, uif_pending: bool) -> u32 {
    // An overflow not yet counted belongs before `low` when `low` is small.
    let high = if uif_pending && low < 0x8000 {
        high + 1
    } else {
        high
    };
    (high << 16) | low as u32
}

/// Capture-timer time now (same clock as the edges).
pub fn now_ticks() -> u32 {
    critical_section::with(|cs| {
        let q = QUEUE.borrow_ref(cs);
        let t = pac::TIM4;
        let low = t.cnt().read().cnt();
        let uif = t.sr().read().uif();
        extend(q.high, low, uif)
    })
}

/// Takes the edges captured since the last call, whether some were lost since, and how
/// many were lost since boot.
pub fn take_edges() -> (heapless::Vec<HallEdge, MAX_EDGES>, bool, u32) {
    critical_section::with(|cs| {
        let mut q = QUEUE.borrow_ref_mut(cs);
        let edges = core::mem::take(&mut q.edges);
        let overflow = core::mem::replace(&mut q.overflow, false);
        (edges, overflow, q.lost)
    })
}

#[interrupt]
fn TIM4() {
    let t = pac::TIM4;
    let sr = t.sr().read();
    critical_section::with(|cs| {
        let mut q = QUEUE.borrow_ref_mut(cs);
        if sr.ccif(0) {
            // Reading CCR1 clears CC1IF.
            let low = t.ccr(0).read().ccr();
            let ticks = extend(q.high, low, sr.uif());
            let state = hall_state();
            // Commutate at the next PWM update: the next phase pair for the new sector.
            crate::bridge::commutate();
            let edge = HallEdge { ticks, state };
            if q.edges.push(edge).is_err() {
                q.overflow = true;
                q.lost = q.lost.saturating_add(1);
            }
        }
        if sr.uif() {
            clear_update_flag();
            q.high = q.high.wrapping_add(1);
        }
    });
}

/// Clears TIM4's update (overflow) flag alone. TIM4_SR's flags are cleared by writing 0 and
/// kept by writing 1; a read-modify-write would clear a capture flag set between its read
/// and its write, and that Hall edge would be lost.
fn clear_update_flag() {
    let mut v = pac::timer::regs::SrGp16(0);
    for n in 0..4 {
        v.set_ccif(n, true);
        v.set_ccof(n, true);
    }
    v.set_tif(true);
    v.set_idxif(true);
    v.set_dirif(true);
    v.set_ierrif(true);
    v.set_terrif(true);
    pac::TIM4.sr().write_value(v);
}
