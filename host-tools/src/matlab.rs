//! MATLAB MAT-files (level 5: the `-v6` and `-v7` formats) as motor logs.
//!
//! The arrays are decoded by the `matfile` crate. In front of it this module checks the
//! container: the 128-byte header (a `-v7.3` file is HDF5 and is refused with the command
//! that re-saves it), every element's tag against the bytes that are there, and each
//! `miCOMPRESSED` element inflated under a budget ([`MAX_INFLATED`]), so that a truncated,
//! corrupt or hostile file is one error naming the file and the byte, never a panic or an
//! allocation sized by a number in the file. Each numeric array is decoded on its own, so one
//! the decoder refuses is named in [`MatData::undecoded`] and the others stay readable.
//! Numeric vectors become columns, scalars metadata (see [`crate::log::MotorLog::parse_mat`]).
use anyhow::{anyhow, bail, Result};
use std::io::Read;
use std::path::Path;

/// Length of the text, subsystem offset, version and endian header of a level-5 MAT-file.
const HEADER: usize = 128;
/// Element types of the level-5 format.
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
/// Array classes: double is the first numeric one, uint64 the last.
const MX_DOUBLE: u32 = 6;
const MX_UINT64: u32 = 15;
/// Most bytes the compressed arrays of one file may inflate to, all together (1 GiB).
pub const MAX_INFLATED: usize = 1 << 30;
/// Largest MAT-file read (bytes), so that every size in it fits the format's 32-bit tags.
pub const MAX_FILE: usize = 1 << 30;

/// The numeric content of a MAT-file: real arrays as `f64`, in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MatData {
    /// 1×1 arrays.
    pub scalars: Vec<(String, f64)>,
    /// N×1 and 1×N arrays (N > 1).
    pub vectors: Vec<(String, Vec<f64>)>,
    /// Numeric arrays the decoder could not read, by name (left out of the above).
    pub undecoded: Vec<String>,
}

/// True when `bytes` start like a MAT-file's descriptive text.
pub fn is_mat_file(bytes: &[u8]) -> bool {
    bytes.starts_with(b"MATLAB")
}

/// Read the real numeric scalars and vectors of a MAT-file (other arrays, complex ones,
/// matrices, cells, structures and strings, are left out). `path` is for messages.
pub fn read(bytes: &[u8], path: &Path) -> Result<MatData> {
    let p = crate::log::echo_path(path);
    if bytes.len() > MAX_FILE {
        bail!(
            "{p}: {} bytes; MAT-files over {MAX_FILE} bytes are not read",
            bytes.len()
        );
    }
    if bytes.len() < HEADER || !is_mat_file(bytes) {
        bail!("{p}: not a MATLAB MAT-file (no 128-byte 'MATLAB' header)");
    }
    let little = match &bytes[126..128] {
        b"IM" => true,
        b"MI" => false,
        _ => bail!("{p}: byte 126: not a MATLAB MAT-file (no endian mark 'IM' or 'MI')"),
    };
    let word = Words { little };
    match word.u16(&bytes[124..126]) {
        0x0100 => {}
        0x0200 => bail!(
            "{p}: a MATLAB v7.3 MAT-file (HDF5), which is not read; save it in MATLAB as \
             v7 with save('FILE.mat', '-v7') or as a CSV"
        ),
        v => bail!("{p}: byte 124: unknown MAT-file version 0x{v:04x}"),
    }

    // Every numeric array uncompressed and checked: what `matfile` then decodes, one by one.
    let mut arrays: Vec<Vec<u8>> = Vec::new();
    let mut inflated_total = 0usize;
    let mut at = HEADER;
    while bytes.len() - at >= 8 {
        let (kind, size) = (word.u32(&bytes[at..]), word.u32(&bytes[at + 4..]) as usize);
        let start = at + 8;
        if size > bytes.len() - start {
            bail!(
                "{p}: byte {at}: an element of {size} bytes, but only {} remain (is the file \
                 truncated?)",
                bytes.len() - start
            );
        }
        let data = &bytes[start..start + size];
        match kind {
            MI_COMPRESSED => {
                let budget = MAX_INFLATED - inflated_total;
                let mut out = Vec::new();
                flate2::read::ZlibDecoder::new(data)
                    .take(budget as u64 + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| anyhow!("{p}: byte {at}: a compressed array is corrupt ({e})"))?;
                if out.len() > budget {
                    bail!(
                        "{p}: byte {at}: the compressed arrays inflate beyond {MAX_INFLATED} bytes"
                    );
                }
                inflated_total += out.len();
                if out.len() < 8 || word.u32(&out) != MI_MATRIX {
                    // Not an array (nothing this reader uses).
                } else {
                    let inner = word.u32(&out[4..]) as usize;
                    if inner > out.len() - 8 {
                        bail!("{p}: byte {at}: a compressed array is truncated");
                    }
                    push_matrix(&mut arrays, &out[..8 + inner], word)
                        .map_err(|e| anyhow!("{p}: byte {at}: {e}"))?;
                }
                at = start + size;
            }
            MI_MATRIX => {
                push_matrix(&mut arrays, &bytes[at..start + size], word)
                    .map_err(|e| anyhow!("{p}: byte {at}: {e}"))?;
                at = (start + size.next_multiple_of(8)).min(bytes.len());
            }
            _ => at = (start + size.next_multiple_of(8)).min(bytes.len()),
        }
    }
    let mut out = MatData::default();
    for element in arrays {
        // Alone behind the header, so that one array the decoder refuses (it reads int32
        // storage as uint32, for one) leaves the others readable.
        let mut one = bytes[..HEADER].to_vec();
        one.extend_from_slice(&element);
        let Ok(file) = matfile::MatFile::parse(one.as_slice()) else {
            out.undecoded.push(array_name(&element, word));
            continue;
        };
        let Some(a) = file.arrays().first() else {
            continue;
        };
        let Some(values) = real_values(a.data()) else {
            continue;
        };
        let size = a.size();
        let name = a.name().to_string();
        if values.len() == 1 {
            out.scalars.push((name, values[0]));
        } else if size.len() == 2 && size.contains(&1) && values.len() > 1 {
            out.vectors.push((name, values));
        }
    }
    Ok(out)
}

/// The sub-elements of an `miMATRIX` payload: `(kind, data)` each, after checking that each
/// fits inside the payload (a small element holds at most 4 bytes).
fn sub_elements(payload: &[u8], word: Words) -> Result<Vec<(u32, &[u8])>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while payload.len() - at >= 8 {
        let first = word.u32(&payload[at..]);
        let small = (first >> 16) as usize;
        if small != 0 {
            if small > 4 {
                bail!("an array's sub-element claims {small} bytes in a 4-byte slot");
            }
            out.push((first & 0xffff, &payload[at + 4..at + 4 + small]));
            at += 8;
        } else {
            let size = word.u32(&payload[at + 4..]) as usize;
            if size > payload.len() - at - 8 {
                bail!("an array's sub-element of {size} bytes runs past the array's end");
            }
            out.push((first, &payload[at + 8..at + 8 + size]));
            at = (at + 8 + size.next_multiple_of(8)).min(payload.len());
        }
    }
    Ok(out)
}

/// The name of an `miMATRIX` element (its third sub-element), for messages.
fn array_name(element: &[u8], word: Words) -> String {
    sub_elements(&element[8..], word)
        .ok()
        .and_then(|s| {
            s.get(2)
                .map(|(_, d)| String::from_utf8_lossy(d).into_owned())
        })
        .unwrap_or_else(|| "?".to_string())
}

/// Append an `miMATRIX` element (tag included) of a real or integer class to `arrays`, padded
/// to 8 bytes, after checking that its sub-elements fit inside it and that its dimensions
/// multiply without overflow (an error otherwise). Cells, structures, strings and sparse
/// arrays are left out.
fn push_matrix(arrays: &mut Vec<Vec<u8>>, element: &[u8], word: Words) -> Result<()> {
    let subs = sub_elements(&element[8..], word)?;
    let Some((MI_UINT32, flags)) = subs.first().copied() else {
        bail!("an array without its flags");
    };
    if flags.len() < 4 || !(MX_DOUBLE..=MX_UINT64).contains(&(word.u32(flags) & 0xff)) {
        return Ok(());
    }
    // The dimensions: int32, multiplying to at most i32::MAX.
    let Some((MI_INT32, dims)) = subs.get(1).copied() else {
        bail!("an array's dimensions are not int32");
    };
    if dims.len() < 8 || dims.len() % 4 != 0 {
        bail!("an array's dimensions are not int32 pairs");
    }
    let mut n: i32 = 1;
    for d in dims.chunks_exact(4) {
        n = (word.u32(d) as i32)
            .checked_mul(n)
            .filter(|n| *n >= 0)
            .ok_or_else(|| anyhow!("an array's dimensions are out of range"))?;
    }
    let mut e = element.to_vec();
    e.resize(e.len().next_multiple_of(8), 0);
    arrays.push(e);
    Ok(())
}

/// The real part of a numeric array as `f64` (`None` for a complex array).
fn real_values(data: &matfile::NumericData) -> Option<Vec<f64>> {
    use matfile::NumericData as D;
    fn all<T: Copy + Into<f64>>(v: &[T]) -> Vec<f64> {
        v.iter().map(|x| (*x).into()).collect()
    }
    Some(match data {
        D::Int8 { real, imag: None } => all(real),
        D::UInt8 { real, imag: None } => all(real),
        D::Int16 { real, imag: None } => all(real),
        D::UInt16 { real, imag: None } => all(real),
        D::Int32 { real, imag: None } => all(real),
        D::UInt32 { real, imag: None } => all(real),
        D::Int64 { real, imag: None } => real.iter().map(|x| *x as f64).collect(),
        D::UInt64 { real, imag: None } => real.iter().map(|x| *x as f64).collect(),
        D::Single { real, imag: None } => all(real),
        D::Double { real, imag: None } => real.clone(),
        _ => return None,
    })
}

/// Fixed-size integers in the file's byte order.
#[derive(Debug, Clone, Copy)]
struct Words {
    little: bool,
}

impl Words {
    fn u16(self, b: &[u8]) -> u16 {
        let b = [b[0], b[1]];
        if self.little {
            u16::from_le_bytes(b)
        } else {
            u16::from_be_bytes(b)
        }
    }

    fn u32(self, b: &[u8]) -> u32 {
        let b = [b[0], b[1], b[2], b[3]];
        if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// One tagged element, padded to 8 bytes (little-endian).
    fn element(kind: u32, data: &[u8]) -> Vec<u8> {
        let mut e = kind.to_le_bytes().to_vec();
        e.extend_from_slice(&(data.len() as u32).to_le_bytes());
        e.extend_from_slice(data);
        e.resize(e.len().next_multiple_of(8), 0);
        e
    }

    /// A level-5 MAT-file of real double arrays `(name, rows, cols, values)`, each compressed
    /// as `-v7` writes it or plain as `-v6` does.
    pub(crate) fn mat_file(arrays: &[(&str, usize, usize, Vec<f64>)], compress: bool) -> Vec<u8> {
        use std::io::Write;
        let mut out = format!("{:<116}", "MATLAB 5.0 MAT-file, written by a test").into_bytes();
        out.extend_from_slice(&[0; 8]);
        out.extend_from_slice(&0x0100u16.to_le_bytes());
        out.extend_from_slice(b"IM");
        for (name, rows, cols, values) in arrays {
            let mut m = element(6, &[6, 0, 0, 0, 0, 0, 0, 0]); // flags: mxDOUBLE_CLASS
            let dims: Vec<u8> = [*rows as i32, *cols as i32]
                .iter()
                .flat_map(|d| d.to_le_bytes())
                .collect();
            m.extend(element(MI_INT32, &dims));
            m.extend(element(1, name.as_bytes()));
            let re: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            m.extend(element(9, &re));
            let matrix = element(MI_MATRIX, &m);
            if compress {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                z.write_all(&matrix).unwrap();
                let z = z.finish().unwrap();
                let mut e = MI_COMPRESSED.to_le_bytes().to_vec();
                e.extend_from_slice(&(z.len() as u32).to_le_bytes());
                e.extend_from_slice(&z);
                out.extend(e);
            } else {
                out.extend(matrix);
            }
        }
        out
    }

    fn sample(compress: bool) -> Vec<u8> {
        mat_file(
            &[
                ("gain", 1, 1, vec![2.5]),
                ("t", 4, 1, vec![0.0, 0.1, 0.2, 0.3]),
                ("grid", 2, 2, vec![1.0, 2.0, 3.0, 4.0]),
                ("row", 1, 3, vec![-1.0, 0.5, 7.0]),
            ],
            compress,
        )
    }

    #[test]
    fn plain_and_compressed_files_read_the_same_scalars_and_vectors() {
        for compress in [false, true] {
            let m = read(&sample(compress), Path::new("a.mat")).unwrap();
            assert_eq!(
                m.scalars,
                vec![("gain".to_string(), 2.5)],
                "compress {compress}"
            );
            assert_eq!(
                m.vectors,
                vec![
                    ("t".to_string(), vec![0.0, 0.1, 0.2, 0.3]),
                    ("row".to_string(), vec![-1.0, 0.5, 7.0]),
                ],
                "a 2x2 matrix is not a column; compress {compress}"
            );
        }
    }

    #[test]
    fn an_array_the_decoder_refuses_leaves_the_others_readable() {
        // An int32 vector stored as int32, which the decoder does not take, then a double one.
        let mut b = mat_file(&[("t", 2, 1, vec![0.0, 1.0])], false);
        let mut m = element(6, &[12, 0, 0, 0, 0, 0, 0, 0]); // flags: mxINT32_CLASS
        m.extend(element(MI_INT32, &[2, 0, 0, 0, 1, 0, 0, 0]));
        m.extend(element(1, b"count"));
        m.extend(element(MI_INT32, &[0xff, 0xff, 0xff, 0xff, 7, 0, 0, 0]));
        b.splice(HEADER..HEADER, element(MI_MATRIX, &m));
        let r = read(&b, Path::new("a.mat")).unwrap();
        assert_eq!(r.vectors, vec![("t".to_string(), vec![0.0, 1.0])]);
        assert_eq!(r.undecoded, vec!["count".to_string()]);
    }

    #[test]
    fn a_v73_file_is_refused_with_the_command_that_resaves_it() {
        let mut b = sample(true);
        b[124..126].copy_from_slice(&0x0200u16.to_le_bytes());
        let e = read(&b, Path::new("a.mat")).unwrap_err().to_string();
        assert!(e.starts_with("a.mat: a MATLAB v7.3 MAT-file (HDF5)"), "{e}");
        assert!(e.contains("'-v7'"), "{e}");
        let e = read(b"MATLAB 5.0 but short", Path::new("a.mat")).unwrap_err();
        assert!(
            e.to_string().starts_with("a.mat: not a MATLAB MAT-file"),
            "{e}"
        );
    }

    #[test]
    fn truncated_and_corrupt_files_are_errors_naming_the_byte() {
        let b = sample(false);
        let e = read(&b[..b.len() - 20], Path::new("a.mat"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("a.mat: byte ") && e.contains("truncated"),
            "{e}"
        );
        let mut b = sample(true);
        let n = b.len();
        for x in &mut b[n - 30..n - 10] {
            *x ^= 0x5a;
        }
        let e = read(&b, Path::new("a.mat")).unwrap_err().to_string();
        assert!(e.starts_with("a.mat: byte "), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }

    #[test]
    fn dimensions_that_overflow_are_an_error() {
        let mut b = mat_file(&[("t", 2, 1, vec![0.0, 1.0])], false);
        // Dimensions sit after the matrix tag (8), flags (16) and the dims tag (8).
        let at = HEADER + 8 + 16 + 8;
        b[at..at + 8].copy_from_slice(&[0, 0, 1, 0, 0, 0, 1, 0]); // 65536 x 65536
        let e = read(&b, Path::new("a.mat")).unwrap_err().to_string();
        assert!(e.contains("dimensions are out of range"), "{e}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]

        /// Any bytes after a valid header, and a valid file with bytes overwritten: a result
        /// or a one-line error naming the file, never a panic.
        #[test]
        fn damaged_files_never_panic(
            tail in proptest::collection::vec(proptest::num::u8::ANY, 0..400),
            edits in proptest::collection::vec((0usize..1000, proptest::num::u8::ANY), 1..8),
            cut in 0usize..1000,
            compress in proptest::bool::ANY,
        ) {
            let mut b = sample(compress)[..HEADER].to_vec();
            b.extend_from_slice(&tail);
            let mut damaged = sample(compress);
            for (at, v) in edits {
                let n = damaged.len();
                damaged[at % n] = v;
            }
            let cut = cut % (damaged.len() + 1);
            for bytes in [&b[..], &damaged[..], &damaged[..cut]] {
                if let Err(e) = read(bytes, Path::new("a.mat")) {
                    let e = e.to_string();
                    proptest::prop_assert!(e.starts_with("a.mat") && !e.contains('\n'), "{}", e);
                }
            }
        }
    }
}
