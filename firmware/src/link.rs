//! The serial link on the ST-LINK virtual COM port (USART2, PB3 TX / PB4 RX, 115200 8N1).
//!
//! Frames and messages are `control::frame` (COBS + postcard + CRC-32; the protocol is
//! documented there). Two tasks: [`rx_task`] decodes frames byte by byte, answers requests
//! and stages/commits coefficient uploads; [`tx_task`] writes every outgoing message (answers,
//! log samples, faults) as one frame. The control loop talks to them through [`OUTGOING`],
//! [`COMMANDS`] and [`NEW_COEFFS`]; the upload handler is `control::board::handle_upload`,
//! the same as the emulated board's.
use core::cell::RefCell;
use core::sync::atomic::{AtomicU8, Ordering};

use control::blob::Coefficients;
use control::board::handle_upload;
use control::frame::{
    self, BoardMsg, FrameDecoder, HostMsg, Nack, Upload, Warning, MAX_ENCODED_LEN,
};
use control::slots::Slots;
use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embedded_io_async::{Read, Write};

use crate::storage::EccFlash;

/// Flash offset of the first coefficient slot: `COEFFS` in `memory.x` (0x0801_F000), as an
/// offset from the flash base 0x0800_0000 (the `NorFlash` driver counts from there).
pub const SLOTS_OFFSET: u32 = 0x1_F000;
/// One slot per 2 KiB page (STM32G431 single-bank page size).
pub const SLOT_SIZE: u32 = 2048;

/// The coefficient flash slots (reads of a double ECC error fail, `storage`).
pub type FlashSlots = Slots<EccFlash>;

/// Host messages for the board logic (`control::board::Board::handle`, in the control loop).
pub static COMMANDS: Channel<CriticalSectionRawMutex, HostMsg, 4> = Channel::new();
/// Control loop and link → host. Samples are dropped (the host sees the `seq` gap) when full.
pub static OUTGOING: Channel<CriticalSectionRawMutex, BoardMsg, 8> = Channel::new();
/// Newly committed coefficients and their slot sequence, for the control loop. A channel
/// of one, not a `Signal`: the channel's empty state is all zero bytes, so this 1.3 KiB
/// static lives in .bss instead of costing its initial image in flash.
pub static NEW_COEFFS: Channel<CriticalSectionRawMutex, (Coefficients, u32), 1> = Channel::new();
/// The flash slots, shared by the link task (uploads) and the control loop (the
/// commissioning result). Both run in thread mode on one executor, so the lock never waits
/// and never masks interrupts during a page erase.
pub static SLOTS: Mutex<ThreadModeRawMutex, RefCell<Option<FlashSlots>>> =
    Mutex::new(RefCell::new(None));

/// What the control loop runs, for refusing commits while running.
pub static MODE: AtomicU8 = AtomicU8::new(MODE_IDLE);
pub const MODE_IDLE: u8 = 0;
pub const MODE_RUNNING: u8 = 1;

/// Loads the newest valid coefficients at boot; `None` (with a warning) when there are none.
pub fn load_coefficients(slots: &mut FlashSlots) -> Option<(Coefficients, u32)> {
    let loaded = slots.load_scanned().map(|(scan, loaded)| {
        for k in 0..2u8 {
            if scan.unreadable & (1 << k) != 0 {
                defmt::error!(
                    "coefficient slot {} unreadable (flash ECC error): skipped, the next upload rewrites it",
                    k
                );
            }
        }
        loaded
    });
    match loaded {
        Ok(Some((info, c))) => {
            defmt::info!(
                "coefficients: slot {} seq {} ({} bytes)",
                info.index,
                info.seq,
                info.len
            );
            Some((c, info.seq))
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

/// Queues a message for the host.
pub fn send(msg: BoardMsg) {
    // Answers are small and rare; if the queue is full the host times out and retries.
    let _ = OUTGOING.try_send(msg);
}

/// Receives and decodes host messages: uploads are handled here, the rest goes to the board
/// logic in the control loop.
#[embassy_executor::task]
pub async fn rx_task(mut rx: BufferedUartRx<'static>) {
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
                Some(Ok(msg)) => handle(msg, upload),
            }
        }
    }
}

fn handle(msg: HostMsg, upload: &mut Upload) {
    let idle = MODE.load(Ordering::Relaxed) == MODE_IDLE;
    let done = SLOTS.lock(|s| {
        let mut s = s.borrow_mut();
        let slots = s.as_mut()?;
        // Erasing a page stalls the CPU (single-bank flash): commits only with the bridge off.
        handle_upload(&msg, upload, slots, idle)
    });
    match done {
        Some((reply, new)) => {
            if let Some((c, seq)) = new {
                defmt::info!("coefficients committed: seq {}", seq);
                // The newest commit wins (a commit takes longer than a control period, so
                // the loop has taken the previous one already).
                NEW_COEFFS.clear();
                let _ = NEW_COEFFS.try_send((c, seq));
            }
            send(reply);
        }
        None if matches!(
            msg,
            HostMsg::UploadBegin { .. }
                | HostMsg::UploadChunk { .. }
                | HostMsg::UploadCommit
                | HostMsg::UploadAbort
        ) =>
        {
            // No flash storage.
            send(BoardMsg::Nack(Nack::Flash))
        }
        None => {
            if COMMANDS.try_send(msg).is_err() {
                send(BoardMsg::Nack(Nack::Busy));
            }
        }
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
