//! The 12 ms control step the firmware (and the emulator) calls.
//!
//! One [`ControlStep::step`] does, in order:
//! 1. Hall decoding of the edges captured since the last step (each edge through the
//!    [`HallDecoder`], its direction and timestamp to the velocity estimator), then of the
//!    present Hall state; faults are flagged.
//! 2. Angle θ = steps·2π/(6·pole_pairs); velocity ω from the chosen estimator. Periodic
//!    position terms (cogging, position load) see θ within one revolution (exact in f32).
//!    The SINDYc model's angle x is θ itself, unwrapped: the angle the board logs (Hall
//!    steps since the run started), which is the angle the fit's library sees
//!    ([`crate::sindy::TermInputs::x`]).
//! 3. Current: the measured current corrected by `current_offset` effects.
//! 4. Friction F_f: the observer (none / LuGre / SINDYc), driven by the speed reference
//!    (reference-based compensation, its reasons where the step calls the observer; the LuGre
//!    torque without its σ1·ż pulse, see [`LugreObserver::step_compensation`]), plus the torque of every torque
//!    effect of the configuration.
//! 5. Compensation `V_c = L·dI_c/dt + R·I_c`, `I_c = F_f/K_t` (R scaled by the heat state of
//!    a `thermal` effect), plus the voltage lost to `deadtime`.
//! 6. `V = PI(ω_ref − ω) + g·V_c + V_deadtime` (`g` the compensation weight
//!    [`StepConfig::comp_gain`]), or the open-loop override in experiment mode, held in the
//!    voltage window [`current_window`]: `[K_b·ω − R·i_limit, K_b·ω + R·i_limit]` [V]
//!    (K_b [V·s/rad], ω [rad/s], R [Ω] the plain winding resistance, i_limit [A]),
//!    tightened by the measured current's window [`measured_current_window`]
//!    `u_prev + g·R·(±i_limit − I)`, intersected with ±min(u_max, V_bus). The window is standing: it bounds every command,
//!    so the current limit holds while the motor keeps running. The PI's anti-windup sees
//!    the window (no integration while the command is held at an edge and the error pushes
//!    further).
//!
//! No allocation; per step the transcendental calls are those of the observer and the
//! effects (LuGre: 2 exp; the paper's SINDYc model: a few tanh), the rest is arithmetic.
use num_traits::Float;
use serde::{Deserialize, Serialize};

use crate::compensation::{CompParams, Compensator};
use crate::effects::{self, Effect, EffectInputs};
use crate::hall::{self, HallDecoder, HallFault, HallTable};
use crate::lugre::{LugreObserver, LugreParams};
use crate::motor::MotorParams;
use crate::pi::{saturate, Pi, PiParams};
use crate::sindy::{SindyModel, SindyObserver};
use crate::velocity::{Estimator, EstimatorConfig, VelocityEstimator};

/// Top speed the Hall edge queue is sized for [rad/s]: the paper's motor unloaded at the
/// board's largest voltage, `MAX_DUTY·RATED_VBUS_MAX/K_b` = 0.95 · 28 V / 0.0713 V·s/rad
/// = 373 rad/s (3560 rpm).
pub const RATED_SPEED_RAD_S: f32 =
    crate::board::MAX_DUTY * crate::blob::RATED_VBUS_MAX / (7.91 / 111.0);
/// Pole pairs the Hall edge queue is sized for: the paper's motor.
pub const RATED_POLE_PAIRS: u16 = crate::hall::PAPER_POLE_PAIRS;
/// Hall edges per second at [`RATED_SPEED_RAD_S`]: `ω/(2π)·pole pairs·6` = 3920 /s.
pub const RATED_EDGE_RATE: f32 =
    RATED_SPEED_RAD_S / core::f32::consts::TAU * RATED_POLE_PAIRS as f32 * 6.0;
/// Hall edges one step can take: the edges of one 12 ms period at [`RATED_EDGE_RATE`]
/// (47.0) with half again as margin for speed ripple and a late period, 71. A motor with
/// more pole pairs reaches the same edge rate at a lower speed, `RATED_EDGE_RATE·2π/(6·pp)`.
/// More edges in one period are counted as lost (`crate::telemetry::Telemetry::edges_lost`)
/// and stop a run ([`Faults::EDGE_OVERFLOW`]).
pub const MAX_EDGES: usize = (RATED_EDGE_RATE * crate::CONTROL_PERIOD_S * 1.5) as usize + 1;
/// Highest speed [rad/s] of a motor with `pole_pairs` whose Hall edges the capture queue
/// holds: [`RATED_EDGE_RATE`]·2π/(6·pole_pairs) (373 rad/s with 11 pole pairs).
pub fn rated_speed(pole_pairs: u16) -> f32 {
    RATED_EDGE_RATE * core::f32::consts::TAU / (6.0 * f32::from(pole_pairs.max(1)))
}
/// Effects a configuration can carry.
pub const MAX_EFFECTS: usize = 8;
/// The velocity estimator's angle reference moves after this many Hall steps (4096 steps are
/// 390 rad with 11 pole pairs, where an f32 keeps 3e-5 rad resolution).
const REBASE_STEPS: u32 = 4096;

/// One Hall edge: the capture timer count and the Hall state after the edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct HallEdge {
    pub ticks: u32,
    pub state: u8,
}

/// Which friction observer runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ObserverConfig<F> {
    /// No observer: friction from the effect terms only.
    None,
    Lugre(LugreParams<F>),
    Sindy(SindyModel<F>),
}

/// Everything the step needs, serialisable (the coefficient blob carries it or converts into
/// it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(deserialize = "F: Deserialize<'de> + Copy + Default"))]
pub struct StepConfig<F> {
    pub motor: MotorParams<F>,
    pub pole_pairs: u16,
    pub hall_table: HallTable,
    pub estimator: EstimatorConfig<F>,
    pub observer: ObserverConfig<F>,
    /// Effects added on top of the observer (do not repeat what the observer models, e.g.
    /// Coulomb friction with a LuGre observer).
    pub effects: heapless::Vec<Effect<F>, MAX_EFFECTS>,
    /// Speed PI gains, anti-windup; its limits are replaced by ±min(`u_max`, V_bus) every step.
    pub pi: PiParams<F>,
    /// Voltage limit of the command [V] (the blob's `u_max`); non-finite or ≤ 0: V_bus only.
    pub u_max: F,
    /// Current limit [A] of the voltage window [`current_window`]; infinite: none.
    pub i_limit: F,
    /// Nominal bus voltage [V], used when the measured one is missing or invalid.
    pub v_bus: F,
    /// Time constant [s] of the filtered derivative of I_c.
    pub tau_d: F,
    /// Control period [s].
    pub dt: F,
    /// Weight of the friction compensation voltage added to the loop output: 0 = none
    /// (friction is estimated and reported but not compensated, the paper's uncompensated
    /// baseline), 1 = full compensation `V_c` of eq. 40, values between scale it.
    pub comp_gain: F,
}

impl<F: Float> StepConfig<F> {
    /// The paper's setup: its motor, 11 pole pairs, 120° Hall sensors, moving average of 10
    /// samples, LuGre observer with its identified parameters, 24 V bus, 12 ms.
    /// Not from the paper (it gives no values): PI kp = 0.05 V/(rad/s), ki = 0.8 V/rad —
    /// a closed loop of ≈ 0.3 s, slow against the 60 ms delay of the moving average — and
    /// τ_d = 24 ms (two periods) for the derivative filter.
    pub fn paper() -> Self {
        let c = |x: f64| F::from(x).unwrap();
        StepConfig {
            motor: MotorParams::paper(),
            pole_pairs: hall::PAPER_POLE_PAIRS,
            hall_table: HallTable::DEFAULT_120,
            estimator: EstimatorConfig::paper(),
            observer: ObserverConfig::Lugre(LugreParams::paper()),
            effects: heapless::Vec::new(),
            pi: PiParams::new(c(0.05), c(0.8), c(24.0)),
            u_max: c(24.0),
            i_limit: F::infinity(),
            v_bus: c(24.0),
            tau_d: c(0.024),
            dt: F::from(crate::CONTROL_PERIOD_S).unwrap(),
            comp_gain: F::one(),
        }
    }
}

/// Inputs of one step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StepInputs<F> {
    /// Present Hall state (bit 0 = A, bit 1 = B, bit 2 = C).
    pub hall: u8,
    /// Hall edges captured since the previous step, oldest first.
    pub edges: heapless::Vec<HallEdge, MAX_EDGES>,
    /// More edges came than `edges` holds (the count is then wrong): flagged as a fault.
    pub edges_overflow: bool,
    /// Capture-timer count at this sample (same timer as the edges).
    pub now_ticks: u32,
    /// Measured winding current [A].
    pub i_meas: F,
    /// Measured bus voltage [V] (non-finite or ≤ 0: the configured nominal value).
    pub v_bus: F,
    /// Speed reference [rad/s].
    pub omega_ref: F,
    /// Experiment mode: apply this voltage open loop (saturated at ±V_bus) instead of the PI.
    pub v_override: Option<F>,
    /// Voltage [V] the bridge applied over the period that ended, whose current `i_meas` is
    /// (`None`: the bridge was off; the window then rests on the motor model alone, see
    /// [`measured_current_window`]).
    pub v_applied: Option<F>,
}

/// Fault and status flags of one step (bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Faults(pub u16);

impl Faults {
    /// A Hall state 000/111 (or unmapped) was seen.
    pub const HALL_INVALID: u16 = 1 << 0;
    /// A jump to a non-adjacent sector was seen.
    pub const HALL_JUMP: u16 = 1 << 1;
    /// More Hall edges than [`MAX_EDGES`] in one step.
    pub const EDGE_OVERFLOW: u16 = 1 << 2;
    /// A non-finite input (current, reference, override) was replaced by 0.
    pub const NONFINITE_INPUT: u16 = 1 << 3;
    /// The measured bus voltage was invalid; the nominal one was used.
    pub const BUS_INVALID: u16 = 1 << 4;
    /// The voltage command is saturated at ±min(u_max, V_bus).
    pub const SATURATED: u16 = 1 << 5;
    /// The friction estimate was not finite; it was replaced by 0 and the observer reset.
    pub const OBSERVER_RESET: u16 = 1 << 6;
    /// The command is held at an edge of the current window `K_b·ω ± R·i_limit` (the
    /// current limit acts; see [`current_window`]).
    pub const CURRENT_LIMIT: u16 = 1 << 7;
    /// The model's window `K_b·ω ± R·i_limit` and the measured-current window do not
    /// overlap: the command was bounded by the measured one alone.
    pub const MODEL_MISMATCH: u16 = 1 << 8;
    /// The measured current flows against the voltage that drives it
    /// ([`current_sign_implausible`]): the command was bounded by the model's window alone.
    /// Set with [`Faults::MODEL_MISMATCH`] when the two windows are also disjoint: then
    /// either the sense or the model's constants are wrong, and the board stops at once.
    pub const CURRENT_SENSE: u16 = 1 << 9;

    pub fn contains(self, flag: u16) -> bool {
        self.0 & flag != 0
    }
    fn set(&mut self, flag: u16) {
        self.0 |= flag;
    }
}

/// Outputs of one step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StepOutputs<F> {
    /// Voltage command [V].
    pub v_cmd: F,
    /// Decoded angle [rad] (steps·step angle; loses resolution in f32 after very long runs:
    /// `steps` is exact).
    pub theta: F,
    /// Hall steps counted since start (signed, exact).
    pub steps: i32,
    /// Estimated velocity [rad/s].
    pub omega: F,
    /// Estimated friction torque F_f [N·m] (observer + torque effects).
    pub friction: F,
    /// Compensation voltage added to the loop output, `g·V_c` [V] (`g` =
    /// [`StepConfig::comp_gain`]; 0 when compensation is off).
    pub v_comp: F,
    /// Observer state z (0 without observer).
    pub z: F,
    pub faults: Faults,
}

#[derive(Debug, Clone, PartialEq)]
enum Observer<F> {
    None,
    Lugre(LugreObserver<F>),
    Sindy(SindyObserver<F>),
}

/// The control step with its state.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlStep<F> {
    motor: MotorParams<F>,
    dt: F,
    v_bus_nominal: F,
    u_max: F,
    /// Current limit now [A] (lowered by [`ControlStep::set_current_limit`]).
    i_limit: F,
    /// The configured current limit [A] ([`StepConfig::i_limit`]), before any lowering.
    i_rated: F,
    /// Weight of the compensation voltage (see [`StepConfig::comp_gain`]).
    comp_gain: F,
    decoder: HallDecoder,
    estimator: Estimator<F>,
    observer: Observer<F>,
    effects: heapless::Vec<Effect<F>, MAX_EFFECTS>,
    /// Heat states of the `thermal` effects (one per effect slot).
    heat: [F; MAX_EFFECTS],
    pi: Pi<F>,
    comp: Compensator<F>,
    /// Voltage commanded at the previous step (the SINDYc model's u).
    u_prev: F,
    /// Back-EMF measured at the previous step, `u_applied − R·I` [V] (`None`: the bridge
    /// was off), for the trend of [`MeasuredCurrent::emf_trend`].
    emf_meas: Option<F>,
    /// Step count the estimator's angle is relative to.
    steps_ref: i32,
    step_angle: F,
    /// Velocity resolution of the estimator [rad/s] (see [`estimator_resolution`]).
    v_res: F,
}

/// Velocity resolution of an estimator [rad/s]: one Hall step `step` [rad] over the moving
/// average's window (10 × 12 ms: 0.79 rad/s with 11 pole pairs), or over the edge-timing
/// estimator's timeout (the slowest speed it reports before it says standstill).
pub fn estimator_resolution<F: Float>(cfg: &EstimatorConfig<F>, step: F, dt: F) -> F {
    let span = match *cfg {
        EstimatorConfig::MovingAverage { window } => F::from(window.max(1)).unwrap() * dt,
        EstimatorConfig::EdgeTiming { timeout_s, .. } => timeout_s,
    };
    if span.is_finite() && span > F::zero() {
        step / span
    } else {
        F::zero()
    }
}

/// The voltage window [V] that keeps the winding current within a limit: `[emf − r_i,
/// emf + r_i]` intersected with `[−lim, lim]`, for the back-EMF `emf = K_b·ω` [V], the
/// limit's resistive drop `r_i = R·i_limit` [V] and the voltage limit `lim` [V].
///
/// Exact for the DC-equivalent winding (eq. 2, `L·dI/dt = V − R·I − K_b·ω`) with the
/// voltage held over the period: the current moves monotonically, with time constant L/R,
/// from its value at the period's start towards `(V − K_b·ω)/R`, which the window keeps
/// within ±i_limit, so a current inside the limit stays inside. The rotor's own response
/// to that current lowers |V − K_b·ω| during the period (motoring speeds it up, braking
/// slows it down). What the window does not see is the error of the velocity estimate:
/// `K_b·|ω − ω̂|/R` [A], nor an error of the model's K_b or R: [`measured_current_window`]
/// bounds those. An infinite `r_i` gives `[−lim, lim]`; a window beyond `±lim` (a back-EMF
/// above the voltage limit) collapses onto that edge. A non-finite `emf`, or a NaN `r_i` or
/// `lim`, gives `(0, 0)`: no drive.
pub fn current_window<F: Float>(emf: F, r_i: F, lim: F) -> (F, F) {
    if !(emf.is_finite() && r_i >= F::zero() && lim >= F::zero()) {
        return (F::zero(), F::zero());
    }
    (
        saturate(emf - r_i, -lim, lim),
        saturate(emf + r_i, -lim, lim),
    )
}

/// Gain `g` of the measured-current bound [`measured_current_window`].
///
/// After a change ΔV of the held voltage the current moves by ΔV/R_true, so the bound
/// moves the current from `I` by at most `g·ρ·(±i_limit − I)`, with `ρ = R/R_true` the
/// model's resistance error. It reaches the limit without overshoot while `g·ρ ≤ 1` and
/// converges while `g·ρ < 2`: `g = 0.5` holds the limit with R up to 2× too high (the
/// resistance is the constant identified least well: a cold winding, the cables, the
/// bridge's on-resistance) and converges up to 4×. The price is the current's rise: from
/// `I` it reaches `I + g·(i_limit − I)` in one period, so a step of the current (a speed
/// step, a level change of an experiment signal at speed) takes two or three periods.
pub const MEASURED_CURRENT_GAIN: f32 = 0.5;

/// The measured current's part of the step's voltage window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredCurrent<F> {
    /// Voltage held over the last period [V] (after a period with the bridge off: the
    /// model's back-EMF `K_b·ω̂`, the terminal voltage of an open winding).
    pub u_prev: F,
    /// Current it drove, measured at the period's end [A].
    pub i: F,
    /// Change of the measured back-EMF `u_prev − R·I` over the last period [V] (0 when not
    /// known).
    pub emf_trend: F,
}

/// The voltage window [V] from the measured current: `u_prev + g·R·(±i_limit − I)`, i.e.
/// [`current_window`] around `u_prev − g·R·I` with the half-width `g·R·i_limit`, for the
/// model's resistance `r` [Ω], the limit `i_limit` [A], the gain `g`
/// ([`MEASURED_CURRENT_GAIN`]) and the voltage limit `lim` [V].
///
/// It rests on the measured back-EMF `u_prev − R·I` (the winding's L/R is short against the
/// period), not on the model's `K_b·ω̂`: it holds the current when K_b, the pole pairs or
/// the velocity estimate are wrong, e.g. a load step at speed while the estimate still
/// reports the old speed. A back-EMF that falls while the current is positive (the drive
/// accelerates, so a load slows the rotor) is expected to fall as much again over the next
/// period, and the upper edge moves down by that much; likewise the lower edge for a
/// rising back-EMF under a negative current. Without it a load rising over several
/// periods would keep the current `ΔE/(g·R)` beyond the limit. A change the drive's own
/// current makes (speeding up under a positive current) is not extrapolated: cutting the
/// voltage stops it. The step takes the tighter of this and the model's window.
pub fn measured_current_window<F: Float>(
    m: MeasuredCurrent<F>,
    r: F,
    i_limit: F,
    g: F,
    lim: F,
) -> (F, F) {
    let g_r = g * r;
    let (mut lo, mut hi) = current_window(m.u_prev - g_r * m.i, g_r * i_limit, lim);
    if m.i > F::zero() && m.emf_trend < F::zero() {
        hi = saturate(hi + m.emf_trend, -lim, lim);
        lo = saturate(lo, -lim, hi);
    } else if m.i < F::zero() && m.emf_trend > F::zero() {
        lo = saturate(lo + m.emf_trend, -lim, lim);
        hi = saturate(hi, lo, lim);
    }
    (lo, hi)
}

/// Smallest current [fraction of i_limit] [`current_sign_implausible`] counts as flowing:
/// a quarter of the limit, far above the current sense's offset and noise (tens of mA) and
/// above the current's change within a period from the rotor's acceleration, which the
/// quasi-static model `(u − K_b·ω̂)/R` does not follow.
pub const SENSE_SIGNIFICANCE: f32 = 0.25;
/// Relative error of the model's back-EMF `K_b·ω̂` [`current_sign_implausible`] allows: its
/// own size. A blob's K_b or pole pairs off by any factor above 1 (the model's back-EMF too
/// high), or by up to 2 below, and the moving average's lag while the speed changes, then
/// never make a correct current look implausible; the measured-current window, which
/// bounds the current in those cases, stays in force.
pub const EMF_TOLERANCE: f32 = 1.0;

/// The measured current `i` [A] flows against the voltage that drives it, significantly:
/// an inverted current sense (or a blob's K_b far off the motor's).
///
/// The model's driving voltage over the last period is `e = u_prev − K_b·ω̂` [V]
/// (`u_prev` the applied voltage, `emf = K_b·ω̂` the model's back-EMF); the winding's L/R
/// is short against the period, so the current at its end has the sign of the true driving
/// voltage (eq. 2 held over the period). `e` is trusted where it exceeds its error,
/// [`EMF_TOLERANCE`]`·|emf| + emf_res` (`emf_res` = K_b times one estimator resolution),
/// by the resistive drop of a significant current `R·i_sig`, `i_sig` =
/// [`SENSE_SIGNIFICANCE`]`·i_limit` (the step passes its configured limit, not one lowered
/// with the board temperature, which near the trip would bring `i_sig` down to the noise); the measurement contradicts it when `i` flows the
/// other way by more than `i_sig`. With the sense inverted, the measured-current window
/// would feed the current back positively (it grows by `1 + g` a period); with the model's
/// window alone it stays at `i_limit`. The check speaks where the drive, not the back-EMF,
/// sets the current: from standstill and at low speed, where every run starts; at speed
/// (`|u_prev| < 2·|emf|`) it stays silent and the `i_max` trip remains the stop.
/// Non-finite inputs or an infinite limit: false.
pub fn current_sign_implausible<F: Float>(
    u_prev: F,
    emf: F,
    emf_res: F,
    i: F,
    r: F,
    i_limit: F,
) -> bool {
    let i_sig = F::from(SENSE_SIGNIFICANCE).unwrap() * i_limit;
    let e = u_prev - emf;
    let e_err = F::from(EMF_TOLERANCE).unwrap() * emf.abs() + emf_res.abs();
    e.abs() > e_err + r * i_sig && i * e.signum() < -i_sig
}

impl<F: Float> ControlStep<F> {
    pub fn new(cfg: &StepConfig<F>) -> Self {
        let step = hall::step_angle::<F>(cfg.pole_pairs);
        let observer = match &cfg.observer {
            ObserverConfig::None => Observer::None,
            ObserverConfig::Lugre(p) => Observer::Lugre(LugreObserver::new(*p)),
            ObserverConfig::Sindy(m) => Observer::Sindy(SindyObserver::new(m.clone())),
        };
        let dt = if cfg.dt.is_finite() && cfg.dt > F::zero() {
            cfg.dt
        } else {
            F::from(crate::CONTROL_PERIOD_S).unwrap()
        };
        ControlStep {
            motor: cfg.motor,
            dt,
            v_bus_nominal: cfg.v_bus.abs(),
            u_max: if cfg.u_max.is_finite() && cfg.u_max > F::zero() {
                cfg.u_max
            } else {
                F::infinity()
            },
            i_limit: if cfg.i_limit > F::zero() {
                cfg.i_limit
            } else {
                F::infinity()
            },
            i_rated: if cfg.i_limit > F::zero() {
                cfg.i_limit
            } else {
                F::infinity()
            },
            comp_gain: if cfg.comp_gain.is_finite() && cfg.comp_gain > F::zero() {
                cfg.comp_gain
            } else {
                F::zero()
            },
            decoder: HallDecoder::new(cfg.hall_table, cfg.pole_pairs),
            estimator: Estimator::from_config(&cfg.estimator, step, dt),
            observer,
            effects: cfg.effects.clone(),
            heat: [F::zero(); MAX_EFFECTS],
            pi: Pi::new(cfg.pi),
            comp: Compensator::new(CompParams {
                kt: cfg.motor.kt,
                r: cfg.motor.r,
                l: cfg.motor.l,
                tau_d: cfg.tau_d,
            }),
            u_prev: F::zero(),
            emf_meas: None,
            steps_ref: 0,
            step_angle: step,
            v_res: estimator_resolution(&cfg.estimator, step, dt),
        }
    }

    /// Current limit [A] (see [`StepConfig::i_limit`]).
    pub fn current_limit(&self) -> F {
        self.i_limit
    }

    /// Changes the current limit [A] (e.g. lowered with the board temperature); zero holds
    /// the voltage at the back-EMF, so that no current flows.
    pub fn set_current_limit(&mut self, i_limit: F) {
        self.i_limit = if i_limit >= F::zero() {
            i_limit
        } else {
            F::zero()
        };
    }

    /// Velocity estimate of the last step [rad/s].
    pub fn omega(&self) -> F {
        self.estimator.omega()
    }

    /// A new run from wherever the rotor is: the position count restarts at the present
    /// sector, the observer, the compensation filter and the PI start again, but the
    /// velocity estimate (and the heat state) go on: the rotor may still turn, and the
    /// current window needs its back-EMF from the first period on. The PI's integral starts
    /// at that back-EMF `K_b·ω̂`, the voltage that drives no current (a bumpless start).
    pub fn restart(&mut self) {
        let rel = self.decoder.steps().wrapping_sub(self.steps_ref);
        self.decoder.restart_count();
        self.steps_ref = self.decoder.steps();
        self.estimator
            .rebase(F::from(rel).unwrap() * self.step_angle);
        match &mut self.observer {
            Observer::None => {}
            Observer::Lugre(o) => o.reset(),
            Observer::Sindy(o) => o.reset(),
        }
        self.comp.reset();
        self.pi.reset();
        let emf = self.motor.kb * self.estimator.omega();
        if emf.is_finite() {
            self.pi.integral = emf;
        }
        self.u_prev = F::zero();
        self.emf_meas = None;
    }

    /// Back to rest: position count, estimator, observer, PI, compensation, heat.
    pub fn reset(&mut self) {
        self.decoder.reset();
        self.estimator.reset();
        match &mut self.observer {
            Observer::None => {}
            Observer::Lugre(o) => o.reset(),
            Observer::Sindy(o) => o.reset(),
        }
        self.heat = [F::zero(); MAX_EFFECTS];
        self.pi.reset();
        self.comp.reset();
        self.u_prev = F::zero();
        self.emf_meas = None;
        self.steps_ref = 0;
    }

    /// The Hall decoder (angle, step count, fault count).
    pub fn decoder(&self) -> &HallDecoder {
        &self.decoder
    }

    /// The speed PI (integral, saturation).
    pub fn pi(&self) -> &Pi<F> {
        &self.pi
    }

    fn hall_fault(faults: &mut Faults, f: Option<HallFault>) {
        match f {
            Some(HallFault::InvalidState) => faults.set(Faults::HALL_INVALID),
            Some(HallFault::ImpossibleJump) => faults.set(Faults::HALL_JUMP),
            None => {}
        }
    }

    /// One control step: the stages of the module docs, in order.
    pub fn step(&mut self, inp: &StepInputs<F>) -> StepOutputs<F> {
        let mut faults = Faults::default();
        // 1-2. Hall edges, present state, angle, velocity.
        let pos = self.position(inp, &mut faults);
        // 3. Current corrected for the sensor offset (measured = I + i0).
        let current =
            finite_or_flag(inp.i_meas, &mut faults) - effects::total_sensor_offset(&self.effects);
        let omega_ref = finite_or_flag(inp.omega_ref, &mut faults);
        let v_bus = self.bus_voltage(inp.v_bus, &mut faults);
        // 4. Friction: observer + torque effects.
        let (friction, z) = self.friction(&pos, omega_ref, current, &mut faults);
        // 5. Compensation voltage and the dead time's loss.
        let (v_comp, ff) = self.feed_forward(friction, current, v_bus);
        // 6. PI with feed-forward, or the open-loop override, within the voltage window.
        let lim = if self.u_max < v_bus {
            self.u_max
        } else {
            v_bus
        };
        let (lo, hi) = self.voltage_window(inp.v_applied, pos.omega, current, lim, &mut faults);
        let v_cmd = self.command(
            inp.v_override,
            omega_ref - pos.omega,
            ff,
            (lo, hi, lim),
            &mut faults,
        );
        StepOutputs {
            v_cmd,
            theta: pos.theta,
            steps: pos.steps,
            omega: pos.omega,
            friction,
            v_comp,
            z,
            faults,
        }
    }

    /// Stages 1-2: the Hall edges and the present state through the decoder, the angle and
    /// the velocity estimate.
    #[inline(always)]
    fn position(&mut self, inp: &StepInputs<F>, faults: &mut Faults) -> Position<F> {
        if inp.edges_overflow {
            faults.set(Faults::EDGE_OVERFLOW);
        }
        for e in &inp.edges {
            let u = self.decoder.update(e.state);
            Self::hall_fault(faults, u.fault);
            if u.dir != 0 {
                self.estimator.on_edge(e.ticks, u.dir);
            }
        }
        let u = self.decoder.update(inp.hall);
        Self::hall_fault(faults, u.fault);
        if u.dir != 0 {
            // A change without a captured edge: time it at the sample.
            self.estimator.on_edge(inp.now_ticks, u.dir);
        }
        let steps = self.decoder.steps();
        // The estimator sees the angle relative to a reference re-based every REBASE_STEPS
        // steps, so that f32 angle differences stay exact over long runs.
        let rel = steps.wrapping_sub(self.steps_ref);
        if rel.unsigned_abs() >= REBASE_STEPS {
            self.steps_ref = steps;
            self.estimator
                .rebase(F::from(rel).unwrap() * self.step_angle);
        }
        let theta_rel = F::from(steps.wrapping_sub(self.steps_ref)).unwrap() * self.step_angle;
        Position {
            steps,
            theta: self.decoder.angle(),
            // Periodic position terms see the angle within one revolution (exact in f32);
            // the SINDYc model sees the unwrapped angle, as the fit does (module docs).
            theta_rev: self.decoder.angle_in_rev(),
            omega: self.estimator.update(theta_rel, inp.now_ticks),
        }
    }

    /// The measured bus voltage, or the nominal one (flagged) when it is not valid.
    #[inline(always)]
    fn bus_voltage(&self, v_bus: F, faults: &mut Faults) -> F {
        if v_bus.is_finite() && v_bus > F::zero() {
            v_bus
        } else {
            faults.set(Faults::BUS_INVALID);
            self.v_bus_nominal
        }
    }

    /// Stage 4: the friction torque F_f [N·m] (observer + torque effects) and the
    /// observer's state z; a non-finite estimate resets the observer.
    #[inline(always)]
    fn friction(
        &mut self,
        pos: &Position<F>,
        omega_ref: F,
        current: F,
        faults: &mut Faults,
    ) -> (F, F) {
        let dt = self.dt;
        // The velocity the friction observer integrates: the speed reference ω_ref.
        //
        // This is reference-based (feed-forward) friction compensation, a deliberate departure
        // from the paper, which fed its observer the measured velocity (feedback compensation).
        // The paper's moving-average estimate lags by half its 120 ms window (≈ 60 ms) and resolves
        // only one Hall step per window, 0.79 rad/s ([`estimator_resolution`]): near a reversal it
        // reports the old direction or zero, so an observer driven by it switches the friction sign
        // late and then compensates the wrong way. ω_ref has neither lag nor quantisation, and the PI
        // keeps ω near ω_ref, so it is the best available predictor of the velocity friction acts
        // at. Measured on the emulated paper motor with its true LuGre parameters (`motorid
        // emulate`, sine reference, low-speed RMS error; none: 1.51 rad/s): observer on ω_ref
        // 0.66 rad/s; on ω_ref moved toward ω̂ by at most the estimator's resolution 0.89 rad/s.
        // Because ω_ref is exact there is nothing to fade near zero speed: at ω_ref = 0 the LuGre
        // state holds (ż = 0) and the compensation keeps its last value, below static friction.
        let v_obs = omega_ref;
        let (f_obs, z) = match &mut self.observer {
            Observer::None => (F::zero(), F::zero()),
            Observer::Lugre(o) => (o.step_compensation(v_obs, dt), o.z),
            Observer::Sindy(o) => (o.step(pos.theta, v_obs, current, self.u_prev, dt), o.z),
        };
        let ex = EffectInputs {
            theta: pos.theta_rev,
            omega: pos.omega,
            current,
            kt: self.motor.kt,
        };
        let mut friction = f_obs + effects::total_torque(&self.effects, &ex);
        if !friction.is_finite() {
            faults.set(Faults::OBSERVER_RESET);
            friction = F::zero();
            match &mut self.observer {
                Observer::None => {}
                Observer::Lugre(o) => o.reset(),
                Observer::Sindy(o) => o.reset(),
            }
        }
        (friction, z)
    }

    /// Stage 5: the weighted compensation voltage `g·V_c` [V] (R follows the heat state of
    /// a thermal effect), and the whole feed-forward with the dead time's loss [V].
    #[inline(always)]
    fn feed_forward(&mut self, friction: F, current: F, v_bus: F) -> (F, F) {
        let dt = self.dt;
        let mut heat = F::zero();
        for (h, e) in self.heat.iter_mut().zip(self.effects.iter()) {
            if let Effect::Thermal { .. } = e {
                *h = e.heat_step(*h, current, dt);
                if !h.is_finite() {
                    *h = F::zero();
                }
                heat = heat + *h;
            }
        }
        self.comp.params.r = self.motor.r * (F::one() + heat);
        let v_comp = if self.comp_gain > F::zero() {
            self.comp_gain * self.comp.step(friction, dt, v_bus).v_c
        } else {
            F::zero()
        };
        let v_dead = effects::total_voltage_loss(&self.effects, current);
        let ff = v_comp
            + if v_dead.is_finite() {
                v_dead
            } else {
                F::zero()
            };
        (v_comp, ff)
    }

    /// Stage 6a: the voltage window [V] within the limit `lim` from the model
    /// ([`current_window`]) and from the measured current ([`measured_current_window`]),
    /// the tighter of both, or the one to trust when they contradict each other.
    #[inline(always)]
    fn voltage_window(
        &mut self,
        v_applied: Option<F>,
        omega: F,
        current: F,
        lim: F,
        faults: &mut Faults,
    ) -> (F, F) {
        // The model's window uses the plain winding resistance: the heat state of a thermal
        // effect is fitted, may be of either sign, and would widen or invert the window.
        let emf = self.motor.kb * omega;
        let (lo, hi) = current_window(emf, self.motor.r * self.i_limit, lim);
        // After a period with the bridge off the terminal voltage was the back-EMF, which
        // only the model knows.
        let r = self.motor.r;
        let (u_prev, emf_meas) = match v_applied {
            Some(u) if u.is_finite() => (u, Some(u - r * current)),
            _ => (emf, None),
        };
        let emf_trend = match (emf_meas, self.emf_meas) {
            (Some(e), Some(p)) => e - p,
            _ => F::zero(),
        };
        self.emf_meas = emf_meas;
        let measured = MeasuredCurrent {
            u_prev,
            i: current,
            emf_trend,
        };
        let (lo_m, hi_m) = measured_current_window(
            measured,
            r,
            self.i_limit,
            F::from(MEASURED_CURRENT_GAIN).unwrap(),
            lim,
        );
        // The tighter of both; where they do not overlap the measurement wins over the
        // model, whole: the model's constants (K_b, pole pairs) disagree with the motor.
        // A measured current against its driving voltage is not trusted: the model's
        // window alone bounds the command.
        // The significance is that of the configured limit: a limit lowered with the board
        // temperature would bring it down to the sense's noise.
        let i_sig_limit = if self.i_rated.is_finite() && self.i_rated > self.i_limit {
            self.i_rated
        } else {
            self.i_limit
        };
        let sense_implausible = emf_meas.is_some()
            && current_sign_implausible(
                u_prev,
                emf,
                self.motor.kb * self.v_res,
                current,
                r,
                i_sig_limit,
            );
        let disjoint = hi < lo_m || lo > hi_m;
        if sense_implausible {
            faults.set(Faults::CURRENT_SENSE);
            if disjoint {
                // Neither window can be trusted: the board stops at once.
                faults.set(Faults::MODEL_MISMATCH);
            }
            (lo, hi)
        } else if disjoint {
            faults.set(Faults::MODEL_MISMATCH);
            (lo_m, hi_m)
        } else {
            (saturate(lo, lo_m, hi_m), saturate(hi, lo_m, hi_m))
        }
    }

    /// Stage 6b: the voltage command [V] in the window `(lo, hi)` within `lim`: the PI on the
    /// speed error `err` with the feed-forward `ff`, or the open-loop override.
    #[inline(always)]
    fn command(
        &mut self,
        v_override: Option<F>,
        err: F,
        ff: F,
        (lo, hi, lim): (F, F, F),
        faults: &mut Faults,
    ) -> F {
        self.pi.set_limits(lo, hi);
        let v_cmd = match v_override {
            Some(v) => {
                let v = saturate(finite_or_flag(v, faults), lo, hi);
                // Bumpless return to closed loop: the integral takes what the PI would need.
                let p = self.pi.params;
                self.pi.integral = saturate(v - p.kp * err - ff, lo, hi);
                v
            }
            None => self.pi.step_ff(err, ff, self.dt),
        };
        let v_cmd = if v_cmd.is_finite() {
            v_cmd
        } else {
            // Only a non-finite gain in the configuration gets here.
            faults.set(Faults::NONFINITE_INPUT);
            self.pi.reset();
            F::zero()
        };
        if v_cmd.abs() >= lim {
            faults.set(Faults::SATURATED);
        } else if v_cmd <= lo || v_cmd >= hi {
            faults.set(Faults::CURRENT_LIMIT);
        }
        self.u_prev = v_cmd;
        v_cmd
    }
}

/// The rotor's position and speed from stages 1-2 of [`ControlStep::step`].
struct Position<F> {
    /// Hall steps since the start (exact).
    steps: i32,
    /// Unwrapped angle [rad].
    theta: F,
    /// Angle within one revolution [rad].
    theta_rev: F,
    /// Velocity estimate [rad/s].
    omega: F,
}

/// `x`, or 0 with [`Faults::NONFINITE_INPUT`] set when it is not finite.
#[inline(always)]
fn finite_or_flag<F: Float>(x: F, faults: &mut Faults) -> F {
    if x.is_finite() {
        x
    } else {
        faults.set(Faults::NONFINITE_INPUT);
        F::zero()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::hall::hall_state_for_angle;
    use crate::lugre;
    use crate::sindy::{SparseEq, Term};
    use proptest::prelude::*;
    use std::vec::Vec;

    /// A DC motor with LuGre friction, integrated finely (exact LuGre update, 0.1 ms steps),
    /// producing Hall states and edges for the control step.
    struct Motor {
        m: MotorParams<f64>,
        lg: LugreParams<f64>,
        theta: f64,
        omega: f64,
        i: f64,
        z: f64,
        t_ticks: u64,
    }

    const HZ: f64 = 1.0e6;

    impl Motor {
        fn new() -> Self {
            Motor {
                m: MotorParams::paper(),
                lg: LugreParams::paper(),
                theta: 0.01,
                omega: 0.0,
                i: 0.0,
                z: 0.0,
                t_ticks: 0,
            }
        }
        /// Apply `v` for 12 ms; returns the step inputs of the next sample.
        fn run(&mut self, v: f64, omega_ref: f64, table: &HallTable) -> StepInputs<f64> {
            let h = 1e-4;
            let mut inp = StepInputs {
                v_bus: 24.0,
                omega_ref,
                ..Default::default()
            };
            let mut state = hall_state_for_angle(self.theta, 11, table);
            for _ in 0..120 {
                // Current: exact first-order update with ω held.
                let a = (-self.m.r * h / self.m.l).exp();
                let i_ss = (v - self.m.kb * self.omega) / self.m.r;
                self.i = i_ss + (self.i - i_ss) * a;
                let (zn, zd) = lugre::z_step(&self.lg, self.z, self.omega, h);
                self.z = zn;
                let ff = self.lg.friction_at(self.omega, zn, zd);
                self.omega += h * (self.m.kt * self.i - ff) / self.m.j;
                self.theta += h * self.omega;
                self.t_ticks += (h * HZ) as u64;
                let s = hall_state_for_angle(self.theta, 11, table);
                if s != state {
                    state = s;
                    let _ = inp.edges.push(HallEdge {
                        ticks: self.t_ticks as u32,
                        state: s,
                    });
                }
            }
            inp.hall = state;
            inp.now_ticks = self.t_ticks as u32;
            inp.i_meas = self.i;
            inp
        }
    }

    fn closed_loop(cfg: &StepConfig<f64>, omega_ref: f64, steps: usize) -> (f64, f64, Faults) {
        let mut ctl = ControlStep::new(cfg);
        let mut motor = Motor::new();
        let mut v = 0.0;
        let mut faults = Faults::default();
        let mut err_sum = 0.0;
        for k in 0..steps {
            let inp = motor.run(v, omega_ref, &cfg.hall_table);
            let out = ctl.step(&inp);
            v = out.v_cmd;
            faults.0 |= out.faults.0;
            if k >= steps - 100 {
                err_sum += (motor.omega - omega_ref).abs();
            }
        }
        (motor.omega, err_sum / 100.0, faults)
    }

    #[test]
    fn closed_loop_tracks_speed_with_both_estimators() {
        let mut cfg = StepConfig::<f64>::paper();
        for est in [
            EstimatorConfig::paper(),
            EstimatorConfig::EdgeTiming {
                tick_hz: HZ,
                timeout_s: 0.1,
            },
        ] {
            cfg.estimator = est;
            let (w, mean_err, faults) = closed_loop(&cfg, 40.0, 600);
            assert!(
                mean_err < 0.02 * 40.0,
                "{est:?}: ω = {w}, mean |err| {mean_err}"
            );
            assert!(!faults.contains(Faults::HALL_INVALID | Faults::HALL_JUMP));
        }
    }

    #[test]
    fn compensation_reports_friction_and_voltage() {
        let cfg = StepConfig::<f64>::paper();
        let mut ctl = ControlStep::new(&cfg);
        let mut motor = Motor::new();
        let mut v = 0.0;
        let mut out = StepOutputs::default();
        for _ in 0..600 {
            let inp = motor.run(v, 40.0, &cfg.hall_table);
            out = ctl.step(&inp);
            v = out.v_cmd;
        }
        // In steady motion the observer's friction is the steady LuGre friction at ω̂ and
        // V_c = R·F_f/K_t (dI_c/dt ≈ 0).
        let p = LugreParams::<f64>::paper();
        let want = p.steady_friction(out.omega);
        assert!(
            (out.friction - want).abs() < 0.01 * want,
            "{} vs {want}",
            out.friction
        );
        let m = MotorParams::<f64>::paper();
        assert!((out.v_comp - m.r * out.friction / m.kt).abs() < 0.05);
        // With compensation off, v_comp is 0 but friction is still reported.
        let mut off = cfg.clone();
        off.comp_gain = 0.0;
        let mut ctl = ControlStep::new(&off);
        let o = ctl.step(&motor.run(v, 40.0, &off.hall_table));
        assert_eq!(o.v_comp, 0.0);
    }

    #[test]
    fn comp_gain_weights_the_compensation_voltage() {
        // The same inputs through a full and a weighted compensation: the added voltage
        // scales with the weight, the friction estimate does not.
        let inputs: Vec<StepInputs<f64>> = {
            let cfg = StepConfig::<f64>::paper();
            let mut ctl = ControlStep::new(&cfg);
            let mut motor = Motor::new();
            let mut v = 0.0;
            (0..300)
                .map(|_| {
                    let inp = motor.run(v, 40.0, &cfg.hall_table);
                    v = ctl.step(&inp).v_cmd;
                    inp
                })
                .collect()
        };
        let run = |g: f64| {
            let mut cfg = StepConfig::<f64>::paper();
            cfg.comp_gain = g;
            let mut ctl = ControlStep::new(&cfg);
            let mut last = StepOutputs::default();
            for inp in &inputs {
                last = ctl.step(inp);
            }
            last
        };
        let full = run(1.0);
        assert!(full.v_comp.abs() > 0.1, "{}", full.v_comp);
        for g in [0.0, 0.25, 0.5, 0.75] {
            let o = run(g);
            assert!((o.friction - full.friction).abs() < 1e-12 * full.friction.abs().max(1.0));
            assert!(
                (o.v_comp - g * full.v_comp).abs() < 1e-9,
                "g = {g}: {} vs {}",
                o.v_comp,
                g * full.v_comp
            );
        }
    }

    #[test]
    fn observer_follows_reference_and_resolution_is_one_step_per_window() {
        let step = hall::step_angle::<f64>(11);
        let r = estimator_resolution(&EstimatorConfig::paper(), step, 0.012);
        assert!(
            (r - step / 0.12).abs() < 1e-12 && (r - 0.793).abs() < 1e-3,
            "{r}"
        );
        let et = EstimatorConfig::EdgeTiming {
            tick_hz: HZ,
            timeout_s: 0.1,
        };
        assert!((estimator_resolution(&et, step, 0.012) - step / 0.1).abs() < 1e-12);
    }

    #[test]
    fn compensation_voltage_has_no_spikes_at_reversals() {
        // A 10 rad/s, 0.5 Hz sine reference reverses the motor every second. V_c must stay
        // at the level of R·s_max/K_t (≈ 0.3 V) plus the small L·dI_c/dt, not the ≈ 4 V
        // pulses the σ1·ż term would give; and it must change sign with the reference.
        let cfg = StepConfig::<f64>::paper();
        let mut ctl = ControlStep::new(&cfg);
        let mut motor = Motor::new();
        let (mut v, mut vc_max, mut agree, mut moving) = (0.0, 0.0f64, 0, 0);
        for k in 0..500 {
            let w_ref = 10.0 * (core::f64::consts::PI * k as f64 * 0.012).sin();
            let inp = motor.run(v, w_ref, &cfg.hall_table);
            let out = ctl.step(&inp);
            v = out.v_cmd;
            vc_max = vc_max.max(out.v_comp.abs());
            if w_ref.abs() > 1.0 {
                moving += 1;
                if out.v_comp * w_ref > 0.0 {
                    agree += 1;
                }
            }
        }
        let m = MotorParams::<f64>::paper();
        let p = LugreParams::<f64>::paper();
        let level = m.r * (p.s_max() + p.alpha2 * 10.0) / m.kt;
        assert!(vc_max < 1.5 * level, "max |V_c| {vc_max} vs {level}");
        assert!(vc_max > 0.8 * level, "max |V_c| {vc_max} vs {level}");
        assert!(agree > moving * 9 / 10, "{agree} of {moving}");
    }

    #[test]
    fn override_and_faults() {
        let cfg = StepConfig::<f64>::paper();
        let mut ctl = ControlStep::new(&cfg);
        let inp = StepInputs {
            hall: 7,
            v_bus: 12.0,
            v_override: Some(30.0),
            i_meas: f64::NAN,
            ..Default::default()
        };
        let out = ctl.step(&inp);
        assert_eq!(out.v_cmd, 12.0);
        assert!(out.faults.contains(Faults::HALL_INVALID));
        assert!(out.faults.contains(Faults::SATURATED));
        assert!(out.faults.contains(Faults::NONFINITE_INPUT));
        let mut inp = StepInputs {
            hall: 1,
            v_bus: -1.0,
            ..Default::default()
        };
        ctl.step(&inp);
        inp.hall = 6;
        let out = ctl.step(&inp);
        assert!(out.faults.contains(Faults::HALL_JUMP));
        assert!(out.faults.contains(Faults::BUS_INVALID));
    }

    #[test]
    fn effects_enter_friction_voltage_and_current() {
        let mut cfg = StepConfig::<f64>::paper();
        cfg.observer = ObserverConfig::None;
        cfg.effects
            .extend_from_slice(&[
                Effect::Offset { t0: 0.05 },
                Effect::CurrentOffset { i0: 0.5 },
                Effect::Deadtime { vd: 0.4 },
            ])
            .unwrap();
        cfg.pi = PiParams::new(0.0, 0.0, 24.0);
        cfg.tau_d = 0.0;
        let mut ctl = ControlStep::new(&cfg);
        let inp = StepInputs {
            hall: 1,
            v_bus: 24.0,
            i_meas: 2.5, // true current 2.0 A
            ..Default::default()
        };
        let out = ctl.step(&inp);
        assert!((out.friction - 0.05).abs() < 1e-12);
        let m = MotorParams::<f64>::paper();
        let v_c = m.r * 0.05 / m.kt;
        assert!((out.v_comp - v_c).abs() < 1e-12);
        // Dead time follows sgn(I) of the corrected current (+2 A): +0.4 V.
        assert!((out.v_cmd - (v_c + 0.4)).abs() < 1e-9);
        let inp = StepInputs {
            i_meas: 0.5 - 2.0, // true current −2 A
            ..inp
        };
        let out = ctl.step(&inp);
        assert!((out.v_cmd - (v_c - 0.4)).abs() < 1e-9);
    }

    #[test]
    fn current_window_centres_on_the_back_emf_within_the_voltage_limit() {
        // K_b·ω = 7 V, R·i_limit = 2 V, limit 12 V: 5..9 V, i.e. ±i_limit at steady state.
        assert_eq!(current_window(7.0, 2.0, 12.0), (5.0, 9.0));
        // A back-EMF beyond the voltage limit collapses the window onto that edge.
        assert_eq!(current_window(20.0, 2.0, 12.0), (12.0, 12.0));
        // No current limit: the voltage limit alone.
        assert_eq!(current_window(-3.0, f64::INFINITY, 12.0), (-12.0, 12.0));
    }

    #[test]
    fn a_current_against_its_driving_voltage_is_implausible_only_where_the_drive_dominates() {
        // R = 0.2 Ω, i_limit = 8 A: a significant current is 2 A, its drop 0.4 V.
        let check = |u: f64, emf: f64, i: f64| current_sign_implausible(u, emf, 0.05, i, 0.2, 8.0);
        // At standstill 1.6 V drive 8 A: measured −8 A (an inverted sense) is implausible,
        // +8 A or a small −1 A is not.
        assert!(check(1.6, 0.0, -8.0));
        assert!(check(-1.6, 0.0, 8.0));
        assert!(!check(1.6, 0.0, 8.0));
        assert!(!check(1.6, 0.0, -1.0));
        // A drive too small to say which way the current flows.
        assert!(!check(0.3, 0.0, -8.0));
        // At speed the back-EMF sets the current: a model back-EMF wrong by its own size
        // (K_b twice the motor's) never makes a braking current look implausible.
        assert!(!check(6.0, 14.0, -8.0));
        assert!(!check(14.0, 7.0, 8.0));
        // Non-finite inputs or no current limit: never.
        assert!(!check(f64::NAN, 0.0, -8.0));
        assert!(!current_sign_implausible(
            1.6,
            0.0,
            0.05,
            -8.0,
            0.2,
            f64::INFINITY
        ));
    }

    #[test]
    fn the_current_window_holds_the_command_and_stops_the_integrator() {
        // At standstill with a large speed error the command rises to R·i_limit, by half
        // the remaining distance per period (the measured current's window), not to the
        // 5 V the PI asks (kp·100 rad/s), and the integral does not grow meanwhile.
        let mut cfg = StepConfig::<f64>::paper();
        cfg.observer = ObserverConfig::None;
        cfg.i_limit = 10.0;
        let mut ctl = ControlStep::new(&cfg);
        let r = cfg.motor.r;
        let r_i = r * 10.0;
        let g = f64::from(MEASURED_CURRENT_GAIN);
        let mut inp = StepInputs {
            hall: 1,
            v_bus: 24.0,
            omega_ref: 100.0,
            ..Default::default()
        };
        for k in 0..50 {
            let out = ctl.step(&inp);
            let want = r_i * (1.0 - (1.0 - g).powi(k + 1));
            assert!(
                (out.v_cmd - want).abs() < 1e-9,
                "{k}: {} vs {want}",
                out.v_cmd
            );
            assert!(out.faults.contains(Faults::CURRENT_LIMIT));
            assert!(!out.faults.contains(Faults::SATURATED));
            // A rotor held at standstill: the current is V/R.
            inp.v_applied = Some(out.v_cmd);
            inp.i_meas = out.v_cmd / r;
        }
        assert_eq!(ctl.pi().integral, 0.0);
        // The open-loop override is held the same way.
        let out = ctl.step(&StepInputs {
            v_override: Some(-20.0),
            ..inp
        });
        assert!(out.v_cmd < 0.0 && out.v_cmd >= -r_i, "{}", out.v_cmd);
    }

    #[test]
    fn the_measured_current_holds_the_limit_with_r_twice_too_high() {
        // The model's R is twice the winding's: the model's window alone would allow
        // 2·i_limit at standstill. With the measured current the current rises to the
        // limit without passing it.
        let (r_true, i_limit, lim) = (0.2, 10.0, 24.0);
        let mut i = 0.0;
        let mut u = 0.0;
        for _ in 0..40 {
            let m = MeasuredCurrent {
                u_prev: u,
                i,
                emf_trend: 0.0,
            };
            let (_, hi) = measured_current_window(m, 2.0 * r_true, i_limit, 0.5, lim);
            u = hi;
            i = u / r_true;
            assert!(i <= i_limit * (1.0 + 1e-12), "{i}");
        }
        assert!(i > 0.999 * i_limit, "{i}");
        // A falling back-EMF under a positive current moves the upper edge down by as much.
        let m = MeasuredCurrent {
            u_prev: 10.0,
            i: 5.0,
            emf_trend: -0.5,
        };
        let flat = measured_current_window(
            MeasuredCurrent {
                emf_trend: 0.0,
                ..m
            },
            0.2,
            10.0,
            0.5,
            lim,
        );
        let (lo, hi) = measured_current_window(m, 0.2, 10.0, 0.5, lim);
        assert!((hi - (flat.1 - 0.5)).abs() < 1e-12 && lo == flat.0);
    }

    #[test]
    fn non_finite_window_inputs_and_a_negative_thermal_coefficient_give_no_runaway() {
        assert_eq!(current_window(f64::NAN, 2.0, 12.0), (0.0, 0.0));
        assert_eq!(current_window(f64::INFINITY, 2.0, 12.0), (0.0, 0.0));
        assert_eq!(current_window(3.0, f64::NAN, 12.0), (0.0, 0.0));
        assert_eq!(current_window(3.0, 2.0, f64::NAN), (0.0, 0.0));
        // A fitted thermal effect with a negative coefficient and a large current: R(1 + heat)
        // turns negative, which would invert the window; the window uses the plain R.
        let mut cfg = StepConfig::<f64>::paper();
        cfg.observer = ObserverConfig::None;
        cfg.i_limit = 10.0;
        cfg.effects
            .push(Effect::Thermal { k: -0.5, tau: 0.05 })
            .unwrap();
        let mut ctl = ControlStep::new(&cfg);
        let r_i = cfg.motor.r * 10.0;
        for _ in 0..100 {
            let out = ctl.step(&StepInputs {
                hall: 1,
                v_bus: 24.0,
                i_meas: 9.0,
                v_override: Some(20.0),
                ..Default::default()
            });
            assert!(out.v_cmd.abs() <= r_i + 1e-12, "{}", out.v_cmd);
        }
    }

    #[test]
    fn edge_queue_holds_a_period_at_the_rated_speed() {
        let per_period = RATED_EDGE_RATE * crate::CONTROL_PERIOD_S;
        assert!(
            (RATED_SPEED_RAD_S - 373.0).abs() < 1.0,
            "{RATED_SPEED_RAD_S}"
        );
        assert!((per_period - 47.0).abs() < 0.5, "{per_period}");
        assert!(MAX_EDGES as f32 >= 1.5 * per_period, "{MAX_EDGES}");
        assert!((MAX_EDGES as f32) < 1.5 * per_period + 2.0, "{MAX_EDGES}");
        assert!((rated_speed(RATED_POLE_PAIRS) - RATED_SPEED_RAD_S).abs() < 1e-3);
        assert!((rated_speed(4) - RATED_SPEED_RAD_S * 11.0 / 4.0).abs() < 1e-2);
    }

    #[test]
    fn f32_velocity_stays_exact_after_long_runs() {
        // 30 edges per 12 ms for 150 000 steps: 4.5 million Hall steps, θ ≈ 4.3e5 rad, where
        // an f32 angle alone resolves only 0.03 rad (0.25 rad/s over the 0.12 s window).
        let mut cfg = StepConfig::<f32>::paper();
        cfg.observer = ObserverConfig::None;
        let mut ctl = ControlStep::new(&cfg);
        let table = HallTable::DEFAULT_120;
        let mut sector = 0u8;
        let mut out = StepOutputs::default();
        for _ in 0..150_000 {
            let mut inp = StepInputs::<f32> {
                v_bus: 24.0,
                ..Default::default()
            };
            for _ in 0..30 {
                sector = (sector + 1) % 6;
                inp.edges
                    .push(HallEdge {
                        ticks: 0,
                        state: table.state_of(sector).unwrap(),
                    })
                    .unwrap();
            }
            inp.hall = table.state_of(sector).unwrap();
            out = ctl.step(&inp);
        }
        assert_eq!(out.steps, 4_500_000);
        let want = 30.0 * hall::step_angle::<f64>(11) / 0.012;
        let rel = (out.omega as f64 - want).abs() / want;
        assert!(rel < 2e-6, "ω = {} vs {want}: {rel:e}", out.omega);
    }

    fn paper_like_sindy() -> SindyModel<f64> {
        let mut m = SindyModel::empty(20.0, 3.0, 3e-4);
        m.z_max = 2.0;
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -5.0),
            (Term::Z, -100.0),
            (Term::I, 237.0),
            (Term::TanhXdot, -250.0),
            (Term::AbsXdotXdot, -0.01),
            (Term::AbsZZ, 3.0),
            (Term::ZU, 0.5),
        ])
        .unwrap();
        m.zdot = SparseEq::from_slice(&[
            (Term::Xdot, 1.0),
            (Term::Z, -30.0),
            (Term::TanhXdot, 0.2),
            (Term::TanhZ, -5.0),
            (Term::AbsXdotXdot, 1e-3),
            (Term::AbsZZ2, -10.0),
        ])
        .unwrap();
        m
    }

    fn xorshift(s: &mut u64) -> u64 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn ten_thousand_random_steps_stay_finite(seed in 1u64..u64::MAX, which in 0usize..6, scale in 0.0f64..1e4) {
            let mut cfg = StepConfig::<f64>::paper();
            cfg.observer = match which % 3 {
                0 => ObserverConfig::None,
                1 => ObserverConfig::Lugre(LugreParams::paper()),
                _ => ObserverConfig::Sindy(paper_like_sindy()),
            };
            if which >= 3 {
                cfg.estimator = EstimatorConfig::EdgeTiming { tick_hz: 1.7e8, timeout_s: 0.05 };
                cfg.effects.extend_from_slice(&[
                    Effect::Coulomb { fc: 0.02 },
                    Effect::Cogging { harmonic: 22, amp: 0.01, phase: 0.3 },
                    Effect::Thermal { k: 0.01, tau: 30.0 },
                    Effect::Deadtime { vd: 0.3 },
                    Effect::LoadFriction { mu: 0.05 },
                ]).unwrap();
            }
            let mut ctl = ControlStep::new(&cfg);
            let mut s = seed;
            let r = |s: &mut u64| (xorshift(s) as f64 / u64::MAX as f64) * 2.0 - 1.0;
            let mut ticks = 0u32;
            for _ in 0..10_000 {
                let mut inp = StepInputs::<f64> {
                    hall: (xorshift(&mut s) % 8) as u8,
                    i_meas: r(&mut s) * scale,
                    v_bus: r(&mut s) * 30.0,
                    omega_ref: r(&mut s) * scale,
                    ..Default::default()
                };
                let n_edges = xorshift(&mut s) % 6;
                for _ in 0..n_edges {
                    ticks = ticks.wrapping_add((xorshift(&mut s) % 400_000) as u32);
                    let _ = inp.edges.push(HallEdge { ticks, state: (xorshift(&mut s) % 8) as u8 });
                }
                ticks = ticks.wrapping_add((xorshift(&mut s) % 3_000_000) as u32);
                inp.now_ticks = ticks;
                if xorshift(&mut s).is_multiple_of(10) {
                    inp.v_override = Some(r(&mut s) * 50.0);
                }
                let out = ctl.step(&inp);
                for v in [out.v_cmd, out.theta, out.omega, out.friction, out.v_comp, out.z] {
                    prop_assert!(v.is_finite());
                }
                let bus = if inp.v_bus > 0.0 { inp.v_bus } else { cfg.v_bus };
                prop_assert!(out.v_cmd.abs() <= bus);
            }
        }
    }
}
