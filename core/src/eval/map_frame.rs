//! Errors against ground truth in the map's own frame, with no alignment:
//! how a localizer is scored.
//!
//! A localizer reports poses in the frame of the map it was given, which
//! is the ground truth's frame. Aligning its trajectory to the truth before
//! scoring (as ATE does, rightly, for SLAM, whose map frame is its own)
//! forgives exactly the failures a localizer can have: a robot placed in
//! the wrong room, or the right room turned round, can align to a small
//! error. Here every pose is compared as it is.

use serde::Serialize;

use crate::geometry::{Pose2, normalize_angle};
use crate::trajectory::Trajectory;

/// A pose counts as localized within this distance of the truth, metres...
pub const WITHIN_M: f64 = 0.2;
/// ...and this heading error, degrees.
pub const WITHIN_DEG: f64 = 5.0;

/// Errors of a trajectory against ground truth, pose by pose, in the map
/// frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MapFrameScore {
    /// Poses with a ground-truth pose at the same stamp.
    pub pairs: usize,
    /// Mean position error, metres.
    pub map_mean_m: f64,
    /// Largest position error, metres.
    pub map_max_m: f64,
    /// Mean absolute heading error, degrees.
    pub map_rot_mean_deg: f64,
    /// Largest absolute heading error, degrees.
    pub map_rot_max_deg: f64,
    /// Share of the poses within [`WITHIN_M`] and [`WITHIN_DEG`] (0 to 1).
    pub map_within_share: f64,
    /// Seconds from the first pose to the first one after which every pose
    /// is within [`WITHIN_M`] and [`WITHIN_DEG`] (0 for a run that starts
    /// localized and stays so); `None` if the last pose is not within them.
    pub converged_after_s: Option<f64>,
}

/// Whether `estimate` is within [`WITHIN_M`] and [`WITHIN_DEG`] of `truth`.
pub fn is_within(estimate: &Pose2, truth: &Pose2) -> bool {
    estimate.distance(truth) <= WITHIN_M
        && normalize_angle(estimate.theta - truth.theta).abs().to_degrees() <= WITHIN_DEG
}

/// Scores `estimate` against `truth` at their common stamps, as they are.
/// `None` if no stamp is common.
pub fn score(estimate: &Trajectory, truth: &Trajectory) -> Option<MapFrameScore> {
    let pairs = super::common_stamps(estimate, truth);
    let (&(first, _, _), &(_, last, last_truth)) = (pairs.first()?, pairs.last()?);
    let n = pairs.len() as f64;
    let (mut sum, mut max, mut rot_sum, mut rot_max, mut within) = (0.0, 0.0f64, 0.0, 0.0f64, 0usize);
    for (_, p, g) in &pairs {
        let (d, r) = (p.distance(g), normalize_angle(p.theta - g.theta).abs().to_degrees());
        (sum, max, rot_sum, rot_max) = (sum + d, max.max(d), rot_sum + r, rot_max.max(r));
        within += usize::from(is_within(p, g));
    }
    // The pose after the last one outside the bounds starts the settled
    // stretch; a run that ends outside never settled.
    let converged_after_s = is_within(&last, &last_truth).then(|| {
        let settled = pairs.iter().rposition(|(_, p, g)| !is_within(p, g)).map_or(0, |i| i + 1);
        pairs[settled].0 - first
    });
    Some(MapFrameScore {
        pairs: pairs.len(),
        map_mean_m: sum / n,
        map_max_m: max,
        map_rot_mean_deg: rot_sum / n,
        map_rot_max_deg: rot_max,
        map_within_share: within as f64 / n,
        converged_after_s,
    })
}

/// Seconds from `since` to the first pose after which every pose of
/// `estimate` is within [`WITHIN_M`] and [`WITHIN_DEG`] of `truth` (to the
/// first pose after `since` when every one is); `None` if
/// the last pose is not within them or no pose comes after `since`. How
/// fast a kidnapped robot is found again: `since` is the kidnapping.
pub fn recovered_after(estimate: &Trajectory, truth: &Trajectory, since: f64) -> Option<f64> {
    let pairs: Vec<_> = super::common_stamps(estimate, truth).into_iter().filter(|p| p.0 > since).collect();
    let (_, last, last_truth) = pairs.last()?;
    if !is_within(last, last_truth) {
        return None;
    }
    let settled = pairs.iter().rposition(|(_, p, g)| !is_within(p, g)).map_or(0, |i| i + 1);
    Some(pairs[settled].0 - since)
}

/// The largest amount by which `estimate`'s position error exceeds
/// `reference`'s (say, raw odometry's) at the stamps all three share,
/// metres; negative when the estimate is better at every one. `None` if
/// no stamp is shared. How a localizer is held to "never worse than dead
/// reckoning" where its sensor sees nothing.
pub fn worst_excess(estimate: &Trajectory, reference: &Trajectory, truth: &Trajectory) -> Option<f64> {
    super::common_stamps(estimate, truth)
        .into_iter()
        .filter_map(|(t, p, g)| {
            let r = reference.at(t, super::relations::STAMP_TOLERANCE)?;
            Some(p.distance(&g) - r.distance(&g))
        })
        .reduce(f64::max)
}

/// When `estimate` was wrong (outside [`WITHIN_M`] and [`WITHIN_DEG`] of
/// `truth`): at its last pose by `end` if wrong there, else at its last
/// wrong pose after `end`; `None` if neither. Where a localizer that
/// missed its time (`end`: the time it was allowed) is judged.
pub fn wrong_at(estimate: &Trajectory, truth: &Trajectory, end: f64) -> Option<f64> {
    let pairs = super::common_stamps(estimate, truth);
    match pairs.iter().rfind(|(t, _, _)| *t <= end) {
        Some((t, p, g)) if !is_within(p, g) => Some(*t),
        _ => pairs.iter().rfind(|(t, p, g)| *t > end && !is_within(p, g)).map(|(t, _, _)| *t),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_miss_is_judged_where_the_estimate_was_wrong() {
        let path = |wrong: &dyn Fn(f64) -> bool| {
            let mut t = Trajectory::default();
            for i in 0..=20 {
                let s = f64::from(i);
                t.push(s, Pose2::new(s + if wrong(s) { 5.0 } else { 0.0 }, 0.0, 0.0));
            }
            t
        };
        let truth = path(&|_| false);
        // Wrong at the end of the time allowed: judged there.
        assert_eq!(wrong_at(&path(&|s| s <= 10.0), &truth, 10.0), Some(10.0));
        // Right then, wrong later (it did not stay): judged at the last wrong pose.
        assert_eq!(wrong_at(&path(&|s| s < 4.0 || (12.0..=14.0).contains(&s)), &truth, 10.0), Some(14.0));
        // Right from the end of the time allowed on: nothing to judge.
        assert_eq!(wrong_at(&path(&|s| s < 4.0), &truth, 10.0), None);
    }

    /// A walk of 50 poses, 0.2 s apart.
    fn walk() -> Trajectory {
        let mut t = Trajectory::default();
        for i in 0..50 {
            let s = i as f64 * 0.2;
            t.push(s, Pose2::new(s, 0.5 * s.sin(), 0.1 * s));
        }
        t
    }

    /// `truth` with pose i moved by `offset(i)`.
    fn moved(truth: &Trajectory, offset: impl Fn(usize) -> Pose2) -> Trajectory {
        let mut t = Trajectory::default();
        for (i, (s, p)) in truth.stamps.iter().zip(&truth.poses).enumerate() {
            let o = offset(i);
            t.push(*s, Pose2::new(p.x + o.x, p.y + o.y, p.theta + o.theta));
        }
        t
    }

    #[test]
    fn the_worst_excess_is_the_largest_gap_over_the_reference_error() {
        let truth = walk();
        // The reference drifts 0.01 m per pose; the estimate is 0.05 m off
        // throughout and 0.5 m off at pose 10.
        let reference = moved(&truth, |i| Pose2::new(0.01 * i as f64, 0.0, 0.0));
        let estimate = moved(&truth, |i| Pose2::new(0.0, if i == 10 { 0.5 } else { 0.05 }, 0.0));
        let worst = worst_excess(&estimate, &reference, &truth).unwrap();
        assert!((worst - 0.4).abs() < 1e-9, "{worst}");
        assert!(worst_excess(&truth, &reference, &truth).unwrap() <= 0.0, "the truth is never worse");
        assert_eq!(worst_excess(&estimate, &Trajectory::default(), &truth), None);
    }

    #[test]
    fn recovery_counts_from_the_kidnapping_to_the_last_pose_off() {
        let truth = walk();
        // Off by 3 m for the poses at 4.0–5.8 s, then within.
        let lost = moved(&truth, |i| Pose2::new(if (20..30).contains(&i) { 3.0 } else { 0.0 }, 0.0, 0.0));
        let after = recovered_after(&lost, &truth, 3.9).unwrap();
        assert!((after - 2.1).abs() < 1e-9, "{after}");
        // Nothing off after the instant: recovered at the first pose.
        let at_once = recovered_after(&lost, &truth, 5.9).unwrap();
        assert!((at_once - 0.1).abs() < 1e-9, "{at_once}");
        // Off at the end: not recovered.
        let stays = moved(&truth, |i| Pose2::new(if i >= 20 { 3.0 } else { 0.0 }, 0.0, 0.0));
        assert_eq!(recovered_after(&stays, &truth, 3.9), None);
        assert_eq!(recovered_after(&truth, &truth, 100.0), None, "no pose after the instant");
    }

    #[test]
    fn the_truth_itself_is_localized_from_the_start() {
        let truth = walk();
        let s = score(&truth, &truth).unwrap();
        assert_eq!(s.pairs, 50);
        assert!(s.map_mean_m < 1e-12 && s.map_max_m < 1e-12 && s.map_rot_max_deg < 1e-9, "{s:?}");
        assert_eq!((s.map_within_share, s.converged_after_s), (1.0, Some(0.0)));
    }

    #[test]
    fn a_rigidly_moved_copy_is_wrong_everywhere_unlike_its_ate() {
        let truth = walk();
        let shifted = moved(&truth, |_| Pose2::new(3.0, -4.0, 0.0));
        let s = score(&shifted, &truth).unwrap();
        assert!((s.map_mean_m - 5.0).abs() < 1e-9 && (s.map_max_m - 5.0).abs() < 1e-9, "{s:?}");
        assert_eq!((s.map_within_share, s.converged_after_s), (0.0, None));
        let aligned = crate::eval::ground_truth::score(&shifted, &truth);
        assert!(aligned.ate_rmse < 1e-9, "alignment forgives the shift: {aligned:?}");
    }

    #[test]
    fn convergence_is_when_the_estimate_arrives_and_stays() {
        let truth = walk();
        // Lost for the first ten poses (2 s), then right to the end.
        let arrives = moved(&truth, |i| if i < 10 { Pose2::new(2.0, 0.0, 0.0) } else { Pose2::default() });
        let s = score(&arrives, &truth).unwrap();
        assert!((s.converged_after_s.unwrap() - 2.0).abs() < 1e-9, "{s:?}");
        assert!((s.map_within_share - 0.8).abs() < 1e-12, "{s:?}");
        // Lost again at pose 30 for one pose: it settles only after that.
        let relapses = moved(&truth, |i| match i {
            0..10 | 30 => Pose2::new(0.0, 0.0, 0.2),
            _ => Pose2::default(),
        });
        let s = score(&relapses, &truth).unwrap();
        assert!((s.converged_after_s.unwrap() - 31.0 * 0.2).abs() < 1e-9, "{s:?}");
        assert!(s.map_mean_m < 1e-12, "the heading alone was off: {s:?}");
        assert!((s.map_rot_max_deg - 0.2f64.to_degrees()).abs() < 1e-9, "{s:?}");
        // Off at the last pose: never settled.
        let leaves = moved(&truth, |i| if i == 49 { Pose2::new(0.0, 0.3, 0.0) } else { Pose2::default() });
        assert_eq!(score(&leaves, &truth).unwrap().converged_after_s, None);
    }

    #[test]
    fn the_bounds_are_inclusive_and_both_must_hold() {
        let at = Pose2::new(1.0, 2.0, 0.5);
        assert!(is_within(&Pose2::new(1.0 + WITHIN_M * 0.999, 2.0, 0.5), &at));
        assert!(!is_within(&Pose2::new(1.0 + WITHIN_M * 1.001, 2.0, 0.5), &at));
        assert!(!is_within(&Pose2::new(1.0, 2.0, 0.5 + (WITHIN_DEG * 1.01).to_radians()), &at));
        // Headings compare across ±π.
        let west = Pose2::new(0.0, 0.0, std::f64::consts::PI - 0.01);
        assert!(is_within(&west, &Pose2::new(0.0, 0.0, -std::f64::consts::PI + 0.01)));
    }

    #[test]
    fn no_common_stamp_is_no_score() {
        let truth = walk();
        let mut late = Trajectory::default();
        late.push(1000.0, Pose2::default());
        assert_eq!(score(&late, &truth), None);
        assert_eq!(score(&Trajectory::default(), &truth), None);
    }
}
