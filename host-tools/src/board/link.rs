//! The serial link client: talks to the board (or `motorid board --pty`) with the frames of
//! `control::frame` over a serial device, with timeouts and retries.
use anyhow::{anyhow, bail, Context, Result};
use control::commission::CommissionOutcome;
use control::frame::{
    self, BoardMsg, Excitation, Fault, FrameDecoder, HostMsg, Nack, Sample, Warning, CHUNK_LEN,
    MAX_ENCODED_LEN,
};
use control::telemetry::Telemetry;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// Baud rate of the board's link (ST-LINK virtual COM port, USART2 at 115200 8N1).
pub const BAUD: u32 = 115_200;
/// How long to wait for an answer before resending a request. 115200 baud moves a 64-byte
/// chunk in ~7 ms; the board answers within one 12 ms period; 500 ms leaves ample margin.
pub const ANSWER_TIMEOUT: Duration = Duration::from_millis(500);
/// Attempts per request (the first and 4 retries).
pub const ATTEMPTS: usize = 5;

/// What the board says about itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Identity {
    pub protocol: u16,
    pub firmware: String,
    pub model: control::blob::ModelKind,
    pub coeff_seq: u32,
    /// Largest speed reference the board takes [rad/s].
    pub speed_max: f32,
    /// The hardware over-current stop is armed.
    pub hw_stop_armed: bool,
    /// The loaded coefficients' motor constants were identified (not defaults).
    pub motor_identified: bool,
}

/// An open link to a board.
pub struct Link {
    port: Box<dyn serialport::SerialPort>,
    name: String,
    decoder: FrameDecoder,
    /// Samples that arrived while waiting for an answer.
    pub pending_samples: Vec<Sample>,
    /// Telemetry reports that arrived while waiting for an answer.
    pub pending_telemetry: Vec<Telemetry>,
}

impl Link {
    /// Open the serial device `path` (e.g. /dev/ttyACM0, or the path `motorid board --pty`
    /// printed).
    pub fn open(path: &str) -> Result<Link> {
        // As messages show it: control characters escaped, a long path cut.
        let name = crate::log::echo_path(std::path::Path::new(path));
        let port = serialport::new(path, BAUD)
            .timeout(Duration::from_millis(20))
            .open()
            .with_context(|| format!("{name}: cannot open the serial port"))?;
        Ok(Link {
            port,
            name,
            decoder: FrameDecoder::new(),
            pending_samples: Vec::new(),
            pending_telemetry: Vec::new(),
        })
    }

    /// The device path as messages show it.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Send one message.
    pub fn send(&mut self, msg: &HostMsg) -> Result<()> {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        let f = frame::encode_frame(msg, &mut buf).map_err(|e| anyhow!("{e}"))?;
        self.port
            .write_all(f)
            .and_then(|_| self.port.flush())
            .with_context(|| format!("{}: cannot write", self.name))
    }

    /// The next message from the board, or `None` after `timeout` without one. Frames that
    /// do not decode are skipped (the board's stream resynchronises at the next zero byte).
    /// A board warning is held as a `warning:` line ([`crate::warnings`]) and returned.
    /// Only a wait that brought no byte counts as silence: bytes waiting when this process
    /// resumes from a pause are read (up to two frames past the deadline to finish one).
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<BoardMsg>> {
        let deadline = Instant::now() + timeout;
        let mut byte = [0u8; 1];
        let mut late = 0usize;
        loop {
            match self.port.read(&mut byte) {
                Ok(1) => {
                    if let Some(Ok(msg)) = self.decoder.push::<BoardMsg>(byte[0]) {
                        if let BoardMsg::Warning(w) = msg {
                            crate::warnings::hold(format!("{}: {}", self.name, warning_text(w)));
                        }
                        return Ok(Some(msg));
                    }
                    // Past the deadline, at most two frames' worth of bytes to finish one.
                    late += usize::from(Instant::now() >= deadline);
                    if late <= 2 * MAX_ENCODED_LEN {
                        continue;
                    }
                }
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e).with_context(|| format!("{}: cannot read", self.name)),
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// Send `msg` and return the board's answer (not a sample, a warning or a periodic
    /// telemetry report), resending on silence.
    pub fn request(&mut self, msg: &HostMsg) -> Result<BoardMsg> {
        let wants_telemetry = matches!(msg, HostMsg::ReadTelemetry);
        for _ in 0..ATTEMPTS {
            self.send(msg)?;
            let deadline = Instant::now() + ANSWER_TIMEOUT;
            while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                match self.recv(left)? {
                    Some(BoardMsg::Sample(s)) => self.pending_samples.push(s),
                    Some(BoardMsg::Telemetry(t)) if !wants_telemetry => {
                        self.pending_telemetry.push(t)
                    }
                    Some(BoardMsg::Warning(_)) => {}
                    Some(BoardMsg::Fault(f)) => {
                        bail!("{}: the board reports a fault: {f:?}", self.name)
                    }
                    Some(other) => return Ok(other),
                    None => break,
                }
            }
        }
        bail!(
            "{}: no answer from the board after {ATTEMPTS} attempts (is it connected, powered and \
             running the motorid firmware?)",
            self.name
        )
    }

    /// Ask the board who it is.
    pub fn identify(&mut self) -> Result<Identity> {
        match self.request(&HostMsg::Identify)? {
            BoardMsg::Identity {
                protocol,
                firmware,
                model,
                coeff_seq,
                speed_max,
                hw_stop_armed,
                motor_identified,
            } => {
                if protocol != frame::PROTOCOL_VERSION {
                    bail!(
                        "{}: the board speaks protocol {protocol}, this motorid speaks {}; update one of them",
                        self.name,
                        frame::PROTOCOL_VERSION
                    );
                }
                // The board reports the state at every Identify: every command that opens
                // the link says so, not only the one that saw the boot warning.
                if !hw_stop_armed {
                    crate::warnings::hold(format!(
                        "{}: {}",
                        self.name,
                        warning_text(Warning::NoHardwareStop)
                    ));
                }
                if !motor_identified && coeff_seq != 0 {
                    crate::warnings::hold(format!(
                        "{}: the motor constants on the board are defaults, not \
                         identified: speed mode is refused until a fitted model is uploaded",
                        self.name
                    ));
                }
                Ok(Identity {
                    protocol,
                    firmware: firmware.as_str().to_string(),
                    model,
                    coeff_seq,
                    speed_max,
                    hw_stop_armed,
                    motor_identified,
                })
            }
            other => bail!("{}: unexpected answer to Identify: {other:?}", self.name),
        }
    }

    fn expect(
        &mut self,
        msg: &HostMsg,
        what: &str,
        ok: impl Fn(&BoardMsg) -> bool,
    ) -> Result<BoardMsg> {
        let ans = self.request(msg)?;
        if ok(&ans) {
            return Ok(ans);
        }
        match ans {
            BoardMsg::Nack(n) => bail!("{}: the board refused {what}: {}", self.name, nack_text(n)),
            other => bail!("{}: unexpected answer to {what}: {other:?}", self.name),
        }
    }

    /// Upload a blob: begin, chunks, commit. `progress(bytes_sent)` after each chunk.
    /// Returns the flash slot sequence number the board committed.
    pub fn upload(&mut self, blob: &[u8], mut progress: impl FnMut(usize)) -> Result<u32> {
        let crc = control::blob::CRC32.checksum(blob);
        let total_len = u16::try_from(blob.len())
            .map_err(|_| anyhow!("the blob is too long ({} bytes)", blob.len()))?;
        self.expect(
            &HostMsg::UploadBegin { total_len, crc },
            "the upload",
            |m| matches!(m, BoardMsg::UploadAck { index: 0xFFFF }),
        )?;
        let mut sent = 0;
        for (index, chunk) in blob.chunks(CHUNK_LEN).enumerate() {
            let index = index as u16;
            let mut data = heapless_chunk();
            if let HostMsg::UploadChunk { data: d, .. } = &mut data {
                d.extend_from_slice(chunk)
                    .map_err(|_| anyhow!("chunk longer than {CHUNK_LEN} bytes"))?;
            }
            if let HostMsg::UploadChunk { index: i, .. } = &mut data {
                *i = index;
            }
            self.expect(
                &data,
                "a chunk of the upload",
                |m| matches!(m, BoardMsg::UploadAck { index: i } if *i == index),
            )?;
            sent += chunk.len();
            progress(sent);
        }
        match self.expect(&HostMsg::UploadCommit, "the commit", |m| {
            matches!(m, BoardMsg::Committed { .. })
        })? {
            BoardMsg::Committed { seq } => Ok(seq),
            _ => unreachable!("expect() checked the variant"),
        }
    }

    /// Start an open-loop experiment (the board streams samples until it ends).
    pub fn start_experiment(&mut self, signal: Excitation, duration_s: f32) -> Result<()> {
        self.pending_samples.clear();
        self.expect(
            &HostMsg::StartExperiment { signal, duration_s },
            "the experiment",
            |m| matches!(m, BoardMsg::Ack),
        )?;
        Ok(())
    }

    /// Read the board's Hall commissioning result and the slot it is stored in.
    pub fn read_commission(&mut self) -> Result<(CommissionOutcome, u32)> {
        match self.request(&HostMsg::ReadCommission)? {
            BoardMsg::Commission { outcome, seq } => Ok((outcome, seq)),
            BoardMsg::Nack(n) => bail!("{}: the board refused: {}", self.name, nack_text(n)),
            other => bail!(
                "{}: unexpected answer to ReadCommission: {other:?}",
                self.name
            ),
        }
    }

    /// Run the Hall commissioning and wait (at most `timeout`) for its result.
    pub fn commission(&mut self, timeout: Duration) -> Result<(CommissionOutcome, u32)> {
        self.command(&HostMsg::Commission, "the commissioning")?;
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.recv(left)? {
                Some(BoardMsg::Commission { outcome, seq })
                    if outcome != CommissionOutcome::Running =>
                {
                    return Ok((outcome, seq))
                }
                Some(BoardMsg::Fault(f)) => {
                    bail!("{}: the board stopped with a fault: {f:?}", self.name)
                }
                Some(_) => {}
                None => break,
            }
        }
        bail!(
            "{}: no commissioning result within {} s",
            self.name,
            timeout.as_secs()
        )
    }

    /// The board's loop telemetry (its last complete one-second window).
    pub fn read_telemetry(&mut self) -> Result<Telemetry> {
        match self.request(&HostMsg::ReadTelemetry)? {
            BoardMsg::Telemetry(t) => Ok(t),
            BoardMsg::Nack(n) => bail!("{}: the board refused: {}", self.name, nack_text(n)),
            other => bail!(
                "{}: unexpected answer to ReadTelemetry: {other:?}",
                self.name
            ),
        }
    }

    /// Clears a latched fault, then listens for `settle`: the fault the board latches again
    /// in that time (its cause persists), if any.
    pub fn clear_fault(&mut self, settle: Duration) -> Result<Option<Fault>> {
        // Not `request`: it turns a fault report into an error, and here it is the answer.
        for _ in 0..ATTEMPTS {
            self.send(&HostMsg::ClearFault)?;
            let deadline = Instant::now() + ANSWER_TIMEOUT;
            let mut acked = false;
            while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                match self.recv(left)? {
                    Some(BoardMsg::Ack) => {
                        acked = true;
                        break;
                    }
                    Some(_) => {}
                    None => break,
                }
            }
            if !acked {
                continue;
            }
            let deadline = Instant::now() + settle;
            while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                match self.recv(left)? {
                    Some(BoardMsg::Fault(f)) => return Ok(Some(f)),
                    Some(_) => {}
                    None => break,
                }
            }
            return Ok(None);
        }
        bail!(
            "{}: no answer from the board after {ATTEMPTS} attempts (is it connected, powered and \
             running the motorid firmware?)",
            self.name
        )
    }

    /// A request answered by a plain `Ack`.
    pub fn command(&mut self, msg: &HostMsg, what: &str) -> Result<()> {
        self.expect(msg, what, |m| matches!(m, BoardMsg::Ack))?;
        Ok(())
    }
}

/// An empty `UploadChunk` (its buffer type comes from `control::frame`).
fn heapless_chunk() -> HostMsg {
    HostMsg::UploadChunk {
        index: 0,
        data: Default::default(),
    }
}

/// A refusal in words.
pub fn nack_text(n: Nack) -> String {
    match n {
        Nack::NoUpload => "no upload in progress".into(),
        Nack::TooLong => "the blob is too long for the board".into(),
        Nack::OutOfOrder { expected } => format!("chunk out of order (expected {expected})"),
        Nack::Conflict => "a chunk was resent with different bytes".into(),
        Nack::Incomplete => "the upload is incomplete".into(),
        Nack::BadCrc => "the received bytes do not match the blob's CRC".into(),
        Nack::BadBlob => {
            "the blob does not decode on the board (corrupted or wrong version)".into()
        }
        Nack::Busy => "the motor is running; stop it first".into(),
        Nack::Flash => "writing the flash failed".into(),
        Nack::Faulted => "a fault is latched; clear it first".into(),
        Nack::NoCoefficients => {
            "the board has no valid coefficients (upload a blob, or run motorid commission)".into()
        }
        Nack::OutOfRange => "a parameter is outside what the board allows".into(),
        Nack::NoHardwareStop => "the hardware over-current stop is not armed (see \
             docs/bring-up.md: check the comparator wiring, or build the firmware with \
             --features run-without-hw-stop to run on the software limit alone)"
            .into(),
        Nack::MotorNotIdentified => "the board's motor constants are defaults, not \
             identified: record an experiment, fit and upload the model (motorid export) \
             before speed mode"
            .into(),
    }
}

/// A board warning in words.
pub fn warning_text(w: Warning) -> &'static str {
    match w {
        Warning::NoCoefficients => {
            "no valid coefficients in flash: identify and commissioning only"
        }
        Warning::BadFrame => "the board received a damaged frame",
        Warning::LinkLost => "the board lost the link and stopped the run",
        Warning::NoHardwareStop => {
            "the hardware over-current stop is NOT armed: speed and experiment runs are refused"
        }
        Warning::Boot0FromPin => {
            "the option bytes take BOOT0 from pin PB8 (Hall H3); set nSWBOOT0 = 0, nBOOT0 = 1 \
             (docs/bring-up.md)"
        }
    }
}
