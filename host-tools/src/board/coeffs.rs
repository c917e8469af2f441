//! From an identified model (MODEL.toml) to the coefficient blob's [`Coefficients`] and its
//! bytes. The control step's configuration comes from `Coefficients::step_config`, the
//! same call the firmware makes after loading a blob.
use crate::model::{Model, ModelKind};
use anyhow::{anyhow, bail, Result};
use control::blob::{self, Coefficients, Estimator, PiGains};
use control::effects::Effect;
use control::lugre::LugreParams;
use control::motor::MotorParams;
use control::sindy::{SindyModel, SparseEq, Term};

/// Loop settings `motorid export` writes next to the model (the blob carries them so that the
/// board and its emulator run the same loop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    /// PI proportional gain [V/(rad/s)].
    pub kp: f32,
    /// PI integral gain [V/rad].
    pub ki: f32,
    /// PI output limit [V].
    pub u_max: f32,
    /// Weight of the compensation voltage, 0..=1 (1 = the paper's eq. 40, 0 = off, values
    /// between scale it).
    pub comp_gain: f32,
    /// Velocity estimator: `None` = the model's moving average (the paper's, window from
    /// MODEL.toml), `Some(timeout)` = Hall-edge timing with this standstill timeout [s].
    pub edge_timing: Option<f32>,
}

impl Default for LoopSettings {
    /// The gains of `control::step::StepConfig::paper()` (kp = 0.05 V/(rad/s), ki = 0.8 V/rad,
    /// see there why), 24 V limit (the paper's motor is a 24 V motor), full compensation.
    fn default() -> Self {
        LoopSettings {
            kp: 0.05,
            ki: 0.8,
            u_max: 24.0,
            comp_gain: 1.0,
            edge_timing: None,
        }
    }
}

fn eq_f32(e: &SparseEq<f64>) -> SparseEq<f32> {
    let terms: Vec<_> = e.terms.iter().map(|&(t, k)| (t, k as f32)).collect();
    SparseEq::from_slice(&terms).unwrap_or_else(SparseEq::new)
}

/// The SINDYc model in single precision (the board's).
pub fn sindy_f32(m: &SindyModel<f64>) -> SindyModel<f32> {
    let c = |x: f64| x as f32;
    SindyModel {
        a: c(m.a),
        vs: c(m.vs),
        j: c(m.j),
        z_max: c(m.z_max),
        accel: eq_f32(&m.accel),
        zdot: eq_f32(&m.zdot),
        idot: eq_f32(&m.idot),
    }
}

/// The model's SINDYc equations as the control core reads them (the `[sindy]` table that
/// `ident::sindyc` writes).
pub fn sindy_model(model: &Model) -> Result<SindyModel<f64>> {
    let table = model
        .sindy
        .as_ref()
        .ok_or_else(|| anyhow!("field 'sindy': a model of kind 'sindyc' needs a [sindy] table"))?;
    crate::ident::sindyc::from_table(table)
        .map(|(m, _)| m)
        .map_err(|e| anyhow!("field 'sindy': {e}"))
}

/// Pole pairs of the model's motor: given, or from the Hall resolution 2π/(6·p), or the
/// paper's 11 (its 0.095 rad resolution).
pub fn pole_pairs(model: &Model) -> u8 {
    if let Some(p) = model.sensor.pole_pairs {
        return p.clamp(1, 255) as u8;
    }
    let res = model.sensor.hall_resolution_rad;
    if res > 0.0 && res.is_finite() {
        let p = (std::f64::consts::TAU / (6.0 * res)).round();
        if (1.0..=255.0).contains(&p) {
            return p as u8;
        }
    }
    control::hall::PAPER_POLE_PAIRS as u8
}

/// What the board needs of a model beyond [`Model::validate`], each failure naming the
/// MODEL.toml field: a voltage plant with a back-EMF constant (the observer divides by it),
/// every number representable in the board's `f32`, and a breakaway friction the board can
/// overcome: `(α0 + α1)/K_t` (LuGre) or `F_c/K_t` (a Coulomb effect) at most the board's
/// rated current [`blob::RATED_I_MAX`].
pub fn board_check(model: &Model) -> Result<()> {
    if model.plant != crate::log::Plant::Voltage {
        bail!(
            "field 'plant': only voltage-driven models can go to the board (this one is '{}')",
            "torque"
        );
    }
    let m = &model.motor;
    if m.kb <= 0.0 {
        bail!(
            "field 'motor.kb': the board needs a positive back-EMF constant (got {})",
            crate::validate::show(m.kb)
        );
    }
    let rated = f64::from(blob::RATED_I_MAX);
    let current = |name: &str, friction: f64| -> Result<()> {
        let amps = friction.abs() / m.kt;
        if amps > rated {
            bail!(
                "field '{name}': a friction of {} N·m needs {} A at K_t = {} N·m/A, above the \
                 board's rated {rated} A",
                crate::validate::show(friction),
                crate::validate::show(amps),
                crate::validate::show(m.kt)
            );
        }
        Ok(())
    };
    if let Some(l) = &model.lugre {
        current("lugre.alpha0", l.alpha0 + l.alpha1.max(0.0))?;
    }
    for e in &model.effects {
        if let Effect::Coulomb { fc } = e {
            current("effects.coulomb.fc", *fc)?;
        }
    }
    if let Some(s) = &model.sindy {
        let (sm, _) = crate::ident::sindyc::from_table(s)?;
        let eqs = [("accel", &sm.accel), ("zdot", &sm.zdot), ("idot", &sm.idot)];
        let big = |x: f64| x.abs() > f64::from(f32::MAX);
        for (name, eq) in eqs {
            if let Some((_, k)) = eq.terms.iter().find(|(_, k)| big(*k)) {
                bail!(
                    "field 'sindy.{name}': coefficient {} does not fit the board's single precision",
                    crate::validate::show(*k)
                );
            }
        }
        if let Some((name, _)) = eqs
            .iter()
            .find(|(_, eq)| eq.terms.iter().any(|(t, _)| *t == Term::AbsXdotZ))
        {
            bail!(
                "field 'sindy.{name}': the presliding bristle (term |xdot|*z, from fit --add \
                 presliding) runs on the host only: the board would compensate the bristle's \
                 damping from its Hall-step velocity estimate, a negative damping of the speed \
                 loop at every reversal; fit without --add presliding for the board"
            );
        }
        for (name, v) in [("sindy.a", sm.a), ("sindy.vs", sm.vs), ("sindy.j", sm.j)] {
            if big(v) {
                bail!(
                    "field '{name}': {} does not fit the board's single precision",
                    crate::validate::show(v)
                );
            }
        }
    }
    Ok(())
}

/// Model → blob payload. Errors name the MODEL.toml field at fault ([`board_check`]).
pub fn coefficients(model: &Model, loop_settings: LoopSettings) -> Result<Coefficients> {
    board_check(model)?;
    let m = &model.motor;
    let mut co = Coefficients {
        model: match model.kind {
            ModelKind::Linear => blob::ModelKind::Linear,
            ModelKind::Lugre => blob::ModelKind::Lugre,
            ModelKind::Sindyc => blob::ModelKind::Sindyc,
        },
        motor: MotorParams {
            r: m.r as f32,
            l: m.l as f32,
            kt: m.kt as f32,
            kb: m.kb as f32,
            j: m.j as f32,
        },
        pole_pairs: pole_pairs(model),
        estimator: match loop_settings.edge_timing {
            Some(timeout_s) => Estimator::EdgeTiming { timeout_s },
            None => Estimator::MovingAverage {
                window: model.sensor.velocity_window.clamp(1, 64) as u8,
            },
        },
        pi: PiGains {
            kp: loop_settings.kp,
            ki: loop_settings.ki,
            u_max: loop_settings.u_max,
            comp_gain: loop_settings.comp_gain,
        },
        // The model's motor constants come from its identification.
        motor_identified: true,
        ..Coefficients::default()
    };
    if let Some(l) = &model.lugre {
        co.lugre = Some(LugreParams {
            alpha0: l.alpha0 as f32,
            alpha1: l.alpha1 as f32,
            alpha2: l.alpha2 as f32,
            v0: l.v0 as f32,
            sigma0: l.sigma0 as f32,
            sigma1: l.sigma1 as f32,
        });
    }
    if model.kind == ModelKind::Sindyc {
        co.sindy = Some(sindy_f32(&sindy_model(model)?));
    }
    // The linear model's viscous friction is compensated like any other effect.
    if model.kind == ModelKind::Linear && model.viscous != 0.0 {
        co.effects
            .push(Effect::Viscous {
                b: model.viscous as f32,
            })
            .map_err(|_| anyhow!("field 'effects': too many effects"))?;
    }
    for e in model.effects.iter().filter(|e| !is_absent_load(e)) {
        co.effects.push(e.map(|x| x as f32)).map_err(|_| {
            anyhow!(
                "field 'effects': the board holds at most {} effects",
                blob::MAX_EFFECTS
            )
        })?;
    }
    co.validate()
        .map_err(|e| anyhow!("the board refuses the coefficients: {e}"))?;
    Ok(co)
}

/// A load behind a coupling (`compliance`, `backlash`) of no inertia: an added load the
/// fit set to zero, which the model names but which acts on nothing; not put in the blob.
pub fn is_absent_load(e: &Effect<f64>) -> bool {
    matches!(*e, Effect::Compliance { j2, .. } | Effect::Backlash { j2, .. } if j2 <= 0.0)
}

/// Encode a blob (bytes ready for a file, the flash slot or an upload).
pub fn encode(co: &Coefficients) -> Result<Vec<u8>> {
    let mut buf = [0u8; blob::MAX_BLOB_LEN];
    let bytes = blob::encode(co, &mut buf).map_err(|e| match e {
        blob::BlobError::BufferTooSmall => anyhow!(
            "field 'effects': the model does not fit the board's {}-byte coefficient blob \
             (a lookup table takes {} bytes); add fewer effects",
            blob::MAX_BLOB_LEN,
            4 * (control::effects::TABLE_MAX_BINS + 2) + 2
        ),
        e => anyhow!("{e}"),
    })?;
    Ok(bytes.to_vec())
}

/// Decode a blob read from `path`; the error names the file and says what is wrong.
pub fn decode_file(path: &std::path::Path) -> Result<(Vec<u8>, Coefficients)> {
    let p = crate::log::echo_path(path);
    let bytes = crate::input::read(path, crate::input::MAX_BLOB_FILE, "coefficient blob")?;
    match blob::decode(&bytes) {
        Ok(co) => Ok((bytes, co)),
        Err(e) => {
            let detail = match (e, blob::blob_len(&bytes)) {
                (blob::BlobError::Truncated, Some(n)) => {
                    format!(" ({} bytes, the header announces {n})", bytes.len())
                }
                (blob::BlobError::Truncated, None) => format!(" ({} bytes)", bytes.len()),
                _ => String::new(),
            };
            bail!("{p}: {e}{detail}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect_spec::EffectSpec;
    use crate::log::Plant;

    /// A full table fits the blob and decodes to itself; as many tables as the blob has
    /// effect slots either fit too or are refused in one line.
    #[test]
    fn tables_go_in_the_blob_while_they_fit() {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(crate::model::LugreParams::paper());
        let last = control::effects::TABLE_MAX_BINS - 1;
        let spec = format!(
            "table:var=omega,bins={},lo=-50,hi=50,b0=0.01,b{last}=-0.02",
            last + 1
        );
        m.effects
            .push(EffectSpec::parse(&spec).unwrap().to_effect());
        let co = coefficients(&m, LoopSettings::default()).unwrap();
        let bytes = encode(&co).unwrap();
        assert_eq!(blob::decode(&bytes).unwrap(), co);
        m.effects = vec![m.effects[0]; blob::MAX_EFFECTS];
        let co = coefficients(&m, LoopSettings::default()).unwrap();
        match encode(&co) {
            Ok(bytes) => assert_eq!(blob::decode(&bytes).unwrap(), co),
            Err(e) => {
                let e = e.to_string();
                assert!(e.contains("does not fit") && !e.contains('\n'), "{e}");
            }
        }
    }
}
