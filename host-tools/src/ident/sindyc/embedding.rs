//! The embedding stage: the velocity `ẋ` from the Hall-quantised angle and the hidden state
//! `z` from the time-delay (Hankel) embedding of that velocity (the paper's §4.3, eq. 46),
//! fitted on all fitting logs and scaled to unit RMS (the paper normalises `z` too; its scale
//! is arbitrary and absorbed by the coefficients).
use super::{centred_velocity, velocity_half, SindycOptions};
use crate::ident::hankel::{HankelEmbedding, Selection};
use crate::log::MotorLog;
use crate::numerics::statistics::correlation;
use anyhow::{bail, Context, Result};

/// The embedded signals of the fitting logs.
pub struct HiddenState {
    pub embedding: HankelEmbedding,
    /// `z` = Hankel reconstruction / `z_scale`.
    pub z_scale: f64,
    /// Largest `|z|` over the fitting logs (after scaling).
    pub z_peak: f64,
    /// Per fitting log: the centred velocity [rad/s].
    pub xdot: Vec<Vec<f64>>,
    /// Per fitting log: the scaled hidden state.
    pub z: Vec<Vec<f64>>,
    /// Correlation of `z` with the first log's `z_true` column, when it has one.
    pub z_correlation: Option<f64>,
}

impl HiddenState {
    /// Velocities, the Hankel embedding fitted on all of them, and `z` of each log. When no
    /// component is below the energy threshold (a noisy velocity has a flat tail), the
    /// embedding falls back to the paper's split: the lower half of the spectrum (its
    /// k = 31..60 of 60 delays).
    pub fn of_logs(logs: &[MotorLog], opts: &SindycOptions) -> Result<HiddenState> {
        let xdot: Vec<Vec<f64>> = logs
            .iter()
            .map(|l| centred_velocity(&l.t, &l.theta, velocity_half(l)))
            .collect();
        let all: Vec<f64> = xdot.iter().flatten().copied().collect();
        let delays = opts.delays(logs[0].sample_period());
        let embedding = match HankelEmbedding::fit(&all, delays, opts.selection) {
            Err(_) if matches!(opts.selection, Selection::EnergyBelow(_)) => {
                HankelEmbedding::fit(&all, delays, Selection::Range(delays / 2 + 1, delays))
            }
            r => r,
        }
        .with_context(|| format!("{}: column 'theta'", crate::log::echo_path(&logs[0].source)))?;
        drop(all);
        let mut z = xdot
            .iter()
            .map(|v| embedding.extract(v))
            .collect::<Result<Vec<_>>>()?;
        let count: usize = z.iter().map(Vec::len).sum();
        let ss: f64 = z.iter().flatten().map(|x| x * x).sum();
        let z_scale = (ss / count as f64).sqrt();
        if !(z_scale.is_finite() && z_scale > 0.0) {
            bail!("SINDYc: the extracted hidden state is zero; the velocity has no low-energy content");
        }
        let mut z_peak: f64 = 0.0;
        for v in z.iter_mut().flatten() {
            *v /= z_scale;
            z_peak = z_peak.max(v.abs());
        }
        let z_correlation = logs[0].extra("z_true").map(|zt| correlation(zt, &z[0]));
        Ok(HiddenState {
            embedding,
            z_scale,
            z_peak,
            xdot,
            z,
            z_correlation,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    #[test]
    fn the_centred_velocity_of_a_ramp_is_its_slope_everywhere() {
        let t: Vec<f64> = (0..50).map(|k| 0.012 * k as f64).collect();
        let theta: Vec<f64> = t.iter().map(|t| 3.0 * t - 1.0).collect();
        let v = centred_velocity(&t, &theta, 5);
        // 1e-9: the slope of a straight line is exact up to rounding.
        assert!(v.iter().all(|v| (v - 3.0).abs() < 1e-9), "{v:?}");
    }

    #[test]
    fn correlation_is_signed_and_zero_for_a_constant() {
        let a = [1.0, 2.0, 3.0, 5.0];
        let b: Vec<f64> = a.iter().map(|x| -2.0 * x + 1.0).collect();
        // An exact linear relation: −1 up to rounding.
        assert!((correlation(&a, &b) + 1.0).abs() < 1e-12);
        assert_eq!(correlation(&a, &[4.0; 4]), 0.0);
    }

    #[test]
    fn the_hidden_state_has_unit_rms_over_all_fitting_logs() {
        let logs: Vec<MotorLog> = [(SignalKind::A, 1), (SignalKind::B, 2)]
            .into_iter()
            .map(|(kind, seed)| {
                let cfg = EmulatorConfig {
                    seed,
                    ..EmulatorConfig::paper()
                };
                simulate_signal(&cfg, kind, 20.0).unwrap().log_with_truth()
            })
            .collect();
        let h = HiddenState::of_logs(&logs, &SindycOptions::default()).unwrap();
        let n: usize = h.z.iter().map(Vec::len).sum();
        let rms = (h.z.iter().flatten().map(|z| z * z).sum::<f64>() / n as f64).sqrt();
        // Normalised to unit RMS by construction: rounding only.
        assert!((rms - 1.0).abs() < 1e-9, "{rms}");
        assert_eq!(h.z[1].len(), logs[1].len());
        assert!(h.z_peak >= 1.0 && h.z_correlation.is_some());
    }

    /// The paper's hidden state on emulated LuGre data. Finding (reported, not hidden): with
    /// the paper's low-energy selection the extracted z is almost uncorrelated with the
    /// emulator's bristle deflection, because the LuGre z is nearly a static function of the
    /// velocity and lives in the high-energy subspace the method discards. What the test pins
    /// down: the low-energy z carries almost none of the velocity itself (it is a projection
    /// onto the complementary subspace), and dropping only the dominant component keeps
    /// clearly more of z_true.
    #[test]
    fn hankel_state_on_lugre_data() {
        let cfg = EmulatorConfig {
            seed: 1,
            ..EmulatorConfig::paper()
        };
        let a = simulate_signal(&cfg, SignalKind::A, 90.0)
            .unwrap()
            .log_with_truth();
        let zt = a.extra("z_true").unwrap();
        let v = centred_velocity(&a.t, &a.theta, velocity_half(&a));
        let paper = HankelEmbedding::fit(&v, 60, Selection::EnergyBelow(0.001)).unwrap();
        let zp = paper.extract(&v).unwrap();
        let broad = HankelEmbedding::fit(&v, 60, Selection::Range(2, 60)).unwrap();
        let zb = broad.extract(&v).unwrap();
        let r_paper = correlation(zt, &zp);
        let r_broad = correlation(zt, &zb);
        assert_eq!(zp.len(), v.len());
        // |r| < 0.1 is under 1 % of the velocity's variance: the projection onto the
        // complementary subspace leaves almost none of it, where a z that followed the
        // velocity would correlate near 1.
        assert!(correlation(&v, &zp).abs() < 0.1);
        // 0.2: many times the standard error of a correlation over 7500 samples of slowly
        // varying signals (about 1/√n_eff, a few hundredths), so the order is not chance.
        assert!(
            r_broad.abs() > r_paper.abs() + 0.2,
            "{r_paper} vs {r_broad}"
        );
    }
}
