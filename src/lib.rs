//! squall: Storm-like stream topologies for cloud robotics.
//!
//! This facade re-exports the engine ([`topology`]), the robotics bolts
//! ([`bolts`]) and the sources ([`spouts`]), and holds the registry of every
//! built-in component kind ([`builtin::registry`]) that the `squall` binary
//! uses.

pub mod builtin;
pub mod cli;
pub mod ui;

pub use squall_bolts as bolts;
pub use squall_core as core;
pub use squall_spouts as spouts;
pub use squall_topology as topology;
