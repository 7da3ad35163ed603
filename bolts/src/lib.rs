//! squall-bolts: robotics algorithms as pure modules, and the thin bolts that
//! host them on the engine.
//!
//! The algorithm modules never touch the runtime: they take values and
//! return values, so they can be tested, benchmarked and reused alone.

pub mod cgr;
mod error;
pub mod parfil;
pub mod pf;
pub mod sinks;
pub mod slam;
pub mod view;

use squall_topology::Registry;

pub use error::{Error, Result};

/// Registers every kind this crate provides: the particle filter kinds with
/// their three models (`slam`, `parfil`, `cgr`, in that order), the
/// localization kinds, the parfil world and the sinks.
pub fn register(r: &mut Registry) {
    slam::register(r);
    parfil::register(r);
    cgr::register(r);
    sinks::register(r);
    view::register(r);
}
