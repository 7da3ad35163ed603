//! squall-bolts: robotics algorithms as pure modules, and the thin bolts that
//! host them on the engine.
//!
//! The algorithm modules never touch the runtime: they take values and
//! return values, so they can be tested, benchmarked and reused alone.

pub mod cgr;
pub mod cgr_topology;
pub mod parfil;
pub mod pf;
pub mod pf_topology;
pub mod sinks;
pub mod slam;
