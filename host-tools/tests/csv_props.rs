//! Property tests of the CSV log reader, through a file as `motorid` reads it: random bytes,
//! log-shaped text with any delimiter, byte-order marks, comments, metadata, CRLF, NaN/inf,
//! huge and tiny numbers and ragged rows. None panics; an error is one line that starts with
//! the file's name (and names the line when one row is at fault); a log that reads holds
//! finite, checked data.
use motorid::log::{ColumnMap, MotorLog, Plant, Units};
use proptest::prelude::*;
use std::path::Path;

/// Longest error line: the text, two echoed paths and a few echoed values.
const MAX_ERROR: usize = 400;

/// Read `bytes` as the log file `dir/log.csv`, as every command does.
fn read(dir: &Path, bytes: &[u8], plant: Plant) -> Result<MotorLog, String> {
    let path = dir.join("log.csv");
    std::fs::write(&path, bytes).unwrap();
    MotorLog::read_with_units(&path, &ColumnMap::default(), &Units::default(), plant)
        .map_err(|e| format!("{e:#}"))
}

/// The error is one line naming the file, without a control character.
fn one_error_line(dir: &Path, e: &str) -> Result<(), TestCaseError> {
    let name = dir.join("log.csv").display().to_string();
    prop_assert!(e.starts_with(&name), "does not name the file: {}", e);
    prop_assert!(
        !e.chars().any(char::is_control),
        "control character: {:?}",
        e
    );
    prop_assert!(
        e.chars().count() <= MAX_ERROR,
        "{} characters: {}",
        e.len(),
        e
    );
    Ok(())
}

/// A log that reads: series of one length, finite, time increasing, a physical sample
/// period; the derived outputs of every command are computable.
fn checked(log: &MotorLog) -> Result<(), TestCaseError> {
    let n = log.t.len();
    prop_assert!(n >= 2 && log.u.len() == n && log.theta.len() == n);
    let optional = log.i.iter().chain(&log.omega);
    prop_assert!(optional.clone().all(|s| s.len() == n));
    prop_assert!(log
        .t
        .iter()
        .chain(&log.u)
        .chain(&log.theta)
        .chain(optional.flatten())
        .all(|v| v.is_finite()));
    prop_assert!(log.t.windows(2).all(|w| w[1] > w[0]), "time not increasing");
    let dt = log.sample_period();
    prop_assert!(
        (motorid::validate::MIN_SAMPLE_PERIOD..=motorid::validate::MAX_SAMPLE_PERIOD).contains(&dt),
        "sample period {}",
        dt
    );
    let _ = log.sanity_warnings();
    let _ = log.to_csv();
    Ok(())
}

/// A number as a careless or hostile file writes one.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => (-1000.0f64..1000.0).prop_map(|v| format!("{v}")),
        1 => proptest::sample::select(vec![
            "nan", "NaN", "inf", "-inf", "+inf", "infinity", "1e308", "-1e308", "1e400",
            "1e-320", "4.9e-324", "-0", "0x10", "1,5", "", " ", "\"1\"", "1e", ".", "-",
            "9999999999999999999999999999", "1_000",
        ])
        .prop_map(str::to_string),
        1 => any::<f64>().prop_map(|v| format!("{v:e}")),
    ]
}

/// Log-shaped text: an optional BOM, metadata and comment lines, a header of standard and
/// other names, rows of numbers with a chosen delimiter, ragged at random, CRLF or LF.
fn log_text() -> impl Strategy<Value = String> {
    let meta = proptest::collection::vec(
        prop_oneof![
            (
                proptest::sample::select(vec![
                    "sample_period",
                    "hall_resolution_rad",
                    "pole_pairs",
                    "unit.t",
                    "unit.theta",
                    "unit.u",
                    "note",
                ]),
                prop_oneof![
                    number(),
                    proptest::sample::select(vec!["ms", "s", "deg", "rad", "us"])
                        .prop_map(str::to_string),
                ],
            )
                .prop_map(|(k, v)| format!("# {k}={v}")),
            "#[^\n]{0,20}".prop_map(|c| c),
        ],
        0..4,
    );
    let header = proptest::collection::vec(
        proptest::sample::select(vec!["t", "u", "i", "theta", "omega", "x", "T", " t"]),
        1..7,
    );
    let delim = proptest::sample::select(vec![",", ";", "\t", "|", " "]);
    let rows = proptest::collection::vec(proptest::collection::vec(number(), 0..8), 0..20);
    (
        any::<bool>(),
        meta,
        header,
        delim,
        rows,
        any::<bool>(),
        proptest::option::of((0usize..20, "#[^\n]{0,10}")),
    )
        .prop_map(|(bom, meta, header, delim, rows, crlf, comment)| {
            let eol = if crlf { "\r\n" } else { "\n" };
            let mut lines: Vec<String> = meta;
            lines.push(header.join(delim));
            for (k, row) in rows.iter().enumerate() {
                if comment.as_ref().is_some_and(|(at, _)| *at == k) {
                    lines.push(comment.as_ref().unwrap().1.clone());
                }
                lines.push(row.join(delim));
            }
            let mut text = if bom {
                "\u{feff}".to_string()
            } else {
                String::new()
            };
            text.push_str(&lines.join(eol));
            text.push_str(eol);
            text
        })
}

/// A good 12 ms log of `n` rows, its rows as fields.
fn good_rows(n: usize) -> Vec<Vec<String>> {
    (0..n)
        .map(|k| {
            let t = k as f64 * 0.012;
            vec![
                format!("{t}"),
                format!("{}", (t * 3.0).sin()),
                format!("{}", 0.1 * (k % 5) as f64),
                format!("{}", 0.0952 * (k / 3) as f64),
            ]
        })
        .collect()
}

/// What is done to one row of a good log: each must be refused at that row's line.
fn bad_field() -> impl Strategy<Value = (u8, String)> {
    prop_oneof![
        // A field too many, or too few.
        Just((0u8, String::new())),
        Just((1u8, String::new())),
        // A value that is not a finite number, in any column.
        proptest::sample::select(vec![
            "nan",
            "inf",
            "-inf",
            "1e400",
            "abc",
            "1,5",
            "",
            "0x1",
            "--1",
            "\u{1b}[31m1",
        ])
        .prop_map(|v| (2u8, v.to_string())),
    ]
}

proptest! {
    // Brief in CI: a few seconds in all.
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn random_bytes_are_a_log_or_one_error_line(
        bytes in proptest::collection::vec(any::<u8>(), 0..1500),
        bom in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let mut b = if bom { vec![0xef, 0xbb, 0xbf] } else { Vec::new() };
        b.extend_from_slice(&bytes);
        for plant in [Plant::Voltage, Plant::Torque] {
            match read(dir.path(), &b, plant) {
                Ok(log) => checked(&log)?,
                Err(e) => one_error_line(dir.path(), &e)?,
            }
        }
    }

    #[test]
    fn log_shaped_text_is_a_log_or_one_error_line(text in log_text()) {
        let dir = tempfile::tempdir().unwrap();
        for plant in [Plant::Voltage, Plant::Torque] {
            match read(dir.path(), text.as_bytes(), plant) {
                Ok(log) => checked(&log)?,
                Err(e) => one_error_line(dir.path(), &e)?,
            }
        }
    }

    /// One bad row in a good log (any delimiter, BOM, comments before it): refused, and the
    /// message names that row's line.
    #[test]
    fn a_bad_row_is_named_by_its_line(
        n in 5usize..40,
        at in 0usize..40,
        column in 0usize..4,
        (how, value) in bad_field(),
        bom in any::<bool>(),
        comments in 0usize..3,
        delim in proptest::sample::select(vec![",", ";", "\t"]),
    ) {
        let mut rows = good_rows(n);
        let at = at % n;
        match how {
            0 => rows[at].push("1".to_string()),
            1 => {
                rows[at].pop();
            }
            _ => rows[at][column] = value,
        }
        let mut lines = vec!["# sample_period=0.012".to_string()];
        lines.extend((0..comments).map(|k| format!("# comment {k}")));
        lines.push(["t", "u", "i", "theta"].join(delim));
        let first_row = lines.len() + 1;
        lines.extend(rows.iter().map(|r| r.join(delim)));
        let mut text = if bom { "\u{feff}".to_string() } else { String::new() };
        text.push_str(&lines.join("\n"));
        text.push('\n');
        let dir = tempfile::tempdir().unwrap();
        let e = match read(dir.path(), text.as_bytes(), Plant::Voltage) {
            Ok(_) => return Err(TestCaseError::fail(format!("accepted:\n{text}"))),
            Err(e) => e,
        };
        one_error_line(dir.path(), &e)?;
        let place = format!("log.csv:{}:", first_row + at);
        prop_assert!(e.contains(&place), "'{}' missing in: {}", place, e);
    }
}

/// Hostile logs kept as a corpus: each reads or fails on one line, never panics.
#[test]
fn the_corpus_reads_or_fails_on_one_line() {
    let corpus: &[&[u8]] = &[
        b"",
        b"\xef\xbb\xbf",
        b"\xef\xbb\xbf\xef\xbb\xbft,u,i,theta\n0,1,2,3\n0.012,1,2,3\n",
        b"t,u,i,theta\n",
        b"t,u,i,theta\n0,1,2,3\n",
        b"t,u,i,theta\r\n0,1,2,3\r\n0.012,1,2,3\r\n",
        b"t,u,i,theta\n0,1,2,3\n0,1,2,3\n",
        b"t,u,i,theta\n1,1,2,3\n0,1,2,3\n",
        b"t,u,i,theta\n0,1e308,1e308,1e308\n0.012,-1e308,-1e308,-1e308\n",
        b"t,u,i,theta\n0,4.9e-324,0,0\n4.9e-324,0,0,0\n",
        b"t;u;i;theta\n0;1;2;3\n0.012;1;2;3\n",
        b"t\tu\ti\ttheta\n0\t1\t2\t3\n0.012\t1\t2\t3\n",
        b"# sample_period=0.012\n# sample_period=0.012\nt,u,i,theta\n",
        b"#\n#=\n#==\n# =1\nt,u,i,theta\n0,1,2,3\n0.012,1,2,3\n",
        b"t,u,i,theta\n0,1,2,3\n# a comment between rows\n0.012,1,2,3\n",
        b"\"t\",\"u\",\"i\",\"theta\"\n\"0\",\"1\",\"2\",\"3\"\n\"0.012\",1,2,3\n",
        b"t,u,i,theta\n0,1,2,\"3\n0.012,1,2,3\n",
        b"\x00\x01\x02\x03",
        b"t,u,i,theta\n0,1,2,3\xff\n",
        b"t,t,t,t\n0,1,2,3\n",
        b",,,\n,,,\n",
    ];
    let dir = tempfile::tempdir().unwrap();
    for bytes in corpus {
        for plant in [Plant::Voltage, Plant::Torque] {
            match read(dir.path(), bytes, plant) {
                Ok(log) => checked(&log).unwrap(),
                Err(e) => one_error_line(dir.path(), &e).unwrap(),
            }
        }
    }
}
