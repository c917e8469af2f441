//! Forward selection of missing effects in one equation: starting from the model's own
//! columns (the base), add the candidate effect that removes the most residual, while it is
//! significant (F-test at the family's per-test level with the residual's effective sample
//! size), relevant (a share of the base residual and a torque above the relevance floor),
//! favoured by BIC and physically plausible; one variant per effect kind.
use super::candidates::{self, Equation, Units};
use super::harmonics;
use super::{
    explain, plausible, EqData, Finding, Options, Tested, MAX_FINDINGS, MIN_TORQUE_FRACTION,
    PRESLIDING_GAIN,
};
use crate::numerics::least_squares::Gram;
use crate::numerics::statistics;
use control::effects::EffectKind;

/// What forward selection found in one equation.
pub(super) struct Selection {
    /// Effects added, in the order chosen.
    pub findings: Vec<Finding>,
    /// The best variant of every effect kind tested against the base, kept or not.
    pub first_round: Vec<Tested>,
    /// Residual of the base alone (the model as given, its coefficients refitted).
    pub base_resid: Vec<f64>,
    /// Residual after the findings.
    pub final_resid: Vec<f64>,
    /// Effective sample size of the base residual.
    pub n_eff_base: f64,
    /// Coefficients of the base columns.
    pub base_beta: Vec<f64>,
}

/// Select the missing effects of `data` (units: `units.r` is updated from the electrical
/// base's resistance).
pub(super) fn select(
    data: &EqData,
    opts: &Options,
    alpha_per_test: f64,
    units: &mut Units,
) -> Selection {
    let mut all_cols: Vec<Vec<f64>> = data.base_cols.clone();
    let mut cand_idx: Vec<Vec<usize>> = Vec::new();
    for (_, cols) in &data.cand {
        let start = all_cols.len();
        all_cols.extend(cols.iter().cloned());
        cand_idx.push((start..start + cols.len()).collect());
    }
    let gram = Gram::new(&all_cols, &data.y);
    let mut base: Vec<usize> = (0..data.base_cols.len()).collect();
    let (beta0, rss0) = gram.fit(&base);
    if data.eq == Equation::Electrical && beta0.first().is_some_and(|r| *r > 0.0) {
        units.r = beta0[0];
    }
    let units = *units;
    let resid_of = |subset: &[usize], beta: &[f64]| -> Vec<f64> {
        let mut r = data.y.clone();
        for (j, b) in subset.iter().zip(beta) {
            for (v, c) in r.iter_mut().zip(&all_cols[*j]) {
                *v -= b * c;
            }
        }
        r
    };
    let base_resid = resid_of(&base, &beta0);
    let n_eff_base = statistics::effective_n(&base_resid);
    // Relevance threshold: from the model's Coulomb friction when it states one, else from the
    // Coulomb friction refitted here (a model whose fit left fc at 0 still has one) or, once
    // Coulomb friction is found, from the one found (see `MIN_TORQUE_FRACTION`).
    let mut min_torque = data.min_torque;
    if let Some(fc) = data.coulomb_col.and_then(|j| beta0.get(j)) {
        if *fc > 0.0 {
            min_torque = MIN_TORQUE_FRACTION * fc * units.mech_scale;
        }
    }

    // Best variant per effect kind, tested against the current base.
    let mut chosen_kinds: Vec<EffectKind> = Vec::new();
    let mut findings = Vec::new();
    let mut first_round: Vec<Tested> = Vec::new();
    let mut rss_cur = rss0;
    let mut resid_cur = base_resid.clone();
    loop {
        let n_eff = statistics::effective_n(&resid_cur);
        let mut best_by_kind: Vec<(usize, f64, statistics::FTest)> = Vec::new();
        let mut kind_score: Vec<f64> = Vec::new();
        for (ci, (v, _)) in data.cand.iter().enumerate() {
            if chosen_kinds.contains(&v.kind) {
                continue;
            }
            let mut subset = base.clone();
            subset.extend(&cand_idx[ci]);
            let (b1, rss1) = gram.fit(&subset);
            // A presliding column is the bristles' own torque: a gain far from 1 means it
            // stands for something else (see `PRESLIDING_GAIN`).
            if v.kind == EffectKind::Presliding
                && !b1.last().is_some_and(|g| {
                    (1.0 / PRESLIDING_GAIN..=PRESLIDING_GAIN).contains(&(g * units.mech_scale))
                })
            {
                continue;
            }
            let t = statistics::f_test(rss_cur, rss1, cand_idx[ci].len(), base.len(), n_eff);
            // Cogging harmonics compete by leave-one-out: a high harmonic's column lives in
            // the few slow windows, where it can fit one window's error (see
            // `harmonics::leave_one_out_rss`).
            let score = if v.kind == EffectKind::Cogging {
                let cols: Vec<&[f64]> = subset.iter().map(|&j| all_cols[j].as_slice()).collect();
                harmonics::leave_one_out_rss(&cols, &data.y)
            } else {
                rss1
            };
            match best_by_kind
                .iter()
                .position(|(j, _, _)| data.cand[*j].0.kind == v.kind)
            {
                Some(k) if kind_score[k] <= score => {}
                Some(k) => (best_by_kind[k], kind_score[k]) = ((ci, rss1, t), score),
                None => {
                    best_by_kind.push((ci, rss1, t));
                    kind_score.push(score);
                }
            }
        }
        if first_round.is_empty() {
            for (ci, _, t) in &best_by_kind {
                let v = &data.cand[*ci].0;
                let mut subset = base.clone();
                subset.extend(&cand_idx[*ci]);
                let (beta, _) = gram.fit(&subset);
                first_round.push(Tested {
                    name: v.kind.name().to_string(),
                    equation: data.eq,
                    spec: candidates::spec_of(v, &beta[base.len()..], units).to_string(),
                    explained: t.explained,
                    p_value: t.p_value,
                    kept: false,
                });
            }
        }
        let spec_for = |ci: usize| {
            let mut subset = base.clone();
            subset.extend(&cand_idx[ci]);
            let (beta, _) = gram.fit(&subset);
            candidates::spec_of(&data.cand[ci].0, &beta[base.len()..], units)
        };
        // Size of the effect's torque [N·m]: RMS over the samples of its fitted term.
        let size_of = |ci: usize| {
            let mut subset = base.clone();
            subset.extend(&cand_idx[ci]);
            let (beta, _) = gram.fit(&subset);
            let v = &data.cand[ci].0;
            // Load friction's column is only its braking part: its size is its whole torque.
            let cols = v
                .torque
                .as_ref()
                .map_or(&v.columns[..], std::slice::from_ref);
            let n = cols.first().map_or(0, |c| c.len());
            let mut ss = 0.0;
            for k in 0..n {
                let v: f64 = cols
                    .iter()
                    .zip(&beta[base.len()..])
                    .map(|(c, b)| b * c[k])
                    .sum();
                ss += v * v;
            }
            units.mech_scale * (ss / n.max(1) as f64).sqrt()
        };
        let Some(&(ci, rss1, t)) = best_by_kind
            .iter()
            .filter(|(ci, rss1, t)| {
                // Relevance is measured against the model's own residual (rss0): an effect
                // that removes 2 % of what is left after larger findings may still change the
                // model's fit by a fraction of a percent.
                t.p_value < alpha_per_test
                    && (rss_cur - rss1) >= opts.min_explained * rss0
                    && t.delta_bic < 0.0
                    && plausible(&spec_for(*ci))
                    && (data.eq != Equation::Mechanical || size_of(*ci) >= min_torque)
            })
            .max_by(|a, b| b.1.total_cmp(&a.1))
        else {
            break;
        };
        let v = &data.cand[ci].0;
        let mut subset = base.clone();
        subset.extend(&cand_idx[ci]);
        let (beta, _) = gram.fit(&subset);
        let spec = candidates::spec_of(v, &beta[base.len()..], units);
        let score = if rss0 > 0.0 {
            (rss_cur - rss1) / rss0
        } else {
            0.0
        };
        findings.push(Finding {
            name: v.kind.name().to_string(),
            explanation: explain(&spec, score, data.eq),
            spec: spec.to_string(),
            score,
            equation: data.eq,
            p_value: t.p_value,
            f: t.f,
            delta_bic: t.delta_bic,
            kind: Some(v.kind),
        });
        if let Some(x) = first_round.iter_mut().find(|x| x.name == v.kind.name()) {
            x.kept = true;
        }
        if v.kind == EffectKind::Coulomb && data.eq == Equation::Mechanical {
            let fc = spec.get("fc");
            if fc > 0.0 {
                min_torque = MIN_TORQUE_FRACTION * fc;
            }
        }
        chosen_kinds.push(v.kind);
        base = subset;
        rss_cur = rss1;
        resid_cur = resid_of(&base, &beta);
        if findings.len() >= MAX_FINDINGS {
            break;
        }
    }
    Selection {
        findings,
        first_round,
        base_resid,
        final_resid: resid_cur,
        n_eff_base,
        base_beta: beta0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::Variant;

    /// A deterministic pseudo-random sequence in [-1, 1).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    fn variant(kind: EffectKind, col: Vec<f64>) -> (Variant, Vec<Vec<f64>>) {
        let v = Variant {
            kind,
            equation: Equation::Mechanical,
            fixed: vec![],
            columns: vec![col.clone()],
            torque: None,
        };
        (v, vec![col])
    }

    /// A torque equation `y = 2·a + t0 + e` with the base column `a`, an offset candidate
    /// (ones) and a viscous candidate unrelated to `y`.
    fn data(t0: f64, sigma: f64) -> EqData {
        let n = 400;
        let a = noise(n, 1);
        let e = noise(n, 2);
        let unrelated = noise(n, 3);
        let y = (0..n).map(|k| 2.0 * a[k] + t0 + sigma * e[k]).collect();
        EqData {
            eq: Equation::Mechanical,
            y,
            base_cols: vec![a],
            base_sample: vec![],
            min_torque: 0.0,
            coulomb_col: None,
            cand: vec![
                variant(EffectKind::Offset, vec![1.0; n]),
                variant(EffectKind::Viscous, unrelated),
            ],
        }
    }

    fn units() -> Units {
        Units {
            r: 1.0,
            kt: 1.0,
            mech_scale: 1.0,
        }
    }

    #[test]
    fn a_present_effect_is_found_with_its_size() {
        let out = select(&data(0.5, 0.05), &Options::default(), 1e-3, &mut units());
        let names: Vec<&str> = out.findings.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["offset"]);
        let spec = crate::effect_spec::EffectSpec::parse(&out.findings[0].spec).unwrap();
        // Least squares on 400 samples of noise 0.05·U(-1,1): t0 within a few of its
        // standard errors (0.05/√3/√400 ≈ 1.4e-3).
        assert!(
            (spec.get("t0") - 0.5).abs() < 0.01,
            "{}",
            out.findings[0].spec
        );
        assert!((out.base_beta[0] - 2.0).abs() < 0.1, "{:?}", out.base_beta);
        let rss = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
        assert!(rss(&out.final_resid) < 0.05 * rss(&out.base_resid));
        // Both kinds were tested in the first round; only the offset was kept.
        assert_eq!(out.first_round.len(), 2);
        assert!(out
            .first_round
            .iter()
            .all(|t| t.kept == (t.name == "offset")));
    }

    #[test]
    fn nothing_is_found_where_nothing_is_missing() {
        let out = select(&data(0.0, 0.05), &Options::default(), 1e-3, &mut units());
        assert!(out.findings.is_empty(), "{:?}", out.findings);
        assert!(out.n_eff_base > 100.0, "{}", out.n_eff_base);
    }

    #[test]
    fn an_effect_below_the_torque_floor_is_not_reported() {
        let mut d = data(0.5, 0.05);
        d.min_torque = 1.0;
        let out = select(&d, &Options::default(), 1e-3, &mut units());
        assert!(out.findings.is_empty(), "{:?}", out.findings);
    }

    #[test]
    fn an_implausible_sign_is_not_reported() {
        // A viscous friction that feeds energy in (b < 0) explains the data but is no
        // physical friction.
        let mut d = data(0.0, 0.05);
        let w = noise(d.y.len(), 4);
        for (y, w) in d.y.iter_mut().zip(&w) {
            *y -= 0.8 * w;
        }
        d.cand[1] = variant(EffectKind::Viscous, w);
        let out = select(&d, &Options::default(), 1e-3, &mut units());
        assert!(
            out.findings.iter().all(|f| f.name != "viscous"),
            "{:?}",
            out.findings
        );
    }
}
