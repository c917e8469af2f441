//! The reference paper's goodness of fit (its eq. 48): `100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖)`.
//!
//! 100 is a perfect prediction, 0 is no better than the mean of the data, and it is negative
//! when the prediction is worse than the mean.
use anyhow::{bail, Result};

/// Fit percentage of `yhat` (model) against `y` (measured). Errors when the lengths differ,
/// when a value is not finite, or when `y` is constant (the measure is undefined).
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> Result<f64> {
    if y.len() != yhat.len() {
        bail!(
            "fit: {} measured values but {} predicted",
            y.len(),
            yhat.len()
        );
    }
    if y.is_empty() {
        bail!("fit: no samples");
    }
    if y.iter().chain(yhat).any(|v| !v.is_finite()) {
        bail!("fit: a value is not finite");
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let den = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    let num = y
        .iter()
        .zip(yhat)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    if den <= f64::EPSILON * (1.0 + mean.abs()) * (y.len() as f64).sqrt() {
        bail!("fit: the measured signal is constant, so its fit percentage is undefined");
    }
    Ok(100.0 * (1.0 - num / den))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perfect_mean_and_worse() {
        let y = [1.0, 2.0, 3.0, 4.0];
        // 1e-12: exact cases (a perfect copy, the mean) up to float rounding on four samples.
        assert!((fit_percent(&y, &y).unwrap() - 100.0).abs() < 1e-12);
        assert!(fit_percent(&y, &[2.5; 4]).unwrap().abs() < 1e-12);
        assert!(fit_percent(&y, &[4.0, 3.0, 2.0, 1.0]).unwrap() < 0.0);
        assert!(fit_percent(&[1.0; 4], &[1.0; 4]).is_err());
        assert!(fit_percent(&y, &[1.0]).is_err());
    }
}
