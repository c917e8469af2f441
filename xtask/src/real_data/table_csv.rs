//! Reading plain numeric CSV tables (header row, then numbers) by column name, for data sets
//! whose layout is not a motor log (stacked steady-state runs, several motors per file).
//! Errors name the file, the line and the column.
use anyhow::{anyhow, bail, Context, Result};
use std::path::Path;

/// A numeric table: column names and columns.
#[derive(Debug, Clone)]
pub struct Table {
    pub names: Vec<String>,
    pub cols: Vec<Vec<f64>>,
}

impl Table {
    /// Read a comma-separated table; every field must be a finite number.
    pub fn read(path: &Path) -> Result<Table> {
        let p = path.display();
        let text = std::fs::read_to_string(path).with_context(|| format!("{p}: cannot read"))?;
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let names: Vec<String> = rdr
            .headers()
            .map_err(|e| anyhow!("{p}:1: cannot read the header row: {e}"))?
            .iter()
            .map(str::to_string)
            .collect();
        let mut cols = vec![Vec::new(); names.len()];
        for rec in rdr.records() {
            let rec = rec.map_err(|e| {
                let line = e.position().map(|q| q.line()).unwrap_or(0);
                anyhow!("{p}:{line}: {e}")
            })?;
            let line = rec.position().map(|q| q.line()).unwrap_or(0);
            if rec.len() != names.len() {
                bail!(
                    "{p}:{line}: {} fields, but the header has {}",
                    rec.len(),
                    names.len()
                );
            }
            for (c, f) in rec.iter().enumerate() {
                let v: f64 = f
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or_else(|| {
                        anyhow!("{p}:{line}: column '{}': '{f}' is not a number", names[c])
                    })?;
                cols[c].push(v);
            }
        }
        if cols.first().is_none_or(|c| c.is_empty()) {
            bail!("{p}: no data rows");
        }
        Ok(Table { names, cols })
    }

    /// A column by name, or an error naming the file and the columns it has.
    pub fn col(&self, name: &str, path: &Path) -> Result<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|k| self.cols[k].as_slice())
            .ok_or_else(|| {
                anyhow!(
                    "{}:1: missing column '{name}'; the header has: {}",
                    path.display(),
                    self.names.join(", ")
                )
            })
    }
}

/// The runs of equal set-point in `sp`, each as (set-point, the sample range kept): the first
/// `skip_fraction` of every run (rounded) is dropped as the controller's transient.
pub fn plateaus(sp: &[f64], skip_fraction: f64) -> Vec<(f64, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..=sp.len() {
        if k == sp.len() || sp[k] != sp[start] {
            let s = start + (skip_fraction * (k - start) as f64).round() as usize;
            out.push((sp[start], s..k));
            start = k;
        }
    }
    out
}

/// Mean and standard deviation.
pub fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len().max(1) as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|a| (a - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, v.sqrt())
}
