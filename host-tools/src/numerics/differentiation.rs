//! Velocity from a sampled angle, for evaluating nonlinear terms (the sign of ω, |ω|, an
//! acceleration carrier) — never as a regression target, which the weak form
//! ([`super::weak_form`]) handles without differentiating.
//!
//! Two estimators, for two different uses, over the half-width [`VELOCITY_HALF_S`] (`diagnose`:
//! the narrower [`DIAGNOSE_VELOCITY_HALF_S`]):
//! * [`smoothed_derivative`] / [`smooth_velocity`]: the least-squares slope over the window
//!   (Savitzky–Golay, first order) at a uniform period: the lowest-variance slope of a
//!   quantised angle, where ω only enters a nonlinear term.
//! * [`centred_velocity`]: the two-point slope across the window at the log's own time
//!   stamps, `(θ_{k+h} − θ_{k−h})/(t_{k+h} − t_{k−h})`: the firmware's moving-average
//!   estimator (control::velocity::MovingAverage) centred. Its mean over a box window
//!   telescopes to a difference of two angles, which the SINDYc current regression
//!   integrates exactly ([`crate::ident::sindyc::rows::held_current_normal`]); a weighted
//!   slope does not.
use crate::log::MotorLog;

/// Half-width [s] of both velocity estimators outside `diagnose`: ±5 samples at the paper's 12 ms,
/// about one Hall step at 1.6 rad/s, and the span of the firmware's 10-sample moving average.
pub const VELOCITY_HALF_S: f64 = 0.06;

/// [`VELOCITY_HALF_S`] in samples of `log` (at least one).
pub fn velocity_half(log: &MotorLog) -> usize {
    crate::scales::samples_for(VELOCITY_HALF_S, log.sample_period(), log.len())
}

/// Half-width [s] of the velocity `diagnose` builds its candidate columns and carriers from:
/// ±4 samples at the paper's 12 ms, one sample narrower than [`VELOCITY_HALF_S`]. A bristle
/// breakaway of a few Hall steps lasts a few samples, and the presliding test finds it only
/// while the velocity does not smear it; the wider span would trade that for fewer false
/// alarms (measured in docs/decisions/0012-diagnose-velocity-half-width.md).
pub const DIAGNOSE_VELOCITY_HALF_S: f64 = 0.048;

/// [`DIAGNOSE_VELOCITY_HALF_S`] in samples of `log` (at least one).
pub fn diagnose_velocity_half(log: &MotorLog) -> usize {
    crate::scales::samples_for(DIAGNOSE_VELOCITY_HALF_S, log.sample_period(), log.len())
}

/// Least-squares slope over `±m` samples (Savitzky–Golay, first order) of a signal sampled
/// every `dt`: a smoothed derivative of a quantised signal; the window shrinks at the ends.
pub fn smoothed_derivative(x: &[f64], dt: f64, m: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| {
            let mm = m.min(j).min(n.saturating_sub(1) - j);
            if mm == 0 {
                return if n < 2 {
                    0.0
                } else if j == 0 {
                    (x[1] - x[0]) / dt
                } else {
                    (x[j] - x[j - 1]) / dt
                };
            }
            let mut num = 0.0;
            let mut den = 0.0;
            for k in 1..=mm {
                num += k as f64 * (x[j + k] - x[j - k]);
                den += 2.0 * (k * k) as f64;
            }
            num / (den * dt)
        })
        .collect()
}

/// The rotor velocity of a log [rad/s]: [`smoothed_derivative`] of its angle over
/// ±[`velocity_half`] samples at the log's sample period.
pub fn smooth_velocity(log: &MotorLog) -> Vec<f64> {
    smoothed_derivative(&log.theta, log.sample_period(), velocity_half(log))
}

/// Centred velocity estimate [rad/s] at the log's own time stamps `t` [s]: slope of the angle
/// between the samples `half` before and after (one-sided at the ends).
pub fn centred_velocity(t: &[f64], theta: &[f64], half: usize) -> Vec<f64> {
    let n = theta.len();
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(half);
            let b = (k + half).min(n.saturating_sub(1));
            if b > a && t[b] > t[a] {
                (theta[b] - theta[a]) / (t[b] - t[a])
            } else {
                0.0
            }
        })
        .collect()
}

/// Centred moving average over `±m` samples (shrinking at the ends).
pub fn moving_average(x: &[f64], m: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| {
            let mm = m.min(j).min(n.saturating_sub(1) - j);
            x[j - mm..=j + mm].iter().sum::<f64>() / (2 * mm + 1) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothed_derivative_of_a_ramp() {
        let x: Vec<f64> = (0..50).map(|k| 2.0 * k as f64 * 0.01).collect();
        for v in smoothed_derivative(&x, 0.01, 4) {
            assert!((v - 2.0).abs() < 1e-9);
        }
        let m = moving_average(&x, 2);
        assert!((m[10] - x[10]).abs() < 1e-12);
    }

    /// The slope of a parabola `x = t²` at an interior sample is exactly `2t` (a symmetric
    /// least-squares slope is exact for quadratics).
    #[test]
    fn smoothed_derivative_is_exact_for_a_parabola() {
        let dt = 0.012;
        let x: Vec<f64> = (0..40).map(|k| (k as f64 * dt).powi(2)).collect();
        let d = smoothed_derivative(&x, dt, 5);
        for (j, v) in d.iter().enumerate().take(35).skip(5) {
            assert!((v - 2.0 * j as f64 * dt).abs() < 1e-12, "{j}");
        }
    }
}
