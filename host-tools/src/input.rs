//! Input files: one policy for every command that reads a file.
//!
//! * **Regular files only.** A device, pipe or socket (`/dev/zero`, a FIFO with no writer) is
//!   refused before any byte is read: it can be endless or block forever.
//! * **Bounded by what the file can hold.** Each kind of input has a size cap of its own
//!   (a coefficient blob is at most a few KiB, a MODEL.toml a few MiB); a larger file is refused
//!   from its length, and the read stops one byte past the cap even if the length lied.
//! * **Text lines bounded.** A log's line is at most [`MAX_LINE`] bytes: a longer one is
//!   refused as soon as the read passes the cap, so one giant line (a file of NUL bytes, a
//!   binary file given as a log) costs [`MAX_LINE`] bytes of memory, not its size.
//! * **A file once.** [`check_distinct`] refuses the same file given twice in a list.
use anyhow::{anyhow, bail, Result};
use std::io::Read;
use std::path::Path;

/// Largest coefficient blob file read [bytes]: blobs are at most 1 KiB.
pub const MAX_BLOB_FILE: u64 = 64 * 1024;
/// Largest MODEL.toml read [bytes]: 256 KiB. A LuGre model with a 16-node table, eight more
/// effects and its 40 parameters is 10 KB, a SINDYc model with full libraries about 25 KB;
/// the rest is room for long provenance lists. The TOML parser takes about 200 bytes of
/// memory per byte of a hostile file (a list of millions of empty tables), so the cap keeps a
/// model's parse under about 50 MB.
pub const MAX_MODEL_FILE: u64 = 256 * 1024;
/// Largest log read [bytes]: 10^8 samples of a six-column CSV.
pub const MAX_LOG_FILE: u64 = 16 * 1024 * 1024 * 1024;
/// Longest line of a text log [bytes]: 64 KiB. A row of 100 columns of 25-character numbers
/// is 2.6 KiB, and a metadata line is a key and a number; a longer line is not a log's.
pub const MAX_LINE: usize = 64 * 1024;

/// Refuse a file given twice among `paths` (also through another path, a symbolic link or a
/// hard link): `what` (`DATA.csv`) names the list in the message.
pub fn check_distinct(paths: &[&Path], what: &str) -> Result<()> {
    for (k, a) in paths.iter().enumerate() {
        if let Some(b) = paths[..k].iter().find(|b| crate::atomic::same_file(a, b)) {
            let also = if a == b {
                String::new()
            } else {
                format!(" (the same file as {})", crate::log::echo_path(b))
            };
            bail!(
                "{}{also}: given twice as {what}; give each file once",
                crate::log::echo_path(a)
            );
        }
    }
    Ok(())
}

/// Read the regular file `path` whole, refusing anything else and anything above `cap` bytes
/// (`what` names the kind of file in the message).
pub fn read(path: &Path, cap: u64, what: &str) -> Result<Vec<u8>> {
    let p = crate::log::echo_path(path);
    let (file, len) = open(path, cap, what)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(cap + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    if bytes.len() as u64 > cap {
        bail!("{p}: too large for a {what} (at most {cap} bytes)");
    }
    Ok(bytes)
}

/// Open the regular file `path` for reading, refusing anything else and anything above
/// `cap` bytes; returns the file and its length.
fn open(path: &Path, cap: u64, what: &str) -> Result<(std::fs::File, u64)> {
    let p = crate::log::echo_path(path);
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
    Ok((file, meta.len()))
}

/// What is wrong with a text file whose lines end in a lone carriage return.
pub const LONE_CR: &str =
    "lines end in a lone CR (classic Mac OS line ends); save the file with LF or CRLF line ends";

/// Bytes [`read_lines`] reads before it asks whether the file is binary.
const SNIFF: usize = 128;

/// [`read`] for a file that is text unless `binary` (given its first bytes, up to 128) says
/// otherwise: a text file's lines must be at most `max_line` bytes, checked as the bytes come
/// in, so that a file without line breaks costs `max_line` bytes, not its size. The message
/// names the file and the line.
pub fn read_lines(
    path: &Path,
    cap: u64,
    max_line: usize,
    what: &str,
    binary: impl Fn(&[u8]) -> bool,
) -> Result<Vec<u8>> {
    let p = crate::log::echo_path(path);
    let (mut file, len) = open(path, cap, what)?;
    let mut bytes = Vec::with_capacity(len as usize);
    let mut chunk = vec![0u8; 64 * 1024];
    let mut text: Option<bool> = None;
    let (mut line, mut line_len) = (1usize, 0usize);
    loop {
        let n = match file.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => bail!("{p}: cannot read: {e}"),
        };
        let start = bytes.len();
        bytes.extend_from_slice(&chunk[..n]);
        if bytes.len() as u64 > cap {
            bail!("{p}: too large for a {what} (at most {cap} bytes)");
        }
        if text.is_none() && bytes.len() >= SNIFF {
            text = Some(!binary(&bytes));
        }
        // Lines of the bytes read so far (re-read from the start once it is known to be text).
        let from = match text {
            Some(false) => continue,
            Some(true) if start >= SNIFF => start,
            _ => 0,
        };
        if from == 0 {
            (line, line_len) = (1, 0);
        }
        let mut k = from;
        while k < bytes.len() {
            // The current line runs on for `run` bytes of those read (to its end, or to the
            // last byte read).
            let end_of_line = memchr::memchr(b'\n', &bytes[k..]);
            let run = end_of_line.unwrap_or(bytes.len() - k);
            if line_len + run > max_line {
                // The line's bytes up to the first one past the cap.
                let end = k + (max_line - line_len) + 1;
                if bytes[end - (max_line + 1)..end].contains(&b'\r') {
                    bail!("{p}:{line}: {LONE_CR}");
                }
                bail!(
                    "{p}:{line}: line longer than {max_line} bytes; a {what}'s lines are \
                     a few KiB at most (is this a {what}?)"
                );
            }
            match end_of_line {
                Some(_) => {
                    line += 1;
                    line_len = 0;
                    k += run + 1;
                }
                None => {
                    line_len += run;
                    k = bytes.len();
                }
            }
        }
    }
    Ok(bytes)
}

/// [`read`] as UTF-8 text.
pub fn read_text(path: &Path, cap: u64, what: &str) -> Result<String> {
    let bytes = read(path, cap, what)?;
    String::from_utf8(bytes).map_err(|e| {
        anyhow!(
            "{}: byte {}: not UTF-8 text",
            crate::log::echo_path(path),
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

    #[test]
    fn an_overlong_line_is_named_by_its_number_across_reads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.csv");
        let text = |t: &str| -> Result<Vec<u8>> {
            std::fs::write(&path, t).unwrap();
            read_lines(&path, 1 << 30, 10, "log", |_| false)
        };
        // A line of exactly the cap is read; one byte more is not.
        assert!(text("12345\n1234567890\n12345\n").is_ok());
        let e = text("12345\n1234567890\n12345678901\nab\n").unwrap_err();
        assert!(e.to_string().ends_with(":3: line longer than 10 bytes; a log's lines are a few KiB at most (is this a log?)"), "{e}");
        let e = text("ab\rcd\ref\rgh\rij\r").unwrap_err();
        assert!(e.to_string().ends_with(&format!(":1: {LONE_CR}")), "{e}");
        // Lines that span the reads of 64 KiB.
        let long = |n: usize| "7".repeat(n);
        let t = format!("a\nb\nc\n{}\n{}\nd\n", long(65_000), long(70_000));
        std::fs::write(&path, &t).unwrap();
        let e = read_lines(&path, 1 << 30, MAX_LINE, "log", |_| false).unwrap_err();
        assert!(e.to_string().contains(":5: line longer than 65536"), "{e}");
        let t = format!("a\n{}\n{}\nd", long(65_536), long(65_536));
        std::fs::write(&path, &t).unwrap();
        assert_eq!(
            read_lines(&path, 1 << 30, MAX_LINE, "log", |_| false).unwrap(),
            t.as_bytes()
        );
    }
}
