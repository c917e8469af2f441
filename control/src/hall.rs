//! Hall-sensor decoding: 3-bit state → sector, direction of each transition, faults, angle.
//!
//! Three Hall sensors 120° (electrical) apart give six valid states per electrical period; each
//! transition is one *electrical step* of 60°, i.e. `2π/(6·pole_pairs)` mechanical radians
//! (0.0952 rad for the paper's 11 pole pairs, its angle resolution). The states 000 and 111
//! cannot occur with healthy 120° sensors, and a transition to a non-adjacent sector means a
//! missed edge or noise: both are faults.
use num_traits::Float;
use serde::{Deserialize, Serialize};

/// Pole pairs of the paper's motor (its Hall resolution 0.0952 rad = 2π/(6·11)).
pub const PAPER_POLE_PAIRS: u16 = 11;

/// Marks a state that maps to no sector in a [`HallTable`].
pub const INVALID: i8 = -1;

/// Map from the 3-bit Hall state (bit 0 = sensor A, bit 1 = B, bit 2 = C) to the sector
/// 0..5 in the forward direction of rotation, or [`INVALID`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct HallTable {
    pub sector: [i8; 8],
}

impl Default for HallTable {
    fn default() -> Self {
        HallTable::DEFAULT_120
    }
}

impl HallTable {
    /// Sensors 120° apart, forward sequence of states 001, 011, 010, 110, 100, 101 (1, 3, 2,
    /// 6, 4, 5), the usual wiring of three-phase BLDC motors.
    pub const DEFAULT_120: HallTable = HallTable {
        sector: [INVALID, 0, 2, 1, 4, 5, 3, INVALID],
    };

    /// Table from the six states in forward order; `None` unless they are six distinct
    /// values in 1..=6.
    pub fn from_sequence(states: [u8; 6]) -> Option<HallTable> {
        let mut sector = [INVALID; 8];
        for (k, &s) in states.iter().enumerate() {
            if s == 0 || s >= 7 || sector[s as usize] != INVALID {
                return None;
            }
            sector[s as usize] = k as i8;
        }
        Some(HallTable { sector })
    }

    /// Sector of a state, `None` for an invalid state.
    pub fn sector_of(&self, state: u8) -> Option<u8> {
        match self.sector.get(state as usize) {
            Some(&s) if (0..6).contains(&s) => Some(s as u8),
            _ => None,
        }
    }

    /// Hall state of a sector (first state that maps to it).
    pub fn state_of(&self, sector: u8) -> Option<u8> {
        self.sector
            .iter()
            .position(|&s| s >= 0 && s as u8 == sector % 6)
            .map(|p| p as u8)
    }

    /// True when the six sectors each have exactly one state.
    pub fn is_valid(&self) -> bool {
        (0..6u8).all(|k| {
            self.sector
                .iter()
                .filter(|&&s| s >= 0 && s as u8 == k)
                .count()
                == 1
        }) && self.sector.iter().all(|&s| (INVALID..6).contains(&s))
    }
}

/// A Hall fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum HallFault {
    /// The state maps to no sector (000 or 111 with 120° sensors).
    InvalidState,
    /// The new sector is not adjacent to the previous one (a missed edge or noise).
    ImpossibleJump,
}

/// Result of one decoded Hall state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HallUpdate {
    /// Current sector, `None` until a valid state has been seen.
    pub sector: Option<u8>,
    /// +1 forward, −1 backward, 0 no (counted) move.
    pub dir: i8,
    pub fault: Option<HallFault>,
}

/// Electrical step angle [rad] (mechanical): `2π/(6·pole_pairs)`.
pub fn step_angle<F: Float>(pole_pairs: u16) -> F {
    let pp = F::from(pole_pairs.max(1)).unwrap();
    F::from(core::f64::consts::TAU).unwrap() / (F::from(6.0).unwrap() * pp)
}

/// Counts electrical steps from a stream of Hall states.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HallDecoder {
    pub table: HallTable,
    pub pole_pairs: u16,
    last: Option<u8>,
    steps: i32,
    faults: u32,
}

impl HallDecoder {
    pub fn new(table: HallTable, pole_pairs: u16) -> Self {
        HallDecoder {
            table,
            pole_pairs,
            last: None,
            steps: 0,
            faults: 0,
        }
    }

    /// Forget the position (the next valid state restarts the count).
    pub fn reset(&mut self) {
        self.last = None;
        self.steps = 0;
    }

    /// Restart the count where the first valid state would set it (its sector), keeping
    /// the present sector, so that the next edge is counted.
    pub fn restart_count(&mut self) {
        self.steps = self.last.map_or(0, i32::from);
    }

    /// Decode one Hall state. The first valid state sets the step count to its sector, so
    /// that the angle is the true angle rounded to the nearest step when the rotor starts in
    /// its first electrical period, [−step/2, 6·step − step/2) (see [`hall_state_for_angle`]). An invalid state leaves everything
    /// unchanged; an impossible jump re-synchronises to the new sector without counting.
    pub fn update(&mut self, state: u8) -> HallUpdate {
        let Some(sector) = self.table.sector_of(state) else {
            self.faults = self.faults.saturating_add(1);
            return HallUpdate {
                sector: self.last,
                dir: 0,
                fault: Some(HallFault::InvalidState),
            };
        };
        let Some(last) = self.last else {
            self.last = Some(sector);
            self.steps = sector as i32;
            return HallUpdate {
                sector: Some(sector),
                dir: 0,
                fault: None,
            };
        };
        self.last = Some(sector);
        let (dir, fault) = match (sector + 6 - last) % 6 {
            0 => (0, None),
            1 => (1, None),
            5 => (-1, None),
            _ => (0, Some(HallFault::ImpossibleJump)),
        };
        self.steps = self.steps.wrapping_add(dir as i32);
        if fault.is_some() {
            self.faults = self.faults.saturating_add(1);
        }
        HallUpdate {
            sector: Some(sector),
            dir,
            fault,
        }
    }

    /// Electrical steps counted (signed).
    pub fn steps(&self) -> i32 {
        self.steps
    }

    /// Faults seen since construction.
    pub fn fault_count(&self) -> u32 {
        self.faults
    }

    /// Current sector, `None` before the first valid state.
    pub fn sector(&self) -> Option<u8> {
        self.last
    }

    /// Mechanical angle [rad] = steps·2π/(6·pole_pairs).
    pub fn angle<F: Float>(&self) -> F {
        F::from(self.steps).unwrap() * step_angle::<F>(self.pole_pairs)
    }

    /// Hall steps per mechanical revolution, 6·pole_pairs.
    pub fn steps_per_rev(&self) -> i32 {
        6 * self.pole_pairs.max(1) as i32
    }

    /// Mechanical angle within one revolution, [0, 2π), computed from the integer step count
    /// (exact in f32 however far the rotor has turned).
    pub fn angle_in_rev<F: Float>(&self) -> F {
        F::from(self.steps.rem_euclid(self.steps_per_rev())).unwrap()
            * step_angle::<F>(self.pole_pairs)
    }
}

/// The Hall state a motor at mechanical angle `theta` shows (inverse of the decoder, used by
/// the emulator). The sensors are taken as mounted half a step ahead of the rotor's zero, so
/// sector = floor((θ + step/2)/step) mod 6 and the decoded angle is θ rounded to the nearest
/// step (quantisation error within ±step/2, zero mean). Returns 0 (an invalid state) if the
/// table lacks the sector or θ is not finite.
pub fn hall_state_for_angle<F: Float>(theta: F, pole_pairs: u16, table: &HallTable) -> u8 {
    if !theta.is_finite() {
        return 0;
    }
    let half = F::from(0.5).unwrap();
    let k = (theta / step_angle::<F>(pole_pairs) + half).floor();
    let six = F::from(6.0).unwrap();
    let sector = k - (k / six).floor() * six;
    let sector = sector.to_u8().unwrap_or(0).min(5);
    table.state_of(sector).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    #[test]
    fn paper_resolution() {
        let s: f64 = step_angle(PAPER_POLE_PAIRS);
        // 5e-5: half the last digit of 0.0952, the step written to four digits.
        assert!((s - 0.0952).abs() < 5e-5);
    }

    #[test]
    fn default_table_is_valid_and_matches_sequence() {
        assert!(HallTable::DEFAULT_120.is_valid());
        assert_eq!(
            HallTable::from_sequence([1, 3, 2, 6, 4, 5]),
            Some(HallTable::DEFAULT_120)
        );
        assert_eq!(HallTable::from_sequence([1, 3, 2, 6, 4, 4]), None);
        assert_eq!(HallTable::from_sequence([0, 3, 2, 6, 4, 5]), None);
        // Adjacent states differ in exactly one bit (Gray sequence).
        for k in 0..6u8 {
            let a = HallTable::DEFAULT_120.state_of(k).unwrap();
            let b = HallTable::DEFAULT_120.state_of((k + 1) % 6).unwrap();
            assert_eq!((a ^ b).count_ones(), 1);
        }
    }

    #[test]
    fn counts_forward_and_backward() {
        let t = HallTable::DEFAULT_120;
        let mut d = HallDecoder::new(t, 11);
        let seq = [1u8, 3, 2, 6, 4, 5, 1, 3];
        d.update(seq[0]);
        for s in &seq[1..] {
            let u = d.update(*s);
            assert_eq!(u.dir, 1);
            assert_eq!(u.fault, None);
        }
        assert_eq!(d.steps(), 7);
        for s in seq.iter().rev().skip(1) {
            assert_eq!(d.update(*s).dir, -1);
        }
        assert_eq!(d.steps(), 0);
        // Repeating a state is no move.
        assert_eq!(d.update(1).dir, 0);
    }

    #[test]
    fn faults_detected() {
        let mut d = HallDecoder::new(HallTable::DEFAULT_120, 11);
        d.update(1);
        for bad in [0u8, 7] {
            let u = d.update(bad);
            assert_eq!(u.fault, Some(HallFault::InvalidState));
            assert_eq!(u.sector, Some(0));
        }
        assert_eq!(d.steps(), 0);
        // 1 (sector 0) → 6 (sector 3): not adjacent.
        let u = d.update(6);
        assert_eq!(u.fault, Some(HallFault::ImpossibleJump));
        assert_eq!(u.dir, 0);
        assert_eq!(d.steps(), 0);
        assert_eq!(d.fault_count(), 3);
        // Re-synchronised: 6 → 4 is a forward step.
        assert_eq!(d.update(4).dir, 1);
    }

    #[test]
    fn inverse_round_trip() {
        let t = HallTable::DEFAULT_120;
        let pp = 11;
        let step: f64 = step_angle(pp);
        let mut d = HallDecoder::new(t, pp);
        // Sweep forward then backward with a fine step; the decoder's angle is θ rounded to
        // the nearest step.
        let mut th = 0.01;
        let mut k = 0;
        while k < 4000 {
            let theta = if k < 2000 {
                th
            } else {
                th - (k - 2000) as f64 * 2e-3
            };
            let u = d.update(hall_state_for_angle(theta, pp, &t));
            assert_eq!(u.fault, None);
            let want = (theta / step).round() * step;
            assert!((d.angle::<f64>() - want).abs() < 1e-9, "θ={theta}");
            if k < 2000 {
                th += 2e-3;
            }
            k += 1;
        }
        assert_eq!(hall_state_for_angle(f64::NAN, pp, &t), 0);
        assert_eq!(hall_state_for_angle(-1e-3, pp, &t), t.state_of(0).unwrap());
        assert_eq!(
            hall_state_for_angle(-0.51 * step, pp, &t),
            t.state_of(5).unwrap()
        );
    }
}
