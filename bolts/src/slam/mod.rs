//! RBPF SLAM, GMapping-style (Grisetti, Stachniss, Burgard 2007): the pure
//! algorithm parts. Work in progress: the map, motion model, scan matcher,
//! resampling and the serial filter are here; the topology, the CLI and the
//! accuracy and speed work follow.

pub mod filter;
pub mod grid;
pub mod integrate;
pub mod matcher;
pub mod model;
pub mod motion;
pub mod options;
