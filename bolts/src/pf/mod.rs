//! Particle filters made parallel by splitting the particles over tasks,
//! written once for any [`ParticleModel`]: the shard a matcher task holds,
//! the resampler's population (weights, Neff, selective resampling,
//! lineage), the reassignment of particles to tasks after resampling, and a
//! [`Filter`] that runs all of it in one thread with K shards (K = 1 is the
//! serial filter; K > 1 gives the same results, which is what the parallel
//! topology relies on).

pub(crate) mod assign;
pub mod filter;
pub mod kinds;
pub mod kld;
pub mod model;
pub(crate) mod modes;
pub mod particle_set;
pub mod population;
pub mod resample;
pub mod shard;
pub mod smoother;
pub(crate) mod trajectory;

pub use filter::{Filter, StepReport};
pub use model::{Correction, ParticleModel};
pub use particle_set::ParticleSet;
pub use smoother::{MeasuredStep, Smoother};
pub use trajectory::{BetweenScans, NoiseWeights, TrajectoryOutput};
