//! The particle filter kinds (`pf.dispatcher`, `pf.matcher`,
//! `pf.resampler`) one task at a time, on parfil with a handful of
//! particles: tuples in, tuples out, through
//! `squall_topology::testing::BoltHarness`.

mod dispatcher;
mod filter;
mod matcher;
mod resampler;

use std::sync::Arc;

use squall_bolts::parfil::{ParfilOptions, ParfilReading, ParfilWorld};
use squall_core::geometry::Pose2;

/// The run seed every test uses.
const SEED: u64 = 7;

/// The options of a parfil matcher with `particles`.
fn options(particles: usize) -> ParfilOptions {
    ParfilOptions { particles, ..ParfilOptions::default() }
}

/// `n` readings of a robot driving 1 m per iteration from (50, 50).
fn drive(n: usize) -> Vec<Arc<ParfilReading>> {
    let mut world = ParfilWorld::new(ParfilOptions::default(), Pose2::new(50.0, 50.0, 0.3), SEED);
    (0..n).map(|_| Arc::new(world.step(1.0, 0.05))).collect()
}
