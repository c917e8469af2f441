//! The model file side of SINDYc: the `[sindy]` table of MODEL.toml (settings, then each
//! equation as `term name = coefficient`), read back with errors that name the field, and the
//! human-readable equations and Pareto table `fit` prints.
use super::{HankelSettings, ParetoRow};
use crate::ident::library::EQUATION_NAMES;
use crate::log::Plant;
use anyhow::{anyhow, bail, Result};
use control::sindy::{SindyModel, SparseEq, Term, MAX_TERMS};
use std::fmt::Write as _;

/// The equations with named terms, one line per equation (eq. 43 included).
pub fn equations_text(m: &SindyModel<f64>, plant: Plant) -> String {
    let mut s = String::from("dx/dt = xdot\n");
    let eqs: Vec<(&str, &SparseEq<f64>)> = if plant == Plant::Voltage {
        vec![
            (EQUATION_NAMES[0], &m.accel),
            (EQUATION_NAMES[1], &m.zdot),
            (EQUATION_NAMES[2], &m.idot),
        ]
    } else {
        vec![(EQUATION_NAMES[0], &m.accel), (EQUATION_NAMES[1], &m.zdot)]
    };
    for (name, eq) in eqs {
        let _ = write!(s, "{name} =");
        if eq.terms.is_empty() {
            s.push_str(" 0");
        }
        for (k, (t, c)) in eq.terms.iter().enumerate() {
            let sign = if *c < 0.0 {
                "-"
            } else if k == 0 {
                ""
            } else {
                "+"
            };
            let _ = write!(s, " {sign} {:.6e}*{}", c.abs(), t);
        }
        s.push('\n');
    }
    let _ = writeln!(s, "(a = {}, vs = {}, |z| <= {:.4})", m.a, m.vs, m.z_max);
    s
}

/// The Pareto table: terms vs validation fit, one row per candidate examined.
pub fn pareto_text(rows: &[ParetoRow]) -> String {
    let mut s = String::from("  terms  validation fit xdot %  kept  step\n");
    for r in rows {
        let fit = match r.fit {
            Some(f) => format!("{f:8.2}"),
            None if r.step.contains("not refined") => "-".to_string(),
            None => "diverged".to_string(),
        };
        let _ = writeln!(
            s,
            "  {:>5}  {:>22}  {:>4}  {}",
            r.terms,
            fit,
            if r.accepted { "yes" } else { "" },
            r.step
        );
    }
    s
}

/// The `[sindy]` table of MODEL.toml: settings, then each equation as `term name = coef`.
pub fn to_table(m: &SindyModel<f64>, h: &HankelSettings) -> toml::Table {
    use toml::Value;
    let mut t = toml::Table::new();
    t.insert("a".into(), Value::Float(m.a));
    t.insert("vs".into(), Value::Float(m.vs));
    t.insert("j".into(), Value::Float(m.j));
    t.insert("z_max".into(), Value::Float(m.z_max));
    t.insert("hankel_delays".into(), Value::Integer(h.delays as i64));
    t.insert(
        "hankel_components".into(),
        Value::Array(vec![
            Value::Integer(h.components.0 as i64),
            Value::Integer(h.components.1 as i64),
        ]),
    );
    t.insert("z_scale".into(), Value::Float(h.z_scale));
    for (name, eq) in [("accel", &m.accel), ("zdot", &m.zdot), ("idot", &m.idot)] {
        let mut e = toml::Table::new();
        for (term, c) in &eq.terms {
            e.insert(term.name().as_str().to_string(), Value::Float(*c));
        }
        t.insert(name.into(), Value::Table(e));
    }
    t
}

/// Read the `[sindy]` table back (errors name the field).
pub fn from_table(t: &toml::Table) -> Result<(SindyModel<f64>, HankelSettings)> {
    let num = |k: &str| -> Result<f64> {
        match t.get(k) {
            Some(toml::Value::Float(v)) => Ok(*v),
            Some(toml::Value::Integer(v)) => Ok(*v as f64),
            Some(_) => bail!("field 'sindy.{k}': not a number"),
            None => bail!("field 'sindy.{k}': missing"),
        }
    };
    let mut m = SindyModel::empty(num("a")?, num("vs")?, num("j")?);
    m.z_max = num("z_max")?;
    for name in ["accel", "zdot", "idot"] {
        let mut eq = SparseEq::new();
        if let Some(v) = t.get(name) {
            let tab = v.as_table().ok_or_else(|| {
                anyhow!("field 'sindy.{name}': not a table of term = coefficient")
            })?;
            for (k, v) in tab {
                let term = Term::parse(k).ok_or_else(|| {
                    anyhow!(
                        "field 'sindy.{name}': unknown term '{}'",
                        crate::log::echo(k)
                    )
                })?;
                let c = v
                    .as_float()
                    .or_else(|| v.as_integer().map(|i| i as f64))
                    .filter(|c| c.is_finite())
                    .ok_or_else(|| {
                        anyhow!(
                            "field 'sindy.{name}.\"{}\"': not a number",
                            crate::log::echo(k)
                        )
                    })?;
                eq.push(term, c)
                    .map_err(|_| anyhow!("field 'sindy.{name}': more than {MAX_TERMS} terms"))?;
            }
        }
        match name {
            "accel" => m.accel = eq,
            "zdot" => m.zdot = eq,
            _ => m.idot = eq,
        }
    }
    let comps = t
        .get("hankel_components")
        .and_then(|v| v.as_array())
        .and_then(|a| Some((a.first()?.as_integer()?, a.get(1)?.as_integer()?)))
        .unwrap_or((0, 0));
    let h = HankelSettings {
        // From the file: bounded, it sizes a Hankel matrix.
        delays: num("hankel_delays").unwrap_or(0.0).clamp(0.0, 1000.0) as usize,
        components: (
            comps.0.clamp(0, 1000) as usize,
            comps.1.clamp(0, 1000) as usize,
        ),
        z_scale: num("z_scale").unwrap_or(1.0),
    };
    Ok((m, h))
}
#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> (SindyModel<f64>, HankelSettings) {
        let mut m = SindyModel::empty(5.0, 1.0, 2e-4);
        m.z_max = 3.5;
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -3.8),
            (Term::I, 190.0),
            (Term::TanhXdot, -240.0),
        ])
        .unwrap();
        m.zdot = SparseEq::from_slice(&[(Term::Z, -40.0), (Term::Xdot, 0.5)]).unwrap();
        m.idot = SparseEq::from_slice(&[(Term::I, -700.0), (Term::U, 3300.0)]).unwrap();
        let h = HankelSettings {
            delays: 60,
            components: (31, 60),
            z_scale: 0.25,
        };
        (m, h)
    }

    #[test]
    fn the_table_reads_back_the_same_model() {
        let (m, h) = model();
        let (back, hb) = from_table(&to_table(&m, &h)).unwrap();
        assert_eq!(hb, h);
        assert_eq!(
            (back.a, back.vs, back.j, back.z_max),
            (m.a, m.vs, m.j, m.z_max)
        );
        // TOML tables are sorted by name: compare term by term, a sum has no order.
        for (a, b) in [
            (&back.accel, &m.accel),
            (&back.zdot, &m.zdot),
            (&back.idot, &m.idot),
        ] {
            assert_eq!(a.terms.len(), b.terms.len());
            for (t, c) in &b.terms {
                assert_eq!(a.coef(*t), *c, "{t}");
            }
        }
    }

    #[test]
    fn a_bad_table_is_an_error_naming_the_field() {
        let (m, h) = model();
        let mut t = to_table(&m, &h);
        t.remove("vs");
        let e = from_table(&t).unwrap_err().to_string();
        assert!(e.contains("sindy.vs") && e.contains("missing"), "{e}");
        let mut t = to_table(&m, &h);
        let accel = t.get_mut("accel").unwrap().as_table_mut().unwrap();
        accel.insert("no_such_term".into(), toml::Value::Float(1.0));
        let e = from_table(&t).unwrap_err().to_string();
        assert!(
            e.contains("sindy.accel") && e.contains("no_such_term"),
            "{e}"
        );
        let mut t = to_table(&m, &h);
        t.insert("hankel_delays".into(), toml::Value::Integer(1 << 40));
        // A size read from the file is bounded before it sizes anything.
        assert_eq!(from_table(&t).unwrap().1.delays, 1000);
    }

    #[test]
    fn the_texts_name_every_term_and_every_step() {
        let (m, _) = model();
        let eq = equations_text(&m, Plant::Voltage);
        assert_eq!(eq.lines().count(), 5, "{eq}");
        assert!(
            eq.contains("tanh(a*xdot)") && eq.contains("di/dt ="),
            "{eq}"
        );
        assert!(!equations_text(&m, Plant::Torque).contains("di/dt"));
        let rows = [
            ParetoRow {
                terms: 9,
                fit: None,
                step: "STLSQ".into(),
                accepted: false,
            },
            ParetoRow {
                terms: 7,
                fit: Some(96.5),
                step: "removed x".into(),
                accepted: true,
            },
        ];
        let p = pareto_text(&rows);
        assert!(
            p.contains("diverged") && p.contains("96.50") && p.contains("yes"),
            "{p}"
        );
    }
}
