//! Depth-camera localization on line maps (thesis ch. 4–5; Biswas &
//! Veloso's FSPF and CGR): observable scenes and their precomputed grid,
//! Fast Sampling Plane Filtering, observations as 2-D points with normals,
//! and the measurement model with Corrective Gradient Refinement. Work in
//! progress: the particle model, the depth simulator and `squall localize`
//! follow.

pub mod fspf;
pub mod measurement;
pub mod model;
pub mod observation;
pub mod scene_grid;
