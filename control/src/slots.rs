//! Two-slot flash storage of the coefficient blob, safe against a power cut at any moment.
//!
//! Two equal slots (on the STM32G431: the last two 2 KiB flash pages, the `COEFFS` region of
//! `memory.x`). Each slot holds a 16-byte header and then the blob:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"MIDS"` |
//! | 4 | 4 | sequence number (u32 LE, 1 for the first blob ever stored) |
//! | 8 | 4 | blob length (u32 LE) |
//! | 12 | 4 | CRC-32/ISO-HDLC over sequence ‖ length ‖ blob |
//! | 16 | len | the blob ([`crate::blob`]), padded with `0xFF` to the write size |
//!
//! A slot is *valid* when its magic, length and CRC hold and its blob decodes
//! ([`crate::blob::decode`]). Boot takes the valid slot with the newest sequence number, compared in serial-number
//! arithmetic so that the wrap from `u32::MAX` to 1 keeps the order.
//!
//! An update never touches the slot being used: it erases the *other* slot, writes the blob,
//! and writes the header last, with a sequence number above every header found. Until the
//! header's last byte is in flash, the new slot's CRC fails and boot keeps the old
//! coefficients; a power cut at any step (during the erase, the blob or the header) leaves
//! the old slot intact. The tests below cut the power after every single byte written or
//! erased and check exactly that.
//!
//! A slot that cannot be read at all is invalid too: on the STM32G4 a double-word program cut
//! by a power loss can leave a double ECC error, whose read raises an NMI; the firmware's
//! flash driver turns that into a read error for this slot only (`firmware/src/storage.rs`).
//! [`Slots::scan`] skips an unreadable slot ([`Scan::unreadable`]) and boots on the other
//! one; the next update erases the unreadable slot, which clears its ECC error. The host
//! tests model the error as a read that fails on a poisoned double-word.
use embedded_storage::nor_flash::NorFlash;

use crate::blob::{self, BlobError, Coefficients, CRC32, MAX_BLOB_LEN};

/// Magic at the start of a written slot.
pub const SLOT_MAGIC: [u8; 4] = *b"MIDS";
/// Slot header size.
pub const SLOT_HEADER_LEN: usize = 16;
/// Largest flash write granularity supported (the G4 writes 8-byte double-words).
const MAX_WRITE_SIZE: usize = 16;

/// Where a blob was found or stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotInfo {
    /// Slot index, 0 or 1.
    pub index: u8,
    /// Sequence number.
    pub seq: u32,
    /// Blob length in bytes.
    pub len: usize,
}

/// Why a slot operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotError<E> {
    /// The flash driver failed (on the host tests: the simulated power cut).
    Flash(E),
    /// The slot geometry does not fit the flash (alignment, size, capacity).
    Geometry,
    /// The blob to store is not valid; nothing was written.
    Blob(BlobError),
    /// The blob read back after writing differs from what was written.
    Verify,
}

impl<E: core::fmt::Debug> core::fmt::Display for SlotError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SlotError::Flash(e) => write!(f, "flash error: {e:?}"),
            SlotError::Geometry => write!(f, "coefficient slots do not fit the flash"),
            SlotError::Blob(e) => write!(f, "{e}"),
            SlotError::Verify => write!(f, "flash verify failed after writing coefficients"),
        }
    }
}

/// What a scan of the two slots found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Scan {
    /// The newest valid slot, if any.
    pub active: Option<SlotInfo>,
    /// Newest sequence number (serial arithmetic, [`seq_is_newer`]) of any slot whose header and
    /// CRC hold (0 if none).
    pub max_seq: u32,
    /// Bit `k` set: slot `k` could not be read (a flash read error, e.g. an ECC error left
    /// by an interrupted write); it counts as invalid.
    pub unreadable: u8,
}

/// Coefficients loaded from a slot, with where they were found.
pub type Loaded = (SlotInfo, Coefficients);

/// Two coefficient slots on a NOR flash.
pub struct Slots<F> {
    flash: F,
    base: u32,
    slot_size: u32,
}

impl<F: NorFlash> Slots<F> {
    /// Slots at `base` and `base + slot_size` (offsets as the flash driver counts them).
    /// Both must be erase-aligned and hold the header plus the largest blob.
    pub fn new(flash: F, base: u32, slot_size: u32) -> Result<Self, SlotError<F::Error>> {
        let erase = F::ERASE_SIZE as u32;
        let ok = erase > 0
            && base.is_multiple_of(erase)
            && slot_size.is_multiple_of(erase)
            && slot_size as usize >= SLOT_HEADER_LEN + MAX_BLOB_LEN
            && (base as usize).saturating_add(2 * slot_size as usize) <= flash.capacity()
            && F::WRITE_SIZE <= MAX_WRITE_SIZE
            && SLOT_HEADER_LEN.is_multiple_of(F::WRITE_SIZE)
            && SLOT_HEADER_LEN.is_multiple_of(F::READ_SIZE)
            && MAX_BLOB_LEN.is_multiple_of(F::READ_SIZE);
        if !ok {
            return Err(SlotError::Geometry);
        }
        Ok(Slots {
            flash,
            base,
            slot_size,
        })
    }

    /// Gives the flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    fn slot_addr(&self, index: u8) -> u32 {
        self.base + index as u32 * self.slot_size
    }

    /// Reads slot `index`: `Some((seq, len))` with the blob in `buf[..len]` when the header
    /// and CRC hold.
    fn read_slot(
        &mut self,
        index: u8,
        buf: &mut [u8; MAX_BLOB_LEN],
    ) -> Result<Option<(u32, usize)>, F::Error> {
        let addr = self.slot_addr(index);
        let mut h = [0u8; SLOT_HEADER_LEN];
        self.flash.read(addr, &mut h)?;
        if h[0..4] != SLOT_MAGIC {
            return Ok(None);
        }
        let word = |k: usize| u32::from_le_bytes([h[k], h[k + 1], h[k + 2], h[k + 3]]);
        let (seq, len, crc) = (word(4), word(8) as usize, word(12));
        if len == 0 || len > MAX_BLOB_LEN {
            return Ok(None);
        }
        let read_len = len.div_ceil(F::READ_SIZE) * F::READ_SIZE;
        self.flash
            .read(addr + SLOT_HEADER_LEN as u32, &mut buf[..read_len])?;
        let mut digest = CRC32.digest();
        digest.update(&h[4..12]);
        digest.update(&buf[..len]);
        Ok((digest.finalize() == crc).then_some((seq, len)))
    }

    /// Scans both slots; the newest valid blob is left in `buf[..active.len]`. A slot whose
    /// read fails is invalid ([`Scan::unreadable`]); only a failure to re-read the winner is
    /// an error.
    pub fn scan(&mut self, buf: &mut [u8; MAX_BLOB_LEN]) -> Result<Scan, F::Error> {
        let mut scan = Scan::default();
        // Read the slot that turns out to be the newest valid one last, so that `buf` holds
        // it: scan both, then re-read the winner.
        for index in 0..2u8 {
            let read = match self.read_slot(index, buf) {
                Ok(r) => r,
                Err(_) => {
                    scan.unreadable |= 1 << index;
                    None
                }
            };
            if let Some((seq, len)) = read {
                if scan.max_seq == 0 || seq_is_newer(seq, scan.max_seq) {
                    scan.max_seq = seq;
                }
                let valid = blob::decode(&buf[..len]).is_ok();
                let newer = scan.active.is_none_or(|a| seq_is_newer(seq, a.seq));
                if valid && newer {
                    scan.active = Some(SlotInfo { index, seq, len });
                }
            }
        }
        if let Some(a) = scan.active {
            if a.index == 0 {
                // Slot 1 was read last; bring slot 0 back into `buf`.
                self.read_slot(0, buf)?;
            }
        }
        Ok(scan)
    }

    /// Loads the newest valid coefficients, or `None` when neither slot holds any.
    pub fn load(&mut self) -> Result<Option<Loaded>, F::Error> {
        Ok(self.load_scanned()?.1)
    }

    /// [`Slots::load`] with what the scan found (unreadable slots, for the boot report).
    pub fn load_scanned(&mut self) -> Result<(Scan, Option<Loaded>), F::Error> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let scan = self.scan(&mut buf)?;
        let loaded = scan.active.and_then(|a| {
            // `scan` validated this blob already; decode cannot fail here, but a failure
            // would only mean "no coefficients", never a panic.
            blob::decode(&buf[..a.len]).ok().map(|c| (a, c))
        });
        Ok((scan, loaded))
    }

    /// Stores a blob in the slot not in use and returns where. The blob must decode.
    pub fn store(&mut self, blob_bytes: &[u8]) -> Result<SlotInfo, SlotError<F::Error>> {
        blob::decode(blob_bytes).map_err(SlotError::Blob)?;
        let len = blob_bytes.len();
        let mut buf = [0u8; MAX_BLOB_LEN];
        let scan = self.scan(&mut buf).map_err(SlotError::Flash)?;
        let index = match scan.active {
            Some(a) => 1 - a.index,
            None => 0,
        };
        let seq = scan.max_seq.wrapping_add(1).max(1);
        let addr = self.slot_addr(index);
        let f = &mut self.flash;
        f.erase(addr, addr + self.slot_size)
            .map_err(SlotError::Flash)?;

        // The blob first: whole write units straight from the input, the tail padded.
        let ws = F::WRITE_SIZE;
        let body = addr + SLOT_HEADER_LEN as u32;
        let whole = len / ws * ws;
        if whole > 0 {
            f.write(body, &blob_bytes[..whole])
                .map_err(SlotError::Flash)?;
        }
        if whole < len {
            let mut tail = [0xFFu8; MAX_WRITE_SIZE];
            tail[..len - whole].copy_from_slice(&blob_bytes[whole..]);
            f.write(body + whole as u32, &tail[..ws])
                .map_err(SlotError::Flash)?;
        }

        // The header last: until its final byte lands, the slot's CRC fails.
        let mut h = [0u8; SLOT_HEADER_LEN];
        h[0..4].copy_from_slice(&SLOT_MAGIC);
        h[4..8].copy_from_slice(&seq.to_le_bytes());
        h[8..12].copy_from_slice(&(len as u32).to_le_bytes());
        let mut digest = CRC32.digest();
        digest.update(&h[4..12]);
        digest.update(blob_bytes);
        h[12..16].copy_from_slice(&digest.finalize().to_le_bytes());
        f.write(addr, &h).map_err(SlotError::Flash)?;

        // Verify.
        match self.read_slot(index, &mut buf).map_err(SlotError::Flash)? {
            Some((s, n)) if s == seq && n == len && buf[..n] == *blob_bytes => {
                Ok(SlotInfo { index, seq, len })
            }
            _ => Err(SlotError::Verify),
        }
    }
}

/// True when sequence number `a` was written after `b`, in serial-number arithmetic
/// (RFC 1982): the numbers wrap from `u32::MAX` to 1, and the two slots never lie more than a
/// few stores apart, so the forward distance from `b` to `a` decides.
pub fn seq_is_newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::blob::{encode, ModelKind};
    use crate::lugre::LugreParams;
    use embedded_storage::nor_flash::{ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash};
    use std::vec::Vec;

    const PAGE: usize = 2048;

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum MemError {
        PowerCut,
        Misaligned,
        OutOfBounds,
        Ecc,
    }

    impl NorFlashError for MemError {
        fn kind(&self) -> NorFlashErrorKind {
            match self {
                MemError::PowerCut | MemError::Ecc => NorFlashErrorKind::Other,
                MemError::Misaligned => NorFlashErrorKind::NotAligned,
                MemError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            }
        }
    }

    /// In-memory NOR flash with the G4's geometry (2 KiB pages, 8-byte writes). Writes can
    /// only clear bits (NOR), erases set 0xFF. With a `budget`, the power fails after that
    /// many byte steps (each byte erased or written is one step): the interrupted operation
    /// is left half done and every later operation fails.
    ///
    /// `ecc` lists double-words (by offset) holding a double ECC error: reading any byte of
    /// one fails, erasing its page clears it.
    #[derive(Clone)]
    struct MemFlash {
        mem: Vec<u8>,
        budget: Option<usize>,
        steps: usize,
        ecc: Vec<usize>,
    }

    impl MemFlash {
        fn new(pages: usize) -> Self {
            MemFlash {
                mem: std::vec![0xFF; pages * PAGE],
                budget: None,
                steps: 0,
                ecc: Vec::new(),
            }
        }

        fn step(&mut self) -> Result<(), MemError> {
            if let Some(b) = self.budget {
                if self.steps >= b {
                    return Err(MemError::PowerCut);
                }
            }
            self.steps += 1;
            Ok(())
        }

        /// The same memory after a reboot: no budget, fresh step count.
        fn rebooted(&self) -> Self {
            MemFlash {
                mem: self.mem.clone(),
                budget: None,
                steps: 0,
                ecc: self.ecc.clone(),
            }
        }
    }

    impl ErrorType for MemFlash {
        type Error = MemError;
    }

    impl ReadNorFlash for MemFlash {
        const READ_SIZE: usize = 1;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MemError> {
            let o = offset as usize;
            if self.ecc.iter().any(|&d| d < o + bytes.len() && o < d + 8) {
                return Err(MemError::Ecc);
            }
            let src = self
                .mem
                .get(o..o + bytes.len())
                .ok_or(MemError::OutOfBounds)?;
            bytes.copy_from_slice(src);
            Ok(())
        }
        fn capacity(&self) -> usize {
            self.mem.len()
        }
    }

    impl NorFlash for MemFlash {
        const WRITE_SIZE: usize = 8;
        const ERASE_SIZE: usize = PAGE;
        fn erase(&mut self, from: u32, to: u32) -> Result<(), MemError> {
            let (from, to) = (from as usize, to as usize);
            if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) || from > to {
                return Err(MemError::Misaligned);
            }
            if to > self.mem.len() {
                return Err(MemError::OutOfBounds);
            }
            for k in from..to {
                self.step()?;
                self.mem[k] = 0xFF;
            }
            self.ecc.retain(|&d| d < from || d >= to);
            Ok(())
        }
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), MemError> {
            let o = offset as usize;
            if !o.is_multiple_of(8) || !bytes.len().is_multiple_of(8) {
                return Err(MemError::Misaligned);
            }
            if o + bytes.len() > self.mem.len() {
                return Err(MemError::OutOfBounds);
            }
            for (k, &b) in bytes.iter().enumerate() {
                self.step()?;
                self.mem[o + k] &= b;
            }
            Ok(())
        }
    }

    /// Slots in pages 1 and 2 of a 4-page flash (base not at 0, as on the board).
    fn slots(f: MemFlash) -> Slots<MemFlash> {
        Slots::new(f, PAGE as u32, PAGE as u32).unwrap()
    }

    fn coeffs(kind: u8) -> Coefficients {
        let mut c = Coefficients::default();
        match kind {
            0 => {}
            1 => {
                c.model = ModelKind::Lugre;
                c.lugre = Some(LugreParams::paper());
            }
            _ => {
                c.model = ModelKind::Linear;
                c.pole_pairs = 4;
                c.pi.kp = 0.125;
            }
        }
        c
    }

    fn blob_of(c: &Coefficients) -> Vec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        encode(c, &mut buf).unwrap().to_vec()
    }

    fn loaded(f: &MemFlash) -> Option<(SlotInfo, Coefficients)> {
        slots(f.rebooted()).load().unwrap()
    }

    #[test]
    fn empty_flash_has_no_coefficients() {
        assert_eq!(loaded(&MemFlash::new(4)), None);
    }

    #[test]
    fn updates_alternate_slots_and_the_newest_wins() {
        let mut s = slots(MemFlash::new(4));
        let a = s.store(&blob_of(&coeffs(0))).unwrap();
        let b = s.store(&blob_of(&coeffs(1))).unwrap();
        let c = s.store(&blob_of(&coeffs(2))).unwrap();
        assert_eq!((a.index, a.seq), (0, 1));
        assert_eq!((b.index, b.seq), (1, 2));
        assert_eq!((c.index, c.seq), (0, 3));
        let f = s.into_inner();
        let (info, got) = loaded(&f).unwrap();
        assert_eq!(info, c);
        assert_eq!(got, coeffs(2));
        // Pages outside the two slots are untouched.
        assert!(f.mem[..PAGE].iter().all(|&b| b == 0xFF));
        assert!(f.mem[3 * PAGE..].iter().all(|&b| b == 0xFF));
    }

    #[test]
    fn invalid_blob_is_not_stored() {
        let mut s = slots(MemFlash::new(4));
        let mut b = blob_of(&coeffs(1));
        b[20] ^= 0x40;
        assert!(matches!(s.store(&b), Err(SlotError::Blob(_))));
        assert!(s.into_inner().mem.iter().all(|&x| x == 0xFF));
    }

    #[test]
    fn corrupted_newest_slot_falls_back_to_the_older() {
        let mut s = slots(MemFlash::new(4));
        s.store(&blob_of(&coeffs(1))).unwrap();
        let newest = s.store(&blob_of(&coeffs(2))).unwrap();
        let mut f = s.into_inner();
        // Flip one bit inside the newest blob (slot 1, page 2).
        f.mem[2 * PAGE + SLOT_HEADER_LEN + 30] ^= 0x01;
        let (info, got) = loaded(&f).unwrap();
        assert_eq!(info.index, 1 - newest.index);
        assert_eq!(got, coeffs(1));
        // The next update must not overwrite the good slot, and must outrank it.
        let mut s = slots(f.rebooted());
        let next = s.store(&blob_of(&coeffs(0))).unwrap();
        assert_eq!(next.index, newest.index);
        assert!(next.seq > info.seq);
        assert_eq!(loaded(&s.into_inner()).unwrap().1, coeffs(0));
    }

    #[test]
    fn undecodable_newer_slot_is_skipped_and_outranked() {
        // A newer slot whose header and CRC hold but whose blob does not decode (e.g. a blob
        // format this firmware does not read): boot keeps the older valid one, and the next
        // update replaces the undecodable slot with a higher sequence number.
        let mut s = slots(MemFlash::new(4));
        s.store(&blob_of(&coeffs(1))).unwrap();
        let mut f = s.into_inner();
        let mut bad = blob_of(&coeffs(2));
        bad[4] = 0x7F; // blob version 0x..7F: refused by blob::decode
        let seq = 5u32;
        let base = 2 * PAGE; // slot 1
        f.mem[base + SLOT_HEADER_LEN..base + SLOT_HEADER_LEN + bad.len()].copy_from_slice(&bad);
        let mut h = [0u8; SLOT_HEADER_LEN];
        h[0..4].copy_from_slice(&SLOT_MAGIC);
        h[4..8].copy_from_slice(&seq.to_le_bytes());
        h[8..12].copy_from_slice(&(bad.len() as u32).to_le_bytes());
        let mut d = CRC32.digest();
        d.update(&h[4..12]);
        d.update(&bad);
        h[12..16].copy_from_slice(&d.finalize().to_le_bytes());
        f.mem[base..base + SLOT_HEADER_LEN].copy_from_slice(&h);

        let (info, got) = loaded(&f).unwrap();
        assert_eq!((info.index, got), (0, coeffs(1)));
        let mut s = slots(f.rebooted());
        let next = s.store(&blob_of(&coeffs(0))).unwrap();
        assert_eq!((next.index, next.seq), (1, seq + 1));
        assert_eq!(loaded(&s.into_inner()).unwrap().1, coeffs(0));
    }

    #[test]
    fn sequence_numbers_wrap_and_the_newer_slot_still_wins() {
        // Slots written at u32::MAX - 1 and u32::MAX: the next store takes 1 (0 is never
        // written), goes to the older slot and wins over u32::MAX.
        let mut f = MemFlash::new(4);
        let mut put = |index: usize, seq: u32, blob: &[u8]| {
            let base = 2 * PAGE * index;
            f.mem[base + SLOT_HEADER_LEN..base + SLOT_HEADER_LEN + blob.len()]
                .copy_from_slice(blob);
            let mut h = [0u8; SLOT_HEADER_LEN];
            h[0..4].copy_from_slice(&SLOT_MAGIC);
            h[4..8].copy_from_slice(&seq.to_le_bytes());
            h[8..12].copy_from_slice(&(blob.len() as u32).to_le_bytes());
            let mut d = CRC32.digest();
            d.update(&h[4..12]);
            d.update(blob);
            h[12..16].copy_from_slice(&d.finalize().to_le_bytes());
            f.mem[base..base + SLOT_HEADER_LEN].copy_from_slice(&h);
        };
        put(0, u32::MAX - 1, &blob_of(&coeffs(1)));
        put(1, u32::MAX, &blob_of(&coeffs(2)));
        let (info, got) = loaded(&f).unwrap();
        assert_eq!((info.index, info.seq, got), (1, u32::MAX, coeffs(2)));

        let mut s = slots(f.rebooted());
        let next = s.store(&blob_of(&coeffs(3))).unwrap();
        assert_eq!((next.index, next.seq), (0, 1));
        let (info, got) = loaded(&s.into_inner()).unwrap();
        assert_eq!((info.index, got), (0, coeffs(3)));
        assert!(seq_is_newer(1, u32::MAX) && !seq_is_newer(u32::MAX, 1));
    }

    #[test]
    fn an_unreadable_slot_is_skipped_and_its_next_update_clears_it() {
        // The newest slot's header holds a double ECC error (a write cut by a power loss):
        // boot takes the older slot, and the next update goes to the unreadable one.
        let mut s = slots(MemFlash::new(4));
        s.store(&blob_of(&coeffs(1))).unwrap();
        let newest = s.store(&blob_of(&coeffs(2))).unwrap();
        let mut f = s.into_inner();
        let slot1 = 2 * PAGE; // slot 1 (page 2) holds the newest
        assert_eq!(newest.index, 1);
        f.ecc.push(slot1 + 8);
        let mut s = slots(f.rebooted());
        let (scan, got) = s.load_scanned().unwrap();
        assert_eq!(scan.unreadable, 0b10);
        let (info, got) = got.unwrap();
        assert_eq!((info.index, got), (0, coeffs(1)));
        let next = s.store(&blob_of(&coeffs(0))).unwrap();
        assert_eq!(next.index, 1);
        assert!(next.seq > info.seq);
        let f = s.into_inner();
        assert!(f.ecc.is_empty(), "the erase clears the ECC error");
        let mut s = slots(f.rebooted());
        let (scan, got) = s.load_scanned().unwrap();
        assert_eq!(scan.unreadable, 0);
        assert_eq!(got.unwrap().1, coeffs(0));
    }

    #[test]
    fn both_slots_unreadable_is_no_coefficients_not_an_error() {
        let mut s = slots(MemFlash::new(4));
        s.store(&blob_of(&coeffs(1))).unwrap();
        s.store(&blob_of(&coeffs(2))).unwrap();
        let mut f = s.into_inner();
        f.ecc.extend([PAGE, 2 * PAGE + 16]);
        let (scan, got) = slots(f.rebooted()).load_scanned().unwrap();
        assert_eq!((scan.unreadable, got), (0b11, None));
    }

    #[test]
    fn bad_geometry_is_refused() {
        assert!(Slots::new(MemFlash::new(4), 100, PAGE as u32).is_err());
        assert!(Slots::new(MemFlash::new(4), 3 * PAGE as u32, PAGE as u32).is_err());
        assert!(Slots::new(MemFlash::new(4), 0, 512).is_err());
    }

    /// Cuts the power after every possible number of byte steps of an update from `old` to
    /// `new`, on a flash that already went through `history`, and checks that the old
    /// coefficients survive each cut, and the new ones load once the update completed.
    fn power_cut_everywhere(history: &[Coefficients], new: &Coefficients) {
        let mut s = slots(MemFlash::new(4));
        for c in history {
            s.store(&blob_of(c)).unwrap();
        }
        let before = s.into_inner().rebooted();
        let old = loaded(&before).map(|(_, c)| c);
        let new_blob = blob_of(new);

        // Count the steps of an uninterrupted update.
        let mut full = slots(before.rebooted());
        full.store(&new_blob).unwrap();
        let full = full.into_inner();
        let total = full.steps;
        assert!(
            total > PAGE,
            "an update erases a page and writes the blob: {total}"
        );
        assert_eq!(loaded(&full).map(|(_, c)| c).as_ref(), Some(new));

        for k in 0..=total {
            let mut f = before.rebooted();
            f.budget = Some(k);
            let mut s = slots(f);
            let r = s.store(&new_blob);
            // `store` needs the flash only up to `total` steps; anything less is a cut.
            let cut = k < total;
            assert_eq!(r.is_err(), cut, "k = {k}: {r:?}");
            // Reboot with the memory as the cut left it.
            let mut f = s.into_inner();
            f.budget = None;
            let got = loaded(&f).map(|(_, c)| c);
            if got.as_ref() == Some(new) {
                // Only acceptable if the new slot is byte-for-byte complete (the last
                // header bytes may already equal their erased value 0xFF).
                assert_eq!(
                    f.mem, full.mem,
                    "k = {k}: new coefficients from a torn slot"
                );
            } else {
                assert_eq!(got, old, "k = {k}: old coefficients lost");
            }
        }
    }

    #[test]
    fn power_cut_during_first_update_leaves_no_coefficients() {
        power_cut_everywhere(&[], &coeffs(1));
    }

    #[test]
    fn power_cut_during_second_update_keeps_the_first() {
        power_cut_everywhere(&[coeffs(0)], &coeffs(1));
    }

    #[test]
    fn power_cut_during_later_updates_keeps_the_previous() {
        // Both slots in use: the update overwrites the older one.
        power_cut_everywhere(&[coeffs(0), coeffs(1)], &coeffs(2));
        power_cut_everywhere(&[coeffs(0), coeffs(1), coeffs(2)], &coeffs(0));
    }
}
