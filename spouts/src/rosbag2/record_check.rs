//! Bounds checks on an MCAP record's length-prefixed fields, made before
//! the `mcap` crate parses the record.
//!
//! The crate (0.26) allocates what a string's length prefix claims before
//! it reads the string: a record of a few dozen bytes can claim up to
//! 4 GiB, allocated and zeroed (found by `fuzz/`'s `mcap_bag` target: an
//! 18 KB bag that claimed 1.8 GB). Every prefix is checked
//! here against the bytes the record actually holds, from the field
//! layouts of the MCAP specification (<https://mcap.dev/spec>).

/// One field of a record, in order.
#[derive(Clone, Copy)]
enum Field {
    /// A fixed-size integer of this many bytes.
    Fixed(usize),
    /// A u32 length, then that many bytes (strings, schema data).
    Prefixed32,
    /// A u64 length, then that many bytes (attachment data).
    Prefixed64,
    /// A u32 byte length, then string→string pairs (a metadata map).
    StringMap,
    /// A u32 byte length, then fixed-size entries (indexes, counts).
    FixedArray,
    /// Whatever follows (message data, chunk records).
    Rest,
}

use Field::{Fixed, FixedArray, Prefixed32, Prefixed64, Rest, StringMap};

/// The fields of the record with `opcode`, or `None` for an opcode the
/// specification does not define (skipped by readers, so not checked).
fn layout(opcode: u8) -> Option<&'static [Field]> {
    Some(match opcode {
        0x01 => &[Prefixed32, Prefixed32],                                // Header
        0x02 => &[Fixed(8), Fixed(8), Fixed(4)],                          // Footer
        0x03 => &[Fixed(2), Prefixed32, Prefixed32, Prefixed32],          // Schema
        0x04 => &[Fixed(2), Fixed(2), Prefixed32, Prefixed32, StringMap], // Channel
        0x05 => &[Fixed(2), Fixed(4), Fixed(8), Fixed(8), Rest],          // Message
        0x06 => &[Fixed(8), Fixed(8), Fixed(8), Fixed(4), Prefixed32, Prefixed64], // Chunk
        0x07 => &[Fixed(2), FixedArray],                                  // MessageIndex
        0x08 => {
            &[Fixed(8), Fixed(8), Fixed(8), Fixed(8), FixedArray, Fixed(8), Prefixed32, Fixed(8), Fixed(8)]
        } // ChunkIndex
        0x09 => &[Fixed(8), Fixed(8), Prefixed32, Prefixed32, Prefixed64, Fixed(4)], // Attachment
        0x0A => &[Fixed(8), Fixed(8), Fixed(8), Fixed(8), Fixed(8), Prefixed32, Prefixed32], // AttachmentIndex
        0x0B => &[Fixed(8), Fixed(2), Fixed(4), Fixed(4), Fixed(4), Fixed(4), Fixed(8), Fixed(8), FixedArray], // Statistics
        0x0C => &[Prefixed32, StringMap],          // Metadata
        0x0D => &[Fixed(8), Fixed(8), Prefixed32], // MetadataIndex
        0x0E => &[Fixed(1), Fixed(8), Fixed(8)],   // SummaryOffset
        0x0F => &[Fixed(4)],                       // DataEnd
        _ => return None,
    })
}

/// Checks that every length prefix in the record `opcode`/`body` fits in
/// the bytes that follow it; the error says which field does not.
pub(crate) fn check(opcode: u8, body: &[u8]) -> Result<(), String> {
    let Some(fields) = layout(opcode) else { return Ok(()) };
    let mut rest = body;
    for (i, field) in fields.iter().enumerate() {
        let fail = |what: String| format!("record 0x{opcode:02x}, field {}: {what}", i + 1);
        rest = match *field {
            Fixed(n) => rest.get(n..).ok_or_else(|| fail("truncated".into()))?,
            Prefixed32 | FixedArray => prefixed(rest, 4).map_err(fail)?.1,
            Prefixed64 => prefixed(rest, 8).map_err(fail)?.1,
            StringMap => {
                let (mut map, after) = prefixed(rest, 4).map_err(fail)?;
                while !map.is_empty() {
                    let (_key, value) = prefixed(map, 4).map_err(|e| fail(format!("a key: {e}")))?;
                    map = prefixed(value, 4).map_err(|e| fail(format!("a value: {e}")))?.1;
                }
                after
            }
            Rest => &[],
        };
    }
    Ok(())
}

/// Splits `bytes` after a little-endian length of `width` bytes and the
/// field it prefixes: (the field, what follows it).
fn prefixed(bytes: &[u8], width: usize) -> Result<(&[u8], &[u8]), String> {
    let (len, after) = bytes.split_at_checked(width).ok_or("truncated length")?;
    let mut le = [0u8; 8];
    le[..width].copy_from_slice(len);
    let len = u64::from_le_bytes(le);
    usize::try_from(len)
        .ok()
        .and_then(|n| after.split_at_checked(n))
        .ok_or_else(|| format!("claims {len} bytes, {} remain in the record", after.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &str) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s.as_bytes());
        v
    }

    #[test]
    fn well_formed_records_pass() {
        let header = [string("ros2"), string("squall")].concat();
        assert_eq!(check(0x01, &header), Ok(()));
        let map = [string("k"), string("v")].concat();
        let channel = [
            vec![1, 0, 2, 0],
            string("/scan"),
            string("cdr"),
            (map.len() as u32).to_le_bytes().to_vec(),
            map,
        ]
        .concat();
        assert_eq!(check(0x04, &channel), Ok(()));
        assert_eq!(check(0x05, &[0; 22]), Ok(()), "a message with no data");
        assert_eq!(check(0x80, &[1, 2, 3]), Ok(()), "opcodes outside the spec are not checked");
    }

    #[test]
    fn a_prefix_past_the_record_is_refused() {
        // An attachment index whose name claims 4 GiB: the kind of record
        // the fuzzer found the mcap crate allocating for.
        let mut index = vec![0; 40];
        index.extend_from_slice(&u32::MAX.to_le_bytes());
        index.extend_from_slice(b"name");
        let error = check(0x0A, &index).unwrap_err();
        assert!(error.contains("field 6") && error.contains("claims 4294967295 bytes, 4 remain"), "{error}");
        // A metadata map whose value runs past the map.
        let map = [string("k"), 99u32.to_le_bytes().to_vec()].concat();
        let metadata = [string("m"), (map.len() as u32).to_le_bytes().to_vec(), map].concat();
        assert!(check(0x0C, &metadata).unwrap_err().contains("a value"));
        assert!(check(0x02, &[0; 19]).unwrap_err().contains("truncated"));
    }
}
