//! The emulated motor, step by step: the paper's DC-equivalent model with LuGre friction and
//! the named physical effects, integrated with an implicit (L-stable) scheme.
//!
//! ```text
//! J·dω/dt = K_t·I − F_f − Σ torque(effect) − T_extra
//! L·dI/dt = −R·(1 + Σh)·I − K_b·ω + V − Σ voltage_loss(effect)
//! dθ/dt  = ω
//! F_f = σ0·z + σ1·ż + α2·ω,   ż = ω − σ0·|ω|·z/s(ω)           (control::lugre)
//! ```
//!
//! # Integration scheme
//! Each fine step `h` (default 0.2 ms, 60 per 12 ms sample) with the voltage held:
//! backward Euler for (θ, ω, I), with the bristle state updated *exactly* for the new
//! velocity (`control::lugre::z_step`) and `ż = (z' − z)/h` the exact mean rate, so the
//! friction is evaluated consistently at the end of the step. The unknown is the new velocity
//! `ω'`: for a given `ω'` the current `I'` solves the (monotone) electrical equation, and the
//! residual `J·(ω' − ω)/h − K_t·I' + F_f + loads` increases with `ω'`, so a bracketing scalar
//! solver ([`super::scalar_root`]) finds it. Heat states are updated exactly with `I'`
//! (`Effect::heat_step`).
//!
//! Why implicit: the paper's σ1 = 22.2 N·m·s/rad acts as a damping of σ1 on the rotor in
//! presliding; with J = 3e-4 kg·m² its time constant J/σ1 is 14 µs, far below any practical
//! step, and explicit Euler diverges. Backward Euler is stable for any step and exact at
//! equilibria (its fixed points are the model's steady states). In presliding the paper's
//! σ0, σ1 make the rotor creep with the time constant σ1/σ0 ≈ 70 ms before breakaway: a
//! visible stiction delay at every reversal, which we keep (it is the paper's model).
//!
//! A second consequence of the paper's σ1 (checked, kept, documented): in sliding, z tracks
//! `s(ω)/σ0`, so `σ1·ż ≈ σ1·s'(ω)·ω̇/σ0` acts as an inertia of `σ1·s'(ω)/σ0`, negative on the
//! Stribeck slope. At |ω| = v0/√2 ≈ 2.6 rad/s it is −2.86e-4 kg·m², leaving an effective
//! inertia of only 1.4e-5 kg·m² (the model would be ill-posed with J < 2.9e-4). Linearised
//! there, the rotor has a lightly damped friction mode near 100 Hz. The 0.2 ms backward
//! Euler damps it; finer steps resolve some chatter at 1.5-4 rad/s. The difference between
//! 0.2 and 0.1 ms there is ~0.03 rad/s rms, 4% of the 0.79 rad/s velocity resolution of the
//! board, so the logs do not depend on it (tests/tests/simulate_physics.rs).
use super::scalar_root::find_root;
use super::sensors::{CurrentSensor, HallEdge, HallSensor};
use super::EmulatorConfig;
use control::effects::{total_sensor_offset, total_torque, total_voltage_loss, EffectInputs};
use control::lugre::{z_step, LugreParams};

/// What an extra load closure may depend on (true values at the end of the fine step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadInputs {
    /// Time [s].
    pub t: f64,
    /// Rotor angle [rad].
    pub theta: f64,
    /// Rotor velocity [rad/s].
    pub omega: f64,
    /// Winding current [A].
    pub i: f64,
}

/// The true state of the emulated motor.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrueState {
    /// Time [s].
    pub t: f64,
    /// Rotor angle θ [rad].
    pub theta: f64,
    /// Rotor velocity ω [rad/s].
    pub omega: f64,
    /// Winding current I [A].
    pub i: f64,
    /// LuGre bristle deflection z [rad].
    pub z: f64,
    /// Sum of the thermal effects' heat states (R is `R·(1 + heat)`).
    pub heat: f64,
    /// LuGre friction torque F_f over the last fine step [N·m].
    pub friction: f64,
    /// Effect torques plus the extra load over the last fine step [N·m].
    pub load: f64,
    /// Voltage reaching the winding over the last fine step (commanded − losses) [V].
    pub applied_voltage: f64,
}

/// The emulated motor with its sensors. Drive it with [`Plant::apply`], read it like the
/// firmware does ([`Plant::hall_state`], [`Plant::hall_angle`], [`Plant::measured_current`]),
/// or look at the truth ([`Plant::truth`]).
pub struct Plant {
    cfg: EmulatorConfig,
    lugre: LugreParams<f64>,
    state: TrueState,
    heats: Vec<f64>,
    /// Largest total |voltage loss| of the effects [V] (bounds the current solve).
    vloss_max: f64,
    sensor_offset: f64,
    hall: HallSensor,
    current: CurrentSensor,
    /// Velocity at the start of the previous fine step (for the solver's first guess).
    omega_prev: f64,
    /// Commutation factor g: torque K_t·g·I and back-EMF K_b·g·ω (1: a DC motor, or a BLDC
    /// motor commutated right; the emulated board sets it per bridge vector).
    g: f64,
}

impl std::fmt::Debug for Plant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Plant")
            .field("state", &self.state)
            .field("lugre", &self.lugre)
            .finish_non_exhaustive()
    }
}

impl Plant {
    /// A motor at rest at angle 0. Fails on a configuration that cannot be simulated.
    pub fn new(cfg: EmulatorConfig) -> anyhow::Result<Plant> {
        cfg.check()?;
        let lugre = cfg.effective_lugre();
        let vloss_max = cfg
            .effects
            .iter()
            .map(|e| e.voltage_loss(1e12).abs().max(e.voltage_loss(-1e12).abs()))
            .sum();
        let sensor_offset = total_sensor_offset(&cfg.effects);
        Ok(Plant {
            hall: HallSensor::new(cfg.pole_pairs, 0.0),
            current: CurrentSensor::new(cfg.current_noise, sensor_offset, cfg.seed),
            heats: vec![0.0; cfg.effects.len()],
            lugre,
            state: TrueState::default(),
            vloss_max,
            sensor_offset,
            omega_prev: 0.0,
            g: 1.0,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &EmulatorConfig {
        &self.cfg
    }

    /// The LuGre parameters in force (the base ones, with `presliding` σ0/σ1 if given).
    pub fn lugre(&self) -> &LugreParams<f64> {
        &self.lugre
    }

    /// Hold voltage `v` for `dt` seconds (split into fine steps of at most
    /// `cfg.fine_step`).
    pub fn apply(&mut self, v: f64, dt: f64) {
        if dt.is_nan() || dt <= 0.0 || !dt.is_finite() {
            return;
        }
        let v = if v.is_finite() { v } else { 0.0 };
        // Bounded whatever dt and fine_step say (a validated config needs at most 12000).
        let n = (dt / self.cfg.fine_step - 1e-9)
            .ceil()
            .clamp(1.0, 100_000.0) as usize;
        let h = dt / n as f64;
        for _ in 0..n {
            self.fine_step(v, h);
        }
    }

    /// Set the commutation factor g (torque K_t·g·I, back-EMF K_b·g·ω) for the next
    /// [`Plant::apply`]: 1 for a DC motor (the default), otherwise how well the bridge vector
    /// applied lines up with the rotor (the emulated board, `board::hw`).
    pub fn set_commutation(&mut self, g: f64) {
        self.g = if g.is_finite() { g } else { 0.0 };
    }

    /// The true state.
    pub fn truth(&self) -> TrueState {
        self.state
    }

    /// Put the motor in a given state (angle, velocity, current, bristle deflection); the
    /// Hall decoder follows from its present angle.
    pub fn set_truth(&mut self, theta: f64, omega: f64, i: f64, z: f64) {
        self.state.theta = theta;
        self.state.omega = omega;
        self.state.i = i;
        self.state.z = z;
        self.omega_prev = omega;
        self.hall.track(theta, self.state.t);
    }

    /// The 3-bit Hall state now.
    pub fn hall_state(&self) -> u8 {
        self.hall.state()
    }

    /// Hall edges (time, state entered) since the last call, in order. The first call
    /// starts the recording; feed them to a decoder / edge-timing estimator to see every
    /// edge, as the board's edge interrupt does.
    pub fn take_hall_edges(&mut self) -> Vec<HallEdge> {
        self.hall.take_edges()
    }

    /// The angle [rad] the firmware's Hall decoder reports now (0 at power-up).
    pub fn hall_angle(&self) -> f64 {
        self.hall.angle()
    }

    /// Hall resolution [rad].
    pub fn hall_resolution(&self) -> f64 {
        self.hall.step()
    }

    /// One reading of the current sensor [A]: true current + sensor offset + noise.
    pub fn measured_current(&mut self) -> f64 {
        self.current.read(self.state.i)
    }

    /// The current-sensor offset of the effects [A].
    pub fn sensor_offset(&self) -> f64 {
        self.sensor_offset
    }

    /// Load torque of the effects and the extra closure at a state.
    fn load_at(&self, t: f64, theta: f64, omega: f64, i: f64) -> f64 {
        let x = EffectInputs {
            theta,
            omega,
            current: i,
            kt: self.cfg.motor.kt,
        };
        let mut tq = total_torque(&self.cfg.effects, &x);
        if let Some(f) = &self.cfg.extra_load {
            tq += f(LoadInputs { t, theta, omega, i });
        }
        tq
    }

    /// The new current for a trial new velocity `w` (backward Euler on the winding).
    fn current_for(&self, v: f64, h: f64, r: f64, w: f64) -> f64 {
        let m = &self.cfg.motor;
        let a = m.l / h + r;
        let rhs = m.l / h * self.state.i + v - m.kb * self.g * w;
        if self.vloss_max == 0.0 {
            return rhs / a;
        }
        let effects = &self.cfg.effects;
        find_root(
            |i| a * i + total_voltage_loss(effects, i) - rhs,
            rhs / a,
            self.vloss_max / a,
            1e-12 * (1.0 + (rhs / a).abs()),
        )
    }

    fn fine_step(&mut self, v: f64, h: f64) {
        let m = self.cfg.motor;
        let s0 = self.state;
        let heat: f64 = self.heats.iter().sum();
        let r = m.r * (1.0 + heat);
        let t1 = s0.t + h;
        // Everything at the end of the step for a trial new velocity w.
        let eval = |w: f64| {
            let i = self.current_for(v, h, r, w);
            let (z, zdot) = z_step(&self.lugre, s0.z, w, h);
            let fric = self.lugre.friction_at(w, z, zdot);
            let theta = s0.theta + h * w;
            let load = self.load_at(t1, theta, w, i);
            let resid = m.j * (w - s0.omega) / h - m.kt * self.g * i + fric + load;
            (resid, i, z, fric, load, theta)
        };
        // First guess: linear extrapolation of the velocity; first search step: the velocity
        // change the residual asks for with the inertia alone.
        let guess = s0.omega + (s0.omega - self.omega_prev);
        let g0 = eval(guess).0;
        let step0 = g0.abs() * h / m.j + 1e-9;
        let w = find_root(|w| eval(w).0, guess, step0, 1e-11 * (1.0 + s0.omega.abs()));
        let (_, i, z, fric, load, theta) = eval(w);
        for (hs, e) in self.heats.iter_mut().zip(&self.cfg.effects) {
            *hs = e.heat_step(*hs, i, h);
        }
        self.omega_prev = s0.omega;
        self.state = TrueState {
            t: t1,
            theta,
            omega: w,
            i,
            z,
            heat: self.heats.iter().sum(),
            friction: fric,
            load,
            applied_voltage: v - total_voltage_loss(&self.cfg.effects, i),
        };
        self.hall.track(theta, t1);
    }
}
