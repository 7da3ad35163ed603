//! KLD-sampling (Fox 2003): how many particles the set needs, decided at
//! each resampling from how spread the weighted set is. Particles are
//! drawn from the weights, each counted into a histogram bin of the pose
//! space; with k bins occupied, n(k) draws bound the Kullback–Leibler
//! distance between the sample and the true posterior by ε with
//! probability 1 − δ:
//!
//! n(k) = (k − 1) / 2ε · (1 − 2 / 9(k − 1) + √(2 / 9(k − 1)) · z₁₋δ)³.
//!
//! A set spread over many places (a global start, a kidnapped robot) keeps
//! up to `max` particles; one that has found the robot falls to `min`,
//! which is what tracking costs.

use std::collections::HashSet;

use rand::RngExt;
use serde::{Deserialize, Serialize};

use squall_core::geometry::{Pose2, Real};
use squall_core::random::stream_for_step;

/// Offset of the random streams of KLD's draws (draw i uses
/// `KLD_STREAM + i`), apart from every other stream of a step.
pub const KLD_STREAM: u64 = 1 << 42;

/// KLD-sampling's settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Kld {
    /// Fewest particles (what tracking needs).
    pub min: usize,
    /// Most particles (the set's size at the start).
    pub max: usize,
    /// ε: the bound on the KL distance.
    pub epsilon: Real,
    /// z₁₋δ: the standard normal quantile of the bound's confidence.
    pub z: Real,
    /// Bin size in x and y, metres.
    pub cell: Real,
    /// Bin size in heading, radians.
    pub turn: Real,
}

impl Kld {
    /// Fox's and ROS AMCL's bins (0.5 m, 10°), with the bound at ε = 0.05
    /// and δ = 0.01 (z = 2.33), between `min` and `max` particles.
    pub fn new(min: usize, max: usize) -> Self {
        Kld { min, max, epsilon: 0.05, z: 2.33, cell: 0.5, turn: 10f64.to_radians() }
    }

    /// n(k): particles that k occupied bins call for (unbounded).
    pub fn bound(&self, k: usize) -> usize {
        if k <= 1 {
            return 1;
        }
        let k1 = (k - 1) as Real;
        let a = 2.0 / (9.0 * k1);
        let cube = (1.0 - a + a.sqrt() * self.z).powi(3);
        (k1 / (2.0 * self.epsilon) * cube).ceil() as usize
    }

    /// Checks the settings; says which is wrong.
    pub fn check(&self) -> crate::Result<()> {
        if self.min == 0 || self.min > self.max {
            return Err(crate::Error::Setting(format!(
                "KLD-sampling needs 1 ≤ min_particles ≤ particles, got {} and {}",
                self.min, self.max
            )));
        }
        for (name, v) in [("epsilon", self.epsilon), ("z", self.z), ("cell", self.cell), ("turn", self.turn)]
        {
            crate::error::positive(name, v)?;
        }
        Ok(())
    }

    /// How many particles to draw from `weights` (normalized; slot i at
    /// `pose(i)`): draws one at a time, keyed by the run seed, the reading
    /// and the draw, counting the bins they land in, until n(k) draws are
    /// made, within [min, max].
    pub fn count(&self, weights: &[Real], pose: impl Fn(usize) -> Pose2, seed: u64, step: u64) -> usize {
        let mut cumulative = Vec::with_capacity(weights.len());
        let mut sum = 0.0;
        for w in weights {
            sum += w;
            cumulative.push(sum);
        }
        if weights.is_empty() || sum <= 0.0 {
            return self.min;
        }
        let mut bins = HashSet::new();
        let mut n = 0;
        while n < self.max {
            let beta = stream_for_step(seed, step, KLD_STREAM + n as u64).random::<Real>() * sum;
            let p = pose(cumulative.partition_point(|&c| c < beta).min(weights.len() - 1));
            let heading = squall_core::geometry::normalize_angle(p.theta);
            bins.insert((
                (p.x / self.cell).floor() as i64,
                (p.y / self.cell).floor() as i64,
                (heading / self.turn).floor() as i64,
            ));
            n += 1;
            if n >= self.min && n >= self.bound(bins.len()) {
                break;
            }
        }
        n.clamp(self.min, self.max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_grows_with_the_bins_as_fox_tabulates() {
        let k = Kld::new(1, 100_000);
        // ε = 0.05, z = 2.33: 67 particles for 2 bins, 217 for 10, 750
        // for 50 (the bound is about linear in k).
        assert_eq!(k.bound(2), 67);
        assert!((200..=230).contains(&k.bound(10)), "{}", k.bound(10));
        assert!((700..=780).contains(&k.bound(50)), "{}", k.bound(50));
        assert!(k.bound(100) > k.bound(50));
    }

    #[test]
    fn a_found_robot_needs_few_particles_and_a_lost_one_many() {
        let k = Kld::new(50, 2000);
        let n = 2000;
        let weights = vec![1.0 / n as Real; n];
        // Within one bin: the fewest.
        let one: Vec<Pose2> = (0..n).map(|i| Pose2::new(1.1 + 1e-4 * i as Real, 2.2, 0.01)).collect();
        assert_eq!(k.count(&weights, |i| one[i], 1, 1), 50);
        // Spread over a 40 m × 40 m floor and every heading: the most.
        let spread: Vec<Pose2> =
            (0..n).map(|i| Pose2::new((i % 40) as Real, (i / 40) as Real * 0.8, i as Real * 0.7)).collect();
        assert_eq!(k.count(&weights, |i| spread[i], 1, 1), 2000);
        // Two places: n(2).
        let two: Vec<Pose2> =
            (0..n).map(|i| Pose2::new(if i % 2 == 0 { 0.1 } else { 30.1 }, 0.1, 0.0)).collect();
        let c = k.count(&weights, |i| two[i], 1, 1);
        assert_eq!(c, 67);
        // The weights, not the slots, decide: all weight on one of the two.
        let mut heavy = vec![0.0; n];
        heavy[0] = 1.0;
        assert_eq!(k.count(&heavy, |i| spread[i], 1, 1), 50);
    }

    #[test]
    fn wrong_settings_are_named() {
        assert!(Kld::new(0, 10).check().is_err());
        assert!(Kld::new(20, 10).check().is_err());
        assert!(Kld { epsilon: 0.0, ..Kld::new(1, 10) }.check().unwrap_err().to_string().contains("epsilon"));
        assert!(Kld::new(50, 2000).check().is_ok());
    }
}
