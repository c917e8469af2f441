//! The coefficient flash with its ECC errors turned into read errors, and the NMI handler
//! that does it.
//!
//! The STM32G4 programs flash in 64-bit double-words with an 8-bit ECC. A program cut by a
//! power loss (a commit interrupted mid-write) can leave a double-word whose ECC does not
//! match: reading it sets `FLASH_ECCR.ECCD` and raises the NMI (RM0440, "Error code
//! correction (ECC)"). Without a handler every boot would fault on the slot scan.
//!
//! [`NonMaskableInt`] clears ECCD; when the failing double-word lies in the coefficient
//! pages (`COEFFS` in `memory.x`) it notes the error and returns, the interrupted copy
//! finishes with unusable bytes, and [`EccFlash::read`] reports the read as failed, so
//! `control::slots` treats that slot as invalid and boots on the other one (the next
//! update erases the bad page, which clears the error). Any other NMI (an ECC error in the
//! program itself, the clock security system) turns the bridge off and waits for the
//! watchdog.
use core::sync::atomic::{compiler_fence, AtomicBool, Ordering};

use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::pac;
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::link::{SLOTS_OFFSET, SLOT_SIZE};

/// Set by the NMI handler: a double ECC error in the coefficient pages since the last read.
static ECC_ERROR: AtomicBool = AtomicBool::new(false);

/// Why a flash operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageError {
    /// The flash driver refused or failed.
    Driver(embassy_stm32::flash::Error),
    /// The bytes read include a double-word with a double ECC error.
    Ecc,
}

impl NorFlashError for StorageError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            StorageError::Driver(e) => e.kind(),
            StorageError::Ecc => NorFlashErrorKind::Other,
        }
    }
}

/// The internal flash, whose reads fail on a double ECC error instead of hanging the MCU.
pub struct EccFlash(pub Flash<'static, Blocking>);

impl ErrorType for EccFlash {
    type Error = StorageError;
}

impl ReadNorFlash for EccFlash {
    const READ_SIZE: usize = <Flash<'static, Blocking> as ReadNorFlash>::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), StorageError> {
        ECC_ERROR.store(false, Ordering::SeqCst);
        compiler_fence(Ordering::SeqCst);
        self.0.read(offset, bytes).map_err(StorageError::Driver)?;
        // The NMI follows the failing load by a few cycles: complete every access and flush
        // the pipeline, so that a pending NMI has run before the flag is read.
        compiler_fence(Ordering::SeqCst);
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
        if ECC_ERROR.swap(false, Ordering::SeqCst) {
            return Err(StorageError::Ecc);
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl NorFlash for EccFlash {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::ERASE_SIZE;

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), StorageError> {
        self.0.write(offset, bytes).map_err(StorageError::Driver)
    }

    fn erase(&mut self, from: u32, to: u32) -> Result<(), StorageError> {
        self.0.erase(from, to).map_err(StorageError::Driver)
    }
}

/// NMI: a double ECC error in the coefficient pages becomes a failed read; anything else
/// turns the bridge off and waits for the watchdog reset.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    let flash = pac::FLASH;
    let eccr = flash.eccr().read();
    if eccr.eccd() {
        // ADDR_ECC: byte offset of the failing double-word from the flash base.
        let addr = eccr.addr_ecc();
        // ECCD is cleared by writing 1; keep the interrupt enable as it was.
        flash.eccr().write(|w| {
            w.set_eccie(eccr.eccie());
            w.set_eccd(true);
        });
        let coeffs = SLOTS_OFFSET..SLOTS_OFFSET + 2 * SLOT_SIZE;
        if !eccr.sysf_ecc() && coeffs.contains(&addr) {
            ECC_ERROR.store(true, Ordering::SeqCst);
            return;
        }
    }
    crate::bridge::force_off();
    loop {
        cortex_m::asm::nop();
    }
}
