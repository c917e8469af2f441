//! Effect specs as the user types them: `NAME` or `NAME:key=value,...`
//! (`--effect` of `simulate`, `--add` of `fit`, the `spec` that `diagnose` prints).
//!
//! The equations behind each name are in `control::effects`; the keys, their units and the
//! defaults used when a key is left out are in each effect's descriptor ([`crate::effects`]).
use crate::effects::{self, TABLE_VAR_UNIT};
use anyhow::{anyhow, bail, Result};
use control::effects::{Effect, EffectKind, TableVar};
use std::collections::BTreeMap;
use std::fmt;

/// A parsed spec: the effect and the values the user gave (others take defaults).
#[derive(Debug, Clone, PartialEq)]
pub struct EffectSpec {
    pub kind: EffectKind,
    pub values: BTreeMap<String, f64>,
}

impl EffectSpec {
    /// A spec with no values (a bare NAME).
    pub fn bare(kind: EffectKind) -> EffectSpec {
        EffectSpec {
            kind,
            values: BTreeMap::new(),
        }
    }

    /// Parse `NAME` or `NAME:key=value,...`.
    pub fn parse(spec: &str) -> Result<EffectSpec> {
        let spec = spec.trim();
        let (name, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let kind = EffectKind::from_name(name.trim()).ok_or_else(|| {
            anyhow!(
                "unknown effect '{}'; known effects: {}",
                crate::log::echo(name.trim()),
                EffectKind::ALL
                    .iter()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?;
        let known = effects::of(kind).keys;
        let mut values = BTreeMap::new();
        for part in rest.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = part.split_once('=').ok_or_else(|| {
                anyhow!(
                    "effect '{}': '{}' is not key=value",
                    kind.name(),
                    crate::log::echo(part)
                )
            })?;
            let k = k.trim();
            if values.contains_key(k) {
                bail!(
                    "effect '{}': key '{}' is given twice",
                    kind.name(),
                    crate::log::echo(k)
                );
            }
            if !known.iter().any(|key| key.name == k) {
                bail!(
                    "effect '{}': unknown key '{}'; its keys are: {}",
                    kind.name(),
                    crate::log::echo(k),
                    known
                        .iter()
                        .map(|key| key.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
            let table_var = (kind == EffectKind::Table && k == "var")
                .then(|| TableVar::from_name(v.trim()))
                .flatten();
            if kind == EffectKind::Table && k == "var" && table_var.is_none() {
                bail!(
                    "effect 'table': key 'var': '{}' is not one of theta, omega, current",
                    crate::log::echo(v.trim())
                );
            }
            let v: f64 = match table_var {
                Some(tv) => TableVar::ALL.iter().position(|x| *x == tv).unwrap_or(0) as f64,
                None => v.trim().parse().map_err(|_| {
                    anyhow!(
                        "effect '{}': key '{k}': '{}' is not a number",
                        kind.name(),
                        crate::log::echo(v.trim())
                    )
                })?,
            };
            values.insert(k.to_string(), v);
        }
        let spec = EffectSpec { kind, values };
        spec.check_values()?;
        Ok(spec)
    }

    /// [`EffectSpec::parse`] of a command-line flag's value: the error names the flag and
    /// echoes the spec safely (control characters removed, cut short), e.g.
    /// `--effect 'offset:t0=nan': effect 'offset': key 't0' [N·m]: NaN is not a finite number`.
    pub fn parse_flag(flag: &str, spec: &str) -> Result<EffectSpec> {
        Self::parse(spec).map_err(|e| anyhow!("{flag} '{}': {e:#}", crate::log::echo(spec)))
    }

    /// Every value given is finite and within its key's [`Key::range`] (cogging's harmonic a
    /// whole number): the one check of effect parameters, used by [`EffectSpec::parse`], by
    /// MODEL.toml's `[[effects]]` and by the emulator. The message names the effect and key.
    pub fn check_values(&self) -> Result<()> {
        let name = self.kind.name();
        for key in effects::of(self.kind).keys {
            let Some(&v) = self.values.get(key.name) else {
                continue;
            };
            let (lo, hi) = key.range();
            crate::validate::in_range(v, lo, hi)
                .map_err(|e| anyhow!("effect '{name}': key '{}' [{}]: {e}", key.name, key.unit))?;
        }
        (effects::of(self.kind).check)(self)
    }

    /// The variable of a `table` spec (θ for other effects).
    pub fn table_var(&self) -> TableVar {
        TableVar::ALL[(self.get("var").clamp(0.0, 2.0)) as usize]
    }

    /// The value of a key: the user's, or the default.
    pub fn get(&self, key: &str) -> f64 {
        self.values.get(key).copied().unwrap_or_else(|| {
            effects::of(self.kind)
                .keys
                .iter()
                .find(|k| k.name == key)
                .map(|k| k.default)
                .unwrap_or(0.0)
        })
    }

    /// The effect with these values (defaults where not given).
    pub fn to_effect(&self) -> Effect<f64> {
        (effects::of(self.kind).to_effect)(self)
    }

    /// The spec of an effect with all its values.
    pub fn from_effect(e: &Effect<f64>) -> EffectSpec {
        let values = (effects::of(e.kind()).values)(e)
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect();
        EffectSpec {
            kind: e.kind(),
            values,
        }
    }

    /// `--help` text listing every effect and its keys.
    pub fn help_text() -> String {
        let mut s = String::from("Effects (NAME or NAME:key=value,...):\n");
        for d in effects::ALL {
            let kind = d.kind;
            if let Some(help) = d.help {
                s.push_str(&format!("  {:<15} {help}\n", kind.name()));
                continue;
            }
            let ks: Vec<String> = d
                .keys
                .iter()
                .map(|k| format!("{}={} [{}] {}", k.name, k.default, k.unit, k.meaning))
                .collect();
            s.push_str(&format!("  {:<15} {}\n", kind.name(), ks.join("; ")));
        }
        s
    }
}

impl fmt::Display for EffectSpec {
    /// `NAME:key=value,...` in the keys' documented order, values with 4 significant digits.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.kind.name())?;
        let mut first = true;
        for key in effects::of(self.kind).keys {
            if let Some(v) = self.values.get(key.name) {
                let sep = if first { ":" } else { "," };
                if key.unit == TABLE_VAR_UNIT {
                    let var = TableVar::ALL[v.clamp(0.0, 2.0) as usize];
                    write!(f, "{sep}{}={}", key.name, var.name())?;
                } else {
                    write!(f, "{sep}{}={}", key.name, short(*v))?;
                }
                first = false;
            }
        }
        Ok(())
    }
}

/// A number with 4 significant digits, without trailing zeros.
fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    if v.fract() == 0.0 && v.abs() < 1e6 {
        return format!("{v}");
    }
    let s = format!("{:.3e}", v);
    let parsed: f64 = s.parse().unwrap_or(v);
    format!("{parsed}")
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    #[test]
    fn parse_and_print_round_trip() {
        let s = EffectSpec::parse("cogging:harmonic=7,amp=0.0312345").unwrap();
        assert_eq!(s.to_string(), "cogging:harmonic=7,amp=0.03123");
        assert_eq!(
            EffectSpec::parse(&s.to_string()).unwrap().get("harmonic"),
            7.0
        );
        assert_eq!(EffectSpec::parse("offset").unwrap().to_string(), "offset");
        let e = EffectSpec::parse("position_load:amp=0.1")
            .unwrap()
            .to_effect();
        assert_eq!(
            e,
            Effect::PositionLoad {
                amp: 0.1,
                phase: 0.0
            }
        );
        assert_eq!(EffectSpec::from_effect(&e).to_effect(), e);
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        assert!(EffectSpec::parse("gravity")
            .unwrap_err()
            .to_string()
            .contains("known effects"));
        assert!(EffectSpec::parse("cogging:h=3")
            .unwrap_err()
            .to_string()
            .contains("unknown key 'h'"));
        assert!(EffectSpec::parse("cogging:harmonic=1").is_err());
        assert!(EffectSpec::parse("offset:t0=abc")
            .unwrap_err()
            .to_string()
            .contains("not a number"));
        assert!(EffectSpec::parse("offset:t0=NaN").is_err());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(500))]

        /// Any string: an error or a spec, never a panic; a spec that parses has values in
        /// range and survives printing and parsing again.
        #[test]
        fn random_specs_never_panic(spec in "\\PC{0,60}") {
            if let Ok(s) = EffectSpec::parse(&spec) {
                proptest::prop_assert!(s.check_values().is_ok());
                let _ = s.to_effect();
            }
        }

        #[test]
        fn spec_shaped_strings_never_panic(
            spec in "(coulomb|offset|cogging|thermal|stribeck|table|x)(:((fc|t0|harmonic|amp|tau|vs|k)=[-+0-9.eEnaif]{0,10},?){0,4})?"
        ) {
            if let Ok(s) = EffectSpec::parse(&spec) {
                for (k, v) in &s.values {
                    proptest::prop_assert!(v.is_finite(), "{} = {}", k, v);
                }
                let again = EffectSpec::parse(&s.to_string());
                proptest::prop_assert!(again.is_ok(), "{} -> {}", spec, s);
                let _ = s.to_effect();
            }
        }
    }

    #[test]
    fn table_specs_parse_print_and_refuse_what_does_not_fit() {
        let s = EffectSpec::parse("table:var=omega,bins=3,lo=-10,hi=10,b0=0.1,b2=-0.2").unwrap();
        assert_eq!(
            s.to_string(),
            "table:var=omega,bins=3,lo=-10,hi=10,b0=0.1,b2=-0.2"
        );
        let e = s.to_effect();
        let x = |omega| control::effects::EffectInputs {
            theta: 0.0,
            omega,
            current: 0.0,
            kt: 0.07,
        };
        assert!((e.torque(&x(-10.0)) - 0.1).abs() < 1e-12);
        assert!((e.torque(&x(5.0)) + 0.1).abs() < 1e-12);
        assert_eq!(EffectSpec::from_effect(&e).to_effect(), e);
        let t = EffectSpec::parse("table:var=theta,bins=12").unwrap();
        assert_eq!(t.to_string(), "table:var=theta,bins=12");
        assert_eq!(t.table_var(), TableVar::Theta);
        // Over a stroke (a linear axis): the range is kept, printed and round-trips.
        let st = EffectSpec::parse("table:var=theta,bins=4,lo=0,hi=240,b3=0.5").unwrap();
        assert_eq!(st.to_string(), "table:var=theta,bins=4,lo=0,hi=240,b3=0.5");
        let e = st.to_effect();
        assert_eq!(EffectSpec::from_effect(&e).to_effect(), e);
        let at = |theta| control::effects::EffectInputs {
            theta,
            omega: 0.0,
            current: 0.0,
            kt: 0.07,
        };
        assert!((e.torque(&at(240.0)) - 0.5).abs() < 1e-12);
        assert!((e.torque(&at(200.0)) - 0.25).abs() < 1e-12);
        for (bad, why) in [
            ("table:var=theta,lo=5,hi=1", "below hi"),
            ("table:var=theta,lo=0,hi=1e6", "outside"),
            ("table:var=speed", "not one of theta"),
            ("table:bins=33", "bins"),
            ("coulomb:fc=1,fc=2", "given twice"),
            ("table:bins=1", "bins"),
            ("table:bins=2.5", "whole"),
            ("table:bins=4,b4=1", "beyond the table's 4 bins"),
            ("table:var=current,lo=2,hi=1", "below hi"),
            ("table:b32=1", "unknown key"),
            ("backlash:gap=-0.1", "-0.1 is outside 0 .. 1000"),
            ("table:bins=4,b20=1", "unknown key 'b20'"),
            ("compliance:k=-1", "key 'k' [N·m/rad]: -1 is outside 0 .."),
            (
                "compliance:c=-0.001",
                "key 'c' [N·m·s/rad]: -0.001 is outside 0 ..",
            ),
        ] {
            let e = EffectSpec::parse(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn every_effect_has_keys_and_defaults() {
        for kind in EffectKind::ALL {
            let e = EffectSpec::bare(kind).to_effect();
            assert_eq!(e.kind(), kind);
            assert!(!effects::of(kind).keys.is_empty());
        }
    }
}
