//! Cluster mode: the same topologies across worker processes joined by
//! zenoh: the cluster file, the frames that cross processes with their
//! checks, workers' sessions, presence and control, and the runs themselves.
//!
//! The cluster file and the frames are plain data, in every build (so they
//! can be checked, and fuzzed, without a transport); sessions and runs need
//! zenoh, the feature `cluster`.

pub mod config;
mod error;
#[cfg(feature = "cluster")]
pub mod identity;
pub mod outcome;
#[cfg(feature = "cluster")]
pub mod run;
#[cfg(feature = "cluster")]
pub mod session;
pub mod wire;

pub use error::{HostError, PlacementError};
