//! The emulated board's sensors: Hall sensors (with the firmware's decoder), the current
//! sensor (offset + Gaussian noise), and the firmware's velocity estimator.
//!
//! Hall sensors: three sensors 120° (electrical) apart give 6 states per electrical
//! revolution, so `6·pole_pairs` edges per mechanical revolution and a resolution of
//! `2π/(6·pole_pairs)` rad (0.0952 rad for the paper's 11 pole pairs, its 5.45°). The
//! sector boundaries sit half a step either side of angle 0, so the decoded angle is the true
//! angle rounded to the nearest step: the quantisation error is within ±step/2.
//! The decoder sees *every* edge (on the board it runs in the Hall-edge interrupt), so fast
//! rotation does not alias at the 12 ms sampling.
use control::hall::{step_angle, HallDecoder, HallTable};
use control::velocity::{MovingAverage, VelocityEstimator, MAX_WINDOW, PAPER_WINDOW};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Hall resolution [rad]: `2π/(6·pole_pairs)` (`control::hall::step_angle`).
pub fn hall_resolution(pole_pairs: u16) -> f64 {
    step_angle(pole_pairs)
}

/// Sector index (edges counted from angle 0) at true angle `theta`: `round(theta/step)`.
/// The sensors are mounted half a step ahead of the rotor's zero, so that the sector
/// `floor((θ + step/2)/step)` the board sees (`control::hall::hall_state_for_angle`) is the
/// nearest step.
pub fn sector_index(theta: f64, step: f64) -> i64 {
    ((theta + 0.5 * step) / step).floor() as i64
}

/// The 3-bit Hall state in sector `k` (any integer; the pattern repeats every 6), with the
/// firmware's default 120° table.
pub fn hall_code(sector: i64) -> u8 {
    HallTable::DEFAULT_120
        .state_of(sector.rem_euclid(6) as u8)
        .unwrap_or(0)
}

/// One Hall edge: the time the rotor crossed a sector boundary (interpolated within the fine
/// step) and the state entered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HallEdge {
    /// Time [s].
    pub t: f64,
    /// Hall state entered (3 bits).
    pub state: u8,
}

/// Hall sensors on the true rotor angle, and the firmware's decoder
/// (`control::hall::HallDecoder`) reading them.
#[derive(Debug, Clone)]
pub struct HallSensor {
    step: f64,
    /// True sector index: `round(theta/step)`.
    sector: i64,
    /// Sector index at power-up.
    sector0: i64,
    decoder: HallDecoder,
    /// Hall states entered since the last [`HallSensor::take_edges`], if anybody asks.
    edges: Vec<HallEdge>,
    keep_edges: bool,
    /// Last tracked angle and time (for edge times).
    last: (f64, f64),
}

impl HallSensor {
    /// Sensors for a motor with `pole_pairs`, rotor at `theta`.
    pub fn new(pole_pairs: u16, theta: f64) -> Self {
        let step = hall_resolution(pole_pairs);
        let sector = sector_index(theta, step);
        let mut decoder = HallDecoder::new(HallTable::DEFAULT_120, pole_pairs);
        decoder.update(hall_code(sector));
        HallSensor {
            step,
            sector,
            sector0: sector - sector.rem_euclid(6),
            decoder,
            edges: Vec::new(),
            keep_edges: false,
            last: (theta, 0.0),
        }
    }

    /// Resolution [rad].
    pub fn step(&self) -> f64 {
        self.step
    }

    /// Follow the rotor to `theta` at time `t`: every boundary crossed is one edge for the
    /// decoder, timed by linear interpolation from the previous call.
    pub fn track(&mut self, theta: f64, t: f64) {
        if !theta.is_finite() {
            return;
        }
        let (th0, t0) = self.last;
        self.last = (theta, t);
        let target = sector_index(theta, self.step);
        while self.sector != target {
            let dir = (target - self.sector).signum();
            // Boundary between sectors k and k+1 is at (k + 1/2)·step.
            let boundary = (self.sector as f64 + 0.5 * dir as f64) * self.step;
            self.sector += dir;
            let code = hall_code(self.sector);
            self.decoder.update(code);
            if self.keep_edges {
                let frac = if theta != th0 {
                    ((boundary - th0) / (theta - th0)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                self.edges.push(HallEdge {
                    t: t0 + frac * (t - t0),
                    state: code,
                });
            }
        }
    }

    /// Current Hall state (3 bits).
    pub fn state(&self) -> u8 {
        hall_code(self.sector)
    }

    /// The decoded angle [rad], as the firmware reports it. The decoder starts its count at
    /// the first state's sector within the electrical period (0 for a rotor starting at 0).
    pub fn angle(&self) -> f64 {
        self.decoder.angle()
    }

    /// The true angle quantised like the decoder does (for checks).
    pub fn ideal_angle(&self) -> f64 {
        (self.sector - self.sector0) as f64 * self.step
    }

    /// Invalid transitions the decoder saw (0 unless the emulation skipped an edge).
    pub fn faults(&self) -> u64 {
        self.decoder.fault_count() as u64
    }

    /// Hall edges since the last call (in order). The first call starts recording.
    pub fn take_edges(&mut self) -> Vec<HallEdge> {
        self.keep_edges = true;
        std::mem::take(&mut self.edges)
    }
}

/// The current sensor: true current + offset + Gaussian noise (seeded).
#[derive(Debug, Clone)]
pub struct CurrentSensor {
    sigma: f64,
    offset: f64,
    rng: StdRng,
}

impl CurrentSensor {
    /// Noise standard deviation `sigma` [A], additive `offset` [A], noise stream `seed`.
    pub fn new(sigma: f64, offset: f64, seed: u64) -> Self {
        CurrentSensor {
            sigma,
            offset,
            // A stream distinct from the signal generator's for the same seed.
            rng: StdRng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xC0FFEE),
        }
    }

    /// One reading of the true current `i`. Always draws one normal number, so the noise
    /// sequence does not depend on the effects or on `sigma`.
    pub fn read(&mut self, i: f64) -> f64 {
        let n: f64 = StandardNormal.sample(&mut self.rng);
        i + self.offset + self.sigma * n
    }
}

/// The firmware's velocity estimator (`control::velocity::MovingAverage`, the very code the
/// board runs) applied to a whole angle series sampled every `ts` [s]:
/// `(θ_k − θ_{k−N})/(N·ts)` over `window` = N samples (clamped to 1..=`MAX_WINDOW`; fewer
/// samples at the start, 0 at the first). Linear in θ: in dual numbers it carries the
/// angle's derivatives through.
pub fn estimate_velocity<F: num_traits::Float>(theta: &[F], window: usize, ts: F) -> Vec<F> {
    let mut est = MovingAverage::new(window.clamp(1, MAX_WINDOW) as u8, ts);
    theta.iter().map(|&th| est.update(th, 0)).collect()
}

/// The board's sensor chain applied to a true (or model) angle series sampled every `ts`:
/// Hall quantisation with the decoder (every edge between samples counted), then the
/// firmware's velocity estimator. Returns `(theta_measured, omega_estimated)`. The first
/// angle is taken as the rotor's power-up angle.
pub fn sensor_chain(theta: &[f64], pole_pairs: u16, ts: f64) -> (Vec<f64>, Vec<f64>) {
    let Some(&first) = theta.first() else {
        return (Vec::new(), Vec::new());
    };
    let mut hall = HallSensor::new(pole_pairs, first);
    let q: Vec<f64> = theta
        .iter()
        .map(|th| {
            hall.track(*th, 0.0);
            hall.angle()
        })
        .collect();
    let w = estimate_velocity(&q, PAPER_WINDOW as usize, ts);
    (q, w)
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    #[test]
    fn resolution_is_the_papers() {
        // 1e-4: 0.0952 is the paper's figure, to four digits.
        assert!((hall_resolution(11) - 0.0952).abs() < 1e-4);
    }

    #[test]
    fn decoder_follows_both_directions() {
        let mut h = HallSensor::new(11, 0.0);
        let step = h.step();
        for k in 0..=300 {
            h.track(k as f64 * 0.013, 0.0);
        }
        let th = 300.0 * 0.013;
        assert!((h.angle() - th).abs() <= step / 2.0 + 1e-12);
        for k in (0..=300).rev() {
            h.track(k as f64 * 0.013 - 1.0, 0.0);
        }
        assert!((h.angle() + 1.0).abs() <= step / 2.0 + 1e-12);
        assert_eq!(h.faults(), 0);
        // A jump of many sectors at once is still every edge.
        h.track(50.0, 0.0);
        assert_eq!(h.faults(), 0);
        assert_eq!(h.angle(), h.ideal_angle());
    }

    #[test]
    fn sensor_chain_quantises_and_differentiates() {
        let step = hall_resolution(11);
        // 10 rad/s for 2 s at 12 ms: the estimate settles at 10 rad/s within its resolution.
        let th: Vec<f64> = (0..167).map(|k| 10.0 * k as f64 * 0.012).collect();
        let (q, w) = sensor_chain(&th, 11, 0.012);
        for (a, b) in q.iter().zip(&th) {
            assert!((a - b).abs() <= step / 2.0 + 1e-12);
        }
        assert!((w[100] - 10.0).abs() <= step / 0.12 + 1e-9);
    }

    #[test]
    fn adjacent_codes_differ_by_one_bit() {
        for k in 0..6 {
            let d = hall_code(k) ^ hall_code(k + 1);
            assert_eq!(d.count_ones(), 1);
        }
    }

    #[test]
    fn moving_average_resolution() {
        // One Hall step inside the 10-sample window: 0.79 rad/s, the paper's resolution.
        let step = hall_resolution(11);
        let mut th = vec![0.0; 20];
        th.extend(vec![step; 20]);
        let w = estimate_velocity(&th, PAPER_WINDOW as usize, 0.012);
        assert!((w[25] - step / 0.12).abs() < 1e-12);
        // 0.01: 0.79 is the paper's figure, to two digits.
        assert!((step / 0.12 - 0.79).abs() < 0.01);
        assert_eq!(w[35], 0.0);
    }
}
