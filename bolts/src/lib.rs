//! squall-bolts: robotics algorithms as pure modules, and the thin bolts that
//! host them on the engine.
//!
//! The algorithm modules never touch the runtime: they take values and
//! return values, so they can be tested, benchmarked and reused alone.

pub mod cgr;
pub mod cgr_topology;
pub mod eval;
pub mod geometry;
pub mod linemap;
pub mod map;
pub mod parfil;
pub mod pf;
pub mod pf_topology;
pub mod sensor;
pub mod sinks;
pub mod slam;
pub mod textfile;
