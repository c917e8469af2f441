//! The emulated board's hardware: the motor emulator ([`Plant`]) behind a six-step bridge,
//! three Hall inputs, a current sense and a capture timer, wired in any order.
//!
//! The motor is BLDC-like, with trapezoidal phase back-EMFs (flat tops of 120°
//! electrical): the bridge vector applied makes torque `K_t·g·I` and back-EMF `K_b·g·ω`,
//! where the factor `g` is a continuous function of the lead of the vector's field over the
//! rotor (60° electrical a Hall sector, sector `s` centred on `s`):
//! - a six-step vector (bridge step `k`, two phases driven, `control::board`'s numbering)
//!   has the line-to-line trapezoid ([`two_phase_factor`]); its field points at a sector
//!   boundary, so the firmware's commutation, step = sector + 1, keeps the lead within
//!   60..120° where `g = 1`: the DC-equivalent motor of the paper, its R and L line to line;
//! - a centre vector (commissioning: two phases high together, one low) has its own shape
//!   ([`centre_factor`]); its field points at a sector's middle and its path has ¾ of the
//!   line-to-line R and L (two phases in parallel in series with the third).
//!
//! A held vector pulls the rotor to where its field is; a permutation of the phase
//! connector maps the board's vectors onto the motor's as the phases are permuted.
//! Bridge off: g = 0 and no voltage (the winding current decays, no braking).
//!
//! The Hall connector may permute the three sensors, and the current sense may be
//! inverted: [`Wiring`]. The Hall sensors are ideal (at the six-step positions, no
//! hysteresis) unless [`Hardware::set_hall_placement`] moves them and gives them hysteresis.
//!
//! The hardware over-current stop (the firmware's comparators on the shunts into TIM1's
//! break input) is checked at every fine integration step: a winding current above
//! [`HW_TRIP_A`] turns the bridge off until [`Hardware::rearm`], and the next measurement
//! reports it.
use super::step_rig::TICK_HZ;
use crate::emulator::{EmulatorConfig, Plant};
use anyhow::{bail, Result};
use control::board::{commutation_step, Drive, Measurements, HW_TRIP_A};
use control::step::HallEdge;

/// How the emulated motor is connected to the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wiring {
    /// Board Hall input j (H1, H2, H3) carries the motor's sensor `hall_order[j]` (0..2).
    pub hall_order: [u8; 3],
    /// Bridge output j (U, V, W) drives the motor's phase `phase_order[j]` (0..2).
    pub phase_order: [u8; 3],
    /// The current sense reads the opposite sign.
    pub current_inverted: bool,
}

impl Default for Wiring {
    fn default() -> Self {
        Wiring {
            hall_order: [0, 1, 2],
            phase_order: [0, 1, 2],
            current_inverted: false,
        }
    }
}

/// (high, low) phase of each bridge step, as in `firmware/src/bridge.rs`.
const STEPS: [(u8, u8); 6] = [(0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1)];

/// `x` wrapped to (−3, 3]: an angle in sectors (60° electrical each) to within half a turn.
fn wrap_sectors(x: f64) -> f64 {
    let w = x.rem_euclid(6.0);
    if w > 3.0 {
        w - 6.0
    } else {
        w
    }
}

/// Torque factor of a two-phase vector whose field leads the rotor by `lead` sectors: the
/// line-to-line back-EMF of trapezoidal phase back-EMFs (flat tops of 120°), normalised to
/// its flat top. It is zero where the rotor lines up with the field (the equilibrium the
/// vector holds) and half a turn from there, rises linearly to 1 within one sector (60°
/// electrical) and stays 1 for the middle sector: `sign(lead)·min(|lead|, 1, 3 − |lead|)`.
/// Six-step with the right table keeps the lead within 1..2 sectors, where the factor is
/// 1: the DC-equivalent motor; a table off by a sector loses torque.
fn two_phase_factor(lead: f64) -> f64 {
    let l = wrap_sectors(lead);
    let x = l.abs();
    l.signum() * x.min(1.0).min(3.0 - x)
}

/// Torque factor of a centre vector (two phases high together, one low, carrying the
/// current `I` out of the low phase) whose field leads the rotor by `lead` sectors, in
/// units of the two-phase flat top: the back-EMF along its path, `(e_a + e_b)/2 − e_c` of
/// the same trapezoidal phase back-EMFs, over `2·E`. It rises as fast as a two-phase
/// vector's, to ½ at 30°, then at half that slope to 1 at 90°, symmetric about 90°:
/// `min(|l|, ½ + (|l| − ½)/2)` for the lead `|l| ≤ 1½` sectors, mirrored beyond.
fn centre_factor(lead: f64) -> f64 {
    let l = wrap_sectors(lead);
    let x = l.abs();
    let x = x.min(3.0 - x);
    l.signum() * x.min(0.5 + 0.5 * (x - 0.5))
}

/// Share of the line-to-line R and L in a centre vector's path: two phases in parallel in
/// series with the third.
const CENTRE_PATH: f64 = 0.75;

/// Parses a permutation of 1, 2, 3 written as three digits ("132").
pub fn parse_order(s: &str) -> Result<[u8; 3]> {
    let d: Vec<u8> = s.bytes().map(|b| b.wrapping_sub(b'1')).collect();
    let mut seen = [false; 3];
    if d.len() != 3
        || d.iter()
            .any(|&x| x > 2 || std::mem::replace(&mut seen[x as usize], true))
    {
        bail!(
            "'{}' is not an order of 1, 2, 3 (e.g. 123, 213, 321)",
            crate::log::echo(s)
        );
    }
    Ok([d[0], d[1], d[2]])
}

impl Wiring {
    /// Checks that both orders are permutations.
    pub fn check(&self) -> Result<()> {
        for o in [self.hall_order, self.phase_order] {
            let mut s = o;
            s.sort_unstable();
            if s != [0, 1, 2] {
                bail!("wiring order {o:?} is not a permutation of 0, 1, 2");
            }
        }
        Ok(())
    }

    /// The Hall state the board reads for the motor's own state `code`.
    pub fn hall(&self, code: u8) -> u8 {
        (0..3).fold(0, |acc, j| acc | (((code >> self.hall_order[j]) & 1) << j))
    }

    /// The motor's bridge step that the board's bridge step `k` drives.
    fn motor_step(&self, k: u8) -> u8 {
        let (hi, lo) = STEPS[k as usize % 6];
        let pair = (self.phase_order[hi as usize], self.phase_order[lo as usize]);
        STEPS.iter().position(|&p| p == pair).unwrap_or(0) as u8
    }

    /// Direction of the field of the board's bridge step `k` [sectors of the motor, 60°
    /// electrical each, sector `s` centred on `s`]: the motor's step `j` points at the
    /// boundary between its sectors `j` and `j + 1`, so that step `s + 1` leads a rotor in
    /// sector `s` by 60..120° (the six-step drive).
    fn step_field(&self, k: u8) -> f64 {
        f64::from(self.motor_step(k)) + 0.5
    }

    /// Direction of the field of the board's centre vector with low phase `low` [sectors of
    /// the motor]: opposite the low phase's axis. The motor's phases U, V, W point at its
    /// sectors 1, 3, 5 (the fields of its steps, `axis_hi − axis_lo`, then fall on the
    /// boundaries [`Wiring::step_field`] gives), so the field lies at sector `4 + 2·m` for
    /// the motor's low phase `m`.
    fn centre_field(&self, low: u8) -> f64 {
        let m = self.phase_order[usize::from(low % 3)];
        f64::from((4 + 2 * m) % 6)
    }

    /// The motor sector that the board numbers `k` when its own steps are the reference:
    /// the one centred between the fields of the board's steps `k − 1` and `k` (sector `k`
    /// of the default wiring), so that the board's step `k + 1` leads it by 60..120°.
    pub fn aligned_sector(&self, k: u8) -> u8 {
        let a = self.step_field((k + 5) % 6);
        let b = self.step_field(k % 6);
        // The two fields are one sector apart: their midpoint, the short way round.
        let mid = a + 0.5 * wrap_sectors(b - a);
        (mid.round() as i64).rem_euclid(6) as u8
    }
}

/// Capture-timer count at time `t` [s] (a free-running u32 counter that wraps).
fn ticks_at(t: f64) -> u32 {
    ((t * TICK_HZ).round() as u64 & u64::from(u32::MAX)) as u32
}

/// Hall sensors placed off the six-step positions, with hysteresis: the sector index
/// moves on only once the rotor is past a boundary by half the hysteresis.
#[derive(Debug, Clone, Copy)]
struct HallPlacement {
    /// How far the sensors sit behind the six-step positions [sectors of 60° electrical].
    offset: f64,
    /// Width of the hysteresis band around each boundary [sectors].
    hysteresis: f64,
    /// Sector index the sensors read now (as [`crate::emulator::sensors::sector_index`]).
    sector: i64,
}

impl HallPlacement {
    /// Follows the rotor to `a` [sectors]; the states entered, in order.
    fn track(&mut self, a: f64, entered: &mut Vec<u8>) {
        let x = a - self.offset;
        let half = 0.5 + 0.5 * self.hysteresis;
        while x > self.sector as f64 + half {
            self.sector += 1;
            entered.push(crate::emulator::sensors::hall_code(self.sector));
        }
        while x < self.sector as f64 - half {
            self.sector -= 1;
            entered.push(crate::emulator::sensors::hall_code(self.sector));
        }
    }

    fn state(&self) -> u8 {
        crate::emulator::sensors::hall_code(self.sector)
    }
}

/// The emulated hardware.
pub struct Hardware {
    plant: Plant,
    wiring: Wiring,
    pending: Vec<HallEdge>,
    /// Sign of the voltage applied last (the current along the vector is I·sign).
    last_sign: f64,
    /// The hardware over-current stop tripped (bridge held off).
    tripped: bool,
    /// Hall edges dropped because a period brought more than the queue holds.
    edges_lost: u32,
    /// Largest |I| [A] of the winding over the fine steps of the last [`Hardware::apply`].
    peak_current: f64,
    /// Bus voltage the board measures [V] (NaN: not measured, the board's nominal one).
    v_bus: f32,
    /// The hardware over-current stop is armed (false: it failed its self-test).
    stop_armed: bool,
    /// Gain of the current sense (1: working; 0: dead, only its offset and noise).
    sense_gain: f64,
    /// Hall sensors off the six-step positions (`None`: the emulator's ideal ones).
    halls: Option<HallPlacement>,
    /// Voltage of the drive applied last [V] (0: off).
    last_volts: f64,
}

impl Hardware {
    /// A motor at rest, wired as `wiring`.
    pub fn new(cfg: EmulatorConfig, wiring: Wiring) -> Result<Hardware> {
        wiring.check()?;
        let mut plant = Plant::new(cfg)?;
        plant.take_hall_edges(); // start recording edges
        Ok(Hardware {
            plant,
            wiring,
            pending: Vec::new(),
            last_sign: 1.0,
            tripped: false,
            edges_lost: 0,
            peak_current: 0.0,
            v_bus: f32::NAN,
            stop_armed: true,
            sense_gain: 1.0,
            halls: None,
            last_volts: 0.0,
        })
    }

    /// The emulated motor.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// Puts the resting rotor at angle `theta` [rad] (no Hall edges reported for the move).
    pub fn place_rotor(&mut self, theta: f64) {
        self.plant.set_truth(theta, 0.0, 0.0, 0.0);
        self.plant.take_hall_edges();
        if let Some(h) = self.halls {
            self.set_hall_placement(h.offset * 60.0, h.hysteresis * 60.0);
        }
    }

    /// The rotor angle [sectors of 60° electrical].
    fn rotor_sectors(&self) -> f64 {
        let step = std::f64::consts::TAU / (6.0 * f64::from(self.plant.config().pole_pairs));
        self.plant.truth().theta / step
    }

    /// Places the Hall sensors `offset_deg` [° electrical] behind the six-step positions,
    /// each switching `hysteresis_deg` [° electrical] apart in the two directions (both 0:
    /// as ideal as the emulator's own).
    pub fn set_hall_placement(&mut self, offset_deg: f64, hysteresis_deg: f64) {
        let (offset, hysteresis) = (offset_deg / 60.0, hysteresis_deg / 60.0);
        let x = self.rotor_sectors() - offset;
        self.halls = Some(HallPlacement {
            offset,
            hysteresis,
            sector: (x + 0.5).floor() as i64,
        });
    }

    /// The Hall state the motor's sensors give now.
    fn motor_hall(&self) -> u8 {
        match self.halls {
            Some(h) => h.state(),
            None => self.plant.hall_state(),
        }
    }

    /// What the board's inputs read now.
    pub fn measure(&mut self) -> Measurements {
        let truth = self.plant.truth();
        let read = self.plant.measured_current();
        let read = if self.sense_gain == 1.0 {
            read
        } else {
            // Offset and noise stay, the current's own part scales.
            read - (1.0 - self.sense_gain) * truth.i
        };
        let mut i = read * self.last_sign;
        if self.wiring.current_inverted {
            i = -i;
        }
        let mut m = Measurements {
            hall: self.wiring.hall(self.motor_hall()),
            now_ticks: ticks_at(truth.t),
            i_vector: i as f32,
            v_bus: self.v_bus,
            hw_overcurrent: self.tripped,
            temperature_c: f32::NAN, // no board temperature model: no derating
            ..Measurements::default()
        };
        for e in self.pending.drain(..) {
            if m.edges.push(e).is_err() {
                m.edges_overflow = true;
                self.edges_lost = self.edges_lost.saturating_add(1);
            }
        }
        m.edges_lost = self.edges_lost;
        m
    }

    /// Largest winding current |I| [A] during the last period, sampled at every fine
    /// integration step (the truth, between the board's 12 ms samples).
    pub fn peak_current(&self) -> f64 {
        self.peak_current
    }

    /// Voltage of the drive the board applied last [V] (0: bridge off), as commanded,
    /// before the over-current stop.
    pub fn last_volts(&self) -> f64 {
        self.last_volts
    }

    /// Sets the bus voltage the board measures [V] (NaN: not measured, the board's nominal
    /// one). The emulated motor takes the board's voltage command as it is; the board
    /// bounds it by the bus.
    pub fn set_bus_voltage(&mut self, v: f32) {
        self.v_bus = v;
    }

    /// Emulates a hardware over-current stop that armed (`true`, the default) or failed
    /// its self-test (`false`: it never trips).
    pub fn set_stop_armed(&mut self, armed: bool) {
        self.stop_armed = armed;
    }

    /// Sets the current sense's gain: 1 (the default) reads the winding current, 0 a dead
    /// sense (only the emulator's sensor offset and noise).
    pub fn set_current_sense_gain(&mut self, gain: f64) {
        self.sense_gain = gain;
    }

    /// Re-arms the hardware over-current stop (the firmware does it after `ClearFault`).
    pub fn rearm(&mut self) {
        self.tripped = false;
    }

    /// Apply `drive` for `dt` seconds; the bridge commutates at every Hall edge (per fine
    /// integration step) as the firmware's capture interrupt does, and stops for good when
    /// the current exceeds the hardware trip.
    pub fn apply(&mut self, drive: Drive, dt: f64) {
        let fine = self.plant.config().fine_step;
        let n = (dt / fine - 1e-9).ceil().max(1.0) as usize;
        let h = dt / n as f64;
        let step = std::f64::consts::TAU / (6.0 * f64::from(self.plant.config().pole_pairs));
        self.peak_current = self.plant.truth().i.abs();
        for _ in 0..n {
            if self.stop_armed && self.plant.truth().i.abs() > f64::from(HW_TRIP_A) {
                self.tripped = true;
            }
            let drive = if self.tripped { Drive::Off } else { drive };
            let theta = self.plant.truth().theta;
            // (voltage, the torque factor at a positive voltage, the path's share of R and L).
            let (v, g, path) = match drive {
                Drive::Off => (0.0, 0.0, 1.0),
                Drive::SixStep { volts, table } => {
                    let hall = self.wiring.hall(self.motor_hall());
                    match table.sector_of(hall) {
                        Some(sec) => {
                            let k = commutation_step(sec, volts < 0.0);
                            let lead = self.wiring.step_field(k) - theta / step;
                            (f64::from(volts), two_phase_factor(lead), 1.0)
                        }
                        None => (0.0, 0.0, 1.0),
                    }
                }
                Drive::Centre { low, volts } => {
                    let lead = self.wiring.centre_field(low) - theta / step;
                    (f64::from(volts), centre_factor(lead), CENTRE_PATH)
                }
            };
            let v = if v.is_finite() { v } else { 0.0 };
            self.plant.set_commutation(if v < 0.0 { -g } else { g });
            self.plant.set_winding_path(path);
            self.plant.apply(v, h);
            self.peak_current = self.peak_current.max(self.plant.truth().i.abs());
            if let Some(mut halls) = self.halls {
                let mut entered = Vec::new();
                halls.track(self.rotor_sectors(), &mut entered);
                self.halls = Some(halls);
                let ticks = ticks_at(self.plant.truth().t);
                for state in entered {
                    self.pending.push(HallEdge {
                        ticks,
                        state: self.wiring.hall(state),
                    });
                }
            }
        }
        self.last_volts = match drive {
            Drive::Off => 0.0,
            Drive::SixStep { volts, .. } | Drive::Centre { volts, .. } => f64::from(volts),
        };
        self.last_sign = match drive {
            Drive::SixStep { volts, .. } | Drive::Centre { volts, .. } if volts < 0.0 => -1.0,
            _ => 1.0,
        };
        let ideal = self.plant.take_hall_edges();
        for e in ideal.into_iter().filter(|_| self.halls.is_none()) {
            self.pending.push(HallEdge {
                ticks: ticks_at(e.t),
                state: self.wiring.hall(e.state),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_orders_map_steps_by_a_symmetry_of_the_hexagon() {
        let id = Wiring::default();
        for k in 0..6 {
            assert_eq!(id.aligned_sector(k), k);
        }
        for o in ["123", "132", "213", "231", "312", "321"] {
            let w = Wiring {
                phase_order: parse_order(o).unwrap(),
                ..Wiring::default()
            };
            let a: Vec<u8> = (0..6).map(|k| w.aligned_sector(k)).collect();
            // Neighbouring steps stay neighbours, all in one direction.
            let d = (a[1] + 6 - a[0]) % 6;
            assert!(d == 1 || d == 5, "{o}: {a:?}");
            for k in 0..6 {
                assert_eq!((a[(k + 1) % 6] + 6 - a[k]) % 6, d, "{o}: {a:?}");
            }
        }
        assert!(parse_order("112").is_err());
        assert!(parse_order("12").is_err());
    }

    /// Back-EMF of the motor's phase `m` per unit speed, normalised to its flat top, at
    /// rotor angle `theta` [sectors]: a trapezoid with a flat top of two sectors (120°)
    /// centred 1½ sectors (90°) behind the phase's axis at sector `1 + 2·m`, and ramps of
    /// one sector.
    fn phase_emf(m: u8, theta: f64) -> f64 {
        let axis = f64::from(1 + 2 * m);
        let x = wrap_sectors(theta - (axis - 1.5)).abs();
        (3.0 - 2.0 * x).clamp(-1.0, 1.0)
    }

    #[test]
    fn torque_factors_are_the_back_emf_along_each_vectors_path() {
        let w = Wiring::default();
        for j in 0..600 {
            let theta = f64::from(j) * 0.01;
            let e = |m: u8| phase_emf(m, theta);
            for k in 0..6u8 {
                // Current in through the high phase, out through the low one: 2·E at most.
                let (hi, lo) = STEPS[usize::from(k)];
                let want = 0.5 * (e(hi) - e(lo));
                let got = two_phase_factor(w.step_field(k) - theta);
                assert!(
                    (got - want).abs() < 1e-9,
                    "step {k} at {theta}: {got} vs {want}"
                );
            }
            for low in 0..3u8 {
                // Half the current through each high phase, all of it out through `low`.
                let (a, b) = ((low + 1) % 3, (low + 2) % 3);
                let want = 0.5 * (0.5 * (e(a) + e(b)) - e(low));
                let got = centre_factor(w.centre_field(low) - theta);
                assert!(
                    (got - want).abs() < 1e-9,
                    "centre {low} at {theta}: {got} vs {want}"
                );
            }
        }
        // A centre vector's field lies midway between the two steps sharing its low phase,
        // the middle of the sector the board's numbering gives it, whatever the wiring.
        for o in ["123", "132", "213", "231", "312", "321"] {
            let w = Wiring {
                phase_order: parse_order(o).unwrap(),
                ..Wiring::default()
            };
            for low in 0..3u8 {
                let c = control::board::centre_sector(low);
                let field = w.centre_field(low);
                assert_eq!(field, f64::from(w.aligned_sector(c)), "{o}, low {low}");
            }
        }
    }
}
