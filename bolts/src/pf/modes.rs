//! The modes of a weighted particle set: where the filter thinks the robot
//! may be, with how much weight each place gets (the thesis's future work:
//! report several hypotheses, not only the best). Particles are taken
//! heaviest first; each joins the first mode within `radius` metres and
//! `turn` radians of its seed particle or starts a new one. A mode's pose
//! is its particles' weighted mean (the heading a circular mean).

use serde::{Deserialize, Serialize};

use squall_core::geometry::{Pose2, Real, normalize_angle};

/// One place the robot may be.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Mode {
    /// Weighted mean pose of its particles.
    pub pose: Pose2,
    /// Its share of the total weight.
    pub weight: Real,
    /// Particles in it.
    pub particles: usize,
}

/// The hypotheses at one reading, heaviest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Hypotheses {
    /// Seconds.
    pub stamp: f64,
    /// At most the requested number of modes.
    pub modes: Vec<Mode>,
}

/// Modes opened at most: particles that fit none of them once this many
/// exist (light ones, taken last) are left out, which bounds the work by
/// N × this for a spread-out set.
pub(crate) const MAX_OPEN: usize = 64;

/// The `keep` heaviest modes of `poses` with normalized `weights` (a
/// mode's weight is its share of all the weight).
pub(crate) fn modes(poses: &[Pose2], weights: &[Real], radius: Real, turn: Real, keep: usize) -> Vec<Mode> {
    let mut order: Vec<usize> = (0..poses.len().min(weights.len())).collect();
    order.sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
    // (seed pose, Σw, Σw·x, Σw·y, Σw·cos, Σw·sin, count)
    let mut found: Vec<(Pose2, [Real; 5], usize)> = Vec::new();
    for i in order {
        let (p, w) = (poses[i], weights[i]);
        let home = found.iter().position(|(seed, _, _)| {
            seed.distance(&p) <= radius && normalize_angle(seed.theta - p.theta).abs() <= turn
        });
        let index = match home {
            Some(k) => k,
            None if found.len() < MAX_OPEN => {
                found.push((p, [0.0; 5], 0));
                found.len() - 1
            }
            None => continue,
        };
        let entry = &mut found[index];
        let s = &mut entry.1;
        s[0] += w;
        s[1] += w * p.x;
        s[2] += w * p.y;
        s[3] += w * p.theta.cos();
        s[4] += w * p.theta.sin();
        entry.2 += 1;
    }
    let total: Real = weights.iter().take(poses.len()).sum();
    let mut out: Vec<Mode> = found
        .into_iter()
        .map(|(seed, s, particles)| {
            let pose = if s[0] > 0.0 { Pose2::new(s[1] / s[0], s[2] / s[0], s[4].atan2(s[3])) } else { seed };
            Mode { pose, weight: if total > 0.0 { s[0] / total } else { 0.0 }, particles }
        })
        .collect();
    out.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    out.truncate(keep);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_clusters_give_two_modes_weighted_by_their_particles() {
        let mut poses = Vec::new();
        let mut weights = Vec::new();
        for k in 0..30 {
            poses.push(Pose2::new(1.0 + 0.01 * (k % 5) as Real, 2.0, 0.1));
            weights.push(1.0);
        }
        for k in 0..10 {
            poses.push(Pose2::new(8.0, -3.0 + 0.01 * k as Real, -1.0));
            weights.push(1.0);
        }
        let total: Real = weights.iter().sum();
        let weights: Vec<Real> = weights.iter().map(|w| w / total).collect();
        let m = modes(&poses, &weights, 0.5, 0.5, 3);
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].particles, m[1].particles), (30, 10));
        assert!((m[0].weight - 0.75).abs() < 1e-12 && (m[1].weight - 0.25).abs() < 1e-12);
        assert!((m[0].pose.x - 1.02).abs() < 1e-9 && (m[1].pose.y + 2.955).abs() < 1e-9, "{m:?}");
        assert_eq!(modes(&poses, &weights, 0.5, 0.5, 1).len(), 1);
    }

    #[test]
    fn a_spread_out_set_opens_a_bounded_number_of_modes() {
        let poses: Vec<Pose2> = (0..1000).map(|k| Pose2::new(k as Real, 0.0, 0.0)).collect();
        let weights = vec![0.001; 1000];
        let m = modes(&poses, &weights, 0.5, 0.5, 1000);
        assert_eq!(m.len(), MAX_OPEN);
        assert!(m.iter().all(|x| (x.weight - 0.001).abs() < 1e-12), "shares of the whole set");
    }

    #[test]
    fn headings_average_across_the_wrap() {
        let poses = [Pose2::new(0.0, 0.0, 3.1), Pose2::new(0.0, 0.0, -3.1)];
        let m = modes(&poses, &[0.5, 0.5], 0.5, 0.5, 2);
        assert_eq!(m.len(), 1);
        assert!((m[0].pose.theta.abs() - std::f64::consts::PI).abs() < 1e-9, "{m:?}");
    }
}
