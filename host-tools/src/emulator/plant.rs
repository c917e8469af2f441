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
//!
//! # Loads behind a coupling (`compliance`, `backlash`)
//! Each such effect adds a load inertia `j2` with its own angle and speed (θ2, ω2), coupled
//! to the rotor by a torque `τ_c(θ1 − θ2, ω1 − ω2)`; the sensors see the rotor (θ1, ω1):
//!
//! ```text
//! J·dω1/dt = K_t·I − F_f − Σ torque(effect) − T_extra − Σ τ_c
//! j2·dω2/dt = τ_c,   dθ2/dt = ω2
//! compliance: τ_c = k·(θ1 − θ2) + c·(ω1 − ω2)
//! backlash:   τ_c = max(0, k_c·(x − gap/2) + c_c·(ω1 − ω2))  for x = θ1 − θ2 >  gap/2,
//!             τ_c = min(0, k_c·(x + gap/2) + c_c·(ω1 − ω2))  for x < −gap/2, 0 inside
//! ```
//!
//! The load takes the same backward Euler step as the rotor, in the same solve: for a trial
//! `ω1'` the load's new speed solves `j2·(ω2' − ω2)/h = τ_c(θ1' − θ2 − h·ω2', ω1' − ω2')`
//! (in closed form, [`control::coupling`], the one home of the coupling's equation), and
//! the rotor feels `j2·(ω2' − ω2)/h`. That torque never falls as `ω1'` rises (τ_c never falls
//! with the deflection or its rate), so the rotor's residual stays increasing and its root
//! unique. Backward Euler on the coupled pair is stable for any stiffness and never adds
//! energy: with no input its spring-plus-kinetic energy falls each step by at least
//! `h·c·(ω1' − ω2')²`. It damps the coupling's mode slightly: a damping ratio of about
//! `ω_c·h/2` on top of the physical one (ω_c the coupled frequency `√(k·(J + j2)/(J·j2))`;
//! 0.003 for the default 5 Hz coupling at 0.2 ms) and a frequency low by `(ω_c·h)²/3`. A
//! coupling far stiffer than the step resolves (`ω_c·h ≫ 1`) is damped out within a step or
//! two, and the pair then moves as one inertia `J + j2`: the rigid limit.
//!
//! Backlash: a rigid, inelastic contact at each end of the gap, made a stiff spring-damper
//! that engages only beyond the gap and never pulls (the clamps above). Its stiffness
//! `k_c = μ·(10/h)²` and critical damping `c_c = 2·μ·10/h`, with `μ = J·j2/(J + j2)` the
//! pair's reduced inertia, give the contact a critically damped frequency of 10/h: backward
//! Euler settles it within one or two steps (an inelastic impact, the momenta merged), and
//! under a torque T it yields only `T/k_c` (2·10⁻⁶ rad per N·m for the paper's rotor, a
//! default load and 0.2 ms). Inside the gap the load has no friction of its own: it coasts.
//! The load starts at rest in the middle of the gap, so the first motion from rest turns the
//! rotor alone for gap/2; after a reversal it turns alone across the whole gap.
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

/// Angle and speed of a load behind a coupling (`compliance`, `backlash`) [rad, rad/s], on
/// the rotor's side of any gear (the same scale as θ).
pub type LoadState = control::coupling::LoadState<f64>;

/// How a load is coupled to the rotor.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Coupling {
    /// Spring `k` [N·m/rad] and damper `c` [N·m·s/rad].
    Spring { k: f64, c: f64 },
    /// A gap `gap` [rad] whose contact is set per fine step from the pair's reduced inertia
    /// `mu` [kg·m²] ([`control::coupling::Coupling::gap`]).
    Gap { gap: f64, mu: f64 },
}

/// A load inertia on the rotor's shaft, behind a coupling.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Load {
    /// Load inertia j2 [kg·m²].
    j2: f64,
    coupling: Coupling,
    state: LoadState,
}

impl Load {
    /// The loads of the effects, at rest at angle 0 (centred in any gap).
    fn of_effects(effects: &[control::effects::Effect<f64>], j: f64) -> Vec<Load> {
        use control::effects::Effect;
        effects
            .iter()
            .filter_map(|e| match *e {
                Effect::Compliance { j2, k, c } => Some(Load {
                    j2,
                    coupling: Coupling::Spring { k, c },
                    state: LoadState::default(),
                }),
                Effect::Backlash { j2, gap } => Some(Load {
                    j2,
                    coupling: Coupling::Gap {
                        gap,
                        mu: j * j2 / (j + j2),
                    },
                    state: LoadState::default(),
                }),
                _ => None,
            })
            .collect()
    }

    /// The load's state at the end of a fine step `h` (backward Euler,
    /// [`control::coupling::Coupling::step`]) when the rotor ends it at angle `theta1` and
    /// speed `omega1`.
    fn step(&self, theta1: f64, omega1: f64, h: f64) -> LoadState {
        let coupling = match self.coupling {
            Coupling::Spring { k, c } => control::coupling::Coupling::Spring { k, c },
            Coupling::Gap { gap, mu } => control::coupling::Coupling::gap(gap, mu, h),
        };
        coupling.step(self.j2, self.state, theta1, omega1, h)
    }
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
    /// Effect torques, the extra load and the couplings' torques to their loads over the
    /// last fine step [N·m].
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
    /// Loads behind a coupling (`compliance`, `backlash`), one per such effect.
    loads: Vec<Load>,
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
    /// Share of the configured R and L in the current's path (1: the line-to-line winding
    /// of a two-phase vector; the emulated board sets it per bridge vector).
    path: f64,
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
            loads: Load::of_effects(&cfg.effects, cfg.motor.j),
            lugre,
            state: TrueState::default(),
            vloss_max,
            sensor_offset,
            omega_prev: 0.0,
            g: 1.0,
            path: 1.0,
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

    /// Set the share of the configured R and L in the current's path for the next
    /// [`Plant::apply`] (1, the default: the line-to-line winding; ¾ for two phases in
    /// parallel in series with the third, a three-phase bridge's centre vector).
    pub fn set_winding_path(&mut self, share: f64) {
        self.path = if share.is_finite() && share > 0.0 {
            share
        } else {
            1.0
        };
    }

    /// The true state.
    pub fn truth(&self) -> TrueState {
        self.state
    }

    /// Angle and speed of each load behind a coupling, in the order of the effects
    /// (`compliance`, `backlash`); empty without one.
    pub fn load_states(&self) -> Vec<LoadState> {
        self.loads.iter().map(|l| l.state).collect()
    }

    /// Put the motor in a given state (angle, velocity, current, bristle deflection); the
    /// Hall decoder follows from its present angle, and each load moves with the rotor,
    /// relaxed (centred in any gap).
    pub fn set_truth(&mut self, theta: f64, omega: f64, i: f64, z: f64) {
        for l in &mut self.loads {
            l.state = LoadState { theta, omega };
        }
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
        let (l, r) = (self.path * m.l, self.path * r);
        let a = l / h + r;
        let rhs = l / h * self.state.i + v - m.kb * self.g * w;
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
            let coupled: f64 = self
                .loads
                .iter()
                .map(|l| l.j2 * (l.step(theta, w, h).omega - l.state.omega) / h)
                .sum();
            let load = self.load_at(t1, theta, w, i) + coupled;
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
        for l in &mut self.loads {
            l.state = l.step(theta, w, h);
        }
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
