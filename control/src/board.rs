//! The board's logic, written once: the command handler, the modes (idle, speed,
//! experiment, commissioning), the limits and the fault logic. The firmware
//! (`firmware/src/main.rs`) and the emulated board
//! (`host-tools/src/board/emulated_board.rs`) both run this [`Board`]; they only move bytes,
//! read sensors and drive the bridge.
//!
//! Per 12 ms period the transport calls [`Board::tick`] with the [`Measurements`] and applies
//! the [`Drive`] it returns; every host message goes to [`Board::handle`] (uploads to
//! [`handle_upload`], which needs the flash). Messages for the host leave through the `send`
//! callback.
//!
//! Limits and faults (each turns the bridge off; faults latch until `ClearFault`):
//! - hardware over-current: the transport's comparators cut the bridge within a PWM period
//!   above [`HW_TRIP_A`] ([`Measurements::hw_overcurrent`]);
//! - over-current: |I| > `limits.i_max`. Below it a standing current limit keeps the motor
//!   running: every command lies in the step's voltage window `K_b·ω ± R·i_limit`,
//!   `i_limit` = [`crate::blob::DERATE_FRACTION`]·i_max ([`crate::step::current_window`]);
//! - over-temperature: the board's NTC at [`TEMP_MAX_C`] or above; from [`TEMP_DERATE_C`]
//!   up the step's current limit falls linearly to zero ([`temperature_derating`]);
//! - bus over-voltage always, under-voltage and control overrun while running;
//! - Hall faults (invalid state, impossible jump, edge overflow) while running;
//! - stall: no Hall step for [`STALL_PERIODS`] while the command is held by the current
//!   limit or above [`STALL_FRACTION`]·u_max;
//! - model mismatch: the step's model and measured-current windows disjoint for
//!   [`MISMATCH_PERIODS`] in a row (the command then follows the measured one alone);
//! - current sense: the measured current flowing against the voltage that drives it
//!   ([`crate::step::current_sign_implausible`]) for [`CURRENT_SENSE_PERIODS`] in a row (an
//!   inverted current sense before commissioning; the command follows the model's window
//!   meanwhile), or in a single period where the model's and the measured windows are also
//!   disjoint (a model's K_b below half the motor's: a braking current; neither window
//!   bounds the current);
//! - over-speed: |ω̂| above [`OVERSPEED_FACTOR`] times the speed limit for
//!   [`OVERSPEED_PERIODS`] in a row;
//! - link loss (a stop, not a fault): no frame for [`LINK_TIMEOUT_PERIODS`] in speed or
//!   experiment mode.
//!
//! Telemetry ([`crate::telemetry`]): the transport reports each period's length, its work in
//! cycles and the lost Hall edges in [`Measurements`]; the board sends one report a second
//! while a run streams samples, and on `ReadTelemetry`.
//!
//! The voltage never exceeds `min(pi.u_max, MAX_DUTY·V_bus)`; speed and experiment modes
//! need valid coefficients (identify and commissioning do not); experiment amplitudes are
//! relative to `u_max` and to `R·i_max`, the smaller ([`crate::excitation`]), and durations
//! are bounded; the speed reference ramps at [`Coefficients::ramp_acceleration`] up to at
//! most [`Coefficients::speed_limit`] (`SetSpeed` beyond it is refused).
use embedded_storage::nor_flash::NorFlash;

use crate::blob::{self, Coefficients, HALL_INVALID, MAX_BLOB_LEN};
use crate::commission::{
    CommissionError, CommissionOutcome, CommissionStep, Commissioner, Commissioning,
};
use crate::excitation;
use crate::frame::{
    BoardMsg, ChunkOutcome, Excitation, Fault, HostMsg, Mode, Nack, Sample, Upload, Warning,
    PROTOCOL_VERSION,
};
use crate::hall::{HallTable, INVALID};
use crate::slots::Slots;
use crate::step::{ControlStep, Faults, HallEdge, StepInputs, StepOutputs, MAX_EDGES};
use crate::telemetry::{LoopStats, PeriodTiming, Telemetry};

/// Phase current at which the hardware stops the bridge within a PWM period [A]: the
/// B-G431B-ESC1's 40 A peak rating (ST UM2516). The firmware sets its comparators' threshold
/// from it, the emulated board trips at it; `limits.i_max` may not exceed it.
pub const HW_TRIP_A: f32 = crate::blob::RATED_I_MAX;
/// Highest bus voltage the board is rated for [V]: the over-voltage threshold of ST's motor
/// control project for the B-G431B-ESC1 (a 6S LiPo pack is 25.2 V fully charged).
/// `limits.vbus_max` may not exceed it.
pub const VBUS_RATING_V: f32 = crate::blob::RATED_VBUS_MAX;
/// Board temperature [°C] from which the current limit is lowered.
pub const TEMP_DERATE_C: f32 = 80.0;
/// Board temperature [°C] at which the bridge stops with [`Fault::OverTemperature`] (the
/// current limit has reached zero here). Conservative for a first spin: the NTC sits on the
/// board, not on the MOSFET junctions.
pub const TEMP_MAX_C: f32 = 100.0;

/// Fraction of the current limit allowed at board temperature `t` [°C]: 1 up to
/// [`TEMP_DERATE_C`], falling linearly to 0 at [`TEMP_MAX_C`]; 1 when the temperature is not
/// measured (non-finite).
pub fn temperature_derating(t: f32) -> f32 {
    if !t.is_finite() || t <= TEMP_DERATE_C {
        1.0
    } else if t >= TEMP_MAX_C {
        0.0
    } else {
        (TEMP_MAX_C - t) / (TEMP_MAX_C - TEMP_DERATE_C)
    }
}

/// Largest duty cycle (95 %, so the bootstrap capacitors of the high-side drivers recharge
/// every PWM period): the largest voltage is `MAX_DUTY·V_bus`.
pub const MAX_DUTY: f32 = 0.95;
/// Longest experiment [s].
pub const MAX_EXPERIMENT_S: f32 = 3600.0;
/// Periods without any frame after which a speed or experiment run stops (2 s).
pub const LINK_TIMEOUT_PERIODS: u32 = 167;
/// Periods with a voltage above the stall threshold and no Hall step before the stall
/// fault (0.6 s).
pub const STALL_PERIODS: u32 = 50;
/// Periods in a row with disjoint model and measured-current windows before the
/// model-mismatch fault (0.3 s: over twice the velocity estimate's 0.12 s average, so a
/// load step's lagging estimate does not trip it).
pub const MISMATCH_PERIODS: u32 = 25;
/// Current-sense fault: the measured current against its driving voltage
/// ([`crate::step::current_sign_implausible`]) this many periods in a row (36 ms; the
/// model's window holds the current at its limit meanwhile).
pub const CURRENT_SENSE_PERIODS: u32 = 3;
/// Over-speed threshold as a multiple of the speed limit ([`Board::speed_limit`]).
pub const OVERSPEED_FACTOR: f32 = 1.25;
/// Periods in a row beyond the over-speed threshold before the over-speed fault (0.1 s).
pub const OVERSPEED_PERIODS: u32 = 8;
/// Stall threshold as a fraction of the voltage limit.
pub const STALL_FRACTION: f32 = 0.5;
/// Commissioning voltage: at most this fraction of the voltage limit...
pub const COMMISSION_U_FRACTION: f32 = 0.25;
/// ...and at most the voltage that drives this fraction of `i_max` (lowered with the board
/// temperature, [`temperature_derating`]) at standstill through the centre vector's path
/// (¾ of the blob's line-to-line R, [`crate::commission::PATH_R_SHARE`]), above the dead
/// time's drop; the measured current then holds the run to this fraction of `i_max` whatever the
/// blob's R ([`crate::commission`]).
pub const COMMISSION_I_FRACTION: f32 = 0.3;

/// PWM carrier frequency of the bridge [Hz] (centre-aligned TIM1).
pub const PWM_HZ: u32 = 20_000;
/// Dead time of the bridge's complementary outputs [ns].
pub const DEAD_TIME_NS: u32 = 500;

/// Voltage [V] the bridge's dead time takes from a vector with a current of one sign, at
/// bus voltage `v_bus` [V]: only the high phases' half-bridges switch (the low phase's low
/// side conducts throughout), and during each of their dead times their diodes clamp them
/// to the rail against the command: `t_d·f_PWM·V_bus` (0.24 V at 500 ns, 20 kHz and
/// 23.5 V), the same for one high phase (six-step) as for two switching together (a
/// [`Drive::Centre`] vector).
pub fn dead_time_drop(v_bus: f32) -> f32 {
    (DEAD_TIME_NS as f32 * 1e-9) * PWM_HZ as f32 * v_bus
}

/// Bridge step (0..5) that drives a rotor in Hall sector `sector`: one vector ahead
/// (forward, positive voltage) or four ahead (reverse, negative voltage). With a
/// commissioned table, sector `k` is centred between the fields of bridge steps `k − 1` and
/// `k` ([`crate::commission`]), so step `k + 1` leads the rotor by 60-120° electrical.
pub fn commutation_step(sector: u8, reverse: bool) -> u8 {
    (sector % 6 + if reverse { 4 } else { 1 }) % 6
}

/// (high phase, low phase) of each bridge step, phases U, V, W numbered 0, 1, 2: the high
/// phase switches with the duty (its low side conducts in the off time), the low phase has
/// its low side on all the time, the third floats (both outputs off). Step `k + 3` is step
/// `k` reversed; neighbouring steps share one phase, in the same role.
pub const BRIDGE_STEPS: [(usize, usize); 6] = [(0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1)];

/// The gate pattern of bridge step `k` (0..5) at compare value `duty`: per phase U, V, W its
/// compare value and whether its outputs are enabled.
pub fn six_step_pattern(k: u8, duty: u16) -> ([u16; 3], [bool; 3]) {
    let (hi, lo) = BRIDGE_STEPS[usize::from(k % 6)];
    let mut ccr = [0; 3];
    let mut enable = [false; 3];
    ccr[hi] = duty;
    enable[hi] = true;
    enable[lo] = true;
    (ccr, enable)
}

/// The sector whose middle the centre vector with low phase `low` (0..2) points at: the
/// one between the two bridge steps whose low phase is `low` (`k` and `k + 1` of
/// [`BRIDGE_STEPS`]), i.e. 4, 0, 2 for U, V, W.
pub fn centre_sector(low: u8) -> u8 {
    (2 * (low % 3) + 4) % 6
}

/// The gate pattern of the centre vector with low phase `low` (0..2) at compare value
/// `duty`: the two other phases switch together with the duty (complementary), `low` has
/// its low side on all the time, all three enabled. The field is the sum of the two bridge
/// steps whose low phase is `low`, 30° electrical from each.
pub fn centre_pattern(low: u8, duty: u16) -> ([u16; 3], [bool; 3]) {
    let low = usize::from(low % 3);
    let mut ccr = [duty; 3];
    ccr[low] = 0;
    (ccr, [true; 3])
}

/// What the bridge does until the next period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// All gates off.
    Off,
    /// Six-step commutation from the Hall state through `table` at every Hall edge
    /// ([`commutation_step`]), duty |volts|/V_bus, reverse for a negative voltage.
    SixStep { volts: f32, table: HallTable },
    /// Hold the centre vector with low phase `low` (0..2, [`centre_pattern`]) at `volts` ≥ 0
    /// whatever the Hall state (commissioning): the rotor rests in the middle of sector
    /// [`centre_sector`]`(low)`; the current flows through both other phases in parallel
    /// and leaves through `low` (its shunt reads it all).
    Centre { low: u8, volts: f32 },
}

/// What the transport measured this period.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Measurements {
    /// Hall state now (bit 0 = H1, bit 1 = H2, bit 2 = H3).
    pub hall: u8,
    /// Hall edges since the last period, oldest first.
    pub edges: heapless::Vec<HallEdge, MAX_EDGES>,
    /// More edges than `edges` holds came.
    pub edges_overflow: bool,
    /// Hall edges lost since boot (the capture queue's running overflow count).
    pub edges_lost: u32,
    /// Time since the previous period started [µs] (not finite: unknown).
    pub period_us: f32,
    /// Cycles the previous period's work took (0: no cycle counter).
    pub step_cycles: u32,
    /// Capture-timer count now.
    pub now_ticks: u32,
    /// Current along the applied bridge vector [A], positive when it flows the way the
    /// applied (positive) duty drives it; the board signs it by the drive's direction and
    /// the commissioned current sign.
    pub i_vector: f32,
    /// Bus voltage [V] (non-finite: not measured, the nominal one is used).
    pub v_bus: f32,
    /// The previous period overran.
    pub overrun: bool,
    /// Board temperature [°C] (the NTC; non-finite: not measured, no limit).
    pub temperature_c: f32,
    /// The hardware over-current stop has cut the bridge (held by the hardware until the
    /// transport clears it after `ClearFault`, see [`Board::handle`]).
    pub hw_overcurrent: bool,
}

#[derive(Debug, Clone, PartialEq)]
enum Run {
    Idle,
    Speed,
    Experiment { signal: Excitation, duration_s: f32 },
    Commission(Commissioner),
}

/// The board's state.
#[derive(Debug, Clone)]
pub struct Board {
    coeffs: Coefficients,
    coeff_seq: u32,
    firmware: &'static str,
    v_bus_nominal: f32,
    step: ControlStep<f32>,
    table: HallTable,
    run: Run,
    /// Speed the host asked for [rad/s] (`SetSpeed`).
    omega_target: f32,
    /// Speed reference of the control step [rad/s]: moves towards `omega_target` at the
    /// ramp's acceleration ([`Coefficients::ramp_acceleration`]).
    omega_ref: f32,
    latched: Option<Fault>,
    seq: u32,
    /// Periods since the run started.
    k: u32,
    /// Periods since the last frame.
    quiet: u32,
    /// Periods in a row at a stall voltage without a Hall step.
    stall: u32,
    /// Periods in a row with disjoint model and measured-current windows.
    mismatch: u32,
    /// Periods in a row beyond the over-speed threshold.
    overspeed: u32,
    /// Periods in a row with the measured current against its driving voltage.
    sense: u32,
    last_steps: i32,
    /// Voltage commanded last period (its sign gives the current's).
    last_volts: f32,
    /// Voltage the bridge applied over the last period (`None`: off or holding a
    /// commissioning vector), for the step's measured-current window.
    applied: Option<f32>,
    /// Speed limit at the bus voltage of the last period [rad/s] ([`Board::speed_limit`]).
    w_max: f32,
    /// Bus voltage of the last period [V] (measured, else the nominal one).
    v_bus: f32,
    /// Current-limit fraction of the last period's board temperature
    /// ([`temperature_derating`]).
    derating: f32,
    /// The hardware over-current stop is armed ([`Board::set_hardware_stop`]; false until
    /// the transport says so).
    hw_stop_armed: bool,
    /// Speed and experiment runs are allowed without it (a firmware built so).
    run_without_hw_stop: bool,
    commission: CommissionOutcome,
    commission_seq: u32,
    store_request: bool,
    stats: LoopStats,
    /// A telemetry window completed in the last period (see [`Board::take_report`]).
    report: Option<Telemetry>,
    /// What the control step returned in the last period.
    last_out: StepOutputs<f32>,
    /// The control step's inputs, filled in place every period: building them anew would
    /// copy the whole edge queue (`MAX_EDGES` edges), not only the edges that came.
    inp: StepInputs<f32>,
}

fn table_of(c: &Coefficients) -> HallTable {
    let mut sector = [INVALID; 8];
    for (s, &b) in sector.iter_mut().zip(&c.hall_table) {
        *s = if b == HALL_INVALID { INVALID } else { b as i8 };
    }
    HallTable { sector }
}

/// The latched fault a step's flags call for (the Hall faults).
pub fn fault_of(f: Faults) -> Option<Fault> {
    if f.contains(Faults::HALL_INVALID) {
        Some(Fault::InvalidHall)
    } else if f.contains(Faults::HALL_JUMP) || f.contains(Faults::EDGE_OVERFLOW) {
        Some(Fault::ImpossibleTransition)
    } else {
        None
    }
}

impl Board {
    /// A board at power-up with the coefficients of flash slot sequence `seq` (`None`: no
    /// valid slot; the defaults run, and only identify and commissioning are allowed).
    /// `firmware` is what `Identify` reports; `v_bus_nominal` [V] is used while the bus is
    /// not measured.
    pub fn new(
        loaded: Option<(Coefficients, u32)>,
        firmware: &'static str,
        v_bus_nominal: f32,
    ) -> Self {
        let (coeffs, seq) = loaded.unwrap_or_default();
        let mut b = Board {
            step: ControlStep::new(&coeffs.step_config(v_bus_nominal)),
            table: table_of(&coeffs),
            coeffs,
            coeff_seq: 0,
            firmware,
            v_bus_nominal,
            run: Run::Idle,
            omega_target: 0.0,
            omega_ref: 0.0,
            latched: None,
            seq: 0,
            k: 0,
            quiet: 0,
            stall: 0,
            mismatch: 0,
            overspeed: 0,
            sense: 0,
            last_steps: 0,
            last_volts: 0.0,
            applied: None,
            w_max: 0.0,
            v_bus: v_bus_nominal,
            derating: 1.0,
            hw_stop_armed: false,
            run_without_hw_stop: false,
            commission: CommissionOutcome::NotRun,
            commission_seq: 0,
            store_request: false,
            stats: LoopStats::new(),
            report: None,
            last_out: StepOutputs::default(),
            inp: StepInputs::default(),
        };
        b.coeff_seq = seq;
        b.w_max = b.coeffs.speed_limit(v_bus_nominal);
        if seq != 0 {
            if let Some(c) = b.coeffs.commission {
                b.commission = CommissionOutcome::Done(c);
                b.commission_seq = seq;
            }
        }
        b
    }

    /// Load newly committed coefficients (flash slot sequence `seq`); any run stops, and
    /// the speed asked for goes back to zero (it was checked against the old limit).
    pub fn load(&mut self, coeffs: Coefficients, seq: u32) {
        self.omega_target = 0.0;
        self.step = ControlStep::new(&coeffs.step_config(self.v_bus_nominal));
        self.table = table_of(&coeffs);
        if let Some(c) = coeffs.commission {
            self.commission = CommissionOutcome::Done(c);
            self.commission_seq = seq;
        }
        self.w_max = coeffs.speed_limit(self.v_bus_nominal);
        self.coeffs = coeffs;
        self.coeff_seq = seq;
        self.run = Run::Idle;
    }

    /// Whether the transport's hardware over-current stop is armed (`armed`; the board
    /// starts out assuming it is not). While it is not, commissioning, speed and experiment
    /// runs are refused (`Nack::NoHardwareStop`) unless
    /// `run_without` says to run on the 12 ms software limit alone. `Identify` reports it.
    pub fn set_hardware_stop(&mut self, armed: bool, run_without: bool) {
        self.hw_stop_armed = armed;
        self.run_without_hw_stop = run_without;
    }

    /// The coefficients in force.
    pub fn coefficients(&self) -> &Coefficients {
        &self.coeffs
    }

    /// Flash slot sequence of the coefficients (0: none, the defaults run).
    pub fn coeff_seq(&self) -> u32 {
        self.coeff_seq
    }

    /// The mode running now.
    pub fn mode(&self) -> Mode {
        match self.run {
            Run::Idle => Mode::Idle,
            Run::Speed => Mode::Speed,
            Run::Experiment { .. } => Mode::Experiment,
            Run::Commission(_) => Mode::Commission,
        }
    }

    /// The latched fault.
    pub fn fault(&self) -> Option<Fault> {
        self.latched
    }

    /// The control step (decoder, PI).
    pub fn control(&self) -> &ControlStep<f32> {
        &self.step
    }

    /// What the control step returned in the last [`Board::tick`] that ran it (every period
    /// but commissioning's).
    pub fn last_step_outputs(&self) -> &StepOutputs<f32> {
        &self.last_out
    }

    /// The voltage limit [V]: `min(u_max, MAX_DUTY·V_bus)`.
    fn u_limit(&self, v_bus: f32) -> f32 {
        let u = self.coeffs.pi.u_max;
        let b = MAX_DUTY * v_bus;
        if u < b {
            u
        } else {
            b
        }
    }

    fn v_bus_of(&self, v: f32) -> f32 {
        if v.is_finite() && v > 0.0 {
            v
        } else {
            self.v_bus_nominal
        }
    }

    /// Largest speed reference `SetSpeed` takes [rad/s] ([`Coefficients::speed_limit`] at
    /// the bus voltage of the last period: measured, or the nominal one while not measured).
    /// The running reference is held within it every period, so a sagging bus lowers it.
    pub fn speed_limit(&self) -> f32 {
        self.w_max
    }

    /// The control step's speed reference now [rad/s] (the ramp towards `SetSpeed`'s).
    pub fn speed_reference(&self) -> f32 {
        self.omega_ref
    }

    /// Starts `run` from wherever the rotor is: the velocity estimate goes on (a rotor still
    /// turning from an earlier run keeps its back-EMF in the current window), and the speed
    /// reference starts at it (bumpless). Only speed mode keeps the speed asked for
    /// (`SetSpeed` before `SetMode`); the other runs drop it.
    fn start(&mut self, run: Run) {
        self.step.restart();
        if run != Run::Speed {
            self.omega_target = 0.0;
        }
        let w_max = self.speed_limit();
        self.omega_ref = crate::pi::saturate(self.step.omega(), -w_max, w_max);
        self.run = run;
        self.seq = 0;
        self.k = 0;
        self.quiet = 0;
        self.stall = 0;
        self.mismatch = 0;
        self.overspeed = 0;
        self.sense = 0;
        self.last_steps = self.step.decoder().steps();
    }

    /// Ends any run; the speed asked for goes back to zero, so that it never carries over
    /// to a later run.
    fn stop(&mut self, send: &mut impl FnMut(BoardMsg)) {
        if let Run::Commission(_) = self.run {
            self.commission = CommissionOutcome::Failed(CommissionError::Aborted);
            send(self.commission_msg());
        }
        self.omega_target = 0.0;
        self.run = Run::Idle;
    }

    fn commission_msg(&self) -> BoardMsg {
        BoardMsg::Commission {
            outcome: self.commission,
            seq: self.commission_seq,
        }
    }

    /// Commissioning current limit [A]: [`COMMISSION_I_FRACTION`] of `i_max`, lowered with
    /// the board temperature of the last period.
    pub fn commission_current(&self) -> f32 {
        COMMISSION_I_FRACTION * self.coeffs.limits.i_max * self.derating
    }

    /// Commissioning voltage [V] at the bus voltage of the last period (see
    /// [`COMMISSION_U_FRACTION`], [`COMMISSION_I_FRACTION`]).
    pub fn commission_volts(&self) -> f32 {
        let u = COMMISSION_U_FRACTION * self.u_limit(self.v_bus);
        let r = crate::commission::PATH_R_SHARE * self.coeffs.motor.r;
        let i = dead_time_drop(self.v_bus) + self.commission_current() * r;
        if i < u {
            i
        } else {
            u
        }
    }

    /// Handles one host message (not the upload messages: `false`, see [`handle_upload`]).
    /// Every frame counts as a sign of life of the link. After a `ClearFault` ([`Board::fault`]
    /// went from some to none) the transport re-arms its hardware over-current stop.
    pub fn handle(&mut self, msg: &HostMsg, send: &mut impl FnMut(BoardMsg)) -> bool {
        self.quiet = 0;
        let reply = match *msg {
            HostMsg::Identify => {
                let mut firmware = heapless::String::new();
                let _ = firmware.push_str(self.firmware);
                BoardMsg::Identity {
                    protocol: PROTOCOL_VERSION,
                    firmware,
                    model: self.coeffs.model,
                    coeff_seq: self.coeff_seq,
                    speed_max: self.speed_limit(),
                    hw_stop_armed: self.hw_stop_armed,
                    motor_identified: self.coeffs.motor_identified,
                }
            }
            HostMsg::UploadBegin { .. }
            | HostMsg::UploadChunk { .. }
            | HostMsg::UploadCommit
            | HostMsg::UploadAbort => return false,
            HostMsg::SetSpeed { omega_ref } => {
                if omega_ref.abs() <= self.speed_limit() {
                    self.omega_target = omega_ref;
                    BoardMsg::Ack
                } else {
                    BoardMsg::Nack(Nack::OutOfRange)
                }
            }
            HostMsg::SetMode { mode: Mode::Idle } | HostMsg::Stop => {
                self.stop(send);
                BoardMsg::Ack
            }
            HostMsg::ClearFault => {
                self.latched = None;
                BoardMsg::Ack
            }
            HostMsg::Heartbeat => return true,
            HostMsg::ReadCommission => self.commission_msg(),
            HostMsg::ReadTelemetry => BoardMsg::Telemetry(self.stats.latest()),
            _ if self.latched.is_some() => BoardMsg::Nack(Nack::Faulted),
            HostMsg::SetMode {
                mode: Mode::Commission,
            }
            | HostMsg::Commission
                if matches!(self.run, Run::Commission(_)) =>
            {
                // A retry of the request that started the run (its Ack was late or lost):
                // the run goes on, restarting it mid-hold would learn from a moving rotor.
                BoardMsg::Ack
            }
            // Commissioning drives an unknown winding from a ramp that samples once a
            // period: the hardware stop bounds what a period can do.
            HostMsg::SetMode {
                mode: Mode::Commission,
            }
            | HostMsg::Commission
                if !(self.hw_stop_armed || self.run_without_hw_stop) =>
            {
                BoardMsg::Nack(Nack::NoHardwareStop)
            }
            HostMsg::SetMode {
                mode: Mode::Commission,
            }
            | HostMsg::Commission => {
                let volts = self.commission_volts();
                let i_limit = self.commission_current();
                let v_dead = dead_time_drop(self.v_bus);
                let r = self.coeffs.motor.r;
                let k_emf = self.coeffs.motor.kb / f32::from(self.coeffs.pole_pairs.max(1));
                self.start(Run::Commission(Commissioner::new(
                    volts, i_limit, v_dead, r, k_emf,
                )));
                self.commission = CommissionOutcome::Running;
                BoardMsg::Ack
            }
            _ if self.coeff_seq == 0 => BoardMsg::Nack(Nack::NoCoefficients),
            HostMsg::SetMode {
                mode: Mode::Speed | Mode::Experiment,
            }
            | HostMsg::StartExperiment { .. }
                if !(self.hw_stop_armed || self.run_without_hw_stop) =>
            {
                BoardMsg::Nack(Nack::NoHardwareStop)
            }
            HostMsg::SetMode { mode: Mode::Speed } if !self.coeffs.motor_identified => {
                BoardMsg::Nack(Nack::MotorNotIdentified)
            }
            HostMsg::SetMode { mode: Mode::Speed } => {
                self.start(Run::Speed);
                BoardMsg::Ack
            }
            // Experiment mode starts with StartExperiment.
            HostMsg::SetMode {
                mode: Mode::Experiment,
            } => BoardMsg::Ack,
            HostMsg::StartExperiment { signal, duration_s } => {
                let u = self.u_limit(self.v_bus_nominal);
                let ok_signal = match signal {
                    Excitation::Steady { volts } => volts.is_finite() && volts.abs() <= u,
                    Excitation::Ramp { volts_per_s } => volts_per_s.is_finite(),
                    _ => true,
                };
                let ok_duration =
                    duration_s.is_finite() && duration_s > 0.0 && duration_s <= MAX_EXPERIMENT_S;
                if !(ok_duration && ok_signal) {
                    BoardMsg::Nack(Nack::OutOfRange)
                } else {
                    self.start(Run::Experiment { signal, duration_s });
                    BoardMsg::Ack
                }
            }
        };
        send(reply);
        true
    }

    /// True once after a commissioning run succeeded: store [`Board::coefficients`] in
    /// flash, then call [`Board::stored`] (see [`store_coefficients`]).
    pub fn take_store_request(&mut self) -> bool {
        core::mem::replace(&mut self.store_request, false)
    }

    /// The coefficients with the commissioning result were stored as slot `seq` (`None`:
    /// the write failed); reports the result to the host.
    pub fn stored(&mut self, seq: Option<u32>, send: &mut impl FnMut(BoardMsg)) {
        if let Some(s) = seq {
            self.coeff_seq = s;
            self.commission_seq = s;
        }
        send(self.commission_msg());
    }

    fn latch(&mut self, f: Fault, send: &mut impl FnMut(BoardMsg)) {
        if self.latched.is_none() {
            send(BoardMsg::Fault(f));
        }
        self.latched = Some(f);
        self.stop(send);
    }

    /// A commissioning run ended with `r`; `resistance` [Ω] is the winding resistance its
    /// holds measured, stored unless the motor constants were identified, and at most
    /// `u_limit/i_limit` (the step's voltage window `R·i_limit` within what the board can
    /// drive at this bus voltage; a smaller R only narrows the window).
    fn commissioned(
        &mut self,
        r: Result<Commissioning, CommissionError>,
        resistance: Option<f32>,
        send: &mut impl FnMut(BoardMsg),
    ) {
        self.run = Run::Idle;
        self.omega_target = 0.0;
        match r {
            Ok(c) => {
                let mut co = self.coeffs.clone();
                co.apply_commissioning(c);
                if let (Some(r), false) = (resistance, co.motor_identified) {
                    let r_max =
                        self.u_limit(self.v_bus) / (blob::DERATE_FRACTION * co.limits.i_max);
                    co.motor.r = if r < r_max { r } else { r_max };
                }
                self.step = ControlStep::new(&co.step_config(self.v_bus_nominal));
                self.table = table_of(&co);
                self.coeffs = co;
                self.commission = CommissionOutcome::Done(c);
                self.commission_seq = 0;
                self.store_request = true;
            }
            Err(e) => {
                self.commission = CommissionOutcome::Failed(e);
                send(self.commission_msg());
            }
        }
    }

    /// The telemetry window that completed in the last [`Board::tick`], once (the firmware
    /// prints it through defmt).
    pub fn take_report(&mut self) -> Option<Telemetry> {
        self.report.take()
    }

    /// One control period: telemetry, the faults that need no step, the link watch, then
    /// commissioning's vector or the control step with its supervision, and the drive.
    pub fn tick(&mut self, m: &Measurements, send: &mut impl FnMut(BoardMsg)) -> Drive {
        self.quiet = self.quiet.saturating_add(1);
        self.record_timing(m, send);
        let v_bus = self.v_bus_of(m.v_bus);
        self.v_bus = v_bus;
        self.w_max = self.coeffs.speed_limit(v_bus);
        let u_lim = self.u_limit(v_bus);
        let i = self.signed_current(m.i_vector);
        self.hard_faults(m, i, send);
        self.derating = temperature_derating(m.temperature_c);
        self.step
            .set_current_limit(blob::DERATE_FRACTION * self.coeffs.limits.i_max * self.derating);
        self.watch_link(send);
        if let Some(drive) = self.commissioning(m, send) {
            return drive;
        }
        let v_override = self.experiment_voltage(u_lim);
        self.fill_inputs(m, i, u_lim, v_override);
        let out = self.step.step(&self.inp);
        self.last_out = out;
        if self.run != Run::Idle {
            self.supervise(&out, u_lim, send);
        }
        self.last_steps = out.steps;
        self.drive(&out, i, send)
    }

    /// The period's timing into the telemetry window; a completed window goes to the host
    /// while a run streams samples (it logs the telemetry beside them).
    #[inline(always)]
    fn record_timing(&mut self, m: &Measurements, send: &mut impl FnMut(BoardMsg)) {
        let timing = PeriodTiming {
            period_us: m.period_us,
            step_cycles: m.step_cycles,
            overrun: m.overrun,
            edges_lost: m.edges_lost,
        };
        self.report = self.stats.record(timing, crate::CONTROL_PERIOD_S * 1.0e6);
        if let Some(t) = self.report {
            if self.run != Run::Idle {
                send(BoardMsg::Telemetry(t));
            }
        }
    }

    /// The current [A] along the applied vector, signed by the drive's direction and the
    /// commissioned sense sign (+1 without commissioning).
    #[inline(always)]
    fn signed_current(&self, i_vector: f32) -> f32 {
        let sign = self
            .coeffs
            .commission
            .map_or(1.0, |c| f32::from(c.current_sign));
        let dir = if self.last_volts < 0.0 { -1.0 } else { 1.0 };
        i_vector * dir * sign
    }

    /// Latches the faults that need no step: hardware and software over-current,
    /// temperature, bus voltage, overrun.
    #[inline(always)]
    fn hard_faults(&mut self, m: &Measurements, i: f32, send: &mut impl FnMut(BoardMsg)) {
        let lim = self.coeffs.limits;
        let active = self.run != Run::Idle;
        let hard = if m.hw_overcurrent {
            Some(Fault::HardwareOverCurrent)
        } else if i.abs() > lim.i_max {
            Some(Fault::OverCurrent)
        } else if m.temperature_c >= TEMP_MAX_C {
            Some(Fault::OverTemperature)
        } else if m.v_bus.is_finite() && m.v_bus > lim.vbus_max {
            Some(Fault::OverVoltage)
        } else if active && m.v_bus.is_finite() && m.v_bus < lim.vbus_min {
            Some(Fault::UnderVoltage)
        } else if active && m.overrun {
            Some(Fault::Overrun)
        } else {
            None
        };
        if let Some(f) = hard {
            self.latch(f, send);
        }
    }

    /// Link loss: a speed or experiment run without a frame for [`LINK_TIMEOUT_PERIODS`]
    /// stops.
    #[inline(always)]
    fn watch_link(&mut self, send: &mut impl FnMut(BoardMsg)) {
        if matches!(self.run, Run::Speed | Run::Experiment { .. })
            && self.quiet > LINK_TIMEOUT_PERIODS
        {
            self.stop(send);
            send(BoardMsg::Warning(Warning::LinkLost));
        }
    }

    /// Commissioning: the vector to hold open loop (no speed loop), or the end of the run
    /// (the bridge off); `None` outside commissioning.
    #[inline(always)]
    fn commissioning(
        &mut self,
        m: &Measurements,
        send: &mut impl FnMut(BoardMsg),
    ) -> Option<Drive> {
        let Run::Commission(c) = &mut self.run else {
            return None;
        };
        let edges = m.edges.iter().map(|e| e.state);
        self.applied = None;
        Some(match c.tick(m.hall, edges, m.edges_overflow, m.i_vector) {
            CommissionStep::Hold { low, volts } => {
                self.last_volts = volts;
                Drive::Centre { low, volts }
            }
            CommissionStep::Done(r) => {
                let resistance = c.resistance();
                self.commissioned(r, resistance, send);
                self.last_volts = 0.0;
                Drive::Off
            }
        })
    }

    /// The experiment's open-loop voltage now [V] (`None` outside an experiment, or at its
    /// end, which stops as a stop does: a speed asked meanwhile is dropped).
    #[inline(always)]
    fn experiment_voltage(&mut self, u_lim: f32) -> Option<f32> {
        let Run::Experiment { signal, duration_s } = self.run else {
            return None;
        };
        let t = self.k as f32 * crate::CONTROL_PERIOD_S;
        if t >= duration_s {
            self.run = Run::Idle;
            self.omega_target = 0.0;
            None
        } else {
            let r_i_max = self.coeffs.motor.r * self.coeffs.limits.i_max;
            Some(excitation::voltage(signal, t, u_lim, r_i_max))
        }
    }

    /// The control step's inputs, in place, with the speed reference: the ramp towards the
    /// asked speed within the speed limit, or in an experiment the measured speed (the
    /// friction observer follows it; the loop is open).
    #[inline(always)]
    fn fill_inputs(&mut self, m: &Measurements, i: f32, u_lim: f32, v_override: Option<f32>) {
        let inp = &mut self.inp;
        inp.hall = m.hall;
        inp.edges.clear();
        // Both hold MAX_EDGES: never fails.
        let _ = inp.edges.extend_from_slice(&m.edges);
        inp.edges_overflow = m.edges_overflow;
        inp.now_ticks = m.now_ticks;
        inp.i_meas = i;
        inp.v_bus = u_lim;
        inp.v_applied = self.applied;
        if v_override.is_some() {
            self.omega_ref = self.step.omega();
        } else {
            // At most the ramp's acceleration times the period per period, within the speed
            // limit at this period's bus voltage.
            let dw =
                self.coeffs.ramp_acceleration(self.step.current_limit()) * crate::CONTROL_PERIOD_S;
            let w = self.omega_ref;
            let w_max = self.w_max;
            let target = crate::pi::saturate(self.omega_target, -w_max, w_max);
            self.omega_ref = crate::pi::saturate(target, w - dw, w + dw);
        }
        inp.omega_ref = self.omega_ref;
        inp.v_override = v_override;
    }

    /// Run supervision: stall, model mismatch, current sense, over-speed, the Hall faults;
    /// counts periods in a row and latches the first fault due.
    #[inline(always)]
    fn supervise(&mut self, out: &StepOutputs<f32>, u_lim: f32, send: &mut impl FnMut(BoardMsg)) {
        let in_row = |n: u32, now: bool| if now { n + 1 } else { 0 };
        // Stall: the drive pushes (a large voltage, or held by the current limit) and the
        // rotor does not step.
        let pushing =
            out.v_cmd.abs() > STALL_FRACTION * u_lim || out.faults.contains(Faults::CURRENT_LIMIT);
        self.stall = in_row(self.stall, pushing && out.steps == self.last_steps);
        self.mismatch = in_row(self.mismatch, out.faults.contains(Faults::MODEL_MISMATCH));
        self.overspeed = in_row(
            self.overspeed,
            out.omega.abs() > OVERSPEED_FACTOR * self.w_max,
        );
        self.sense = in_row(self.sense, out.faults.contains(Faults::CURRENT_SENSE));
        // A current against its driving voltage while the model's and the measured windows
        // are disjoint: neither bounds the current, stop at once.
        let untrusted = out.faults.contains(Faults::CURRENT_SENSE)
            && out.faults.contains(Faults::MODEL_MISMATCH);
        let f = if self.sense >= CURRENT_SENSE_PERIODS || untrusted {
            Some(Fault::CurrentSense)
        } else if self.stall >= STALL_PERIODS {
            Some(Fault::Stall)
        } else if self.mismatch >= MISMATCH_PERIODS {
            Some(Fault::ModelMismatch)
        } else if self.overspeed >= OVERSPEED_PERIODS {
            Some(Fault::OverSpeed)
        } else {
            fault_of(out.faults)
        };
        if let Some(f) = f {
            self.latch(f, send);
        }
    }

    /// The drive for the step's command: off while idle or without a valid sector; else
    /// six-step at the command, with a sample to the host.
    #[inline(always)]
    fn drive(&mut self, out: &StepOutputs<f32>, i: f32, send: &mut impl FnMut(BoardMsg)) -> Drive {
        if self.run == Run::Idle || self.step.decoder().sector().is_none() {
            self.last_volts = 0.0;
            self.applied = None;
            return Drive::Off;
        }
        self.last_volts = out.v_cmd;
        self.applied = Some(out.v_cmd);
        send(BoardMsg::Sample(Sample {
            seq: self.seq,
            t: self.k as f32 * crate::CONTROL_PERIOD_S,
            u: out.v_cmd,
            i,
            theta: out.theta,
            omega: out.omega,
        }));
        self.seq = self.seq.wrapping_add(1);
        self.k = self.k.wrapping_add(1);
        Drive::SixStep {
            volts: out.v_cmd,
            table: self.table,
        }
    }
}

/// Handles the upload messages (the others: `None`) on `slots`; `idle`: no run is active
/// (a commit is refused otherwise, erasing stalls the CPU). Returns the reply and, after a
/// commit, the new coefficients with their slot sequence for [`Board::load`].
pub fn handle_upload<S: NorFlash>(
    msg: &HostMsg,
    upload: &mut Upload,
    slots: &mut Slots<S>,
    idle: bool,
) -> Option<(BoardMsg, Option<(Coefficients, u32)>)> {
    let reply = match msg {
        HostMsg::UploadBegin { total_len, crc } => match upload.begin(*total_len, *crc) {
            Ok(()) => BoardMsg::UploadAck { index: 0xFFFF },
            Err(n) => BoardMsg::Nack(n),
        },
        HostMsg::UploadChunk { index, data } => match upload.chunk(*index, data) {
            Ok(ChunkOutcome::Stored) | Ok(ChunkOutcome::Duplicate) => {
                BoardMsg::UploadAck { index: *index }
            }
            Err(n) => BoardMsg::Nack(n),
        },
        HostMsg::UploadAbort => {
            upload.abort();
            BoardMsg::UploadAck { index: 0xFFFF }
        }
        HostMsg::UploadCommit if !idle => BoardMsg::Nack(Nack::Busy),
        HostMsg::UploadCommit => match upload.commit() {
            Err(n) => BoardMsg::Nack(n),
            Ok((bytes, coeffs)) => match slots.store(bytes) {
                Ok(info) => {
                    return Some((
                        BoardMsg::Committed { seq: info.seq },
                        Some((coeffs, info.seq)),
                    ))
                }
                Err(_) => BoardMsg::Nack(Nack::Flash),
            },
        },
        _ => return None,
    };
    Some((reply, None))
}

/// Serves a store request of `board` (after commissioning) on `slots`.
pub fn store_coefficients<S: NorFlash>(
    board: &mut Board,
    slots: &mut Slots<S>,
    send: &mut impl FnMut(BoardMsg),
) {
    if !board.take_store_request() {
        return;
    }
    let mut buf = [0u8; MAX_BLOB_LEN];
    let seq = match blob::encode(board.coefficients(), &mut buf) {
        Ok(bytes) => slots.store(bytes).ok().map(|i| i.seq),
        Err(_) => None,
    };
    board.stored(seq, send);
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn neighbouring_bridge_steps_switch_one_leg_off_and_one_on() {
        let duty = 1234;
        for k in 0..6u8 {
            let (ccr, en) = six_step_pattern(k, duty);
            // One phase switches with the duty, one is held low, one floats.
            assert_eq!(en.iter().filter(|&&e| e).count(), 2, "step {k}");
            assert_eq!(ccr.iter().filter(|&&c| c == duty).count(), 1, "step {k}");
            let (hi, lo) = BRIDGE_STEPS[usize::from(k)];
            assert!(en[hi] && en[lo] && ccr[hi] == duty && ccr[lo] == 0);
            // Reversed: the same pair with the roles swapped.
            assert_eq!(BRIDGE_STEPS[usize::from(k + 3) % 6], (lo, hi));
            // To the next step (either direction): the shared phase keeps its role and
            // compare value, one leg turns off, one turns on.
            for next in [(k + 1) % 6, (k + 5) % 6] {
                let (ccr2, en2) = six_step_pattern(next, duty);
                let kept: Vec<usize> = (0..3).filter(|&p| en[p] && en2[p]).collect();
                assert_eq!(kept.len(), 1, "{k} -> {next}");
                assert_eq!(ccr[kept[0]], ccr2[kept[0]], "{k} -> {next}");
            }
        }
        // The forward commutation of consecutive sectors walks the steps one by one.
        for sector in 0..6u8 {
            let a = commutation_step(sector, false);
            let b = commutation_step((sector + 1) % 6, false);
            assert_eq!(b, (a + 1) % 6);
        }
    }

    #[test]
    fn a_centre_vector_is_the_sum_of_the_two_steps_sharing_its_low_phase() {
        let duty = 1234;
        let mut sectors = Vec::new();
        for low in 0..3u8 {
            let (ccr, en) = centre_pattern(low, duty);
            assert_eq!(en, [true; 3]);
            let l = usize::from(low);
            assert_eq!(ccr[l], 0);
            assert!((0..3).filter(|&p| p != l).all(|p| ccr[p] == duty));
            // The steps whose low phase is `low`: k − 1 and k for the centre's sector k.
            let c = centre_sector(low);
            sectors.push(c);
            for k in [(c + 5) % 6, c] {
                let (hi, lo) = BRIDGE_STEPS[usize::from(k)];
                assert_eq!(lo, l, "low {low}: step {k}");
                assert_eq!(ccr[hi], duty);
            }
        }
        // Three centres 120° apart.
        sectors.sort_unstable();
        assert_eq!(sectors, [0, 2, 4]);
    }

    #[test]
    fn temperature_derating_falls_from_the_derate_point_to_the_trip() {
        assert_eq!(temperature_derating(25.0), 1.0);
        assert_eq!(temperature_derating(TEMP_DERATE_C), 1.0);
        let mid = 0.5 * (TEMP_DERATE_C + TEMP_MAX_C);
        // 1e-6: f32 rounding of the linear ramp (an ulp of 0.5 is 6e-8).
        assert!((temperature_derating(mid) - 0.5).abs() < 1e-6);
        assert_eq!(temperature_derating(TEMP_MAX_C), 0.0);
        assert_eq!(temperature_derating(f32::NAN), 1.0);
    }

    fn identified() -> Coefficients {
        Coefficients {
            motor_identified: true,
            ..Coefficients::default()
        }
    }

    fn running_board() -> (Board, Vec<BoardMsg>) {
        let mut b = Board::new(Some((identified(), 1)), "test", 22.2);
        b.set_hardware_stop(true, false);
        let mut out = Vec::new();
        b.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |m| {
            out.push(m)
        });
        assert_eq!(out, [BoardMsg::Ack]);
        (b, Vec::new())
    }

    fn at(temperature_c: f32) -> Measurements {
        Measurements {
            hall: 1,
            v_bus: f32::NAN,
            temperature_c,
            ..Measurements::default()
        }
    }

    #[test]
    fn a_hot_board_lowers_the_current_limit_then_stops() {
        let (mut b, mut out) = running_board();
        let full = blob::DERATE_FRACTION * b.coefficients().limits.i_max;
        b.tick(&at(40.0), &mut |m| out.push(m));
        assert_eq!(b.control().current_limit(), full);
        let mid = 0.5 * (TEMP_DERATE_C + TEMP_MAX_C);
        b.tick(&at(mid), &mut |m| out.push(m));
        // 1e-4 A: f32 rounding of a limit of tens of amperes (an ulp of 24 A is 2e-6 A).
        assert!((b.control().current_limit() - 0.5 * full).abs() < 1e-4);
        assert_eq!(b.fault(), None);
        assert_eq!(b.mode(), Mode::Speed);

        let d = b.tick(&at(TEMP_MAX_C + 1.0), &mut |m| out.push(m));
        assert_eq!(d, Drive::Off);
        assert_eq!(b.fault(), Some(Fault::OverTemperature));
        assert_eq!(b.mode(), Mode::Idle);
        assert!(out.contains(&BoardMsg::Fault(Fault::OverTemperature)));
        // Clearing while still hot latches again at the next period; once cool it holds.
        b.handle(&HostMsg::ClearFault, &mut |m| out.push(m));
        b.tick(&at(TEMP_MAX_C + 1.0), &mut |m| out.push(m));
        assert_eq!(b.fault(), Some(Fault::OverTemperature));
        b.handle(&HostMsg::ClearFault, &mut |m| out.push(m));
        b.tick(&at(60.0), &mut |m| out.push(m));
        assert_eq!(b.fault(), None);
    }

    #[test]
    fn bus_voltage_overrun_and_invalid_hall_faults_stop_a_run() {
        let lim = identified().limits;
        let cases = [
            (
                Measurements {
                    v_bus: lim.vbus_max + 1.0,
                    ..at(25.0)
                },
                Fault::OverVoltage,
            ),
            (
                Measurements {
                    v_bus: lim.vbus_min - 1.0,
                    ..at(25.0)
                },
                Fault::UnderVoltage,
            ),
            (
                Measurements {
                    overrun: true,
                    ..at(25.0)
                },
                Fault::Overrun,
            ),
            (
                Measurements {
                    hall: 0b111,
                    ..at(25.0)
                },
                Fault::InvalidHall,
            ),
        ];
        for (m, fault) in cases {
            let (mut b, mut out) = running_board();
            assert_eq!(b.tick(&m, &mut |m| out.push(m)), Drive::Off, "{fault:?}");
            assert_eq!(b.fault(), Some(fault));
            assert_eq!(b.mode(), Mode::Idle);
            assert!(out.contains(&BoardMsg::Fault(fault)), "{out:?}");
        }
        // Idle, an under-voltage or an overrun is no fault (the supply may be off); an
        // over-voltage always is.
        let mut b = Board::new(Some((identified(), 1)), "test", 22.2);
        let low = Measurements {
            v_bus: lim.vbus_min - 1.0,
            overrun: true,
            ..at(25.0)
        };
        b.tick(&low, &mut |_| {});
        assert_eq!(b.fault(), None);
        let high = Measurements {
            v_bus: lim.vbus_max + 1.0,
            ..at(25.0)
        };
        b.tick(&high, &mut |_| {});
        assert_eq!(b.fault(), Some(Fault::OverVoltage));
    }

    #[test]
    fn lost_hall_edges_stop_a_run_and_are_reported() {
        let (mut b, mut out) = running_board();
        let m = Measurements {
            edges_overflow: true,
            edges_lost: 3,
            ..at(25.0)
        };
        assert_eq!(b.tick(&m, &mut |m| out.push(m)), Drive::Off);
        assert_eq!(b.fault(), Some(Fault::ImpossibleTransition));
        out.clear();
        b.handle(&HostMsg::ReadTelemetry, &mut |m| out.push(m));
        match out.as_slice() {
            [BoardMsg::Telemetry(t)] => assert_eq!((t.edges_lost, t.periods), (3, 1)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_run_streams_telemetry_every_window() {
        let (mut b, mut out) = running_board();
        let mut m = at(25.0);
        m.period_us = 12_010.0;
        m.step_cycles = 4321;
        for k in 0..3 * crate::telemetry::WINDOW_PERIODS {
            if k % 50 == 0 {
                // A listening host's sign of life.
                b.handle(&HostMsg::Heartbeat, &mut |m| out.push(m));
            }
            b.tick(&m, &mut |m| out.push(m));
        }
        assert_eq!(b.mode(), Mode::Speed);
        let reports: Vec<_> = out
            .iter()
            .filter_map(|m| match m {
                BoardMsg::Telemetry(t) => Some(*t),
                _ => None,
            })
            .collect();
        assert_eq!(reports.len(), 3);
        for t in &reports {
            assert_eq!(t.periods, crate::telemetry::WINDOW_PERIODS);
            // 0.1 µs: f32 rounding of the window's running sum (an ulp near 10^6 µs is 0.06 µs).
            assert!((t.period_us - 12_010.0).abs() < 0.1, "{}", t.period_us);
            assert!((t.jitter_us - 10.0).abs() < 0.1, "{}", t.jitter_us);
            assert_eq!(t.step_cycles_max, 4321);
        }
        // Idle, the windows go on (for the firmware's defmt line) but nothing is sent.
        b.handle(&HostMsg::Stop, &mut |m| out.push(m));
        out.clear();
        let mut reports = 0;
        for _ in 0..crate::telemetry::WINDOW_PERIODS {
            b.tick(&m, &mut |m| out.push(m));
            reports += usize::from(b.take_report().is_some());
        }
        assert_eq!(reports, 1);
        assert!(out.is_empty(), "{out:?}");
    }

    #[test]
    fn new_coefficients_drop_a_speed_checked_against_the_old_limit() {
        let (mut b, mut out) = running_board();
        b.handle(&HostMsg::SetSpeed { omega_ref: 150.0 }, &mut |m| {
            out.push(m)
        });
        assert_eq!(out, [BoardMsg::Ack]);
        let mut slow = identified();
        slow.pi.u_max = 3.0; // 42 rad/s
        b.load(slow, 2);
        b.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |m| {
            out.push(m)
        });
        for _ in 0..20 {
            b.tick(&at(25.0), &mut |m| out.push(m));
        }
        assert_eq!(b.speed_reference(), 0.0);
        // 43: the new limit, 3 V/K_b = 42.1 rad/s, with room for rounding; the old one is 300.
        assert!(b.speed_limit() < 43.0, "{}", b.speed_limit());
    }

    #[test]
    fn a_new_board_refuses_runs_until_the_hardware_stop_is_armed() {
        let mut b = Board::new(Some((identified(), 1)), "test", 22.2);
        let mut out = Vec::new();
        b.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |m| {
            out.push(m)
        });
        assert_eq!(out, [BoardMsg::Nack(Nack::NoHardwareStop)]);
        b.set_hardware_stop(true, false);
        out.clear();
        b.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |m| {
            out.push(m)
        });
        assert!(
            !out.contains(&BoardMsg::Nack(Nack::NoHardwareStop)),
            "{out:?}"
        );
    }

    #[test]
    fn a_hardware_stop_latches_even_when_idle() {
        let mut b = Board::new(Some((Coefficients::default(), 1)), "test", 22.2);
        let mut out = Vec::new();
        let m = Measurements {
            hw_overcurrent: true,
            ..at(25.0)
        };
        assert_eq!(b.tick(&m, &mut |m| out.push(m)), Drive::Off);
        assert_eq!(b.fault(), Some(Fault::HardwareOverCurrent));
        assert_eq!(out, [BoardMsg::Fault(Fault::HardwareOverCurrent)]);
        b.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |m| {
            out.push(m)
        });
        assert_eq!(out.last(), Some(&BoardMsg::Nack(Nack::Faulted)));
    }

    #[test]
    fn commissioning_is_sized_at_the_measured_bus_and_the_board_temperature() {
        let mut b = Board::new(Some((identified(), 1)), "test", 22.2);
        let co = identified();
        let cool = Measurements {
            v_bus: 12.0,
            ..at(25.0)
        };
        b.tick(&cool, &mut |_| {});
        let i_full = COMMISSION_I_FRACTION * co.limits.i_max;
        assert_eq!(b.commission_current(), i_full);
        // Through the centre vector's path: ¾ of the line-to-line R.
        let v = (dead_time_drop(12.0) + i_full * crate::commission::PATH_R_SHARE * co.motor.r)
            .min(COMMISSION_U_FRACTION * co.pi.u_max.min(MAX_DUTY * 12.0));
        // 1e-6 V: the same f32 formula, evaluated in another order (an ulp of 2 V is 2.4e-7).
        assert!(
            (b.commission_volts() - v).abs() < 1e-6,
            "{}",
            b.commission_volts()
        );
        let mid = 0.5 * (TEMP_DERATE_C + TEMP_MAX_C);
        b.tick(
            &Measurements {
                v_bus: 12.0,
                ..at(mid)
            },
            &mut |_| {},
        );
        // 1e-5 A: f32 rounding of the derated current (amperes: an ulp is about 2e-7 A).
        assert!((b.commission_current() - 0.5 * i_full).abs() < 1e-5);
        assert!(b.commission_volts() < v);
    }

    #[test]
    fn a_hot_board_does_not_take_sense_noise_for_an_inverted_current() {
        // Near the trip the derated limit is a tenth of the full one; a current of 0.7 A
        // against the drive (noise and offset of a working sense) is not significant
        // against the full limit's quarter, while 7 A against it at 25 °C is.
        for (t, i, want) in [(98.0, -0.7, None), (25.0, -7.0, Some(Fault::CurrentSense))] {
            let mut b = Board::new(Some((identified(), 1)), "test", 22.2);
            b.set_hardware_stop(true, false);
            b.handle(
                &HostMsg::StartExperiment {
                    signal: Excitation::Steady { volts: 5.0 },
                    duration_s: 1.0,
                },
                &mut |_| {},
            );
            for _ in 0..10 {
                let m = Measurements {
                    i_vector: i,
                    ..at(t)
                };
                b.tick(&m, &mut |_| {});
            }
            assert_eq!(b.fault(), want, "{t} °C, {i} A");
        }
    }
}
