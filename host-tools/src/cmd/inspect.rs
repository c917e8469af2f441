//! `motorid inspect`: validate and decode a coefficient blob.
use crate::board::coeffs;
use crate::effect_spec::EffectSpec;
use anyhow::Result;
use control::blob::{self, Coefficients};
use serde_json::json;
use std::path::PathBuf;

/// Validate a coefficient blob (magic, version, length, CRC-32, values) and show what it
/// holds: model kind, effects, every coefficient. A corrupted or truncated blob is an error.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The blob (written by `motorid export`).
    pub blob: PathBuf,
    /// Print one JSON object: {"file", "bytes", "version", "crc32", "model", "effects":
    /// [{"name", "spec"}], "coefficients": {...}}.
    #[arg(long)]
    pub json: bool,
}

/// Model kind as the command line names it.
pub fn kind_name(k: blob::ModelKind) -> &'static str {
    match k {
        blob::ModelKind::None => "none",
        blob::ModelKind::Linear => "linear",
        blob::ModelKind::Lugre => "lugre",
        blob::ModelKind::Sindyc => "sindyc",
    }
}

/// An f32 as the f64 of its shortest decimal form (0.01f32 → 0.01, not 0.009999999776).
pub fn f32_shortest(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// The blob's effects as `diagnose`-style specs.
pub fn effect_specs(co: &Coefficients) -> Vec<EffectSpec> {
    co.effects
        .iter()
        .map(|e| EffectSpec::from_effect(&e.map(f32_shortest)))
        .collect()
}

/// The JSON object `inspect --json` prints.
/// The format version in a (decoded, so well-formed) blob's header: 1, 2 or 3, see
/// [`blob::VERSION`].
fn format_version(bytes: &[u8]) -> u16 {
    bytes
        .get(4..6)
        .map_or(blob::VERSION, |b| u16::from_le_bytes([b[0], b[1]]))
}

pub fn to_json(file: &str, bytes: &[u8], co: &Coefficients) -> Result<serde_json::Value> {
    let crc = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into()?);
    let effects: Vec<_> = effect_specs(co)
        .iter()
        .map(|s| json!({"name": s.kind.name(), "spec": s.to_string()}))
        .collect();
    Ok(json!({
        "file": file,
        "bytes": bytes.len(),
        "version": format_version(bytes),
        "crc32": format!("{crc:08x}"),
        "model": kind_name(co.model),
        "effects": effects,
        // Through text so that each f32 keeps its shortest decimal form.
        "derived_limits": derived_limits(co),
        "coefficients": serde_json::from_str::<serde_json::Value>(&serde_json::to_string(co)?)?,
    }))
}

pub fn run(args: Args) -> Result<()> {
    let (bytes, co) = coeffs::decode_file(&args.blob)?;
    let file = args.blob.display().to_string();
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&to_json(&file, &bytes, &co)?)?
        );
        return Ok(());
    }
    let m = &co.motor;
    println!(
        "{file}: valid coefficient blob, format version {}, {} bytes",
        format_version(&bytes),
        bytes.len()
    );
    println!("model:      {}", kind_name(co.model));
    println!(
        "motor:      R = {} Ω, L = {} H, Kt = {} N·m/A, Kb = {} V·s/rad, J = {} kg·m² ({})",
        m.r,
        m.l,
        m.kt,
        m.kb,
        m.j,
        if co.motor_identified {
            "identified"
        } else {
            "defaults, not identified: the board refuses speed mode"
        }
    );
    if let Some(l) = &co.lugre {
        println!(
            "lugre:      α0 = {} N·m, α1 = {} N·m, α2 = {} N·m·s/rad, v0 = {} rad/s, σ0 = {} N·m/rad, σ1 = {} N·m·s/rad",
            l.alpha0, l.alpha1, l.alpha2, l.v0, l.sigma0, l.sigma1
        );
    }
    if let Some(s) = &co.sindy {
        println!(
            "sindyc:     a = {}, vs = {} rad/s, J = {} kg·m², terms: {} (dω/dt), {} (dz/dt), {} (dI/dt)",
            s.a,
            s.vs,
            s.j,
            s.accel.terms.len(),
            s.zdot.terms.len(),
            s.idot.terms.len()
        );
    }
    let specs = effect_specs(&co);
    if specs.is_empty() {
        println!("effects:    none");
    }
    for s in specs {
        // The control step compensates torques on the rotor; a load behind a coupling is a
        // state of the plant it does not simulate (its torque term is zero there).
        let note = match s.kind {
            control::effects::EffectKind::Compliance | control::effects::EffectKind::Backlash => {
                "  (carried, not compensated: the board has no load state)"
            }
            _ => "",
        };
        println!("effect:     {s}{note}");
    }
    println!(
        "hall:       {} pole pairs, table {:?}; velocity estimator {:?}",
        co.pole_pairs, co.hall_table, co.estimator
    );
    println!(
        "loop:       kp = {} V/(rad/s), ki = {} V/rad, u_max = {} V, compensation gain {}",
        co.pi.kp, co.pi.ki, co.pi.u_max, co.pi.comp_gain
    );
    let d = derived_limits(&co);
    println!(
        "limits:     i_max = {} A (current held below {} A), bus {}..{} V; speed reference \
         at most {} rad/s, ramped at {} rad/s²",
        co.limits.i_max,
        d.current_limit_a,
        co.limits.vbus_min,
        co.limits.vbus_max,
        d.speed_limit_rad_s,
        d.ramp_rad_s2
    );
    Ok(())
}

/// What the board derives from the blob's limits and motor constants (`control::blob`):
/// the standing current limit, the largest speed reference at the highest allowed bus
/// voltage, and the speed reference's ramp.
#[derive(serde::Serialize)]
struct DerivedLimits {
    /// `DERATE_FRACTION·i_max` [A].
    current_limit_a: f32,
    /// `min(u_max, MAX_DUTY·vbus_max)/K_b`, capped by the Hall capture rate [rad/s].
    speed_limit_rad_s: f32,
    /// Acceleration of the speed reference at that current limit [rad/s²].
    ramp_rad_s2: f32,
}

fn derived_limits(co: &Coefficients) -> DerivedLimits {
    let current_limit_a = blob::DERATE_FRACTION * co.limits.i_max;
    DerivedLimits {
        current_limit_a,
        speed_limit_rad_s: co.speed_limit(co.limits.vbus_max),
        ramp_rad_s2: co.ramp_acceleration(current_limit_a),
    }
}
