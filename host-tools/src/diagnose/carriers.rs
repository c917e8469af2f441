//! What carries the rest: which measured variable the unexplained residual depends on.
//!
//! When the residual is structured and no effect of the list explains it, the physics is
//! still somewhere. Each variable gets a smooth nonparametric function (a basis of hat
//! functions on its quantiles, a Fourier series for the angle over one revolution, a band of
//! sinusoids for a spectral peak), integrated against the same weak-form windows as the
//! equation, and tested against a constant on disjoint windows with a Wald test that holds
//! its level whatever each window's variance and however the windows of one held input share
//! an error ([`statistics::robust_wald_test`]). A variable *carries* structure when the test
//! is significant at the family level split over the checks and variables of the run
//! (Bonferroni; [`test_count`]) and the function explains at least the same share of the
//! residual an effect must ([`super::MIN_EXPLAINED`]).
//!
//! | variable | its function | physics that leaves this signature |
//! |---|---|---|
//! | `theta` | Fourier series over one revolution (or hats over a linear axis' travel) | cogging of another shape, a position-dependent load, a misplaced Hall sensor |
//! | `omega` | hats over speed | a friction curve of another shape, windage |
//! | `acceleration` | hats over acceleration | a wrong inertia, a second inertia on a compliant coupling |
//! | `current` | hats over current (torque command on a torque plant) | magnetic saturation, load-dependent friction |
//! | `time` | hats over the run | heating, wear, lubrication warming up, a sagging supply |
//! | `reversal` | hats over the time since the last reversal, signed by the direction | backlash, presliding |
//! | `frequency` | a band of sinusoids around the best peak | a compliant coupling, a structural resonance |
use super::candidates::Signals;
use crate::numerics::weak_form::WeakForm;
use crate::numerics::{least_squares, statistics};
use serde::Serialize;

/// Hat functions per variable: 8 knots, a smooth curve with 7 free shapes beyond a constant.
pub const KNOTS: usize = 8;
/// Harmonics of the angle's Fourier series: 6 (12 columns).
pub const ANGLE_HARMONICS: usize = 6;
/// Relative half-width of the frequency band: ±10 % around its centre (5 sinusoid pairs),
/// wide enough for a lightly damped resonance excited by steps.
pub const BAND: f64 = 0.10;

/// A variable that carries structure of the residual.
#[derive(Debug, Clone, Serialize)]
pub struct Carrier {
    /// `theta`, `omega`, `acceleration`, `current`, `time`, `reversal` or `frequency`.
    pub variable: &'static str,
    /// Share of the residual's sum of squares its function explains (0..1).
    pub share: f64,
    pub p_value: f64,
    /// Which physics leaves this signature, in words.
    pub explanation: String,
    /// Which equation's residual it carries.
    pub equation: super::candidates::Equation,
    /// The fitted function of the variable ([`Shape`]).
    pub shape: Shape,
    /// Centre of the band [Hz] (`frequency` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hz: Option<f64>,
    /// The term that takes this structure into the model where it is a torque over θ, ω or
    /// I (`table:var=V,bins=N`, N the carrier's own basis size), for `fit --add`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spec: Option<String>,
}

/// The fitted function of a carrier's variable, in the units of its equation's residual per
/// unit of the window's integral (volts for both equations of a voltage plant, the input's
/// unit for a torque plant): where the residual is large or small along the variable.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Shape {
    /// Values of the variable: the knots of its hats, points over one revolution for the
    /// angle's Fourier series, the band's frequencies [Hz] for `frequency`.
    pub x: Vec<f64>,
    /// The function at `x` (for `frequency`: the amplitude of each sinusoid of the band; for
    /// `reversal`: the part that acts in the direction of motion).
    pub y: Vec<f64>,
    /// For `time`: the part of the function that acts in the direction of motion, at `x`
    /// (`y` is then the part that does not).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub y_signed: Option<Vec<f64>>,
}

/// Points at which the angle's Fourier series is drawn over one revolution.
const SHAPE_POINTS: usize = 97;

/// The basis a variable's function was fitted on, to evaluate its coefficients.
enum Basis {
    /// Hats on these knots (one coefficient per knot).
    Hats(Vec<f64>),
    /// Hats on these knots, plain and signed by the direction of motion (`time`).
    PlainAndSigned(Vec<f64>),
    /// Sine and cosine of each harmonic of the angle, `ANGLE_HARMONICS` of them.
    Fourier,
    /// Sine and cosine at the band's frequencies around this centre [Hz].
    Band(f64),
}

impl Basis {
    /// The function of coefficients `beta` on this basis. Knots beyond any finite value (the
    /// time since a reversal before the first one) are left out.
    fn shape(&self, beta: &[f64]) -> Shape {
        let drawable = |x: f64| x.is_finite() && x.abs() < 1e299;
        match self {
            Basis::Hats(k) if k.len() == beta.len() => {
                let (x, y) = k
                    .iter()
                    .zip(beta)
                    .filter(|(x, _)| drawable(**x))
                    .map(|(x, y)| (*x, *y))
                    .unzip();
                Shape {
                    x,
                    y,
                    y_signed: None,
                }
            }
            Basis::PlainAndSigned(k) if 2 * k.len() == beta.len() => {
                let m = k.len();
                Shape {
                    x: k.clone(),
                    y: beta[..m].to_vec(),
                    y_signed: Some(beta[m..].to_vec()),
                }
            }
            Basis::Fourier if beta.len() == 2 * ANGLE_HARMONICS => {
                let x: Vec<f64> = (0..SHAPE_POINTS)
                    .map(|k| std::f64::consts::TAU * k as f64 / (SHAPE_POINTS - 1) as f64)
                    .collect();
                let y = x
                    .iter()
                    .map(|&a| {
                        beta.chunks(2)
                            .enumerate()
                            .map(|(h, sc)| {
                                let kf = (h + 1) as f64;
                                sc[0] * (kf * a).sin() + sc[1] * (kf * a).cos()
                            })
                            .sum()
                    })
                    .collect();
                Shape {
                    x,
                    y,
                    y_signed: None,
                }
            }
            Basis::Band(f0) if beta.len() == 2 * band_frequencies(*f0).len() => Shape {
                x: band_frequencies(*f0),
                y: beta.chunks(2).map(|sc| sc[0].hypot(sc[1])).collect(),
                y_signed: None,
            },
            _ => Shape::default(),
        }
    }
}

/// The frequencies [Hz] of the band of sinusoids around `f0`.
fn band_frequencies(f0: f64) -> Vec<f64> {
    (-2..=2)
        .map(|j| f0 * (1.0 + BAND * j as f64 / 2.0))
        .collect()
}

/// The `table` spec a carrier of the torque equation offers: over θ when its basis is the
/// Fourier series of one revolution (`2·ANGLE_HARMONICS` nodes resolve its harmonics), over
/// θ's travel when its basis is hats (a linear axis' stroke, `lo`..`hi` from the first to the
/// last knot), over ω or I (the current of a voltage plant) with one node per knot of its
/// hats.
fn table_spec(variable: &str, knots: &[f64], label: &str, s: &Signals) -> Option<String> {
    if label != super::candidates::Equation::Mechanical.label() {
        return None;
    }
    let n = knots.len();
    let (bins, range) = match variable {
        "theta" if n == 0 => (2 * ANGLE_HARMONICS, String::new()),
        "theta" => (n, format!(",lo={:.6e},hi={:.6e}", knots[0], knots[n - 1])),
        "omega" => (n, String::new()),
        "current" if s.plant == crate::log::Plant::Voltage && s.i.is_some() => (n, String::new()),
        _ => return None,
    };
    (2..=control::effects::TABLE_MAX_BINS)
        .contains(&bins)
        .then(|| format!("table:var={variable},bins={bins}{range}"))
}

/// One equation's residual on its weak-form windows.
pub struct Rows<'a> {
    pub wf: &'a WeakForm,
    /// Which windows the residual has (in window order).
    pub keep: &'a [bool],
    /// The residual on the kept windows (weighted by `scale` where given).
    pub resid: &'a [f64],
    /// Weight of each kept row, applied to the regressors as it was to the residual.
    pub scale: Option<&'a [f64]>,
    /// Equation label for explanations.
    pub label: &'a str,
    /// Cluster of each kept row ([`super::verdict::hold_clusters`]): rows that may share an
    /// error of the angle's reading.
    pub cluster: &'a [usize],
}

/// Hat functions on `knots` (ascending): a partition of unity, linear between knots.
fn hats(x: &[f64], knots: &[f64]) -> Vec<Vec<f64>> {
    let m = knots.len();
    let mut cols = vec![vec![0.0; x.len()]; m];
    for (k, &v) in x.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        if v <= knots[0] {
            cols[0][k] = 1.0;
            continue;
        }
        if v >= knots[m - 1] {
            cols[m - 1][k] = 1.0;
            continue;
        }
        let j = knots.partition_point(|&q| q <= v).clamp(1, m - 1);
        let (a, b) = (knots[j - 1], knots[j]);
        let w = if b > a { (v - a) / (b - a) } else { 0.0 };
        cols[j - 1][k] = 1.0 - w;
        cols[j][k] = w;
    }
    cols
}

/// `m` knots at the quantiles of `x` (only samples marked in `mask`), distinct.
fn quantile_knots(x: &[f64], mask: &[bool], m: usize) -> Vec<f64> {
    let mut v: Vec<f64> = x
        .iter()
        .zip(mask)
        .filter(|(v, k)| **k && v.is_finite())
        .map(|(v, _)| *v)
        .collect();
    if v.is_empty() {
        return vec![];
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let mut knots: Vec<f64> = (0..m)
        .map(|j| v[((v.len() - 1) as f64 * j as f64 / (m - 1) as f64).round() as usize])
        .collect();
    knots.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * (a.abs() + b.abs() + 1e-300));
    knots
}

/// Samples covered by at least one kept window.
fn sample_mask(rows: &Rows, n: usize) -> Vec<bool> {
    let mut m = vec![false; n];
    for (c, k) in rows.wf.centres.iter().zip(rows.keep) {
        if *k {
            let lo = c.saturating_sub(rows.wf.half);
            let hi = (c + rows.wf.half + 1).min(n);
            m[lo..hi].iter_mut().for_each(|x| *x = true);
        }
    }
    m
}

struct Tested {
    share: f64,
    /// `NaN` when the test cannot reject on this log (too few windows or held inputs).
    p_value: f64,
    /// Share of the residual in directions one held input decides alone (left untested).
    dropped_share: f64,
    beta: Vec<f64>,
}

/// Test of the residual on the weak-form integrals of sample-level columns, beyond a
/// constant (∫φ), on disjoint windows (every other row), whose
/// residuals share no sample: the share is the columns' least-squares share of the
/// residual's sum of squares, the p-value that of the cluster-robust Wald test
/// ([`statistics::robust_wald_test`]), which holds its level where the residual's variance
/// changes from window to window (stick-slip, steps) and where the windows of one held input
/// share an error of the angle's reading. `spans_constant`: the columns sum to one (hats).
///
/// The columns are tested beyond a constant, not beyond the model's own columns: those are
/// read from the same angle as the residual (errors in variables), and removing them from a
/// carrier passes the angle's rounding noise into it, which the residual shares; a correct
/// model's speed carrier then fires on most logs. The current would also rebuild, with the
/// model's columns, the equation's own left side.
fn test_columns(rows: &Rows, cols: &[Vec<f64>], spans_constant: bool) -> Tested {
    let every_other = |v: &[f64]| -> Vec<f64> { v.iter().step_by(2).copied().collect() };
    let thin = |v: Vec<f64>| -> Vec<f64> {
        let v = match rows.scale {
            Some(w) => v.iter().zip(w).map(|(a, b)| a * b).collect(),
            None => v,
        };
        every_other(&v)
    };
    let resid = every_other(rows.resid);
    let cluster: Vec<usize> = rows.cluster.iter().step_by(2).copied().collect();
    let ones_w: Vec<f64> = thin(super::select_rows(
        &rows.wf.integral(&vec![1.0; cols[0].len()]),
        rows.keep,
    ));
    let w: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| thin(super::select_rows(&rows.wf.integral(c), rows.keep)))
        .collect();
    let (test, share) = statistics::robust_test_beyond(
        &resid,
        &[&ones_w],
        &w,
        &cluster,
        statistics::CLUSTER_LEVERAGE_CAP,
    );
    let (p_value, dropped_share) = test.map_or((f64::NAN, 0.0), |t| (t.p_value, t.dropped_share));
    // The shape for the report: the residual against the columns alone (and a constant
    // where they do not span one).
    let mut refs: Vec<&[f64]> = Vec::with_capacity(w.len() + 1);
    if !spans_constant {
        refs.push(&ones_w);
    }
    refs.extend(w.iter().map(|c| c.as_slice()));
    let full = least_squares::lstsq(&refs, &resid);
    let beta = if spans_constant {
        full.beta
    } else {
        full.beta[1..].to_vec()
    };
    Tested {
        share,
        p_value,
        dropped_share,
        beta,
    }
}

/// Time since the last reversal of the velocity [s] at each sample (a reversal: the velocity
/// crosses from beyond the stick speed on one side to beyond it on the other).
fn since_reversal(s: &Signals) -> Vec<f64> {
    let stick = s.stick_speed();
    let mut last_sign = 0.0;
    let mut last_t = f64::NEG_INFINITY;
    s.omega
        .iter()
        .zip(&s.t)
        .map(|(&w, &t)| {
            if w.abs() >= stick {
                let sg = w.signum();
                if last_sign != 0.0 && sg != last_sign {
                    last_t = t;
                }
                last_sign = sg;
            }
            if last_t.is_finite() {
                t - last_t
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// Number of frequency-band centres [`carriers`] scans for a log (for the Bonferroni count).
pub fn band_centres(s: &Signals, wf: &WeakForm) -> Vec<f64> {
    let span = s.t.last().copied().unwrap_or(0.0) - s.t.first().copied().unwrap_or(0.0);
    if span <= 0.0 || s.dt <= 0.0 {
        return vec![];
    }
    // From a few periods per log to where the window's bump has attenuated a sinusoid to
    // about a tenth (period ≈ 0.7 × the window's half-width), and below the sample Nyquist.
    // A resonance is sought above the excitation's own band: the input's RMS frequency
    // `rms(u̇)/(2π·rms(u − ū))` (a sinusoid's own frequency; higher for steps), times 3.
    let f_lo = (8.0 / span).max(3.0 * rms_frequency(&s.raw_u, s.dt));
    let half_s: f64 = wf.half as f64 * s.dt;
    let f_hi = (1.5 / half_s).min(0.45 / s.dt);
    let mut v = Vec::new();
    let mut f = f_lo * (1.0 + BAND);
    while f * (1.0 + BAND) <= f_hi && v.len() < 200 {
        v.push(f);
        f *= 1.0 + BAND;
    }
    v
}

/// RMS frequency [Hz] of a sampled signal: `rms(Δu/dt) / (2π·rms(u − ū))`.
pub fn rms_frequency(u: &[f64], dt: f64) -> f64 {
    if u.len() < 3 || dt <= 0.0 {
        return 0.0;
    }
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    let centred: Vec<f64> = u.iter().map(|v| v - mean).collect();
    let du: Vec<f64> = u.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
    let a = statistics::rms(&centred);
    if a > 0.0 {
        statistics::rms(&du) / (2.0 * std::f64::consts::PI * a)
    } else {
        0.0
    }
}

/// Number of tests [`carriers`] runs on one equation, for the Bonferroni split of the level:
/// one per variable. The frequency is one variable searched over many bands; its best band's
/// p-value is multiplied by the number of bands searched (Bonferroni within the variable), so
/// that a search over a wide band does not take the level from the other variables.
pub fn test_count() -> usize {
    7
}

/// The variables that carry the residual's structure, and those whose test cannot decide on
/// this log.
#[derive(Debug, Default)]
pub struct Carried {
    /// Carriers, largest share first.
    pub carriers: Vec<Carrier>,
    /// Variables whose test cannot reject anything here (too few windows or held inputs).
    pub untested: Vec<&'static str>,
}

/// One variable's test, before it is judged a carrier, untested or neither.
struct Finding {
    variable: &'static str,
    tested: Tested,
    /// The hats' knots when the test's coefficients are a shape over them, else empty.
    knots: Vec<f64>,
    /// Centre of the frequency band [Hz], for the frequency's test.
    hz: Option<f64>,
    /// The basis of the test's coefficients, for the shape.
    basis: Basis,
}

/// Rank the variables that carry the residual's structure; `level` is the per-test level.
pub fn carriers(s: &Signals, rows: &Rows, level: f64, min_share: f64) -> Carried {
    let n = s.len();
    if rows.resid.len() < 4 * KNOTS || n == 0 {
        return Carried {
            carriers: vec![],
            untested: vec!["every variable"],
        };
    }
    let mask = sample_mask(rows, n);
    let sgn: Vec<f64> = s.omega.iter().map(|w| w.signum()).collect();
    let findings = angle_finding(s, rows, &mask)
        .into_iter()
        .chain(hat_findings(s, rows, &mask, &sgn))
        .chain(reversal_finding(s, rows, &mask, &sgn))
        .chain(frequency_finding(s, rows));
    let mut carried = Carried::default();
    for finding in findings {
        carried.record(finding, s, rows, level, min_share);
    }
    carried.carriers.sort_by(|a, b| b.share.total_cmp(&a.share));
    carried
}

impl Carried {
    /// Judge one finding: untested where the test cannot decide, or where what it had to leave
    /// out (directions one held input decides alone) could hold as much of the residual as an
    /// effect must explain; a carrier where it rejects at `level` with at least `min_share`.
    fn record(&mut self, f: Finding, s: &Signals, rows: &Rows, level: f64, min_share: f64) {
        let t = f.tested;
        if t.p_value.is_nan() || t.dropped_share >= min_share {
            self.untested.push(f.variable);
        } else if t.p_value < level && t.share >= min_share {
            let spec = table_spec(f.variable, &f.knots, rows.label, s);
            let shape = f.basis.shape(&t.beta);
            let equation = if rows.label == super::candidates::Equation::Electrical.label() {
                super::candidates::Equation::Electrical
            } else {
                super::candidates::Equation::Mechanical
            };
            let mut explanation = explanation(f.variable, t.share, f.hz, rows.label);
            if let Some(spec) = &spec {
                explanation.push_str(&format!(
                    " Where no named effect fits, `motorid fit --add {spec}` adds a lookup table of torque over it."
                ));
            }
            self.carriers.push(Carrier {
                variable: f.variable,
                share: t.share,
                p_value: t.p_value,
                explanation,
                equation,
                shape,
                hz: f.hz,
                spec,
            });
        }
    }
}

/// Angle: one revolution's Fourier series for a rotor that turns, else hats over the travel of
/// a linear axis or a rotor that never completes two turns.
fn angle_finding(s: &Signals, rows: &Rows, mask: &[bool]) -> Option<Finding> {
    let (lo, hi) = s
        .theta
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if hi - lo >= 4.0 * std::f64::consts::PI && s.plant == crate::log::Plant::Voltage {
        let mut cols = Vec::new();
        for k in 1..=ANGLE_HARMONICS {
            let kf = k as f64;
            cols.push(s.theta.iter().map(|x| (kf * x).sin()).collect());
            cols.push(s.theta.iter().map(|x| (kf * x).cos()).collect());
        }
        return Some(Finding {
            variable: "theta",
            tested: test_columns(rows, &cols, false),
            knots: vec![],
            hz: None,
            basis: Basis::Fourier,
        });
    }
    let knots = quantile_knots(&s.theta, mask, KNOTS);
    (knots.len() >= 3).then(|| Finding {
        variable: "theta",
        tested: test_columns(rows, &hats(&s.theta, &knots), true),
        basis: Basis::Hats(knots.clone()),
        knots,
        hz: None,
    })
}

/// Hats over speed, acceleration, current and time. Speed, acceleration and current are
/// signed: their hats carry odd functions. Time is not: a friction that changes over the run
/// acts with the direction of motion `sgn`, so time's hats come twice, plain and signed.
fn hat_findings(s: &Signals, rows: &Rows, mask: &[bool], sgn: &[f64]) -> Vec<Finding> {
    let acc =
        crate::numerics::differentiation::smoothed_derivative(&s.omega, s.dt, s.velocity_half);
    let current: &[f64] = s.i.as_deref().unwrap_or(&s.raw_u);
    let mut found = Vec::new();
    for (variable, x, signed) in [
        ("omega", &s.omega[..], false),
        ("acceleration", &acc[..], false),
        ("current", current, false),
        ("time", &s.t[..], true),
    ] {
        let knots = quantile_knots(x, mask, KNOTS);
        if knots.len() >= 3 {
            let mut cols = hats(x, &knots);
            if signed {
                let more: Vec<Vec<f64>> = cols.iter().map(|c| signed_by(c, sgn)).collect();
                cols.extend(more);
            }
            found.push(Finding {
                variable,
                tested: test_columns(rows, &cols, true),
                basis: if signed {
                    Basis::PlainAndSigned(knots.clone())
                } else {
                    Basis::Hats(knots.clone())
                },
                knots: if signed { vec![] } else { knots },
                hz: None,
            });
        }
    }
    found
}

/// Hats over the time since the last reversal, signed by the direction of motion `sgn`; the
/// last knot also takes every sample long after a reversal.
fn reversal_finding(s: &Signals, rows: &Rows, mask: &[bool], sgn: &[f64]) -> Option<Finding> {
    let finite: Vec<f64> = since_reversal(s).iter().map(|r| r.min(1e300)).collect();
    let knots = quantile_knots(&finite, mask, KNOTS);
    if knots.len() < 3 {
        return None;
    }
    let cols: Vec<Vec<f64>> = hats(&finite, &knots)
        .iter()
        .map(|c| signed_by(c, sgn))
        .collect();
    Some(Finding {
        variable: "reversal",
        tested: test_columns(rows, &cols, false),
        basis: Basis::Hats(knots.clone()),
        knots,
        hz: None,
    })
}

/// The column `c` times the direction of motion `sgn`, sample by sample.
fn signed_by(c: &[f64], sgn: &[f64]) -> Vec<f64> {
    c.iter().zip(sgn).map(|(a, b)| a * b).collect()
}

/// Frequency: the band of sinusoids with the smallest p-value, adjusted for the bands searched
/// (Bonferroni); a band the test cannot decide leaves the frequency untested.
fn frequency_finding(s: &Signals, rows: &Rows) -> Option<Finding> {
    let mut best: Option<(f64, Tested)> = None;
    let mut undecided: Option<Tested> = None;
    let centres = band_centres(s, rows.wf);
    for &f0 in &centres {
        let mut cols = Vec::new();
        for f in band_frequencies(f0) {
            let w = 2.0 * std::f64::consts::PI * f;
            cols.push(s.t.iter().map(|t| (w * t).sin()).collect());
            cols.push(s.t.iter().map(|t| (w * t).cos()).collect());
        }
        let t = test_columns(rows, &cols, false);
        if t.p_value.is_nan() {
            undecided.get_or_insert(t);
        } else if best.as_ref().is_none_or(|(_, b)| t.p_value < b.p_value) {
            best = Some((f0, t));
        }
    }
    let (tested, hz) = match (undecided, best) {
        (Some(t), _) => (t, None),
        (None, Some((f0, mut t))) => {
            t.p_value = (t.p_value * centres.len() as f64).min(1.0);
            (t, Some(f0))
        }
        (None, None) => return None,
    };
    Some(Finding {
        variable: "frequency",
        tested,
        knots: vec![],
        basis: hz.map_or(Basis::Hats(vec![]), Basis::Band),
        hz,
    })
}

/// Which physics leaves the signature of `variable`, in one sentence.
pub fn explanation(variable: &str, share: f64, hz: Option<f64>, label: &str) -> String {
    let what = match variable {
        "theta" => "the error repeats with the rotor angle or position: cogging of another shape than a sine, a position-dependent load, or a misplaced Hall sensor".to_string(),
        "omega" => "the error is a function of speed that the model's friction curve does not follow: a friction law of another shape (a Stribeck dip, higher-order viscous or windage losses)".to_string(),
        "acceleration" => "the error follows the acceleration: a wrong inertia, a second inertia on a compliant coupling that the motor feels only when it accelerates, or, where the current rises with the acceleration (voltage steps), magnetic saturation".to_string(),
        "current" => "the error grows with the current: magnetic saturation (a torque constant falling at high current), friction growing with transmitted torque, or dead time".to_string(),
        "time" => "the error drifts over the run: heating of the winding or the bearings, lubrication warming up, wear, or a sagging supply".to_string(),
        "reversal" => "the error is concentrated after reversals of the motion: backlash in a gear or coupling, or presliding of the friction contacts".to_string(),
        "frequency" => format!(
            "the error has a spectral peak near {:.2} Hz: a compliant coupling or a structural resonance",
            hz.unwrap_or(0.0)
        ),
        _ => variable.to_string(),
    };
    format!(
        "A smooth function of {variable} explains {:.0}% of the {label} residual that no effect of the list explains; {what}.",
        100.0 * share
    )
}

#[cfg(test)]
mod tests {
    // The tolerances here (1e-12, 1e-9) compare closed forms with their exact values: float
    // rounding.
    use super::*;

    #[test]
    fn hats_are_a_partition_of_unity_and_interpolate() {
        let knots = [0.0, 1.0, 3.0];
        let x = [-1.0, 0.0, 0.5, 2.0, 3.0, 9.0];
        let h = hats(&x, &knots);
        for k in 0..x.len() {
            let s: f64 = h.iter().map(|c| c[k]).sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
        assert_eq!(h[0][2], 0.5);
        assert_eq!(h[1][3], 0.5);
        assert_eq!(h[2][3], 0.5);
    }

    #[test]
    fn a_carrier_over_the_travel_offers_a_table_over_that_stroke() {
        let s = Signals {
            dt: 1e-3,
            t: vec![],
            u: vec![],
            raw_u: vec![],
            i: None,
            theta: vec![],
            theta_s: vec![],
            theta_torque: vec![],
            theta_torque_var: vec![],
            omega: vec![],
            drive: vec![],
            drive_model: vec![],
            plant: crate::log::Plant::Torque,
            kt: 1.0,
            hall_resolution: None,
            vscale: 1.0,
            velocity_half: 4,
        };
        let torque = super::super::candidates::Equation::Mechanical.label();
        let knots = [2.0, 50.0, 120.0, 245.5];
        let spec = table_spec("theta", &knots, torque, &s).unwrap();
        let e = crate::effect_spec::EffectSpec::parse(&spec).unwrap();
        assert_eq!(e.get("bins"), 4.0, "{spec}");
        assert!((e.get("lo") - 2.0).abs() < 1e-9 && (e.get("hi") - 245.5).abs() < 1e-9);
        // One revolution's Fourier series (no knots): the periodic table, no range.
        let rev = table_spec("theta", &[], torque, &s).unwrap();
        assert_eq!(rev, "table:var=theta,bins=12");
    }

    #[test]
    fn shapes_evaluate_their_basis() {
        // sin θ / 2 + cos 2θ: 1 at θ = 0, smallest (−1.5) at 3π/2.
        let mut beta = vec![0.0; 2 * ANGLE_HARMONICS];
        beta[0] = 0.5;
        beta[3] = 1.0;
        let s = Basis::Fourier.shape(&beta);
        let (k, _) =
            s.y.iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .unwrap();
        assert!(
            (s.x[k] - 1.5 * std::f64::consts::PI).abs() < 1e-9,
            "{}",
            s.x[k]
        );
        assert!((s.y[0] - 1.0).abs() < 1e-12 && (s.y[k] + 1.5).abs() < 1e-12);
        // A band: each sinusoid's amplitude at its frequency.
        let s = Basis::Band(10.0).shape(&[3.0, 4.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(s.x.len(), 5);
        assert!((s.x[2] - 10.0).abs() < 1e-12 && (s.y[0] - 5.0).abs() < 1e-12);
        // Hats: the coefficients at their knots, the never-reached knot left out.
        let s = Basis::Hats(vec![0.0, 1.0, 1e300]).shape(&[1.0, 2.0, 3.0]);
        assert_eq!((s.x, s.y), (vec![0.0, 1.0], vec![1.0, 2.0]));
        let s = Basis::PlainAndSigned(vec![0.0, 1.0]).shape(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.y_signed, Some(vec![3.0, 4.0]));
    }

    #[test]
    fn quantile_knots_are_distinct_and_ordered() {
        let x: Vec<f64> = (0..100).map(|k| (k / 10) as f64).collect();
        let k = quantile_knots(&x, &[true; 100], 8);
        assert!(k.windows(2).all(|w| w[1] > w[0]), "{k:?}");
        assert_eq!(k[0], 0.0);
        assert_eq!(*k.last().unwrap(), 9.0);
    }
}
