//! Input files: one policy for every command that reads a file.
//!
//! * **Regular files only.** A device, pipe or socket (`/dev/zero`, a FIFO with no writer) is
//!   refused before any byte is read: it can be endless or block forever.
//! * **Bounded by what the file can hold.** Each kind of input has a size cap of its own
//!   (a coefficient blob is at most a few KiB, a MODEL.toml a few MiB); a larger file is refused
//!   from its length, and the read stops one byte past the cap even if the length lied.
use anyhow::{anyhow, bail, Result};
use std::io::Read;
use std::path::Path;

/// Largest coefficient blob file read [bytes]: blobs are at most 1 KiB.
pub const MAX_BLOB_FILE: u64 = 64 * 1024;
/// Largest MODEL.toml read [bytes]: a model with every effect and a SINDYc table is a few KiB.
pub const MAX_MODEL_FILE: u64 = 16 * 1024 * 1024;
/// Largest log read [bytes]: 10^8 samples of a six-column CSV.
pub const MAX_LOG_FILE: u64 = 16 * 1024 * 1024 * 1024;

/// Read the regular file `path` whole, refusing anything else and anything above `cap` bytes
/// (`what` names the kind of file in the message).
pub fn read(path: &Path, cap: u64, what: &str) -> Result<Vec<u8>> {
    let p = path.display();
    let meta = std::fs::metadata(path).map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    if meta.is_dir() {
        bail!("{p}: is a directory; give the {what} file");
    }
    if !meta.is_file() {
        bail!("{p}: is not a regular file (a device or pipe); give the {what} file");
    }
    if meta.len() > cap {
        bail!(
            "{p}: {} bytes is too large for a {what} (at most {cap} bytes)",
            meta.len()
        );
    }
    let file = std::fs::File::open(path).map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(cap + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    if bytes.len() as u64 > cap {
        bail!("{p}: too large for a {what} (at most {cap} bytes)");
    }
    Ok(bytes)
}

/// [`read`] as UTF-8 text.
pub fn read_text(path: &Path, cap: u64, what: &str) -> Result<String> {
    let bytes = read(path, cap, what)?;
    String::from_utf8(bytes).map_err(|e| {
        anyhow!(
            "{}: byte {}: not UTF-8 text",
            path.display(),
            e.utf8_error().valid_up_to()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_directories_and_oversized_files_are_refused() {
        let e = read(Path::new("/dev/zero"), MAX_BLOB_FILE, "blob").unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let e = read(Path::new("/"), MAX_BLOB_FILE, "blob").unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let big = dir.path().join("big.bin");
        std::fs::write(&big, vec![0u8; 2048]).unwrap();
        let e = read(&big, 1024, "blob").unwrap_err();
        assert!(e.to_string().contains("too large"), "{e}");
        assert_eq!(read(&big, 4096, "blob").unwrap().len(), 2048);
    }
}
