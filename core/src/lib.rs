//! squall-core: the robotics vocabulary every part of squall shares.
//!
//! Geometry and poses, sensor readings (laser, odometry, depth frames and
//! the camera model), occupancy grids and line maps, a building's inside, what is visible from a
//! point of a line map, trajectories and how the SLAM field scores them, the
//! odometry motion model, seeded random streams, text parsing helpers, the
//! map writers and the depth renderer. Pure values and functions: nothing
//! here runs a topology, so sources (`squall-spouts`) and algorithms
//! (`squall-bolts`) share it without depending on each other.

pub mod camera;
pub mod clock;
pub mod covariance;
pub mod depth_render;
mod error;
pub mod eval;
pub mod geometry;
pub mod interior;
pub mod linemap;
pub mod map_files;
pub mod motion;
pub mod no_return;
pub mod occupancy;
pub mod odometry_track;
pub mod random;
pub mod scan_match;
pub mod sensor;
pub mod slip;
pub mod textfile;
pub mod trajectory;
pub mod visibility;

pub use error::{Error, Result};
