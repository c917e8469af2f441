//! MODEL.toml: an identified motor model, human-readable.
//!
//! A model is a motor (paper eqs. 1–2: `J·dω/dt = K_t·I − F_f − τ_effects`,
//! `L·dI/dt = −R·I − K_b·ω + V − v_loss`) with a friction law `F_f` chosen by the model kind:
//!
//! * `linear`: viscous friction only, `F_f = b·ω` (the paper's linear model);
//! * `lugre`: the LuGre law (paper eqs. 12–14), parameters in [`LugreParams`];
//! * `sindyc`: sparse equations found by SINDYc (`ident::sindyc`), stored as a
//!   TOML table in `sindy`.
//!
//! Every model may carry extra physical effects (`[[effects]]`, one table per effect with its
//! `name` and its keys, the same keys as an effect spec) and lists every identified number in
//! `[[parameters]]` with its unit, standard error and whether the data could identify it.
//!
//! `--plant torque`: there is no electrical equation; `u` is the torque or force command,
//! `motor.kt` is the input gain (torque or force per unit of `u`, fixed to 1), `motor.j` is the
//! inertia (rotary, kg·m²) or the mass (linear axis, kg) in units of `u` per rad/s² (m/s²),
//! and `motor.r`, `motor.l`, `motor.kb` are unused (0).
use crate::effect_spec::EffectSpec;
use crate::log::{echo, Plant};
use anyhow::{anyhow, Context, Result};
use control::effects::{Effect, EffectKind};
use control::motor::MotorParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The keys of MODEL.toml's `[lugre]` table: the LuGre parameters of
/// [`control::lugre::LugreParams`] by name.
pub const LUGRE_KEYS: [&str; 6] = ["alpha0", "alpha1", "alpha2", "v0", "sigma0", "sigma1"];

/// Which friction law the model uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum, Default)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// Viscous friction only (paper eqs. 1–2).
    #[default]
    Linear,
    /// LuGre friction (paper eqs. 12–14).
    Lugre,
    /// Sparse nonlinear equations identified by SINDYc (paper eqs. 43–46).
    Sindyc,
}

impl ModelKind {
    /// The name used on the command line and in MODEL.toml.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Linear => "linear",
            ModelKind::Lugre => "lugre",
            ModelKind::Sindyc => "sindyc",
        }
    }
}

/// LuGre friction (paper eqs. 12–14), SI units, with the field names of the paper's Table 2
/// (`control::lugre::LugreParams`, the same struct the firmware's observer runs):
/// `F_f = σ0·z + σ1·dz/dt + α2·ω`, `dz/dt = ω − σ0·|ω|·z / s(ω)`,
/// `s(ω) = α0 + α1·exp(−(ω/v0)²)`.
pub type LugreParams = control::lugre::LugreParams<f64>;

/// `dz/dt` of the LuGre bristle state at velocity ω and deflection z.
pub fn lugre_z_rate(l: &LugreParams, omega: f64, z: f64) -> f64 {
    omega - l.sigma0 * omega.abs() * z / l.s(omega).max(1e-12)
}

/// LuGre friction torque `σ0·z + σ1·dz/dt + α2·ω` [N·m] at state (ω, z).
pub fn lugre_friction(l: &LugreParams, omega: f64, z: f64) -> f64 {
    l.friction_at(omega, z, lugre_z_rate(l, omega, z))
}

/// One identified number.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Parameter {
    /// Name, as in the equations (`R`, `alpha0`, `cogging.amp`, ...).
    pub name: String,
    pub value: f64,
    /// SI unit.
    pub unit: String,
    /// Standard error from the Jacobian at the optimum, σ²·(JᵀJ)⁻¹; absent when not estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_err: Option<f64>,
    /// False when the data cannot pin this number down (then `note` says why).
    #[serde(default = "yes")]
    pub identifiable: bool,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
}

fn yes() -> bool {
    true
}

impl Parameter {
    /// A parameter with a value and a unit, identifiable, no std error yet.
    pub fn new(name: &str, value: f64, unit: &str) -> Parameter {
        Parameter {
            name: name.to_string(),
            value,
            unit: unit.to_string(),
            std_err: None,
            identifiable: true,
            note: String::new(),
        }
    }
}

/// Where the model's data came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// The logs it was fitted on.
    pub files: Vec<String>,
    /// Logs used for validation only (if any).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub validate: Vec<String>,
    /// Total number of samples fitted.
    pub samples: usize,
    /// Sample period [s].
    pub sample_period: f64,
    /// Free text: how the parameters were found.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub method: String,
    /// Units the logs declared for their standard columns (`# unit.COLUMN=UNIT` or
    /// `--units`), by column (`t = "ms"`); the data were converted to SI on read, so the
    /// model's numbers are SI all the same. Columns not listed were SI. When the logs
    /// disagree, the value names each file's unit. Absent in models written before units
    /// existed.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub units: BTreeMap<String, String>,
    /// Parameters held at a known value (`fit --fix KEY=VALUE`), by the parameter table's name,
    /// in its units: the fit did not estimate them.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub fixed: BTreeMap<String, f64>,
    /// Parameters kept inside a known range (`fit --bound KEY=LO..HI`): `[LO, HI]`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub bounds: BTreeMap<String, [f64; 2]>,
    /// Factor the standard errors of `parameters` were multiplied by for the autocorrelation
    /// of the fit's residual (`ident::sim_error::autocorrelation_factor`): the white-noise
    /// errors σ²·(JᵀJ)⁻¹ are this many times too small.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_err_factor: Option<f64>,
}

impl Provenance {
    /// The `fixed` and `bounds` of this model as fit constraints.
    pub fn constraints(&self) -> crate::ident::free_params::Constraints {
        crate::ident::free_params::Constraints {
            fixed: self.fixed.clone(),
            bounds: self
                .bounds
                .iter()
                .map(|(k, v)| (k.clone(), (v[0], v[1])))
                .collect(),
        }
    }
}

/// The measurement chain the data went through (needed for `fit_sensor`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sensor {
    /// Angle quantum of the Hall sensors [rad] (0 = not quantised).
    pub hall_resolution_rad: f64,
    /// Moving-average window of the velocity estimator [samples]. Default 10: the paper's
    /// filter (Section 4: window of 10 samples at 12 ms).
    pub velocity_window: usize,
    /// Pole pairs of the motor, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pole_pairs: Option<u32>,
}

impl Default for Sensor {
    fn default() -> Self {
        Sensor {
            hall_resolution_rad: 0.0,
            velocity_window: 10,
            pole_pairs: None,
        }
    }
}

/// One effect as written in MODEL.toml: its name and its keys (the keys of its spec).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct EffectEntry {
    name: String,
    /// A table's variable by name (`theta`, `omega`, `current`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    var: Option<String>,
    #[serde(flatten)]
    values: BTreeMap<String, f64>,
}

mod effects_serde {
    use super::*;
    use serde::{Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[Effect<f64>], s: S) -> Result<S::Ok, S::Error> {
        let entries: Vec<EffectEntry> = v
            .iter()
            .map(|e| {
                let mut spec = EffectSpec::from_effect(e);
                let var = match e {
                    Effect::Table { var, .. } => {
                        spec.values.remove("var");
                        Some(var.name().to_string())
                    }
                    _ => None,
                };
                EffectEntry {
                    name: spec.kind.name().to_string(),
                    var,
                    values: spec.values,
                }
            })
            .collect();
        entries.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Effect<f64>>, D::Error> {
        let entries = Vec::<EffectEntry>::deserialize(d)?;
        entries
            .into_iter()
            .map(|en| {
                let kind = EffectKind::from_name(&en.name).ok_or_else(|| {
                    serde::de::Error::custom(format!("unknown effect '{}'", echo(&en.name)))
                })?;
                let keys = crate::effects::of(kind).keys;
                for k in en.values.keys() {
                    if !keys.iter().any(|key| key.name == k) {
                        return Err(serde::de::Error::custom(format!(
                            "effect '{}': unknown key '{}'",
                            en.name,
                            echo(k)
                        )));
                    }
                }
                let mut values = en.values;
                if let Some(var) = &en.var {
                    let tv = control::effects::TableVar::from_name(var)
                        .filter(|_| kind == EffectKind::Table)
                        .ok_or_else(|| {
                            serde::de::Error::custom(format!(
                                "effect '{}': key 'var': '{}' is not one of theta, omega, current",
                                en.name,
                                crate::log::echo(var)
                            ))
                        })?;
                    let code = control::effects::TableVar::ALL
                        .iter()
                        .position(|v| *v == tv)
                        .unwrap_or(0);
                    values.insert("var".into(), code as f64);
                }
                let spec = EffectSpec { kind, values };
                spec.check_values()
                    .map_err(|e| serde::de::Error::custom(format!("{e:#}")))?;
                Ok(spec.to_effect())
            })
            .collect()
    }
}

/// ` field 'table.key':` for the `key = value` line starting at byte `start` (with the table
/// header above it), or nothing.
fn field_at(text: &str, start: usize) -> String {
    let line = text[start..].lines().next().unwrap_or("");
    let Some((key, _)) = line.split_once('=') else {
        return String::new();
    };
    let key = key.trim();
    let table = text[..start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').to_string());
    match table {
        Some(t) => format!(" field '{}.{}':", echo(&t), echo(key)),
        None => format!(" field '{}':", echo(key)),
    }
}

/// A key of table `[name]` that is not one of `known` is an error naming it (the tables whose
/// structs live in the `control` crate, which cannot refuse unknown keys themselves).
fn unknown_keys(text: &str, name: &str, known: &[&str]) -> Result<()> {
    let Ok(doc) = toml::from_str::<toml::Table>(text) else {
        return Ok(());
    };
    if let Some(toml::Value::Table(t)) = doc.get(name) {
        if let Some(k) = t.keys().find(|k| !known.contains(&k.as_str())) {
            anyhow::bail!(
                "field '{name}.{}': unknown field; the fields are {}",
                echo(k),
                known.join(", ")
            );
        }
    }
    Ok(())
}

/// Every float in a TOML value is finite (`field 'sindy.accel...': NaN is not a finite
/// number`).
fn check_toml_numbers(path: &str, v: &toml::Value) -> Result<()> {
    match v {
        // The SINDYc z bound may be +inf on purpose (no bound).
        toml::Value::Float(f) if path.ends_with(".z_max") && *f == f64::INFINITY => Ok(()),
        toml::Value::Float(f) => crate::validate::finite(*f)
            .map(|_| ())
            .map_err(|e| anyhow!("field '{}': {e}", echo(path))),
        toml::Value::Table(t) => t
            .iter()
            .try_for_each(|(k, v)| check_toml_numbers(&format!("{path}.{k}"), v)),
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .try_for_each(|(i, v)| check_toml_numbers(&format!("{path}[{i}]"), v)),
        _ => Ok(()),
    }
}

/// The physical range of each MODEL.toml number, SI units, wide enough for any motor from a
/// micro motor to a multi-kilowatt servo or a linear axis carrying a tonne, narrow enough that
/// every product and quotient a simulation forms stays finite in `f64` and every value fits
/// the board's `f32`. [`Model::validate`] checks a model against them.
pub mod ranges {
    use crate::validate::show;

    /// `lo ..= hi`, with `lo` itself excluded when `open` (a quantity that divides).
    #[derive(Debug, Clone, Copy)]
    pub struct Range {
        pub lo: f64,
        pub hi: f64,
        pub open: bool,
        /// What the number is, with its unit, for messages.
        pub what: &'static str,
    }

    impl Range {
        /// Ok when `v` is finite and in the range; else what is wrong with it.
        pub fn check(&self, v: f64) -> Result<(), String> {
            crate::validate::finite(v)?;
            let below = if self.open { v <= self.lo } else { v < self.lo };
            if below || v > self.hi {
                let (lo, hi) = (show(self.lo), show(self.hi));
                let range = if self.open {
                    format!("({lo}, {hi}]")
                } else {
                    format!("{lo} .. {hi}")
                };
                return Err(format!("{} is outside {range} ({})", show(v), self.what));
            }
            Ok(())
        }
    }

    const fn range(lo: f64, hi: f64, open: bool, what: &'static str) -> Range {
        Range { lo, hi, open, what }
    }

    /// Sample period [s]: the range a log's may have (`validate::sample_period`).
    pub const SAMPLE_PERIOD: Range = range(
        crate::validate::MIN_SAMPLE_PERIOD,
        crate::validate::MAX_SAMPLE_PERIOD,
        false,
        "sample period [s]",
    );
    /// Phase resistance R [Ω]: 10 µΩ, below the winding of any multi-kilowatt motor, to
    /// 10 kΩ, ten times a micro motor's; it divides in the electrical time constant.
    pub const R: Range = range(1e-5, 1e4, true, "resistance [Ω]");
    /// Phase inductance L [H]: 1 nH (an ironless PCB motor has µH) to 10 H (no motor winding
    /// comes near); it divides in `dI/dt`.
    pub const L: Range = range(1e-9, 10.0, true, "inductance [H]");
    /// Torque constant K_t [N·m/A], or the input gain of a torque plant (1): 1 µN·m/A (a
    /// watch motor has about 10 µN·m/A) to 1000 N·m/A (a direct-drive torque motor has
    /// tens).
    pub const KT: Range = range(1e-6, 1e3, true, "torque constant [N·m/A]");
    /// Back-EMF constant K_b [V·s/rad]: 0 (not identified, or a torque plant) to 1000, the
    /// same scale as K_t (equal in SI units).
    pub const KB: Range = range(0.0, 1e3, false, "back-EMF constant [V·s/rad]");
    /// Inertia J [kg·m²], or the mass of a linear axis [kg]: 1e-12 (below a watch motor's
    /// rotor, about 1e-10) to 1e6 (a tonne-scale axis with margin); it divides in `dω/dt`.
    pub const J: Range = range(1e-12, 1e6, true, "inertia [kg·m²] or mass [kg]");
    /// A viscous or bristle damping [N·m·s/rad or N·s/m]: magnitude up to 1e6 (a loaded
    /// linear axis has hundreds); the sign is left to the fit, which may land slightly below 0
    /// on noisy data.
    pub const DAMPING: Range = range(-1e6, 1e6, false, "damping [N·m·s/rad]");
    /// A friction level (Coulomb α0, Stribeck excess α1) [N·m or N]: magnitude up to 1e6
    /// (a tonne-scale linear axis has a few hundred N).
    pub const FRICTION: Range = range(-1e6, 1e6, false, "friction [N·m]");
    /// Stribeck velocity v0 [rad/s or m/s]: above 0 (it divides) to 1e4 (about 100 000 rpm,
    /// beyond any motor's top speed).
    pub const STRIBECK_VELOCITY: Range = range(0.0, 1e4, true, "Stribeck velocity [rad/s]");
    /// Bristle stiffness σ0 [N·m/rad or N/m]: above 0 (it divides the deflection) to 1e9
    /// (a stiff ball-screw axis has about 1e8 N/m).
    pub const STIFFNESS: Range = range(0.0, 1e9, true, "bristle stiffness [N·m/rad]");
    /// Moving-average window [samples]: 1 to the firmware estimator's capacity
    /// (`control::velocity::MAX_WINDOW`); a longer window would be cut short on the board.
    pub const VELOCITY_WINDOW: Range = range(
        1.0,
        control::velocity::MAX_WINDOW as f64,
        false,
        "moving-average window [samples]",
    );
    /// Most effects a model carries: 32, four times what the board's blob holds
    /// (`control::blob::MAX_EFFECTS`), room for every effect kind and a few cogging
    /// harmonics; each effect costs every simulation step, so the count bounds their time.
    pub const MAX_EFFECTS: usize = 32;
    /// Pole pairs: 1 to 255, the byte the coefficient blob stores (real motors have 1 to
    /// about 100).
    pub const POLE_PAIRS: Range = range(1.0, 255.0, false, "pole pairs");
}

/// An identified model (MODEL.toml). A key the model does not have (a typo, a key in the
/// wrong table) is an error, not ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// `linear`, `lugre` or `sindyc`.
    pub kind: ModelKind,
    /// `voltage` (u is a voltage, eqs. 1–2) or `torque` (u is a torque/force command).
    pub plant: Plant,
    /// Sample period [s] the model was identified at (free-run simulation step).
    pub sample_period: f64,
    /// Motor constants: r [Ω], l [H], kt [N·m/A], kb [V·s/rad], j [kg·m²]
    /// (see the file's doc comment for `--plant torque`).
    pub motor: MotorParams<f64>,
    /// Viscous friction b [N·m·s/rad] of the linear model (0 for the other kinds).
    #[serde(default)]
    pub viscous: f64,
    /// LuGre friction (kind `lugre`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lugre: Option<LugreParams>,
    /// SINDYc equations (kind `sindyc`), as written by `ident::sindyc`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sindy: Option<toml::Table>,
    /// Extra physical effects, added with `fit --add`.
    #[serde(default, with = "effects_serde")]
    pub effects: Vec<Effect<f64>>,
    /// Width [rad/s, or the log's velocity unit] of the smooth sign `tanh(ω/ε)` of the
    /// Coulomb-like effects: `control::effects::VELOCITY_EPS` for a log as fast as the paper's
    /// motor, that times [`crate::scales::velocity_scale`] for a slower one (a linear axis in
    /// m/s), so that the friction switches as sharply relative to the data's speeds. Written
    /// only when it differs from `VELOCITY_EPS`.
    #[serde(
        default = "default_sign_width",
        skip_serializing_if = "is_default_sign_width"
    )]
    pub sign_width: f64,
    /// The measurement chain.
    #[serde(default)]
    pub sensor: Sensor,
    /// Where the data came from.
    #[serde(default)]
    pub data: Provenance,
    /// Every identified number with its unit and standard error (for people; the simulation
    /// reads the sections above).
    #[serde(default)]
    pub parameters: Vec<Parameter>,
}

fn default_sign_width() -> f64 {
    control::effects::VELOCITY_EPS
}

fn is_default_sign_width(w: &f64) -> bool {
    *w == control::effects::VELOCITY_EPS
}

impl Model {
    /// A model of the given kind with the paper's motor and nothing fitted.
    pub fn new(kind: ModelKind, plant: Plant, sample_period: f64) -> Model {
        Model {
            kind,
            plant,
            sample_period,
            motor: MotorParams::paper(),
            viscous: 0.0,
            lugre: None,
            sindy: None,
            effects: Vec::new(),
            sign_width: default_sign_width(),
            sensor: Sensor::default(),
            data: Provenance::default(),
            parameters: Vec::new(),
        }
    }

    /// Parse MODEL.toml text; `path` names the file in errors (with line and column).
    pub fn parse(text: &str, path: &Path) -> Result<Model> {
        let p = crate::log::echo_path(path);
        let model = toml::from_str::<Model>(text).map_err(|e| {
            // One line, and no word of the input echoed whole (a 300-digit number, escapes).
            let msg: Vec<String> = e.message().split_whitespace().map(echo).collect();
            let msg = msg.join(" ");
            match e.span() {
                Some(span) => {
                    let before = &text[..span.start.min(text.len())];
                    let line = before.matches('\n').count() + 1;
                    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
                    let col = before.len() - line_start + 1;
                    anyhow!("{p}:{line}:{col}:{} {msg}", field_at(text, line_start))
                }
                None => anyhow!("{p}: {msg}"),
            }
        })?;
        unknown_keys(text, "motor", &["r", "l", "kt", "kb", "j"])
            .and_then(|()| unknown_keys(text, "lugre", &LUGRE_KEYS))
            .map_err(|e| anyhow!("{p}: {e}"))?;
        Ok(model)
    }

    /// Read MODEL.toml.
    pub fn load(path: &Path) -> Result<Model> {
        let text = crate::input::read_text(path, crate::input::MAX_MODEL_FILE, "MODEL.toml")?;
        let m = Self::parse(&text, path)?;
        m.validate()
            .map_err(|e| anyhow!("{}: {e}", crate::log::echo_path(path)))?;
        Ok(m)
    }

    /// Every number a simulation or an export relies on is finite and in its physical range
    /// ([`ranges`]): the one check of a model, run by [`Model::load`] for every command that
    /// reads MODEL.toml, and by `fit` before it writes one. The message names the field
    /// (`field 'lugre.alpha0': NaN is not a finite number`, `field 'motor.j': 1e-300 is
    /// outside 1e-12 .. 1e6 (inertia [kg·m²] or mass [kg])`).
    pub fn validate(&self) -> Result<()> {
        use ranges::*;
        let check = |name: &str, v: f64, r: &Range| -> Result<()> {
            r.check(v).map_err(|e| anyhow!("field '{name}': {e}"))
        };
        check("sample_period", self.sample_period, &SAMPLE_PERIOD)?;
        let m = &self.motor;
        let voltage = self.plant == Plant::Voltage;
        // A torque plant has no electrical equation: r, l, kb are unused (0), kt is 1.
        let unused = |r: &Range| Range {
            lo: 0.0,
            open: false,
            ..*r
        };
        check("motor.r", m.r, &if voltage { R } else { unused(&R) })?;
        check("motor.l", m.l, &if voltage { L } else { unused(&L) })?;
        check("motor.kt", m.kt, &KT)?;
        check("motor.kb", m.kb, &KB)?;
        check("motor.j", m.j, &J)?;
        check("viscous", self.viscous, &DAMPING)?;
        if self.effects.len() > MAX_EFFECTS {
            anyhow::bail!(
                "field 'effects': {} effects; a model carries at most {MAX_EFFECTS}",
                self.effects.len()
            );
        }
        let sensor = &self.sensor;
        crate::validate::angle_quantum(sensor.hall_resolution_rad)
            .map_err(|e| anyhow!("field 'sensor.hall_resolution_rad': {e}"))?;
        check(
            "sensor.velocity_window",
            sensor.velocity_window as f64,
            &VELOCITY_WINDOW,
        )?;
        if let Some(p) = sensor.pole_pairs {
            check("sensor.pole_pairs", f64::from(p), &POLE_PAIRS)?;
        }
        if let Some(l) = &self.lugre {
            check("lugre.alpha0", l.alpha0, &FRICTION)?;
            check("lugre.alpha1", l.alpha1, &FRICTION)?;
            check("lugre.alpha2", l.alpha2, &DAMPING)?;
            check("lugre.v0", l.v0, &STRIBECK_VELOCITY)?;
            check("lugre.sigma0", l.sigma0, &STIFFNESS)?;
            check("lugre.sigma1", l.sigma1, &DAMPING)?;
            if l.alpha0 + l.alpha1 <= 0.0 {
                anyhow::bail!(
                    "field 'lugre.alpha0': alpha0 + alpha1 (the breakaway friction) must be positive"
                );
            }
        }
        if let Some(t) = &self.sindy {
            check_toml_numbers("sindy", &toml::Value::Table(t.clone()))?;
            // Terms and keys too: a table the simulation cannot read is refused here, once.
            let (sm, _) = crate::ident::sindyc::from_table(t)?;
            // Without a term of the current or the input the modelled rotor never moves.
            let driven = sm
                .accel
                .terms
                .iter()
                .any(|(term, c)| (term.has_current() || term.has_voltage()) && *c != 0.0);
            if self.kind == ModelKind::Sindyc && !driven {
                anyhow::bail!(
                    "field 'sindy.accel': no term of the current or the input (i, u, ...) with a \
                     nonzero coefficient: the modelled motor cannot move"
                );
            }
        }
        // The smooth sign's width is a velocity, as the Stribeck velocity.
        check("sign_width", self.sign_width, &STRIBECK_VELOCITY)?;
        if self.kind == ModelKind::Lugre && self.lugre.is_none() {
            anyhow::bail!("field 'lugre': a model of kind 'lugre' needs a [lugre] table");
        }
        if self.kind == ModelKind::Sindyc && self.sindy.is_none() {
            anyhow::bail!("field 'sindy': a model of kind 'sindyc' needs a [sindy] table");
        }
        // A table of another kind would be silently ignored: the kind decides how it reads.
        for (table, present, kind) in [
            ("lugre", self.lugre.is_some(), ModelKind::Lugre),
            ("sindy", self.sindy.is_some(), ModelKind::Sindyc),
        ] {
            if present && self.kind != kind {
                anyhow::bail!(
                    "field '{table}': a model of kind '{}' has no [{table}] table (it belongs to \
                     kind '{}'); remove it or change 'kind'",
                    self.kind.name(),
                    kind.name()
                );
            }
        }
        Ok(())
    }

    /// The TOML text.
    pub fn to_toml(&self) -> Result<String> {
        let body = toml::to_string_pretty(self).context("cannot render the model as TOML")?;
        Ok(format!(
            "# motorid model ({}). Units are SI; see [[parameters]] for each number's unit and\n\
             # standard error. Written by `motorid fit`.\n{body}",
            self.kind.name()
        ))
    }

    /// Write MODEL.toml atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::atomic::write_str(path, &self.to_toml()?)
    }

    /// The effect specs of the model's effects (as `diagnose` prints them).
    pub fn effect_specs(&self) -> Vec<EffectSpec> {
        self.effects.iter().map(EffectSpec::from_effect).collect()
    }

    /// A parameter by name.
    pub fn parameter(&self, name: &str) -> Option<&Parameter> {
        self.parameters.iter().find(|p| p.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_round_trip_keeps_effects_and_parameters() {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(LugreParams::paper());
        m.effects.push(Effect::Cogging {
            harmonic: 7,
            amp: 0.0123456789,
            phase: 0.5,
        });
        let table = EffectSpec::parse("table:var=current,bins=3,lo=-2,hi=4,b0=0.01,b2=-0.03")
            .unwrap()
            .to_effect();
        m.effects.push(table);
        // A table over the stroke of a linear axis keeps its range.
        let stroke = EffectSpec::parse("table:var=theta,bins=4,lo=0,hi=0.25,b1=0.5")
            .unwrap()
            .to_effect();
        m.effects.push(stroke);
        m.parameters.push(Parameter::new("R", 0.2, "Ω"));
        m.data.units.insert("t".into(), "ms".into());
        let text = m.to_toml().unwrap();
        assert!(text.contains("[data.units]"), "{text}");
        assert!(text.contains("name = \"cogging\""), "{text}");
        assert!(text.contains("var = \"current\""), "{text}");
        let back = Model::parse(&text, Path::new("m.toml")).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn models_written_before_units_still_load() {
        let m = Model::new(ModelKind::Linear, Plant::Voltage, 0.012);
        let text = m.to_toml().unwrap();
        assert!(!text.contains("units"), "{text}");
        let back = Model::parse(&text, Path::new("m.toml")).unwrap();
        assert!(back.data.units.is_empty());
    }

    #[test]
    fn errors_name_line_and_field() {
        let mut m = Model::new(ModelKind::Linear, Plant::Voltage, 0.012);
        m.viscous = 0.001;
        let text = m
            .to_toml()
            .unwrap()
            .replace("kind = \"linear\"", "kind = \"quadratic\"");
        let e = Model::parse(&text, Path::new("m.toml"))
            .unwrap_err()
            .to_string();
        let line = text.lines().position(|l| l.contains("quadratic")).unwrap() + 1;
        assert!(e.starts_with(&format!("m.toml:{line}:")), "{e}");
        let mut m2 = m.clone();
        m2.motor.j = -1.0;
        assert!(m2.validate().unwrap_err().to_string().contains("motor.j"));
    }

    #[test]
    fn bristles_rest_on_the_stribeck_curve() {
        let l = LugreParams::paper();
        // On the Stribeck curve the bristles are still and the friction is s(ω) + α2·ω.
        let z = l.s(2.0) / l.sigma0;
        assert!(lugre_z_rate(&l, 2.0, z).abs() < 1e-12);
        assert!((lugre_friction(&l, 2.0, z) - l.steady_friction(2.0)).abs() < 1e-12);
    }

    /// The motor ranges of MODEL.toml are the board's (control::blob), so a model that
    /// loads also exports and a blob that decodes also loads.
    #[test]
    fn model_motor_ranges_are_the_blobs() {
        use control::blob::{MOTOR_J, MOTOR_KB, MOTOR_KT, MOTOR_L, MOTOR_R};
        for (r, b) in [
            (ranges::R, MOTOR_R),
            (ranges::L, MOTOR_L),
            (ranges::KT, MOTOR_KT),
            (ranges::KB, MOTOR_KB),
            (ranges::J, MOTOR_J),
        ] {
            assert_eq!((r.lo as f32, r.hi as f32), b, "{}", r.what);
        }
    }
}
