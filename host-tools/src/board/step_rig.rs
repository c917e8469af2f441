//! The firmware's control step alone (no link, modes or storage: those are
//! [`super::emulated_board`]): the step ([`control::step::ControlStep`], in f32
//! as on the STM32G431) driving the emulated motor ([`crate::emulator::Plant`]) through the
//! board's sensors, one 12 ms period at a time.
//!
//! Per period, as the firmware's control task does: read the Hall state, the Hall edges
//! captured since the last period (stamped by a 1 MHz capture timer, [`TICK_HZ`]) and the
//! current; run the step; hold its voltage for the period.
use crate::emulator::{EmulatorConfig, Plant};
use anyhow::Result;
use control::step::{ControlStep, HallEdge, StepConfig, StepInputs, StepOutputs, MAX_EDGES};

/// Capture-timer frequency [Hz] (the firmware's embassy tick rate, tick-hz-1_000_000).
pub const TICK_HZ: f64 = control::blob::Coefficients::CAPTURE_TICK_HZ as f64;

/// Capture-timer count at time `t` [s] (a free-running u32 counter that wraps).
fn ticks_at(t: f64) -> u32 {
    ((t * TICK_HZ).round() as u64 & u64::from(u32::MAX)) as u32
}
/// What one period did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigSample {
    /// Time at the start of the period [s].
    pub t: f64,
    /// Speed reference [rad/s].
    pub omega_ref: f64,
    /// The step's outputs (voltage command, decoded angle, velocity estimate, friction...).
    pub out: StepOutputs<f32>,
    /// Measured current the step saw [A].
    pub i_meas: f64,
    /// True velocity at the start of the period [rad/s].
    pub omega_true: f64,
    /// True angle at the start of the period [rad].
    pub theta_true: f64,
}

/// Plant + control step + timer.
pub struct Rig {
    plant: Plant,
    ctl: ControlStep<f32>,
    dt: f64,
    t: f64,
    /// Hall edges captured during the running period, for the next step (more than
    /// [`MAX_EDGES`] is reported as an overflow, as the firmware's capture buffer does).
    pending: Vec<HallEdge>,
    /// Every step's inputs, when recording (for the QEMU parity trace).
    pub recorded: Option<Vec<StepInputs<f32>>>,
}

impl Rig {
    /// A motor at rest and a control step configured by `cfg`.
    pub fn new(plant: EmulatorConfig, cfg: &StepConfig<f32>) -> Result<Rig> {
        let mut plant = Plant::new(plant)?;
        plant.take_hall_edges(); // start recording edges
        Ok(Rig {
            plant,
            ctl: ControlStep::new(cfg),
            dt: f64::from(cfg.dt),
            t: 0.0,
            pending: Vec::with_capacity(MAX_EDGES),
            recorded: None,
        })
    }

    /// Replace the control step's configuration (a new blob was committed): the step restarts
    /// from rest, the motor keeps turning.
    pub fn reconfigure(&mut self, cfg: &StepConfig<f32>) {
        self.ctl = ControlStep::new(cfg);
        self.dt = f64::from(cfg.dt);
    }

    /// Time [s].
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The emulated motor.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// One control period: closed loop on `omega_ref`, or open loop with `v_override`.
    pub fn step(&mut self, omega_ref: f64, v_override: Option<f64>) -> RigSample {
        let truth = self.plant.truth();
        let i_meas = self.plant.measured_current();
        let mut inp = StepInputs {
            hall: self.plant.hall_state(),
            now_ticks: ticks_at(truth.t),
            i_meas: i_meas as f32,
            v_bus: f32::NAN, // no bus measurement: the configured nominal voltage
            omega_ref: omega_ref as f32,
            v_override: v_override.map(|v| v as f32),
            ..StepInputs::default()
        };
        for e in self.pending.drain(..) {
            if inp.edges.push(e).is_err() {
                inp.edges_overflow = true;
            }
        }
        let out = self.ctl.step(&inp);
        if let Some(rec) = self.recorded.as_mut() {
            rec.push(inp);
        }
        // Hold the command for the period; the capture timer stamps each Hall edge.
        self.plant.apply(f64::from(out.v_cmd), self.dt);
        for e in self.plant.take_hall_edges() {
            self.pending.push(HallEdge {
                ticks: ticks_at(e.t),
                state: e.state,
            });
        }
        let sample = RigSample {
            t: self.t,
            omega_ref,
            out,
            i_meas,
            omega_true: truth.omega,
            theta_true: truth.theta,
        };
        self.t += self.dt;
        sample
    }
}

#[cfg(test)]
mod tests {
    use crate::ident::library::{Library, Signals};
    use crate::log::Plant;
    use control::hall::HallTable;
    use control::sindy::{SindyModel, SparseEq, Term};
    use control::step::{ControlStep, HallEdge, ObserverConfig, StepConfig, StepInputs};

    /// The board's SINDYc observer and the fit's library evaluate the angle terms on the
    /// same angle: the unwrapped one the board logs. Thirty revolutions forward, where an
    /// angle reduced to one revolution would differ by up to 30·2π in `x`.
    #[test]
    fn board_and_fit_evaluate_sindyc_angle_terms_on_the_same_angle() {
        let (b_x, b_sin) = (-0.5f32, 40.0f32);
        let mut m = SindyModel::<f32>::empty(20.0, 3.0, 3.0e-4);
        m.accel =
            SparseEq::from_slice(&[(Term::X, b_x), (Term::SinTheta(3), b_sin), (Term::I, 237.0)])
                .unwrap();
        let mut cfg = StepConfig::<f32>::paper();
        cfg.observer = ObserverConfig::Sindy(m.clone());
        let mut ctl = ControlStep::new(&cfg);
        let table = HallTable::DEFAULT_120;
        let (mut sector, mut ticks) = (0u8, 0u32);
        let (mut theta, mut friction) = (Vec::new(), Vec::new());
        for _ in 0..400 {
            let mut inp = StepInputs::<f32> {
                v_bus: 24.0,
                omega_ref: 40.0,
                ..Default::default()
            };
            for _ in 0..5 {
                sector = (sector + 1) % 6;
                ticks = ticks.wrapping_add(2400);
                let state = table.state_of(sector).unwrap();
                inp.edges.push(HallEdge { ticks, state }).unwrap();
            }
            inp.hall = table.state_of(sector).unwrap();
            inp.now_ticks = ticks;
            let out = ctl.step(&inp);
            theta.push(f64::from(out.theta));
            friction.push(f64::from(out.friction));
        }
        let revs = theta.last().unwrap() / std::f64::consts::TAU;
        // 2000 Hall steps fed are 30.3 revolutions: above 25 the angle followed them.
        assert!(revs > 25.0, "{revs} revolutions");

        // The fit's side: library columns on the logged angle, friction −J·Σ b_k·θ_k (eq. 47).
        let n = theta.len();
        let zeros = vec![0.0; n];
        let s = Signals {
            x: &theta,
            xdot: &zeros,
            z: &zeros,
            i: Some(&zeros),
            u: &zeros,
        };
        let lib = Library::paper(Plant::Voltage, 20.0, 3.0);
        let (mut cx, mut cs) = (vec![0.0; n], vec![0.0; n]);
        lib.column(Term::X, &s, &mut cx);
        lib.column(Term::SinTheta(3), &s, &mut cs);
        for k in 0..n {
            let fit = -3.0e-4 * (f64::from(b_x) * cx[k] + f64::from(b_sin) * cs[k]);
            // 1e-4: the board's f32 against the host's f64 (ε 1.2e-7, over the terms' sums and the
            // observer's state); near a zero crossing, 1e-6 absolute.
            assert!(
                (friction[k] - fit).abs() <= 1e-4 * fit.abs().max(1e-2),
                "sample {k}, θ = {}: board {} vs fit {fit}",
                theta[k],
                friction[k]
            );
        }
    }
}
