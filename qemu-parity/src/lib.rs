//! Shared by the bare-metal (QEMU) and the host run: the recorded input trace, the three
//! observer configurations, and one pass of the control step over the trace.
//!
//! Both runs call [`run_trace`] with the same bytes, so any difference in their outputs comes
//! from code generation and floating point on the two machines, which is what the parity check
//! measures.
//!
//! Trace format (`trace/*.qpt`, little-endian, written by `motorid emulate --trace-out`):
//! magic `QPT1`, `u32` field count, `u32` step count, then `steps × fields` `f32` values,
//! one row per 12 ms control step, fields in the order of [`TRACE_FIELDS`].
#![no_std]

use control::lugre::{LugreObserver, LugreParams};

/// Names of the trace's per-step fields, in file order.
pub const TRACE_FIELDS: [&str; 4] = ["t", "theta", "i", "omega_ref"];

/// Magic at the head of a trace file.
pub const TRACE_MAGIC: [u8; 4] = *b"QPT1";

/// Number of `f32` outputs a step reports.
pub const N_OUTPUTS: usize = 3;

/// The observer a control step runs for friction compensation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Observer {
    /// No compensation.
    None,
    /// LuGre observer (paper eqs. 12–14).
    Lugre,
    /// SINDYc friction model (paper eq. 47).
    Sindyc,
}

impl Observer {
    /// All three, in report order.
    pub const ALL: [Observer; 3] = [Observer::None, Observer::Lugre, Observer::Sindyc];

    /// Lower-case name used in the printed lines.
    pub fn name(self) -> &'static str {
        match self {
            Observer::None => "none",
            Observer::Lugre => "lugre",
            Observer::Sindyc => "sindyc",
        }
    }
}

/// A decoded trace header; rows are read with [`Trace::row`].
#[derive(Debug, Clone, Copy)]
pub struct Trace<'a> {
    pub fields: usize,
    pub steps: usize,
    data: &'a [u8],
}

/// Why a trace could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceError {
    /// The first four bytes are not `QPT1`.
    BadMagic,
    /// The field count differs from [`TRACE_FIELDS`].
    BadFields,
    /// Fewer bytes than the header announces.
    Truncated,
}

impl<'a> Trace<'a> {
    /// Parse a trace; checks the magic, the field count and the length.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, TraceError> {
        if bytes.len() < 12 || bytes[..4] != TRACE_MAGIC {
            return Err(TraceError::BadMagic);
        }
        let word =
            |k: usize| u32::from_le_bytes([bytes[k], bytes[k + 1], bytes[k + 2], bytes[k + 3]]);
        let fields = word(4) as usize;
        let steps = word(8) as usize;
        if fields != TRACE_FIELDS.len() {
            return Err(TraceError::BadFields);
        }
        let data = &bytes[12..];
        if data.len() < fields * steps * 4 {
            return Err(TraceError::Truncated);
        }
        Ok(Trace {
            fields,
            steps,
            data,
        })
    }

    /// Row `k` (0-based), `fields` values.
    pub fn row(&self, k: usize) -> [f32; TRACE_FIELDS.len()] {
        let mut row = [0.0f32; TRACE_FIELDS.len()];
        let base = k * self.fields * 4;
        for (j, v) in row.iter_mut().enumerate() {
            let o = base + 4 * j;
            *v = f32::from_le_bytes([
                self.data[o],
                self.data[o + 1],
                self.data[o + 2],
                self.data[o + 3],
            ]);
        }
        row
    }
}

/// The state the control step keeps between calls for one observer configuration.
pub struct Runner {
    observer: Observer,
    lugre: LugreObserver<f32>,
    prev_theta: f32,
}

impl Runner {
    /// A runner at rest.
    pub fn new(observer: Observer) -> Self {
        Runner {
            observer,
            lugre: LugreObserver::new(LugreParams::paper()),
            prev_theta: 0.0,
        }
    }

    /// One control step on one trace row; returns the step's outputs.
    #[inline(never)]
    pub fn step(&mut self, row: &[f32; TRACE_FIELDS.len()]) -> [f32; N_OUTPUTS] {
        let dt = control::CONTROL_PERIOD_S;
        let omega = (row[1] - self.prev_theta) / dt;
        self.prev_theta = row[1];
        let friction = match self.observer {
            Observer::None => 0.0,
            Observer::Lugre | Observer::Sindyc => self.lugre.step(omega, dt),
        };
        [omega, friction, row[3] - omega]
    }
}

/// Run every observer over the whole trace; `emit(observer, step, outputs)` receives each
/// step's outputs, `mark(observer, begin)` is called right before and after each step (the
/// bare-metal run uses it to count instructions).
pub fn run_trace(
    trace: &Trace<'_>,
    mut emit: impl FnMut(Observer, usize, &[f32; N_OUTPUTS]),
    mut mark: impl FnMut(Observer, bool),
) {
    for obs in Observer::ALL {
        let mut runner = Runner::new(obs);
        for k in 0..trace.steps {
            let row = trace.row(k);
            mark(obs, true);
            let out = runner.step(&row);
            mark(obs, false);
            emit(obs, k, &out);
        }
    }
}
