//! One descriptor per physical effect: what the host knows about an effect beside its
//! equations (which are in `control::effects`). Each effect's file holds its name and meaning,
//! its keys (unit, default, meaning, accepted values), the bounds a fit keeps its estimable
//! keys in, and the regressor columns and library terms the identification code builds from
//! it. This file is the registry: the list of every descriptor and the lookup by kind or name.
//!
//! The spec parser ([`crate::effect_spec`]), the free parameters, the weak-form regressions,
//! the SINDYc library and `diagnose`'s candidates read an effect only through its
//! [`Descriptor`].
use crate::diagnose::candidates::{Equation, Signals, Units, Variant};
use crate::effect_spec::EffectSpec;
use crate::ident::library::ACCEL;
use anyhow::Result;
use control::effects::{Effect, EffectKind, TableVar, TABLE_MAX_BINS};
use control::sindy::Term;
use std::collections::BTreeMap;

mod asymmetry;
mod backlash;
mod cogging;
mod compliance;
mod coulomb;
mod current_offset;
mod deadtime;
mod load_friction;
mod offset;
mod position_load;
pub mod presliding;
mod saturation;
mod stribeck;
pub mod table;
mod thermal;
mod viscous;

pub use table::table_value_key;

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

/// A key that may take either sign.
pub(crate) const fn k(
    name: &'static str,
    unit: &'static str,
    default: f64,
    meaning: &'static str,
) -> Key {
    Key {
        name,
        unit,
        default,
        meaning,
        nonnegative: false,
    }
}

/// [`k`] for a key that is never negative.
pub(crate) const fn k0(
    name: &'static str,
    unit: &'static str,
    default: f64,
    meaning: &'static str,
) -> Key {
    Key {
        nonnegative: true,
        ..k(name, unit, default, meaning)
    }
}

/// An estimable key with the bounds a fit keeps it in: physical sign where there is one,
/// else ± a generous range.
pub type FitKey = (&'static str, f64, f64);

/// The signals a torque regressor is made of, on one log.
pub struct TorqueSignals<'a> {
    /// The effect (its structural keys: a Stribeck velocity, a harmonic).
    pub effect: &'a Effect<f64>,
    /// Torque constant K_t [N·m/A] (1 on a torque plant).
    pub kt: f64,
    /// Rotor angle [rad].
    pub theta: &'a [f64],
    /// Smoothed velocity [rad/s].
    pub ws: &'a [f64],
    /// Smooth sign of `ws`.
    pub sgn: &'a [f64],
    /// Current less the sensor offset [A], or the torque command on a torque plant.
    pub cur: &'a [f64],
}

/// A torque regressor: the torque per unit of one key, sample by sample.
pub type Regressor = fn(&TorqueSignals) -> Vec<f64>;

/// How an effect's torque enters the mechanical equation's linear regression.
#[derive(Clone, Copy)]
pub enum WeakTorque {
    /// Not linear in its keys (or no torque): left to the free-run refinement.
    None,
    /// Linear in these keys, one regressor each.
    PerKey(&'static [(&'static str, Regressor)]),
    /// `amp·cos(h·θ − phase)`: a sine and a cosine column of h·θ, h from [`Descriptor::harmonic`].
    Periodic,
    /// A lookup table: one hat-function column per node ([`table::columns`]).
    Table,
}

/// The column an electrical effect adds to the electrical equation's regression.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum VoltageColumn {
    /// `∫φ·sgn(I − i0)`.
    SignOfCurrent,
    /// `∫φ`.
    One,
}

/// An effect with a term in the electrical equation.
pub struct Voltage {
    pub column: VoltageColumn,
    /// The key the coefficient sets.
    pub key: &'static str,
    /// The key's value from the column's coefficient `x` [V] and the resistance `r` [Ω].
    pub value: fn(x: f64, r: f64) -> f64,
    /// Lowest value the residual regression of `fit --add` keeps.
    pub residual_floor: f64,
}

/// What an effect adds to the SINDYc library: terms with the equations they may appear in,
/// and the Stribeck velocity the library's Stribeck term uses, if the effect sets it.
pub struct SindyTerms {
    pub terms: Vec<(Term, [bool; 3])>,
    pub vs: Option<f64>,
}

/// Allowed in the acceleration equation only.
pub const IN_ACCEL: [bool; 3] = {
    let mut a = [false; 3];
    a[ACCEL] = true;
    a
};
/// Allowed in the current equation only.
pub const IN_CURRENT: [bool; 3] = [false, false, true];

/// Everything the host knows about one effect beside its equations.
pub struct Descriptor {
    pub kind: EffectKind,
    /// One line: what the effect is, physically.
    pub meaning: &'static str,
    /// The keys, in the order a spec prints them.
    pub keys: &'static [Key],
    /// `--help` text replacing the list of keys (for keys that come in a number).
    pub help: Option<&'static str>,
    /// Checks beyond each key's range (a whole number, an order of keys).
    pub check: fn(&EffectSpec) -> Result<()>,
    /// The effect with a spec's values (defaults where not given).
    pub to_effect: fn(&EffectSpec) -> Effect<f64>,
    /// An effect's keys and values.
    pub values: fn(&Effect<f64>) -> Vec<(&'static str, f64)>,
    /// The estimable keys with the bounds a fit keeps them in; structural keys (a harmonic,
    /// a table's variable) stay fixed.
    pub fit_keys: fn(&Effect<f64>) -> Vec<FitKey>,
    /// The effect with its magnitudes multiplied by `f` (a phase or time constant kept).
    pub scale: fn(&mut Effect<f64>, f: f64),
    /// Periods per revolution of an angle-periodic torque.
    pub harmonic: fn(&Effect<f64>) -> Option<f64>,
    /// Its torque in the mechanical equation's weak-form regression.
    pub weak_torque: WeakTorque,
    /// Its term in the electrical equation's regression.
    pub voltage: Option<Voltage>,
    /// Re-estimated on a fitted model's residual (`fit --add`), not only refined.
    pub on_residual: bool,
    /// Its SINDYc library terms, or why it has none.
    pub sindy: fn(&EffectSpec) -> Result<SindyTerms>,
    /// What `diagnose` tries and says about it.
    pub diagnose: Diagnose,
}

/// Sample-level columns, each with the equation it belongs to.
pub type Columns = Vec<(Equation, Vec<f64>)>;

/// What `diagnose` knows about an effect: the variants it tries when a model lacks the
/// effect, the columns that stand for it when the model has it, and how a variant's fitted
/// coefficients become the effect's keys.
pub struct Diagnose {
    /// The variants tried when the model lacks the effect, one per point of its grid over
    /// the keys that enter nonlinearly (a harmonic, a Stribeck velocity, a time constant);
    /// empty where the effect cannot show in these signals or is not a candidate.
    pub variants: fn(&Signals) -> Vec<Variant>,
    /// The columns that stand for the effect when the model has it (its nonlinear keys taken
    /// from the model), each in its equation.
    pub present: fn(&Effect<f64>, &Signals) -> Columns,
    /// The keys a variant's fitted coefficients `b` set (torque-equation ones in N·m; at
    /// least two, zero beyond the variant's columns), into `values` beside the variant's
    /// fixed keys.
    pub keys: fn(b: &[f64], units: Units, values: &mut BTreeMap<String, f64>),
    /// Names of its present columns in the base, where they have their own (else the
    /// effect's name, numbered when it has several).
    pub column_names: &'static [&'static str],
    /// Unit of a present column's coefficient in the torque equation.
    pub torque_unit: &'static str,
    /// Whether a finding's fitted keys are physical: a dissipation dissipates, a load has an
    /// inertia. An implausible best fit is not reported.
    pub plausible: fn(&EffectSpec) -> bool,
    /// What a finding means physically, as a clause for `diagnose`'s sentence (lower case).
    pub explain: fn(&EffectSpec) -> String,
}

/// Every descriptor, in [`EffectKind::ALL`]'s order.
pub static ALL: [&Descriptor; 16] = [
    &coulomb::D,
    &viscous::D,
    &stribeck::D,
    &presliding::D,
    &cogging::D,
    &position_load::D,
    &offset::D,
    &asymmetry::D,
    &deadtime::D,
    &current_offset::D,
    &thermal::D,
    &load_friction::D,
    &saturation::D,
    &compliance::D,
    &backlash::D,
    &table::D,
];

/// The descriptor of an effect kind.
pub fn of(kind: EffectKind) -> &'static Descriptor {
    ALL.iter()
        .copied()
        .find(|d| d.kind == kind)
        .expect("every kind has a descriptor")
}

/// The descriptor of an effect name (`position_load`), if it names one.
pub fn by_name(name: &str) -> Option<&'static Descriptor> {
    ALL.iter().copied().find(|d| d.kind.name() == name)
}

/// The number behind key `key` of an effect in any number type (the free runs' duals), if
/// it has one. A function pointer cannot be generic, so this one accessor dispatches here
/// to the effect's file.
pub fn key_mut<'a, D: num_traits::Float>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match e.kind() {
        EffectKind::Coulomb => coulomb::key_mut(e, key),
        EffectKind::Viscous => viscous::key_mut(e, key),
        EffectKind::Stribeck => stribeck::key_mut(e, key),
        EffectKind::Presliding => presliding::key_mut(e, key),
        EffectKind::Cogging => cogging::key_mut(e, key),
        EffectKind::PositionLoad => position_load::key_mut(e, key),
        EffectKind::Offset => offset::key_mut(e, key),
        EffectKind::Asymmetry => asymmetry::key_mut(e, key),
        EffectKind::Deadtime => deadtime::key_mut(e, key),
        EffectKind::CurrentOffset => current_offset::key_mut(e, key),
        EffectKind::Thermal => thermal::key_mut(e, key),
        EffectKind::LoadFriction => load_friction::key_mut(e, key),
        EffectKind::Saturation => saturation::key_mut(e, key),
        EffectKind::Compliance => compliance::key_mut(e, key),
        EffectKind::Backlash => backlash::key_mut(e, key),
        EffectKind::Table => table::key_mut(e, key),
    }
}

/// [`Descriptor::check`] of effects without checks beyond their keys' ranges.
pub(crate) fn no_check(_: &EffectSpec) -> Result<()> {
    Ok(())
}

/// [`Descriptor::harmonic`] of effects that are not periodic in angle.
pub(crate) fn not_periodic(_: &Effect<f64>) -> Option<f64> {
    None
}

/// [`Descriptor::sindy`] of effects whose terms the paper's library already has.
pub(crate) fn in_paper_library(_: &EffectSpec) -> Result<SindyTerms> {
    Ok(SindyTerms {
        terms: vec![],
        vs: None,
    })
}

/// [`Descriptor::sindy`] of effects the library has no term for.
pub(crate) fn no_sindy_term(spec: &EffectSpec) -> Result<SindyTerms> {
    anyhow::bail!(
        "--add {}: a SINDYc library has no term for it; fit --model lugre --add {}",
        spec.kind.name(),
        spec
    )
}

/// [`Diagnose::variants`] of effects `diagnose` does not try by themselves.
pub(crate) fn no_variants(_: &Signals) -> Vec<Variant> {
    vec![]
}

/// [`Diagnose::present`] of effects without a column of their own in the base.
pub(crate) fn no_columns(_: &Effect<f64>, _: &Signals) -> Columns {
    vec![]
}

/// [`Diagnose::keys`] of effects whose keys all come from the variant's grid.
pub(crate) fn no_keys(_: &[f64], _: Units, _: &mut BTreeMap<String, f64>) {}

/// [`Diagnose::plausible`] of effects whose every fitted value is physical.
pub(crate) fn always_plausible(_: &EffectSpec) -> bool {
    true
}

/// [`Diagnose::keys`] helper: set `key` to `x`.
pub(crate) fn put(values: &mut BTreeMap<String, f64>, key: &str, x: f64) {
    values.insert(key.to_string(), x);
}

/// SINDYc terms without a Stribeck velocity.
pub(crate) fn terms(t: &[(Term, [bool; 3])]) -> Result<SindyTerms> {
    Ok(SindyTerms {
        terms: t.to_vec(),
        vs: None,
    })
}

/// Regressor: the smooth sign of the velocity (a Coulomb-like torque).
pub(crate) fn sign_of_velocity(s: &TorqueSignals) -> Vec<f64> {
    s.sgn.to_vec()
}

/// The table variable's code in a spec (`var` = index in [`TableVar::ALL`]).
pub(crate) fn table_var_code(var: TableVar) -> f64 {
    TableVar::ALL.iter().position(|x| *x == var).unwrap_or(0) as f64
}

/// Effects, or `diagnose`'s carrier variables (`theta`, `omega`, `reversal`, ...), that one
/// log can leave looking alike, and an experiment in which they differ.
pub struct LookAlikes {
    /// The pairs this experiment separates, in either order; `"*"` pairs an effect with
    /// anything no other row pairs it with.
    pub pairs: &'static [(&'static str, &'static str)],
    /// The experiment (a log to record or simulate) and what tells them apart there.
    pub experiment: &'static str,
}

/// Every look-alike pair with the experiment that separates it (see decision 0025 for why a
/// table names both sides rather than one effect's file holding the pair).
#[rustfmt::skip]
pub static LOOK_ALIKES: &[LookAlikes] = &[
    LookAlikes {
        pairs: &[("offset", "asymmetry")],
        experiment: "none of a turning rotor: while it turns, a constant load and a Coulomb friction that differs by direction are one torque, of one sign and size at every speed either way. A viscous part that differs by direction grows with speed, which a constant load does not: constant voltages over a wide speed range each way separate it (`motorid simulate --signal speeds`, or `motorid record --signal speeds`). The Coulomb part shows only at breakaway: in slow ramps from rest each way (signal ramp) a constant load t0 raises the voltage at which the rotor first moves one way and lowers it the other way, by R·t0/K_t each, while a friction that differs by direction leaves the two equal; `diagnose` does not fit breakaway, so read the two voltages in the log. A load that can be disengaged, or a torque sensor, tells them apart directly",
    },
    LookAlikes {
        pairs: &[("load_friction", "deadtime")],
        experiment: "voltage steps of either sign, many of them down while the rotor turns fast (signal d, three minutes or more): dead time is a voltage loss of one size at every current, following the sign of the current, and shows in the current's own equation (on any log whose current changes sign, signal a too); load friction is a torque in proportion to the current against the motion, which differs from a lower torque constant only while the drive brakes the rotor, right after the steps down",
    },
    LookAlikes {
        pairs: &[("load_friction", "saturation")],
        experiment: "voltage steps to several levels, from rest and braking from speed, over several minutes (signal d): a saturating torque constant loses torque as the cube of the current, nothing at low current and fast growing at high current, whether the drive motors or brakes; friction growing with the transmitted torque takes the same share of it at every level, and only against the motion; a torque constant off by a constant share loses the same share at every level and is taken by a refit",
    },
    LookAlikes {
        pairs: &[("cogging", "position_load"), ("cogging", "theta")],
        experiment: "constant speeds over several revolutions (`motorid simulate --signal speeds` or steady, or any log that turns several revolutions each way): count the periods of the torque error per revolution (one: a position load; the number of magnet or slot periods: cogging); a shape over one revolution that neither fits stays with the angle (`table:var=theta` fits it)",
    },
    LookAlikes {
        pairs: &[("stribeck", "presliding"), ("presliding", "reversal")],
        experiment: "slow ramps from rest each way (signal ramp) against constant low speeds (signal speeds): presliding is a deflection that follows the voltage before breakaway, a Stribeck dip is friction falling with speed across the low constant levels. A deflection shows in a motor log only when it spans a Hall step or more (breakaway torque over bristle stiffness, against 2π/(6·pole pairs)); a smaller one needs a finer encoder",
    },
    LookAlikes {
        pairs: &[("coulomb", "stribeck"), ("coulomb", "viscous"), ("viscous", "stribeck"), ("stribeck", "omega")],
        experiment: "constant speeds at many levels, low and high, each way (`motorid simulate --signal speeds`, or `motorid record --signal speeds`): the friction at each speed separates a constant (Coulomb), a dip at low speed (Stribeck) and a slope (viscous). Signal steady spans too narrow a range of speeds (2-5 rad/s on the paper's motor) for the slope",
    },
    LookAlikes {
        pairs: &[("current_offset", "offset"), ("current_offset", "deadtime")],
        experiment: "rests at zero voltage with the rotor still (signal ramp rests 1 s before each of its ramps): a current-sensor offset reads a current where none flows; a load torque or a dead time leaves the current at zero there",
    },
    LookAlikes {
        pairs: &[("thermal", "time"), ("thermal", "*")],
        experiment: "minutes of large current (signal d), a rest at zero voltage of several thermal time constants, then the same signal again (two records): heating follows the mean square of the current with its time constant and cools during the rest, so the resistance starts near cold again when the steps resume; wear, a supply sag or a sensor drift goes on with time. The rest itself measures nothing: the resistance shows only while current flows",
    },
    LookAlikes {
        pairs: &[("backlash", "compliance")],
        experiment: "voltage steps (signal d): a compliant coupling rings at one frequency after every step, whatever its direction; a gap shows only where the torque on the load changes sign (a step down brakes the rotor, a reversal of the drive): the rotor crosses the gap with its own inertia, then takes up the load with a knock. Slow ramps (signal ramp) show neither: at low speed friction, not inertia, carries the torque. A second encoder on the load side separates them directly",
    },
    LookAlikes {
        pairs: &[("reversal", "frequency")],
        experiment: "voltage steps (signal d): a resonance rings at one frequency after every step, whether or not the step reverses the rotor; what a velocity reversal carries (a gap, presliding) appears only after the steps that reverse it. Compare the residual after steps that keep the direction with that after reversals: ringing after both is a resonance, a disturbance after reversals only is a gap or presliding",
    },
    LookAlikes {
        pairs: &[("acceleration", "current"), ("saturation", "acceleration")],
        experiment: "voltage steps of several sizes (signal d): on a free rotor a large current comes with a large acceleration, so only the shape tells them apart: a torque constant that falls with current loses torque as the cube of the current (nothing on small steps), an inertia error in proportion to the acceleration on every step. A locked rotor shows neither in a motor log, which does not measure torque; a torque sensor on the locked shaft measures the torque constant at each current directly",
    },
    LookAlikes {
        pairs: &[("viscous", "asymmetry")],
        experiment: "constant speeds over a wide range each way (`motorid simulate --signal speeds`, or `motorid record --signal speeds`): the friction curve of each direction on its own; a slope equal both ways is viscous friction, a slope or level that differs by direction is asymmetry",
    },
];

/// The experiment of [`LOOK_ALIKES`] that tells `a` from `b` (either order): a row naming
/// both, else a row pairing either with `"*"`.
pub fn experiment(a: &str, b: &str) -> Option<&'static str> {
    let both = |(x, y): &(&str, &str)| (a == *x && b == *y) || (a == *y && b == *x);
    let any = |(x, y): &(&str, &str)| *y == "*" && (a == *x || b == *x);
    let row =
        |m: &dyn Fn(&(&str, &str)) -> bool| LOOK_ALIKES.iter().find(|r| r.pairs.iter().any(m));
    row(&both).or_else(|| row(&any)).map(|r| r.experiment)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_registry_has_every_kind_once_in_order() {
        for (d, kind) in ALL.iter().zip(EffectKind::ALL) {
            assert_eq!(d.kind, kind);
            assert!(std::ptr::eq(of(kind), *d));
            assert!(std::ptr::eq(by_name(kind.name()).unwrap(), *d));
            assert!(!d.meaning.is_empty() && !d.keys.is_empty());
        }
        assert!(by_name("gravity").is_none());
    }

    /// Every name of the look-alike table is an effect or a carrier variable, and no pair
    /// is listed twice (in either order), so the row found does not depend on the order.
    #[test]
    fn look_alike_pairs_name_effects_or_carriers_once() {
        let carriers = [
            "theta",
            "omega",
            "acceleration",
            "current",
            "time",
            "reversal",
            "frequency",
        ];
        let known = |n: &str| by_name(n).is_some() || carriers.contains(&n) || n == "*";
        let mut seen = Vec::new();
        for row in LOOK_ALIKES {
            assert!(!row.experiment.is_empty());
            for &(a, b) in row.pairs {
                assert!(known(a) && known(b) && a != "*", "{a}, {b}");
                let key = if a < b { (a, b) } else { (b, a) };
                assert!(!seen.contains(&key), "{a}, {b} twice");
                seen.push(key);
                assert_eq!(experiment(a, b), Some(row.experiment));
                assert_eq!(experiment(b, a), Some(row.experiment));
            }
        }
        assert!(experiment("cogging", "offset").is_none());
    }

    #[test]
    fn values_name_keys_and_key_mut_reaches_each_estimable_key() {
        for d in ALL {
            let mut e = (d.to_effect)(&EffectSpec::bare(d.kind));
            for (key, _) in (d.values)(&e) {
                assert!(d.keys.iter().any(|k| k.name == key), "{key}");
            }
            let values = (d.values)(&e);
            for (key, _, _) in (d.fit_keys)(&e.clone()) {
                let want = values.iter().find(|(k, _)| *k == key).map(|(_, v)| *v);
                assert_eq!(
                    key_mut(&mut e, key).map(|v| *v),
                    want,
                    "{}.{key}",
                    d.kind.name()
                );
            }
        }
    }
}
