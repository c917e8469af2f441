//! Motor logs: the CSV format every command reads and writes.
//!
//! ```text
//! # sample_period=0.012
//! # hall_resolution_rad=0.0951998
//! t,u,i,theta,omega
//! 0.000,0.0,0.0,0.0,0.0
//! ```
//! Optional `# key=value` metadata lines, one header row, one row per sample. The delimiter
//! (comma, semicolon or tab) is sniffed from the header row; numbers use a decimal point
//! (a decimal comma is an error, not a silent misreading). A UTF-8 byte-order mark is skipped.
//! A MATLAB MAT-file (`.mat`, v5 or v7) is read too ([`MotorLog::parse_mat`]): its vectors are
//! the columns, its scalars the metadata. A log with a velocity `omega` but no angle `theta`
//! gets the angle integrated from the velocity (trapezoid rule, from 0), and a warning says so.
//! Standard columns `t`, `u`, `i`, `theta`, `omega` are SI unless a metadata line
//! `# unit.COLUMN=UNIT` or `--units COLUMN=UNIT,...` declares another unit ([`Units`]); they are
//! converted to SI on read and the declared units are kept in [`MotorLog::units`]. Other names
//! are mapped with `--map STD=NAME,...`; extra columns are kept. Every error names the file
//! and the line (1-based, as an editor shows it) and the column at fault, and echoes at most
//! [`ECHO_MAX`] characters of the input, control characters removed.
use anyhow::{anyhow, bail, Result};
use std::collections::BTreeMap;
use std::f64::consts::PI;
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
                anyhow!(
                    "--map: '{}' is not of the form STD=NAME (e.g. t=time_s)",
                    echo(part)
                )
            })?;
            let k = k.trim();
            if !Self::STANDARD.contains(&k) {
                bail!(
                    "--map: '{}' is not a standard column; use one of {}",
                    echo(k),
                    Self::STANDARD.join(", ")
                );
            }
            let v = v.trim();
            if let Some((other, _)) = m.iter().find(|(_, name)| *name == v) {
                bail!(
                    "--map: column '{}' is mapped to both {other} and {k}",
                    echo(v)
                );
            }
            if m.insert(k.to_string(), v.to_string()).is_some() {
                bail!("--map: '{k}' is mapped twice; map each standard column once");
            }
        }
        Ok(ColumnMap(m))
    }

    /// The file's name for a standard column.
    pub fn name_of<'a>(&'a self, std: &'a str) -> &'a str {
        self.0.get(std).map(String::as_str).unwrap_or(std)
    }

    /// The standard column a name (standard, or the file's own name mapped with `--map`)
    /// stands for.
    pub fn standard_of(&self, name: &str) -> Option<&'static str> {
        Self::STANDARD
            .iter()
            .find(|s| self.0.get(**s).map(String::as_str) == Some(name))
            .or_else(|| Self::STANDARD.iter().find(|s| **s == name))
            .copied()
    }
}

/// `--map` and `--units` of a command as given on the command line, parsed once
/// (the commands that read logs share this).
pub fn column_options(map: Option<&str>, units: Option<&str>) -> Result<(ColumnMap, Units)> {
    let map = match map {
        Some(m) => ColumnMap::parse(m)?,
        None => ColumnMap::default(),
    };
    let units = match units {
        Some(u) => Units::parse(u)?,
        None => Units::default(),
    };
    Ok((map, units))
}

/// What a standard column measures (which units it accepts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Time,
    Angle,
    Velocity,
    Voltage,
    Current,
    /// Torque or force (`u` of a torque plant).
    Torque,
}

impl Quantity {
    /// What column `std` measures for this plant.
    pub fn of_column(std: &str, plant: Plant) -> Option<Quantity> {
        Some(match std {
            "t" => Quantity::Time,
            "theta" => Quantity::Angle,
            "omega" => Quantity::Velocity,
            "i" => Quantity::Current,
            "u" if plant == Plant::Torque => Quantity::Torque,
            "u" => Quantity::Voltage,
            _ => return None,
        })
    }

    /// Its name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Time => "a time",
            Quantity::Angle => "an angle (or a linear position)",
            Quantity::Velocity => "a velocity",
            Quantity::Voltage => "a voltage",
            Quantity::Current => "a current",
            Quantity::Torque => "a torque or force",
        }
    }

    /// The units it accepts, canonical names, for messages.
    pub fn accepted(self) -> String {
        UNIT_TABLE
            .iter()
            .filter(|d| d.quantity == self)
            .map(|d| d.names[0])
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A unit a log may declare for a standard column: SI value = value · `mul` / `div`
/// (two factors, so that 12 ms becomes exactly 12/1000 = 0.012 s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitDef {
    /// Accepted spellings, the canonical one first.
    pub names: &'static [&'static str],
    pub quantity: Quantity,
    pub mul: f64,
    pub div: f64,
    /// A linear axis (m, mm, m/s, mm/s) rather than a rotary one.
    pub linear: bool,
}

impl UnitDef {
    /// The canonical spelling.
    pub fn name(&self) -> &'static str {
        self.names[0]
    }

    /// A value in this unit, in SI.
    pub fn to_si(&self, v: f64) -> f64 {
        if self.mul == 1.0 && self.div == 1.0 {
            v
        } else if self.mul == 1.0 {
            v / self.div
        } else {
            v * self.mul / self.div
        }
    }

    /// Look a unit up by any of its spellings (exact first, then ignoring case).
    pub fn lookup(name: &str) -> Option<&'static UnitDef> {
        let name = name.trim();
        UNIT_TABLE
            .iter()
            .find(|d| d.names.contains(&name))
            .or_else(|| {
                UNIT_TABLE
                    .iter()
                    .find(|d| d.names.iter().any(|n| n.eq_ignore_ascii_case(name)))
            })
    }
}

const fn unit(
    names: &'static [&'static str],
    quantity: Quantity,
    mul: f64,
    div: f64,
    linear: bool,
) -> UnitDef {
    UnitDef {
        names,
        quantity,
        mul,
        div,
        linear,
    }
}

/// Every unit a log may declare (the documented list, plus a few obvious spellings).
pub const UNIT_TABLE: &[UnitDef] = &[
    unit(&["s"], Quantity::Time, 1.0, 1.0, false),
    unit(&["ms"], Quantity::Time, 1.0, 1e3, false),
    unit(&["us", "µs", "μs"], Quantity::Time, 1.0, 1e6, false),
    unit(&["rad"], Quantity::Angle, 1.0, 1.0, false),
    unit(&["deg", "°"], Quantity::Angle, PI, 180.0, false),
    unit(&["rev"], Quantity::Angle, 2.0 * PI, 1.0, false),
    unit(&["m"], Quantity::Angle, 1.0, 1.0, true),
    unit(&["mm"], Quantity::Angle, 1.0, 1e3, true),
    unit(&["rad/s"], Quantity::Velocity, 1.0, 1.0, false),
    unit(&["rpm"], Quantity::Velocity, 2.0 * PI, 60.0, false),
    unit(&["deg/s", "°/s"], Quantity::Velocity, PI, 180.0, false),
    unit(&["rev/s"], Quantity::Velocity, 2.0 * PI, 1.0, false),
    unit(&["m/s"], Quantity::Velocity, 1.0, 1.0, true),
    unit(&["mm/s"], Quantity::Velocity, 1.0, 1e3, true),
    unit(&["V"], Quantity::Voltage, 1.0, 1.0, false),
    unit(&["mV"], Quantity::Voltage, 1.0, 1e3, false),
    unit(&["A"], Quantity::Current, 1.0, 1.0, false),
    unit(&["mA"], Quantity::Current, 1.0, 1e3, false),
    unit(
        &["N·m", "N*m", "Nm", "N.m", "N m", "N⋅m"],
        Quantity::Torque,
        1.0,
        1.0,
        false,
    ),
    unit(&["N"], Quantity::Torque, 1.0, 1.0, true),
];

/// Units declared on the command line (`--units COLUMN=UNIT,...`): COLUMN is a standard
/// column name or the file's own name mapped with `--map`. They override the file's
/// `# unit.COLUMN=UNIT` lines.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Units(pub BTreeMap<String, String>);

impl Units {
    /// Parse `COLUMN=UNIT[,COLUMN=UNIT...]`; every unit must be known (its kind is checked
    /// against the column when a log is read).
    pub fn parse(spec: &str) -> Result<Units> {
        let mut m = BTreeMap::new();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = part.split_once('=').ok_or_else(|| {
                anyhow!(
                    "--units: '{}' is not of the form COLUMN=UNIT (e.g. t=ms)",
                    echo(part)
                )
            })?;
            let (k, v) = (k.trim(), v.trim());
            if UnitDef::lookup(v).is_none() {
                bail!(
                    "--units: {}={}: unknown unit; known units: {}",
                    echo(k),
                    echo(v),
                    known_units()
                );
            }
            if m.insert(k.to_string(), v.to_string()).is_some() {
                bail!(
                    "--units: '{}' is given twice; give each column's unit once",
                    echo(k)
                );
            }
        }
        Ok(Units(m))
    }
}

fn known_units() -> String {
    UNIT_TABLE
        .iter()
        .map(|d| d.names[0])
        .collect::<Vec<_>>()
        .join(", ")
}

/// Most characters of the input an error message echoes.
pub const ECHO_MAX: usize = 40;

/// Input text made safe to echo in a one-line message: control characters shown as escapes
/// (`\0`, `\x1b`, `\n`, `\u{feff}` for a byte-order mark), so that a NUL or an ANSI escape
/// sequence is visible and never reaches the terminal as such; cut to [`ECHO_MAX`] characters
/// with `…`.
pub fn echo(s: &str) -> String {
    let pieces: Vec<String> = s.chars().map(escape_char).collect();
    let total: usize = pieces.iter().map(|p| p.chars().count()).sum();
    if total <= ECHO_MAX {
        return pieces.concat();
    }
    let mut out = String::new();
    let mut len = 0;
    for piece in pieces {
        let n = piece.chars().count();
        if len + n > ECHO_MAX - 1 {
            break;
        }
        len += n;
        out.push_str(&piece);
    }
    out.push('…');
    out
}

/// Most characters of a path a message shows.
pub const ECHO_PATH_MAX: usize = 100;

/// A path made safe to echo in a one-line message, by the rule of [`echo`] with a longer cut
/// ([`ECHO_PATH_MAX`]) made in the middle: the start and the file name stay.
pub fn echo_path(path: &std::path::Path) -> String {
    let pieces: Vec<String> = path.to_string_lossy().chars().map(escape_char).collect();
    let total: usize = pieces.iter().map(|p| p.chars().count()).sum();
    if total <= ECHO_PATH_MAX {
        return pieces.concat();
    }
    // A third of the room for the start, the rest for the end (the file's name).
    let head_room = ECHO_PATH_MAX / 3;
    let tail_room = ECHO_PATH_MAX - head_room - 1;
    let (mut head, mut len) = (String::new(), 0);
    for piece in &pieces {
        let n = piece.chars().count();
        if len + n > head_room {
            break;
        }
        len += n;
        head.push_str(piece);
    }
    let (mut tail, mut len) = (Vec::new(), 0);
    for piece in pieces.iter().rev() {
        let n = piece.chars().count();
        if len + n > tail_room {
            break;
        }
        len += n;
        tail.push(piece.as_str());
    }
    tail.reverse();
    format!("{head}…{}", tail.concat())
}

/// `s` with every control character shown as an escape (as [`echo`] does, without the cut):
/// for a whole message line, whose paths and names come from outside.
pub fn escape_controls(s: &str) -> String {
    s.chars().map(escape_char).collect()
}

/// One character as a message shows it: a control character as `\0`, `\t`, `\x1b`, ...
fn escape_char(c: char) -> String {
    match c {
        '\0' => "\\0".to_string(),
        '\t' => "\\t".to_string(),
        '\n' => "\\n".to_string(),
        '\r' => "\\r".to_string(),
        '\u{feff}' => "\\u{feff}".to_string(),
        c if (c as u32) < 0x100 && c.is_control() => format!("\\x{:02x}", c as u32),
        c if c.is_control() => format!("\\u{{{:x}}}", c as u32),
        c => c.to_string(),
    }
}

/// A motor log in memory. All series have the same length.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MotorLog {
    /// Where it came from (for error messages and model provenance).
    pub source: PathBuf,
    /// `# key=value` metadata, in file order of keys (sorted). `sample_period` is in seconds
    /// (converted when `# unit.t` declared another time unit); the `unit.*` lines of standard
    /// columns are not here but in `units`.
    pub meta: BTreeMap<String, String>,
    pub t: Vec<f64>,
    pub u: Vec<f64>,
    pub i: Option<Vec<f64>>,
    pub theta: Vec<f64>,
    pub omega: Option<Vec<f64>>,
    /// Extra columns, kept in file order.
    pub extra: Vec<(String, Vec<f64>)>,
    /// Units the file (`# unit.COLUMN=UNIT`) or `--units` declared for the standard columns
    /// present, canonical spelling (`t` → `ms`), by standard name. The series above are
    /// already converted to SI; this records what the data was in.
    pub units: BTreeMap<String, String>,
}

/// Where a declared unit came from (for messages).
#[derive(Debug, Clone)]
enum UnitSource {
    /// A `# unit.X=...` line of the file (its place, `x.csv:2`).
    Line(String),
    /// `--units`.
    Flag,
}

/// Longest time step a log may take, in median steps: jitter and a few lost samples (a serial
/// link dropping some) stay well below it; a longer step is a gap between two recordings.
pub const MAX_GAP_STEPS: f64 = 10.0;

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
        self.median_step()
    }

    /// The median step of the `t` column [s] (0 with fewer than two samples).
    pub fn median_step(&self) -> f64 {
        let d: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).collect();
        median(d).unwrap_or(0.0)
    }

    /// True when the declared units make this a linear axis (theta in m or mm, omega in m/s or
    /// mm/s, or a force input N).
    pub fn is_linear(&self) -> bool {
        self.units
            .values()
            .any(|u| UnitDef::lookup(u).is_some_and(|d| d.linear))
    }

    /// An extra column by name.
    pub fn extra(&self, name: &str) -> Option<&[f64]> {
        self.extra
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// Read a log (CSV, or a MATLAB MAT-file: [`MotorLog::parse_mat`]) in SI units or with
    /// `# unit.*` lines. `plant` decides whether `i` is required.
    pub fn read(path: &Path, map: &ColumnMap, plant: Plant) -> Result<MotorLog> {
        Self::read_with_units(path, map, &Units::default(), plant)
    }

    /// Read a log; `units` (from `--units`) override the file's `# unit.*` lines.
    pub fn read_with_units(
        path: &Path,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<MotorLog> {
        let mat_name = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mat"));
        let text = crate::input::read_lines(
            path,
            // A MAT-file over the reader's cap is refused from its length.
            if mat_name {
                crate::matlab::MAX_FILE as u64
            } else {
                crate::input::MAX_LOG_FILE
            },
            crate::input::MAX_LINE,
            "log",
            |head| mat_name || crate::matlab::is_mat_file(head),
        )?;
        if crate::matlab::is_mat_file(&text) || mat_name {
            return Self::parse_mat(&text, path, map, units, plant);
        }
        let text = String::from_utf8(text).map_err(|e| {
            let bytes = e.as_bytes();
            let at = e.utf8_error().valid_up_to();
            let line = bytes[..at].iter().filter(|b| **b == b'\n').count() + 1;
            anyhow!(
                "{}:{line}: not UTF-8 text (byte {at}); save the file as UTF-8",
                crate::log::echo_path(path)
            )
        })?;
        Self::parse_with_units(&text, path, map, units, plant)
    }

    /// [`MotorLog::read_with_units`], then every [`MotorLog::sanity_warnings`] held for a
    /// `warning:` line ([`crate::warnings`]): what the commands that read logs call.
    pub fn read_and_warn(
        path: &Path,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<MotorLog> {
        let log = Self::read_with_units(path, map, units, plant)?;
        tracing::debug!(
            file = %crate::log::echo_path(path),
            samples = log.t.len(),
            sample_period_s = log.sample_period(),
            "log read"
        );
        for w in log.sanity_warnings() {
            crate::warnings::hold(w);
        }
        Ok(log)
    }

    /// Parse a log from text (SI units or `# unit.*` lines); `path` is used in messages only.
    pub fn parse(text: &str, path: &Path, map: &ColumnMap, plant: Plant) -> Result<MotorLog> {
        Self::parse_with_units(text, path, map, &Units::default(), plant)
    }

    /// Parse a log from text; `units` (from `--units`) override the file's `# unit.*` lines.
    pub fn parse_with_units(
        text: &str,
        path: &Path,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<MotorLog> {
        let p = crate::log::echo_path(path);
        // A byte-order mark is not part of the first line's text (nor a line of its own).
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        if text.contains('\r') && !text.contains('\n') {
            bail!("{p}:1: {}", crate::input::LONE_CR);
        }
        let pre = Preamble::scan(text, &p)?;
        let body = &text[pre.body_start..];
        let delimiter = sniff_delimiter(body.lines().next().unwrap_or(""));
        let mut rdr = csv_reader(delimiter, true).from_reader(body.as_bytes());
        let header_line = pre.header_line;
        let headers: Vec<String> = rdr
            .headers()
            .map_err(|e| {
                anyhow!(
                    "{p}:{header_line}: cannot read the header row: {}",
                    csv_problem(&e)
                )
            })?
            .iter()
            .map(str::to_string)
            .collect();
        let mut places = Places::Csv {
            header_line,
            meta_line: pre.meta_line,
            row_lines: Vec::new(),
        };
        let columns = StdColumns::find(&headers, map, plant, &places.header(path))?;
        let rows = CsvRows {
            p: &p,
            headers: &headers,
            std_cols: &columns.indices(),
            delimiter,
        };
        let data_start = rdr.position().byte() as usize;
        let (cols, row_lines) = match rows.chunks(body.as_bytes(), data_start, PARALLEL_READ_BYTES)
        {
            Some(chunks) => rows.read_chunks(&chunks, header_line)?,
            None => rows.read(&mut rdr, header_line)?,
        };
        if let Places::Csv { row_lines: r, .. } = &mut places {
            *r = row_lines;
        }
        Table {
            meta: pre.meta,
            places,
            headers,
            cols,
        }
        .into_log(path, &columns, map, units, plant)
    }

    /// Read a MATLAB MAT-file (v5, or v7 with compressed arrays): every numeric vector as
    /// long as the time vector (`t`, or the name `--map` gives it) is a column, every scalar
    /// a metadata value; `path` is used in messages only.
    pub fn parse_mat(
        bytes: &[u8],
        path: &Path,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<MotorLog> {
        let p = crate::log::echo_path(path);
        let mat = crate::matlab::read(bytes, path)?;
        let t_name = map.name_of("t");
        let Some(n) = mat
            .vectors
            .iter()
            .find(|(k, _)| k == t_name)
            .map(|(_, v)| v.len())
        else {
            let names: Vec<String> = mat.vectors.iter().map(|(k, _)| k.clone()).collect();
            let hint = if t_name == "t" {
                " (map another variable with --map t=NAME)"
            } else {
                ""
            };
            bail!(
                "{p}: no vector variable '{}'{hint}; its vectors are: {}",
                echo(t_name),
                header_list(&names)
            );
        };
        let mut meta = BTreeMap::new();
        for (k, v) in &mat.scalars {
            meta.insert(k.clone(), format!("{v}"));
        }
        let (headers, cols): (Vec<String>, Vec<Vec<f64>>) = mat
            .vectors
            .iter()
            .filter(|(_, v)| v.len() == n)
            .cloned()
            .unzip();
        let places = Places::Mat;
        let columns =
            StdColumns::find(&headers, map, plant, &places.header(path)).map_err(|e| match mat
                .vectors
                .iter()
                .find(|(_, v)| v.len() != n)
            {
                Some((k, v)) => anyhow!(
                    "{e}; variable '{}' has {} elements, not {n} as '{}'",
                    echo(k),
                    v.len(),
                    echo(t_name)
                ),
                None if !mat.undecoded.is_empty() => {
                    anyhow!("{e}; not decoded: {}", header_list(&mat.undecoded))
                }
                None => e,
            })?;
        for c in columns.indices() {
            if let Some(k) = cols[c].iter().position(|v| !v.is_finite()) {
                bail!(
                    "{p}: variable '{}', element {}: value {} is not finite",
                    echo(&headers[c]),
                    k + 1,
                    cols[c][k]
                );
            }
        }
        Table {
            meta,
            places,
            headers,
            cols,
        }
        .into_log(path, &columns, map, units, plant)
    }

    /// Numbers that do not fit the units, as readable sentences naming the file (for
    /// `warning:` lines; not errors): `# sample_period` more than 1 % off the median step of
    /// `t`, a median angle step that is not a multiple of `# hall_resolution_rad`, a speed
    /// beyond any motor's (|Δθ/Δt| above [`MAX_PLAUSIBLE_SPEED`] in rad/s).
    pub fn sanity_warnings(&self) -> Vec<String> {
        let p = crate::log::echo_path(&self.source);
        let mut out = Vec::new();
        if self.len() < 2 {
            return out;
        }
        let declare = |col: &str, unit: &str| {
            format!("declare it with a line '# unit.{col}={unit}' or --units {col}={unit}")
        };
        let dt = self.median_step();
        if let Some(sp) = self.meta_f64("sample_period") {
            if sp > 0.0 && dt > 0.0 && (sp / dt - 1.0).abs() > 0.01 {
                let ratio = dt / sp;
                let hint = [(1e3, "ms"), (1e6, "us")]
                    .iter()
                    .find(|(f, _)| (ratio / f - 1.0).abs() < 0.05)
                    .map(|(_, u)| format!(": is t in {u}? {}", declare("t", u)))
                    .unwrap_or_default();
                out.push(format!(
                    "{p}: sample_period={sp} s but the median step of column 't' is {dt} s \
                     ({ratio:.4}x){hint}"
                ));
            }
        }
        let integrated = self.meta.get(THETA_INTEGRATED);
        if let Some(how) = integrated {
            out.push(format!(
                "{p}: no angle column: theta is the integral of {how}; effects of the angle \
                 (cogging, position_load) and the angle's fit percentage rest on that integral"
            ));
        }
        let steps: Vec<f64> = self.theta.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
        let hall = self.meta_f64("hall_resolution_rad").filter(|r| *r > 0.0);
        if let Some(res) = hall.filter(|_| integrated.is_none()) {
            let moved: Vec<f64> = steps.iter().copied().filter(|d| *d > 1e-9 * res).collect();
            if let Some(m) = median(moved) {
                let r = m / res;
                if r < 0.5 || (r - r.round()).abs() > 0.1 {
                    let deg = (r / (180.0 / PI)).round() >= 1.0
                        && ((r / (180.0 / PI)) - (r / (180.0 / PI)).round()).abs() < 0.1;
                    let hint = if deg {
                        format!(": is theta in degrees? {}", declare("theta", "deg"))
                    } else {
                        String::new()
                    };
                    out.push(format!(
                        "{p}: the median angle step {m:.6} of column 'theta' is not a multiple \
                         of hall_resolution_rad={res} ({r:.3} steps){hint}"
                    ));
                }
            }
        }
        let mut speeds: Vec<f64> = steps
            .iter()
            .zip(self.t.windows(2))
            .map(|(d, w)| d / (w[1] - w[0]))
            .filter(|v| v.is_finite())
            .collect();
        if !speeds.is_empty() {
            let k = (speeds.len() - 1) * 99 / 100;
            let q = *speeds.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
            if q > MAX_PLAUSIBLE_SPEED {
                let unit = if self.is_linear() { "m/s" } else { "rad/s" };
                out.push(format!(
                    "{p}: column 'theta' moves at {q:.3e} {unit} (99th percentile of |Δθ/Δt|), \
                     beyond any motor: are theta and t in SI units (rad or m, s)? Declare other \
                     units with lines '# unit.COLUMN=UNIT' or --units COLUMN=UNIT"
                ));
            }
        }
        out
    }

    /// Render as motor-log CSV text (metadata first, standard columns, then extras).
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

/// Where a log's parts are in its file, for messages.
#[derive(Debug, Clone)]
enum Places {
    /// A CSV text: the header's, each metadata key's and each data row's line (1-based).
    Csv {
        header_line: usize,
        meta_line: BTreeMap<String, usize>,
        row_lines: Vec<usize>,
    },
    /// A MAT-file: variables by name, samples by index.
    Mat,
}

impl Places {
    /// The header row (`x.csv:3`), or the file.
    fn header(&self, path: &Path) -> String {
        match self {
            Places::Csv { header_line, .. } => {
                format!("{}:{header_line}", crate::log::echo_path(path))
            }
            Places::Mat => crate::log::echo_path(path).to_string(),
        }
    }

    /// A metadata value (`x.csv:2`, `x.mat: variable 'k'`).
    fn meta(&self, path: &Path, key: &str) -> String {
        match self {
            Places::Csv { meta_line, .. } => {
                let line = meta_line.get(key).copied().unwrap_or(0);
                format!("{}:{line}", crate::log::echo_path(path))
            }
            Places::Mat => format!("{}: variable '{}'", crate::log::echo_path(path), echo(key)),
        }
    }

    /// Data row `k` (0-based): `x.csv:17`, `x.mat: sample 15`.
    fn row(&self, path: &Path, k: usize) -> String {
        match self {
            Places::Csv { row_lines, .. } => {
                format!(
                    "{}:{}",
                    crate::log::echo_path(path),
                    row_lines.get(k).copied().unwrap_or(0)
                )
            }
            Places::Mat => format!("{}: sample {}", crate::log::echo_path(path), k + 1),
        }
    }
}

/// The positions of the standard columns in a header.
#[derive(Debug, Clone, Copy)]
struct StdColumns {
    t: usize,
    u: usize,
    /// Absent when `omega` is there: the angle is then integrated from it.
    theta: Option<usize>,
    i: Option<usize>,
    omega: Option<usize>,
}

impl StdColumns {
    /// Find them (mapped with `--map`); `t`, `u`, `theta` or `omega`, and for a voltage plant
    /// `i`, are required. `at` is the header's place for messages.
    fn find(headers: &[String], map: &ColumnMap, plant: Plant, at: &str) -> Result<StdColumns> {
        for (k, h) in headers.iter().enumerate() {
            if headers[..k].contains(h) {
                bail!(
                    "{at}: column '{}' appears twice (columns {} and {}); rename one",
                    echo(h),
                    headers[..k].iter().position(|o| o == h).unwrap_or(0) + 1,
                    k + 1
                );
            }
        }
        let find = |std: &str| headers.iter().position(|h| h == map.name_of(std));
        let need = |std: &str, also: &str| {
            find(std).ok_or_else(|| {
                let name = map.name_of(std);
                let hint = if name == std {
                    format!(" (map another column with --map {std}=NAME{also})")
                } else {
                    String::new()
                };
                anyhow!(
                    "{at}: missing column '{}'{hint}; the header has: {}",
                    echo(name),
                    header_list(headers)
                )
            })
        };
        let omega = find("omega");
        let theta = match omega {
            Some(_) => find("theta"),
            None => Some(need("theta", ", or give a velocity column 'omega'")?),
        };
        Ok(StdColumns {
            t: need("t", "")?,
            u: need("u", "")?,
            theta,
            i: match plant {
                Plant::Voltage => Some(need("i", "")?),
                Plant::Torque => find("i"),
            },
            omega,
        })
    }

    /// The columns that are standard ones.
    fn indices(&self) -> Vec<usize> {
        [Some(self.t), Some(self.u), self.theta, self.i, self.omega]
            .into_iter()
            .flatten()
            .collect()
    }

    /// True when standard column `std` is in the file.
    fn present(&self, std: &str) -> bool {
        match std {
            "i" => self.i.is_some(),
            "omega" => self.omega.is_some(),
            "theta" => self.theta.is_some(),
            _ => true,
        }
    }
}

/// Metadata key set when the angle was integrated from the velocity (value: how).
pub const THETA_INTEGRATED: &str = "theta_integrated_from";

/// A metadata value's check: the message says what is wrong with the value.
type MetaCheck = fn(&str) -> std::result::Result<(), String>;

/// The metadata keys the tools know, each with the check of its value. A known key whose
/// value fails its check, or a known key given twice, is an error naming the line and the
/// key; other keys are kept as text and otherwise ignored (`-v` lists them). `unit.*` keys are
/// checked with the column units, and `sample_period`'s range (1 µs .. 10 s) once it is in
/// seconds.
pub const METADATA_KEYS: &[(&str, MetaCheck)] = &[
    // Seconds, or the unit of `t`: its range is checked after conversion.
    ("sample_period", |v| crate::validate::number(v).map(drop)),
    // 0 = not quantised, else 1e-12 .. 2π rad (validate::angle_quantum).
    ("hall_resolution_rad", |v| {
        crate::validate::angle_quantum(crate::validate::number(v)?).map(drop)
    }),
    // The coefficient blob stores it in a byte; real motors have 1 to about 100.
    ("pole_pairs", |v| {
        crate::validate::whole_number(v, 1, 255).map(drop)
    }),
    // Written by `simulate` and `record`: the same ranges as their flags.
    ("seed", |v| {
        crate::validate::whole_number(v, 0, u64::MAX).map(drop)
    }),
    ("lost_samples", |v| {
        crate::validate::whole_number(v, 0, u64::MAX).map(drop)
    }),
    ("current_noise", |v| {
        crate::validate::parse_noise(v).map(drop)
    }),
    ("fine_step", |v| {
        crate::validate::parse_fine_step(v).map(drop)
    }),
    ("speed_ref", |v| crate::validate::number(v).map(drop)),
];

/// True for a metadata key whose value the tools read (a repeated one is an error).
fn known_meta_key(key: &str) -> bool {
    key.starts_with("unit.") || METADATA_KEYS.iter().any(|(k, _)| *k == key)
}

/// The lines before a CSV log's header row: `# key=value` metadata, comments and blanks.
struct Preamble {
    meta: BTreeMap<String, String>,
    /// Line (1-based) of each metadata key.
    meta_line: BTreeMap<String, usize>,
    /// Line (1-based) of the header row.
    header_line: usize,
    /// Byte offset of the header row in the text.
    body_start: usize,
}

impl Preamble {
    /// Read the metadata lines up to the header row; `p` names the file in messages.
    fn scan(text: &str, p: &str) -> Result<Preamble> {
        let mut meta = BTreeMap::new();
        let mut meta_line: BTreeMap<String, usize> = BTreeMap::new();
        let mut offset = 0usize;
        for (n, line) in text.split_inclusive('\n').enumerate() {
            let trimmed = line.trim();
            if let Some(rest) = trimmed.strip_prefix('#') {
                if let Some((k, v)) = rest.split_once('=') {
                    let k = k.trim();
                    if let Some(first) = meta_line.get(k).filter(|_| known_meta_key(k)) {
                        bail!(
                            "{p}:{}: {}: given twice (first on line {first}); keep one",
                            n + 1,
                            echo(k)
                        );
                    }
                    meta.insert(k.to_string(), v.trim().to_string());
                    meta_line.insert(k.to_string(), n + 1);
                }
                offset += line.len();
                continue;
            }
            if trimmed.is_empty() {
                offset += line.len();
                continue;
            }
            return Ok(Preamble {
                meta,
                meta_line,
                header_line: n + 1,
                body_start: offset,
            });
        }
        bail!("{p}: no header row (expected a line like 't,u,i,theta')")
    }
}

/// The reader of a log's body: `delimiter`, `#` comment lines, every row read whatever its
/// number of fields (a row with another number of fields is reported by [`CsvRows`], with its
/// line). Header names are trimmed here; fields by [`CsvRows`] (the reader's own field
/// trimming allocates a record per row, twice).
fn csv_reader(delimiter: u8, has_headers: bool) -> csv::ReaderBuilder {
    let mut b = csv::ReaderBuilder::new();
    b.has_headers(has_headers)
        .delimiter(delimiter)
        .trim(csv::Trim::Headers)
        .comment(Some(b'#'))
        .flexible(true);
    b
}

/// The data rows of a CSV log: what a row is checked against.
struct CsvRows<'a> {
    /// The file, as messages name it.
    p: &'a str,
    headers: &'a [String],
    /// Indices of the standard columns (must be finite numbers).
    std_cols: &'a [usize],
    delimiter: u8,
}

/// A log's columns (one series per header) and each row's line.
type Columns = (Vec<Vec<f64>>, Vec<usize>);

/// Smallest body of a log [bytes] that [`CsvRows::chunks`] cuts into pieces to read in
/// parallel: below it (about 25,000 rows of four columns) the threads cost more than they
/// save.
const PARALLEL_READ_BYTES: usize = 1 << 20;

impl CsvRows<'_> {
    /// The rows after byte `start` of a log's `body` cut at line ends into pieces of at
    /// least `min_piece` bytes, one or two for each thread, each with the number of
    /// lines before it in `body`; `None` when the body is too small to be worth it, or may
    /// hold a quoted field (a line end inside quotes is not a row's end) or a piece would
    /// begin with a byte-order mark (which the reader drops only at the start of a file).
    fn chunks<'b>(
        &self,
        body: &'b [u8],
        start: usize,
        min_piece: usize,
    ) -> Option<Vec<(&'b [u8], usize)>> {
        let data = body.get(start..)?;
        let wanted = (2 * rayon::current_num_threads()).min(data.len() / min_piece.max(1));
        if wanted < 2 || memchr::memchr(b'"', data).is_some() {
            return None;
        }
        let mut cuts = vec![0];
        for k in 1..wanted {
            let from = (k * data.len() / wanted).max(*cuts.last().expect("a cut"));
            match memchr::memchr(b'\n', &data[from..]) {
                Some(at) if from + at + 1 < data.len() => cuts.push(from + at + 1),
                _ => break,
            }
        }
        cuts.dedup();
        cuts.push(data.len());
        let pieces: Vec<&[u8]> = cuts.windows(2).map(|w| &data[w[0]..w[1]]).collect();
        if pieces.iter().any(|c| c.starts_with(b"\xEF\xBB\xBF")) {
            return None;
        }
        use rayon::prelude::*;
        let lines: Vec<usize> = pieces
            .par_iter()
            .map(|c| memchr::memchr_iter(b'\n', c).count())
            .collect();
        let mut before = memchr::memchr_iter(b'\n', &body[..start]).count();
        let mut out = Vec::with_capacity(pieces.len());
        for (c, n) in pieces.into_iter().zip(lines) {
            out.push((c, before));
            before += n;
        }
        Some(out)
    }

    /// [`CsvRows::read`] of the pieces of [`CsvRows::chunks`] in parallel, joined in order;
    /// the error is the first piece's that has one, the one a reading from the start meets
    /// first. `first_line` is the file's line of the body's first line.
    fn read_chunks(&self, chunks: &[(&[u8], usize)], first_line: usize) -> Result<Columns> {
        use rayon::prelude::*;
        let parts: Vec<Result<Columns>> = chunks
            .par_iter()
            .map(|(c, before)| {
                let mut rdr = csv_reader(self.delimiter, false).from_reader(*c);
                self.read(&mut rdr, first_line + before)
            })
            .collect();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); self.headers.len()];
        let mut row_lines = Vec::new();
        let parts: Vec<Columns> = parts.into_iter().collect::<Result<_>>()?;
        let rows: usize = parts.iter().map(|(_, l)| l.len()).sum();
        for c in &mut cols {
            c.reserve_exact(rows);
        }
        row_lines.reserve_exact(rows);
        for (pc, pl) in parts {
            for (c, v) in cols.iter_mut().zip(pc) {
                c.extend(v);
            }
            row_lines.extend(pl);
        }
        Ok((cols, row_lines))
    }

    /// Every row `rdr` has left as numbers, one series per header, and each row's line;
    /// `first_line` is the file's line of the reader's first line.
    fn read(&self, rdr: &mut csv::Reader<&[u8]>, first_line: usize) -> Result<Columns> {
        let p = self.p;
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); self.headers.len()];
        let mut row_lines: Vec<usize> = Vec::new();
        let mut rec = csv::ByteRecord::new();
        loop {
            let more = rdr.read_byte_record(&mut rec).map_err(|e| {
                let line = e
                    .position()
                    .map(|q| q.line() as usize + first_line - 1)
                    .unwrap_or(0);
                anyhow!("{p}:{line}: {}", csv_problem(&e))
            })?;
            if !more {
                break;
            }
            let line = rec
                .position()
                .map(|q| q.line() as usize + first_line - 1)
                .unwrap_or(0);
            row_lines.push(line);
            if rec.len() != self.headers.len() {
                bail!(
                    "{p}:{line}: {} fields, but the header has {}",
                    rec.len(),
                    self.headers.len()
                );
            }
            for (c, field) in rec.iter().enumerate() {
                // A field of text read whole is text (the delimiter and line ends are ASCII).
                let field = std::str::from_utf8(field)
                    .map_err(|_| anyhow!("{p}:{line}: not UTF-8 text"))?
                    .trim();
                cols[c].push(self.field(line, c, field)?);
            }
        }
        Ok((cols, row_lines))
    }

    /// One field as a number: NaN where an extra column is not numeric; an error for a
    /// decimal comma, and where a standard column is not a finite number.
    fn field(&self, line: usize, c: usize, field: &str) -> Result<f64> {
        let p = self.p;
        let std_col = self.std_cols.contains(&c);
        let v: f64 = match field.parse() {
            Ok(v) => v,
            Err(_) if self.delimiter != b',' && looks_like_decimal_comma(field) => bail!(
                "{p}:{line}: column '{}': '{}' has a decimal comma; decimal commas are \
                 not supported, write numbers with a decimal point ({})",
                echo(&self.headers[c]),
                echo(field),
                echo(&field.replace(',', "."))
            ),
            Err(_) if !std_col => f64::NAN,
            Err(_) => bail!(
                "{p}:{line}: column '{}': '{}' is not a number",
                echo(&self.headers[c]),
                echo(field)
            ),
        };
        if std_col && !v.is_finite() {
            bail!(
                "{p}:{line}: column '{}': value '{}' is not finite",
                echo(&self.headers[c]),
                echo(field)
            );
        }
        Ok(v)
    }
}

/// A log's columns as read, before units and checks: what CSV and MAT-files have in common.
struct Table {
    meta: BTreeMap<String, String>,
    places: Places,
    headers: Vec<String>,
    /// One series per header, all of the same length; standard columns finite.
    cols: Vec<Vec<f64>>,
}

impl Table {
    /// Declared units, time checks, conversion to SI, the angle from the velocity where it is
    /// absent, and the sample period's checks.
    fn into_log(
        self,
        path: &Path,
        columns: &StdColumns,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<MotorLog> {
        let p = crate::log::echo_path(path);
        self.check_metadata(path, &p)?;
        let declared = self.declared_units(path, columns, map, units, plant)?;
        check_declared_kinds(&declared)?;
        self.check_time_column(path, columns)?;
        let Table {
            mut meta,
            places,
            headers,
            mut cols,
        } = self;
        // The unit lines of standard columns are read; those of extra columns stay.
        meta.retain(|k, _| {
            k.strip_prefix("unit.")
                .is_none_or(|col| map.standard_of(col).is_none())
        });
        let take = |c: usize, cols: &mut Vec<Vec<f64>>| std::mem::take(&mut cols[c]);
        let convert = |std: &str, mut v: Vec<f64>| {
            if let Some((d, _)) = declared.get(std) {
                for x in &mut v {
                    *x = d.to_si(*x);
                }
            }
            v
        };
        let std_cols = columns.indices();
        let t = convert("t", take(columns.t, &mut cols));
        let u = convert("u", take(columns.u, &mut cols));
        let theta = columns.theta.map(|c| convert("theta", take(c, &mut cols)));
        let i = columns.i.map(|c| convert("i", take(c, &mut cols)));
        let omega = columns.omega.map(|c| convert("omega", take(c, &mut cols)));
        let theta = match (theta, &omega) {
            (Some(theta), _) => theta,
            (None, Some(w)) => {
                meta.insert(
                    THETA_INTEGRATED.to_string(),
                    format!(
                        "{} (trapezoid rule, from 0)",
                        echo(&headers[columns.omega.unwrap_or(0)])
                    ),
                );
                integrate_trapezoid(&t, w)
            }
            (None, None) => bail!("{p}: no column 'theta' nor 'omega'"),
        };
        let extra = headers
            .iter()
            .enumerate()
            .filter(|(c, _)| !std_cols.contains(c))
            .map(|(c, h)| (h.clone(), std::mem::take(&mut cols[c])))
            .collect();
        let time = TimeChecks {
            path,
            places: &places,
            t_header: &headers[columns.t],
            declared: &declared,
        };
        time.sample_period(&mut meta, &t)?;
        let units = declared
            .iter()
            .map(|(std, (d, _))| (std.to_string(), d.name().to_string()))
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
            units,
        })
    }

    /// Every metadata value motorid reads passes its check; other keys are ignored.
    fn check_metadata(&self, path: &Path, p: &str) -> Result<()> {
        for (key, value) in &self.meta {
            match METADATA_KEYS.iter().find(|(k, _)| k == key) {
                Some((_, check)) => check(value)
                    .map_err(|e| anyhow!("{}: {}: {e}", self.places.meta(path, key), echo(key)))?,
                None if key.starts_with("unit.") => {}
                None => tracing::debug!(
                    file = %p,
                    key = %echo(key),
                    "metadata key not used by motorid, ignored"
                ),
            }
        }
        Ok(())
    }

    /// Declared units of the standard columns present: the file's `# unit.X` lines, then
    /// --units over them.
    fn declared_units(
        &self,
        path: &Path,
        columns: &StdColumns,
        map: &ColumnMap,
        units: &Units,
        plant: Plant,
    ) -> Result<Declared> {
        let mut declared = Declared::new();
        for (key, value) in self.meta.iter().filter(|(k, _)| k.starts_with("unit.")) {
            let col = &key["unit.".len()..];
            let at = self.places.meta(path, key);
            let Some(std) = map.standard_of(col) else {
                if self.headers.iter().any(|h| h == col) {
                    // The unit of an extra column: kept in the metadata, not converted.
                    continue;
                }
                bail!(
                    "{at}: unit.{}: no column '{}' in the header ({})",
                    echo(col),
                    echo(col),
                    header_list(&self.headers)
                );
            };
            let def = check_unit(std, value, plant)
                .map_err(|e| anyhow!("{at}: unit.{}={}: {e}", echo(col), echo(value)))?;
            declared.insert(std, (def, UnitSource::Line(at)));
        }
        for (col, value) in &units.0 {
            let std = map.standard_of(col).ok_or_else(|| {
                anyhow!(
                    "--units: '{}' is not a standard column (t, u, i, theta, omega) nor a \
                     column mapped to one with --map",
                    echo(col)
                )
            })?;
            let def = check_unit(std, value, plant)
                .map_err(|e| anyhow!("--units: {}={}: {e}", echo(col), echo(value)))?;
            declared.insert(std, (def, UnitSource::Flag));
        }
        declared.retain(|std, _| columns.present(std));
        Ok(declared)
    }

    /// The time column as written: at least two rows, increasing, no step longer than a
    /// recording's.
    fn check_time_column(&self, path: &Path, columns: &StdColumns) -> Result<()> {
        let p = crate::log::echo_path(path);
        let ct = &self.cols[columns.t];
        let n = ct.len();
        if n < 2 {
            bail!("{p}: only {n} data rows; a log needs at least 2");
        }
        for k in 1..n {
            let step = ct[k] - ct[k - 1];
            if step > crate::validate::MAX_TIME_STEP {
                bail!(
                    "{}: column '{}': time jumps by {} s (from {} to {}); a step longer \
                     than {} s is not a recording's",
                    self.places.row(path, k),
                    echo(&self.headers[columns.t]),
                    crate::validate::show(step),
                    crate::validate::show(ct[k - 1]),
                    crate::validate::show(ct[k]),
                    crate::validate::show(crate::validate::MAX_TIME_STEP)
                );
            }
            if ct[k] <= ct[k - 1] {
                bail!(
                    "{}: column '{}': time does not increase ({} after {})",
                    self.places.row(path, k),
                    echo(&self.headers[columns.t]),
                    ct[k],
                    ct[k - 1]
                );
            }
        }
        Ok(())
    }
}

/// The unit declared for each standard column, and where it was declared.
type Declared = BTreeMap<&'static str, (&'static UnitDef, UnitSource)>;

/// The angle and the velocity must both be rotary or both linear.
fn check_declared_kinds(declared: &Declared) -> Result<()> {
    let (Some((a, sa)), Some((w, sw))) = (declared.get("theta"), declared.get("omega")) else {
        return Ok(());
    };
    if a.linear == w.linear {
        return Ok(());
    }
    let at = |s: &UnitSource| match s {
        UnitSource::Line(at) => at.clone(),
        UnitSource::Flag => "--units".to_string(),
    };
    bail!(
        "{}: unit of omega '{}' does not match unit of theta '{}' ({}): one is \
         rotary, the other linear",
        at(sw),
        w.name(),
        a.name(),
        at(sa)
    )
}

/// The checks of a log's sample period, once its time is in seconds.
struct TimeChecks<'a> {
    path: &'a Path,
    places: &'a Places,
    t_header: &'a str,
    declared: &'a Declared,
}

impl TimeChecks<'_> {
    /// `# sample_period` converted to seconds and checked, then the median step of `t` [s],
    /// and no gap longer than [`MAX_GAP_STEPS`] median steps.
    fn sample_period(&self, meta: &mut BTreeMap<String, String>, t: &[f64]) -> Result<()> {
        let p = crate::log::echo_path(self.path);
        // `# sample_period` is in the unit of `t`.
        if let Some((d, _)) = self.declared.get("t") {
            if let Some(sp) = meta
                .get("sample_period")
                .and_then(|v| v.parse::<f64>().ok())
            {
                meta.insert("sample_period".to_string(), format!("{}", d.to_si(sp)));
            }
        }
        // The sample period sizes every window and loop downstream: it must be physical.
        if let Some(v) = meta.get("sample_period") {
            let at = self.places.meta(self.path, "sample_period");
            let sp: f64 = v
                .parse()
                .map_err(|_| anyhow!("{at}: sample_period: '{}' is not a number", echo(v)))?;
            crate::validate::sample_period(sp)
                .map_err(|e| anyhow!("{at}: sample_period: {e}{}", self.unit_hint(sp)))?;
        }
        let dt = median(t.windows(2).map(|w| w[1] - w[0]).collect()).unwrap_or(0.0);
        if let Err(e) = crate::validate::sample_period(dt) {
            bail!(
                "{p}: column '{}': median time step: {e}{}",
                echo(self.t_header),
                self.unit_hint(dt)
            );
        }
        // A gap: the model would be run across time the log does not cover, and every
        // simulated state after it compared with a motor that moved unseen.
        if let Some(k) = (1..t.len()).find(|&k| t[k] - t[k - 1] > MAX_GAP_STEPS * dt) {
            bail!(
                "{}: column '{}': time jumps by {} s (from {} to {}), more than {MAX_GAP_STEPS} \
                 median steps ({} s): the log has a gap; split it there into two logs",
                self.places.row(self.path, k),
                echo(self.t_header),
                crate::validate::show(t[k] - t[k - 1]),
                crate::validate::show(t[k - 1]),
                crate::validate::show(t[k]),
                crate::validate::show(dt)
            );
        }
        Ok(())
    }

    /// A sample period `dt` too long for an undeclared time unit: perhaps t is in ms or us.
    fn unit_hint(&self, dt: f64) -> String {
        if self.declared.contains_key("t") || dt <= crate::validate::MAX_SAMPLE_PERIOD {
            return String::new();
        }
        [(1e3, "ms"), (1e6, "us")]
            .iter()
            .find(|(f, _)| crate::validate::sample_period(dt / f).is_ok())
            .map(|(_, u)| {
                format!(" (is t in {u}? declare it with a line '# unit.t={u}' or --units t={u})")
            })
            .unwrap_or_default()
    }
}

/// What is wrong in a CSV error, without the reader's own position (the message gives the
/// line once).
fn csv_problem(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("{len} fields, but the header has {expected_len}"),
        csv::ErrorKind::Utf8 { .. } => "not UTF-8 text".to_string(),
        csv::ErrorKind::Io(e) => format!("cannot read: {e}"),
        _ => echo(&e.to_string()),
    }
}

/// The running integral of `y` over `t` by the trapezoid rule, starting at 0:
/// `x_k = x_{k-1} + (t_k − t_{k−1})·(y_k + y_{k−1})/2`.
fn integrate_trapezoid(t: &[f64], y: &[f64]) -> Vec<f64> {
    let mut x = Vec::with_capacity(y.len());
    let mut acc = 0.0;
    for k in 0..y.len().min(t.len()) {
        if k > 0 {
            acc += (t[k] - t[k - 1]) * 0.5 * (y[k] + y[k - 1]);
        }
        x.push(acc);
    }
    x
}

/// Above this |Δθ/Δt| [rad/s] (about a million rpm) no motor turns: the units are wrong.
pub const MAX_PLAUSIBLE_SPEED: f64 = 1e5;

/// The median of some numbers (`None` when there are none).
fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let k = v.len() / 2;
    Some(*v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1)
}

/// The delimiter of a header row: the most frequent of comma, semicolon and tab (outside
/// quotes); comma when there is none.
fn sniff_delimiter(header: &str) -> u8 {
    let mut counts = [(b',', 0usize), (b';', 0), (b'\t', 0)];
    let mut quoted = false;
    for b in header.bytes() {
        if b == b'"' {
            quoted = !quoted;
        } else if !quoted {
            for (d, n) in &mut counts {
                if b == *d {
                    *n += 1;
                }
            }
        }
    }
    // max_by_key keeps the last maximum: scan in reverse priority so a tie picks the comma.
    counts
        .iter()
        .rev()
        .max_by_key(|(_, n)| *n)
        .filter(|(_, n)| *n > 0)
        .map(|(d, _)| *d)
        .unwrap_or(b',')
}

/// A field such as `1,5` or `-0,012`: a number once its comma is a point.
fn looks_like_decimal_comma(field: &str) -> bool {
    field.matches(',').count() == 1
        && field
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, ',' | '-' | '+' | 'e' | 'E'))
        && field.replace(',', ".").parse::<f64>().is_ok()
}

/// The header's column names for a message (each echoed safely, at most 12).
fn header_list(headers: &[String]) -> String {
    let mut s: Vec<String> = headers.iter().take(12).map(|h| echo(h)).collect();
    if headers.len() > 12 {
        s.push(format!("… ({} columns)", headers.len()));
    }
    s.join(", ")
}

/// The unit `value` declared for standard column `std`, checked against what the column
/// measures.
fn check_unit(std: &str, value: &str, plant: Plant) -> Result<&'static UnitDef> {
    let Some(q) = Quantity::of_column(std, plant) else {
        bail!("'{std}' is not a standard column");
    };
    let hint = |d: Option<&UnitDef>| match (std, d.map(|d| d.quantity)) {
        ("u", Some(Quantity::Torque)) => " (a torque or force input needs --plant torque)",
        ("u", Some(Quantity::Voltage)) => " (with --plant torque, u is a torque or force)",
        _ => "",
    };
    let Some(def) = UnitDef::lookup(value) else {
        bail!(
            "unknown unit; column '{std}' is {}: use {}{}",
            q.name(),
            q.accepted(),
            hint(None)
        );
    };
    if def.quantity != q {
        bail!(
            "'{}' is a unit of {}, but column '{std}' is {}: use {}{}",
            def.name(),
            def.quantity
                .name()
                .trim_start_matches("a ")
                .trim_start_matches("an "),
            q.name(),
            q.accepted(),
            hint(Some(def))
        );
    }
    Ok(def)
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
    fn parse_units(text: &str, units: &str, plant: Plant) -> Result<MotorLog> {
        let units = Units::parse(units)?;
        MotorLog::parse_with_units(
            text,
            Path::new("x.csv"),
            &ColumnMap::default(),
            &units,
            plant,
        )
    }

    #[test]
    fn semicolon_and_tab_delimiters_are_sniffed() {
        for d in [";", "\t"] {
            let text =
                "# sample_period=0.5\nt,u,i,theta\n0,1,2,3\n0.5,1.5,2.5,3.5\n".replace(',', d);
            let log = parse(&text, Plant::Voltage).unwrap();
            assert_eq!(log.u, vec![1.0, 1.5], "delimiter {d:?}");
            assert_eq!(log.theta, vec![3.0, 3.5]);
            assert_eq!(log.sample_period(), 0.5);
        }
        // A comma inside a quoted header name does not make it comma-separated.
        let log = parse(
            "\"t\";u;i;theta;\"a,b\"\n0;1;2;3;4\n1;1;2;3;4\n",
            Plant::Voltage,
        )
        .unwrap();
        assert_eq!(log.extra("a,b"), Some(&[4.0, 4.0][..]));
    }

    #[test]
    fn decimal_commas_are_an_error_naming_line_and_column() {
        let e = parse("t;u;i;theta\n0;1;2;3\n0,012;1,5;2;3\n", Plant::Voltage).unwrap_err();
        let e = e.to_string();
        assert!(e.starts_with("x.csv:3: column 't': '0,012'"), "{e}");
        assert!(e.contains("decimal comma") && e.contains("0.012"), "{e}");
        let e = parse("t\tu\ti\ttheta\n0\t1\t2\t3\n1\t1,5\t2\t3\n", Plant::Voltage)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:3: column 'u': '1,5'"), "{e}");
        assert!(e.contains("decimal point"), "{e}");
    }

    #[test]
    fn byte_order_mark_keeps_metadata_and_line_numbers() {
        let text = "\u{feff}# sample_period=0.25\n# hall_resolution_rad=0.1\nt,u,i,theta\n0,1,2,3\n0.25,1,2,3\n0.5,x,2,3\n";
        let e = parse(text, Plant::Voltage).unwrap_err().to_string();
        assert_eq!(e, "x.csv:6: column 'u': 'x' is not a number");
        let log = parse(&text.replace(",x,", ",1,"), Plant::Voltage).unwrap();
        assert_eq!(log.sample_period(), 0.25);
        assert_eq!(log.meta_f64("hall_resolution_rad"), Some(0.1));
        // Without metadata the BOM sits before the header's first name.
        let log = parse("\u{feff}t,u,i,theta\n0,1,2,3\n1,1,2,3\n", Plant::Voltage).unwrap();
        assert_eq!(log.t, vec![0.0, 1.0]);
    }

    #[test]
    fn line_numbers_count_comment_lines_in_the_body() {
        let text = "# a=b\nt,u,i,theta\n0,1,2,3\n# a comment\n\n1,1,2,3\n2,y,2,3\n";
        let e = parse(text, Plant::Voltage).unwrap_err().to_string();
        assert_eq!(e, "x.csv:7: column 'u': 'y' is not a number");
        let text = "t,u,i,theta\n0,1,2,3\n# pause\n1,1,2,3\n1,1,2,3\n";
        let e = parse(text, Plant::Voltage).unwrap_err().to_string();
        assert!(
            e.starts_with("x.csv:5: column 't': time does not increase"),
            "{e}"
        );
    }

    #[test]
    fn rows_read_in_pieces_equal_rows_read_from_the_start() {
        let mut text = String::from("t,u,i,theta\r\n");
        for k in 0..400 {
            match k % 37 {
                5 => text.push_str("# a comment\n"),
                11 => text.push('\n'),
                _ => {}
            }
            let end = if k % 3 == 0 { "\r\n" } else { "\n" };
            text.push_str(&format!(
                "{k},{}, {} ,{}{end}",
                k % 7,
                0.1 * k as f64,
                -2.5e-3 * k as f64
            ));
        }
        let headers: Vec<String> = ["t", "u", "i", "theta"].map(String::from).to_vec();
        let rows = CsvRows {
            p: "x.csv",
            headers: &headers,
            std_cols: &[0, 1, 2, 3],
            delimiter: b',',
        };
        let read_both = |text: &str| {
            let mut rdr = csv_reader(b',', true).from_reader(text.as_bytes());
            rdr.headers().unwrap();
            let start = rdr.position().byte() as usize;
            let chunks = rows.chunks(text.as_bytes(), start, 64).expect("pieces");
            assert!(chunks.len() > 1);
            (rows.read(&mut rdr, 3), rows.read_chunks(&chunks, 3))
        };
        let (whole, pieces) = read_both(&text);
        let (whole, pieces) = (whole.unwrap(), pieces.unwrap());
        assert_eq!(whole.1, pieces.1);
        assert_eq!(whole.0, pieces.0);
        assert_eq!(whole.1.len(), 400);
        // An error names the same line.
        let bad = text.replace("\n350,", "\n350x,");
        let (whole, pieces) = read_both(&bad);
        let (whole, pieces) = (whole.unwrap_err(), pieces.unwrap_err());
        assert_eq!(whole.to_string(), pieces.to_string());
        assert!(whole.to_string().contains("'350x'"), "{whole}");
        // A quote anywhere keeps the reading in one piece.
        let quoted = text.replace("\n7,", "\n\"7\",");
        let body = quoted.as_bytes();
        assert!(rows.chunks(body, 13, 64).is_none());
    }

    #[test]
    fn declared_units_are_converted_to_si() {
        let text = "# sample_period=12\n# unit.t=ms\n# unit.theta=deg\n# unit.omega=rpm\n\
                    # unit.i=mA\n# unit.u=mV\nt,u,i,theta,omega\n0,1000,1500,180,60\n\
                    12,2000,-500,360,-30\n";
        let log = parse(text, Plant::Voltage).unwrap();
        assert_eq!(log.t, vec![0.0, 0.012]);
        assert_eq!(log.sample_period(), 0.012);
        assert_eq!(log.u, vec![1.0, 2.0]);
        assert_eq!(log.i, Some(vec![1.5, -0.5]));
        assert!((log.theta[0] - PI).abs() < 1e-15 && (log.theta[1] - 2.0 * PI).abs() < 1e-15);
        let w = log.omega.clone().unwrap();
        assert!((w[0] - 2.0 * PI).abs() < 1e-15 && (w[1] + PI).abs() < 1e-15);
        assert_eq!(log.units["t"], "ms");
        assert_eq!(log.units["omega"], "rpm");
        assert!(
            !log.meta.contains_key("unit.t"),
            "converted: no unit line left"
        );
        // Written back it is SI and reads the same without unit lines.
        let again = parse(&log.to_csv(), Plant::Voltage).unwrap();
        assert_eq!(again.t, log.t);
        assert_eq!(again.sample_period(), 0.012);
        // --units does the same (and overrides the file); a mapped name works too.
        let log = parse_units(
            "t,u,i,theta\n0,1,1,1\n5,1,1,1\n",
            "t=us,theta=rev",
            Plant::Voltage,
        )
        .unwrap();
        assert_eq!(log.t, vec![0.0, 5e-6]);
        assert_eq!(log.theta[0], 2.0 * PI);
        let map = ColumnMap::parse("t=time,u=force,theta=pos").unwrap();
        let log = MotorLog::parse_with_units(
            "# unit.pos=mm\ntime,force,pos\n0,1,1\n1,1,2\n",
            Path::new("e.csv"),
            &map,
            &Units::parse("force=N").unwrap(),
            Plant::Torque,
        )
        .unwrap();
        assert_eq!(log.theta, vec![0.001, 0.002]);
        assert!(log.is_linear());
        for spelling in ["N·m", "N*m", "Nm", "N.m"] {
            let text = format!("# unit.u={spelling}\nt,u,theta\n0,1,1\n1,1,2\n");
            let log = parse(&text, Plant::Torque).unwrap();
            assert_eq!(log.units["u"], "N·m");
        }
    }

    #[test]
    fn a_unit_of_the_wrong_kind_or_unknown_is_an_error_naming_the_line() {
        let e = parse(
            "# a=b\n# unit.t=rpm\nt,u,i,theta\n0,1,2,3\n1,1,2,3\n",
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("x.csv:2: unit.t=rpm: 'rpm' is a unit of velocity"),
            "{e}"
        );
        assert!(e.contains("use s, ms, us"), "{e}");
        let e = parse(
            "# unit.theta=furlong\nt,u,i,theta\n0,1,2,3\n1,1,2,3\n",
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("x.csv:1: unit.theta=furlong: unknown unit"),
            "{e}"
        );
        let e = parse(
            "# unit.u=N·m\nt,u,i,theta\n0,1,2,3\n1,1,2,3\n",
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("--plant torque"), "{e}");
        let e = parse(
            "# unit.tt=s\nt,u,i,theta\n0,1,2,3\n1,1,2,3\n",
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("x.csv:1: unit.tt: no column 'tt'"), "{e}");
        let e = parse_units("t,u,i,theta\n0,1,2,3\n1,1,2,3\n", "i=V", Plant::Voltage)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--units: i=V: 'V' is a unit of voltage"),
            "{e}"
        );
        assert!(Units::parse("t=fortnight")
            .unwrap_err()
            .to_string()
            .starts_with("--units"));
        assert!(Units::parse("t").is_err());
        // The unit of an extra column stays in the metadata.
        let log = parse(
            "# unit.temp=degC\nt,u,i,theta,temp\n0,1,2,3,4\n1,1,2,3,4\n",
            Plant::Voltage,
        )
        .unwrap();
        assert_eq!(log.meta["unit.temp"], "degC");
    }

    #[test]
    fn sanity_warnings_catch_numbers_that_do_not_fit_the_units() {
        // t in ms without a unit line: the sample period disagrees with the steps.
        let mut text =
            String::from("# sample_period=0.001\n# hall_resolution_rad=0.1\nt,u,i,theta\n");
        for k in 0..20 {
            text.push_str(&format!("{},1,1,{}\n", k, 0.1 * (k / 2) as f64));
        }
        let w = parse(&text, Plant::Voltage).unwrap().sanity_warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].starts_with("x.csv: sample_period=0.001 s"), "{w:?}");
        assert!(w[0].contains("unit.t=ms"), "{w:?}");
        // Declared, all is well.
        let ok = text.replace("# hall", "# unit.t=ms\n# sample_period=1\n# hall");
        let ok = ok.replacen("# sample_period=0.001\n", "", 1);
        let w = parse(&ok, Plant::Voltage).unwrap().sanity_warnings();
        assert!(w.is_empty(), "{w:?}");
        // The angle in degrees: not a multiple of the Hall step, and too fast.
        let mut text =
            String::from("# sample_period=0.001\n# hall_resolution_rad=0.1\nt,u,i,theta\n");
        for k in 0..20 {
            text.push_str(&format!(
                "{},1,1,{}\n",
                0.001 * k as f64,
                5000.37 * k as f64
            ));
        }
        let w = parse(&text, Plant::Voltage).unwrap().sanity_warnings();
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].contains("not a multiple of hall_resolution_rad"),
            "{w:?}"
        );
        assert!(w[1].contains("beyond any motor"), "{w:?}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(400))]

        /// Any bytes: an error or a log, never a panic.
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..600)) {
            let text = String::from_utf8_lossy(&bytes);
            for plant in [Plant::Voltage, Plant::Torque] {
                let _ = parse(&text, plant);
            }
        }

        /// Text shaped like a log (metadata, delimiters, numbers, junk): never a panic, and
        /// a log that reads has a physical sample period and finite standard columns.
        #[test]
        fn log_like_text_never_panics(
            text in "\u{feff}?(# ?(sample_period|unit\\.t|unit\\.theta|hall_resolution_rad|x)=[-0-9.eEnaifmsrdgv]{0,8}\n){0,4}(t|u|i|theta|omega|x|\"t,u\")([,;\t](t|u|i|theta|omega|x)){0,6}\n([-+0-9.eEnaif]{0,12}([,;\t\"][-+0-9.eEnaif]{0,12}){0,6}\n){0,12}"
        ) {
            for plant in [Plant::Voltage, Plant::Torque] {
                if let Ok(log) = parse(&text, plant) {
                    let dt = log.sample_period();
                    proptest::prop_assert!((crate::validate::MIN_SAMPLE_PERIOD..=crate::validate::MAX_SAMPLE_PERIOD).contains(&dt), "dt {}", dt);
                    proptest::prop_assert!(log.t.iter().chain(&log.u).chain(&log.theta).all(|v| v.is_finite()));
                    let _ = log.sanity_warnings();
                    let _ = log.to_csv();
                }
            }
        }
    }

    #[test]
    fn a_mat_file_reads_with_map_and_units_like_a_csv() {
        use crate::matlab::tests::mat_file;
        let n = 5;
        let t: Vec<f64> = (0..n).map(|k| k as f64).collect(); // ms
        let q: Vec<f64> = (0..n).map(|k| 2.0 * k as f64).collect(); // mm
        let f: Vec<f64> = (0..n).map(|k| 10.0 + k as f64).collect();
        let bytes = mat_file(
            &[
                ("gtau", 1, 1, vec![35.15]),
                ("t_ms", n, 1, t.clone()),
                ("qm", n, 1, q),
                ("force", 1, n, f.clone()),
                ("short", 3, 1, vec![0.0; 3]),
            ],
            true,
        );
        let map = ColumnMap::parse("t=t_ms,theta=qm,u=force").unwrap();
        let units = Units::parse("t=ms,theta=mm").unwrap();
        let log =
            MotorLog::parse_mat(&bytes, Path::new("e.mat"), &map, &units, Plant::Torque).unwrap();
        assert_eq!(log.t, t.iter().map(|v| v / 1e3).collect::<Vec<_>>());
        assert_eq!(log.theta, vec![0.0, 0.002, 0.004, 0.006, 0.008]);
        assert_eq!(log.u, f);
        assert_eq!(log.meta_f64("gtau"), Some(35.15));
        assert!(log.is_linear() && log.i.is_none());
        // A voltage plant needs a current; a variable of another length is named.
        let e = MotorLog::parse_mat(&bytes, Path::new("e.mat"), &map, &units, Plant::Voltage)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("e.mat: missing column 'i'"), "{e}");
        let map = ColumnMap::parse("t=t_ms,theta=short,u=force").unwrap();
        let e = MotorLog::parse_mat(&bytes, Path::new("e.mat"), &map, &units, Plant::Torque)
            .unwrap_err()
            .to_string();
        assert!(e.contains("variable 'short' has 3 elements, not 5"), "{e}");
        let e = MotorLog::parse_mat(
            &bytes,
            Path::new("e.mat"),
            &ColumnMap::default(),
            &Units::default(),
            Plant::Torque,
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("e.mat: no vector variable 't' (map"), "{e}");
        assert!(e.contains("t_ms, qm, force, short"), "{e}");
    }

    #[test]
    fn a_log_with_velocity_but_no_angle_integrates_it_and_says_so() {
        // omega = 3 + 2t: the trapezoid rule is exact, theta = 3t + t^2.
        let mut text = String::from("# hall_resolution_rad=0.1\nt,u,i,speed\n");
        for k in 0..11 {
            let t = 0.1 * k as f64;
            text.push_str(&format!("{t},1,0,{}\n", 3.0 + 2.0 * t));
        }
        let map = ColumnMap::parse("omega=speed").unwrap();
        let log = MotorLog::parse(&text, Path::new("w.csv"), &map, Plant::Voltage).unwrap();
        for (t, th) in log.t.iter().zip(&log.theta) {
            assert!((th - (3.0 * t + t * t)).abs() < 1e-12, "t {t}: {th}");
        }
        let w = log.sanity_warnings();
        assert_eq!(w.len(), 1, "no Hall warning on an integrated angle: {w:?}");
        assert!(
            w[0].starts_with("w.csv: no angle column: theta is the integral of speed"),
            "{w:?}"
        );
        // Neither angle nor velocity: the message names both.
        let e = parse("t,u,i\n0,1,1\n1,1,1\n", Plant::Voltage)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:1: missing column 'theta'"), "{e}");
        assert!(e.contains("velocity column 'omega'"), "{e}");
    }

    #[test]
    fn echoed_paths_keep_their_start_and_file_name() {
        let short = Path::new("logs/run\u{1b}[2J.csv");
        assert_eq!(echo_path(short), "logs/run\\x1b[2J.csv");
        let long = format!("/data/{}/run.csv", "d\u{7}".repeat(3000));
        let shown = echo_path(Path::new(&long));
        assert!(shown.chars().count() <= ECHO_PATH_MAX, "{shown}");
        assert!(
            shown.starts_with("/data/d\\x07") && shown.ends_with("/run.csv"),
            "{shown}"
        );
        assert_eq!(shown.matches('…').count(), 1, "{shown}");
        assert!(!shown.chars().any(char::is_control), "{shown}");
    }

    #[test]
    fn echoed_fields_are_cut_and_cleaned() {
        let long = "9".repeat(500) + "x";
        let e = parse(
            &format!("t,u,i,theta\n0,1,2,3\n1,{long},2,3\n"),
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert!(e.len() < 120 && e.contains('…'), "{e}");
        let e = parse(
            "t,u,i,theta\n0,1,2,3\n1,\u{1b}[31mred\u{7},2,3\n",
            Plant::Voltage,
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "x.csv:3: column 'u': '\\x1b[31mred\\x07' is not a number"
        );
        assert_eq!(echo("a\u{1b}]0;x\u{7}b"), "a\\x1b]0;x\\x07b");
        assert_eq!(echo("1\u{0}2"), "1\\02");
        let nuls = echo(&"\0".repeat(100));
        assert!(
            nuls.chars().count() <= ECHO_MAX && nuls.ends_with("\\0…"),
            "{nuls}"
        );
        let e = parse(&format!("t,u,{long}\n0,1,3\n"), Plant::Voltage)
            .unwrap_err()
            .to_string();
        assert!(e.len() < 200, "{e}");
    }
}
