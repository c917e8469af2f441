//! Steady states of the emulated motor in closed form, and the paper's static-friction
//! experiment (constant voltages, steady speeds) run on the emulator.
//!
//! At a constant voltage the motor settles where the motor torque balances the steady
//! friction: `K_t·I = s(ω)·sgn(ω) + α2·ω + Σ torque(effect)`, with the current from the
//! winding at rest, `R·(1 + h(I))·I + Σ voltage_loss(I) = V − K_b·ω` (`h = k·I²` for
//! `thermal`). Below breakaway (`|K_t·I(0)| ≤ s(0)`) the rotor stays still.
use super::scalar_root::find_root;
use super::{EmulatorConfig, Plant};
use control::effects::{total_torque, total_voltage_loss, Effect, EffectInputs};

/// The steady-state current for velocity `w` under voltage `v`.
fn steady_current(cfg: &EmulatorConfig, v: f64, w: f64) -> f64 {
    let m = &cfg.motor;
    let rhs = v - m.kb * w;
    let heat_gain: f64 = cfg
        .effects
        .iter()
        .map(|e| match e {
            Effect::Thermal { k, .. } => *k,
            _ => 0.0,
        })
        .sum();
    let f =
        |i: f64| m.r * (1.0 + heat_gain * i * i) * i + total_voltage_loss(&cfg.effects, i) - rhs;
    find_root(
        f,
        rhs / m.r,
        1.0 + rhs.abs() / m.r,
        1e-12 * (1.0 + (rhs / m.r).abs()),
    )
}

/// The steady speed [rad/s] under constant voltage `v`, in closed form (a scalar root), or
/// `None` when the motor has no steady speed (an angle-dependent effect or an extra load).
pub fn steady_speed(cfg: &EmulatorConfig, v: f64) -> Option<f64> {
    if cfg.extra_load.is_some()
        || cfg
            .effects
            .iter()
            .any(|e| matches!(e, Effect::Cogging { .. } | Effect::PositionLoad { .. }))
    {
        return None;
    }
    let p = cfg.effective_lugre();
    let m = cfg.motor;
    // Net accelerating torque at velocity w: decreasing in w, with a jump of 2·s(0) at 0.
    let net = |w: f64| {
        let i = steady_current(cfg, v, w);
        let x = EffectInputs {
            theta: 0.0,
            omega: w,
            current: i,
            kt: m.kt,
        };
        m.kt * i - p.steady_friction(w) - total_torque(&cfg.effects, &x)
    };
    // find_root walks an increasing function: use −net. It stops at the jump at 0 when the
    // motor is stuck.
    let w = find_root(|w| -net(w), 0.0, 1.0, 1e-12);
    Some(if w.abs() < 1e-9 { 0.0 } else { w })
}

/// The paper's static experiment: hold each voltage for `hold` seconds and average the
/// true velocity over the last half of the hold. Returns `(voltage, speed)` pairs.
pub fn steady_speeds(
    cfg: &EmulatorConfig,
    voltages: &[f64],
    hold: f64,
) -> anyhow::Result<Vec<(f64, f64)>> {
    let mut out = Vec::with_capacity(voltages.len());
    for &v in voltages {
        let mut plant = Plant::new(cfg.clone())?;
        plant.apply(v, hold / 2.0);
        let n = 50;
        let mut sum = 0.0;
        for _ in 0..n {
            plant.apply(v, hold / 2.0 / n as f64);
            sum += plant.truth().omega;
        }
        out.push((v, sum / n as f64));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn breakaway_voltage_of_the_paper_motor() {
        let cfg = EmulatorConfig::paper();
        // s(0) = 0.0975 N·m needs I = s(0)/K_t = 1.368 A, i.e. V = R·I = 0.296 V.
        assert_eq!(steady_speed(&cfg, 0.25), Some(0.0));
        assert!(steady_speed(&cfg, 0.35).unwrap() > 0.0);
        assert!(steady_speed(&cfg, -0.35).unwrap() < 0.0);
        let w = steady_speed(&cfg, 12.0).unwrap();
        // Far above v0: K_t(V − K_b ω)/R = α0 + α2 ω.
        let m = cfg.motor;
        let want = (m.kt * 12.0 / m.r - 0.08) / (m.kt * m.kb / m.r + 0.0016);
        assert!((w - want).abs() < 1e-6 * want, "{w} vs {want}");
    }
}
