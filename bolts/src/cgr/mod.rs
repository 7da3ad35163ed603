//! Depth-camera localization on line maps (thesis ch. 4–5; Biswas &
//! Veloso's FSPF and CGR): observable scenes and their precomputed grid,
//! Fast Sampling Plane Filtering, observations as 2-D points with normals,
//! the measurement model with Corrective Gradient Refinement, the particle
//! model, and the kinds that host them (`cgr.laser`, `cgr.fspf`, and
//! `model = "cgr"` on the particle filter kinds).

pub(crate) mod depth_points;
pub mod fspf;
pub(crate) mod hosted;
pub(crate) mod laser_points;
pub mod measurement;
pub mod model;
pub mod observation;
pub mod scene_grid;

pub use hosted::register;
