//! RBPF SLAM, GMapping-style (Grisetti, Stachniss, Burgard 2007): the pure
//! algorithm parts: the tiled map, the motion model, the scan matcher, the
//! search against a particle's older map, the particle model, a serial
//! filter, and map transfers between processes.
//! [`hosted`] puts it on the particle filter kinds (`model = "slam"`).

pub mod filter;
pub mod grid;
pub mod hosted;
pub mod integrate;
pub mod matcher;
pub mod model;
pub mod old_map;
pub mod options;
#[cfg(test)]
mod scenes;
pub mod transfer;
mod transfer_message;

pub use hosted::register;
