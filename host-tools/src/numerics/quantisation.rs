//! A quantised angle read back where its readings pin it: stretches of steady speed.
//!
//! A Hall or encoder reading `θ_m` says only that the true angle lies in a band one step `q`
//! wide around it (interval-censored). Its error is a sawtooth in the true angle: while the
//! speed changes, the error jumps about from sample to sample, but at a steady speed whose
//! advance per sample is close to a whole number of steps it drifts slowly and wraps, a
//! pattern that lasts as long as the speed does and that every derivative of the angle
//! inherits (a weak-form residual then repeats itself window after window).
//!
//! At a steady speed the bands of many samples together pin the true angle far inside one
//! step: the straight lines that pass through all of them form a narrow bundle (a vernier:
//! each sample's band is cut at another fraction of the step). Where such a stretch is at
//! least a weak-form window long, its readings are replaced by the bundle's centre line;
//! elsewhere they stay as read. So the angle is nowhere further from the truth than its own
//! band, and where the speed is steady it is much closer. A curved path is left alone: a
//! smooth path drawn through curving bands cuts their corners, an error that follows the
//! acceleration and that an inertia or a coupling would then explain.

/// The angle a quantised reading `theta` (step `q`; the true angle within half a step of each
/// reading, as a rounding quantiser gives; a truncating one differs by a constant, which no
/// weak derivative sees) most plausibly came from where the rotor turns at a steady speed:
/// every stretch of at least `min_len` samples through whose bands `θ_m ± q/2` one straight
/// line passes is replaced by the centre of all such lines ([`steady_line`]); the readings
/// stay as they are elsewhere. With `q` not positive or not finite, the readings unchanged.
pub fn dequantise(theta: &[f64], q: f64, min_len: usize) -> Vec<f64> {
    dequantise_with_variance(theta, q, min_len).0
}

/// [`dequantise`], with the variance of each sample's remaining error [rad²]: `q²/12` (a
/// uniform error over the band) where the reading stays, `(q/m)²/12` on the line of a steady
/// stretch of `m` samples (the bundle of lines through `m` bands is about `q/m` wide).
pub fn dequantise_with_variance(theta: &[f64], q: f64, min_len: usize) -> (Vec<f64>, Vec<f64>) {
    let mut out = theta.to_vec();
    if !(q > 0.0 && q.is_finite()) {
        return (out, vec![0.0; theta.len()]);
    }
    let mut var = vec![q * q / 12.0; theta.len()];
    let n = theta.len();
    let lo: Vec<f64> = theta.iter().map(|t| t - 0.5 * q).collect();
    let hi: Vec<f64> = theta.iter().map(|t| t + 0.5 * q).collect();
    let mut a = 0;
    while a < n {
        let (b, line) = steady_line(&lo, &hi, a);
        if b - a >= min_len.max(3) {
            if let Some((c, s)) = line {
                let m = (b - a) as f64;
                for k in a..b {
                    out[k] = c + s * (k - a) as f64;
                    var[k] = (q / m).powi(2) / 12.0;
                }
            }
        }
        a = b;
    }
    (out, var)
}

/// The longest stretch `a..b` from `a` through whose bands `[lo_k, hi_k]` a straight line
/// passes, and the centre line `(value at a, slope per sample)`: the slope midway between the
/// least and the greatest feasible one, the value midway in what that slope leaves. A line
/// passes through every band of a stretch exactly when every pair of bands `i < j` admits its
/// slope, `(lo_j − hi_i)/(j − i) ≤ s ≤ (hi_j − lo_i)/(j − i)` (a line through intervals at
/// fixed abscissae needs nothing beyond pairs).
pub fn steady_line(lo: &[f64], hi: &[f64], a: usize) -> (usize, Option<(f64, f64)>) {
    let n = lo.len().min(hi.len());
    if a >= n {
        return (n, None);
    }
    let (mut smin, mut smax) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut b = a + 1;
    while b < n {
        let (mut lo_s, mut hi_s) = (smin, smax);
        for i in a..b {
            let d = (b - i) as f64;
            lo_s = lo_s.max((lo[b] - hi[i]) / d);
            hi_s = hi_s.min((hi[b] - lo[i]) / d);
        }
        if lo_s > hi_s || lo_s.is_nan() || hi_s.is_nan() {
            break;
        }
        (smin, smax) = (lo_s, hi_s);
        b += 1;
    }
    if b - a < 2 {
        return (b, None);
    }
    let s = 0.5 * (smin + smax);
    let (mut c_lo, mut c_hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in a..b {
        c_lo = c_lo.max(lo[k] - s * (k - a) as f64);
        c_hi = c_hi.min(hi[k] - s * (k - a) as f64);
    }
    (b, Some((0.5 * (c_lo + c_hi), s)))
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    fn quantise(x: f64, q: f64) -> f64 {
        (x / q).round() * q
    }

    #[test]
    fn a_steady_speed_is_recovered_far_inside_one_step() {
        // 2.03 steps per sample: the reading's error beats with a period of 33 samples.
        let q = 0.1;
        let truth: Vec<f64> = (0..400).map(|k| 0.013 + 0.203 * k as f64).collect();
        let meas: Vec<f64> = truth.iter().map(|x| quantise(*x, q)).collect();
        let est = dequantise(&meas, q, 9);
        let worst = |a: &[f64]| {
            a.iter()
                .zip(&truth)
                .skip(40)
                .take(320)
                .map(|(x, t)| (x - t).abs())
                .fold(0.0f64, f64::max)
        };
        // The reading's error comes near q/2 = 0.05 as the beat sweeps it; the estimate must
        // bring it under a tenth of the step.
        assert!(worst(&meas) > 0.04, "{}", worst(&meas));
        assert!(worst(&est) < 0.01, "{}", worst(&est));
    }

    #[test]
    fn the_angle_stays_in_its_bands_and_a_curve_is_left_alone() {
        let q = 0.1;
        let truth: Vec<f64> = (0..300)
            .map(|k| {
                let t = k as f64 * 0.01;
                3.0 * (2.0 * t).sin() + 0.5 * t
            })
            .collect();
        let meas: Vec<f64> = truth.iter().map(|x| quantise(*x, q)).collect();
        let est = dequantise(&meas, q, 9);
        for k in 0..meas.len() {
            assert!((est[k] - meas[k]).abs() <= 0.5 * q + 1e-12, "sample {k}");
        }
        let rms = |a: &[f64]| {
            (a.iter()
                .zip(&truth)
                .map(|(x, t)| (x - t).powi(2))
                .sum::<f64>()
                / a.len() as f64)
                .sqrt()
        };
        assert!(
            rms(&est) <= rms(&meas) + 1e-12,
            "{} vs {}",
            rms(&est),
            rms(&meas)
        );
    }

    #[test]
    fn a_standstill_stays_put_and_short_inputs_pass_through() {
        let est = dequantise(&[0.2; 50], 0.1, 9);
        assert!(est.iter().all(|x| (x - 0.2).abs() < 1e-9));
        assert_eq!(dequantise(&[1.0, 2.0], 0.1, 9), vec![1.0, 2.0]);
        assert_eq!(dequantise(&[1.0, 2.0, 3.0], 0.0, 9), vec![1.0, 2.0, 3.0]);
    }
}
