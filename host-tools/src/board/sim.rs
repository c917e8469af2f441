//! The emulated board's firmware logic, transport-free: the serial protocol handler (the
//! same messages and rules as `firmware/src/link.rs`, built on `control::frame`'s decoder and
//! upload state machine and `control::slots`' two-slot storage) and the 12 ms control task
//! (modes idle / speed / experiment, faults, log samples), driving the [`Rig`].
//!
//! Feed received bytes to [`BoardSim::receive`], call [`BoardSim::tick`] every control
//! period, send what [`BoardSim::take_output`] returns.
use super::flash::RamFlash;
use super::rig::Rig;
use crate::emulator::{signal_at, EmulatorConfig, SignalKind};
use anyhow::{anyhow, Result};
use control::blob::{self, Coefficients};
use control::frame::{
    self, BoardMsg, ChunkOutcome, Excitation, Fault, FrameDecoder, HostMsg, Mode, Nack, Sample,
    Upload, Warning, MAX_ENCODED_LEN, PROTOCOL_VERSION,
};
use control::slots::Slots;
use control::step::Faults;

/// Nominal bus voltage of the emulated board [V]: a 6S LiPo at rest (the firmware's
/// `V_BUS_NOMINAL`, 22.2 V).
pub const V_BUS_NOMINAL: f32 = 22.2;

#[derive(Debug, Clone, PartialEq)]
enum Run {
    Idle,
    Speed,
    Experiment {
        /// Voltage per period, precomputed.
        volts: Vec<f64>,
        k: usize,
    },
}

/// The emulated board.
pub struct BoardSim {
    rig: Rig,
    coeffs: Coefficients,
    coeff_seq: u32,
    slots: Slots<RamFlash>,
    upload: Upload,
    decoder: FrameDecoder,
    run: Run,
    omega_ref: f32,
    latched: Option<Fault>,
    seq: u32,
    run_start: f64,
    out: Vec<u8>,
    seed: u64,
}

fn fault_of(f: Faults) -> Option<Fault> {
    if f.contains(Faults::HALL_INVALID) {
        Some(Fault::InvalidHall)
    } else if f.contains(Faults::HALL_JUMP) {
        Some(Fault::ImpossibleTransition)
    } else {
        None
    }
}

impl BoardSim {
    /// A board at power-up: loads the newest valid coefficient slot of `flash` (or runs
    /// without compensation, with a warning, as the firmware does).
    pub fn new(plant: EmulatorConfig, flash: RamFlash) -> Result<BoardSim> {
        let seed = plant.seed;
        let mut slots = Slots::new(flash, 0, super::flash::PAGE as u32)
            .map_err(|e| anyhow!("emulated flash geometry: {e:?}"))?;
        let loaded = slots
            .load()
            .map_err(|e| anyhow!("emulated flash read: {e:?}"))?;
        let (coeffs, coeff_seq) = match loaded {
            Some((info, c)) => (c, info.seq),
            None => (Coefficients::default(), 0),
        };
        let rig = Rig::new(plant, &coeffs.step_config(V_BUS_NOMINAL))?;
        let mut sim = BoardSim {
            rig,
            coeffs,
            coeff_seq,
            slots,
            upload: Upload::new(),
            decoder: FrameDecoder::new(),
            run: Run::Idle,
            omega_ref: 0.0,
            latched: None,
            seq: 0,
            run_start: 0.0,
            out: Vec::new(),
            seed,
        };
        if coeff_seq == 0 {
            sim.send(&BoardMsg::Warning(Warning::NoCoefficients));
        }
        Ok(sim)
    }

    /// The loaded coefficients.
    pub fn coefficients(&self) -> &Coefficients {
        &self.coeffs
    }

    /// Sequence number of the loaded slot (0: none).
    pub fn coeff_seq(&self) -> u32 {
        self.coeff_seq
    }

    /// True while a run (speed or experiment) is active.
    pub fn is_running(&self) -> bool {
        self.run != Run::Idle
    }

    fn send(&mut self, msg: &BoardMsg) {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        if let Ok(f) = frame::encode_frame(msg, &mut buf) {
            self.out.extend_from_slice(f);
        }
    }

    /// Bytes to send to the host (whole frames).
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// Bytes received from the host.
    pub fn receive(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.decoder.push::<HostMsg>(b) {
                None => {}
                Some(Err(_)) => self.send(&BoardMsg::Warning(Warning::BadFrame)),
                Some(Ok(msg)) => self.handle(msg),
            }
        }
    }

    fn handle(&mut self, msg: HostMsg) {
        let reply = match msg {
            HostMsg::Identify => {
                let mut id = BoardMsg::Identity {
                    protocol: PROTOCOL_VERSION,
                    firmware: Default::default(),
                    model: self.coeffs.model,
                    coeff_seq: self.coeff_seq,
                };
                if let BoardMsg::Identity { firmware, .. } = &mut id {
                    // "emu-" marks the emulated board; the version is the firmware crate's.
                    let _ = firmware.push_str(concat!("emu-", env!("CARGO_PKG_VERSION")));
                }
                id
            }
            HostMsg::UploadBegin { total_len, crc } => match self.upload.begin(total_len, crc) {
                Ok(()) => BoardMsg::UploadAck { index: 0xFFFF },
                Err(n) => BoardMsg::Nack(n),
            },
            HostMsg::UploadChunk { index, data } => match self.upload.chunk(index, &data) {
                Ok(ChunkOutcome::Stored) | Ok(ChunkOutcome::Duplicate) => {
                    BoardMsg::UploadAck { index }
                }
                Err(n) => BoardMsg::Nack(n),
            },
            HostMsg::UploadAbort => {
                self.upload.abort();
                BoardMsg::UploadAck { index: 0xFFFF }
            }
            HostMsg::UploadCommit => {
                if self.run != Run::Idle {
                    BoardMsg::Nack(Nack::Busy)
                } else {
                    match self.upload.commit() {
                        Err(n) => BoardMsg::Nack(n),
                        Ok((bytes, coeffs)) => match self.slots.store(bytes) {
                            Ok(info) => {
                                self.coeff_seq = info.seq;
                                self.rig.reconfigure(&coeffs.step_config(V_BUS_NOMINAL));
                                self.coeffs = coeffs;
                                BoardMsg::Committed { seq: info.seq }
                            }
                            Err(_) => BoardMsg::Nack(Nack::Flash),
                        },
                    }
                }
            }
            HostMsg::SetSpeed { omega_ref } => {
                if omega_ref.is_finite() {
                    self.omega_ref = omega_ref;
                }
                BoardMsg::Ack
            }
            HostMsg::SetMode { mode } => match mode {
                Mode::Idle => {
                    self.run = Run::Idle;
                    BoardMsg::Ack
                }
                _ if self.latched.is_some() => BoardMsg::Nack(Nack::Faulted),
                Mode::Speed => {
                    self.start(Run::Speed);
                    BoardMsg::Ack
                }
                // Experiment mode starts with StartExperiment.
                Mode::Experiment => BoardMsg::Ack,
            },
            HostMsg::StartExperiment { signal, duration_s } => {
                if self.latched.is_some() {
                    BoardMsg::Nack(Nack::Faulted)
                } else {
                    let volts = excitation(signal, f64::from(duration_s), self.seed);
                    self.start(Run::Experiment { volts, k: 0 });
                    BoardMsg::Ack
                }
            }
            HostMsg::Stop => {
                self.run = Run::Idle;
                BoardMsg::Ack
            }
            HostMsg::ClearFault => {
                self.latched = None;
                BoardMsg::Ack
            }
        };
        self.send(&reply);
    }

    fn start(&mut self, run: Run) {
        self.rig
            .reconfigure(&self.coeffs.step_config(V_BUS_NOMINAL));
        self.run = run;
        self.run_start = self.rig.time();
        self.seq = 0;
    }

    /// One 12 ms control period. In idle the bridge is off and nothing is simulated.
    pub fn tick(&mut self) {
        let v_override = match &mut self.run {
            Run::Idle => return,
            Run::Speed => None,
            Run::Experiment { volts, k } => match volts.get(*k) {
                Some(&v) => {
                    *k += 1;
                    Some(v)
                }
                None => {
                    self.run = Run::Idle;
                    return;
                }
            },
        };
        let s = self.rig.step(f64::from(self.omega_ref), v_override);
        let lim = self.coeffs.limits;
        let fault = if s.i_meas.abs() > f64::from(lim.i_max) {
            Some(Fault::OverCurrent)
        } else {
            fault_of(s.out.faults)
        };
        if let Some(f) = fault {
            if self.latched.is_none() {
                self.send(&BoardMsg::Fault(f));
            }
            self.latched = Some(f);
            self.run = Run::Idle;
            return;
        }
        let sample = Sample {
            seq: self.seq,
            t: (s.t - self.run_start) as f32,
            u: s.out.v_cmd,
            i: s.i_meas as f32,
            theta: s.out.theta,
            omega: s.out.omega,
        };
        self.seq = self.seq.wrapping_add(1);
        self.send(&BoardMsg::Sample(sample));
    }
}

/// Longest experiment the board runs [s]; a longer request is cut to this.
pub const MAX_EXPERIMENT_S: f64 = 3600.0;

/// The board's excitation voltage per period, from the host emulator's signal table.
pub fn excitation(signal: Excitation, duration_s: f64, seed: u64) -> Vec<f64> {
    let ts = f64::from(control::CONTROL_PERIOD_S);
    // The duration comes over the serial link: bounded (NaN gives 0 samples).
    let n = (duration_s.clamp(0.0, MAX_EXPERIMENT_S) / ts).round() as usize;
    let kind = match signal {
        Excitation::A => SignalKind::A,
        Excitation::B => SignalKind::B,
        Excitation::C => SignalKind::C,
        Excitation::D => SignalKind::D,
        Excitation::Steady { volts } => return vec![f64::from(volts); n],
        Excitation::Ramp { volts_per_s } => {
            return (0..n)
                .map(|k| f64::from(volts_per_s) * k as f64 * ts)
                .collect()
        }
    };
    let mut v = signal_at(kind, duration_s.max(2.0 * ts), seed, ts);
    v.truncate(n);
    v
}

/// Blob helper for tests and tools: decode or say why not.
pub fn decode_blob(bytes: &[u8]) -> Result<Coefficients> {
    blob::decode(bytes).map_err(|e| anyhow!("{e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::frame::{decode_frame, encode_frame, CHUNK_LEN};

    fn frame(msg: &HostMsg) -> Vec<u8> {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        encode_frame(msg, &mut buf).unwrap().to_vec()
    }

    fn replies(sim: &mut BoardSim) -> Vec<BoardMsg> {
        sim.take_output()
            .split_inclusive(|&b| b == 0)
            .map(|f| decode_frame::<BoardMsg>(f).unwrap())
            .collect()
    }

    fn chunk(index: u16, bytes: &[u8]) -> HostMsg {
        let mut m = HostMsg::UploadChunk {
            index,
            data: Default::default(),
        };
        if let HostMsg::UploadChunk { data, .. } = &mut m {
            data.extend_from_slice(bytes).unwrap();
        }
        m
    }

    #[test]
    fn upload_with_a_retried_chunk_commits_once_and_is_refused_while_running() {
        let mut sim = BoardSim::new(EmulatorConfig::paper(), RamFlash::new(None)).unwrap();
        assert_eq!(
            replies(&mut sim),
            [BoardMsg::Warning(Warning::NoCoefficients)]
        );
        let co = Coefficients {
            model: control::blob::ModelKind::Lugre,
            lugre: Some(control::lugre::LugreParams::paper()),
            ..Coefficients::default()
        };
        let blob = crate::board::coeffs::encode(&co).unwrap();
        let crc = control::blob::CRC32.checksum(&blob);
        sim.receive(&frame(&HostMsg::UploadBegin {
            total_len: blob.len() as u16,
            crc,
        }));
        for (k, c) in blob.chunks(CHUNK_LEN).enumerate() {
            sim.receive(&frame(&chunk(k as u16, c)));
            // A lost ack: the host sends the same chunk again.
            sim.receive(&frame(&chunk(k as u16, c)));
        }
        sim.receive(&frame(&HostMsg::UploadCommit));
        let r = replies(&mut sim);
        assert_eq!(r.last(), Some(&BoardMsg::Committed { seq: 1 }));
        assert!(!r.iter().any(|m| matches!(m, BoardMsg::Nack(_))), "{r:?}");
        assert_eq!(sim.coefficients(), &co);
        // A replayed commit finds no upload.
        sim.receive(&frame(&HostMsg::UploadCommit));
        assert_eq!(replies(&mut sim), [BoardMsg::Nack(Nack::NoUpload)]);
        // Running: samples flow, commits are refused.
        sim.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        sim.tick();
        sim.tick();
        let r = replies(&mut sim);
        assert_eq!(r[0], BoardMsg::Ack);
        assert!(
            matches!(r[2], BoardMsg::Sample(Sample { seq: 1, .. })),
            "{r:?}"
        );
        sim.receive(&frame(&HostMsg::UploadBegin {
            total_len: blob.len() as u16,
            crc,
        }));
        sim.receive(&frame(&HostMsg::UploadCommit));
        let r = replies(&mut sim);
        assert_eq!(r.last(), Some(&BoardMsg::Nack(Nack::Busy)));
    }
}
