//! Harmonic search in rotor angle: which whole number of periods per revolution a signal
//! (a model error, an equation residual) repeats with.
//!
//! Cogging torque repeats `h ≥ 2` times per revolution, a gravity or unbalanced load once. An
//! error that is periodic in angle shows as a large fraction of its variance explained by
//! `a·sin(hθ) + b·cos(hθ)` for one `h`.
use super::stats::lstsq;

/// Highest harmonic searched by default. Hall sensors quantise the angle: a harmonic is
/// resolvable while its period spans at least four quantisation steps (`h·res ≤ π/2`); the
/// paper's 0.0952 rad resolution gives h ≤ 16, and 24 covers finer encoders with margin
/// while keeping the search (and its Bonferroni correction) small.
pub const MAX_HARMONIC: u32 = 24;

/// Highest harmonic resolvable with an angle quantisation of `res` rad (at least 2).
pub fn resolvable(res: Option<f64>) -> u32 {
    match res {
        Some(r) if r > 0.0 && r.is_finite() => {
            ((std::f64::consts::FRAC_PI_2 / r).floor() as u32).clamp(2, MAX_HARMONIC)
        }
        _ => MAX_HARMONIC,
    }
}

/// One line of an angle spectrum: `amplitude·sin(h·θ + phase)` explains `explained` of the
/// signal's variance (about its mean).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HarmonicLine {
    /// Periods per revolution.
    pub harmonic: u32,
    /// Amplitude, in the signal's unit.
    pub amplitude: f64,
    /// Phase [rad].
    pub phase: f64,
    /// Fraction of the signal's variance explained by this harmonic alone.
    pub explained: f64,
}

/// Amplitude and phase of `a·sin(x) + b·cos(x) = amp·sin(x + phase)`.
pub fn amp_phase(a: f64, b: f64) -> (f64, f64) {
    (a.hypot(b), b.atan2(a))
}

/// Angle spectrum of `e` over harmonics `1..=hmax` of `theta` (one fit of
/// `c + a·sin(hθ) + b·cos(hθ)` per harmonic: the angle samples are not uniform, so an FFT does
/// not apply).
pub fn angle_spectrum(theta: &[f64], e: &[f64], hmax: u32) -> Vec<HarmonicLine> {
    let n = e.len().min(theta.len());
    let mean = e[..n].iter().sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = e[..n].iter().map(|v| v - mean).collect();
    let tss: f64 = centred.iter().map(|v| v * v).sum();
    let ones = vec![1.0; n];
    (1..=hmax)
        .map(|h| {
            let s: Vec<f64> = theta[..n].iter().map(|t| (h as f64 * t).sin()).collect();
            let c: Vec<f64> = theta[..n].iter().map(|t| (h as f64 * t).cos()).collect();
            let fit = lstsq(&[&ones, &s, &c], &centred);
            let (amplitude, phase) = amp_phase(fit.beta[1], fit.beta[2]);
            HarmonicLine {
                harmonic: h,
                amplitude,
                phase,
                explained: if tss > 0.0 {
                    ((tss - fit.rss) / tss).clamp(0.0, 1.0)
                } else {
                    0.0
                },
            }
        })
        .collect()
}

/// The strongest line of a spectrum.
pub fn dominant(lines: &[HarmonicLine]) -> Option<HarmonicLine> {
    lines
        .iter()
        .copied()
        .max_by(|a, b| a.explained.total_cmp(&b.explained))
}

/// Attenuation of an angle-periodic torque of `harmonic` periods per revolution averaged over
/// one sample at velocity `omega`: `sinc(h·ω·dt/2)`. A sampled regressor `sin(hθ_k)` stands
/// for the torque over the sample only while this is near 1; at high speed the torque averages
/// out of the motion, and so must the regressor (else it is aliased noise).
pub fn sample_average_gain(harmonic: f64, omega: f64, dt: f64) -> f64 {
    let x = 0.5 * harmonic * omega * dt;
    if x.abs() < 1e-9 {
        1.0
    } else {
        x.sin() / x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_harmonic_of_a_periodic_error() {
        // Angle sweeping back and forth over several turns, error repeating 7 times per turn.
        let n = 4000;
        let theta: Vec<f64> = (0..n)
            .map(|k| 20.0 * (k as f64 * 0.003).sin() + 0.01 * k as f64)
            .collect();
        let e: Vec<f64> = theta
            .iter()
            .enumerate()
            .map(|(k, t)| 0.03 * (7.0 * t + 0.4).sin() + 0.002 * ((k * 7919) % 13) as f64)
            .collect();
        let lines = angle_spectrum(&theta, &e, 12);
        let d = dominant(&lines).unwrap();
        assert_eq!(d.harmonic, 7);
        assert!((d.amplitude - 0.03).abs() < 0.003, "{d:?}");
        assert!((d.phase - 0.4).abs() < 0.1, "{d:?}");
        assert!(d.explained > 0.5);
        assert!(lines[2].explained < 0.05);
    }

    #[test]
    fn resolvable_harmonics_follow_the_quantisation() {
        assert_eq!(resolvable(Some(0.0951998)), 16);
        assert_eq!(resolvable(None), MAX_HARMONIC);
        assert_eq!(resolvable(Some(1.0)), 2);
        assert!((sample_average_gain(7.0, 0.0, 0.012) - 1.0).abs() < 1e-12);
        assert!(sample_average_gain(7.0, 100.0, 0.012).abs() < 0.3);
    }
}
