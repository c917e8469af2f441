//! Property tests of the readers a user's text reaches: MODEL.toml (any text, mutated valid
//! models, the SINDYc `[sindy]` tables through the model loader) and `--map`. None panics;
//! each error is one line naming the file or the flag; what is accepted is usable.
use motorid::board::coeffs::{self, LoopSettings};
use motorid::log::ColumnMap;
use motorid::model::{Model, ModelKind};
use proptest::prelude::*;
use std::path::Path;

const LUGRE: &str = r#"kind = "lugre"
plant = "voltage"
sample_period = 0.012

[motor]
r = 0.2162
l = 0.0003
kt = 0.07126
kb = 0.07126
j = 0.0003

[lugre]
alpha0 = 0.08
alpha1 = 0.0175
alpha2 = 0.0016
v0 = 3.676
sigma0 = 317.225
sigma1 = 22.2464

[[effects]]
name = "cogging"
harmonic = 6
amp = 0.01
phase = 0.5

[sensor]
hall_resolution_rad = 0.0952
velocity_window = 10
"#;

/// A SINDYc model of the paper's motor (voltage plant).
const SINDYC: &str = include_str!("fixtures/paper_sindyc.toml");

/// Load as `motorid` does (parse, then validate), then use the model as `export` does.
/// Returns the error text, if any.
fn load_and_use(text: &str) -> Result<Model, String> {
    let path = Path::new("m.toml");
    let model = Model::parse(text, path)
        .and_then(|m| {
            m.validate().map_err(|e| anyhow::anyhow!("m.toml: {e}"))?;
            Ok(m)
        })
        .map_err(|e| format!("{e:#}"))?;
    if model.kind == ModelKind::Sindyc {
        // A model that loads has a table the simulation and export can read.
        coeffs::sindy_model(&model).expect("a loaded SINDYc model's table reads");
    }
    let _ = coeffs::coefficients(&model, LoopSettings::default());
    Ok(model)
}

fn one_line(e: &str) -> bool {
    e.starts_with("m.toml") && !e.contains('\n') && e.len() < 400
}

/// Numbers a careless or hostile file puts where a number goes.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e308".to_string()),
        Just("-1e308".to_string()),
        Just("0".to_string()),
        Just("0.0".to_string()),
        Just("-1".to_string()),
        Just("9223372036854775807".to_string()),
        Just("\"text\"".to_string()),
        Just("[]".to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
    ]
}

/// A valid model with some lines' values replaced, some lines dropped or repeated.
fn mutated(base: &'static str) -> impl Strategy<Value = String> {
    let n = base.lines().count();
    proptest::collection::vec((0..n, 0u8..4, number()), 1..5).prop_map(move |edits| {
        let mut lines: Vec<String> = base.lines().map(str::to_string).collect();
        for (at, how, value) in edits {
            let at = at % lines.len().max(1);
            if lines.is_empty() {
                break;
            }
            match how {
                0 | 1 => {
                    if let Some((k, _)) = lines[at].split_once('=') {
                        lines[at] = format!("{k}= {value}");
                    }
                }
                2 => {
                    lines.remove(at);
                }
                _ => {
                    let l = lines[at].clone();
                    lines.insert(at, l);
                }
            }
        }
        lines.join("\n")
    })
}

/// Terms a `[sindy.*]` table may name, and names it must refuse.
fn term_name() -> impl Strategy<Value = String> {
    prop_oneof![
        proptest::sample::select(vec![
            "x",
            "xdot",
            "z",
            "i",
            "u",
            "tanh(a*xdot)",
            "tanh(a*z)",
            "|xdot|*xdot",
            "sin(x)",
            "cos(x)",
            "sin(6*x)",
            "sin(65535*x)",
            "sin(99999999999*x)",
            "exp",
            "",
            "\\u0000",
            "tanh(a*",
            "z*xdot",
        ])
        .prop_map(str::to_string),
        "[a-z*()|0-9]{0,12}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Any text: an error on one line, or a model whose numbers are finite.
    #[test]
    fn any_text_is_a_model_or_one_error_line(
        text in "([a-z_.\\[\\]\"]{0,12} ?= ?[-0-9a-z.e\"\\[\\],]{0,12}\n|\\[[a-z.]{0,10}\\]\n|\\[\\[effects\\]\\]\n|[^\n]{0,20}\n){0,20}"
    ) {
        match load_and_use(&text) {
            Err(e) => prop_assert!(one_line(&e), "{}", e),
            Ok(m) => prop_assert!(m.sample_period.is_finite() && m.motor.j > 0.0),
        }
    }

    #[test]
    fn mutated_lugre_models_never_panic(text in mutated(LUGRE)) {
        match load_and_use(&text) {
            Err(e) => prop_assert!(one_line(&e), "{}", e),
            Ok(m) => {
                let l = m.lugre.unwrap();
                prop_assert!([l.alpha0, l.alpha1, l.alpha2, l.v0, l.sigma0, l.sigma1]
                    .iter()
                    .all(|v| v.is_finite()));
            }
        }
    }

    #[test]
    fn mutated_sindyc_models_never_panic(text in mutated(SINDYC)) {
        if let Err(e) = load_and_use(&text) {
            prop_assert!(one_line(&e), "{}", e);
        }
    }

    /// `[sindy.accel]` tables of arbitrary terms and values, through the model loader.
    #[test]
    fn sindy_tables_of_any_terms_never_panic(
        terms in proptest::collection::vec((term_name(), number()), 0..40)
    ) {
        let mut text = SINDYC.replace("[sindy.accel]\ni = 85.9\n\"tanh(a*xdot)\" = -168.2\n", "");
        text.push_str("\n[sindy.accel]\n");
        for (name, value) in terms {
            text.push_str(&format!("{name:?} = {value}\n"));
        }
        match load_and_use(&text) {
            Err(e) => prop_assert!(one_line(&e), "{}", e),
            Ok(m) => {
                let s = coeffs::sindy_model(&m).unwrap();
                prop_assert!(s.accel.terms.iter().all(|(_, c)| c.is_finite()));
            }
        }
    }

    /// `--map`: any text is a map or one `--map` error line; a map of standard names reads
    /// back both ways.
    #[test]
    fn map_specs_parse_or_fail_on_one_line(spec in "[a-z_=, \t\u{1b}\\[\u{7f}é]{0,40}") {
        if let Err(e) = ColumnMap::parse(&spec) {
            let e = e.to_string();
            prop_assert!(e.starts_with("--map: ") && !e.contains('\n'), "{}", e);
            prop_assert!(!e.contains('\u{1b}'), "{}", e);
        }
    }

    #[test]
    fn standard_maps_read_back(
        names in proptest::collection::btree_map(
            proptest::sample::select(ColumnMap::STANDARD.to_vec()),
            "[A-Za-z][A-Za-z0-9_]{0,10}",
            0..5,
        )
    ) {
        // One log column cannot stand for two quantities (that is an error of its own).
        let columns: std::collections::BTreeSet<String> =
            names.values().map(|v| v.to_lowercase()).collect();
        prop_assume!(columns.len() == names.len());
        let spec: Vec<String> = names.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let map = ColumnMap::parse(&spec.join(",")).unwrap();
        for (std, name) in &names {
            prop_assert_eq!(map.name_of(std), name.as_str());
        }
        for std in ColumnMap::STANDARD {
            if !names.contains_key(std) {
                prop_assert_eq!(map.name_of(std), std);
            }
        }
    }
}

#[test]
fn the_base_models_load() {
    load_and_use(LUGRE).unwrap();
    load_and_use(SINDYC).unwrap();
}
