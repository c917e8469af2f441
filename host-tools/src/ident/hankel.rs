//! Hidden friction state from a time-delay (Hankel) embedding of the velocity, the reference
//! paper's internal-state extraction (its eqs. 29–31.2): build the Hankel matrix of the
//! velocity with `m` delays, take its SVD, keep only the low-energy singular components and
//! use the first row of the reconstruction `Ĥ = U Σ̂ Vᵀ` as the hidden state `z`.
//!
//! # How it is computed (fast, exact)
//! With `H[k, j] = ω[j + k]` (`m` rows, `n = N − m + 1` columns) and `U_low` the left singular
//! vectors kept, `Ĥ = U Σ̂ Vᵀ = U_low U_lowᵀ H = P H`. So row 0 of `Ĥ` is a fixed FIR filter of
//! the velocity: `z[j] = Σ_k P[0, k]·ω[j + k]`. `U` and `σ` come from the eigen-decomposition
//! of the `m × m` Gram matrix `H Hᵀ` (`σ_k = sqrt(λ_k)`), which is built in `O(N·m)` from
//! shifted dot products: `G[0, d] = Σ_j ω[j]·ω[j + d]`, then along each diagonal
//! `G[k+1, l+1] = G[k, l] − ω[k]·ω[l] + ω[n + k]·ω[n + l]`. The `N × m` matrix is never formed.
//! A test checks this against faer's thin SVD of `H`.
//!
//! `P` does not depend on the signs faer picks for the singular vectors (each `u_k u_kᵀ` is
//! sign-free), so `z` needs no sign convention. Accuracy limit of the Gram route: singular
//! values below ~1e-7·σ_max lose relative accuracy (the Gram matrix squares the condition
//! number); the projection onto the selected subspace is unaffected when the selection
//! boundary lies in a spectral gap, as it does for motor data.
//!
//! # The last `m − 1` samples
//! `H` has columns only for `j ≤ N − m`. For the tail `t = N − m + k` (`k = 1..m−1`) we use the
//! reconstruction of the last column, row `k`: `z[t] = Σ_l P[k, l]·ω[N − m + l]`, the same
//! projection read at a later delay, so `z` has one value per sample.
use anyhow::{bail, Context, Result};
use faer::{Mat, Side};
use std::path::Path;

/// Number of delays of the paper (its §4.3: "the order of delay embedding (m) was selected as 60").
pub const DEFAULT_DELAYS: usize = 60;
/// Energy threshold of the paper: high-energy singular values are those with
/// `σ_k / Σσ > 0.001` (its §4.3); the rest are kept.
pub const DEFAULT_ENERGY: f64 = 0.001;

/// Which singular components make the hidden state.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// Every component whose energy `σ_k / Σσ` is below this value (paper: 0.001).
    EnergyBelow(f64),
    /// Components `lo..=hi`, 1-based as in the paper (its choice: 31..=60).
    Range(usize, usize),
}

impl Default for Selection {
    fn default() -> Self {
        Selection::EnergyBelow(DEFAULT_ENERGY)
    }
}

/// A fitted delay embedding: the singular spectrum and the projection filter.
#[derive(Debug, Clone, PartialEq)]
pub struct HankelEmbedding {
    m: usize,
    sigma: Vec<f64>,
    lo: usize,
    hi: usize,
    /// Projection `P = U_low U_lowᵀ`, row-major `m × m`.
    proj: Vec<f64>,
}

/// Dot product with 8 independent accumulators so that it vectorises.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// The Gram matrix `H Hᵀ` (`m × m`, full, row-major) of the `m`-delay Hankel matrix of `w`.
pub fn gram(w: &[f64], m: usize) -> Vec<f64> {
    let n = w.len() + 1 - m;
    let mut g = vec![0.0; m * m];
    for d in 0..m {
        g[d] = dot(&w[..n], &w[d..d + n]);
    }
    for k in 1..m {
        for l in k..m {
            let v = g[(k - 1) * m + (l - 1)] - w[k - 1] * w[l - 1] + w[n + k - 1] * w[n + l - 1];
            g[k * m + l] = v;
        }
    }
    for k in 0..m {
        for l in 0..k {
            g[k * m + l] = g[l * m + k];
        }
    }
    g
}

impl HankelEmbedding {
    /// Fit the embedding to the velocity `omega` with `m` delays.
    ///
    /// Errors: fewer than `2·m` samples, a non-finite or constant signal, a selection that
    /// is empty or outside `1..=m`.
    pub fn fit(omega: &[f64], m: usize, selection: Selection) -> Result<Self> {
        if m < 2 {
            bail!("delay embedding: the number of delays must be 2 or more (got {m})");
        }
        if omega.len() < 2 * m {
            bail!(
                "delay embedding: {} samples are too few for {m} delays (need at least {})",
                omega.len(),
                2 * m
            );
        }
        if let Some(i) = omega.iter().position(|v| !v.is_finite()) {
            bail!("delay embedding: velocity sample {i} is not a finite number");
        }
        let (lo_v, hi_v) = omega
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if hi_v - lo_v <= 1e-12 * hi_v.abs().max(lo_v.abs()).max(1e-300) {
            bail!("delay embedding: the velocity is constant; there is no dynamics to embed");
        }
        let g = gram(omega, m);
        let gm = Mat::<f64>::from_fn(m, m, |i, j| g[i * m + j]);
        let evd = gm
            .self_adjoint_eigen(Side::Lower)
            .map_err(|e| anyhow::anyhow!("delay embedding: eigen-decomposition failed: {e:?}"))?;
        // faer sorts eigenvalues ascending; singular values are wanted descending.
        let s = evd.S().column_vector();
        let u = evd.U();
        let order: Vec<usize> = (0..m).rev().collect();
        let sigma: Vec<f64> = order.iter().map(|&i| s[i].max(0.0).sqrt()).collect();
        let total: f64 = sigma.iter().sum();
        let (lo, hi) = match selection {
            Selection::Range(lo, hi) => {
                if lo < 1 || hi > m || lo > hi {
                    bail!("delay embedding: component range {lo}..{hi} must lie within 1..{m}");
                }
                (lo, hi)
            }
            Selection::EnergyBelow(e) => {
                if !(e > 0.0 && e < 1.0) {
                    bail!("delay embedding: energy threshold must be between 0 and 1 (got {e})");
                }
                let first = sigma.iter().position(|&s| s / total < e).with_context(|| {
                    format!(
                        "delay embedding: no singular value has energy below {e}; choose a \
                         component range instead"
                    )
                })?;
                (first + 1, m)
            }
        };
        let mut proj = vec![0.0; m * m];
        for &c in &order[lo - 1..hi] {
            for a in 0..m {
                let ua = u[(a, c)];
                for b in 0..m {
                    proj[a * m + b] += ua * u[(b, c)];
                }
            }
        }
        Ok(HankelEmbedding {
            m,
            sigma,
            lo,
            hi,
            proj,
        })
    }

    /// Number of delays `m`.
    pub fn delays(&self) -> usize {
        self.m
    }

    /// Singular values of the Hankel matrix, descending.
    pub fn spectrum(&self) -> &[f64] {
        &self.sigma
    }

    /// Energies `σ_k / Σσ`, descending.
    pub fn energies(&self) -> Vec<f64> {
        let t: f64 = self.sigma.iter().sum();
        self.sigma.iter().map(|s| s / t).collect()
    }

    /// The kept components, 1-based inclusive (the paper's `k = 31..60` is `(31, 60)`).
    pub fn selected(&self) -> (usize, usize) {
        (self.lo, self.hi)
    }

    /// The FIR filter: `z[j] = Σ_k filter[k]·ω[j + k]` (row 0 of the projection).
    pub fn filter(&self) -> &[f64] {
        &self.proj[..self.m]
    }

    /// Row `k` of the projection `P = U_low U_lowᵀ`.
    pub fn projection_row(&self, k: usize) -> &[f64] {
        &self.proj[k * self.m..(k + 1) * self.m]
    }

    /// The hidden state `z` of a velocity signal (one value per sample; the last `m − 1` from
    /// the last column's lower rows, see the module doc). The signal may differ from the one
    /// the embedding was fitted to (validation data): the filter is fixed.
    pub fn extract(&self, omega: &[f64]) -> Result<Vec<f64>> {
        let m = self.m;
        let len = omega.len();
        if len < m {
            bail!("delay embedding: {len} samples are too few for {m} delays");
        }
        let n = len + 1 - m;
        let mut z = vec![0.0; len];
        let h = self.filter();
        // Blocked "one tap at a time" accumulation: each inner loop is a vectorisable axpy
        // over a block that stays in cache.
        const BLOCK: usize = 2048;
        let mut start = 0;
        while start < n {
            let end = (start + BLOCK).min(n);
            let out = &mut z[start..end];
            for (k, &c) in h.iter().enumerate() {
                let src = &omega[start + k..end + k];
                for (o, s) in out.iter_mut().zip(src) {
                    *o += c * s;
                }
            }
            start = end;
        }
        let last = &omega[n - 1..];
        for k in 1..m {
            z[n - 1 + k] = dot(self.projection_row(k), last);
        }
        Ok(z)
    }

    /// Write the singular-value spectrum as an SVG (log scale; the selected components in the
    /// palette's second colour, the dropped ones in its first),
    /// atomically.
    pub fn spectrum_svg(&self, path: &Path) -> Result<()> {
        use crate::report::svg::colour;
        use plotters::prelude::*;
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (800, 500)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
            let pos: Vec<f64> = self.sigma.iter().copied().filter(|s| *s > 0.0).collect();
            let smin = pos
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .max(1e-300);
            let smax = pos.iter().copied().fold(0.0, f64::max).max(smin * 10.0);
            let mut chart = ChartBuilder::on(&root)
                .caption(
                    format!(
                        "Singular values of the {}-delay Hankel matrix (kept: {}..{})",
                        self.m, self.lo, self.hi
                    ),
                    ("sans-serif", 20),
                )
                .margin(15)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0usize..self.m + 1, (smin / 2.0..smax * 2.0).log_scale())
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            chart
                .configure_mesh()
                .x_desc("component k")
                .y_desc("singular value σ_k")
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let pts = |sel: bool| {
                self.sigma
                    .iter()
                    .enumerate()
                    .filter(move |(k, s)| **s > 0.0 && ((k + 1 >= self.lo && *k < self.hi) == sel))
                    .map(|(k, s)| (k + 1, *s))
                    .collect::<Vec<_>>()
            };
            chart
                .draw_series(
                    pts(false)
                        .into_iter()
                        .map(|p| Circle::new(p, 3, colour(0).filled())),
                )
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label("high energy (dropped)")
                .legend(|(x, y)| Circle::new((x, y), 3, colour(0).filled()));
            chart
                .draw_series(
                    pts(true)
                        .into_iter()
                        .map(|p| Circle::new(p, 3, colour(1).filled())),
                )
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label("low energy (kept: hidden state)")
                .legend(|(x, y)| Circle::new((x, y), 3, colour(1).filled()));
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        crate::atomic::write_str(path, &svg)
    }
}

#[cfg(test)]
mod tests {
    // Tolerances of 1e-9 and 1e-8 (relative) compare one product or decomposition computed
    // two ways: float rounding on a few hundred terms.
    use super::*;

    fn signal(n: usize) -> Vec<f64> {
        // Two tones, a slow ramp-like component and deterministic pseudo-noise.
        let mut s = 12345u64;
        (0..n)
            .map(|i| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let r = ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
                let t = i as f64 * 0.012;
                10.0 * (2.0 * std::f64::consts::PI * 0.3 * t).sin()
                    + 3.0 * (2.0 * std::f64::consts::PI * 1.7 * t).cos()
                    + 0.2 * r
            })
            .collect()
    }

    #[test]
    fn gram_matches_direct_product() {
        let w = signal(300);
        let m = 12;
        let g = gram(&w, m);
        let n = w.len() + 1 - m;
        for k in 0..m {
            for l in 0..m {
                let d: f64 = (0..n).map(|j| w[j + k] * w[j + l]).sum();
                assert!(
                    (g[k * m + l] - d).abs() <= 1e-9 * d.abs().max(1.0),
                    "{k},{l}"
                );
            }
        }
    }

    #[test]
    fn fir_projection_equals_thin_svd_reconstruction() {
        let w = signal(700);
        let m = 20;
        let n = w.len() + 1 - m;
        let emb = HankelEmbedding::fit(&w, m, Selection::Range(6, 20)).unwrap();
        let h = Mat::<f64>::from_fn(m, n, |k, j| w[j + k]);
        let svd = h.thin_svd().unwrap();
        let s = svd.S().column_vector();
        for k in 0..m {
            let rel = (emb.spectrum()[k] - s[k]).abs() / s[k];
            assert!(
                rel < 1e-8,
                "σ_{k}: {} vs {} (rel {rel:e})",
                emb.spectrum()[k],
                s[k]
            );
        }
        // Ĥ = U Σ̂ Vᵀ with components 6..=20 kept.
        let (u, v) = (svd.U(), svd.V());
        let mut hhat = Mat::<f64>::zeros(m, n);
        for c in 5..20 {
            for a in 0..m {
                for j in 0..n {
                    hhat[(a, j)] += u[(a, c)] * s[c] * v[(j, c)];
                }
            }
        }
        let z = emb.extract(&w).unwrap();
        let scale = z.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(scale > 1e-6);
        for j in 0..n {
            assert!((z[j] - hhat[(0, j)]).abs() < 1e-8 * scale, "column {j}");
        }
        // Tail: rows of the last column.
        for k in 1..m {
            assert!(
                (z[n - 1 + k] - hhat[(k, n - 1)]).abs() < 1e-8 * scale,
                "tail {k}"
            );
        }
    }

    #[test]
    fn energy_selection_keeps_low_energy_tail() {
        let w = signal(2000);
        let emb = HankelEmbedding::fit(&w, 30, Selection::EnergyBelow(0.01)).unwrap();
        let e = emb.energies();
        let (lo, hi) = emb.selected();
        assert_eq!(hi, 30);
        assert!(e[lo - 1] < 0.01 && (lo == 1 || e[lo - 2] >= 0.01));
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(HankelEmbedding::fit(&[1.0; 50], 60, Selection::default()).is_err());
        let e = HankelEmbedding::fit(&[2.0; 500], 60, Selection::default()).unwrap_err();
        assert!(e.to_string().contains("constant"), "{e}");
        let w = signal(500);
        assert!(HankelEmbedding::fit(&w, 60, Selection::Range(0, 10)).is_err());
        assert!(HankelEmbedding::fit(&w, 60, Selection::Range(31, 61)).is_err());
    }

    #[test]
    fn spectrum_svg_is_written() {
        let w = signal(1000);
        let emb = HankelEmbedding::fit(&w, 20, Selection::Range(8, 20)).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("spectrum.svg");
        emb.spectrum_svg(&p).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        // The selected components are drawn in the palette's second colour.
        let c = crate::report::svg::colour(1);
        let hex = format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2);
        assert!(
            text.starts_with("<svg") && text.contains(&hex),
            "{hex} not drawn"
        );
    }
}
