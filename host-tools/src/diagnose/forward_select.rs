//! Forward selection of missing effects in one equation: starting from the model's own
//! columns (the base), add the candidate effect that removes the most residual, while it is
//! significant (the entry test: the jackknifed cluster-robust Wald test of its columns beyond
//! the base, on disjoint windows clustered by held input, at the family's per-test level),
//! relevant (a share of the base residual; a second inertia also a torque above the floor of
//! `MIN_TORQUE_FRACTION`), favoured by BIC and physically plausible; one variant per effect
//! kind.
//!
//! Why a robust entry test: a correct model's residual is far noisier in the windows of a
//! slip or an input step than elsewhere, and the windows of one held input share one error
//! of the angle's reading (`docs/decisions/0011-robust-wald-verdict.md`). A nested-model
//! F-test counts such windows as independent evidence of equal weight, and a column that
//! lives in a few of them (a resonance excited by the steps, a dead angle after reversals)
//! passes it on a correct model.
use super::candidates::{self, Equation, Units};
use super::{
    explain, plausible, EqData, Finding, Options, Tested, MAX_FINDINGS, MIN_TORQUE_FRACTION,
    PRESLIDING_GAIN,
};
use crate::effect_spec::EffectSpec;
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
    /// Effects left after the findings that pass every rule but the share of the residual
    /// ([`Problem::small`]): significant, too small to name.
    pub small: Vec<Small>,
}

/// A candidate left after the findings whose entry test rejects at the per-test level, with
/// a lower BIC and physical parameters, that explains less than the smallest share of the
/// model's residual a finding must: the model misses something the data show, too small for
/// its name or spec to be taken as an estimate.
#[derive(Debug, Clone)]
pub(super) struct Small {
    /// The effect kind whose column it is (the column, not a claim that this is the physics).
    pub name: String,
    /// Its entry test's p-value and Hotelling's `T²`.
    pub p_value: f64,
    pub t2: f64,
    /// Fraction of the model's own residual sum of squares it removes.
    pub share: f64,
}

/// The entry test of a candidate against the current base.
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// Hotelling's `T²` of the candidate's coefficients ([`statistics::robust_wald_test`]);
    /// NaN when the test cannot decide on this log.
    t2: f64,
    /// Its p-value; 1 when the test cannot decide.
    p_value: f64,
    /// Fraction of the current residual sum of squares the candidate removes (every row).
    explained: f64,
    /// Change of BIC with the effective sample size (negative: the larger model is better).
    delta_bic: f64,
}

/// The candidate that won its kind in one round: its index in `data.cand`, the residual sum
/// of squares with it, and its entry test against the current base.
type Best = (usize, f64, Entry);

/// One equation's columns (base, then every candidate's) and their Gram matrix.
struct Problem<'a> {
    data: &'a EqData,
    all_cols: Vec<Vec<f64>>,
    /// Indices into `all_cols` of each candidate's columns.
    cand_idx: Vec<Vec<usize>>,
    gram: Gram,
    units: Units,
}

impl<'a> Problem<'a> {
    fn new(data: &'a EqData, units: Units) -> Problem<'a> {
        let mut all_cols: Vec<Vec<f64>> = data.base_cols.clone();
        let mut cand_idx: Vec<Vec<usize>> = Vec::new();
        for (_, cols) in &data.cand {
            let start = all_cols.len();
            all_cols.extend(cols.iter().cloned());
            cand_idx.push((start..start + cols.len()).collect());
        }
        let gram = Gram::new(&all_cols, &data.y);
        Problem {
            data,
            all_cols,
            cand_idx,
            gram,
            units,
        }
    }

    /// The base with candidate `ci` added.
    fn with(&self, base: &[usize], ci: usize) -> Vec<usize> {
        let mut subset = base.to_vec();
        subset.extend(&self.cand_idx[ci]);
        subset
    }

    /// `y` minus the fit of `subset` with coefficients `beta`.
    fn resid_of(&self, subset: &[usize], beta: &[f64]) -> Vec<f64> {
        let mut r = self.data.y.clone();
        for (j, b) in subset.iter().zip(beta) {
            for (v, c) in r.iter_mut().zip(&self.all_cols[*j]) {
                *v -= b * c;
            }
        }
        r
    }

    /// The spec candidate `ci` gets when added to `base`.
    fn spec_for(&self, base: &[usize], ci: usize) -> EffectSpec {
        let (beta, _) = self.gram.fit(&self.with(base, ci));
        candidates::spec_of(&self.data.cand[ci].0, &beta[base.len()..], self.units)
    }

    /// Size of candidate `ci`'s torque [N·m] when added to `base`: RMS over the samples of
    /// its fitted term (load friction's column is only its braking part: its size is its
    /// whole torque).
    fn size_of(&self, base: &[usize], ci: usize) -> f64 {
        let (beta, _) = self.gram.fit(&self.with(base, ci));
        let v = &self.data.cand[ci].0;
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
        self.units.mech_scale * (ss / n.max(1) as f64).sqrt()
    }

    /// The entry test of candidate `ci` beyond `base`: the jackknifed cluster-robust Wald
    /// test ([`statistics::robust_test_beyond`], leverage cap
    /// [`statistics::ENTRY_LEVERAGE_CAP`]) clustered by held input, on disjoint windows. The
    /// weak-form windows overlap by half, so the rows of one parity tile the log without
    /// sharing a sample, and either tiling is a valid test; an effect that lives in a few
    /// windows (cogging in the slowest stretches) shows more in the tiling whose windows
    /// centre on them, so both are tested and the smaller p-value, doubled (Bonferroni over
    /// the two), is the test's. `rss_cur` and `rss1` are the residual sums of squares without
    /// and with the candidate on every row, `n_eff` their effective sample size (for BIC).
    fn entry_test(&self, base: &[usize], ci: usize, rss_cur: f64, rss1: f64, n_eff: f64) -> Entry {
        let tiling = |parity: usize| {
            let rows =
                |c: &[f64]| -> Vec<f64> { c.iter().skip(parity).step_by(2).copied().collect() };
            let y = rows(&self.data.y);
            let null: Vec<Vec<f64>> = base.iter().map(|&j| rows(&self.all_cols[j])).collect();
            let null_refs: Vec<&[f64]> = null.iter().map(|c| c.as_slice()).collect();
            let cols: Vec<Vec<f64>> = self.cand_idx[ci]
                .iter()
                .map(|&j| rows(&self.all_cols[j]))
                .collect();
            let cluster: Vec<usize> = self
                .data
                .cluster
                .iter()
                .skip(parity)
                .step_by(2)
                .copied()
                .collect();
            statistics::robust_test_beyond(
                &y,
                &null_refs,
                &cols,
                &cluster,
                statistics::ENTRY_LEVERAGE_CAP,
            )
            .0
        };
        let test = [tiling(0), tiling(1)]
            .into_iter()
            .flatten()
            .min_by(|a, b| a.p_value.total_cmp(&b.p_value));
        let explained = if rss_cur > 0.0 {
            ((rss_cur - rss1) / rss_cur).clamp(0.0, 1.0)
        } else {
            0.0
        };
        Entry {
            t2: test.map_or(f64::NAN, |t| t.t2),
            p_value: test.map_or(1.0, |t| (2.0 * t.p_value).min(1.0)),
            explained,
            delta_bic: statistics::delta_bic(rss_cur, rss1, self.cand_idx[ci].len(), n_eff),
        }
    }

    /// The best variant of every kind not chosen yet, tested against `base` (residual sum of
    /// squares `rss_cur`, effective sample size `n_eff`).
    fn best_by_kind(
        &self,
        base: &[usize],
        chosen: &[EffectKind],
        rss_cur: f64,
        n_eff: f64,
    ) -> Vec<Best> {
        // The best variant of each kind by its score: (index, rss with it, score).
        let mut best: Vec<(usize, f64)> = Vec::new();
        let mut kind_score: Vec<f64> = Vec::new();
        for (ci, (v, _)) in self.data.cand.iter().enumerate() {
            if chosen.contains(&v.kind) {
                continue;
            }
            let subset = self.with(base, ci);
            let (b1, rss1) = self.gram.fit(&subset);
            // A presliding column is the bristles' own torque: a gain far from 1 means it
            // stands for something else (see `PRESLIDING_GAIN`).
            if v.kind == EffectKind::Presliding
                && !b1.last().is_some_and(|g| {
                    (1.0 / PRESLIDING_GAIN..=PRESLIDING_GAIN).contains(&(g * self.units.mech_scale))
                })
            {
                continue;
            }
            // Cogging harmonics compete by leave-one-out: a high harmonic's column lives in
            // the few slow windows, where it can fit one window's error (see
            // the `diagnose::harmonics` module doc).
            let score = if v.kind == EffectKind::Cogging {
                let cols: Vec<&[f64]> = subset
                    .iter()
                    .map(|&j| self.all_cols[j].as_slice())
                    .collect();
                crate::numerics::least_squares::leave_one_out_rss(&cols, &self.data.y)
            } else {
                rss1
            };
            match best
                .iter()
                .position(|(j, _)| self.data.cand[*j].0.kind == v.kind)
            {
                Some(k) if kind_score[k] <= score => {}
                Some(k) => (best[k], kind_score[k]) = ((ci, rss1), score),
                None => {
                    best.push((ci, rss1));
                    kind_score.push(score);
                }
            }
        }
        best.into_iter()
            .map(|(ci, rss1)| (ci, rss1, self.entry_test(base, ci, rss_cur, rss1, n_eff)))
            .collect()
    }

    /// The first round's tests, for tables: every kind's best variant against the base.
    fn first_round(&self, base: &[usize], best: &[Best]) -> Vec<Tested> {
        best.iter()
            .map(|(ci, _, t)| Tested {
                name: self.data.cand[*ci].0.kind.name().to_string(),
                equation: self.data.eq,
                spec: self.spec_for(base, *ci).to_string(),
                explained: t.explained,
                p_value: t.p_value,
                kept: false,
            })
            .collect()
    }

    /// Whether `(ci, rss1, t)` passes every rule of [`Problem::pick`] but the share of the
    /// residual.
    fn significant(&self, st: &State, (ci, _, t): &Best, alpha: f64) -> bool {
        t.p_value < alpha
            && t.delta_bic < 0.0
            && plausible(&self.spec_for(&st.base, *ci))
            && (self.data.cand[*ci].0.kind != EffectKind::Compliance
                || self.size_of(&st.base, *ci) >= st.min_torque)
    }

    /// The candidates of the last round that are significant ([`Problem::significant`]) but
    /// remove less than `min_explained` of the model's own residual `rss0`, most significant
    /// first.
    fn small(&self, st: &State, best: &[Best], alpha: f64, min_explained: f64) -> Vec<Small> {
        let mut out: Vec<Small> = best
            .iter()
            .filter(|b| self.significant(st, b, alpha))
            .filter(|(_, rss1, _)| (st.rss_cur - rss1) < min_explained * st.rss0)
            .map(|(ci, rss1, t)| Small {
                name: self.data.cand[*ci].0.kind.name().to_string(),
                p_value: t.p_value,
                t2: t.t2,
                share: if st.rss0 > 0.0 {
                    ((st.rss_cur - rss1) / st.rss0).max(0.0)
                } else {
                    0.0
                },
            })
            .collect();
        out.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
        out
    }

    /// The candidate to add: the one removing the most residual among those significant,
    /// relevant (against the model's own residual `rss0`: an effect that removes 2 % of what
    /// is left after larger findings may still change the model's fit by a fraction of a
    /// percent), favoured by BIC and physically plausible; a second inertia on a coupling
    /// also at least `min_torque` (see `MIN_TORQUE_FRACTION`).
    fn pick(&self, st: &State, best: &[Best], alpha: f64, min_explained: f64) -> Option<Best> {
        best.iter()
            .filter(|b| {
                (st.rss_cur - b.1) >= min_explained * st.rss0 && self.significant(st, b, alpha)
            })
            .max_by(|a, b| b.1.total_cmp(&a.1))
            .copied()
    }

    /// The finding candidate `ci` makes when added to `st.base`.
    fn finding(&self, st: &State, (ci, rss1, t): Best) -> Added {
        let v = &self.data.cand[ci].0;
        let subset = self.with(&st.base, ci);
        let (beta, _) = self.gram.fit(&subset);
        let spec = candidates::spec_of(v, &beta[st.base.len()..], self.units);
        let score = if st.rss0 > 0.0 {
            (st.rss_cur - rss1) / st.rss0
        } else {
            0.0
        };
        let finding = Finding {
            name: v.kind.name().to_string(),
            explanation: explain(&spec, score, self.data.eq),
            spec: spec.to_string(),
            score,
            equation: self.data.eq,
            p_value: t.p_value,
            t2: t.t2,
            delta_bic: t.delta_bic,
            kind: Some(v.kind),
        };
        Added {
            finding,
            kind: v.kind,
            spec,
            subset,
            beta,
        }
    }
}

/// A candidate added to the base: its finding, spec, the new base columns and coefficients.
struct Added {
    finding: Finding,
    kind: EffectKind,
    spec: EffectSpec,
    subset: Vec<usize>,
    beta: Vec<f64>,
}

/// Where forward selection stands: the columns in the base, their residual, and the floor of
/// a relevant torque.
struct State {
    base: Vec<usize>,
    /// Residual sum of squares of the model's own structure.
    rss0: f64,
    rss_cur: f64,
    resid_cur: Vec<f64>,
    min_torque: f64,
    chosen: Vec<EffectKind>,
}

/// Relevance threshold [N·m]: from the model's Coulomb friction when it states one, else from
/// the Coulomb friction refitted in the base (a model whose fit left fc at 0 still has one);
/// see `MIN_TORQUE_FRACTION`.
fn relevance_floor(data: &EqData, beta0: &[f64], units: Units) -> f64 {
    match data.coulomb_col.and_then(|j| beta0.get(j)) {
        Some(fc) if *fc > 0.0 => MIN_TORQUE_FRACTION * fc * units.mech_scale,
        _ => data.min_torque,
    }
}

/// Select the missing effects of `data` (units: `units.r` is updated from the electrical
/// base's resistance).
pub(super) fn select(
    data: &EqData,
    opts: &Options,
    alpha_per_test: f64,
    units: &mut Units,
) -> Selection {
    let mut pb = Problem::new(data, *units);
    let base: Vec<usize> = (0..data.base_cols.len()).collect();
    let (beta0, rss0) = pb.gram.fit(&base);
    if data.eq == Equation::Electrical && beta0.first().is_some_and(|r| *r > 0.0) {
        units.r = beta0[0];
    }
    pb.units = *units;
    let base_resid = pb.resid_of(&base, &beta0);
    let n_eff_base = statistics::effective_n(&base_resid);
    let mut st = State {
        min_torque: relevance_floor(data, &beta0, pb.units),
        base,
        rss0,
        rss_cur: rss0,
        resid_cur: base_resid.clone(),
        chosen: Vec::new(),
    };
    let mut findings: Vec<Finding> = Vec::new();
    let mut first_round: Vec<Tested> = Vec::new();
    let mut small = Vec::new();
    loop {
        let n_eff = statistics::effective_n(&st.resid_cur);
        let best = pb.best_by_kind(&st.base, &st.chosen, st.rss_cur, n_eff);
        if first_round.is_empty() {
            first_round = pb.first_round(&st.base, &best);
        }
        let Some(pick) = pb.pick(&st, &best, alpha_per_test, opts.min_explained) else {
            small = pb.small(&st, &best, alpha_per_test, opts.min_explained);
            break;
        };
        let added = pb.finding(&st, pick);
        if let Some(x) = first_round
            .iter_mut()
            .find(|x| x.name == added.finding.name)
        {
            x.kept = true;
        }
        // Once Coulomb friction is found, the effects tested after it are measured against it.
        if added.kind == EffectKind::Coulomb && data.eq == Equation::Mechanical {
            let fc = added.spec.get("fc");
            if fc > 0.0 {
                st.min_torque = MIN_TORQUE_FRACTION * fc;
            }
        }
        st.chosen.push(added.kind);
        st.rss_cur = pick.1;
        st.resid_cur = pb.resid_of(&added.subset, &added.beta);
        st.base = added.subset;
        findings.push(added.finding);
        if findings.len() >= MAX_FINDINGS {
            break;
        }
    }
    Selection {
        findings,
        first_round,
        base_resid,
        final_resid: st.resid_cur,
        n_eff_base,
        base_beta: beta0,
        small,
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
        data_of(400, t0, sigma)
    }

    /// The same on `n` rows.
    fn data_of(n: usize, t0: f64, sigma: f64) -> EqData {
        let a = noise(n, 1);
        let e = noise(n, 2);
        let unrelated = noise(n, 3);
        let y = (0..n).map(|k| 2.0 * a[k] + t0 + sigma * e[k]).collect();
        let mut d = EqData::new(Equation::Mechanical, y, (0..n).collect());
        d.base_cols = vec![a];
        d.cand = vec![
            variant(EffectKind::Offset, vec![1.0; n]),
            variant(EffectKind::Viscous, unrelated),
        ];
        d
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
        // The base fit lacks the offset, which leaks into the slope by 0.5·mean(a)/var(a):
        // mean(a) over 400 draws is about ±0.03, so a few hundredths, against a standard
        // error of 2.5e-3; 0.1 covers both.
        assert!((out.base_beta[0] - 2.0).abs() < 0.1, "{:?}", out.base_beta);
        let rss = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
        // Noise variance 0.05²/3 ≈ 8e-4 against 0.25 for the offset: the ratio is about
        // 3e-3, and 0.05 would still hold with most of the offset left over.
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
        assert!(out.small.is_empty(), "{:?}", out.small);
        // White noise: n_eff is near n = 400; under 100 would mean a correlation time of
        // four samples, which this residual does not have.
        assert!(out.n_eff_base > 100.0, "{}", out.n_eff_base);
    }

    /// An offset that explains about 1.2 % of the residual on 4000 rows: below the share a
    /// finding must explain, far beyond the entry level. It is not named, and it is left as
    /// a small effect.
    #[test]
    fn a_significant_but_small_effect_is_left_unnamed() {
        // Uniform noise of variance 1/3: an offset t0 explains t0²/(t0² + 1/3) of the base
        // residual, 1.2 % at t0 = 0.064; on each tiling's 2000 rows its t-statistic is about
        // √(2000·0.012) ≈ 4.9 (p near 1e-6), so a test that fails to reject at 1e-3 would be
        // a 3-σ draw.
        let out = select(
            &data_of(4000, 0.064, 1.0),
            &Options::default(),
            1e-3,
            &mut units(),
        );
        assert!(out.findings.is_empty(), "{:?}", out.findings);
        let names: Vec<&str> = out.small.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["offset"], "{:?}", out.small);
        let e = &out.small[0];
        assert!(e.p_value < 1e-3 && e.share > 0.0 && e.share < 0.02, "{e:?}");
    }

    #[test]
    fn a_significant_effect_is_reported_whatever_its_torque() {
        let mut d = data(0.5, 0.05);
        d.min_torque = 1.0;
        let out = select(&d, &Options::default(), 1e-3, &mut units());
        let names: Vec<&str> = out.findings.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["offset"]);
    }

    #[test]
    fn a_second_inertia_below_the_torque_floor_is_not_reported() {
        let mut d = data(0.5, 0.05);
        d.cand[0].0.kind = EffectKind::Compliance;
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
