//! The serial frame codec between a host and the board (ST-LINK virtual COM port, USART2).
//!
//! # Protocol (version [`PROTOCOL_VERSION`])
//!
//! The link is a plain byte stream, 115200 baud 8N1 on the board. Each message travels as
//! one frame:
//!
//! ```text
//! frame = COBS( body ) 0x00
//! body  = postcard(message) ‖ CRC-32/ISO-HDLC(postcard(message)) as 4 bytes little-endian
//! ```
//!
//! COBS removes every zero byte from the body, so `0x00` only ever ends a frame: a receiver
//! that joins mid-stream, or loses bytes, resynchronises at the next zero. Empty frames
//! (consecutive zeros) are ignored; a frame longer than [`MAX_ENCODED_LEN`] is dropped whole.
//! A frame whose CRC, COBS code or postcard payload is wrong is an error and is dropped
//! (the receiver answers nothing; the host times out and retries).
//!
//! Host → board ([`HostMsg`]) and board → host ([`BoardMsg`]) are postcard-encoded Rust
//! enums; the variant index is the first byte of the body. The exchange:
//!
//! | host sends | board answers |
//! |---|---|
//! | `Identify` | `Identity { protocol, firmware, model, coeff_seq, speed_max, hw_stop_armed, motor_identified }` |
//! | `UploadBegin { total_len, crc }` | `UploadAck { index: 0xFFFF }` or `Nack` |
//! | `UploadChunk { index, data }` (≤ [`CHUNK_LEN`] bytes, index 0, 1, ...) | `UploadAck { index }` or `Nack` |
//! | `UploadCommit` | `Committed { seq }` after the flash write, or `Nack` (`Busy` unless idle) |
//! | `UploadAbort` | `UploadAck { index: 0xFFFF }` |
//! | `SetSpeed { omega_ref }` | `Ack`, or `Nack(OutOfRange)` when \|omega_ref\| exceeds `speed_max` (or is not finite) |
//! | `SetMode { mode }` | `Ack`, or `Nack(Faulted)` with a latched fault, `Nack(NoCoefficients)`, `Nack(NoHardwareStop)`, `Nack(MotorNotIdentified)` (see below), `Nack(Busy)` if the firmware's command queue is full |
//! | `StartExperiment { signal, duration_s }` | `Ack`, then samples until done (`t` and `seq` restart at 0) |
//! | `Stop` / `ClearFault` | `Ack` |
//! | `Heartbeat` | nothing (any frame keeps a speed or experiment run alive) |
//! | `Commission` | `Ack`, then `Commission { outcome, seq }` when done (during a commissioning run: `Ack`, the run goes on) |
//! | `ReadCommission` | `Commission { outcome, seq }` (the last run, or the stored one) |
//! | `ReadTelemetry` | `Telemetry(..)`: the last complete window of [`crate::telemetry`] |
//! | (nothing) | `Sample { .. }` every 12 ms while running, `Telemetry(..)` every second while running, `Fault`, `Warning` |
//!
//! Refusals: `SetMode { Speed }`, commissioning and experiments while the hardware
//! over-current stop is not armed (`Nack(NoHardwareStop)`, unless the firmware was built to run without it);
//! `SetMode { Speed }` while the coefficients' motor constants are not identified
//! (`Nack(MotorNotIdentified)`); a `SetSpeed` beyond `speed_max` (`Nack(OutOfRange)`);
//! `SetMode { Speed }` and `StartExperiment` without valid coefficients
//! (`Nack(NoCoefficients)`); an experiment whose duration is not finite, not
//! positive or above [`crate::board::MAX_EXPERIMENT_S`], or a steady voltage beyond `u_max`
//! (`Nack(OutOfRange)`); any start while a fault is latched (`Nack(Faulted)`). A speed or
//! experiment run stops (`Warning(LinkLost)`) when no frame came for
//! [`crate::board::LINK_TIMEOUT_PERIODS`] periods: hosts send `Heartbeat` while they listen.
//!
//! Replays and duplicates: upload chunks carry an index. The board accepts only the next
//! index; the same index again with the same bytes (the host retried after a lost ack) is
//! acknowledged without being stored twice; any other index, or the same index with other
//! bytes, is refused with `Nack(OutOfOrder { expected })` / `Nack(Conflict)`. A commit
//! checks the total length, the CRC announced in `UploadBegin` and then the blob itself
//! ([`crate::blob::decode`]) before anything is written to flash; a replayed commit finds
//! no upload in progress and is refused. Samples carry a running `seq`, so the host sees
//! dropped samples.
//!
//! [`encode_frame`] and [`decode_frame`] are pure functions; [`FrameDecoder`] accepts bytes
//! one at a time (the UART receive path) and yields whole messages; [`Upload`] is the
//! board-side upload state machine. Nothing here allocates or panics on any input.
use heapless::Vec;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::blob::{self, Coefficients, ModelKind, CRC32, MAX_BLOB_LEN};

/// Protocol version reported by `Identity`.
pub const PROTOCOL_VERSION: u16 = 10;
/// Largest upload chunk.
pub const CHUNK_LEN: usize = 64;
/// Largest body (postcard message + CRC).
pub const MAX_BODY_LEN: usize = 128;
/// Largest frame on the wire: COBS adds one byte per 254 plus one, then the delimiter.
pub const MAX_ENCODED_LEN: usize = MAX_BODY_LEN + MAX_BODY_LEN / 254 + 2;
/// Size of the CRC at the end of a body.
pub const FRAME_CRC_LEN: usize = 4;

/// What the board runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mode {
    /// Bridge off, nothing runs (the only mode in which coefficients can be committed).
    Idle,
    /// Closed-loop PI speed control with friction compensation.
    Speed,
    /// Open-loop excitation ([`Excitation`]) while logging.
    Experiment,
    /// Hall commissioning ([`crate::commission`]).
    Commission,
}

/// Open-loop excitation for experiment mode: the paper's signals a-d and two simple ones.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Excitation {
    /// Fitting signal up to 12 V, 0.1-1 Hz.
    A,
    /// Lower amplitude, 0.05-1 Hz, slower variation.
    B,
    /// 0-0.5 V, 0.25-1 Hz.
    C,
    /// Steps up to 10 V.
    D,
    /// Constant voltage.
    Steady { volts: f32 },
    /// Voltage rising linearly from zero.
    Ramp { volts_per_s: f32 },
}

/// Messages from the host to the board.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum HostMsg {
    /// Ask for [`BoardMsg::Identity`].
    Identify,
    /// Start staging a coefficient blob of `total_len` bytes whose CRC-32 is `crc`.
    UploadBegin { total_len: u16, crc: u32 },
    /// One piece of the blob; `index` counts from 0.
    UploadChunk {
        index: u16,
        data: Vec<u8, CHUNK_LEN>,
    },
    /// Verify the staged blob and write it to the spare flash slot.
    UploadCommit,
    /// Drop the staged blob.
    UploadAbort,
    /// Speed reference [rad/s] for [`Mode::Speed`].
    SetSpeed { omega_ref: f32 },
    /// Switch mode.
    SetMode { mode: Mode },
    /// Play an excitation open loop for `duration_s` seconds while streaming samples.
    StartExperiment { signal: Excitation, duration_s: f32 },
    /// Back to [`Mode::Idle`] (bridge off).
    Stop,
    /// Clear a latched fault (the bridge stays off until a mode is set).
    ClearFault,
    /// Nothing to do: keeps a run alive (link-loss detection).
    Heartbeat,
    /// Run the Hall commissioning ([`crate::commission`]); the result is stored with the
    /// coefficients.
    Commission,
    /// Ask for [`BoardMsg::Commission`].
    ReadCommission,
    /// Ask for [`BoardMsg::Telemetry`].
    ReadTelemetry,
}

/// Why a request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Nack {
    /// No upload in progress (chunk or commit without a begin, or a replayed commit).
    NoUpload,
    /// The announced or accumulated length exceeds the blob limit.
    TooLong,
    /// A chunk out of order; the board expects `expected`.
    OutOfOrder { expected: u16 },
    /// The same chunk index again with different bytes.
    Conflict,
    /// Commit before all announced bytes arrived.
    Incomplete,
    /// The staged bytes do not match the announced CRC.
    BadCrc,
    /// The staged blob does not decode or validate.
    BadBlob,
    /// Not allowed in the current mode (commit while the motor runs).
    Busy,
    /// Writing the flash failed.
    Flash,
    /// A fault is latched; clear it first.
    Faulted,
    /// No valid coefficients are loaded (speed and experiment modes need them).
    NoCoefficients,
    /// A parameter is outside what the board allows (duration, voltage).
    OutOfRange,
    /// The hardware over-current stop is not armed (commissioning, speed and experiment
    /// runs need it).
    NoHardwareStop,
    /// The coefficients' motor constants are defaults, not identified for this motor
    /// ([`crate::blob::Coefficients::motor_identified`]): speed mode needs an identified
    /// model; identify runs and experiments stay allowed.
    MotorNotIdentified,
}

/// Latched faults: each turns the bridge off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Fault {
    /// Hall state 000 or 111 (or unmapped in the table).
    InvalidHall,
    /// A Hall transition that skips a sector.
    ImpossibleTransition,
    /// Phase current above the limit.
    OverCurrent,
    /// Bus voltage below the limit.
    UnderVoltage,
    /// Bus voltage above the limit.
    OverVoltage,
    /// The control step overran its 12 ms period.
    Overrun,
    /// A voltage above the stall threshold and no Hall edge for
    /// [`crate::board::STALL_PERIODS`] periods.
    Stall,
    /// The hardware over-current stop cut the bridge within a PWM period: a phase current
    /// above [`crate::board::HW_TRIP_A`] (the board's rating), e.g. a short or a winding
    /// of very low resistance.
    HardwareOverCurrent,
    /// The board temperature (its NTC) reached [`crate::board::TEMP_MAX_C`].
    OverTemperature,
    /// The model's current window (`K_b·ω̂ ± R·i_limit`) and the measured current's did
    /// not overlap for [`crate::board::MISMATCH_PERIODS`] periods in a row: K_b or the
    /// pole pairs in the blob disagree with the motor.
    ModelMismatch,
    /// The speed estimate beyond [`crate::board::OVERSPEED_FACTOR`] times the speed limit
    /// for [`crate::board::OVERSPEED_PERIODS`] periods in a row.
    OverSpeed,
    /// The measured current flowed against the voltage driving it for
    /// [`crate::board::CURRENT_SENSE_PERIODS`] periods in a row
    /// ([`crate::step::current_sign_implausible`]): the current sense's sign is inverted
    /// (commissioning measures it), or the blob's K_b is far off the motor's.
    CurrentSense,
}

/// Warnings: logged, nothing stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Warning {
    /// No valid coefficient slot at boot: running without compensation.
    NoCoefficients,
    /// Received bytes that did not form a valid frame.
    BadFrame,
    /// No frame for [`crate::board::LINK_TIMEOUT_PERIODS`] periods: the run was stopped.
    LinkLost,
    /// The hardware over-current stop failed its boot self-test and is not armed: only the
    /// 12 ms software current limit protects the bridge (see the defmt log for why).
    NoHardwareStop,
    /// The option bytes take BOOT0 from its pin (nSWBOOT0 = 1); on the B-G431B-ESC1 that
    /// pin (PB8) is Hall input H3, so a motor resting with H3 high can start the ROM
    /// bootloader at reset instead of the firmware. Set nSWBOOT0 = 0, nBOOT0 = 1
    /// (docs/bring-up.md).
    Boot0FromPin,
}

/// One log sample, every 12 ms while running (the motor log's standard columns).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Running sample number (gaps mean lost samples).
    pub seq: u32,
    /// Time since the start of the run [s].
    pub t: f32,
    /// Commanded voltage [V].
    pub u: f32,
    /// Measured current [A].
    pub i: f32,
    /// Rotor angle [rad] (Hall-quantised).
    pub theta: f32,
    /// Velocity estimate [rad/s].
    pub omega: f32,
}

/// Messages from the board to the host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum BoardMsg {
    /// Answer to `Identify`.
    Identity {
        protocol: u16,
        /// Firmware version (`CARGO_PKG_VERSION`).
        firmware: heapless::String<16>,
        /// Model kind of the loaded coefficients.
        model: ModelKind,
        /// Sequence number of the loaded flash slot (0: none).
        coeff_seq: u32,
        /// Largest speed reference `SetSpeed` takes [rad/s]
        /// ([`crate::blob::Coefficients::speed_limit`]).
        speed_max: f32,
        /// The hardware over-current stop is armed (false: it failed its self-test at
        /// boot; speed and experiment runs are refused unless the firmware was built to
        /// run without it).
        hw_stop_armed: bool,
        /// The motor constants of the loaded coefficients were identified
        /// ([`crate::blob::Coefficients::motor_identified`]).
        motor_identified: bool,
    },
    /// Request done.
    Ack,
    /// Upload step accepted (`index` 0xFFFF for begin/abort).
    UploadAck { index: u16 },
    /// Blob written to flash as slot sequence `seq`; active now.
    Committed { seq: u32 },
    /// Request refused.
    Nack(Nack),
    /// Log sample.
    Sample(Sample),
    /// Fault latched, bridge off.
    Fault(Fault),
    /// Something to know.
    Warning(Warning),
    /// Hall commissioning result; `seq` is the flash slot it was stored in (0: not stored).
    Commission {
        outcome: crate::commission::CommissionOutcome,
        seq: u32,
    },
    /// Loop timing and lost Hall edges ([`crate::telemetry`]).
    Telemetry(crate::telemetry::Telemetry),
}

/// Why a frame could not be built or read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// The message does not fit [`MAX_BODY_LEN`] or the output buffer.
    TooLong,
    /// Invalid COBS encoding.
    Cobs,
    /// Fewer bytes than a CRC.
    Truncated,
    /// CRC mismatch.
    Crc,
    /// The body is not a postcard encoding of the expected message type.
    Payload,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::TooLong => "frame too long",
            FrameError::Cobs => "invalid COBS encoding",
            FrameError::Truncated => "frame too short",
            FrameError::Crc => "frame CRC mismatch",
            FrameError::Payload => "frame payload does not decode",
        })
    }
}

impl core::error::Error for FrameError {}

/// Encodes `msg` as one frame (COBS, CRC, trailing `0x00`) into `out`; returns the frame.
pub fn encode_frame<'a, M: Serialize>(msg: &M, out: &'a mut [u8]) -> Result<&'a [u8], FrameError> {
    let mut body = [0u8; MAX_BODY_LEN];
    let n = postcard::to_slice(msg, &mut body[..MAX_BODY_LEN - FRAME_CRC_LEN])
        .map_err(|_| FrameError::TooLong)?
        .len();
    let crc = CRC32.checksum(&body[..n]);
    body[n..n + FRAME_CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    let len = n + FRAME_CRC_LEN;
    let k = cobs::try_encode(&body[..len], out).map_err(|_| FrameError::TooLong)?;
    if k >= out.len() {
        return Err(FrameError::TooLong);
    }
    out[k] = 0;
    Ok(&out[..k + 1])
}

/// Checks the CRC of a COBS-decoded body and deserialises the message.
fn decode_body<M: DeserializeOwned>(body: &[u8]) -> Result<M, FrameError> {
    if body.len() < FRAME_CRC_LEN {
        return Err(FrameError::Truncated);
    }
    let (payload, crc) = body.split_at(body.len() - FRAME_CRC_LEN);
    let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC32.checksum(payload) != stored {
        return Err(FrameError::Crc);
    }
    match postcard::take_from_bytes::<M>(payload) {
        Ok((m, [])) => Ok(m),
        _ => Err(FrameError::Payload),
    }
}

/// Decodes one frame (with or without its trailing `0x00`).
pub fn decode_frame<M: DeserializeOwned>(frame: &[u8]) -> Result<M, FrameError> {
    let frame = frame.strip_suffix(&[0]).unwrap_or(frame);
    if frame.len() > MAX_ENCODED_LEN {
        return Err(FrameError::TooLong);
    }
    let mut buf = [0u8; MAX_ENCODED_LEN];
    let n = cobs::decode(frame, &mut buf).map_err(|_| FrameError::Cobs)?;
    decode_body(&buf[..n])
}

/// Streaming frame decoder: feed it received bytes one at a time.
#[derive(Debug)]
pub struct FrameDecoder {
    buf: [u8; MAX_ENCODED_LEN],
    len: usize,
    overflow: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        FrameDecoder {
            buf: [0; MAX_ENCODED_LEN],
            len: 0,
            overflow: false,
        }
    }

    /// Adds one byte. Returns `Some` when the byte ended a (non-empty) frame: the message,
    /// or why the frame was dropped. The decoder is ready for the next frame either way.
    pub fn push<M: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<M, FrameError>> {
        if byte != 0 {
            if self.len < self.buf.len() {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if overflow {
            return Some(Err(FrameError::TooLong));
        }
        if len == 0 {
            return None;
        }
        Some(match cobs::decode_in_place(&mut self.buf[..len]) {
            Ok(n) => decode_body(&self.buf[..n]),
            Err(_) => Err(FrameError::Cobs),
        })
    }

    /// Drops a partly received frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }
}

/// Result of an accepted chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkOutcome {
    /// New bytes stored.
    Stored,
    /// The previous chunk again, same bytes: acknowledged, nothing stored.
    Duplicate,
}

/// Board-side staging of a coefficient upload (begin, chunks in order, commit).
#[derive(Debug)]
pub struct Upload {
    buf: [u8; MAX_BLOB_LEN],
    total: usize,
    crc: u32,
    received: usize,
    next_index: u16,
    last_start: usize,
    active: bool,
}

impl Default for Upload {
    fn default() -> Self {
        Self::new()
    }
}

impl Upload {
    /// No upload in progress.
    pub const fn new() -> Self {
        Upload {
            buf: [0; MAX_BLOB_LEN],
            total: 0,
            crc: 0,
            received: 0,
            next_index: 0,
            last_start: 0,
            active: false,
        }
    }

    /// True between a begin and a commit/abort.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// Starts (or restarts) an upload of `total_len` bytes with CRC-32 `crc`.
    pub fn begin(&mut self, total_len: u16, crc: u32) -> Result<(), Nack> {
        let total = total_len as usize;
        if total == 0 || total > MAX_BLOB_LEN {
            self.active = false;
            return Err(Nack::TooLong);
        }
        *self = Upload {
            total,
            crc,
            active: true,
            ..Upload::new()
        };
        Ok(())
    }

    /// Stores chunk `index`; see the module doc for the replay rules.
    pub fn chunk(&mut self, index: u16, data: &[u8]) -> Result<ChunkOutcome, Nack> {
        if !self.active {
            return Err(Nack::NoUpload);
        }
        if self.next_index > 0 && index == self.next_index - 1 {
            let prev = &self.buf[self.last_start..self.received];
            return if prev == data {
                Ok(ChunkOutcome::Duplicate)
            } else {
                Err(Nack::Conflict)
            };
        }
        if index != self.next_index || self.next_index == u16::MAX {
            return Err(Nack::OutOfOrder {
                expected: self.next_index,
            });
        }
        if data.is_empty() {
            return Err(Nack::Conflict);
        }
        let end = self.received + data.len();
        if end > self.total {
            return Err(Nack::TooLong);
        }
        self.buf[self.received..end].copy_from_slice(data);
        self.last_start = self.received;
        self.received = end;
        self.next_index += 1;
        Ok(ChunkOutcome::Stored)
    }

    /// Verifies the staged blob (length, announced CRC, blob decode) and ends the upload.
    /// On success returns the blob bytes to persist and their decoded coefficients; on
    /// failure the upload is dropped.
    pub fn commit(&mut self) -> Result<(&[u8], Coefficients), Nack> {
        if !self.active {
            return Err(Nack::NoUpload);
        }
        self.active = false;
        if self.received != self.total {
            return Err(Nack::Incomplete);
        }
        let bytes = &self.buf[..self.total];
        if CRC32.checksum(bytes) != self.crc {
            return Err(Nack::BadCrc);
        }
        let c = blob::decode(bytes).map_err(|_| Nack::BadBlob)?;
        Ok((bytes, c))
    }

    /// Drops the staged bytes.
    pub fn abort(&mut self) {
        self.active = false;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec as StdVec;

    fn sample(k: u32) -> BoardMsg {
        BoardMsg::Sample(Sample {
            seq: k,
            t: k as f32 * 0.012,
            u: 11.5,
            i: -3.25,
            theta: 1.0e3,
            omega: -250.0,
        })
    }

    fn host_msgs() -> StdVec<HostMsg> {
        let mut data = Vec::new();
        for k in 0..CHUNK_LEN {
            data.push(k as u8).unwrap(); // includes zero bytes: COBS must hide them
        }
        std::vec![
            HostMsg::Identify,
            HostMsg::UploadBegin {
                total_len: 1000,
                crc: 0,
            },
            HostMsg::UploadChunk { index: 65534, data },
            HostMsg::UploadCommit,
            HostMsg::SetSpeed { omega_ref: -0.0 },
            HostMsg::SetMode { mode: Mode::Speed },
            HostMsg::StartExperiment {
                signal: Excitation::Ramp {
                    volts_per_s: 0.0095
                },
                duration_s: 120.0,
            },
            HostMsg::Stop,
        ]
    }

    fn frame_of<M: Serialize>(m: &M) -> StdVec<u8> {
        let mut out = [0u8; MAX_ENCODED_LEN];
        encode_frame(m, &mut out).unwrap().to_vec()
    }

    #[test]
    fn frames_round_trip_and_hide_zeros() {
        for m in host_msgs() {
            let f = frame_of(&m);
            assert_eq!(f.iter().filter(|&&b| b == 0).count(), 1);
            assert_eq!(*f.last().unwrap(), 0);
            assert_eq!(decode_frame::<HostMsg>(&f).unwrap(), m);
        }
        let id = BoardMsg::Identity {
            protocol: PROTOCOL_VERSION,
            firmware: heapless::String::try_from("0.1.0").unwrap(),
            model: ModelKind::Lugre,
            coeff_seq: 7,
            speed_max: 336.8,
            hw_stop_armed: true,
            motor_identified: true,
        };
        for m in [
            id,
            sample(3),
            BoardMsg::Nack(Nack::OutOfOrder { expected: 4 }),
        ] {
            assert_eq!(decode_frame::<BoardMsg>(&frame_of(&m)).unwrap(), m);
        }
    }

    #[test]
    fn streaming_decoder_splits_a_stream_and_resyncs() {
        let mut stream = std::vec![0x13, 0x37, 0x00]; // garbage before the first frame
        let msgs = host_msgs();
        for m in &msgs {
            stream.extend(frame_of(m));
            stream.push(0); // empty frames are ignored
        }
        let mut d = FrameDecoder::new();
        let mut got = StdVec::new();
        let mut errors = 0;
        for b in stream {
            match d.push::<HostMsg>(b) {
                Some(Ok(m)) => got.push(m),
                Some(Err(_)) => errors += 1,
                None => {}
            }
        }
        assert_eq!(got, msgs);
        assert_eq!(errors, 1, "the leading garbage is one bad frame");
    }

    #[test]
    fn overlong_frame_is_dropped_and_the_next_one_decodes() {
        let mut d = FrameDecoder::new();
        for _ in 0..MAX_ENCODED_LEN + 10 {
            assert!(d.push::<HostMsg>(0x55).is_none());
        }
        assert_eq!(d.push::<HostMsg>(0), Some(Err(FrameError::TooLong)));
        let f = frame_of(&HostMsg::Identify);
        let mut out = None;
        for &b in &f {
            out = d.push::<HostMsg>(b).or(out);
        }
        assert_eq!(out, Some(Ok(HostMsg::Identify)));
    }

    #[test]
    fn every_single_bit_flip_is_an_error() {
        for m in host_msgs() {
            let f = frame_of(&m);
            for byte in 0..f.len() - 1 {
                for bit in 0..8 {
                    let mut g = f.clone();
                    g[byte] ^= 1 << bit;
                    // A flip may create a 0x00 and split the frame: decode each piece.
                    let mut d = FrameDecoder::new();
                    for &b in &g {
                        if let Some(Ok(got)) = d.push::<HostMsg>(b) {
                            panic!("flip {byte}.{bit} of {m:?} decoded as {got:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn truncated_frames_are_errors() {
        for m in host_msgs() {
            let f = frame_of(&m);
            for n in 0..f.len() - 1 {
                assert!(
                    decode_frame::<HostMsg>(&f[..n]).is_err(),
                    "{m:?} cut to {n}"
                );
            }
        }
    }

    fn good_blob() -> StdVec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let c = Coefficients {
            model: ModelKind::Lugre,
            lugre: Some(crate::lugre::LugreParams::paper()),
            ..Coefficients::default()
        };
        blob::encode(&c, &mut buf).unwrap().to_vec()
    }

    #[test]
    fn upload_in_chunks_with_a_retried_chunk() {
        let b = good_blob();
        let mut up = Upload::new();
        up.begin(b.len() as u16, CRC32.checksum(&b)).unwrap();
        for (k, c) in b.chunks(CHUNK_LEN).enumerate() {
            assert_eq!(up.chunk(k as u16, c), Ok(ChunkOutcome::Stored));
            // The host retries the same chunk (lost ack): acknowledged, not stored twice.
            assert_eq!(up.chunk(k as u16, c), Ok(ChunkOutcome::Duplicate));
        }
        let (bytes, c) = up.commit().unwrap();
        assert_eq!(bytes, &b[..]);
        assert_eq!(c.model, ModelKind::Lugre);
        // A replayed commit finds nothing to commit.
        assert_eq!(up.commit().unwrap_err(), Nack::NoUpload);
    }

    #[test]
    fn replayed_and_out_of_order_chunks_are_refused() {
        let b = good_blob();
        let chunks: StdVec<&[u8]> = b.chunks(16).collect();
        let mut up = Upload::new();
        assert_eq!(up.chunk(0, chunks[0]), Err(Nack::NoUpload));
        up.begin(b.len() as u16, CRC32.checksum(&b)).unwrap();
        up.chunk(0, chunks[0]).unwrap();
        up.chunk(1, chunks[1]).unwrap();
        up.chunk(2, chunks[2]).unwrap();
        // An older chunk replayed.
        assert_eq!(
            up.chunk(0, chunks[0]),
            Err(Nack::OutOfOrder { expected: 3 })
        );
        // A skipped chunk.
        assert_eq!(
            up.chunk(4, chunks[4]),
            Err(Nack::OutOfOrder { expected: 3 })
        );
        // The last index with other bytes.
        assert_eq!(up.chunk(2, chunks[3]), Err(Nack::Conflict));
        // Early commit.
        assert_eq!(up.commit().unwrap_err(), Nack::Incomplete);
    }

    #[test]
    fn commit_checks_crc_and_blob() {
        let b = good_blob();
        let mut up = Upload::new();
        up.begin(b.len() as u16, CRC32.checksum(&b) ^ 1).unwrap();
        for (k, c) in b.chunks(CHUNK_LEN).enumerate() {
            up.chunk(k as u16, c).unwrap();
        }
        assert_eq!(up.commit().unwrap_err(), Nack::BadCrc);
        // Right CRC over bytes that are not a blob.
        let junk = [0xA5u8; 100];
        up.begin(100, CRC32.checksum(&junk)).unwrap();
        up.chunk(0, &junk[..50]).unwrap();
        up.chunk(1, &junk[50..]).unwrap();
        assert_eq!(up.commit().unwrap_err(), Nack::BadBlob);
        // Too long.
        assert_eq!(up.begin(MAX_BLOB_LEN as u16 + 1, 0), Err(Nack::TooLong));
        up.begin(10, 0).unwrap();
        assert_eq!(up.chunk(0, &[1; 11]), Err(Nack::TooLong));
    }

    proptest! {
        #[test]
        fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = decode_frame::<HostMsg>(&bytes);
            let _ = decode_frame::<BoardMsg>(&bytes);
            let mut d = FrameDecoder::new();
            for &b in &bytes {
                let _ = d.push::<HostMsg>(b);
            }
        }

        #[test]
        fn corrupted_frames_are_errors(
            which in 0usize..8,
            pos in any::<prop::sample::Index>(),
            xor in 1u8..=255,
        ) {
            let m = &host_msgs()[which];
            let mut f = frame_of(m);
            let body_len = f.len() - 1;
            let p = pos.index(body_len);
            f[p] ^= xor;
            let mut d = FrameDecoder::new();
            for &b in &f {
                if let Some(r) = d.push::<HostMsg>(b) {
                    prop_assert!(r.is_err(), "corrupted frame decoded: {:?}", r);
                }
            }
        }

        #[test]
        fn random_samples_round_trip(seq in any::<u32>(), t in any::<f32>(), u in -30f32..30.0,
                                     i in -40f32..40.0, th in any::<f32>(), om in any::<f32>()) {
            let m = BoardMsg::Sample(Sample { seq, t, u, i, theta: th, omega: om });
            let got: BoardMsg = decode_frame(&frame_of(&m)).unwrap();
            // Compare bit patterns: NaN != NaN.
            match (got, m) {
                (BoardMsg::Sample(a), BoardMsg::Sample(b)) => {
                    prop_assert_eq!(a.seq, b.seq);
                    prop_assert_eq!(a.t.to_bits(), b.t.to_bits());
                    prop_assert_eq!(a.theta.to_bits(), b.theta.to_bits());
                    prop_assert_eq!(a.omega.to_bits(), b.omega.to_bits());
                }
                _ => prop_assert!(false),
            }
        }
    }
}
