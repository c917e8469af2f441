//! The analog measurements of one control period: bus voltage, board temperature (NTC) and
//! the current along the applied bridge vector, read by ADC1/ADC2 from the three op-amp
//! current-sense outputs, PA0 (bus divider) and PB14 (NTC).
use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::opamp::OpAmpOutput;
use embassy_stm32::peripherals::{ADC1, ADC2, OPAMP1, OPAMP2, OPAMP3, PA0, PB14};
use embassy_stm32::Peri;

use crate::board;
use crate::bridge::{self, Bridge};

/// Samples averaged for the zero-current offset of each op-amp at boot (bridge off).
const ZERO_SAMPLES: u32 = 64;
const ST_CURRENT: SampleTime = SampleTime::CYCLES24_5;
const ST_VBUS: SampleTime = SampleTime::CYCLES247_5;

/// What one period measured.
pub struct Readings {
    /// Bus voltage [V].
    pub v_bus: f32,
    /// Board temperature [°C].
    pub temperature_c: f32,
    /// Current along the applied vector [A] (0 with the bridge off).
    pub i_vector: f32,
}

/// The ADCs and their inputs, with the op-amps' zero-current offsets.
pub struct Sense<'d> {
    adc1: Adc<'d, ADC1>,
    adc2: Adc<'d, ADC2>,
    i_u: OpAmpOutput<'d, OPAMP1>,
    i_v: OpAmpOutput<'d, OPAMP2>,
    i_w: OpAmpOutput<'d, OPAMP3>,
    vbus: Peri<'d, PA0>,
    ntc: Peri<'d, PB14>,
    /// Raw ADC code of each op-amp at zero current.
    zero: [u16; 3],
}

impl<'d> Sense<'d> {
    /// The measurement chain; measures the zero-current offsets (call with the bridge off).
    pub fn new(
        adcs: (Adc<'d, ADC1>, Adc<'d, ADC2>),
        i_u: OpAmpOutput<'d, OPAMP1>,
        i_v: OpAmpOutput<'d, OPAMP2>,
        i_w: OpAmpOutput<'d, OPAMP3>,
        vbus: Peri<'d, PA0>,
        ntc: Peri<'d, PB14>,
    ) -> Self {
        let (adc1, adc2) = adcs;
        let mut s = Sense {
            adc1,
            adc2,
            i_u,
            i_v,
            i_w,
            vbus,
            ntc,
            zero: [0; 3],
        };
        let mut sum = [0u32; 3];
        for _ in 0..ZERO_SAMPLES {
            for (phase, acc) in sum.iter_mut().enumerate() {
                *acc += u32::from(s.read_phase(phase));
            }
        }
        s.zero = sum.map(|x| (x / ZERO_SAMPLES) as u16);
        s
    }

    /// Raw ADC code of phase `phase`'s current sense (0 = U, 1 = V, 2 = W).
    fn read_phase(&mut self, phase: usize) -> u16 {
        match phase {
            0 => self.adc1.blocking_read(&mut self.i_u, ST_CURRENT),
            1 => self.adc2.blocking_read(&mut self.i_v, ST_CURRENT),
            _ => self.adc1.blocking_read(&mut self.i_w, ST_CURRENT),
        }
    }

    /// This period's readings, with the bridge as it is now.
    pub fn read(&mut self, bridge: &Bridge) -> Readings {
        let v_bus = board::vbus_from_raw(self.adc1.blocking_read(&mut self.vbus, ST_VBUS));
        let temperature_c = board::ntc_celsius(self.adc1.blocking_read(&mut self.ntc, ST_VBUS));
        let lo = bridge::last_low();
        let raw = self.read_phase(lo);
        // The winding current leaves through the low phase's shunt: along the applied vector
        // it is −i_phase (ASSUMED sign convention; commissioning measures and stores the
        // sign, `Commissioning::current_sign`).
        let i_vector = if bridge.is_on() {
            -board::current_from_raw(raw, self.zero[lo])
        } else {
            0.0
        };
        Readings {
            v_bus,
            temperature_c,
            i_vector,
        }
    }
}
