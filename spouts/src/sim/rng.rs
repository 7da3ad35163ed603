//! Random streams keyed by what they are for, so that adding one use of
//! randomness never shifts another.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The generator for `purpose` under `seed`.
pub(crate) fn rng_for(seed: u64, purpose: &str) -> ChaCha8Rng {
    let mut h = 0xcbf2_9ce4_8422_2325_u64;
    for b in purpose.bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    ChaCha8Rng::seed_from_u64(seed ^ h.rotate_left(17))
}

/// A standard normal sample (Box–Muller).
pub(crate) fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    use rand::RngExt;
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}
