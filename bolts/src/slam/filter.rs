//! The Rao-Blackwellized particle filter of GMapping: the generic
//! [`Filter`] over [`SlamModel`], with the SLAM outputs (best map, the
//! trajectory for every scan).
//!
//! Per reading: every particle is moved by the motion model. When the robot
//! has travelled `linear_update` or turned `angular_update` since the last
//! processed reading: (1) each particle's pose is refined by scan matching,
//! (2) its log-weight gains the scan's log-likelihood, (3) Neff is computed
//! and the set is resampled (low variance) when it falls below
//! `resample_threshold` × N, (4) each particle adds the scan to its map.
//! Random draws are keyed by the run seed, the step and the particle's slot,
//! never by a thread or task, so the particles may be split over any number
//! of shards with the same result.

use crate::pf::ParticleModel;
use crate::pf::trajectory;
use crate::pf::{Filter, StepReport};
use crate::slam::grid::TiledGrid;
use crate::slam::model::{SlamModel, SlamParticle};
use crate::slam::options::SlamOptions;
use squall_core::geometry::Pose2;
use squall_core::sensor::LaserReading;

/// GMapping's filter.
#[derive(Debug)]
pub struct Rbpf {
    filter: Filter<SlamModel>,
}

impl Rbpf {
    /// A filter; errors name the wrong option.
    pub fn new(options: SlamOptions, seed: u64) -> crate::Result<Self> {
        Self::sharded(options, seed, 1)
    }

    /// A filter with its particles split over `shards` (the same results
    /// as one; this is how the parallel topology splits them).
    pub fn sharded(options: SlamOptions, seed: u64, shards: usize) -> crate::Result<Self> {
        Ok(Rbpf { filter: Filter::new(SlamModel::new(options)?, seed, shards)? })
    }

    /// Feeds one reading; `Some` when it was processed.
    pub fn process(&mut self, scan: &LaserReading) -> Option<StepReport> {
        self.filter.process(scan)
    }

    /// Every particle, in slot order.
    pub fn particles(&self) -> Vec<&SlamParticle> {
        self.filter.states()
    }

    /// The particle whose lineage has the highest accumulated likelihood.
    pub fn best(&self) -> Option<&SlamParticle> {
        self.filter.best_state()
    }

    /// Distinct tiles over all particles' maps and snapshots, and their
    /// bytes.
    pub fn map_memory(&self) -> (usize, usize) {
        TiledGrid::distinct_tiles(self.particles().into_iter().flat_map(SlamParticle::grids))
    }

    /// The best particle's pose at `odometry`: its last processed pose moved
    /// by the odometry since then.
    pub fn estimate(&self, odometry: &Pose2) -> Option<Pose2> {
        self.filter.estimate(odometry)
    }

    /// A pose for each of `scans` (stamp, odometry), in order, from the
    /// final best particle's lineage, filled in between processed scans as
    /// `between_scans` says (see [`trajectory::fill`]). This is what
    /// `trajectory.tum` holds and what results are scored on.
    pub fn lineage_poses(&self, scans: impl IntoIterator<Item = (f64, Pose2)>) -> Vec<(f64, Pose2)> {
        let Some(population) = self.filter.population() else { return Vec::new() };
        let scans: Vec<(f64, Pose2)> = scans.into_iter().collect();
        let measured = self.filter.measured_steps();
        trajectory::fill(
            &population.best_trajectory(),
            &scans,
            self.filter.model().trajectory_output(),
            &measured,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_options_are_refused() {
        let e = Rbpf::new(SlamOptions { particles: 0, ..SlamOptions::default() }, 1).unwrap_err().to_string();
        assert!(e.contains("particles"), "{e}");
        assert!(Rbpf::sharded(SlamOptions::default(), 1, 0).is_err());
    }
}
