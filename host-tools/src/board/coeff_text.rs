//! The coefficients as text for firmware not written in Rust: a JSON object and a C header.
//!
//! Both are made from one flat list of the [`Coefficients`] leaves ([`leaves`]): each number
//! under its dotted path (`motor.r`, `effects.0.coulomb.fc`, `hall_table.3`) with its unit.
//! Units are the blob's, rotary SI (for a linear axis read rad as m and N·m as N). The JSON
//! also carries the [`Coefficients`] object itself, which reads back into the same values,
//! and the blob's byte layout.
use crate::effect_spec::EffectSpec;
use anyhow::Result;
use control::blob::{self, Coefficients};
use serde_json::{json, Value};

/// One number or name of the coefficients.
#[derive(Debug, Clone, PartialEq)]
pub struct Leaf {
    /// Dotted path, lower case: `motor.r`, `effects.0.coulomb.fc`.
    pub path: String,
    /// The value (a number, a bool or an enum variant's name).
    pub value: Value,
    /// Its unit, "" where it has none (counts, flags, table entries).
    pub unit: &'static str,
}

/// Units of the fixed fields, by dotted path.
const UNITS: &[(&str, &str)] = &[
    ("motor.r", "ohm"),
    ("motor.l", "H"),
    ("motor.kt", "N·m/A"),
    ("motor.kb", "V·s/rad"),
    ("motor.j", "kg·m²"),
    ("lugre.alpha0", "N·m"),
    ("lugre.alpha1", "N·m"),
    ("lugre.alpha2", "N·m·s/rad"),
    ("lugre.v0", "rad/s"),
    ("lugre.sigma0", "N·m/rad"),
    ("lugre.sigma1", "N·m·s/rad"),
    ("sindy.a", "s/rad"),
    ("sindy.vs", "rad/s"),
    ("sindy.j", "kg·m²"),
    ("estimator.movingaverage.window", "samples"),
    ("estimator.edgetiming.timeout_s", "s"),
    ("pi.kp", "V/(rad/s)"),
    ("pi.ki", "V/rad"),
    ("pi.u_max", "V"),
    ("pi.comp_gain", "1"),
    ("limits.i_max", "A"),
    ("limits.vbus_min", "V"),
    ("limits.vbus_max", "V"),
];

/// The coefficients as serde sees them, each f32 in its shortest decimal form.
fn as_json(co: &Coefficients) -> Result<Value> {
    // Through text so that 0.01f32 stays 0.01 and not 0.009999999776.
    Ok(serde_json::from_str(&serde_json::to_string(co)?)?)
}

/// Every leaf of the coefficients, in field order (absent parts, such as `lugre` of a
/// linear model, are left out).
pub fn leaves(co: &Coefficients) -> Result<Vec<Leaf>> {
    let specs: Vec<EffectSpec> = crate::cmd::inspect::effect_specs(co);
    let mut out = Vec::new();
    walk(&as_json(co)?, String::new(), &specs, &mut out);
    Ok(out)
}

fn walk(v: &Value, path: String, specs: &[EffectSpec], out: &mut Vec<Leaf>) {
    let join = |k: &str| {
        let k = k.to_ascii_lowercase();
        if path.is_empty() {
            k
        } else {
            format!("{path}.{k}")
        }
    };
    match v {
        Value::Null => {}
        Value::Object(m) => {
            for (k, v) in m {
                walk(v, join(k), specs, out);
            }
        }
        Value::Array(a) => {
            for (k, v) in a.iter().enumerate() {
                walk(v, join(&k.to_string()), specs, out);
            }
        }
        leaf => {
            let unit = unit_of(&path, specs);
            out.push(Leaf {
                path,
                value: leaf.clone(),
                unit,
            });
        }
    }
}

/// The unit of a leaf: the fixed table, or an effect key's unit from [`crate::effects::Descriptor::keys`].
fn unit_of(path: &str, specs: &[EffectSpec]) -> &'static str {
    if let Some((_, u)) = UNITS.iter().find(|(p, _)| *p == path) {
        return u;
    }
    let parts: Vec<&str> = path.split('.').collect();
    if let ["effects", k, _, key] = parts[..] {
        if let Some(spec) = k.parse::<usize>().ok().and_then(|k| specs.get(k)) {
            if let Some(key) = crate::effects::of(spec.kind)
                .keys
                .iter()
                .find(|x| x.name == key)
            {
                return key.unit;
            }
        }
    }
    ""
}

/// The blob's byte layout: `[(offset, size, field)]` for a payload of `payload` bytes.
fn layout(payload: usize) -> Value {
    let h = blob::HEADER_LEN;
    json!([
        {"offset": 0, "size": 4, "field": "magic", "value": "MIDC"},
        {"offset": 4, "size": 2, "field": "format version, u16 little-endian"},
        {"offset": 6, "size": 2, "field": "payload length, u16 little-endian"},
        {"offset": h, "size": payload, "field": "postcard encoding of the coefficients"},
        {"offset": h + payload, "size": blob::CRC_LEN,
         "field": "CRC-32/ISO-HDLC of all bytes before it, u32 little-endian"},
    ])
}

/// The JSON export: `{"model", "source", "parameters": [{"name", "value", "unit"}],
/// "effects": [{"name", "spec"}], "coefficients": {...}, "blob": {"version", "bytes",
/// "crc32", "layout": [...]}}`. `coefficients` deserializes back into [`Coefficients`].
pub fn to_json(co: &Coefficients, source: &str, blob_bytes: &[u8]) -> Result<Value> {
    let parameters: Vec<Value> = leaves(co)?
        .into_iter()
        .map(|l| json!({"name": l.path, "value": l.value, "unit": l.unit}))
        .collect();
    let effects: Vec<Value> = crate::cmd::inspect::effect_specs(co)
        .iter()
        .map(|s| json!({"name": s.kind.name(), "spec": s.to_string()}))
        .collect();
    let n = blob_bytes.len();
    let crc = blob_bytes
        .get(n.saturating_sub(4)..)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map(u32::from_le_bytes)
        .unwrap_or(0);
    Ok(json!({
        "model": crate::cmd::inspect::kind_name(co.model),
        "source": source,
        "units": "rotary SI; for a linear axis read rad as m and N·m as N",
        "parameters": parameters,
        "effects": effects,
        "coefficients": as_json(co)?,
        "blob": {
            "version": blob::VERSION,
            "bytes": n,
            "crc32": format!("{crc:08x}"),
            "layout": layout(n.saturating_sub(blob::HEADER_LEN + blob::CRC_LEN)),
        },
    }))
}

/// A C identifier from a dotted path: `MOTORID_MOTOR_R`.
fn c_name(path: &str) -> String {
    let mut s = String::from("MOTORID_");
    for c in path.chars() {
        s.push(if c.is_ascii_alphanumeric() {
            c.to_ascii_uppercase()
        } else {
            '_'
        });
    }
    s
}

/// The C header export: one `#define` per leaf with its unit in a comment (floats with an
/// `f` suffix, enum variants as strings), the effects' specs, and the blob's layout.
pub fn to_c_header(co: &Coefficients, source: &str) -> Result<String> {
    use std::fmt::Write;
    let mut s = String::new();
    let clean = |t: &str| t.replace("*/", "* /");
    let _ = writeln!(
        s,
        "/* Motor model coefficients written by motorid export from {}.\n * \
         Model: {}. Units: rotary SI (for a linear axis read rad as m and N·m as N). */",
        clean(&crate::log::echo(source)),
        crate::cmd::inspect::kind_name(co.model)
    );
    s.push_str("#ifndef MOTORID_COEFFICIENTS_H\n#define MOTORID_COEFFICIENTS_H\n\n");
    let _ = writeln!(
        s,
        "#define MOTORID_MODEL \"{}\"",
        crate::cmd::inspect::kind_name(co.model)
    );
    let _ = writeln!(s, "#define MOTORID_EFFECT_COUNT {}", co.effects.len());
    for (k, spec) in crate::cmd::inspect::effect_specs(co).iter().enumerate() {
        let _ = writeln!(s, "/* effect {k}: {} */", clean(&spec.to_string()));
    }
    s.push('\n');
    for l in leaves(co)? {
        if l.path == "model" {
            continue;
        }
        let value = match &l.value {
            Value::Number(n) if n.is_f64() => {
                let f = n.as_f64().unwrap_or(0.0);
                let text = format!("{f:?}");
                if text.contains(['.', 'e', 'E']) {
                    format!("{text}f")
                } else {
                    format!("{text}.0f")
                }
            }
            Value::Number(n) => n.to_string(),
            Value::Bool(b) => u8::from(*b).to_string(),
            Value::String(v) => format!("\"{}\"", v.replace(['"', '\\'], "")),
            _ => continue,
        };
        let unit = if l.unit.is_empty() {
            String::new()
        } else {
            format!(" /* [{}] */", l.unit)
        };
        let _ = writeln!(s, "#define {} {value}{unit}", c_name(&l.path));
    }
    let _ = write!(
        s,
        "\n/* Blob layout (little-endian): magic \"MIDC\" (4 bytes), format version (u16), \
         payload length n (u16),\n * n bytes of postcard-encoded coefficients, CRC-32/ISO-HDLC \
         of the bytes before it (u32). */\n#define MOTORID_BLOB_VERSION {}\n\
         #define MOTORID_BLOB_HEADER_LEN {}\n#define MOTORID_BLOB_CRC_LEN {}\n\n\
         #endif /* MOTORID_COEFFICIENTS_H */\n",
        blob::VERSION,
        blob::HEADER_LEN,
        blob::CRC_LEN
    );
    Ok(s)
}
