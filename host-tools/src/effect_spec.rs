//! Effect specs as the user types them: `NAME` or `NAME:key=value,...`
//! (`--effect` of `simulate`, `--add` of `fit`, the `spec` that `diagnose` prints).
//!
//! The equations behind each name are in `control::effects`; this file holds the keys, their
//! units and the defaults used when a key is left out.
use anyhow::{anyhow, bail, Result};
use control::effects::{Effect, EffectKind, TableVar, TABLE_MAX_BINS};
use std::collections::BTreeMap;
use std::fmt;

/// One key of an effect: name, unit, default value (for the emulator), meaning.
pub struct Key {
    pub name: &'static str,
    pub unit: &'static str,
    pub default: f64,
    pub meaning: &'static str,
    /// Never negative, whatever its unit allows elsewhere (a width, a spring, a damper).
    pub nonnegative: bool,
}

impl Key {
    /// The values this key accepts (inclusive), by its unit: wide enough for any motor or
    /// linear axis (torques and forces up to 10⁴ N·m or N), narrow enough that a simulation
    /// stays finite and quick. Signs are free where a fit may estimate either sign; a time
    /// constant or a velocity scale must be positive.
    pub fn range(&self) -> (f64, f64) {
        let (lo, hi) = self.unit_range();
        (if self.nonnegative { lo.max(0.0) } else { lo }, hi)
    }

    fn unit_range(&self) -> (f64, f64) {
        match self.unit {
            "N·m" | "N·m·s/rad" | "V" | "A" => (-1e4, 1e4),
            "N·m/rad" => (-1e9, 1e9),
            "rad" => (-1e3, 1e3),
            "rad/s" => (1e-6, 1e5),
            "1/rev" => (2.0, 1000.0),
            "1/A²" => (-1e3, 1e3),
            "kg·m²" => (0.0, 1e3),
            TABLE_VAR_UNIT => (0.0, 2.0),
            "bins" => (2.0, TABLE_MAX_BINS as f64),
            "rad, rad/s or A" => (-1e5, 1e5),
            "s" => (1e-3, 1e7),
            "1" => (-1.0, 1.0),
            _ => (-1e9, 1e9),
        }
    }
}

/// The "unit" of a table's `var` key: its value is a variable's name, stored as its index
/// in [`TableVar::ALL`].
pub const TABLE_VAR_UNIT: &str = "theta|omega|current";

const fn k(name: &'static str, unit: &'static str, default: f64, meaning: &'static str) -> Key {
    Key {
        name,
        unit,
        default,
        meaning,
        nonnegative: false,
    }
}

/// [`k`] for a key that is never negative.
const fn k0(name: &'static str, unit: &'static str, default: f64, meaning: &'static str) -> Key {
    Key {
        nonnegative: true,
        ..k(name, unit, default, meaning)
    }
}

/// The keys of a `table`: the variable, the number of nodes, the range of ω or I the nodes
/// span (set from the data by `fit`), then the torque at each node.
#[rustfmt::skip]
const TABLE_KEYS: &[Key] = &[
    k("var", TABLE_VAR_UNIT, 0.0, "variable the torque is looked up by"),
    k("bins", "bins", 8.0, "number of table nodes (2 to 16)"),
    k("lo", "rad, rad/s or A", 0.0, "first node (omega, current; theta: start of a stroke)"),
    k("hi", "rad, rad/s or A", 0.0, "last node (omega, current; theta: end of a stroke)"),
    k("b0", "N·m", 0.0, "table torque at node 0"),
    k("b1", "N·m", 0.0, "table torque at node 1"),
    k("b2", "N·m", 0.0, "table torque at node 2"),
    k("b3", "N·m", 0.0, "table torque at node 3"),
    k("b4", "N·m", 0.0, "table torque at node 4"),
    k("b5", "N·m", 0.0, "table torque at node 5"),
    k("b6", "N·m", 0.0, "table torque at node 6"),
    k("b7", "N·m", 0.0, "table torque at node 7"),
    k("b8", "N·m", 0.0, "table torque at node 8"),
    k("b9", "N·m", 0.0, "table torque at node 9"),
    k("b10", "N·m", 0.0, "table torque at node 10"),
    k("b11", "N·m", 0.0, "table torque at node 11"),
    k("b12", "N·m", 0.0, "table torque at node 12"),
    k("b13", "N·m", 0.0, "table torque at node 13"),
    k("b14", "N·m", 0.0, "table torque at node 14"),
    k("b15", "N·m", 0.0, "table torque at node 15"),
];

// One key per node the board can hold: a key beyond them would parse and then be dropped.
const _: () = assert!(TABLE_KEYS.len() == 4 + TABLE_MAX_BINS);

/// The name of the torque at node `k` of a table (`b0`, `b1`, ...).
pub fn table_value_key(k: usize) -> &'static str {
    TABLE_KEYS[4 + k.min(TABLE_MAX_BINS - 1)].name
}

// The keys of each effect, in the order the spec prints them: name, unit, default, meaning.
// Defaults are sized for the reference paper's motor (Coulomb friction 0.08 N·m,
// K_t = 0.071 N·m/A): clearly visible in the data, but smaller than the friction the base
// model already has.

/// Backlash. Default: a load twice the paper rotor's inertia behind a gap of two Hall steps
/// of the paper's board (0.19 rad), a worn gear stage seen at the rotor.
#[rustfmt::skip]
const BACKLASH_KEYS: &[Key] = &[
    k("j2", "kg·m²", 6e-4, "inertia of the load behind the gap"),
    // A gap is a width.
    k0("gap", "rad", 0.19, "angle the rotor turns alone after a reversal"),
];

/// Coulomb friction.
const COULOMB_KEYS: &[Key] = &[k("fc", "N·m", 0.05, "Coulomb friction torque")];

/// Viscous friction.
const VISCOUS_KEYS: &[Key] = &[k("b", "N·m·s/rad", 0.001, "viscous friction coefficient")];

/// Stribeck friction.
#[rustfmt::skip]
const STRIBECK_KEYS: &[Key] = &[
    k("fs", "N·m", 0.04, "breakaway torque above Coulomb"),
    k("vs", "rad/s", 5.0, "Stribeck velocity"),
];

/// Presliding (the LuGre bristles). Defaults: the compliance of a geared axis as seen at the
/// rotor, where presliding becomes visible. A size-14 harmonic drive winds up about 1 mrad at
/// its output under its rated torque (torsional stiffness of a few 10³ N·m/rad); with ratio
/// 100 the rotor sees that stiffness divided by 100², about 0.4 N·m/rad. With the paper's
/// static friction s(0) = α0 + α1 = 0.0975 N·m the breakaway deflection s(0)/σ0 is then
/// 0.24 rad at the rotor, 2.6 Hall steps (0.095 rad) of the paper's board. (The paper's own
/// bristles, σ0 = 317, deflect 0.3 mrad: far inside one Hall step, invisible.) σ1 = 0.022:
/// critical damping of the rotor inertia J = 3e-4 kg·m² on that spring, 2·√(σ0·J).
#[rustfmt::skip]
const PRESLIDING_KEYS: &[Key] = &[
    k("sigma0", "N·m/rad", 0.4, "bristle stiffness"),
    k("sigma1", "N·m·s/rad", 0.022, "bristle damping"),
];

/// Cogging torque.
#[rustfmt::skip]
const COGGING_KEYS: &[Key] = &[
    k("harmonic", "1/rev", 7.0, "periods per revolution (2 or more)"),
    k("amp", "N·m", 0.03, "torque amplitude"),
    k("phase", "rad", 0.0, "phase"),
];

/// A load torque periodic in angle, one period per revolution.
#[rustfmt::skip]
const POSITION_LOAD_KEYS: &[Key] = &[
    k("amp", "N·m", 0.05, "torque amplitude (one period per revolution)"),
    k("phase", "rad", 0.0, "phase"),
];

/// A constant load torque.
const OFFSET_KEYS: &[Key] = &[k("t0", "N·m", 0.03, "constant load torque")];

/// Friction that differs by direction.
#[rustfmt::skip]
const ASYMMETRY_KEYS: &[Key] = &[
    k("dv", "N·m·s/rad", 0.0008, "viscous friction difference (b ± dv by direction)"),
    k("dc", "N·m", 0.0, "Coulomb friction difference (fc ± dc by direction)"),
];

/// The inverter's voltage loss.
const DEADTIME_KEYS: &[Key] = &[k(
    "vd",
    "V",
    0.3,
    "inverter voltage loss, sign of the current",
)];

/// The current sensor's offset.
const CURRENT_OFFSET_KEYS: &[Key] = &[k("i0", "A", 0.2, "current-sensor offset")];

/// Winding resistance rising as the motor heats. Defaults: copper's resistance rises
/// 0.393 %/K; k = 0.02/A² is +8 % (≈ +20 K of winding) at 2 A steady and +2 % at 1 A, what a
/// small BLDC motor with a few K/W winding-to-ambient reaches at the paper's currents (a
/// tenth of it, +0.8 %, is too small to see in a 60–90 s log). tau = 30 s: a small motor's
/// winding thermal time constant (the case takes minutes).
#[rustfmt::skip]
const THERMAL_KEYS: &[Key] = &[
    k("k", "1/A²", 0.02, "relative resistance rise per A² of steady current"),
    k("tau", "s", 30.0, "thermal time constant"),
];

/// Friction growing with transmitted torque. Default μ = 0.2: high-ratio transmissions (worm
/// and harmonic gears, lead screws) lose 10–30 % of the torque they transmit; spur gears and
/// ball screws 2–10 %. Smaller values differ from a lower K_t only while the drive brakes and
/// are not visible on the paper motor (docs/limits.md).
const LOAD_FRICTION_KEYS: &[Key] = &[k("mu", "1", 0.2, "friction per N·m of transmitted torque")];

/// A second inertia on a spring-damper coupling. Default: a load twice the paper rotor's
/// inertia on a coupling that resonates near 5 Hz, lightly damped (ζ ≈ 0.05), as a flexible
/// coupling or a long shaft.
#[rustfmt::skip]
const COMPLIANCE_KEYS: &[Key] = &[
    k("j2", "kg·m²", 6e-4, "inertia of the load behind the coupling"),
    // A spring or damper of negative sign would give energy back: the coupled free run and
    // the plant would be unstable, and the implicit step's divisor j2/h + k·h + c could vanish.
    k0("k", "N·m/rad", 0.2, "stiffness of the coupling"),
    k0("c", "N·m·s/rad", 6e-4, "damping of the coupling"),
];

/// A torque constant falling with current. Default k = 2e-4/A²: K_t down 2 % at 10 A and
/// 24 % at 40 A, the board's peak rating; small BLDC motors lose 10-30 % of K_t at two to
/// three times their continuous current.
const SATURATION_KEYS: &[Key] = &[k(
    "k",
    "1/A²",
    2e-4,
    "torque constant falls as K_t/(1 + k·I²)",
)];

/// The keys of an effect, in the order the spec prints them (see the tables above for their
/// units, defaults and the reasons behind the defaults).
pub fn keys(kind: EffectKind) -> &'static [Key] {
    match kind {
        EffectKind::Table => TABLE_KEYS,
        EffectKind::Backlash => BACKLASH_KEYS,
        EffectKind::Coulomb => COULOMB_KEYS,
        EffectKind::Viscous => VISCOUS_KEYS,
        EffectKind::Stribeck => STRIBECK_KEYS,
        EffectKind::Presliding => PRESLIDING_KEYS,
        EffectKind::Cogging => COGGING_KEYS,
        EffectKind::PositionLoad => POSITION_LOAD_KEYS,
        EffectKind::Offset => OFFSET_KEYS,
        EffectKind::Asymmetry => ASYMMETRY_KEYS,
        EffectKind::Deadtime => DEADTIME_KEYS,
        EffectKind::CurrentOffset => CURRENT_OFFSET_KEYS,
        EffectKind::Thermal => THERMAL_KEYS,
        EffectKind::LoadFriction => LOAD_FRICTION_KEYS,
        EffectKind::Compliance => COMPLIANCE_KEYS,
        EffectKind::Saturation => SATURATION_KEYS,
    }
}

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
        let known = keys(kind);
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
        for key in keys(self.kind) {
            let Some(&v) = self.values.get(key.name) else {
                continue;
            };
            let (lo, hi) = key.range();
            crate::validate::in_range(v, lo, hi)
                .map_err(|e| anyhow!("effect '{name}': key '{}' [{}]: {e}", key.name, key.unit))?;
        }
        if self.kind == EffectKind::Cogging {
            if let Some(h) = self.values.get("harmonic") {
                if *h < 2.0 || h.fract() != 0.0 || *h > 1000.0 {
                    bail!(
                        "effect 'cogging': harmonic must be a whole number of 2 or more (got {}); \
                         one period per revolution is 'position_load'",
                        crate::validate::show(*h)
                    );
                }
            }
        }
        if self.kind == EffectKind::Table {
            let whole = |key: &str| self.values.get(key).is_none_or(|v| v.fract() == 0.0);
            if !whole("var") || !whole("bins") {
                bail!("effect 'table': var and bins must be whole (var one of theta, omega, current; bins 2 to {TABLE_MAX_BINS})");
            }
            let bins = self.get("bins") as usize;
            if let Some(k) =
                (bins..TABLE_MAX_BINS).find(|&k| self.values.contains_key(table_value_key(k)))
            {
                bail!(
                    "effect 'table': key '{}' is beyond the table's {bins} bins (b0 to b{})",
                    table_value_key(k),
                    bins - 1
                );
            }
            if let (Some(lo), Some(hi)) = (self.values.get("lo"), self.values.get("hi")) {
                if lo >= hi {
                    bail!(
                        "effect 'table': lo ({}) must be below hi ({})",
                        crate::validate::show(*lo),
                        crate::validate::show(*hi)
                    );
                }
            }
        }
        Ok(())
    }

    /// The variable of a `table` spec (θ for other effects).
    pub fn table_var(&self) -> TableVar {
        TableVar::ALL[(self.get("var").clamp(0.0, 2.0)) as usize]
    }

    /// The value of a key: the user's, or the default.
    pub fn get(&self, key: &str) -> f64 {
        self.values.get(key).copied().unwrap_or_else(|| {
            keys(self.kind)
                .iter()
                .find(|k| k.name == key)
                .map(|k| k.default)
                .unwrap_or(0.0)
        })
    }

    /// The effect with these values (defaults where not given).
    pub fn to_effect(&self) -> Effect<f64> {
        let g = |k: &str| self.get(k);
        match self.kind {
            EffectKind::Coulomb => Effect::Coulomb { fc: g("fc") },
            EffectKind::Viscous => Effect::Viscous { b: g("b") },
            EffectKind::Stribeck => Effect::Stribeck {
                fs: g("fs"),
                vs: g("vs"),
            },
            EffectKind::Presliding => Effect::Presliding {
                sigma0: g("sigma0"),
                sigma1: g("sigma1"),
            },
            EffectKind::Cogging => Effect::Cogging {
                harmonic: g("harmonic").round().clamp(2.0, 1000.0) as u16,
                amp: g("amp"),
                phase: g("phase"),
            },
            EffectKind::PositionLoad => Effect::PositionLoad {
                amp: g("amp"),
                phase: g("phase"),
            },
            EffectKind::Offset => Effect::Offset { t0: g("t0") },
            EffectKind::Asymmetry => Effect::Asymmetry {
                dv: g("dv"),
                dc: g("dc"),
            },
            EffectKind::Deadtime => Effect::Deadtime { vd: g("vd") },
            EffectKind::CurrentOffset => Effect::CurrentOffset { i0: g("i0") },
            EffectKind::Thermal => Effect::Thermal {
                k: g("k"),
                tau: g("tau"),
            },
            EffectKind::LoadFriction => Effect::LoadFriction { mu: g("mu") },
            EffectKind::Saturation => Effect::Saturation { k: g("k") },
            EffectKind::Compliance => Effect::Compliance {
                j2: g("j2"),
                k: g("k"),
                c: g("c"),
            },
            EffectKind::Backlash => Effect::Backlash {
                j2: g("j2"),
                gap: g("gap"),
            },
            EffectKind::Table => {
                let bins = g("bins").round().clamp(2.0, TABLE_MAX_BINS as f64) as u8;
                let mut values = [0.0; TABLE_MAX_BINS];
                for (k, v) in values.iter_mut().enumerate().take(bins as usize) {
                    *v = g(table_value_key(k));
                }
                Effect::Table {
                    var: self.table_var(),
                    bins,
                    lo: g("lo"),
                    hi: g("hi"),
                    values,
                }
            }
        }
    }

    /// The spec of an effect with all its values.
    pub fn from_effect(e: &Effect<f64>) -> EffectSpec {
        let mut values = BTreeMap::new();
        let mut put = |k: &str, v: f64| {
            values.insert(k.to_string(), v);
        };
        match *e {
            Effect::Coulomb { fc } => put("fc", fc),
            Effect::Viscous { b } => put("b", b),
            Effect::Stribeck { fs, vs } => {
                put("fs", fs);
                put("vs", vs)
            }
            Effect::Presliding { sigma0, sigma1 } => {
                put("sigma0", sigma0);
                put("sigma1", sigma1)
            }
            Effect::Cogging {
                harmonic,
                amp,
                phase,
            } => {
                put("harmonic", harmonic as f64);
                put("amp", amp);
                put("phase", phase)
            }
            Effect::PositionLoad { amp, phase } => {
                put("amp", amp);
                put("phase", phase)
            }
            Effect::Offset { t0 } => put("t0", t0),
            Effect::Asymmetry { dv, dc } => {
                put("dv", dv);
                put("dc", dc)
            }
            Effect::Deadtime { vd } => put("vd", vd),
            Effect::CurrentOffset { i0 } => put("i0", i0),
            Effect::Thermal { k, tau } => {
                put("k", k);
                put("tau", tau)
            }
            Effect::LoadFriction { mu } => put("mu", mu),
            Effect::Saturation { k } => put("k", k),
            Effect::Compliance { j2, k, c } => {
                put("j2", j2);
                put("k", k);
                put("c", c)
            }
            Effect::Backlash { j2, gap } => {
                put("j2", j2);
                put("gap", gap)
            }
            Effect::Table {
                var,
                bins,
                lo,
                hi,
                values: ref v,
            } => {
                put(
                    "var",
                    TableVar::ALL.iter().position(|x| *x == var).unwrap_or(0) as f64,
                );
                put("bins", bins as f64);
                if var != TableVar::Theta || hi > lo {
                    put("lo", lo);
                    put("hi", hi);
                }
                for (k, x) in v.iter().enumerate().take(bins as usize) {
                    put(table_value_key(k), *x);
                }
            }
        }
        EffectSpec {
            kind: e.kind(),
            values,
        }
    }

    /// `--help` text listing every effect and its keys.
    pub fn help_text() -> String {
        let mut s = String::from("Effects (NAME or NAME:key=value,...):\n");
        for kind in EffectKind::ALL {
            if kind == EffectKind::Table {
                s.push_str(&format!(
                    "  {:<15} var=theta|omega|current; bins=8 [2 to {TABLE_MAX_BINS}] nodes; \
                     lo, hi [rad, rad/s or A] range the nodes span (omega, current: fit takes it \
                     from the data; theta: the stroke of a linear axis, clamped at its ends); \
                     b0..b<bins-1> [N·m] torque at each node (theta without lo, hi: one \
                     revolution, periodic)\n",
                    kind.name()
                ));
                continue;
            }
            let ks: Vec<String> = keys(kind)
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
        for key in keys(self.kind) {
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
            assert!(!keys(kind).is_empty());
        }
    }
}
