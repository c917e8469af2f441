//! Fixed-size arrays through serde in a loop, for `#[serde(with = "crate::serde_array")]`.
//!
//! The encoding is serde's own for `[T; N]` (a tuple of `N` elements; in postcard the
//! elements back to back, no length), so blobs do not change. serde's impl unrolls its
//! per-element read `N` times, each with its error path; on the board that made a table
//! effect's 16 values alone several hundred bytes of flash. Here one loop reads them all.
use core::fmt;
use core::marker::PhantomData;

use serde::de::{Deserializer, Error, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// Writes `a` as a tuple of `N` elements.
pub fn serialize<S: Serializer, T: Serialize, const N: usize>(
    a: &[T; N],
    s: S,
) -> Result<S::Ok, S::Error> {
    let mut t = s.serialize_tuple(N)?;
    for x in a {
        t.serialize_element(x)?;
    }
    t.end()
}

/// Reads a tuple of `N` elements.
pub fn deserialize<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de> + Copy + Default,
{
    struct ArrayVisitor<T, const N: usize>(PhantomData<T>);

    impl<'de, T: Deserialize<'de> + Copy + Default, const N: usize> Visitor<'de>
        for ArrayVisitor<T, N>
    {
        type Value = [T; N];

        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("a fixed-size array")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[T; N], A::Error> {
            let mut a = [T::default(); N];
            for (i, x) in a.iter_mut().enumerate() {
                *x = seq
                    .next_element()?
                    .ok_or_else(|| A::Error::invalid_length(i, &self))?;
            }
            Ok(a)
        }
    }

    d.deserialize_tuple(N, ArrayVisitor::<T, N>(PhantomData))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Looped(#[serde(with = "super")] [f32; 5], u8);

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Unrolled([f32; 5], u8);

    #[test]
    fn the_loop_reads_and_writes_serdes_own_encoding() {
        let v = [1.5, -2.0, 0.0, 3.25, f32::MAX];
        let (mut buf, mut buf2) = ([0u8; 64], [0u8; 64]);
        let ours = postcard::to_slice(&Looped(v, 7), &mut buf).unwrap();
        let theirs = postcard::to_slice(&Unrolled(v, 7), &mut buf2).unwrap();
        assert_eq!(ours, theirs);
        assert_eq!(
            postcard::from_bytes::<Looped>(theirs).unwrap(),
            Looped(v, 7)
        );
        // Too short: an error, not a panic.
        assert!(postcard::from_bytes::<Looped>(&theirs[..10]).is_err());
    }
}
