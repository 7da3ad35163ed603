//! RBPF SLAM, GMapping-style (Grisetti, Stachniss, Burgard 2007): the pure
//! algorithm parts: the tiled map, the motion model, the scan matcher, the
//! search against a particle's older map, the particle model, a serial
//! filter, and map transfers between processes.
//! [`hosted`] puts it on the particle filter kinds (`model = "slam"`).

pub mod backend;
pub mod filter;
pub mod grid;
pub(crate) mod hosted;
pub(crate) mod integrate;
pub(crate) mod matcher;
pub mod model;
pub(crate) mod old_map;
pub mod options;
pub(crate) mod proposal;
#[cfg(test)]
mod scenes;
pub(crate) mod transfer;
mod transfer_message;

pub use hosted::register;
