//! The serial link on the ST-LINK virtual COM port (USART2, PB3 TX / PB4 RX, 115200 8N1).
//!
//! Frames and messages are `control::frame` (COBS + postcard + CRC-32; the protocol is
//! documented there). Two tasks: [`rx_task`] decodes frames byte by byte, answers requests
//! and stages/commits coefficient uploads; [`tx_task`] writes every outgoing message (answers,
//! log samples, faults) as one frame. The control loop talks to them through [`OUTGOING`],
//! [`COMMANDS`] and [`NEW_COEFFS`].
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};

use control::blob::{Coefficients, ModelKind};
use control::frame::{
    self, BoardMsg, ChunkOutcome, Excitation, FrameDecoder, HostMsg, Mode, Nack, Upload, Warning,
    MAX_ENCODED_LEN, PROTOCOL_VERSION,
};
use control::slots::Slots;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embedded_io_async::{Read, Write};

/// Flash offset of the first coefficient slot: `COEFFS` in `memory.x` (0x0801_F000), as an
/// offset from the flash base 0x0800_0000 (the `NorFlash` driver counts from there).
pub const SLOTS_OFFSET: u32 = 0x1_F000;
/// One slot per 2 KiB page (STM32G431 single-bank page size).
pub const SLOT_SIZE: u32 = 2048;

/// Requests the control loop acts on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    SetSpeed(f32),
    SetMode(Mode),
    Start { signal: Excitation, duration_s: f32 },
    Stop,
    ClearFault,
}

/// Link → control loop.
pub static COMMANDS: Channel<CriticalSectionRawMutex, Command, 4> = Channel::new();
/// Control loop and link → host. Samples are dropped (the host sees the `seq` gap) when full.
pub static OUTGOING: Channel<CriticalSectionRawMutex, BoardMsg, 8> = Channel::new();
/// Newly committed coefficients for the control loop.
pub static NEW_COEFFS: Signal<CriticalSectionRawMutex, Coefficients> = Signal::new();

/// What the control loop runs, for `Identify` and for refusing commits while running.
pub static MODE: AtomicU8 = AtomicU8::new(MODE_IDLE);
pub const MODE_IDLE: u8 = 0;
pub const MODE_SPEED: u8 = 1;
pub const MODE_EXPERIMENT: u8 = 2;
/// Model kind of the loaded coefficients (0 none, 1 linear, 2 lugre, 3 sindyc).
pub static MODEL: AtomicU8 = AtomicU8::new(0);
/// Sequence number of the loaded flash slot (0: none).
pub static COEFF_SEQ: AtomicU32 = AtomicU32::new(0);

/// Encodes a model kind for [`MODEL`].
pub fn model_code(m: ModelKind) -> u8 {
    match m {
        ModelKind::None => 0,
        ModelKind::Linear => 1,
        ModelKind::Lugre => 2,
        ModelKind::Sindyc => 3,
    }
}

fn model_of(code: u8) -> ModelKind {
    match code {
        1 => ModelKind::Linear,
        2 => ModelKind::Lugre,
        3 => ModelKind::Sindyc,
        _ => ModelKind::None,
    }
}

/// Loads the newest valid coefficients at boot; `None` (with a warning) when there are none.
pub fn load_coefficients(slots: &mut Slots<Flash<'static, Blocking>>) -> Option<Coefficients> {
    match slots.load() {
        Ok(Some((info, c))) => {
            defmt::info!(
                "coefficients: slot {} seq {} ({} bytes)",
                info.index,
                info.seq,
                info.len
            );
            COEFF_SEQ.store(info.seq, Ordering::Relaxed);
            MODEL.store(model_code(c.model), Ordering::Relaxed);
            Some(c)
        }
        Ok(None) => {
            defmt::warn!("no valid coefficient slot: running without compensation");
            None
        }
        Err(e) => {
            let _ = e;
            defmt::warn!("flash read failed: running without compensation");
            None
        }
    }
}

fn send(msg: BoardMsg) {
    // Answers are small and rare; if the queue is full the host times out and retries.
    let _ = OUTGOING.try_send(msg);
}

fn command(c: Command) {
    if COMMANDS.try_send(c).is_err() {
        send(BoardMsg::Nack(Nack::Busy));
    } else {
        send(BoardMsg::Ack);
    }
}

/// Receives, decodes and answers host messages.
#[embassy_executor::task]
pub async fn rx_task(mut rx: BufferedUartRx<'static>, mut slots: Slots<Flash<'static, Blocking>>) {
    // Static: the decoder and the upload stage are 1.2 KiB; keep them off the task stack.
    static UPLOAD: static_cell::StaticCell<Upload> = static_cell::StaticCell::new();
    static DECODER: static_cell::StaticCell<FrameDecoder> = static_cell::StaticCell::new();
    let upload = UPLOAD.init(Upload::new());
    let decoder = DECODER.init(FrameDecoder::new());
    let mut buf = [0u8; 32];
    loop {
        let n = match rx.read(&mut buf).await {
            Ok(n) => n,
            Err(e) => {
                let _ = e;
                defmt::warn!("uart rx error");
                decoder.reset();
                continue;
            }
        };
        for &b in &buf[..n] {
            match decoder.push::<HostMsg>(b) {
                None => {}
                Some(Err(_)) => {
                    defmt::debug!("bad frame");
                    send(BoardMsg::Warning(Warning::BadFrame));
                }
                Some(Ok(msg)) => handle(msg, upload, &mut slots),
            }
        }
    }
}

fn handle(msg: HostMsg, upload: &mut Upload, slots: &mut Slots<Flash<'static, Blocking>>) {
    match msg {
        HostMsg::Identify => {
            let mut firmware = heapless::String::new();
            let _ = firmware.push_str(env!("CARGO_PKG_VERSION"));
            send(BoardMsg::Identity {
                protocol: PROTOCOL_VERSION,
                firmware,
                model: model_of(MODEL.load(Ordering::Relaxed)),
                coeff_seq: COEFF_SEQ.load(Ordering::Relaxed),
            });
        }
        HostMsg::UploadBegin { total_len, crc } => match upload.begin(total_len, crc) {
            Ok(()) => send(BoardMsg::UploadAck { index: 0xFFFF }),
            Err(n) => send(BoardMsg::Nack(n)),
        },
        HostMsg::UploadChunk { index, data } => match upload.chunk(index, &data) {
            Ok(ChunkOutcome::Stored) | Ok(ChunkOutcome::Duplicate) => {
                send(BoardMsg::UploadAck { index })
            }
            Err(n) => send(BoardMsg::Nack(n)),
        },
        HostMsg::UploadAbort => {
            upload.abort();
            send(BoardMsg::UploadAck { index: 0xFFFF });
        }
        HostMsg::UploadCommit => {
            // Erasing a page stalls the CPU (single-bank flash): only with the bridge off.
            if MODE.load(Ordering::Relaxed) != MODE_IDLE {
                send(BoardMsg::Nack(Nack::Busy));
                return;
            }
            match upload.commit() {
                Err(n) => send(BoardMsg::Nack(n)),
                Ok((bytes, coeffs)) => match slots.store(bytes) {
                    Ok(info) => {
                        defmt::info!(
                            "coefficients committed: slot {} seq {}",
                            info.index,
                            info.seq
                        );
                        COEFF_SEQ.store(info.seq, Ordering::Relaxed);
                        MODEL.store(model_code(coeffs.model), Ordering::Relaxed);
                        NEW_COEFFS.signal(coeffs);
                        send(BoardMsg::Committed { seq: info.seq });
                    }
                    Err(_) => {
                        defmt::error!("flash write failed");
                        send(BoardMsg::Nack(Nack::Flash));
                    }
                },
            }
        }
        HostMsg::SetSpeed { omega_ref } => command(Command::SetSpeed(omega_ref)),
        HostMsg::SetMode { mode } => command(Command::SetMode(mode)),
        HostMsg::StartExperiment { signal, duration_s } => {
            command(Command::Start { signal, duration_s })
        }
        HostMsg::Stop => command(Command::Stop),
        HostMsg::ClearFault => command(Command::ClearFault),
    }
}

/// Writes every outgoing message as one frame.
#[embassy_executor::task]
pub async fn tx_task(mut tx: BufferedUartTx<'static>) {
    let mut out = [0u8; MAX_ENCODED_LEN];
    loop {
        let msg = OUTGOING.receive().await;
        match frame::encode_frame(&msg, &mut out) {
            Ok(f) => {
                if tx.write_all(f).await.is_err() {
                    defmt::warn!("uart tx error");
                }
            }
            Err(_) => defmt::error!("frame encode failed"),
        }
    }
}
