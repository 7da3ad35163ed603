//! Errors against a ground-truth trajectory: ATE after the best SE(2)
//! alignment (no scale) and RPE between consecutive poses.

use serde::Serialize;

use crate::geometry::{Pose2, normalize_angle};
use crate::trajectory::Trajectory;

/// Absolute and relative errors against ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GroundTruthScore {
    /// Poses with a ground-truth pose at the same stamp.
    pub pairs: usize,
    /// Root mean square position error after alignment, metres.
    pub ate_rmse: f64,
    /// Mean absolute heading error after alignment, degrees.
    pub ate_rot_mean_deg: f64,
    /// RMS translational error of consecutive relative motions, metres.
    pub rpe_trans_rmse: f64,
    /// RMS rotational error of consecutive relative motions, degrees.
    pub rpe_rot_rmse_deg: f64,
}

/// The rigid motion that best maps `from` points onto `to` points in the
/// least-squares sense (2-D Kabsch/Umeyama without scale).
pub fn align(from: &[(f64, f64)], to: &[(f64, f64)]) -> Pose2 {
    let n = from.len().max(1) as f64;
    let mean = |pts: &[(f64, f64)]| {
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |(ax, ay), (x, y)| (ax + x, ay + y));
        (sx / n, sy / n)
    };
    let (fx, fy) = mean(from);
    let (tx, ty) = mean(to);
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for ((ax, ay), (bx, by)) in from.iter().zip(to) {
        let (ax, ay, bx, by) = (ax - fx, ay - fy, bx - tx, by - ty);
        sxx += ax * bx + ay * by;
        sxy += ax * by - ay * bx;
    }
    let theta = sxy.atan2(sxx);
    let (s, c) = theta.sin_cos();
    Pose2::new(tx - (c * fx - s * fy), ty - (s * fx + c * fy), theta)
}

/// Scores `estimate` against `truth` at their common stamps.
pub fn score(estimate: &Trajectory, truth: &Trajectory) -> GroundTruthScore {
    let pairs: Vec<(Pose2, Pose2)> =
        super::common_stamps(estimate, truth).into_iter().map(|(_, p, g)| (p, g)).collect();
    let from: Vec<(f64, f64)> = pairs.iter().map(|(p, _)| (p.x, p.y)).collect();
    let to: Vec<(f64, f64)> = pairs.iter().map(|(_, g)| (g.x, g.y)).collect();
    let t = align(&from, &to);
    let n = pairs.len().max(1) as f64;
    let (mut sq, mut rot) = (0.0, 0.0);
    for (p, g) in &pairs {
        let aligned = t.compose(p);
        sq += aligned.distance(g).powi(2);
        rot += normalize_angle(aligned.theta - g.theta).abs().to_degrees();
    }
    let (mut rpe_t, mut rpe_r, mut m) = (0.0, 0.0, 0usize);
    for w in pairs.windows(2) {
        let (p1, g1) = w[0];
        let (p2, g2) = w[1];
        let e = p2.relative_to(&p1).relative_to(&g2.relative_to(&g1));
        rpe_t += e.x * e.x + e.y * e.y;
        rpe_r += normalize_angle(e.theta).to_degrees().powi(2);
        m += 1;
    }
    let m = m.max(1) as f64;
    GroundTruthScore {
        pairs: pairs.len(),
        ate_rmse: (sq / n).sqrt(),
        ate_rot_mean_deg: rot / n,
        rpe_trans_rmse: (rpe_t / m).sqrt(),
        rpe_rot_rmse_deg: (rpe_r / m).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wiggle() -> Trajectory {
        let mut t = Trajectory::default();
        for i in 0..50 {
            let s = i as f64 * 0.2;
            t.push(s, Pose2::new(s.cos() * 3.0, s.sin() * 2.0 + 0.1 * s, 0.3 * s));
        }
        t
    }

    #[test]
    fn a_rigidly_moved_copy_scores_zero() {
        let truth = wiggle();
        let shift = Pose2::new(5.0, -3.0, 1.1);
        let mut moved = Trajectory::default();
        for (t, p) in truth.stamps.iter().zip(&truth.poses) {
            moved.push(*t, shift.compose(p));
        }
        let s = score(&moved, &truth);
        assert_eq!(s.pairs, 50);
        assert!(s.ate_rmse < 1e-9 && s.ate_rot_mean_deg < 1e-7, "{s:?}");
        assert!(s.rpe_trans_rmse < 1e-9 && s.rpe_rot_rmse_deg < 1e-7, "{s:?}");
    }

    #[test]
    fn a_constant_offset_in_one_pose_shows_in_ate_and_rpe() {
        let truth = wiggle();
        let mut est = truth.clone();
        est.poses[25].x += 1.0;
        let s = score(&est, &truth);
        assert!(s.ate_rmse > 0.1 && s.ate_rmse < 0.2, "{s:?}");
        // Two consecutive relations touch the moved pose: each off by 1 m.
        assert!((s.rpe_trans_rmse - (2.0f64 / 49.0).sqrt()).abs() < 0.02, "{s:?}");
    }
}
