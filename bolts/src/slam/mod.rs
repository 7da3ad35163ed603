//! RBPF SLAM, GMapping-style (Grisetti, Stachniss, Burgard 2007): the pure
//! algorithm parts. Work in progress: the grid map and scan integration are
//! here; the motion model, scan matcher and resampling follow.

pub mod grid;
pub mod integrate;
pub mod matcher;
pub mod motion;
pub mod options;
