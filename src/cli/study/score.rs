//! The accuracy of a run and of its log's raw odometry, on the log's
//! relations (Kümmerle et al. 2009, as `squall eval` scores them).

use std::path::Path;

use squall_core::eval::ground_truth;
use squall_core::eval::relations::{Relation, score};
use squall_core::trajectory::Trajectory;

use super::Log;
use crate::cli::eval::{is_carmen, odometry_at_scans};

/// The relation metric's headline figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Accuracy {
    /// Mean translational error over the matched relations, m.
    pub(super) trans_m: f64,
    /// Mean rotational error, degrees.
    pub(super) rot_deg: f64,
    /// Mean translational error of the relations spanning under 10 s
    /// (local accuracy), m; `None` when none of them matched.
    pub(super) span_0_10_m: Option<f64>,
}

/// Scores `trajectory`; `None` when no relation matches its stamps.
fn accuracy(trajectory: &Trajectory, relations: &[Relation]) -> Option<Accuracy> {
    let s = score(trajectory, relations);
    (s.matched > 0).then(|| Accuracy {
        trans_m: s.trans_mean,
        rot_deg: s.rot_mean_deg,
        span_0_10_m: (s.by_span[0].matched > 0).then_some(s.by_span[0].trans_mean),
    })
}

/// A finished run's scores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Scored {
    /// On the log's relations; `None` without relations (or none matched).
    pub(super) accuracy: Option<Accuracy>,
    /// Absolute trajectory error (RMSE after alignment) against the ground
    /// truth, m, where there is one (simulated worlds).
    pub(super) ate_m: Option<f64>,
}

/// Scores a finished run's trajectory; `Err` when it is missing or
/// unreadable.
pub(super) fn run(
    trajectory: &Path,
    relations: Option<&[Relation]>,
    truth: Option<&Trajectory>,
) -> Result<Scored, String> {
    let t = Trajectory::read_tum(trajectory).map_err(|e| format!("no usable trajectory: {e}"))?;
    if t.is_empty() {
        return Err(format!("{}: the trajectory has no poses", trajectory.display()));
    }
    let ate_m = truth.map(|truth| ground_truth::score(&t, truth)).filter(|s| s.pairs > 0).map(|s| s.ate_rmse);
    Ok(Scored { accuracy: relations.and_then(|r| accuracy(&t, r)), ate_m })
}

/// Scores the raw odometry of a CARMEN log at its scans, the first
/// `max_scans` of them when the runs stop there (so both are scored on the
/// same stretch); `None` without relations or when the log does not read.
pub(super) fn odometry(log: &Log, max_scans: Option<u64>) -> Option<Accuracy> {
    let relations = log.relations.as_deref()?;
    if !is_carmen(&log.path) {
        return None;
    }
    let mut t = odometry_at_scans(&log.path).ok()?;
    if let Some(m) = max_scans.and_then(|m| usize::try_from(m).ok()) {
        t.stamps.truncate(m);
        t.poses.truncate(m);
    }
    accuracy(&t, relations)
}
