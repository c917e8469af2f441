//! Error by operating region: where in the motion a model fails (velocity bands, reversals,
//! rotor angle, current level, time), and sentences that name the worst regions.
use super::harmonics;
use crate::numerics::statistics::rms;
use serde::Serialize;

/// Velocity below which the motor counts as at standstill [rad/s]: about one Hall step
/// (0.095 rad) per 100 ms, below what the velocity estimate resolves reliably. Scaled by
/// [`crate::scales::velocity_scale`] of the log's velocity (a slower log or other units).
pub const STANDSTILL: f64 = 0.5;
/// Upper edge of the "low speed" band [rad/s]: the Stribeck region of the paper's motor
/// (v0 = 3.7 rad/s) with margin. Scaled as [`STANDSTILL`].
pub const LOW_SPEED: f64 = 5.0;
/// Time either side of a velocity sign change that counts as "reversal" [s]: ±5 × 12 ms,
/// in samples at the log's own period.
pub const REVERSAL_HALF_S: f64 = 0.06;

/// `x` rounded to 3 significant digits, for labels (0.5 prints as 0.5).
fn sig3(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let p = 10f64.powi(2 - x.abs().log10().floor() as i32);
    (x * p).round() / p
}
/// A region is named in words when its RMS error is at least this many times the overall.
pub const WORSE_FACTOR: f64 = 1.5;

/// RMS error in one region.
#[derive(Debug, Clone, Serialize)]
pub struct Region {
    /// Group: "velocity", "angle", "current", "time".
    pub group: &'static str,
    pub label: String,
    pub samples: usize,
    pub rms: f64,
    /// `rms` divided by the RMS over all samples.
    pub ratio: f64,
}

/// Error broken down by region, plus the angle spectrum and sentences.
#[derive(Debug, Clone, Serialize)]
pub struct Breakdown {
    pub overall_rms: f64,
    pub regions: Vec<Region>,
    /// Angle spectrum of the error (harmonics 1..).
    #[serde(skip)]
    pub spectrum: Vec<harmonics::HarmonicLine>,
    /// The worst regions in words.
    pub sentences: Vec<String>,
}

/// A velocity band: its name and which samples belong to it.
type Band<'a> = (&'static str, Box<dyn Fn(usize) -> bool + 'a>);

/// Inputs of the breakdown: one value per sample.
pub struct RegionInputs<'a> {
    pub t: &'a [f64],
    pub theta: &'a [f64],
    pub omega: &'a [f64],
    pub current: Option<&'a [f64]>,
    pub error: &'a [f64],
    /// Name of the error for the sentences ("velocity error").
    pub what: &'a str,
}

fn region(group: &'static str, label: String, e: &[f64], overall: f64) -> Option<Region> {
    if e.len() < 10 {
        return None;
    }
    let r = rms(e);
    Some(Region {
        group,
        label,
        samples: e.len(),
        rms: r,
        ratio: if overall > 0.0 { r / overall } else { 0.0 },
    })
}

/// Break the error down by operating region.
pub fn breakdown(x: &RegionInputs) -> Breakdown {
    let n = x.error.len().min(x.omega.len()).min(x.theta.len());
    let e = &x.error[..n];
    let overall = rms(e);
    let mut regions = Vec::new();
    let pick = |f: &dyn Fn(usize) -> bool| -> Vec<f64> {
        (0..n).filter(|&k| f(k)).map(|k| e[k]).collect()
    };

    // Velocity bands and reversals, in the log's velocity units and sample period.
    let vscale = crate::scales::velocity_scale(&x.omega[..n]);
    let (standstill, low_speed) = (sig3(STANDSTILL * vscale), sig3(LOW_SPEED * vscale));
    let dt = if x.t.len() > 1 {
        (x.t[x.t.len() - 1] - x.t[0]) / (x.t.len() - 1) as f64
    } else {
        0.0
    };
    let reversal_half = crate::scales::samples_for(REVERSAL_HALF_S, dt, n);
    let mut near_rev = vec![false; n];
    for k in 1..n {
        if x.omega[k].signum() != x.omega[k - 1].signum() && x.omega[k] != 0.0 {
            for v in
                near_rev[k.saturating_sub(reversal_half)..(k + reversal_half).min(n)].iter_mut()
            {
                *v = true;
            }
        }
    }
    let high = {
        let mut v: Vec<f64> = x.omega[..n].iter().map(|w| w.abs()).collect();
        v.sort_by(f64::total_cmp);
        v.get(n * 3 / 4)
            .copied()
            .unwrap_or(0.0)
            .max(low_speed * 2.0)
    };
    let bands: [Band; 5] = [
        (
            "standstill",
            Box::new(|k| x.omega[k].abs() < standstill && !near_rev[k]),
        ),
        ("reversals", Box::new(|k| near_rev[k])),
        (
            "low speed",
            Box::new(|k| (standstill..low_speed).contains(&x.omega[k].abs()) && !near_rev[k]),
        ),
        (
            "medium speed",
            Box::new(|k| (low_speed..high).contains(&x.omega[k].abs())),
        ),
        ("high speed", Box::new(|k| x.omega[k].abs() >= high)),
    ];
    for (label, f) in bands.iter() {
        let label = match *label {
            "standstill" => format!("standstill (|ω| < {standstill} rad/s)"),
            "low speed" => format!("low speed ({standstill}–{low_speed} rad/s)"),
            "medium speed" => format!("medium speed ({low_speed}–{} rad/s)", sig3(high)),
            "high speed" => format!("high speed (> {} rad/s)", sig3(high)),
            other => other.to_string(),
        };
        regions.extend(region("velocity", label, &pick(f.as_ref()), overall));
    }
    // Direction.
    regions.extend(region(
        "direction",
        "forward (ω > 0)".into(),
        &pick(&|k| x.omega[k] > standstill),
        overall,
    ));
    regions.extend(region(
        "direction",
        "backward (ω < 0)".into(),
        &pick(&|k| x.omega[k] < -standstill),
        overall,
    ));
    // Angle bins over one revolution.
    const ANGLE_BINS: usize = 12;
    for b in 0..ANGLE_BINS {
        let lo = b as f64 * 360.0 / ANGLE_BINS as f64;
        let hi = lo + 360.0 / ANGLE_BINS as f64;
        let f = |k: usize| {
            let d = x.theta[k].rem_euclid(std::f64::consts::TAU).to_degrees();
            d >= lo && d < hi
        };
        regions.extend(region(
            "angle",
            format!("{lo:.0}–{hi:.0}°"),
            &pick(&f),
            overall,
        ));
    }
    // Current quartiles.
    if let Some(i) = x.current {
        let mut a: Vec<f64> = i[..n].iter().map(|v| v.abs()).collect();
        a.sort_by(f64::total_cmp);
        let q = |p: usize| a.get(n * p / 4).copied().unwrap_or(0.0);
        let edges = [0.0, q(1), q(2), q(3), f64::INFINITY];
        for w in 0..4 {
            let (lo, hi) = (edges[w], edges[w + 1]);
            let f = |k: usize| (lo..hi).contains(&i[k].abs());
            let label = if hi.is_finite() {
                format!("|I| {lo:.2}–{hi:.2} A")
            } else {
                format!("|I| > {lo:.2} A")
            };
            regions.extend(region("current", label, &pick(&f), overall));
        }
    }
    // Time quarters (drift).
    for w in 0..4 {
        let f = |k: usize| k * 4 / n.max(1) == w;
        let (a, b) = (w * n / 4, ((w + 1) * n / 4).min(n.max(1)) - 1);
        regions.extend(region(
            "time",
            format!("{:.0}–{:.0} s", x.t[a.min(n - 1)], x.t[b.min(n - 1)]),
            &pick(&f),
            overall,
        ));
    }
    let spectrum = harmonics::angle_spectrum(&x.theta[..n], e, harmonics::MAX_HARMONIC);
    let sentences = sentences(&regions, &spectrum, x.what);
    Breakdown {
        overall_rms: overall,
        regions,
        spectrum,
        sentences,
    }
}

/// Fraction of the error's variance one angle harmonic must explain to be named: 10 %.
pub const HARMONIC_NAMED: f64 = 0.10;

fn sentences(regions: &[Region], spectrum: &[harmonics::HarmonicLine], what: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut worst: Vec<&Region> = regions
        .iter()
        .filter(|r| r.ratio >= WORSE_FACTOR && r.group != "time")
        .collect();
    worst.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    for r in worst.iter().take(3) {
        out.push(format!(
            "The {what} is {:.1}x larger {} ({}).",
            r.ratio,
            match r.group {
                "velocity" => "in this velocity band",
                "angle" => "at this rotor angle",
                "current" => "at this current level",
                _ => "here",
            },
            r.label
        ));
    }
    let times: Vec<&Region> = regions.iter().filter(|r| r.group == "time").collect();
    if times.len() == 4 && times[0].rms > 0.0 && times[3].rms / times[0].rms >= WORSE_FACTOR {
        out.push(format!(
            "The {what} grows with time ({:.1}x larger in the last quarter than in the first), as when the motor heats.",
            times[3].rms / times[0].rms
        ));
    }
    if let Some(d) = harmonics::dominant(spectrum) {
        if d.explained >= HARMONIC_NAMED {
            out.push(format!(
                "The {what} repeats {} time{} per revolution ({:.0}% of its variance).",
                d.harmonic,
                if d.harmonic == 1 { "" } else { "s" },
                100.0 * d.explained
            ));
        }
    }
    if out.is_empty() {
        out.push(format!(
            "The {what} is spread evenly: no region is {WORSE_FACTOR}x worse than the average."
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_the_low_speed_band_and_the_harmonic() {
        let n = 6000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        let omega: Vec<f64> = t.iter().map(|t| 30.0 * (0.5 * t).sin()).collect();
        let mut theta = vec![0.0; n];
        for k in 1..n {
            theta[k] = theta[k - 1] + omega[k] * 0.01;
        }
        // Error: small noise everywhere, large below 5 rad/s.
        let error: Vec<f64> = (0..n)
            .map(|k| {
                let base = 0.01 * ((k * 7919 % 101) as f64 / 50.0 - 1.0);
                if omega[k].abs() < 5.0 {
                    base + 0.2 * (7.0 * theta[k]).sin()
                } else {
                    base
                }
            })
            .collect();
        let b = breakdown(&RegionInputs {
            t: &t,
            theta: &theta,
            omega: &omega,
            current: None,
            error: &error,
            what: "velocity error",
        });
        assert!(
            b.sentences.iter().any(|s| s.contains("larger")),
            "{:?}",
            b.sentences
        );
        let low = b
            .regions
            .iter()
            .find(|r| r.label.starts_with("low speed"))
            .unwrap();
        let high = b
            .regions
            .iter()
            .find(|r| r.label.starts_with("high speed"))
            .unwrap();
        assert!(low.ratio > 2.0 && high.ratio < 0.5, "{low:?} {high:?}");
        assert!(
            b.sentences.iter().any(|s| s.contains("repeats 7 times")),
            "{:?}",
            b.sentences
        );
    }
}
