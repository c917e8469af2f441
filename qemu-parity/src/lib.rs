//! Shared by the bare-metal (QEMU) and the host run: the recorded input trace, the five
//! observer configurations, and one pass of the board's logic over the trace: every period
//! is one `control::board::Board::tick` in speed mode (fault and limit checks, telemetry,
//! stall and link supervision, and the control step), the period the firmware runs.
//!
//! Both runs call [`run_trace`] with the same bytes, so any difference in their outputs comes
//! from code generation and floating point on the two machines, which is what the parity check
//! measures.
//!
//! * The trace (`trace/closed_loop.qpt`) is the control step's inputs recorded during a
//!   closed-loop run on the emulated board: `motorid emulate --model trace/lugre.toml --model
//!   trace/sindyc.toml --compensation sindyc --edge-timing 0.1 --trace-out trace/closed_loop.qpt`.
//!   Format (little-endian): `QPT2`, u32 step count, then per step: hall u8, edge count u8,
//!   flags u8 (bit 0 edge overflow, bit 1 voltage override), 0 u8, now_ticks u32, i_meas f32,
//!   v_bus f32, omega_ref f32, v_override f32, then per edge: ticks u32, state u8, 3 zeros.
//! * The configurations are the coefficient blobs `motorid export --edge-timing 0.1` wrote for
//!   the models (`trace/lugre.bin`, `trace/sindyc.bin`, and `trace/lugre-table.bin`: the
//!   LuGre model with all eight effect slots filled by hand), decoded with
//!   `control::blob::decode` and turned into a step configuration with
//!   `Coefficients::step_config`, as the firmware does; "none" is the default coefficients.
#![no_std]

use control::blob::{self, Coefficients};
use control::board::{Board, Measurements};
use control::frame::{Excitation, HostMsg, Mode};
use control::step::{HallEdge, StepInputs, StepOutputs};

/// Magic at the head of a trace file.
pub const TRACE_MAGIC: [u8; 4] = *b"QPT2";

/// Number of `f32` outputs a step reports (v_cmd, theta, omega, friction, v_comp, z) plus
/// the fault bits as a seventh word.
pub const N_OUTPUTS: usize = 7;

/// Nominal bus voltage [V] of the configurations (the firmware's `V_BUS_NOMINAL`).
pub const V_BUS: f32 = 22.2;

/// The observer a control step runs for friction compensation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Observer {
    /// No compensation.
    None,
    /// LuGre observer (paper eqs. 12–14).
    Lugre,
    /// SINDYc friction model (paper eq. 47).
    Sindyc,
    /// The SINDYc configuration in experiment mode: the paper's signal a, open loop, with
    /// the observer following the measured speed.
    SindycSignalA,
    /// LuGre observer with all eight effect slots of the blob used (`trace/lugre-table.toml`:
    /// a 16-node lookup table over the speed, magnetic saturation, cogging, a position load,
    /// heating, dead time, asymmetry and a current offset): the largest effect evaluation a
    /// blob can ask of a step.
    LugreTable,
}

impl Observer {
    /// All configurations, in report order.
    pub const ALL: [Observer; 5] = [
        Observer::None,
        Observer::Lugre,
        Observer::Sindyc,
        Observer::SindycSignalA,
        Observer::LugreTable,
    ];

    /// Lower-case name used in the printed lines.
    pub fn name(self) -> &'static str {
        match self {
            Observer::None => "none",
            Observer::Lugre => "lugre",
            Observer::Sindyc => "sindyc",
            Observer::SindycSignalA => "sindyc-a",
            Observer::LugreTable => "lugre+all",
        }
    }
}

/// A parsed trace; steps are decoded one at a time by [`Trace::inputs`].
#[derive(Debug, Clone)]
pub struct Trace<'a> {
    pub steps: usize,
    /// Byte offset of each step in `data`.
    data: &'a [u8],
}

/// Why a trace could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceError {
    /// The first four bytes are not `QPT2`.
    BadMagic,
    /// Fewer bytes than the steps need.
    Truncated,
    /// More edges in a step than the control step takes.
    TooManyEdges,
}

const STEP_LEN: usize = 24;
const EDGE_LEN: usize = 8;

fn word(b: &[u8], k: usize) -> u32 {
    u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]])
}

impl<'a> Trace<'a> {
    /// Parse a trace: checks the magic and that every step is complete.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, TraceError> {
        if bytes.len() < 8 || bytes[..4] != TRACE_MAGIC {
            return Err(TraceError::BadMagic);
        }
        let steps = word(bytes, 4) as usize;
        let data = &bytes[8..];
        let mut at = 0;
        for _ in 0..steps {
            if at + STEP_LEN > data.len() {
                return Err(TraceError::Truncated);
            }
            let n = data[at + 1] as usize;
            if n > control::step::MAX_EDGES {
                return Err(TraceError::TooManyEdges);
            }
            at += STEP_LEN + n * EDGE_LEN;
            if at > data.len() {
                return Err(TraceError::Truncated);
            }
        }
        Ok(Trace { steps, data })
    }

    /// Decode the steps in order.
    pub fn inputs(&self) -> impl Iterator<Item = StepInputs<f32>> + '_ {
        let mut at = 0;
        (0..self.steps).map(move |_| {
            let d = &self.data[at..];
            let f = |k: usize| f32::from_bits(word(d, k));
            let n = d[1] as usize;
            let mut inp = StepInputs {
                hall: d[0],
                edges_overflow: d[2] & 1 != 0,
                now_ticks: word(d, 4),
                i_meas: f(8),
                v_bus: f(12),
                omega_ref: f(16),
                v_override: if d[2] & 2 != 0 { Some(f(20)) } else { None },
                ..StepInputs::default()
            };
            for e in 0..n {
                let o = STEP_LEN + e * EDGE_LEN;
                // parse() checked the count against MAX_EDGES.
                let _ = inp.edges.push(HallEdge {
                    ticks: word(d, o),
                    state: d[o + 4],
                });
            }
            at += STEP_LEN + n * EDGE_LEN;
            inp
        })
    }
}

/// The coefficient blobs of the configurations (`motorid export`).
#[derive(Debug, Clone, Copy)]
pub struct Blobs<'a> {
    pub lugre: &'a [u8],
    pub sindyc: &'a [u8],
    /// LuGre with all eight effect slots used.
    pub lugre_table: &'a [u8],
}

/// The coefficients of one observer configuration; an error when a blob does not decode.
pub fn coefficients(obs: Observer, blobs: &Blobs<'_>) -> Result<Coefficients, blob::BlobError> {
    let mut co = match obs {
        Observer::None => Coefficients::default(),
        Observer::Lugre => blob::decode(blobs.lugre)?,
        Observer::Sindyc | Observer::SindycSignalA => blob::decode(blobs.sindyc)?,
        Observer::LugreTable => blob::decode(blobs.lugre_table)?,
    };
    // The traced run is a speed run, which needs identified motor constants (the traced
    // blobs are of format version 3, read as not identified).
    co.motor_identified = true;
    Ok(co)
}

/// The step's outputs as raw words, in a fixed order.
pub fn output_words(o: &StepOutputs<f32>) -> [u32; N_OUTPUTS] {
    [
        o.v_cmd.to_bits(),
        o.theta.to_bits(),
        o.omega.to_bits(),
        o.friction.to_bits(),
        o.v_comp.to_bits(),
        o.z.to_bits(),
        u32::from(o.faults.0),
    ]
}

/// The board's measurements for one traced step: the step's inputs as the transport reports
/// them. The current along the applied vector is signed by the previous voltage `last_v`
/// (the board signs it back, `Measurements::i_vector`).
pub fn measurements(inp: StepInputs<f32>, last_v: f32) -> Measurements {
    Measurements {
        hall: inp.hall,
        edges: inp.edges,
        edges_overflow: inp.edges_overflow,
        now_ticks: inp.now_ticks,
        i_vector: if last_v < 0.0 {
            -inp.i_meas
        } else {
            inp.i_meas
        },
        v_bus: inp.v_bus,
        period_us: control::CONTROL_PERIOD_S * 1.0e6,
        temperature_c: f32::NAN,
        ..Measurements::default()
    }
}

/// Run every observer over the whole trace; `emit(observer, step, outputs)` receives each
/// step's outputs, `mark(observer, begin)` is called right before and after each period of
/// the board logic (the bare-metal run uses it to count instructions). The speed reference
/// reaches the board as a `SetSpeed` message before each period, outside the marks.
pub fn run_trace(
    trace: &Trace<'_>,
    blobs: &Blobs<'_>,
    mut emit: impl FnMut(Observer, usize, &[u32; N_OUTPUTS]),
    mut mark: impl FnMut(Observer, bool),
) -> Result<(), blob::BlobError> {
    for obs in Observer::ALL {
        let co = coefficients(obs, blobs)?;
        let mut board = Board::new(Some((co, 1)), "qemu-parity", V_BUS);
        board.set_hardware_stop(true, false);
        if obs == Observer::SindycSignalA {
            let start = HostMsg::StartExperiment {
                signal: Excitation::A,
                duration_s: control::board::MAX_EXPERIMENT_S,
            };
            board.handle(&start, &mut |_| {});
        } else {
            board.handle(&HostMsg::SetMode { mode: Mode::Speed }, &mut |_| {});
        }
        let mut last_v = 0.0f32;
        for (k, inp) in trace.inputs().enumerate() {
            let omega_ref = inp.omega_ref;
            board.handle(&HostMsg::SetSpeed { omega_ref }, &mut |_| {});
            let m = measurements(inp, last_v);
            mark(obs, true);
            let _ = board.tick(&m, &mut |_| {});
            mark(obs, false);
            let out = board.last_step_outputs();
            last_v = out.v_cmd;
            emit(obs, k, &output_words(out));
        }
    }
    Ok(())
}
