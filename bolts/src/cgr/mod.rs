//! Depth-camera localization on line maps (thesis ch. 4–5; Biswas &
//! Veloso's FSPF and CGR): observable scenes, their precomputed grid, and
//! Fast Sampling Plane Filtering. Work in progress: the CGR model, the
//! depth simulator and `squall localize` follow.

pub mod fspf;
pub mod scene;
pub mod scene_grid;
