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
//! - that the current sense sees the current at all ([`CommissionError::NoCurrent`]): the
//!   mean current at the higher level `Ī_hi` must reach a quarter of what the blob's R
//!   lets flow, `|Ī_hi| ≥ ¼·min(i_limit, (V_hi − V_d)/R_blob)`, and the two levels' currents
//!   must differ by a quarter of it, `|Ī_hi − Ī_lo| ≥ ¼·|Ī_hi|` (they differ by a half
//!   when the sense works). The quarter admits a winding of up to four times the blob's R
//!   (a first spin runs on the default R) and a dead-time estimate off by half the drop,
//!   while a dead sense (its offset and noise, tens of mA against amperes) or a hold
//!   voltage at or below the drop fails: neither a sign nor an R is taken from noise;
//! - the winding resistance R [Ω] along a vector (two phases in series, the DC-equivalent
//!   motor's R) from two voltage levels held while the rotor rests (no back-EMF) and the
//!   current has settled (L/R is a few ms): `R = (V_hi − V_lo)/(Ī_hi − Ī_lo)`. The bridge's
//!   dead time takes a constant voltage from a current of one sign (`t_d·f_PWM·V_bus`: in
//!   six-step only the high leg switches; about 0.24 V at 500 ns, 20 kHz and 24 V), and the
//!   difference cancels it, as it does the current sense's offset
//!   ([`Commissioner::resistance`]).
//!
//! Each hold lasts [`HOLD_PERIODS`] control periods: the first half at the run's voltage
//! `V_hi` (the rotor turns and settles), then a quarter at the lower level
//! `V_lo = V_d + `[`LOW_LEVEL`]`·(V_hi − V_d)` and the last quarter at `V_hi` again (the Hall
//! state is read at the end, under full torque); the current is averaged over each of the
//! two quarters but their first two periods (it settles with the winding's L/R, up to 15 ms). `V_d` is the dead time's drop the caller expects: placing the lower level
//! above it keeps its current at about half the higher level's, of the same sign, where the
//! drop is constant; an error of `V_d` moves that current, not R.
//!
//! The voltage is chosen by the caller (the board logic limits it to a fraction of `u_max`
//! and to the voltage that drives a fraction of `i_max` through the blob's R, which may not
//! be the motor's); the measured current then bounds it:
//! - the first hold starts at [`RAMP_START`] of the way from `V_d/2` to `V_hi` and grows by
//!   [`RAMP_GROWTH`] a period, so the current approaches the limit from below whatever the
//!   winding's R and even when the drop `V_d` is overestimated twofold (starting at `V_d`
//!   itself would drive `(V_d − V_d,true)/R` at once: 12 A through 20 mΩ); once the current
//!   passes [`RAMP_NEAR`] of the limit the growth slows to [`RAMP_GROWTH_NEAR`] and the voltage goes
//!   no further than the one extrapolated to drive [`RAMP_TARGET`] of the limit,
//!   `V_d + (V − V_d)·RAMP_TARGET·i_limit/|I|`, where the ramp ends;
//! - whenever `|I|` exceeds the run's current limit `i_limit`, `V_hi` falls to the voltage
//!   that drives the limit, `V_d + (V − V_d)·i_limit/|I|` for the voltage `V` that drove
//!   `I` (the current at rest is `(V − V_d)/R`), and stays there for the rest of the run.
use serde::{Deserialize, Serialize};

use crate::hall::HallTable;

/// Control periods each vector is held (0.3 s at 12 ms).
pub const HOLD_PERIODS: u16 = 25;
/// Smallest share of the expected current the higher level's mean must reach, and of that
/// mean the two levels' difference must reach ([`CommissionError::NoCurrent`], module docs).
pub const CURRENT_SHARE: f32 = 0.25;
/// Holds in a run: two forward passes and one backward pass.
pub const HOLDS: u8 = 18;
/// The lower of a hold's two voltage levels, as a fraction of the higher above the dead
/// time's drop: the current's difference between them is half the higher level's, enough
/// against the sense's noise, and the lower level's current keeps its sign.
pub const LOW_LEVEL: f32 = 0.5;
/// Where the first hold's voltage starts, as a fraction of the way from half the dead time's
/// drop to the run's voltage.
pub const RAMP_START: f32 = 1.0 / 16.0;
/// Growth of the first hold's voltage above half the dead time's drop per period, while the
/// current is below [`RAMP_NEAR`] of the limit.
pub const RAMP_GROWTH: f32 = 1.25;
/// Share of the limit the current passes where the ramp slows to [`RAMP_GROWTH_NEAR`].
pub const RAMP_NEAR: f32 = 0.25;
/// Growth per period once the current has passed [`RAMP_NEAR`] of the limit: the last
/// steps towards the limit are small against the winding's L/R lag (15 ms at 0.3 mH and
/// 20 mΩ).
pub const RAMP_GROWTH_NEAR: f32 = 1.05;
/// Where the ramp ends: at the voltage extrapolated to drive this fraction of the limit (the
/// current measured at a period's end still lags the voltage by `e^(−T·R/L)` of its last
/// step when L/R is long).
pub const RAMP_TARGET: f32 = 0.9;

/// The default Hall state sequence of [`HallTable::DEFAULT_120`] (sectors 0..5).
pub const DEFAULT_SEQUENCE: [u8; 6] = [1, 3, 2, 6, 4, 5];

/// What a commissioning run learned (stored with the coefficients).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Commissioning {
    /// Hall state seen with bridge step `k` held, k = 0..5 (sector `k`'s state).
    #[serde(with = "crate::serde_array")]
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
    /// The measured current was far below what the voltage drives through the blob's R, or
    /// did not follow the voltage level: the current sense does not work (or the winding's
    /// R is over four times the blob's, or the hold voltage does not exceed the dead
    /// time's drop). Neither a current sign nor an R is stored.
    NoCurrent,
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

/// Mean of the current samples at one voltage level.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct LevelMean {
    /// Sum of the held voltages [V].
    v_sum: f32,
    /// Sum of the currents [A] (sign as measured).
    i_sum: f32,
    n: u16,
}

impl LevelMean {
    fn add(&mut self, v: f32, i: f32) {
        self.v_sum += v;
        self.i_sum += i;
        self.n = self.n.saturating_add(1);
    }

    /// (mean voltage, mean current) [V, A] (the current's sign as measured).
    fn mean(&self) -> Option<(f32, f32)> {
        (self.n > 0).then(|| {
            let n = f32::from(self.n);
            (self.v_sum / n, self.i_sum / n)
        })
    }
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
    /// Current samples at the higher and the lower level.
    hi: LevelMean,
    lo: LevelMean,
    /// The higher level [V] (lowered by the current limit).
    volts: f32,
    /// Current limit of the run [A].
    i_limit: f32,
    /// Voltage the bridge's dead time is expected to take [V].
    v_dead: f32,
    /// The blob's winding resistance [Ω] (what the current is expected from).
    r_model: f32,
    /// Fraction of the way from `v_dead/2` to `volts` the ramp has reached (1: done).
    ramp: f32,
    /// The current has passed [`RAMP_NEAR`] of the limit (the ramp slows).
    near: bool,
    /// The drive returned last period: its voltage, and the level its current samples
    /// (`None`: not sampled).
    last: (f32, Option<bool>),
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
    /// A run at `volts` [V] along each vector, at most `i_limit` [A] (non-finite or not
    /// positive: no current limit), on a bridge whose dead time takes `v_dead` [V] (below 0
    /// or not finite: 0), on a winding the blob gives `r_model` [Ω] (the expected current).
    pub fn new(volts: f32, i_limit: f32, v_dead: f32, r_model: f32) -> Self {
        Commissioner {
            hold: 0,
            // The first tick makes it 0.
            period: u16::MAX,
            fwd: [0; 6],
            bwd: [0; 6],
            path: heapless::Vec::new(),
            path_full: false,
            hi: LevelMean::default(),
            lo: LevelMean::default(),
            volts,
            i_limit: if i_limit > 0.0 {
                i_limit
            } else {
                f32::INFINITY
            },
            v_dead: if v_dead > 0.0 && v_dead.is_finite() {
                v_dead
            } else {
                0.0
            },
            r_model,
            ramp: RAMP_START,
            near: false,
            last: (0.0, None),
        }
    }

    /// The voltage a fraction `x` of the way from `base` [V] to `v_hi` [V] (from 0 when
    /// `v_hi` is not above `base`).
    fn above(base: f32, v_hi: f32, x: f32) -> f32 {
        if v_hi > base {
            base + x * (v_hi - base)
        } else {
            x * v_hi
        }
    }

    /// The voltage a fraction `x` of the way from the dead time's drop to `v_hi` [V].
    fn above_drop(&self, v_hi: f32, x: f32) -> f32 {
        Self::above(self.v_dead, v_hi, x)
    }

    /// The higher voltage level now [V] (the run's voltage, lowered by the current limit).
    pub fn volts(&self) -> f32 {
        self.volts
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
        // The first period's current was driven before the run (another run's drive, a
        // rotor still turning): it is neither a sample of a level nor a bound on the voltage.
        let i_vector = if self.hold == 0 && self.period == u16::MAX {
            f32::NAN
        } else {
            i_vector
        };
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
        self.measured(i_vector);
        self.period = self.period.wrapping_add(1);
        if self.period >= HOLD_PERIODS {
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
        // Settle, then a quarter at the lower level and a quarter at the higher one.
        let level = match self.period {
            p if p < HOLD_PERIODS / 2 => None,
            p if p < 3 * HOLD_PERIODS / 4 => Some(false),
            _ => Some(true),
        };
        self.near |= i_vector.is_finite() && i_vector.abs() > RAMP_NEAR * self.i_limit;
        let near = self.near;
        let v_hi = if self.ramp < 1.0 {
            let v = Self::above(0.5 * self.v_dead, self.volts, self.ramp);
            // Near the limit, no further than the voltage extrapolated to drive it.
            let cap = self.above_drop(self.last.0, RAMP_TARGET * self.i_limit / i_vector.abs());
            if near && i_vector.abs() > 0.0 && cap < v {
                // The ramp ends there.
                self.volts = cap;
                self.ramp = 1.0;
                cap
            } else {
                v
            }
        } else {
            self.volts
        };
        let growth = if near { RAMP_GROWTH_NEAR } else { RAMP_GROWTH };
        self.ramp = (self.ramp * growth).min(1.0);
        let volts = if level == Some(false) {
            self.above_drop(v_hi, LOW_LEVEL)
        } else {
            v_hi
        };
        // The first two periods at each level are not sampled: the current settles with L/R.
        let p = self.period;
        let settled = !(HOLD_PERIODS / 2..HOLD_PERIODS / 2 + 2).contains(&p)
            && !(3 * HOLD_PERIODS / 4..3 * HOLD_PERIODS / 4 + 2).contains(&p);
        self.last = (volts, level.filter(|_| settled));
        CommissionStep::Hold {
            step: Self::step_of(self.hold),
            volts,
        }
    }

    /// The current `i` [A] the last drive made: the current limit, and a sample of its level.
    fn measured(&mut self, i: f32) {
        if !i.is_finite() {
            return;
        }
        let (v, level) = self.last;
        if i.abs() > self.i_limit {
            let v_limit = self.above_drop(v, self.i_limit / i.abs());
            if v_limit < self.volts {
                self.volts = v_limit;
                self.ramp = 1.0;
            }
        }
        match level {
            Some(true) => self.hi.add(v, i),
            Some(false) => self.lo.add(v, i),
            None => {}
        }
    }

    /// Whether the current sense saw the current the holds drove (module docs,
    /// [`CommissionError::NoCurrent`]): `(Ī_hi, Ī_lo)` [A], signed as measured.
    fn current_seen(&self) -> Option<(f32, f32)> {
        let (v_hi, i_hi) = self.hi.mean()?;
        let (_, i_lo) = self.lo.mean()?;
        let expected = (v_hi - self.v_dead) / self.r_model;
        let expected = if expected < self.i_limit {
            expected
        } else {
            self.i_limit
        };
        let seen = expected > 0.0
            && i_hi.abs() >= CURRENT_SHARE * expected
            && (i_hi - i_lo).abs() >= CURRENT_SHARE * i_hi.abs()
            && (i_hi - i_lo) * i_hi > 0.0;
        seen.then_some((i_hi, i_lo))
    }

    /// The winding resistance [Ω] from the holds so far: the difference of the two levels'
    /// mean voltages over that of their mean currents (module docs); `None` without samples
    /// at both levels, when the current sense did not see the current
    /// ([`CommissionError::NoCurrent`]), or outside the physical range
    /// [`crate::blob::MOTOR_R`].
    pub fn resistance(&self) -> Option<f32> {
        let (i_hi, i_lo) = self.current_seen()?;
        let (v_hi, _) = self.hi.mean()?;
        let (v_lo, _) = self.lo.mean()?;
        let r = (v_hi - v_lo) / (i_hi - i_lo).abs();
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
        let Some((i_hi, _)) = self.current_seen() else {
            return Err(CommissionError::NoCurrent);
        };
        let rot = |s: &[u8; 6]| (0..6).any(|o| (0..6).all(|k| seq[k] == s[(k + o) % 6]));
        let mut rev = DEFAULT_SEQUENCE;
        rev.reverse();
        let forward = rot(&DEFAULT_SEQUENCE);
        let reversed = rot(&rev);
        Ok(Commissioning {
            sequence: seq,
            reversed,
            permuted: !forward && !reversed,
            current_sign: if i_hi < 0.0 { -1 } else { 1 },
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
    /// sequence; the current `(V − 0.4 V)/0.2 Ω` a hold drives, of a given sign.
    fn run(seq: [u8; 6], sign: f32, start: u8) -> Result<Commissioning, CommissionError> {
        let mut c = Commissioner::new(2.0, 10.0, 0.4, 0.2);
        let mut sector = start;
        let mut hall = seq[sector as usize];
        // Edges arrive with the next period's measurement.
        let mut edges: std::vec::Vec<u8> = std::vec::Vec::new();
        let mut i = 0.0f32;
        for _ in 0..10_000 {
            match c.tick(hall, edges.drain(..), false, i) {
                CommissionStep::Done(r) => return r,
                CommissionStep::Hold { step, volts } => {
                    i = sign * (volts - 0.4).max(0.0) / 0.2;
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

    /// Runs a whole commissioning on a resting winding of resistance `r` [Ω] behind a
    /// dead time of `vd` [V] (the current a voltage drives is `(V − vd)/R`, of its sign);
    /// returns the sequencer and the largest current [A].
    fn resting_winding(c: &mut Commissioner, r: f32, vd: f32) -> f32 {
        let mut i = 0.0f32;
        let mut peak = 0.0f32;
        for _ in 0..10_000 {
            match c.tick(1, [], false, i) {
                CommissionStep::Done(_) => return peak,
                CommissionStep::Hold { volts, .. } => {
                    i = (volts - vd).max(0.0) / r;
                    peak = peak.max(i);
                }
            }
        }
        panic!("never finished");
    }

    #[test]
    fn two_levels_measure_r_without_the_dead_time_drop() {
        // 2 V across 0.2 Ω behind a 0.5 V drop: V/I would read 0.267 Ω (a third high).
        for (vd_expected, r, vd) in [(0.5, 0.2, 0.5), (0.4, 0.2, 0.5), (0.0, 0.5, 0.3)] {
            let mut c = Commissioner::new(2.0, f32::INFINITY, vd_expected, r);
            resting_winding(&mut c, r, vd);
            let got = c.resistance().unwrap();
            // 1e-3: far above the f32 rounding of the two levels' difference quotient, far below
            // the third by which V/I would be off.
            assert!(
                (got - r).abs() < 1e-3 * r,
                "R {got} vs {r} (drop {vd}, expected {vd_expected})"
            );
        }
    }

    #[test]
    fn the_measured_current_lowers_the_hold_voltage_to_the_limit() {
        // The caller sized 2 V for a 0.2 Ω winding (7.5 A); the winding has 0.05 Ω (30 A).
        let mut c = Commissioner::new(2.0, 7.5, 0.5, 0.2);
        let peak = resting_winding(&mut c, 0.05, 0.5);
        assert!(peak <= 7.5 + 1e-3, "peak {peak} A");
        // The ramp ends at the voltage that drives its target share of the limit:
        // 0.5 V + 0.9 · 7.5 A · 0.05 Ω.
        let want = 0.5 + RAMP_TARGET * 7.5 * 0.05;
        assert!((c.volts() - want).abs() < 1e-3, "{} V", c.volts());
        assert!((c.resistance().unwrap() - 0.05).abs() < 1e-4);
    }

    #[test]
    fn a_blocked_rotor_is_no_motion() {
        let mut c = Commissioner::new(2.0, 10.0, 0.4, 0.2);
        let r = loop {
            if let CommissionStep::Done(r) = c.tick(1, [], false, 1.0) {
                break r;
            }
        };
        assert_eq!(r, Err(CommissionError::NoMotion));
    }

    /// Runs a whole commissioning with an ideal rotor (default sequence) whose current sense
    /// reads `sense(true current, period)`; the winding has `r` [Ω] behind a 0.4 V drop.
    fn with_sense(
        r: f32,
        sense: impl Fn(f32, usize) -> f32,
    ) -> (Result<Commissioning, CommissionError>, Option<f32>) {
        let mut c = Commissioner::new(2.0, 10.0, 0.4, 0.2);
        let (mut hall, mut i) = (DEFAULT_SEQUENCE[0], 0.0f32);
        let mut edge = None;
        for k in 0..10_000 {
            match c.tick(hall, edge.take(), false, sense(i, k)) {
                CommissionStep::Done(res) => return (res, c.resistance()),
                CommissionStep::Hold { step, volts } => {
                    let next = DEFAULT_SEQUENCE[step as usize];
                    if next != hall {
                        edge = Some(next);
                    }
                    hall = next;
                    i = (volts - 0.4).max(0.0) / r;
                }
            }
        }
        panic!("never finished");
    }

    #[test]
    fn a_current_sense_that_does_not_see_the_current_fails_the_run() {
        // Pseudo-random noise of ±50 mA (a dead sense's noise), with and without a 0.3 A
        // offset, and a sense reading nothing at all.
        let noise =
            |k: usize| ((k as u32).wrapping_mul(2_654_435_761) >> 16) as f32 / 65_536.0 - 0.5;
        type Sense<'a> = &'a dyn Fn(f32, usize) -> f32;
        let cases: [(&str, Sense); 4] = [
            ("zero", &|_, _| 0.0),
            ("noise", &|_, k| 0.1 * noise(k)),
            ("offset and noise", &|_, k| 0.3 + 0.1 * noise(k)),
            ("a hundredth of the current", &|i, _| 0.01 * i),
        ];
        for (what, sense) in cases {
            let (res, r) = with_sense(0.2, sense);
            assert_eq!(res, Err(CommissionError::NoCurrent), "{what}");
            assert_eq!(r, None, "{what}");
        }
        // A working sense, inverted, on windings of a third and three times the blob's R.
        for r_true in [0.2 / 3.0, 0.6] {
            let (res, r) = with_sense(r_true, |i, _| -i);
            let res = res.unwrap();
            assert_eq!(res.current_sign, -1);
            let r = r.unwrap();
            // 1e-3, as for the two levels above: the sign is taken out before the difference
            // quotient, so only f32 rounding (2e-6 here) is left.
            assert!((r - r_true).abs() < 1e-3 * r_true, "{r} vs {r_true}");
        }
        // Five times the blob's R: the current is under a quarter of the expected one.
        let (res, _) = with_sense(1.0, |i, _| i);
        assert_eq!(res, Err(CommissionError::NoCurrent));
        // A hold voltage below the dead time's drop drives nothing to measure.
        let mut c = Commissioner::new(0.3, 10.0, 0.4, 0.2);
        let res = loop {
            if let CommissionStep::Done(r) = c.tick(1, [], false, 0.0) {
                break r;
            }
        };
        assert!(res.is_err());
    }

    #[test]
    fn each_hold_lasts_hold_periods() {
        let mut c = Commissioner::new(2.0, 10.0, 0.4, 0.2);
        let mut steps = std::vec::Vec::new();
        while let CommissionStep::Hold { step, .. } = c.tick(1, [], false, 1.0) {
            steps.push(step);
        }
        assert_eq!(steps.len(), usize::from(HOLDS) * usize::from(HOLD_PERIODS));
        for (h, hold) in steps.chunks(usize::from(HOLD_PERIODS)).enumerate() {
            assert!(
                hold.iter().all(|&k| k == Commissioner::step_of(h as u8)),
                "{h}"
            );
        }
    }
}
