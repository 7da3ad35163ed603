//! Stable hashing: the same value hashes the same in every process, run and
//! build (unlike `std`'s randomly keyed hasher), so a hash can route a key
//! to a task in cluster mode, key a random stream or name a cache file.
//!
//! Two classic pieces, each written once here and used across squall:
//! FNV-1a 64 over bytes (Fowler, Noll, Vo) and SplitMix64's output mix
//! (Steele, Lea, Flood 2014), which spreads any 64-bit state so that
//! `hash % n` is uniform.

/// SplitMix64's increment, the golden-ratio constant ⌊2⁶⁴/φ⌋.
pub const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// SplitMix64's output function: a bijective mix of a 64-bit state.
#[inline]
pub fn splitmix64_mix(state: u64) -> u64 {
    let z = (state ^ (state >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// FNV-1a 64 over a stream of bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fnv1a(u64);

impl Fnv1a {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The hash of no bytes.
    pub const fn new() -> Self {
        Fnv1a(Self::OFFSET)
    }

    /// The hash of `bytes`.
    pub fn of(bytes: &[u8]) -> u64 {
        let mut h = Self::new();
        h.write(bytes);
        h.value()
    }

    /// Adds `bytes`.
    #[inline]
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u8(b);
        }
    }

    /// Adds one byte.
    #[inline]
    pub fn write_u8(&mut self, b: u8) {
        self.0 = (self.0 ^ u64::from(b)).wrapping_mul(Self::PRIME);
    }

    /// Adds the little-endian bytes of `v`.
    #[inline]
    pub fn write_u64(&mut self, v: u64) {
        self.write(&v.to_le_bytes());
    }

    /// The FNV-1a value of the bytes so far.
    pub fn value(&self) -> u64 {
        self.0
    }

    /// The value spread by SplitMix64 (one step from it), for `hash % n`.
    pub fn mixed(&self) -> u64 {
        splitmix64_mix(self.0.wrapping_add(GOLDEN_GAMMA))
    }
}

/// Lets encoders that write into any `Extend<u8>` (postcard's
/// `to_extend`) hash a value without allocating.
impl Extend<u8> for Fnv1a {
    fn extend<I: IntoIterator<Item = u8>>(&mut self, bytes: I) {
        for b in bytes {
            self.write_u8(b);
        }
    }
}

impl<'a> Extend<&'a u8> for Fnv1a {
    fn extend<I: IntoIterator<Item = &'a u8>>(&mut self, bytes: I) {
        self.extend(bytes.into_iter().copied());
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_the_reference_vectors() {
        // From the FNV reference (draft-eastlake-fnv): "" and "a" and "foobar".
        assert_eq!(Fnv1a::of(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(Fnv1a::of(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(Fnv1a::of(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // SplitMix64 seeded with 0: the first outputs of the reference code.
        let mut state = 0u64;
        let mut next = || {
            state = state.wrapping_add(GOLDEN_GAMMA);
            splitmix64_mix(state)
        };
        assert_eq!(next(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(next(), 0x6e78_9e6a_a1b9_65f4);
    }
}
