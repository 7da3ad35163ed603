//! Particle filters made parallel by splitting the particles over tasks,
//! written once for any [`ParticleModel`]: the shard a matcher task holds,
//! the resampler's population (weights, Neff, selective resampling,
//! lineage), the reassignment of particles to tasks after resampling, and a
//! [`Filter`] that runs all of it in one thread with K shards (K = 1 is the
//! serial filter; K > 1 gives the same results, which is what the parallel
//! topology relies on).

pub mod assign;
pub mod filter;
pub mod model;
pub mod modes;
pub mod population;
pub mod resample;
pub mod shard;
pub mod trajectory;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use filter::{Filter, StepReport};
pub use model::{Correction, ParticleModel};

/// The random stream of `slot` at reading `step` of a run (`u64::MAX` as
/// the slot: the resampler's): a hash of the three, so draws never depend
/// on which task holds a particle.
pub fn rng_for(seed: u64, step: u64, slot: u64) -> ChaCha8Rng {
    let mut z = seed ^ step.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ slot.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 31)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ChaCha8Rng::seed_from_u64(z)
}
