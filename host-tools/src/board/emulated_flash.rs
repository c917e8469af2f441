//! The emulated board's flash: the STM32G431's two coefficient pages in RAM (optionally
//! persisted to a file), behind the `embedded-storage` NorFlash traits so that the board
//! emulator stores blobs with the firmware's own two-slot code (`control::slots`).
use control::slots::Slots;
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use std::path::PathBuf;

/// Erase page of the STM32G431 (2 KiB, RM0440).
pub const PAGE: usize = 2048;
/// Flash size the slots use: two pages (the `COEFFS` region of memory.x).
pub const SIZE: usize = 2 * PAGE;

/// Out of range or misaligned access.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlashError(NorFlashErrorKind);

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        self.0
    }
}

/// Two erased pages; with `file`, loaded from and saved to it after every write.
///
/// A double-word can be marked as holding a double ECC error
/// ([`RamFlash::inject_ecc_error`]), as a program cut by a power loss leaves it on the
/// STM32G4: reading it fails (the firmware's NMI handler turns the NMI into a read error),
/// erasing its page clears it.
#[derive(Debug)]
pub struct RamFlash {
    mem: Vec<u8>,
    file: Option<PathBuf>,
    ecc: Vec<usize>,
}

impl RamFlash {
    /// Erased flash (all 0xFF), or the content of `file` if it exists.
    pub fn new(file: Option<PathBuf>) -> RamFlash {
        let mut mem = vec![0xFF; SIZE];
        if let Some(bytes) = file.as_ref().and_then(|f| std::fs::read(f).ok()) {
            let n = bytes.len().min(SIZE);
            mem[..n].copy_from_slice(&bytes[..n]);
        }
        RamFlash {
            mem,
            file,
            ecc: Vec::new(),
        }
    }

    /// The firmware's two-slot coefficient store ([`control::slots`]) on this flash: one
    /// page a slot from offset 0, as the `COEFFS` region lays them out.
    pub fn into_slots(self) -> anyhow::Result<Slots<RamFlash>> {
        Slots::new(self, 0, PAGE as u32).map_err(|e| anyhow::anyhow!("slot geometry: {e:?}"))
    }

    /// Marks the double-word holding byte `offset` as unreadable (a double ECC error).
    pub fn inject_ecc_error(&mut self, offset: usize) {
        self.ecc.push(offset / 8 * 8);
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<usize, FlashError> {
        let o = offset as usize;
        if !o.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(FlashError(NorFlashErrorKind::NotAligned));
        }
        if o + len > self.mem.len() {
            return Err(FlashError(NorFlashErrorKind::OutOfBounds));
        }
        Ok(o)
    }

    fn persist(&self) {
        if let Some(f) = &self.file {
            // Best effort: the emulated board keeps running on a read-only disk.
            let _ = crate::atomic::write(f, &self.mem);
        }
    }
}

impl ErrorType for RamFlash {
    type Error = FlashError;
}

impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let o = self.check(offset, bytes.len(), 1)?;
        if self.ecc.iter().any(|&d| d < o + bytes.len() && o < d + 8) {
            return Err(FlashError(NorFlashErrorKind::Other));
        }
        bytes.copy_from_slice(&self.mem[o..o + bytes.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl NorFlash for RamFlash {
    /// The G4 programs 64-bit double-words.
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if to < from {
            return Err(FlashError(NorFlashErrorKind::OutOfBounds));
        }
        let o = self.check(from, (to - from) as usize, PAGE)?;
        self.mem[o..to as usize].fill(0xFF);
        self.ecc.retain(|&d| d < o || d >= to as usize);
        self.persist();
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let o = self.check(offset, bytes.len(), 8)?;
        // NOR flash only clears bits.
        for (m, b) in self.mem[o..o + bytes.len()].iter_mut().zip(bytes) {
            *m &= *b;
        }
        self.persist();
        Ok(())
    }
}
