//! Velocity estimators from Hall signals behind one interface.
//!
//! * [`MovingAverage`] — the paper's: `ω_k = (θ_k − θ_{k−N})/(N·Ts)` with N = 10 samples of
//!   Ts = 12 ms, so its resolution is one Hall step over 0.12 s: 0.0952/0.12 ≈ 0.79 rad/s.
//! * [`EdgeTiming`] — the Hall-edge-timing estimator of VESC, ODrive, moteus and ST's motor
//!   control SDK: each Hall edge is timestamped by a free-running timer capture; the speed is
//!   the angle of the last two edge intervals over the time they span. It is zero on a
//!   reversal, decays as `step/(time since the last edge)` when the next edge is late, and is
//!   zero after a timeout.
use num_traits::Float;
use serde::{Deserialize, Serialize};

/// The paper's moving-average window (10 samples of 12 ms).
pub const PAPER_WINDOW: u8 = 10;
/// Largest moving-average window this estimator stores.
pub const MAX_WINDOW: usize = 32;

/// A velocity estimator fed once per control period.
pub trait VelocityEstimator<F> {
    /// A Hall edge captured at timer count `ticks`, direction `dir` (+1/−1). Estimators that
    /// do not time edges ignore it.
    fn on_edge(&mut self, _ticks: u32, _dir: i8) {}
    /// One control sample: decoded angle `theta` [rad] and the timer count `now_ticks` at the
    /// sample. Returns the velocity estimate [rad/s].
    fn update(&mut self, theta: F, now_ticks: u32) -> F;
    /// Latest estimate [rad/s].
    fn omega(&self) -> F;
    /// Forget the history.
    fn reset(&mut self);
    /// The angle reference moved by `delta` [rad]: later `theta` values are smaller by
    /// `delta` (keeps f32 angles small over long runs). Stored angles shift to match.
    fn rebase(&mut self, _delta: F) {}
}

/// The paper's moving-average differentiator over a window of `window` samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingAverage<F> {
    window: usize,
    ts: F,
    buf: [F; MAX_WINDOW + 1],
    head: usize,
    len: usize,
    omega: F,
}

impl<F: Float> MovingAverage<F> {
    /// Window of `window` samples (clamped to 1..=[`MAX_WINDOW`]) of period `ts` [s].
    pub fn new(window: u8, ts: F) -> Self {
        MovingAverage {
            window: (window as usize).clamp(1, MAX_WINDOW),
            ts,
            buf: [F::zero(); MAX_WINDOW + 1],
            head: 0,
            len: 0,
            omega: F::zero(),
        }
    }

    /// The paper's: N = 10 at 12 ms.
    pub fn paper() -> Self {
        MovingAverage::new(PAPER_WINDOW, F::from(0.012).unwrap())
    }

    pub fn window(&self) -> usize {
        self.window
    }
}

impl<F: Float> VelocityEstimator<F> for MovingAverage<F> {
    /// `(θ_k − θ_{k−N})/(N·Ts)`; while fewer than N+1 samples exist, the oldest available
    /// sample is used with its true span (0 for the very first sample). A non-finite θ is
    /// skipped.
    fn update(&mut self, theta: F, _now_ticks: u32) -> F {
        if !theta.is_finite() {
            return self.omega;
        }
        let cap = self.window + 1;
        self.buf[self.head] = theta;
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
        let span = self.len - 1;
        if span == 0 || self.ts.is_nan() || self.ts <= F::zero() {
            self.omega = F::zero();
            return self.omega;
        }
        let oldest = self.buf[(self.head + cap - self.len) % cap];
        self.omega = (theta - oldest) / (F::from(span).unwrap() * self.ts);
        self.omega
    }

    fn omega(&self) -> F {
        self.omega
    }

    fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.omega = F::zero();
    }

    fn rebase(&mut self, delta: F) {
        for v in self.buf.iter_mut() {
            *v = *v - delta;
        }
    }
}

/// Hall-edge-timing estimator (timer capture, u32 ticks with wrap-around).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeTiming<F> {
    /// Angle of one Hall step [rad].
    step: F,
    /// Timer frequency [Hz].
    tick_hz: F,
    /// No edge for this long [ticks] → zero.
    timeout_ticks: u32,
    /// Timestamps of the last three edges (newest first) and how many of them are in the
    /// current direction run.
    t: [u32; 3],
    run: u8,
    dir: i8,
    /// Velocity from the edges alone.
    edge_omega: F,
    /// Span [ticks] of the window behind `edge_omega`, divided by its edge count.
    mean_interval: u32,
    timed_out: bool,
    omega: F,
}

impl<F: Float> EdgeTiming<F> {
    /// `step`: Hall step angle [rad] (see [`crate::hall::step_angle`]); `tick_hz`: capture
    /// timer frequency; `timeout_s`: no edge for this long means standstill (keep it below
    /// the timer's wrap period 2³²/tick_hz).
    pub fn new(step: F, tick_hz: F, timeout_s: F) -> Self {
        let to = (timeout_s * tick_hz).max(F::one());
        let timeout_ticks = to.to_u32().unwrap_or(u32::MAX / 2).min(u32::MAX / 2);
        EdgeTiming {
            step,
            tick_hz,
            timeout_ticks,
            t: [0; 3],
            run: 0,
            dir: 0,
            edge_omega: F::zero(),
            mean_interval: 0,
            timed_out: true,
            omega: F::zero(),
        }
    }
}

impl<F: Float> VelocityEstimator<F> for EdgeTiming<F> {
    /// A direction change (or the first edge) restarts the window with zero speed; otherwise
    /// the speed is `step·n/(t_k − t_{k−n})` over the last n = min(2, edges − 1) intervals.
    fn on_edge(&mut self, ticks: u32, dir: i8) {
        if dir == 0 {
            return;
        }
        if dir != self.dir || self.run == 0 || self.timed_out {
            self.dir = dir;
            self.run = 1;
            self.t[0] = ticks;
            self.edge_omega = F::zero();
            self.mean_interval = 0;
            self.timed_out = false;
            self.omega = F::zero();
            return;
        }
        self.t = [ticks, self.t[0], self.t[1]];
        self.run = (self.run + 1).min(3);
        let n = (self.run - 1) as usize;
        let span = ticks.wrapping_sub(self.t[n]);
        if span == 0 {
            return;
        }
        self.mean_interval = span / n as u32;
        let secs = F::from(span).unwrap() / self.tick_hz;
        self.edge_omega = F::from(dir).unwrap() * self.step * F::from(n).unwrap() / secs;
        self.omega = self.edge_omega;
    }

    fn update(&mut self, _theta: F, now_ticks: u32) -> F {
        if self.run == 0 || self.timed_out {
            self.omega = F::zero();
            return self.omega;
        }
        let since = now_ticks.wrapping_sub(self.t[0]);
        // An edge stamped after `now` (capture raced the sample): treat as "just now".
        let since = if since > u32::MAX / 2 { 0 } else { since };
        if since > self.timeout_ticks {
            self.timed_out = true;
            self.omega = F::zero();
        } else if self.run >= 2 && since > self.mean_interval {
            // Late edge: the speed is at most one step over the time since the last edge.
            let secs = F::from(since).unwrap() / self.tick_hz;
            self.omega = F::from(self.dir).unwrap() * self.step / secs;
        } else {
            self.omega = self.edge_omega;
        }
        self.omega
    }

    fn omega(&self) -> F {
        self.omega
    }

    fn reset(&mut self) {
        self.run = 0;
        self.dir = 0;
        self.edge_omega = F::zero();
        self.omega = F::zero();
        self.timed_out = true;
    }
}

/// Which estimator the control step uses (serialisable configuration).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum EstimatorConfig<F> {
    /// The paper's moving average over `window` control periods.
    MovingAverage { window: u8 },
    /// Hall-edge timing with the capture timer at `tick_hz` and standstill after `timeout_s`.
    EdgeTiming { tick_hz: F, timeout_s: F },
}

impl<F: Float> EstimatorConfig<F> {
    /// The paper's estimator.
    pub fn paper() -> Self {
        EstimatorConfig::MovingAverage {
            window: PAPER_WINDOW,
        }
    }
}

/// One of the estimators, chosen at run time (static dispatch, no allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Estimator<F> {
    MovingAverage(MovingAverage<F>),
    EdgeTiming(EdgeTiming<F>),
}

impl<F: Float> Estimator<F> {
    /// Build from a configuration, the Hall step angle `step` [rad] and the control period `ts`.
    pub fn from_config(cfg: &EstimatorConfig<F>, step: F, ts: F) -> Self {
        match *cfg {
            EstimatorConfig::MovingAverage { window } => {
                Estimator::MovingAverage(MovingAverage::new(window, ts))
            }
            EstimatorConfig::EdgeTiming { tick_hz, timeout_s } => {
                Estimator::EdgeTiming(EdgeTiming::new(step, tick_hz, timeout_s))
            }
        }
    }
}

impl<F: Float> VelocityEstimator<F> for Estimator<F> {
    fn on_edge(&mut self, ticks: u32, dir: i8) {
        match self {
            Estimator::MovingAverage(e) => e.on_edge(ticks, dir),
            Estimator::EdgeTiming(e) => e.on_edge(ticks, dir),
        }
    }
    fn update(&mut self, theta: F, now_ticks: u32) -> F {
        match self {
            Estimator::MovingAverage(e) => e.update(theta, now_ticks),
            Estimator::EdgeTiming(e) => e.update(theta, now_ticks),
        }
    }
    fn omega(&self) -> F {
        match self {
            Estimator::MovingAverage(e) => e.omega(),
            Estimator::EdgeTiming(e) => e.omega(),
        }
    }
    fn reset(&mut self) {
        match self {
            Estimator::MovingAverage(e) => e.reset(),
            Estimator::EdgeTiming(e) => e.reset(),
        }
    }
    fn rebase(&mut self, delta: F) {
        match self {
            Estimator::MovingAverage(e) => e.rebase(delta),
            Estimator::EdgeTiming(e) => e.rebase(delta),
        }
    }
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;
    use crate::hall::step_angle;

    const HZ: f64 = 1.0e6;

    #[test]
    fn moving_average_paper_resolution_and_ramp() {
        let mut ma = MovingAverage::<f64>::paper();
        let step: f64 = step_angle(11);
        // One Hall step in the window: the paper's resolution 0.79 rad/s.
        for k in 0..11 {
            ma.update(if k == 10 { step } else { 0.0 }, 0);
        }
        assert!((ma.omega() - 0.7933).abs() < 1e-3);
        // Exact on a ramp θ = 5·t once the window is full.
        let mut ma = MovingAverage::<f64>::paper();
        for k in 0..40 {
            ma.update(5.0 * 0.012 * k as f64, 0);
        }
        assert!((ma.omega() - 5.0).abs() < 1e-9);
        ma.reset();
        assert_eq!(ma.update(3.0, 0), 0.0);
    }

    fn feed_constant(e: &mut EdgeTiming<f64>, w: f64, t0: u32, edges: u32) -> u32 {
        // Edges of a motor at constant w, starting at tick t0.
        let step: f64 = step_angle(11);
        let dt = step / w.abs() * HZ;
        let dir = if w > 0.0 { 1 } else { -1 };
        let mut last = t0;
        for k in 0..edges {
            last = t0.wrapping_add((k as f64 * dt).round() as u32);
            e.on_edge(last, dir);
        }
        last
    }

    #[test]
    fn edge_timing_exact_at_constant_speed() {
        let step: f64 = step_angle(11);
        for w in [-120.0, -3.0, 0.5, 10.0, 250.0] {
            // Choose w so that the interval is an integer number of ticks: closed form then
            // holds to rounding.
            let dt_ticks = (step / f64::abs(w) * HZ).round();
            let w_exact = step * HZ / dt_ticks * f64::signum(w);
            let mut e = EdgeTiming::new(step, HZ, 0.5);
            let last = feed_constant(&mut e, w_exact, 1000, 6);
            let got = e.update(0.0, last + (dt_ticks as u32) / 2);
            assert!(
                (got - w_exact).abs() < 1e-9 * w_exact.abs(),
                "{got} vs {w_exact}"
            );
        }
    }

    #[test]
    fn edge_timing_timer_wrap() {
        let step: f64 = step_angle(11);
        let mut e = EdgeTiming::new(step, HZ, 0.5);
        let w = step * HZ / 1000.0; // exactly 1000 ticks per edge
        let last = feed_constant(&mut e, w, u32::MAX - 2500, 6);
        assert!(last < 5000, "the sequence wrapped");
        let got = e.update(0.0, last.wrapping_add(10));
        assert!((got - w).abs() < 1e-9 * w);
    }

    #[test]
    fn edge_timing_zero_on_reversal() {
        let step: f64 = step_angle(11);
        let mut e = EdgeTiming::new(step, HZ, 0.5);
        let last = feed_constant(&mut e, 20.0, 0, 5);
        // Near 20 rad/s (the tick rounding is 1e-4 of it), so the reversal below has a speed to
        // drop.
        assert!(e.omega() > 19.0);
        e.on_edge(last + 3000, -1);
        assert_eq!(e.omega(), 0.0);
        assert_eq!(e.update(0.0, last + 3100), 0.0);
        // The next backward edge gives a backward speed over one interval.
        e.on_edge(last + 5000, -1);
        assert!((e.omega() + step * HZ / 2000.0).abs() < 1e-9);
    }

    #[test]
    fn edge_timing_decay_and_timeout() {
        let step: f64 = step_angle(11);
        let mut e = EdgeTiming::new(step, HZ, 0.5);
        let w = step * HZ / 1000.0;
        let last = feed_constant(&mut e, w, 0, 6);
        // Before the next edge is due: the edge speed.
        assert!((e.update(0.0, last + 900) - w).abs() < 1e-9);
        // Late: step/(time since last edge), decreasing with time.
        let a = e.update(0.0, last + 4000);
        assert!((a - step * HZ / 4000.0).abs() < 1e-9);
        let b = e.update(0.0, last + 40_000);
        assert!(b < a && b > 0.0);
        // After the timeout (0.5 s = 500 000 ticks): zero, and it stays zero.
        assert_eq!(e.update(0.0, last + 600_000), 0.0);
        assert_eq!(e.update(0.0, last + 10), 0.0);
        // A new edge after a timeout restarts from zero.
        e.on_edge(last + 700_000, 1);
        assert_eq!(e.omega(), 0.0);
    }

    #[test]
    fn estimator_dispatch() {
        let step: f64 = step_angle(11);
        let mut e = Estimator::from_config(&EstimatorConfig::paper(), step, 0.012);
        for k in 0..20 {
            e.update(2.0 * 0.012 * k as f64, 0);
        }
        assert!((e.omega() - 2.0).abs() < 1e-9);
    }
}
