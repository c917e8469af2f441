//! Hall commissioning: learn how the Hall sensors and the motor phases are wired.
//!
//! The bridge holds one of its six commutation vectors (bridge step `k`, two phases driven)
//! at a limited voltage; the rotor turns until it sits in the sector where that vector makes
//! no torque, and the Hall state read there is the state of sector `k`. Stepping `k` through
//! 0..5 forward twice (the first pass only aligns the rotor, from wherever it was) and then
//! backward once gives:
//! - the Hall table: state → sector, so that the sector numbers rise with the vector index,
//!   which makes [`crate::board::commutation_step`] (step = sector + 1 forward, + 4 reverse)
//!   drive the motor and the decoded angle count up for a positive voltage;
//! - the direction: whether the learned state sequence is the default 1-3-2-6-4-5 order
//!   forward or backward (`reversed`), or another order (a permuted Hall connector);
//! - a pole-pair check: the net Hall edges over one electrical revolution of the vector
//!   (the second forward pass; an edge back to the state before cancels the edge that left
//!   it, so a rotor that overshoots and settles back counts once) must be 6, or the Hall
//!   magnet's pole count differs from the motor's;
//! - the current-sense sign: with a positive voltage along the held vector the current
//!   along it is positive; a negative mean says the sense is inverted (`current_sign` −1);
//! - the winding resistance R = V/|Ī| [Ω] along a vector (two phases in series, the
//!   DC-equivalent motor's R), from the mean current of the holds' second halves, where
//!   the rotor rests (no back-EMF) and the current has settled (L/R is a few ms)
//!   ([`Commissioner::resistance`]).
//!
//! Each hold lasts [`HOLD_PERIODS`] control periods; the current is averaged over the
//! second half of every hold. The voltage is chosen by the caller (the board logic limits it
//! to a fraction of `u_max` and to the voltage that drives a fraction of `i_max` through R).
use serde::{Deserialize, Serialize};

use crate::hall::HallTable;

/// Control periods each vector is held (0.3 s at 12 ms).
pub const HOLD_PERIODS: u16 = 25;
/// Holds in a run: two forward passes and one backward pass.
pub const HOLDS: u8 = 18;

/// The default Hall state sequence of [`HallTable::DEFAULT_120`] (sectors 0..5).
pub const DEFAULT_SEQUENCE: [u8; 6] = [1, 3, 2, 6, 4, 5];

/// What a commissioning run learned (stored with the coefficients).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Commissioning {
    /// Hall state seen with bridge step `k` held, k = 0..5 (sector `k`'s state).
    pub sequence: [u8; 6],
    /// The sequence is the default 1-3-2-6-4-5 order backward (motor phases or Hall
    /// sensors wired for the other direction).
    pub reversed: bool,
    /// The sequence is neither the default order nor its reverse (a permuted Hall
    /// connector); the learned table covers it all the same.
    pub permuted: bool,
    /// Sign to apply to the measured current (+1 or −1).
    pub current_sign: i8,
    /// Hall edges over one electrical revolution of the vector (6 when the Hall magnet has
    /// the motor's pole pairs).
    pub edges_per_elec_rev: u8,
    /// Voltage the vectors were held at [V].
    pub volts: f32,
}

impl Commissioning {
    /// The learned Hall table (state → sector).
    pub fn hall_table(&self) -> Option<HallTable> {
        HallTable::from_sequence(self.sequence)
    }

    /// Plausible values: a valid, Gray-coded sequence, a sign of ±1, a finite voltage.
    pub fn is_valid(&self) -> bool {
        self.hall_table().is_some()
            && gray(&self.sequence)
            && (self.current_sign == 1 || self.current_sign == -1)
            && self.volts.is_finite()
            && self.volts >= 0.0
    }
}

/// Why a commissioning run failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum CommissionError {
    /// The Hall state did not change while the vector turned: the rotor is blocked, the
    /// voltage too low, or the Hall sensors are not connected.
    NoMotion,
    /// A Hall state 000 or 111 was read.
    InvalidState,
    /// The six vectors did not give six different states.
    NotSixStates,
    /// Neighbouring vectors gave states more than one sensor apart.
    NotAdjacent,
    /// The backward pass read other states than the forward pass.
    Inconsistent,
    /// The Hall edges over one electrical revolution were not 6 (pole pairs differ).
    PolePairs,
    /// Stopped before the end (a stop command or a fault).
    Aborted,
}

/// How the last commissioning run ended.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum CommissionOutcome {
    /// No run since power-up, and none stored.
    NotRun,
    /// A run is in progress.
    Running,
    /// Done (and stored with the coefficients, or from them).
    Done(Commissioning),
    /// Failed.
    Failed(CommissionError),
}

fn gray(seq: &[u8; 6]) -> bool {
    (0..6).all(|k| (seq[k] ^ seq[(k + 1) % 6]).count_ones() == 1)
}

/// The commissioning sequencer: which vector to hold, what was read.
#[derive(Debug, Clone, PartialEq)]
pub struct Commissioner {
    hold: u8,
    period: u16,
    fwd: [u8; 6],
    bwd: [u8; 6],
    /// Hall states passed in the counted revolution, returns cancelled.
    path: heapless::Vec<u8, 16>,
    /// The path overflowed (far more than one revolution).
    path_full: bool,
    i_sum: f32,
    /// Samples in `i_sum`.
    i_count: u16,
    volts: f32,
}

/// What the sequencer wants this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CommissionStep {
    /// Hold bridge step `step` at the run's voltage.
    Hold { step: u8, volts: f32 },
    /// Finished.
    Done(Result<Commissioning, CommissionError>),
}

impl Commissioner {
    /// A run at `volts` [V] along each vector.
    pub fn new(volts: f32) -> Self {
        Commissioner {
            hold: 0,
            period: 0,
            fwd: [0; 6],
            bwd: [0; 6],
            path: heapless::Vec::new(),
            path_full: false,
            i_sum: 0.0,
            i_count: 0,
            volts,
        }
    }

    /// Bridge step of hold `h`: 0..5, 0..5, then 5..0.
    fn step_of(h: u8) -> u8 {
        if h < 12 {
            h % 6
        } else {
            5 - (h - 12)
        }
    }

    /// Net Hall edges of the counted revolution.
    fn net_edges(&self) -> u16 {
        if self.path_full {
            u16::MAX
        } else {
            self.path.len().saturating_sub(1) as u16
        }
    }

    /// One control period: the Hall state now, the states entered at the Hall edges since
    /// the last period (oldest first; `overflow`: more came than were captured) and the
    /// current along the held vector [A] (sign as measured).
    pub fn tick(
        &mut self,
        hall: u8,
        edges: impl IntoIterator<Item = u8>,
        overflow: bool,
        i_vector: f32,
    ) -> CommissionStep {
        if self.hold >= HOLDS {
            return CommissionStep::Done(self.result());
        }
        if (6..12).contains(&self.hold) {
            // The second forward pass: one electrical revolution, from the state the first
            // pass ended in (the motion into sector 0 of the second pass counts).
            self.path_full |= overflow;
            for e in edges {
                let n = self.path.len();
                if n >= 2 && self.path[n - 2] == e {
                    self.path.pop();
                } else if self.path.push(e).is_err() {
                    self.path_full = true;
                }
            }
        }
        if self.period >= HOLD_PERIODS / 2 && i_vector.is_finite() {
            self.i_sum += i_vector;
            self.i_count = self.i_count.saturating_add(1);
        }
        self.period += 1;
        if self.period > HOLD_PERIODS {
            // The hold is over: the state now is that vector's sector.
            let k = Self::step_of(self.hold) as usize;
            match self.hold {
                5 => {
                    // The counted revolution starts here.
                    self.path.clear();
                    let _ = self.path.push(hall);
                }
                6..=11 => self.fwd[k] = hall,
                12.. => self.bwd[k] = hall,
                _ => {}
            }
            self.hold += 1;
            self.period = 0;
            if self.hold >= HOLDS {
                return CommissionStep::Done(self.result());
            }
        }
        CommissionStep::Hold {
            step: Self::step_of(self.hold),
            volts: self.volts,
        }
    }

    /// The winding resistance [Ω] from the holds so far: the hold voltage over the mean
    /// current of the holds' second halves; `None` without samples or outside the physical
    /// range [`crate::blob::MOTOR_R`].
    pub fn resistance(&self) -> Option<f32> {
        if self.i_count == 0 {
            return None;
        }
        let r = self.volts / (self.i_sum / f32::from(self.i_count)).abs();
        let (lo, hi) = crate::blob::MOTOR_R;
        (r >= lo && r <= hi).then_some(r)
    }

    fn result(&self) -> Result<Commissioning, CommissionError> {
        let seq = self.fwd;
        if seq.iter().any(|&s| s == 0 || s >= 7) {
            return Err(CommissionError::InvalidState);
        }
        if seq.iter().all(|&s| s == seq[0]) {
            return Err(CommissionError::NoMotion);
        }
        if HallTable::from_sequence(seq).is_none() {
            return Err(CommissionError::NotSixStates);
        }
        if !gray(&seq) {
            return Err(CommissionError::NotAdjacent);
        }
        if self.bwd != seq {
            return Err(CommissionError::Inconsistent);
        }
        if self.net_edges() != 6 {
            return Err(CommissionError::PolePairs);
        }
        let rot = |s: &[u8; 6]| (0..6).any(|o| (0..6).all(|k| seq[k] == s[(k + o) % 6]));
        let mut rev = DEFAULT_SEQUENCE;
        rev.reverse();
        let forward = rot(&DEFAULT_SEQUENCE);
        let reversed = rot(&rev);
        Ok(Commissioning {
            sequence: seq,
            reversed,
            permuted: !forward && !reversed,
            current_sign: if self.i_sum < 0.0 { -1 } else { 1 },
            edges_per_elec_rev: self.net_edges().min(255) as u8,
            volts: self.volts,
        })
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// An ideal rotor that jumps into the held vector's sector; Hall states of a given
    /// sequence; current of a given sign.
    fn run(seq: [u8; 6], sign: f32, start: u8) -> Result<Commissioning, CommissionError> {
        let mut c = Commissioner::new(2.0);
        let mut sector = start;
        let mut hall = seq[sector as usize];
        // Edges arrive with the next period's measurement.
        let mut edges: std::vec::Vec<u8> = std::vec::Vec::new();
        for _ in 0..10_000 {
            match c.tick(hall, edges.drain(..), false, sign * 5.0) {
                CommissionStep::Done(r) => return r,
                CommissionStep::Hold { step, .. } => {
                    // The rotor turns the short way into the vector's sector, overshooting
                    // by one sector and back.
                    let start = sector;
                    while sector != step {
                        let up = (step + 6 - sector) % 6 <= 3;
                        sector = if up {
                            (sector + 1) % 6
                        } else {
                            (sector + 5) % 6
                        };
                        edges.push(seq[sector as usize]);
                    }
                    if start != step {
                        let up = (step + 6 - start) % 6 <= 3;
                        let over = if up { (step + 1) % 6 } else { (step + 5) % 6 };
                        edges.push(seq[over as usize]);
                        edges.push(seq[step as usize]);
                    }
                    hall = seq[sector as usize];
                }
            }
        }
        panic!("never finished");
    }

    #[test]
    fn learns_default_reversed_and_permuted_sequences() {
        let r = run(DEFAULT_SEQUENCE, 1.0, 3).unwrap();
        assert_eq!(r.sequence, DEFAULT_SEQUENCE);
        assert!(!r.reversed && !r.permuted);
        assert_eq!(r.current_sign, 1);
        assert_eq!(r.hall_table(), Some(HallTable::DEFAULT_120));
        let mut rev = DEFAULT_SEQUENCE;
        rev.reverse();
        let r = run(rev, -1.0, 0).unwrap();
        assert!(r.reversed);
        assert_eq!(r.current_sign, -1);
        // Hall bits A and B swapped.
        let sw = DEFAULT_SEQUENCE.map(|s| (s & 4) | ((s & 1) << 1) | ((s >> 1) & 1));
        let r = run(sw, 1.0, 5).unwrap();
        assert_eq!(r.sequence, sw);
        assert!(r.is_valid());
    }

    #[test]
    fn a_blocked_rotor_is_no_motion() {
        let mut c = Commissioner::new(2.0);
        let r = loop {
            if let CommissionStep::Done(r) = c.tick(1, [], false, 1.0) {
                break r;
            }
        };
        assert_eq!(r, Err(CommissionError::NoMotion));
    }
}
