//! The weighted particle set after a correction, as the resampler emits it
//! on `particles` for whoever watches the filter (a Foxglove view).

use serde::{Deserialize, Serialize};

use squall_core::geometry::{Pose2, Real};

/// Every particle's pose and normalized weight at one reading.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParticleSet {
    /// Seconds.
    pub stamp: f64,
    /// Each particle's pose.
    pub poses: Vec<Pose2>,
    /// Each particle's weight; they sum to 1.
    pub weights: Vec<Real>,
}
