//! Seeded random streams, keyed by what they are for, so that adding one
//! use of randomness never shifts another and a draw never depends on which
//! task or thread made it. The generator is ChaCha8: portable, the same
//! sequence on every platform and in every build.
//!
//! Two keyings, for two kinds of user:
//! - [`stream_for_purpose`]: a named purpose (`"people"`, `"laser noise"`),
//!   for simulators that open a handful of streams once;
//! - [`stream_for_step`]: numbers (run seed, reading, particle slot), for
//!   particle filters that open one stream per particle per reading and
//!   cannot afford to hash a name each time.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use squall_topology::hash::{Fnv1a, GOLDEN_GAMMA};

/// The stream for `purpose` under `seed`.
pub fn stream_for_purpose(seed: u64, purpose: &str) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ Fnv1a::of(purpose.as_bytes()).rotate_left(17))
}

/// The stream of `slot` at reading `step` of a run (`u64::MAX` as the slot:
/// a filter's own draws, such as resampling): a hash of the three.
pub fn stream_for_step(seed: u64, step: u64, slot: u64) -> ChaCha8Rng {
    let mut z = seed ^ step.wrapping_mul(GOLDEN_GAMMA) ^ slot.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 31)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ChaCha8Rng::seed_from_u64(z)
}

/// A standard normal sample (Box–Muller, one of the pair).
pub fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    use rand::RngExt;
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;

    #[test]
    fn streams_differ_by_key_and_repeat_by_seed() {
        let first = |mut r: ChaCha8Rng| r.random::<u64>();
        assert_eq!(first(stream_for_purpose(7, "people")), first(stream_for_purpose(7, "people")));
        assert_ne!(first(stream_for_purpose(7, "people")), first(stream_for_purpose(7, "noise")));
        assert_ne!(first(stream_for_purpose(7, "people")), first(stream_for_purpose(8, "people")));
        assert_eq!(first(stream_for_step(1, 2, 3)), first(stream_for_step(1, 2, 3)));
        assert_ne!(first(stream_for_step(1, 2, 3)), first(stream_for_step(1, 3, 2)));
        assert_ne!(first(stream_for_step(1, 2, 3)), first(stream_for_step(1, 2, u64::MAX)));
    }

    #[test]
    fn standard_normal_has_unit_spread() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 50_000;
        let samples: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng)).collect();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.02 && (var - 1.0).abs() < 0.03, "mean {mean}, variance {var}");
    }
}
