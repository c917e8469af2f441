//! The free parameters of a model structure: which numbers of a [`Model`] a fit may move,
//! with their units and bounds, read and written by name.
use crate::effect_spec::EffectSpec;
use crate::effects::{self, FitKey};
use crate::model::{Model, Parameter};

/// One number inside a model.
#[derive(Debug, Clone, PartialEq)]
pub enum Slot {
    /// Winding resistance R.
    R,
    /// Winding inductance L.
    L,
    /// Back-EMF constant K_b; K_t is tied to it (equal in SI units for a BLDC motor).
    Kb,
    /// Inertia J (or mass).
    J,
    /// Viscous friction of the linear model.
    Viscous,
    /// A LuGre field: alpha0, alpha1, alpha2, v0, sigma0, sigma1.
    Lugre(&'static str),
    /// Key of the i-th effect.
    Effect(usize, &'static str),
}

/// A free parameter: where it lives and its bounds.
#[derive(Debug, Clone)]
pub struct Free {
    pub slot: Slot,
    pub lo: f64,
    pub hi: f64,
}

impl Slot {
    /// Display name (`R`, `alpha0`, `cogging.amp`).
    pub fn name(&self, m: &Model) -> String {
        match self {
            Slot::R => "R".into(),
            Slot::L => "L".into(),
            Slot::Kb => "Kb".into(),
            Slot::J => "J".into(),
            Slot::Viscous => "b".into(),
            Slot::Lugre(f) => (*f).into(),
            Slot::Effect(i, k) => format!("{}.{k}", m.effects[*i].kind().name()),
        }
    }

    /// SI unit.
    pub fn unit(&self, m: &Model) -> String {
        let torque_plant = m.plant == crate::log::Plant::Torque;
        match self {
            Slot::R => "Ω".into(),
            Slot::L => "H".into(),
            Slot::Kb => "V·s/rad".into(),
            Slot::J if torque_plant => "u·s²/rad".into(),
            Slot::J => "kg·m²".into(),
            Slot::Viscous | Slot::Lugre("alpha2") | Slot::Lugre("sigma1") => "N·m·s/rad".into(),
            Slot::Lugre("v0") => "rad/s".into(),
            Slot::Lugre("sigma0") => "N·m/rad".into(),
            Slot::Lugre(_) => "N·m".into(),
            Slot::Effect(i, k) => effects::of(m.effects[*i].kind())
                .keys
                .iter()
                .find(|key| key.name == *k)
                .map(|key| key.unit.to_string())
                .unwrap_or_default(),
        }
    }

    pub fn get(&self, m: &Model) -> f64 {
        match self {
            Slot::R => m.motor.r,
            Slot::L => m.motor.l,
            Slot::Kb => m.motor.kb,
            Slot::J => m.motor.j,
            Slot::Viscous => m.viscous,
            Slot::Lugre(f) => {
                let l = m.lugre.unwrap_or_else(crate::model::LugreParams::paper);
                match *f {
                    "alpha0" => l.alpha0,
                    "alpha1" => l.alpha1,
                    "alpha2" => l.alpha2,
                    "v0" => l.v0,
                    "sigma0" => l.sigma0,
                    _ => l.sigma1,
                }
            }
            Slot::Effect(i, k) => EffectSpec::from_effect(&m.effects[*i]).get(k),
        }
    }

    pub fn set(&self, m: &mut Model, v: f64) {
        match self {
            Slot::R => m.motor.r = v,
            Slot::L => m.motor.l = v,
            Slot::Kb => {
                m.motor.kb = v;
                m.motor.kt = v;
            }
            Slot::J => m.motor.j = v,
            Slot::Viscous => m.viscous = v,
            Slot::Lugre(f) => {
                let l = m.lugre.get_or_insert_with(crate::model::LugreParams::paper);
                match *f {
                    "alpha0" => l.alpha0 = v,
                    "alpha1" => l.alpha1 = v,
                    "alpha2" => l.alpha2 = v,
                    "v0" => l.v0 = v,
                    "sigma0" => l.sigma0 = v,
                    _ => l.sigma1 = v,
                }
            }
            Slot::Effect(i, k) => {
                let mut s = EffectSpec::from_effect(&m.effects[*i]);
                s.values.insert(k.to_string(), v);
                m.effects[*i] = s.to_effect();
            }
        }
    }
}

/// The estimable keys of effect `e` with the bounds a fit keeps them in (its descriptor's
/// [`effects::Descriptor::fit_keys`]); structural keys (cogging `harmonic`) stay fixed.
pub fn effect_keys_of(e: &control::effects::Effect<f64>) -> Vec<FitKey> {
    (effects::of(e.kind()).fit_keys)(e)
}

/// The parameter table of a model for these free parameters, with standard errors.
pub fn parameter_rows(m: &Model, free: &[Free], std_err: &[Option<f64>]) -> Vec<Parameter> {
    free.iter()
        .enumerate()
        .map(|(k, f)| {
            let mut p = Parameter::new(&f.slot.name(m), f.slot.get(m), &f.slot.unit(m));
            p.std_err = std_err.get(k).copied().flatten();
            if let Some(se) = p.std_err {
                // Relative standard error above 50 %: the data does not pin it down.
                if !se.is_finite() || se > 0.5 * p.value.abs() {
                    p.identifiable = false;
                    p.note = if p.value.abs() > 1e-12 && se.is_finite() {
                        format!(
                            "relative standard error {:.0} %: the data barely constrains it",
                            100.0 * se / p.value.abs()
                        )
                    } else {
                        "the data does not constrain it (flat cost)".to_string()
                    };
                }
            }
            let v = p.value;
            if v <= f.lo || v >= f.hi {
                let b = if v <= f.lo { f.lo } else { f.hi };
                let sep = if p.note.is_empty() { "" } else { "; " };
                p.note = format!("{}{sep}at its bound {b}", p.note);
            }
            p
        })
        .collect()
}

/// Parameters the user knows: `fit --fix KEY=VALUE` holds KEY at VALUE, `fit --bound
/// KEY=LO..HI` keeps it inside [LO, HI]. Keys are the names of the parameter table (`R`, `L`,
/// `Kb` (or `Kt`), `J`, `b`, `alpha0`..`sigma1`, `coulomb.fc`, ...), values in the units it
/// prints.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Constraints {
    pub fixed: std::collections::BTreeMap<String, f64>,
    pub bounds: std::collections::BTreeMap<String, (f64, f64)>,
}

impl Constraints {
    /// No parameter known.
    pub const NONE: Constraints = Constraints {
        fixed: std::collections::BTreeMap::new(),
        bounds: std::collections::BTreeMap::new(),
    };

    /// True when nothing is fixed or bounded.
    pub fn is_empty(&self) -> bool {
        self.fixed.is_empty() && self.bounds.is_empty()
    }
}

/// The table's name for a user's key: `Kt`, `K_t` and `K_b` name the back-EMF constant `Kb`
/// (K_t is tied to it); other keys as given.
pub fn canonical_key(key: &str) -> String {
    // MODEL.toml's names (`motor.r`, `r`, `viscous`, `lugre.alpha0`) name the same parameters.
    let key = key.strip_prefix("lugre.").unwrap_or(key);
    match key.strip_prefix("motor.").unwrap_or(key) {
        "Kt" | "K_t" | "K_b" | "kt" | "kb" => "Kb".into(),
        "r" => "R".into(),
        "l" => "L".into(),
        "j" => "J".into(),
        "viscous" => "b".into(),
        k => k.to_string(),
    }
}

/// Which kind of quantity a unit of the parameter table is, for [`widen_to_data`].
fn dimension_factors(unit: &str, v: f64, d: f64) -> (f64, f64) {
    let torque = |u: &str| u == "N·m" || u == "u";
    if torque(unit) {
        (d, d)
    } else if unit == "N·m·s/rad" || unit == "u·s/rad" {
        (d / v, d / v)
    } else if unit == "kg·m²" || unit == "u·s²/rad" {
        (v / d, d / v)
    } else if unit == "rad/s" {
        (v, 1.0)
    } else {
        (1.0, 1.0)
    }
}

/// Bounds `(lo, hi)` of a parameter in `unit` widened to a log's scales: `v` its
/// [`crate::scales::velocity_scale`] (≤ 1), `d` its [`crate::scales::drive_scale`] (≥ 1).
/// The bounds were chosen for the paper's motor (rad/s, drives up to 1 N·m); a torque bound grows
/// with the drive, a velocity's lower bound (a Stribeck velocity) shrinks with the speeds, a
/// friction per velocity or an inertia grows as torque over velocity. Every factor only
/// widens, so on the paper's motor (v = d = 1) nothing changes.
pub fn widen_to_data(lo: f64, hi: f64, unit: &str, v: f64, d: f64) -> (f64, f64) {
    let (a, b) = dimension_factors(unit, v, d);
    let scale = |x: f64, f: f64| {
        let y = x * f;
        if y.is_finite() {
            y
        } else {
            x
        }
    };
    let (l, h) = (scale(lo, if lo > 0.0 { a } else { b }), scale(hi, b));
    // A negative lower bound widens with the upper factor (a signed torque: ±10 → ±10·d).
    (l.min(lo), h.max(hi))
}

/// Free parameters with the user's [`Constraints`] applied, for a fit of `m`: bounds widened
/// to the data (`v`, `d`: see [`widen_to_data`]), then each `--bound` replaces its key's
/// bounds and each `--fix` sets its key on `m` and drops it from the list. Returns the free
/// parameters left and the table rows of the fixed ones.
pub fn constrain(
    m: &mut Model,
    free: &[Free],
    user: &Constraints,
    v: f64,
    d: f64,
) -> (Vec<Free>, Vec<Parameter>) {
    let mut left = Vec::new();
    let mut rows = Vec::new();
    for f in free {
        let name = f.slot.name(m);
        let unit = f.slot.unit(m);
        if let Some(&value) = user.fixed.get(&name) {
            f.slot.set(m, value);
            let mut p = Parameter::new(&name, value, &unit);
            p.note = "fixed by --fix".into();
            rows.push(p);
            continue;
        }
        let (mut lo, mut hi) = widen_to_data(f.lo, f.hi, &unit, v, d);
        if let Some(&(l, h)) = user.bounds.get(&name) {
            (lo, hi) = (l, h);
            let x = f.slot.get(m);
            if !(lo..=hi).contains(&x) {
                f.slot.set(m, x.clamp(lo, hi));
            }
        }
        left.push(Free {
            slot: f.slot.clone(),
            lo,
            hi,
        });
    }
    (left, rows)
}

/// The names `--fix` and `--bound` accept for a fit of `kind` on `plant` with effects `adds`:
/// the names its parameter table gives the parameters it estimates.
pub fn constrainable_keys(
    kind: crate::model::ModelKind,
    plant: crate::log::Plant,
    adds: &[EffectSpec],
) -> Vec<String> {
    use crate::model::ModelKind;
    let mut out: Vec<String> = match plant {
        crate::log::Plant::Voltage => ["R", "L", "Kb", "J"].map(String::from).to_vec(),
        crate::log::Plant::Torque => vec!["J".into()],
    };
    match kind {
        ModelKind::Linear => out.push("b".into()),
        ModelKind::Lugre => {
            out.extend(["alpha0", "alpha1", "alpha2", "v0", "sigma0", "sigma1"].map(String::from))
        }
        ModelKind::Sindyc => return vec![],
    }
    for spec in adds {
        for (key, _, _) in effect_keys_of(&spec.to_effect()) {
            out.push(format!("{}.{key}", spec.kind.name()));
        }
    }
    out
}

/// Checks the user's constraints name parameters of this fit and give a non-empty range:
/// one error naming the key and the accepted names.
pub fn check_constraints(
    user: &Constraints,
    kind: crate::model::ModelKind,
    plant: crate::log::Plant,
    adds: &[EffectSpec],
) -> anyhow::Result<()> {
    if user.is_empty() {
        return Ok(());
    }
    let known = constrainable_keys(kind, plant, adds);
    if known.is_empty() {
        anyhow::bail!(
            "--fix/--bound: a {} model's coefficients are chosen by sparse regression, not \
             named parameters; fix or bound parameters of --model linear or lugre",
            kind.name()
        );
    }
    let keys = user
        .fixed
        .keys()
        .map(|k| ("--fix", k))
        .chain(user.bounds.keys().map(|k| ("--bound", k)));
    for (flag, key) in keys {
        if !known.contains(key) {
            anyhow::bail!(
                "{flag} {key}: not a parameter of this fit ({} model, {} plant); its \
                 parameters: {}",
                kind.name(),
                match plant {
                    crate::log::Plant::Voltage => "voltage",
                    crate::log::Plant::Torque => "torque",
                },
                known.join(", ")
            );
        }
    }
    for (key, &(lo, hi)) in &user.bounds {
        if lo >= hi || lo.is_nan() || hi.is_nan() {
            anyhow::bail!("--bound {key}={lo}..{hi}: the range is empty (LO must be below HI)");
        }
        if user.fixed.contains_key(key) {
            anyhow::bail!("--fix and --bound both give {key}: give one");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_widen_with_the_data_and_only_widen() {
        // The paper's motor: unchanged.
        assert_eq!(widen_to_data(-10.0, 10.0, "N·m", 1.0, 1.0), (-10.0, 10.0));
        assert_eq!(widen_to_data(0.05, 500.0, "rad/s", 1.0, 1.0), (0.05, 500.0));
        // A drive a hundred times larger, speeds a hundred times smaller (a linear axis).
        assert_eq!(
            widen_to_data(-10.0, 10.0, "u", 0.01, 100.0),
            (-1000.0, 1000.0)
        );
        // The tolerances below are a few float ε of each bound (1e-15 of 5e-4, 1e-25 of
        // 1e-13, ...): the products are exact up to rounding.
        let (lo, hi) = widen_to_data(0.05, 500.0, "rad/s", 0.01, 100.0);
        assert!((lo - 5e-4).abs() < 1e-15 && hi == 500.0);
        let (lo, hi) = widen_to_data(0.0, 100.0, "u·s/rad", 0.01, 100.0);
        assert!(lo == 0.0 && (hi - 1e6).abs() < 1e-6);
        let (lo, hi) = widen_to_data(1e-9, 1e6, "u·s²/rad", 0.01, 100.0);
        assert!((lo - 1e-13).abs() < 1e-25 && (hi - 1e10).abs() < 1.0);
        // Electrical constants keep their SI bounds.
        assert_eq!(widen_to_data(1e-4, 1e3, "Ω", 0.01, 100.0), (1e-4, 1e3));
    }

    /// MODEL.toml's names of the motor and LuGre numbers name the table's parameters.
    #[test]
    fn model_file_names_are_parameter_names() {
        for (given, key) in [
            ("r", "R"),
            ("motor.l", "L"),
            ("motor.j", "J"),
            ("kt", "Kb"),
            ("viscous", "b"),
            ("lugre.alpha0", "alpha0"),
            ("coulomb.fc", "coulomb.fc"),
        ] {
            assert_eq!(canonical_key(given), key);
        }
    }

    #[test]
    fn constraints_name_only_parameters_of_the_fit() {
        use crate::log::Plant;
        use crate::model::ModelKind;
        let adds = [EffectSpec::parse("coulomb").unwrap()];
        let keys = constrainable_keys(ModelKind::Linear, Plant::Torque, &adds);
        assert_eq!(keys, ["J", "b", "coulomb.fc"]);
        let mut c = Constraints::default();
        c.fixed.insert("R".into(), 1.0);
        let e = check_constraints(&c, ModelKind::Linear, Plant::Torque, &adds)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--fix R") && e.contains("J, b, coulomb.fc"),
            "{e}"
        );
        let e = check_constraints(&c, ModelKind::Sindyc, Plant::Voltage, &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("sindyc"), "{e}");
        assert_eq!(canonical_key("Kt"), "Kb");
    }
}
