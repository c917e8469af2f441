//! The measurement chain of the board, applied to model states (for `fit_sensor`).
//!
//! A real log's angle is Hall-quantised (the log's `hall_resolution_rad`, 0.0952 rad on the
//! paper's motor) and its velocity is the firmware's estimate: a moving average of the
//! quantised angle over `velocity_window` samples (the paper: 10 samples at 12 ms), i.e.
//! `ω̂_k = (θ_k − θ_{k−N}) / (t_k − t_{k−N})`. Passing the model's true states through the same
//! chain makes model and measurement comparable where the sensor cannot resolve the motion.
use crate::emulator::sensors::estimate_velocity;
use crate::log::MotorLog;

/// Hall quantisation of an angle: the nearest step (the board's sensors sit half a step
/// either side of angle 0, see `emulator::sensors`).
pub fn quantise(theta: f64, resolution: f64) -> f64 {
    if resolution > 0.0 {
        ((theta + 0.5 * resolution) / resolution).floor() * resolution
    } else {
        theta
    }
}

/// The firmware's moving-average velocity estimate ([`estimate_velocity`]) of an angle series
/// at the median sample period of its time stamps `t`.
pub fn velocity_estimate<F: num_traits::Float>(t: &[f64], theta: &[F], window: usize) -> Vec<F> {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let ts = if d.is_empty() {
        0.0
    } else {
        let k = d.len() / 2;
        *d.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
    };
    estimate_velocity(theta, window, F::from(ts).unwrap_or_else(F::zero))
}

/// The log's Hall resolution: `# hall_resolution_rad`, else 0 (no quantisation known).
pub fn hall_resolution(log: &MotorLog) -> f64 {
    log.meta_f64("hall_resolution_rad")
        .filter(|v| v.is_finite() && *v >= 0.0)
        .unwrap_or(0.0)
}

/// The measured velocity of a log: its `omega` column, else the firmware estimator applied
/// to its `theta`.
pub fn measured_velocity(log: &MotorLog, window: usize) -> Vec<f64> {
    match &log.omega {
        Some(w) => w.clone(),
        None => velocity_estimate(&log.t, &log.theta, window),
    }
}

/// Model angle and velocity as the board would have measured them: (θ quantised, ω̂).
pub fn through_sensor(
    t: &[f64],
    theta: &[f64],
    resolution: f64,
    window: usize,
) -> (Vec<f64>, Vec<f64>) {
    let q: Vec<f64> = theta.iter().map(|&th| quantise(th, resolution)).collect();
    let w = velocity_estimate(t, &q, window);
    (q, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiser_and_estimator() {
        // 1e-12 and 1e-9: float rounding of exact answers (a step of 0.1, a slope of 3).
        assert!((quantise(0.26, 0.1) - 0.3).abs() < 1e-12);
        assert!((quantise(-0.04, 0.1)).abs() < 1e-12);
        let t: Vec<f64> = (0..30).map(|k| k as f64 * 0.012).collect();
        let th: Vec<f64> = t.iter().map(|t| 3.0 * t).collect();
        let w = velocity_estimate(&t, &th, 10);
        assert!((w[25] - 3.0).abs() < 1e-12);
        let (q, wq) = through_sensor(&t, &th, 0.0952, 10);
        // Quantisation errs by at most half a step (0.0476 rad); the velocity over a
        // 10-sample (0.12 s) window by at most one step over the window.
        assert!(q
            .iter()
            .zip(&th)
            .all(|(a, b)| (a - b).abs() <= 0.0476 + 1e-12));
        assert!((wq[29] - 3.0).abs() < 0.0952 / 0.12 + 1e-9);
    }
}
