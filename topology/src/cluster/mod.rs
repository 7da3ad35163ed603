//! Cluster mode (feature `cluster`): the same topologies across worker
//! processes joined by zenoh: the cluster file, the frames that cross
//! processes with their checks, workers' sessions, presence and control,
//! and the runs themselves.

pub mod config;
mod error;
pub mod outcome;
pub mod run;
pub mod session;
pub mod wire;

pub use error::{HostError, PlacementError};
