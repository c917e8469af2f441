//! Motor logs: the contract's CSV format.
//!
//! ```text
//! # sample_period=0.012
//! # hall_resolution_rad=0.0951998
//! t,u,i,theta,omega
//! 0.000,0.0,0.0,0.0,0.0
//! ```
//! Optional `# key=value` metadata lines, one header row, one row per sample. Standard
//! columns `t`, `u`, `i`, `theta`, `omega` (SI units); other names are mapped with
//! `--map STD=NAME,...`; extra columns are kept. Every error names the file and the line
//! (1-based, as an editor shows it) and the column at fault.
use anyhow::{anyhow, bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What `u` means (`--plant`).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Plant {
    /// `u` is a voltage and `i` is measured (the default).
    #[default]
    Voltage,
    /// `u` is a torque or force command; no electrical equation, `i` may be absent.
    Torque,
}

/// Mapping of standard column names to the file's own names (`--map t=time_s,u=vir`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ColumnMap(pub BTreeMap<String, String>);

impl ColumnMap {
    /// The standard column names that can be mapped.
    pub const STANDARD: [&'static str; 5] = ["t", "u", "i", "theta", "omega"];

    /// Parse `STD=NAME[,STD=NAME...]`.
    pub fn parse(spec: &str) -> Result<ColumnMap> {
        let mut m = BTreeMap::new();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = part.split_once('=').ok_or_else(|| {
                anyhow!("--map: '{part}' is not of the form STD=NAME (e.g. t=time_s)")
            })?;
            let k = k.trim();
            if !Self::STANDARD.contains(&k) {
                bail!(
                    "--map: '{k}' is not a standard column; use one of {}",
                    Self::STANDARD.join(", ")
                );
            }
            m.insert(k.to_string(), v.trim().to_string());
        }
        Ok(ColumnMap(m))
    }

    /// The file's name for a standard column.
    pub fn name_of<'a>(&'a self, std: &'a str) -> &'a str {
        self.0.get(std).map(String::as_str).unwrap_or(std)
    }
}

/// A motor log in memory. All series have the same length.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MotorLog {
    /// Where it came from (for error messages and model provenance).
    pub source: PathBuf,
    /// `# key=value` metadata, in file order of keys (sorted).
    pub meta: BTreeMap<String, String>,
    pub t: Vec<f64>,
    pub u: Vec<f64>,
    pub i: Option<Vec<f64>>,
    pub theta: Vec<f64>,
    pub omega: Option<Vec<f64>>,
    /// Extra columns, kept in file order.
    pub extra: Vec<(String, Vec<f64>)>,
}

impl MotorLog {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when the log has no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// A metadata value parsed as a number.
    pub fn meta_f64(&self, key: &str) -> Option<f64> {
        self.meta.get(key).and_then(|v| v.trim().parse().ok())
    }

    /// The sample period: `# sample_period` if given, else the median time step.
    pub fn sample_period(&self) -> f64 {
        if let Some(p) = self.meta_f64("sample_period") {
            return p;
        }
        let mut d: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).collect();
        if d.is_empty() {
            return 0.0;
        }
        d.sort_by(|a, b| a.total_cmp(b));
        d[d.len() / 2]
    }

    /// An extra column by name.
    pub fn extra(&self, name: &str) -> Option<&[f64]> {
        self.extra
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// Read a log. `plant` decides whether `i` is required.
    pub fn read(path: &Path, map: &ColumnMap, plant: Plant) -> Result<MotorLog> {
        let text =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let text = String::from_utf8(text).map_err(|e| {
            anyhow!(
                "{}: not UTF-8 text (byte {})",
                path.display(),
                e.utf8_error().valid_up_to()
            )
        })?;
        Self::parse(&text, path, map, plant)
    }

    /// Parse a log from text; `path` is used in messages only.
    pub fn parse(text: &str, path: &Path, map: &ColumnMap, plant: Plant) -> Result<MotorLog> {
        let p = path.display();
        let mut meta = BTreeMap::new();
        let mut header_line = 0usize;
        let mut body_start = 0usize;
        let mut offset = 0usize;
        for (n, line) in text.split_inclusive('\n').enumerate() {
            let trimmed = line.trim();
            if let Some(rest) = trimmed.strip_prefix('#') {
                if let Some((k, v)) = rest.split_once('=') {
                    meta.insert(k.trim().to_string(), v.trim().to_string());
                }
                offset += line.len();
                continue;
            }
            if trimmed.is_empty() {
                offset += line.len();
                continue;
            }
            header_line = n + 1;
            body_start = offset;
            break;
        }
        if header_line == 0 {
            bail!("{p}: no header row (expected a line like 't,u,i,theta')");
        }
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(&text.as_bytes()[body_start..]);
        let headers: Vec<String> = rdr
            .headers()
            .map_err(|e| anyhow!("{p}:{header_line}: cannot read the header row: {e}"))?
            .iter()
            .map(str::to_string)
            .collect();
        let find = |std: &str| headers.iter().position(|h| h == map.name_of(std));
        let need = |std: &str| {
            find(std).ok_or_else(|| {
                let name = map.name_of(std);
                let hint = if name == std {
                    format!(" (map another column with --map {std}=NAME)")
                } else {
                    String::new()
                };
                anyhow!(
                    "{p}:{header_line}: missing column '{name}'{hint}; the header has: {}",
                    headers.join(", ")
                )
            })
        };
        let ci_t = need("t")?;
        let ci_u = need("u")?;
        let ci_theta = need("theta")?;
        let ci_i = match plant {
            Plant::Voltage => Some(need("i")?),
            Plant::Torque => find("i"),
        };
        let ci_omega = find("omega");
        let std_cols: Vec<usize> = [Some(ci_t), Some(ci_u), Some(ci_theta), ci_i, ci_omega]
            .into_iter()
            .flatten()
            .collect();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); headers.len()];
        let mut rec = csv::StringRecord::new();
        loop {
            let more = rdr.read_record(&mut rec).map_err(|e| {
                let line = e
                    .position()
                    .map(|q| q.line() as usize + header_line - 1)
                    .unwrap_or(0);
                anyhow!("{p}:{line}: {e}")
            })?;
            if !more {
                break;
            }
            let line = rec
                .position()
                .map(|q| q.line() as usize + header_line - 1)
                .unwrap_or(0);
            if rec.len() != headers.len() {
                bail!(
                    "{p}:{line}: {} fields, but the header has {}",
                    rec.len(),
                    headers.len()
                );
            }
            for (c, field) in rec.iter().enumerate() {
                let v: f64 = match field.parse() {
                    Ok(v) => v,
                    Err(_) if !std_cols.contains(&c) => f64::NAN,
                    Err(_) => bail!(
                        "{p}:{line}: column '{}': '{field}' is not a number",
                        headers[c]
                    ),
                };
                if std_cols.contains(&c) && !v.is_finite() {
                    bail!(
                        "{p}:{line}: column '{}': value '{field}' is not finite",
                        headers[c]
                    );
                }
                cols[c].push(v);
            }
        }
        let n = cols[ci_t].len();
        if n < 2 {
            bail!("{p}: only {n} data rows; a log needs at least 2");
        }
        for k in 1..n {
            if cols[ci_t][k] <= cols[ci_t][k - 1] {
                bail!(
                    "{p}:{}: column '{}': time does not increase ({} after {})",
                    header_line + k + 1,
                    headers[ci_t],
                    cols[ci_t][k],
                    cols[ci_t][k - 1]
                );
            }
        }
        let take = |c: usize, cols: &mut Vec<Vec<f64>>| std::mem::take(&mut cols[c]);
        let t = take(ci_t, &mut cols);
        let u = take(ci_u, &mut cols);
        let theta = take(ci_theta, &mut cols);
        let i = ci_i.map(|c| take(c, &mut cols));
        let omega = ci_omega.map(|c| take(c, &mut cols));
        let extra = headers
            .iter()
            .enumerate()
            .filter(|(c, _)| !std_cols.contains(c))
            .map(|(c, h)| (h.clone(), std::mem::take(&mut cols[c])))
            .collect();
        Ok(MotorLog {
            source: path.to_path_buf(),
            meta,
            t,
            u,
            i,
            theta,
            omega,
            extra,
        })
    }

    /// Render as contract CSV text (metadata first, standard columns, then extras).
    pub fn to_csv(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        for (k, v) in &self.meta {
            let _ = writeln!(s, "# {k}={v}");
        }
        let mut names: Vec<&str> = vec!["t", "u"];
        let mut series: Vec<&[f64]> = vec![&self.t, &self.u];
        if let Some(i) = &self.i {
            names.push("i");
            series.push(i);
        }
        names.push("theta");
        series.push(&self.theta);
        if let Some(w) = &self.omega {
            names.push("omega");
            series.push(w);
        }
        for (n, v) in &self.extra {
            names.push(n);
            series.push(v);
        }
        s.push_str(&names.join(","));
        s.push('\n');
        for k in 0..self.len() {
            for (c, col) in series.iter().enumerate() {
                if c > 0 {
                    s.push(',');
                }
                let _ = write!(s, "{}", col[k]);
            }
            s.push('\n');
        }
        s
    }

    /// Write atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::atomic::write_str(path, &self.to_csv())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, plant: Plant) -> Result<MotorLog> {
        MotorLog::parse(text, Path::new("x.csv"), &ColumnMap::default(), plant)
    }

    #[test]
    fn round_trip_keeps_everything() {
        let text = "# sample_period=0.012\nt,u,i,theta,omega,extra\n0,1,2,3,4,5\n0.012,1.5,2.5,3.5,4.5,5.5\n";
        let log = parse(text, Plant::Voltage).unwrap();
        assert_eq!(log.sample_period(), 0.012);
        assert_eq!(log.extra("extra"), Some(&[5.0, 5.5][..]));
        let again = parse(&log.to_csv(), Plant::Voltage).unwrap();
        assert_eq!(again.t, log.t);
        assert_eq!(again.extra, log.extra);
        assert_eq!(again.meta, log.meta);
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse("t,u,i,theta\n0,1,2,3\n0.1,x,2,3\n", Plant::Voltage).unwrap_err();
        assert_eq!(e.to_string(), "x.csv:3: column 'u': 'x' is not a number");
        let e = parse("t,u,theta\n0,1,3\n0.1,1,3\n", Plant::Voltage).unwrap_err();
        assert!(
            e.to_string().starts_with("x.csv:1: missing column 'i'"),
            "{e}"
        );
        let e = parse("# a=b\nt,u,i,theta\n0,1,2,3\n0,1,2,3\n", Plant::Voltage).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("x.csv:4: column 't': time does not increase"),
            "{e}"
        );
        let e = parse("t,u,i,theta\n0,1,2,3\n0.1,1,NaN,3\n", Plant::Voltage).unwrap_err();
        assert!(e.to_string().starts_with("x.csv:3: column 'i'"), "{e}");
    }

    #[test]
    fn torque_plant_needs_no_current_and_map_renames() {
        let map = ColumnMap::parse("t=t_s,u=vir,theta=qm").unwrap();
        let log = MotorLog::parse(
            "t_s,vir,qm\n0,1,2\n0.001,1,2\n",
            Path::new("e.csv"),
            &map,
            Plant::Torque,
        )
        .unwrap();
        assert!(log.i.is_none());
        assert_eq!(log.u, vec![1.0, 1.0]);
        assert!(ColumnMap::parse("speed=w").is_err());
    }
}
