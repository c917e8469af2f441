//! The candidate regressors of the physical effects: the sample-level signals and columns
//! the effects add to the mechanical (torque) or electrical (voltage) equation, and the
//! variants `diagnose` tests. Which columns an effect adds, over which grid of its
//! nonlinear keys, and how the fitted coefficients turn back into its keys (its spec) is in
//! the effect's descriptor ([`crate::effects::Diagnose`]); this module reads it from there.
//!
//! Equations, with the sign conventions of `control::effects` (load torques oppose motion,
//! voltage losses are subtracted from the command):
//! - mechanical: `K_t·I_meas = J·θ̈ + Σ torque_j + K_t·i0` (torque plant: `u` instead of `K_t·I`)
//! - electrical: `V = R·I_meas + L·İ + K_b·ω + vd·sgn(I) + R·k·h·I − R·i0`
//!
//! Parameters that enter nonlinearly (Stribeck velocity, cogging harmonic, thermal time
//! constant, bristle stiffness) are searched over a grid; the others are the linear
//! coefficients.
use super::harmonics;
use crate::effect_spec::EffectSpec;
use crate::effects;
use crate::log::{MotorLog, Plant};
use crate::numerics::differentiation;
use control::coupling::{Coupling, LoadState};
use control::effects::{smooth_sign, Effect, EffectKind, VELOCITY_EPS};
use control::lugre::{LugreObserver, LugreParams};
use std::collections::BTreeMap;

/// Which equation an effect shows in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Equation {
    /// Torque balance of the rotor.
    Mechanical,
    /// Voltage balance of the winding.
    Electrical,
}

impl Equation {
    /// Name for people.
    pub fn label(self) -> &'static str {
        match self {
            Equation::Mechanical => "torque equation",
            Equation::Electrical => "voltage equation",
        }
    }
}

/// Steps per sample of a load behind a gap ([`Signals::load_angle`]): the contact settles
/// within a step or two of its own, and a catch lands within a sixteenth of a sample.
pub const LOAD_SUBSTEPS: usize = 16;

/// Largest `ω_n·h` of a spring's step in [`Signals::load_acceleration`]: backward Euler
/// adds a damping ratio of about half of it, 0.005, a tenth of the lightest coupling the
/// compliance candidate tests (ζ = 0.05).
pub const SPRING_STEP: f64 = 0.01;

/// Sample-level signals derived from a log.
#[derive(Debug, Clone)]
pub struct Signals {
    /// Sample period [s].
    pub dt: f64,
    pub t: Vec<f64>,
    /// Input on the sample grid: voltage [V] held just before each sample (voltage plant)
    /// or torque command (torque plant).
    pub u: Vec<f64>,
    /// Input as logged, held over `[t_k, t_k+1)`.
    pub raw_u: Vec<f64>,
    /// Measured current [A] (voltage plant).
    pub i: Option<Vec<f64>>,
    /// Angle as measured [rad].
    pub theta: Vec<f64>,
    /// Angle smoothed over a few samples (less quantisation error while moving) [rad].
    pub theta_s: Vec<f64>,
    /// The angle the torque equation integrates [rad]: the readings, or a path through their
    /// quantisation bands (`diagnose` sets it, see `numerics::quantisation`).
    pub theta_torque: Vec<f64>,
    /// Variance of the error left in `theta_torque` at each sample [rad²].
    pub theta_torque_var: Vec<f64>,
    /// Velocity: smoothed derivative of the angle [rad/s].
    pub omega: Vec<f64>,
    /// Motor torque: `K_t·I` (voltage plant) or `u` (torque plant).
    pub drive: Vec<f64>,
    /// The drive torque as the model explains it from the motion (inertia and friction),
    /// free of the measured current's noise and of the model's error: regressors built from
    /// the measured drive would "explain" the residual with itself.
    pub drive_model: Vec<f64>,
    pub plant: Plant,
    /// Torque constant used to express currents as torques (1 for a torque plant).
    pub kt: f64,
    /// Angle quantisation step [rad], when the log says it.
    pub hall_resolution: Option<f64>,
    /// Velocity scale of the log relative to the rotary motor the velocity constants were
    /// chosen for ([`velocity_scale`]): 1 for the paper's motor, ≈0.003 for a linear axis in m/s.
    pub vscale: f64,
    /// Half-width (samples) of the velocity estimate:
    /// [`differentiation::diagnose_velocity_half`].
    pub velocity_half: usize,
}

pub use crate::scales::{samples_for, velocity_scale, REFERENCE_SPEED};

impl Signals {
    /// Derive the signals from a log. `kt` is the model's torque constant.
    pub fn from_log(log: &MotorLog, plant: Plant, kt: f64) -> Signals {
        let dt = log.sample_period();
        let velocity_half = differentiation::diagnose_velocity_half(log);
        let omega = differentiation::smoothed_derivative(&log.theta, dt, velocity_half);
        let vscale = velocity_scale(&omega);
        let theta_s = differentiation::moving_average(&log.theta, 2);
        // The input u[k] is held over [t_k, t_k+1) while angle and current are sampled at t_k.
        // The winding settles within L/R ≈ 1.4 ms, so the current sampled at t_k is the
        // quasi-static response to the input held just before it, u[k−1]: on the sample grid
        // the voltage equation pairs i[k] with u[k−1].
        let mut u = log.u.clone();
        if plant == Plant::Voltage && u.len() > 1 {
            u.rotate_right(1);
            u[0] = u[1];
        }
        let i = match (plant, &log.i) {
            (Plant::Voltage, Some(i)) => Some(i.clone()),
            _ => None,
        };
        let (drive, kt) = match &i {
            Some(i) => (i.iter().map(|v| kt * v).collect(), kt),
            None => (u.clone(), 1.0),
        };
        Signals {
            dt,
            t: log.t.clone(),
            u,
            raw_u: log.u.clone(),
            i,
            theta: log.theta.clone(),
            theta_torque: log.theta.clone(),
            theta_torque_var: vec![0.0; log.len()],
            theta_s,
            omega,
            drive_model: drive.clone(),
            drive,
            plant,
            kt,
            hall_resolution: log.meta_f64("hall_resolution_rad"),
            vscale,
            velocity_half,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The measured current [A] of a voltage plant, where the voltage equation exists.
    pub fn current(&self) -> Option<&Vec<f64>> {
        match self.plant {
            Plant::Voltage => self.i.as_ref(),
            _ => None,
        }
    }

    /// Smooth sign of the velocity, of width [`Self::velocity_eps`].
    pub fn sgn_omega(&self) -> Vec<f64> {
        let eps = self.velocity_eps();
        self.omega.iter().map(|w| smooth_sign(*w, eps)).collect()
    }

    /// Width of the smooth sign: the control crate's `VELOCITY_EPS` times [`Self::vscale`].
    pub fn velocity_eps(&self) -> f64 {
        VELOCITY_EPS * self.vscale
    }

    /// Speed below which the rotor counts as stuck: [`STICK_SPEED`] times [`Self::vscale`].
    pub fn stick_speed(&self) -> f64 {
        STICK_SPEED * self.vscale
    }

    /// Sample-level angle harmonic pair for `h` periods per revolution, attenuated where the
    /// torque averages out over a sample (see [`harmonics::sample_average_gain`]).
    pub fn angle_pair(&self, h: u32) -> [Vec<f64>; 2] {
        let hf = h as f64;
        let g: Vec<f64> = self
            .omega
            .iter()
            .map(|w| harmonics::sample_average_gain(hf, *w, self.dt).max(0.0))
            .collect();
        [
            self.theta_s
                .iter()
                .zip(&g)
                .map(|(t, g)| g * (hf * t).sin())
                .collect(),
            self.theta_s
                .iter()
                .zip(&g)
                .map(|(t, g)| g * (hf * t).cos())
                .collect(),
        ]
    }

    /// Heat state `h_τ` for unit gain (`dh/dt = (I² − h)/τ`, exact per sample), times I.
    pub fn thermal_column(&self, tau: f64) -> Vec<f64> {
        let Some(i) = &self.i else {
            return vec![0.0; self.len()];
        };
        let e = Effect::Thermal { k: 1.0, tau };
        let mut h = 0.0;
        i.iter()
            .map(|c| {
                let out = c * h;
                h = e.heat_step(h, *c, self.dt);
                out
            })
            .collect()
    }

    /// LuGre dynamic friction minus its static part along the measured velocity, with the
    /// given parameters: what the bristle state adds to the static friction curve
    /// `s(ω)·sgn(ω) + α2·ω` (the smooth sign of the model's Coulomb column). Zero while stuck
    /// (the stick column of the base stands for the friction there). The bristle state is
    /// integrated with the exact update of `control::lugre` from the estimated velocity, so
    /// it follows the measured angle (a Hall sensor resolves a deflection of a few steps).
    pub fn presliding_column(&self, p: &LugreParams<f64>) -> Vec<f64> {
        let mut obs = LugreObserver::new(*p);
        let eps = self.velocity_eps();
        let stuck = self.stuck();
        self.omega
            .iter()
            .zip(stuck)
            .map(|(w, st)| {
                let f = obs.step(*w, self.dt) - p.alpha2 * w;
                if st {
                    0.0
                } else {
                    f - p.s(*w) * smooth_sign(*w, eps)
                }
            })
            .collect()
    }

    /// Angle quantisation step [rad]: the log's `hall_resolution_rad`, else the smallest
    /// angle change the log shows (at least 1e-9).
    pub fn angle_step(&self) -> f64 {
        if let Some(h) = self.hall_resolution.filter(|h| *h > 0.0 && h.is_finite()) {
            return h;
        }
        self.theta
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .filter(|d| *d > 1e-9 && d.is_finite())
            .fold(f64::INFINITY, f64::min)
            .min(1.0)
    }

    /// Median angle [rad] the rotor travels between two consecutive reversals (the velocity
    /// crossing from beyond the stick speed on one side to beyond it on the other); `None`
    /// with fewer than two reversals.
    pub fn median_swing(&self) -> Option<f64> {
        let stick = self.stick_speed();
        let mut swings = Vec::new();
        let (mut sign, mut from) = (0.0, None::<f64>);
        for (w, th) in self.omega.iter().zip(&self.theta) {
            if w.abs() < stick {
                continue;
            }
            let sg = w.signum();
            if sign != 0.0 && sg != sign {
                if let Some(a) = from {
                    swings.push((th - a).abs());
                }
                from = Some(*th);
            }
            sign = sg;
        }
        if swings.is_empty() {
            return None;
        }
        swings.sort_by(|a, b| a.total_cmp(b));
        Some(swings[swings.len() / 2])
    }
}

/// Map a signal held over sample intervals onto the sample grid: `(x[k−1] + x[k])/2`.
pub fn zoh_to_grid(x: &[f64]) -> Vec<f64> {
    (0..x.len())
        .map(|k| {
            if k == 0 {
                x[0]
            } else {
                0.5 * (x[k - 1] + x[k])
            }
        })
        .collect()
}

/// Velocity below which the rotor counts as stuck [rad/s]: less than about one Hall step
/// (0.095 rad) across the ±4-sample velocity window. While stuck, static friction takes
/// whatever value balances the drive, so the torque equation there has its own unknown.
pub const STICK_SPEED: f64 = 1.0;

/// Time [s] around a reversal or a standstill where the load-friction column is left at zero:
/// two weak-form half-widths (2 × [`crate::numerics::weak_form::HALF_WIDTH_S`]), so that no window that
/// holds a reversal sees it. A fast reversal can skip the stick band between two samples, and
/// its window keeps the friction's switch (the velocity estimate's sign lags the true one) and
/// the drive's own braking right before it, which a correct model would read as a negative μ
/// (measured in decision 0026).
pub const LOAD_FRICTION_GUARD_S: f64 = 2.0 * crate::numerics::weak_form::HALF_WIDTH_S;

impl Signals {
    /// `1` where the rotor is stuck (|ω| < [`STICK_SPEED`]), else `0`.
    pub fn stuck(&self) -> Vec<bool> {
        let v = self.stick_speed();
        self.omega.iter().map(|w| w.abs() < v).collect()
    }

    /// Load-dependent friction `μ·|drive|·sgn(ω)`, the part of it the model's structure cannot
    /// absorb: `|drive|·sgn(ω) − drive` with the modelled drive; zero while stuck and within
    /// [`LOAD_FRICTION_GUARD_S`] of a reversal or a standstill.
    ///
    /// Where the drive pushes along the motion (motoring), `|drive|·sgn(ω)` *is* the drive: a
    /// friction `μ·drive` there only scales the drive by `1 − μ`, which the refitted inertia
    /// and friction coefficients take up exactly (a torque constant a few percent low). Only
    /// where the drive opposes the motion (braking, the load driving the motor) does the
    /// friction keep opposing the motion while the drive changes sign; there the column is
    /// `−2·drive`, elsewhere 0. Its coefficient is `μ` (the `μ·drive` part is in the base).
    ///
    /// On a log whose drive never brakes the moving rotor (signal a brakes only in the last
    /// two samples before a stop) the column is zero: the effect cannot be told from a lower
    /// K_t there, and no finding is the right answer. The whole `|drive|·sgn(ω)` as a column
    /// is the modelled drive itself, which differs from the base only by the weak form's
    /// errors (the angle leak of `J·∫φ''θ`, the smoothed acceleration of the modelled drive),
    /// which such a column would fit as a large spurious μ (decision 0026).
    pub fn load_friction_column(&self) -> Vec<f64> {
        let guard = samples_for(LOAD_FRICTION_GUARD_S, self.dt, self.len());
        let near = self.near_reversal(guard);
        self.drive_model
            .iter()
            .zip(&self.omega)
            .zip(near)
            .map(|((d, w), near)| {
                if near {
                    0.0
                } else {
                    d.abs() * smooth_sign(*w, self.velocity_eps()) - d
                }
            })
            .collect()
    }

    /// Load-dependent friction per sample *interval* `[t_k, t_k+1)` for the torque equation
    /// written with the held input (`integral_zoh`): `(column, torque)`, both held over the
    /// interval. The drive over an interval is its mean: the held torque command (torque
    /// plant) or `(K_t/R)·(V_k − K_b·Δθ_k/Δt)` (voltage plant, the current quasi-static: the
    /// winding settles in L/R ≈ 1.4 ms), with the angle's own increment, so that it is exact
    /// however fast the rotor changes speed inside the interval. The column is `−2·drive` on
    /// intervals whose drive opposes the interval's motion by more than the velocity
    /// resolution `K_b·(angle step)/Δt` can blur (voltage plant), else 0; zero while stuck
    /// and within [`LOAD_FRICTION_GUARD_S`] of a reversal or standstill, as
    /// [`Self::load_friction_column`]. `torque` is `|drive|·sgn(motion)` (0 while stuck).
    ///
    /// Why: a motor whose mechanical transient is shorter than a sample brakes for about one
    /// sample after a step down of the voltage; the sampled current (or the modelled drive
    /// built from the smoothed acceleration) misses most of that interval, the interval mean
    /// from the held voltage and the angle increment does not (decision 0026).
    pub fn load_friction_intervals(&self, kb: f64, r: f64) -> (Vec<f64>, Vec<f64>) {
        let n = self.len();
        let guard = samples_for(LOAD_FRICTION_GUARD_S, self.dt, self.len());
        let near = self.near_reversal(guard);
        let voltage = self.i.is_some() && r > 0.0 && r.is_finite();
        let margin = if voltage {
            self.kt / r * kb.abs() * self.angle_step() / self.dt
        } else {
            0.0
        };
        let mut col = vec![0.0; n];
        let mut torque = vec![0.0; n];
        for k in 0..n.saturating_sub(1) {
            let w = (self.theta[k + 1] - self.theta[k]) / self.dt;
            if w.abs() < self.stick_speed() || near[k] || near[k + 1] {
                continue;
            }
            let drive = if voltage {
                self.kt / r * (self.raw_u[k] - kb * w)
            } else {
                self.raw_u[k]
            };
            torque[k] = drive.abs() * w.signum();
            if drive * w.signum() < -margin {
                col[k] = -2.0 * drive;
            }
        }
        (col, torque)
    }

    /// The torque a falling K_t loses per unit k, `K_t·I³`, averaged over each sample
    /// interval. The rotor's mechanical time constant is about one sample, so the current
    /// changes a lot inside an interval after a voltage step, and I³ weighs exactly those
    /// moments: the current jumps at the step by `ΔV/R` (the winding settles in L/R, a tenth of
    /// the interval) and then falls to the next sample `i[k+1]` as the back-EMF builds up.
    /// With the current taken linear between `i[k] + ΔV/R` and `i[k+1]`, the interval's mean of
    /// I³ is `(a³ + a²b + ab² + b³)/4`.
    pub fn saturation_intervals(&self, r: f64) -> Vec<f64> {
        let n = self.len();
        let mut col = vec![0.0; n];
        let Some(i) = self.i.as_ref() else {
            return col;
        };
        if !(r > 0.0 && r.is_finite()) {
            return col;
        }
        for k in 1..n.saturating_sub(1) {
            let a = i[k] + (self.raw_u[k] - self.raw_u[k - 1]) / r;
            let b = i[k + 1];
            col[k] = self.kt * (a * a * a + a * a * b + a * b * b + b * b * b) / 4.0;
        }
        col
    }

    /// The torque a load engaged across a gap of `gap` rad adds beyond the rigid inertia, per
    /// unit of its inertia: `θ̈2 − θ̈1`, the load's acceleration less the rotor's (a rigid
    /// model carries the load's inertia in J, so only the difference is new and the column
    /// cannot stand in for an inertia error). The load's angle is [`Signals::load_angle`]
    /// behind the gap, so it coasts inside the gap, parts from the rotor wherever the rotor
    /// slows down and is caught with a jolt at either face; `θ̈2 − θ̈1` is the second
    /// difference of the deflection `θ2 − θ1` over the sample period squared, `θ1` the angle
    /// the torque equation integrates (the inertia's own column), so that a catch's jolt
    /// lands in the sample it happens in. The load is driven by the smoothed angle and the
    /// deflection subtracts the integrated one, so in contact the rigid part cancels only to
    /// the difference of the two, which carries some of the angle's rounding.
    pub fn backlash_acceleration(&self, gap: f64) -> Vec<f64> {
        let n = self.len();
        if n < 3 || !(self.dt > 0.0 && gap.is_finite() && gap >= 0.0) {
            return vec![0.0; n];
        }
        let theta2 = self.load_angle(
            |h| Coupling::gap(gap, 1.0, h),
            LOAD_SUBSTEPS,
            self.load_hold(),
        );
        let deflection: Vec<f64> = theta2
            .iter()
            .zip(&self.theta_torque)
            .map(|(a, b)| a - b)
            .collect();
        self.second_difference(&deflection)
    }

    /// `(x[k+1] − 2·x[k] + x[k−1])/dt²` at each inner sample, 0 at both ends: the mean
    /// acceleration over the hat of width two samples. The weak form takes it through its
    /// held-input integral, whose weights differ from those its second derivative gives the
    /// angle (a smoothing over neighbouring samples), so the column and the inertia's are
    /// close but not weighed identically.
    pub fn second_difference(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        let mut out = vec![0.0; n];
        if n < 3 || self.dt.is_nan() || self.dt <= 0.0 {
            return out;
        }
        let dt2 = self.dt * self.dt;
        for k in 1..n - 1 {
            out[k] = (x[k + 1] - 2.0 * x[k] + x[k - 1]) / dt2;
        }
        out
    }

    /// The deceleration [rad/s²] a load's own friction gives it in flight behind a gap: the
    /// finest the angle resolves, one angle step over the square of the velocity window
    /// (`2·velocity_half + 1` samples). A rotor that slows down less than that keeps the load
    /// pressed against the face; a gentler parting is within the angle's rounding, and a
    /// column built on it would fit that rounding (on hard braking steps of a plant without
    /// any gap, a frictionless load's flights fitted a wide gap after a load friction).
    pub fn load_hold(&self) -> f64 {
        let tv = (2 * self.velocity_half + 1) as f64 * self.dt;
        if tv > 0.0 {
            self.angle_step() / (tv * tv)
        } else {
            0.0
        }
    }

    /// Angle θ2 [rad] at each sample of a load of unit inertia behind the coupling
    /// `coupling(h)` (its constants for a step `h`), driven by the measured rotor: the
    /// smoothed angle `theta_s`, straight between samples, with that line's slope as the
    /// rotor's speed, so that the angle and the speed the load meets are one motion (a
    /// smoothed speed beside the angle would part and catch the load where the two
    /// disagree). `sub` steps per sample of the coupling's own update
    /// ([`control::coupling`], the emulator's too); the load starts with the rotor, in the
    /// middle of any gap. A rotor whose motion is given is an infinitely heavy rotor: the
    /// pair's reduced inertia is the load's own. While the coupling passes no torque (in
    /// flight inside a gap) the load slows by `hold` [rad/s²], its own friction
    /// ([`Signals::load_hold`]).
    pub fn load_angle(
        &self,
        coupling: impl Fn(f64) -> Coupling<f64>,
        sub: usize,
        hold: f64,
    ) -> Vec<f64> {
        let n = self.len();
        if n == 0 || self.dt.is_nan() || self.dt <= 0.0 {
            return vec![0.0; n];
        }
        let sub = sub.max(1);
        let h = self.dt / sub as f64;
        let c = coupling(h);
        let th = &self.theta_s;
        let mut s = LoadState {
            theta: th[0],
            omega: if n > 1 {
                (th[1] - th[0]) / self.dt
            } else {
                0.0
            },
        };
        let mut out = vec![s.theta; n];
        for k in 0..n - 1 {
            let w1 = (th[k + 1] - th[k]) / self.dt;
            for j in 1..=sub {
                let th1 = th[k] + (th[k + 1] - th[k]) * (j as f64 / sub as f64);
                s = c.step(1.0, s, th1, w1, h);
                if hold > 0.0 && c.torque(th1 - s.theta, w1 - s.omega) == 0.0 {
                    let dw = (hold * h).min(s.omega.abs());
                    s.omega -= dw * s.omega.signum();
                }
            }
            out[k + 1] = s.theta;
        }
        out
    }

    /// Acceleration θ̈2 of a load on a spring-damper coupling driven by the measured rotor
    /// (natural frequency `fn_hz` against a fixed rotor, damping ratio `zeta`): the second
    /// difference of [`Signals::load_angle`] behind the spring `k = ω_n²`, `c = 2ζω_n` per
    /// unit of load inertia. The coupling's torque on the rotor is `J2·θ̈2`, so this is the
    /// compliance's column per unit J2. The step is backward Euler, which damps the
    /// coupling by about `ω_n·h/2` on top of its own damping; steps of at most
    /// [`SPRING_STEP`]`/ω_n` keep that at a tenth of the lightest damping tested.
    pub fn load_acceleration(&self, fn_hz: f64, zeta: f64) -> Vec<f64> {
        let n = self.len();
        let wn = 2.0 * std::f64::consts::PI * fn_hz;
        if n == 0 || !(wn.is_finite() && wn > 0.0 && self.dt > 0.0 && zeta >= 0.0) {
            return vec![0.0; n];
        }
        let sub = ((wn * self.dt / SPRING_STEP).ceil() as usize).clamp(LOAD_SUBSTEPS, 4096);
        let spring = Coupling::Spring {
            k: wn * wn,
            c: 2.0 * zeta * wn,
        };
        self.second_difference(&self.load_angle(|_| spring, sub, 0.0))
    }

    /// The load-dependent friction's whole torque per unit `μ`, `|drive|·sgn(ω)` (modelled
    /// drive, zero while stuck): what its size is measured on.
    pub fn load_friction_torque(&self) -> Vec<f64> {
        self.drive_model
            .iter()
            .zip(&self.omega)
            .map(|(d, w)| {
                if w.abs() < self.stick_speed() {
                    0.0
                } else {
                    d.abs() * smooth_sign(*w, self.velocity_eps())
                }
            })
            .collect()
    }

    /// `true` within `guard` samples of a standstill (|ω| below [`Self::stick_speed`]) or of
    /// a change of the velocity's sign.
    pub fn near_reversal(&self, guard: usize) -> Vec<bool> {
        let n = self.len();
        let stuck = self.stuck();
        let mut near = vec![false; n];
        for k in 0..n {
            let flips = k > 0 && self.omega[k].signum() != self.omega[k - 1].signum();
            if stuck[k] || flips {
                let hi = (k + guard + 1).min(n);
                near[k.saturating_sub(guard)..hi].fill(true);
            }
        }
        near
    }

    /// Static friction while stuck: it balances the drive, `drive·1[stuck]` (in volts, the
    /// input, when the torque equation is written in volts).
    pub fn stick_column(&self) -> Vec<f64> {
        let drive = if self.i.is_some() {
            &self.raw_u
        } else {
            &self.drive
        };
        drive
            .iter()
            .zip(self.stuck())
            .map(|(d, s)| if s { *d } else { 0.0 })
            .collect()
    }

    /// Breakaway lag: friction above the static curve right after the rotor starts moving,
    /// decaying with time constant `tau` (LuGre: σ1/σ0): `sgn(ω)·exp(−t_moving/τ)`.
    pub fn breakaway_column(&self, tau: f64) -> Vec<f64> {
        let stuck = self.stuck();
        let mut since = f64::INFINITY;
        let mut last_sign = 0.0;
        self.omega
            .iter()
            .zip(stuck)
            .map(|(w, st)| {
                if st || w.signum() != last_sign {
                    since = 0.0;
                } else {
                    since += self.dt;
                }
                if !st {
                    last_sign = w.signum();
                }
                if st {
                    0.0
                } else {
                    w.signum() * (-since / tau).exp()
                }
            })
            .collect()
    }
}

/// The saturation candidate's columns less their least-squares fit by `instruments`, the
/// base columns computed on the model's own noise-free run (rows as the test sees them).
///
/// Its column is computed on that run too, and where the current's magnitude holds still
/// it is the run's friction level: a noise-free copy of the speed the base only has as it
/// was measured (through the angle's rounding). Beside the measured one, such a copy lets a
/// fit separate the speed from its reading's error, which the torque residual carries, and
/// names that error a saturation. What the model's own columns make of the run carries no
/// such copy, so only the part of `K_t·I³` the model cannot produce on its own run is tested.
///
/// A column the run's base columns span (the part left is below [`SPANNED`] of the column)
/// becomes zero, and a candidate with nothing left is dropped: the test's scaling to unit
/// norm would otherwise blow the rounding up into a direction of its own.
pub fn saturation_beyond_run(
    cand: &mut Vec<(Variant, Vec<Vec<f64>>)>,
    instruments: &[Option<Vec<f64>>],
) {
    let inst: Vec<&[f64]> = instruments.iter().flatten().map(|z| z.as_slice()).collect();
    if inst.is_empty() {
        return;
    }
    let norm = |c: &[f64]| c.iter().map(|x| x * x).sum::<f64>().sqrt();
    cand.retain_mut(|(v, cols)| {
        if v.kind != EffectKind::Saturation {
            return true;
        }
        let left: Vec<(Vec<f64>, bool)> = cols
            .iter()
            .map(|c| {
                let r = crate::numerics::least_squares::lstsq(&inst, c).resid;
                if norm(&r) > SPANNED * norm(c) {
                    (r, true)
                } else {
                    (vec![0.0; r.len()], false)
                }
            })
            .collect();
        let any = left.iter().any(|(_, k)| *k);
        *cols = left.into_iter().map(|(r, _)| r).collect();
        any
    });
}

/// The share of a column below which what is left after its least-squares fit by other
/// columns counts as spanned: the ridge-regularised solve leaves about 1e-9 of a spanned
/// column, and a coefficient fitted on a part a millionth of the column would carry a
/// standard error a million times that of the column itself, no estimate at all.
pub const SPANNED: f64 = 1e-6;

/// Value of a grid parameter in a variant (`harmonic=7`, `vs=3`, `tau=20`).
pub type Fixed = Vec<(&'static str, f64)>;

/// One way to add an effect: its sample-level columns in one equation, with the values of its
/// nonlinear parameters fixed.
#[derive(Debug, Clone)]
pub struct Variant {
    pub kind: EffectKind,
    pub equation: Equation,
    pub fixed: Fixed,
    pub columns: Vec<Vec<f64>>,
    /// The effect's torque per unit coefficient when it is not the columns' own (load
    /// friction: its column is only the part the base cannot absorb): its size is measured on
    /// this.
    pub torque: Option<Vec<f64>>,
}

impl Variant {
    /// A variant whose size is measured on its own columns.
    pub fn new(
        kind: EffectKind,
        equation: Equation,
        fixed: Fixed,
        columns: Vec<Vec<f64>>,
    ) -> Variant {
        Variant {
            kind,
            equation,
            fixed,
            columns,
            torque: None,
        }
    }
}

/// Every variant of an effect on these signals (empty when the effect cannot show in them,
/// e.g. electrical effects on a torque plant): the effect's grid
/// ([`crate::effects::Diagnose::variants`]).
pub fn variants(kind: EffectKind, s: &Signals) -> Vec<Variant> {
    (effects::of(kind).diagnose.variants)(s)
}

/// Columns that stand for an effect the model already has (its nonlinear parameters taken
/// from the model), in its equation; empty for effects with no column.
pub fn present_columns(e: &Effect<f64>, s: &Signals) -> Vec<(Equation, Vec<f64>)> {
    (effects::of(e.kind()).diagnose.present)(e, s)
}

/// Parameters of the physical unit system the spec needs (fitted in the base equations).
#[derive(Debug, Clone, Copy)]
pub struct Units {
    /// Winding resistance R [Ω] (from the voltage equation's fit).
    pub r: f64,
    /// Torque constant K_t [N·m/A].
    pub kt: f64,
    /// Factor from a torque-equation coefficient to N·m (K_t/R when the torque equation is
    /// written in volts, 1 for a torque plant).
    pub mech_scale: f64,
}

/// The spec of an effect from a variant's fitted coefficients.
pub fn spec_of(v: &Variant, beta: &[f64], units: Units) -> EffectSpec {
    let mut values = BTreeMap::new();
    for (k, x) in &v.fixed {
        values.insert(k.to_string(), *x);
    }
    let scale = if v.equation == Equation::Mechanical {
        units.mech_scale
    } else {
        1.0
    };
    let b: Vec<f64> = (0..beta.len().max(2))
        .map(|k| beta.get(k).copied().unwrap_or(0.0) * scale)
        .collect();
    (effects::of(v.kind).diagnose.keys)(&b, units, &mut values);
    EffectSpec {
        kind: v.kind,
        values,
    }
}

#[cfg(test)]
mod tests {
    // Tolerances of 1e-12 compare a column with its closed form: float rounding.
    use super::*;

    /// Signals with the given velocity and modelled drive (the other fields only sized).
    fn signals(omega: &[f64], drive_model: &[f64]) -> Signals {
        let n = omega.len();
        Signals {
            dt: 0.012,
            t: (0..n).map(|k| k as f64 * 0.012).collect(),
            u: vec![0.0; n],
            raw_u: vec![0.0; n],
            i: None,
            theta: vec![0.0; n],
            theta_s: vec![0.0; n],
            theta_torque: vec![0.0; n],
            theta_torque_var: vec![0.0; n],
            omega: omega.to_vec(),
            drive: drive_model.to_vec(),
            drive_model: drive_model.to_vec(),
            plant: Plant::Torque,
            kt: 1.0,
            hall_resolution: None,
            vscale: 1.0,
            velocity_half: 4,
        }
    }

    #[test]
    fn load_friction_column_is_the_braking_part_of_the_drive() {
        // 0..40 motoring forward, 40..60 braking forward, 60..100 motoring forward, then
        // reversed: 100..140 braking backward, 140..200 motoring backward, 200..210 stuck.
        let n = 210;
        let omega: Vec<f64> = (0..n)
            .map(|k| match k {
                0..100 => 20.0,
                100..200 => -20.0,
                _ => 0.2,
            })
            .collect();
        let drive: Vec<f64> = (0..n)
            .map(|k| match k {
                40..60 | 100..140 => -0.4 * omega[k].signum(),
                _ => 0.3 * omega[k].signum(),
            })
            .collect();
        let s = signals(&omega, &drive);
        let col = s.load_friction_column();
        let guard = samples_for(LOAD_FRICTION_GUARD_S, s.dt, s.len());
        assert_eq!(guard, 16);
        for k in 0..n {
            let near_reversal = (100 - guard..=100 + guard).contains(&k) || k + guard >= 200;
            let want = if near_reversal {
                0.0
            } else if drive[k] * omega[k] < 0.0 {
                // Braking: friction keeps opposing the motion while the drive changes sign.
                -2.0 * drive[k]
            } else {
                // Motoring: the friction μ·|drive| is μ·drive, which the base takes up.
                0.0
            };
            assert!(
                (col[k] - want).abs() < 1e-12,
                "sample {k}: {} vs {want}",
                col[k]
            );
        }
        assert!(col[50] > 0.0 && col[130] < 0.0, "both directions brake");
        // Away from reversals, with the base's drive column it spans μ·|drive|·sgn(ω), the
        // effect's torque, which is what its size is measured on.
        let torque = s.load_friction_torque();
        let mu = 0.05;
        for k in [10, 50, 130, 170] {
            let effect = mu * drive[k].abs() * omega[k].signum();
            assert!((mu * drive[k] + mu * col[k] - effect).abs() < 1e-12);
            assert!((mu * torque[k] - effect).abs() < 1e-12);
        }
        assert_eq!(torque[205], 0.0, "stuck");
    }

    /// The saturation candidate keeps only what the run's base columns cannot make: a
    /// column they span (a friction level and a speed, block by block) projects to zero, and
    /// a part orthogonal to them stays whole; other candidates are left alone.
    #[test]
    fn saturation_is_tested_beyond_the_runs_own_columns() {
        let n = 120;
        let level: Vec<f64> = (0..n).map(|k| if k < 60 { 1.0 } else { -1.0 }).collect();
        let speed: Vec<f64> = (0..n).map(|k| 2.0 + (k / 20) as f64).collect();
        // Orthogonal to both: alternating signs, even within each block of 20.
        let other: Vec<f64> = (0..n)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let spanned: Vec<f64> = (0..n).map(|k| 0.3 * level[k] + 0.05 * speed[k]).collect();
        let with_other: Vec<f64> = (0..n).map(|k| spanned[k] + 0.01 * other[k]).collect();
        let v = |kind| Variant::new(kind, Equation::Mechanical, vec![], vec![]);
        let mut cand = vec![
            (v(EffectKind::Saturation), vec![spanned.clone(), with_other]),
            (v(EffectKind::Offset), vec![spanned.clone()]),
        ];
        let inst = vec![Some(level), None, Some(speed)];
        saturation_beyond_run(&mut cand, &inst);
        // The least-squares ridge leaves about 1e-9 of a spanned column.
        assert!(
            cand[0].1[0].iter().all(|x| x.abs() < 1e-6),
            "{:?}",
            cand[0].1[0]
        );
        for (x, o) in cand[0].1[1].iter().zip(&other) {
            assert!((x - 0.01 * o).abs() < 1e-6, "{x} against {}", 0.01 * o);
        }
        assert_eq!(cand[1].1[0], spanned, "not a saturation column");
        // A candidate the run's columns span whole is not tested at all.
        let mut only_spanned = vec![(v(EffectKind::Saturation), vec![spanned.clone()])];
        saturation_beyond_run(&mut only_spanned, &inst);
        assert!(only_spanned.is_empty());
    }

    /// The interval column of a voltage plant: the interval's mean drive from the held
    /// voltage and the angle increment; braking beyond the velocity resolution counts.
    #[test]
    fn load_friction_intervals_use_the_held_voltage_and_the_angle_increment() {
        let (kt, r, kb, dt) = (0.0713, 0.216, 0.0713, 0.012);
        let n = 200;
        // ±50 rad/s, reversing at sample 100 (back-EMF 3.565 V).
        let omega: Vec<f64> = (0..n).map(|k| if k < 100 { 50.0 } else { -50.0 }).collect();
        let mut s = signals(&omega, &vec![0.0; n]);
        s.plant = Plant::Voltage;
        s.kt = kt;
        s.i = Some(vec![0.0; n]);
        s.hall_resolution = Some(0.0952);
        s.theta = (0..n)
            .map(|k| 50.0 * dt * (k.min(100) as f64) - 50.0 * dt * (k.saturating_sub(100) as f64))
            .collect();
        // Motoring (5 V), braking hard (1 V), braking less than the velocity resolution
        // (3.4 V: −0.054 N·m against a resolution of 0.19 N·m), then backward braking (−1 V).
        s.raw_u = (0..n)
            .map(|k| match k {
                0..30 => 5.0,
                30..50 => 1.0,
                50..100 => 3.4,
                _ => -1.0,
            })
            .collect();
        let (col, torque) = s.load_friction_intervals(kb, r);
        let drive = |v: f64, w: f64| kt / r * (v - kb * w);
        assert_eq!(col[10], 0.0, "motoring");
        assert!((torque[10] - drive(5.0, 50.0)).abs() < 1e-12);
        assert!((col[40] + 2.0 * drive(1.0, 50.0)).abs() < 1e-12);
        // 0.5 N·m: well beyond the velocity resolution's 0.19 N·m (the column is 1.69).
        assert!(col[40] > 0.5, "hard braking forward: {}", col[40]);
        assert!((torque[40] - drive(1.0, 50.0).abs()).abs() < 1e-12);
        assert_eq!(col[60], 0.0, "braking within the velocity resolution");
        let guard = samples_for(LOAD_FRICTION_GUARD_S, dt, usize::MAX);
        for k in 100 - guard - 1..=100 + guard {
            assert_eq!(
                (col[k], torque[k]),
                (0.0, 0.0),
                "sample {k} near the reversal"
            );
        }
        assert!((col[150] + 2.0 * drive(-1.0, -50.0)).abs() < 1e-12);
        assert!(col[150] < -0.5, "hard braking backward: {}", col[150]);
        assert_eq!(col[n - 1], 0.0, "no interval after the last sample");
    }
}
