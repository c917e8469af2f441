//! `table`: a smooth lookup table of torque over θ, ω or I, for physics without a name.
use super::*;
use control::effects::table_nodes;

/// The keys of a `table`: the variable, the number of nodes, the range of ω or I the nodes
/// span (set from the data by `fit`), then the torque at each node.
#[rustfmt::skip]
const KEYS: &[Key] = &[
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
const _: () = assert!(KEYS.len() == 4 + TABLE_MAX_BINS);

/// The name of the torque at node `k` of a table (`b0`, `b1`, ...).
pub fn table_value_key(k: usize) -> &'static str {
    KEYS[4 + k.min(TABLE_MAX_BINS - 1)].name
}

/// `var` and `bins` whole, no node key beyond `bins`, `lo` below `hi`.
fn check(s: &EffectSpec) -> Result<()> {
    let whole = |key: &str| s.values.get(key).is_none_or(|v| v.fract() == 0.0);
    if !whole("var") || !whole("bins") {
        anyhow::bail!("effect 'table': var and bins must be whole (var one of theta, omega, current; bins 2 to {TABLE_MAX_BINS})");
    }
    let bins = s.get("bins") as usize;
    if let Some(k) = (bins..TABLE_MAX_BINS).find(|&k| s.values.contains_key(table_value_key(k))) {
        anyhow::bail!(
            "effect 'table': key '{}' is beyond the table's {bins} bins (b0 to b{})",
            table_value_key(k),
            bins - 1
        );
    }
    if let (Some(lo), Some(hi)) = (s.values.get("lo"), s.values.get("hi")) {
        if lo >= hi {
            anyhow::bail!(
                "effect 'table': lo ({}) must be below hi ({})",
                crate::validate::show(*lo),
                crate::validate::show(*hi)
            );
        }
    }
    Ok(())
}

fn to_effect(s: &EffectSpec) -> Effect<f64> {
    let bins = s.get("bins").round().clamp(2.0, TABLE_MAX_BINS as f64) as u8;
    let mut values = [0.0; TABLE_MAX_BINS];
    for (k, v) in values.iter_mut().enumerate().take(bins as usize) {
        *v = s.get(table_value_key(k));
    }
    Effect::Table {
        var: s.table_var(),
        bins,
        lo: s.get("lo"),
        hi: s.get("hi"),
        values,
    }
}

/// The keys of a table: a θ table over one revolution (no stroke) prints no range.
fn values(e: &Effect<f64>) -> Vec<(&'static str, f64)> {
    let Effect::Table {
        var,
        bins,
        lo,
        hi,
        values: ref v,
    } = *e
    else {
        return vec![];
    };
    let mut out = vec![("var", table_var_code(var)), ("bins", bins as f64)];
    if var != TableVar::Theta || hi > lo {
        out.push(("lo", lo));
        out.push(("hi", hi));
    }
    for (k, x) in v.iter().enumerate().take(bins as usize) {
        out.push((table_value_key(k), *x));
    }
    out
}

/// The node torques `b0..b<bins-1>`, ± 10 N·m as an offset.
fn fit_keys(e: &Effect<f64>) -> Vec<FitKey> {
    match *e {
        Effect::Table { bins, .. } => (0..bins as usize)
            .map(|k| (table_value_key(k), -10.0, 10.0))
            .collect(),
        _ => vec![],
    }
}

/// The hat functions of a table's nodes on one log: column k is `h_k(x)` (see
/// [`control::effects::table_nodes`]), x the table's variable (θ, the smoothed velocity
/// `ws`, or the current `cur`).
pub fn columns(e: &Effect<f64>, theta: &[f64], ws: &[f64], cur: &[f64]) -> Vec<Vec<f64>> {
    let Effect::Table {
        var, bins, lo, hi, ..
    } = *e
    else {
        return vec![];
    };
    let x = match var {
        TableVar::Theta => theta,
        TableVar::Omega => ws,
        TableVar::Current => cur,
    };
    let mut cols = vec![vec![0.0; x.len()]; bins as usize];
    for (k, &v) in x.iter().enumerate() {
        let (k0, k1, w) = table_nodes(var, bins, lo, hi, v);
        cols[k0][k] += 1.0 - w;
        cols[k1][k] += w;
    }
    cols
}

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Table,
    meaning: "a smooth lookup table of torque over angle, velocity or current",
    keys: KEYS,
    help: Some(
        "var=theta|omega|current; bins=8 [2 to 16] nodes; \
         lo, hi [rad, rad/s or A] range the nodes span (omega, current: fit takes it \
         from the data; theta: the stroke of a linear axis, clamped at its ends); \
         b0..b<bins-1> [N·m] torque at each node (theta without lo, hi: one \
         revolution, periodic)",
    ),
    check,
    to_effect,
    values,
    fit_keys,
    scale: |e, f| {
        if let Effect::Table { values, .. } = e {
            values.iter_mut().for_each(|v| *v *= f)
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::Table,
    voltage: None,
    on_residual: false,
    sindy: no_sindy_term,
    // Not a named physics: `diagnose` offers a table where an `unexplained` carrier (θ, ω,
    // I) holds structure no named effect explains (`diagnose/carriers.rs`).
    diagnose: Diagnose {
        variants: no_variants,
        // The model's table stands in the torque equation's base as its node columns, so
        // that what it explains is not left to the carriers (a table over θ would
        // otherwise still be found carried by θ once added).
        present: |e, s| {
            let cur = s.i.as_deref().unwrap_or(&s.drive);
            columns(e, &s.theta_s, &s.omega, cur)
                .into_iter()
                .map(|c| (Equation::Mechanical, c))
                .collect()
        },
        keys: no_keys,
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "a torque that depends on {} as the fitted lookup table describes",
                s.table_var().name()
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Table { lo, .. }, "lo") => Some(lo),
        (Effect::Table { hi, .. }, "hi") => Some(hi),
        (Effect::Table { bins, values, .. }, k) => {
            let i: usize = k.strip_prefix('b')?.parse().ok()?;
            if i >= *bins as usize {
                return None;
            }
            values.get_mut(i)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The help text states the number of nodes the board holds.
    #[test]
    fn help_names_the_most_bins() {
        let help = D.help.unwrap();
        assert!(help.contains(&format!("[2 to {TABLE_MAX_BINS}]")), "{help}");
    }
}
