//! The scales of a log, read from its own numbers, that turn the constants of identification
//! and diagnosis into the log's units: its sample period (windows are given in seconds and
//! converted here), its speeds (widths and thresholds in velocity units) and its drive
//! (bounds in torque units).
//!
//! The constants themselves were chosen on the paper's motor (rad/s, N·m, 12 ms). A factor is 1
//! on a log like that one, so the documented behaviour there is unchanged; on a log in other
//! units (a linear axis in m/s, a speed in mm/s, a drive in volts of a command) or at another
//! rate, the same constant means the same thing relative to the data.

/// Speed [rad/s] the velocity constants (stick speed, smooth-sign width, Stribeck grid and
/// bounds, speed bands) were chosen for: rotary logs whose 99th-percentile speed reaches at
/// least this (the paper's signal a reaches about 125 rad/s). Slower logs (a linear axis in
/// m/s, a slow test) scale those constants down by `q99(|ω|)/REFERENCE_SPEED`.
pub const REFERENCE_SPEED: f64 = 50.0;

/// Drive [N·m, or the unit of a torque command] the torque bounds (±10 for Coulomb friction,
/// an offset, a cogging amplitude) were chosen for: ±10 is ten times 1 N·m, above the paper's
/// motor (99th percentile of K_t·I on its signal a ≈ 0.34 N·m). A log whose 99th-percentile
/// drive exceeds this (a force in newtons, a command in millivolts) widens the bounds by
/// `q99(|drive|)/REFERENCE_DRIVE`.
pub const REFERENCE_DRIVE: f64 = 1.0;

/// 99th percentile of `|x|` over the finite values (None when there are none or it is 0).
fn q99_abs(x: impl Iterator<Item = f64>) -> Option<f64> {
    let mut a: Vec<f64> = x.map(f64::abs).filter(|v| v.is_finite()).collect();
    if a.is_empty() {
        return None;
    }
    let k = ((a.len() - 1) as f64 * 0.99) as usize;
    let q = *a.select_nth_unstable_by(k, f64::total_cmp).1;
    (q > 0.0).then_some(q)
}

/// Samples closest to `seconds` at period `dt`, at least 1 and at most `n` (the samples the
/// data has): a window never outgrows the data, whatever the period says.
pub fn samples_for(seconds: f64, dt: f64, n: usize) -> usize {
    let k = if dt > 0.0 && dt.is_finite() && seconds.is_finite() {
        (seconds / dt).round().clamp(1.0, n.max(1) as f64) as usize
    } else {
        1
    };
    k.clamp(1, n.max(1))
}

/// `min(1, q99(|ω|)/REFERENCE_SPEED)`: 1 for logs as fast as the paper's motor (so emulated
/// results keep the documented constants), smaller for slow logs or other units.
pub fn velocity_scale(omega: &[f64]) -> f64 {
    match q99_abs(omega.iter().copied()) {
        Some(q) => (q / REFERENCE_SPEED).min(1.0),
        None => 1.0,
    }
}

/// `max(1, q99(|drive|)/REFERENCE_DRIVE)`: 1 for drives up to 1 N·m (the paper's motor), larger for a
/// drive in bigger units, so that a torque bound is never tighter than the data's own drive.
pub fn drive_scale(drive: &[f64]) -> f64 {
    match q99_abs(drive.iter().copied()) {
        Some(q) => (q / REFERENCE_DRIVE).max(1.0),
        None => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_follow_the_units_of_the_data() {
        let w: Vec<f64> = (0..1000).map(|k| (k as f64 * 0.01).sin() * 100.0).collect();
        assert_eq!(velocity_scale(&w), 1.0);
        let slow: Vec<f64> = w.iter().map(|v| v * 1e-3).collect();
        let s = velocity_scale(&slow);
        assert!(s > 0.0019 && s <= 0.002, "{s}");
        // Same log in mm/s instead of m/s: a thousand times the scale.
        let mm: Vec<f64> = slow.iter().map(|v| v * 1e3).collect();
        assert!((velocity_scale(&mm) - 1.0).abs() < 1e-12);
        let d: Vec<f64> = w.iter().map(|v| v * 0.5).collect();
        assert!((drive_scale(&d) - 50.0).abs() < 0.5, "{}", drive_scale(&d));
        assert_eq!(drive_scale(&[0.01, -0.02]), 1.0);
        assert_eq!(samples_for(0.48, 0.012, 1000), 40);
        assert_eq!(samples_for(0.48, 0.0001, 1000), 1000);
        assert_eq!(samples_for(0.48, 0.0, 1000), 1);
    }
}
