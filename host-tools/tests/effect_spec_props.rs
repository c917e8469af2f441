//! Property tests of the effect-spec parser (`--effect` and `--add`): random strings and
//! mutations of valid specs never panic; an error is one line naming the flag; a spec that
//! parses has finite values within its keys' ranges and gives the same effect back.
use control::effects::EffectKind;
use motorid::effect_spec::EffectSpec;
use motorid::effects;
use proptest::prelude::*;

/// Longest error line: the flag, the echoed spec and the list of known effects or keys.
const MAX_ERROR: usize = 600;

/// Parse as the commands do; check what comes back either way.
fn parse_checked(flag: &str, spec: &str) -> Result<(), TestCaseError> {
    match EffectSpec::parse_flag(flag, spec) {
        Err(e) => {
            let e = format!("{e:#}");
            prop_assert!(e.starts_with(&format!("{flag} '")), "{}", e);
            prop_assert!(!e.chars().any(char::is_control), "{:?}", e);
            prop_assert!(
                e.chars().count() <= MAX_ERROR,
                "{} characters: {}",
                e.len(),
                e
            );
        }
        Ok(s) => {
            for key in effects::of(s.kind).keys {
                let v = s.get(key.name);
                let (lo, hi) = key.range();
                prop_assert!(v.is_finite(), "{} = {}", key.name, v);
                if s.values.contains_key(key.name) {
                    prop_assert!(
                        lo <= v && v <= hi,
                        "{} = {} outside {}..{}",
                        key.name,
                        v,
                        lo,
                        hi
                    );
                }
            }
            // A table given without its range (`lo`, `hi`) takes it from the data when it is
            // fitted: there is no effect to read back until then.
            if s.kind == EffectKind::Table && s.get("lo") >= s.get("hi") {
                return Ok(());
            }
            // The effect the simulation and the fit use, and the spec it reads back as.
            let e = s.to_effect();
            let back = EffectSpec::from_effect(&e);
            prop_assert_eq!(back.kind, s.kind);
            prop_assert!(back.check_values().is_ok(), "{:?}", back);
        }
    }
    Ok(())
}

/// A valid spec: an effect with some of its keys at values inside their ranges.
fn valid_spec() -> impl Strategy<Value = String> {
    (
        proptest::sample::select(EffectKind::ALL.to_vec()),
        proptest::collection::vec((any::<proptest::sample::Index>(), 0.0f64..=1.0), 0..4),
    )
        .prop_map(|(kind, picks)| {
            let ks = effects::of(kind).keys;
            let mut parts: Vec<String> = Vec::new();
            let mut used = std::collections::BTreeSet::new();
            for (i, f) in picks {
                if ks.is_empty() {
                    break;
                }
                let key = &ks[i.index(ks.len())];
                if !used.insert(key.name) {
                    continue;
                }
                let (lo, hi) = key.range();
                let v = match key.name {
                    // A table's variable is a name.
                    "var" => {
                        let names = ["theta", "omega", "current"];
                        names[((f * 3.0) as usize).min(2)].to_string()
                    }
                    // Whole numbers where the key counts something.
                    "harmonic" | "bins" => (lo + f * (hi - lo)).round().to_string(),
                    _ => (lo + f * (hi - lo)).to_string(),
                };
                parts.push(format!("{}={v}", key.name));
            }
            if parts.is_empty() {
                kind.name().to_string()
            } else {
                format!("{}:{}", kind.name(), parts.join(","))
            }
        })
}

/// A valid spec with a few characters replaced, inserted or removed.
fn mutated_spec() -> impl Strategy<Value = String> {
    (
        valid_spec(),
        proptest::collection::vec(
            (
                any::<proptest::sample::Index>(),
                0u8..3,
                proptest::sample::select(vec![
                    ':', ',', '=', '.', '-', 'e', '9', ' ', '\t', '\u{1b}', '\0', 'n', 'é', ';',
                ]),
            ),
            1..5,
        ),
    )
        .prop_map(|(spec, edits)| {
            let mut chars: Vec<char> = spec.chars().collect();
            for (at, how, c) in edits {
                let k = at.index(chars.len() + 1);
                match how {
                    0 if k < chars.len() => chars[k] = c,
                    1 if k < chars.len() => {
                        chars.remove(k);
                    }
                    _ => chars.insert(k, c),
                }
            }
            chars.into_iter().collect()
        })
}

proptest! {
    // Brief in CI: well under a second each.
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn valid_specs_parse_and_read_back(spec in valid_spec()) {
        // Keys in range, but a table's keys also depend on each other (lo below hi, values
        // only for the bins it has): those refusals are not this property's.
        if let Err(e) = EffectSpec::parse(&spec) {
            let e = format!("{e:#}");
            let between = e.contains("must be below") || e.contains("beyond the table's");
            prop_assume!(!between);
            return Err(TestCaseError::fail(format!("{spec} refused: {e}")));
        }
        parse_checked("--effect", &spec)?;
    }

    #[test]
    fn mutated_specs_parse_or_fail_on_one_line(spec in mutated_spec()) {
        parse_checked("--effect", &spec)?;
        parse_checked("--add", &spec)?;
    }

    #[test]
    fn any_text_parses_or_fails_on_one_line(spec in "[a-z_:=,.0-9e+\\- \t\u{1b}\u{7f}é]{0,60}") {
        parse_checked("--effect", &spec)?;
    }

    #[test]
    fn long_specs_fail_on_one_short_line(n in 100usize..5000, c in "[a-z0-9=,:]") {
        let spec = format!("offset:t0={}", c.repeat(n));
        parse_checked("--add", &spec)?;
        let spec = format!("{}:t0=1", c.repeat(n));
        parse_checked("--effect", &spec)?;
    }
}
