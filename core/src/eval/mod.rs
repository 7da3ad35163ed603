//! Accuracy the way the SLAM field measures it.
//!
//! - [`relations`]: the relation metric of Kümmerle et al. 2009 ("On
//!   measuring the accuracy of SLAM algorithms"): for each ground-truth
//!   relation between two scans, the error of the estimated relative motion.
//! - [`ground_truth`]: absolute trajectory error after an SE(2) alignment,
//!   and relative pose error between consecutive poses.
//! - [`map_frame`]: errors in the map's frame, with no alignment, and the
//!   time to convergence: how a localizer is scored.
//! - [`lookalike`]: whether a localizer's wrong place looked, to its
//!   sensor, like the truth: a miss no localizer could have avoided.
//!
//! Each scores a [`Trajectory`](crate::trajectory::Trajectory).

pub mod ground_truth;
pub mod lookalike;
pub mod map_frame;
pub mod relations;

use crate::geometry::Pose2;
use crate::trajectory::Trajectory;

/// (stamp, estimated pose, true pose) at every stamp of `estimate` that
/// `truth` has a pose for (within [`relations::STAMP_TOLERANCE`]).
pub(crate) fn common_stamps(estimate: &Trajectory, truth: &Trajectory) -> Vec<(f64, Pose2, Pose2)> {
    estimate
        .stamps
        .iter()
        .zip(&estimate.poses)
        .filter_map(|(&t, p)| truth.at(t, relations::STAMP_TOLERANCE).map(|g| (t, *p, g)))
        .collect()
}

/// Mean and population standard deviation.
pub(crate) fn mean_std(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}
