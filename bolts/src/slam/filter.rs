//! The Rao-Blackwellized particle filter of GMapping, serial: each particle
//! carries a pose, an accumulated log-weight, its own (tiled, shared) map
//! and its node in the lineage tree from which the best trajectory is read.
//!
//! Per reading: every particle is moved by the motion model. When the robot
//! has travelled `linear_update` or turned `angular_update` since the last
//! processed reading: (1) each particle's pose is refined by scan matching,
//! (2) its log-weight gains the scan's log-likelihood, (3) Neff is computed
//! and the set is resampled (low variance) when it falls below
//! `resample_threshold` × N, (4) each particle adds the scan to its map.
//! Random draws are keyed by the run seed, the step and the particle's slot,
//! never by a thread or task.

use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Pose2, Real, normalize_angle};
use crate::sensor::LaserReading;
use crate::slam::grid::TiledGrid;
use crate::slam::integrate::integrate_scan;
use crate::slam::matcher::{Matcher, PreparedScan};
use crate::slam::motion::sample_motion;
use crate::slam::options::SlamOptions;
use crate::slam::resample::{low_variance, normalize};
use crate::slam::trajectory::{self, NoiseWeights};

/// A pose a particle held at a processed reading, linked to its ancestor's.
#[derive(Debug)]
pub struct Node {
    /// Reading stamp, seconds.
    pub stamp: f64,
    /// The particle's pose then.
    pub pose: Pose2,
    /// The odometry pose of that reading.
    pub odometry: Pose2,
    /// The ancestor's node.
    pub parent: Option<Arc<Node>>,
}

/// One hypothesis of trajectory and map.
#[derive(Debug, Clone)]
pub struct Particle {
    /// Current pose.
    pub pose: Pose2,
    /// Log-likelihood accumulated since the last resampling.
    pub log_weight: Real,
    /// Log-likelihood accumulated over the particle's whole lineage (never
    /// reset): what "best particle" means, as in GMapping's `weightSum`.
    pub lineage_weight: Real,
    /// The map built along this particle's trajectory.
    pub map: TiledGrid,
    /// The last processed pose and its ancestry.
    pub node: Arc<Node>,
}

/// What one processed reading did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Pose evaluations per particle.
    pub evaluations: Vec<u32>,
    /// Neff before resampling.
    pub neff: Real,
    /// Whether the set was resampled.
    pub resampled: bool,
    /// Map tiles cloned by copy-on-write while updating.
    pub tiles_cloned: u64,
}

/// The filter.
#[derive(Debug)]
pub struct Rbpf {
    options: SlamOptions,
    seed: u64,
    particles: Vec<Particle>,
    last_odometry: Option<Pose2>,
    travelled: (Real, Real),
    step: u64,
    /// Scan-matching scratch memory, reused by every particle.
    matcher: Matcher,
}

fn rng_for(seed: u64, step: u64, slot: u64) -> ChaCha8Rng {
    let mut z = seed ^ step.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ slot.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 31)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ChaCha8Rng::seed_from_u64(z)
}

impl Rbpf {
    /// A filter; errors name the wrong option.
    pub fn new(options: SlamOptions, seed: u64) -> Result<Self, String> {
        options.check()?;
        Ok(Rbpf {
            options,
            seed,
            particles: Vec::new(),
            last_odometry: None,
            travelled: (0.0, 0.0),
            step: 0,
            matcher: Matcher::default(),
        })
    }

    /// The particles.
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// The particle whose lineage has the highest accumulated likelihood.
    pub fn best(&self) -> Option<&Particle> {
        self.particles.iter().max_by(|a, b| a.lineage_weight.total_cmp(&b.lineage_weight))
    }

    /// The best particle's pose at `odometry`: its last processed pose moved
    /// by the odometry since then.
    pub fn estimate(&self, odometry: &Pose2) -> Option<Pose2> {
        self.best().map(|p| p.node.pose.compose(&odometry.relative_to(&p.node.odometry)))
    }

    /// The best particle's processed poses, oldest first: (stamp, pose,
    /// odometry).
    pub fn best_trajectory(&self) -> Vec<(f64, Pose2, Pose2)> {
        let mut out = Vec::new();
        let mut node = self.best().map(|p| p.node.clone());
        while let Some(n) = node {
            out.push((n.stamp, n.pose, n.odometry));
            node = n.parent.clone();
        }
        out.reverse();
        out
    }

    /// A pose for each of `scans` (stamp, odometry), in order, from the
    /// final best particle's lineage, filled in between processed scans as
    /// `between_scans` says (see [`trajectory::fill`]). This is what
    /// `trajectory.tum` holds and what results are scored on.
    pub fn lineage_poses(&self, scans: impl IntoIterator<Item = (f64, Pose2)>) -> Vec<(f64, Pose2)> {
        let scans: Vec<(f64, Pose2)> = scans.into_iter().collect();
        let o = &self.options;
        let noise = NoiseWeights { per_metre: o.srr, per_radian: o.str };
        trajectory::fill(&self.best_trajectory(), &scans, o.between_scans, noise)
    }

    /// Feeds one reading; `Some` when it was processed.
    pub fn process(&mut self, scan: &LaserReading) -> Option<StepReport> {
        let o = &self.options;
        let Some(last) = self.last_odometry else {
            return Some(self.start(scan));
        };
        self.step += 1;
        let odometry = scan.odometry;
        for (slot, p) in self.particles.iter_mut().enumerate() {
            let mut rng = rng_for(self.seed, self.step, slot as u64);
            p.pose = sample_motion(&p.pose, &last, &odometry, o, &mut rng);
        }
        let d = odometry.relative_to(&last);
        self.travelled.0 += d.x.hypot(d.y);
        self.travelled.1 += normalize_angle(d.theta).abs();
        self.last_odometry = Some(odometry);
        if self.travelled.0 < o.linear_update && self.travelled.1 < o.angular_update {
            return None;
        }
        self.travelled = (0.0, 0.0);
        let prepared = PreparedScan::new(scan, o);
        let mut report = StepReport::default();
        for p in &mut self.particles {
            let m = self.matcher.refine(&p.map, &p.pose, &prepared, o);
            // A climb that matched nothing leaves the pose where it was
            // (then `m.pose` is that pose).
            p.pose = m.pose;
            p.log_weight += m.log_likelihood;
            p.lineage_weight += m.log_likelihood;
            report.evaluations.push(m.evaluations);
        }
        let logs: Vec<Real> = self.particles.iter().map(|p| p.log_weight).collect();
        let (weights, neff) = normalize(&logs, o.ogain);
        report.neff = neff;
        if neff < o.resample_threshold * self.particles.len() as Real {
            use rand::RngExt;
            let u = rng_for(self.seed, self.step, u64::MAX).random::<Real>();
            let picks = low_variance(&weights, u);
            self.particles =
                picks.iter().map(|&i| Particle { log_weight: 0.0, ..self.particles[i].clone() }).collect();
            report.resampled = true;
        }
        for p in &mut self.particles {
            integrate_scan(&mut p.map, &p.pose, scan, o.max_urange);
            report.tiles_cloned += p.map.take_clone_count();
            p.node =
                Arc::new(Node { stamp: scan.stamp, pose: p.pose, odometry, parent: Some(p.node.clone()) });
        }
        Some(report)
    }

    /// The first reading: every particle starts at its odometry pose with a
    /// map of that scan (one map, shared tile by tile).
    fn start(&mut self, scan: &LaserReading) -> StepReport {
        let o = &self.options;
        let mut map = TiledGrid::new(o.delta, (0.0, 0.0)).with_wall_threshold(o.occupied_threshold);
        integrate_scan(&mut map, &scan.odometry, scan, o.max_urange);
        let node =
            Arc::new(Node { stamp: scan.stamp, pose: scan.odometry, odometry: scan.odometry, parent: None });
        self.particles = (0..o.particles)
            .map(|_| Particle {
                pose: scan.odometry,
                log_weight: 0.0,
                lineage_weight: 0.0,
                map: map.clone(),
                node: node.clone(),
            })
            .collect();
        self.last_odometry = Some(scan.odometry);
        StepReport { neff: o.particles as Real, ..StepReport::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(odometry: Pose2) -> LaserReading {
        LaserReading {
            stamp: 0.0,
            ranges: vec![2.0; 10],
            angle_min: -1.0,
            angle_increment: 0.2,
            range_min: 0.0,
            range_max: 30.0,
            odometry,
            laser_offset: Pose2::IDENTITY,
        }
    }

    #[test]
    fn the_best_particle_is_the_best_lineage_even_right_after_resampling() {
        let mut f = Rbpf::new(SlamOptions { particles: 4, ..SlamOptions::default() }, 1).unwrap();
        assert!(
            f.process(&reading(Pose2::new(1.0, 2.0, 0.3))).is_some(),
            "the first reading starts the filter"
        );
        assert_eq!(f.particles().len(), 4);
        assert!(f.particles().iter().all(|p| p.pose == Pose2::new(1.0, 2.0, 0.3)));
        // As after a resampling: all current weights 0, lineages differ.
        for (i, p) in f.particles.iter_mut().enumerate() {
            p.log_weight = 0.0;
            p.lineage_weight = [-9.0, -2.0, -5.0, -7.0][i];
            p.pose = Pose2::new(i as f64, 0.0, 0.0);
        }
        assert_eq!(f.best().unwrap().pose.x, 1.0);
    }

    #[test]
    fn bad_options_are_refused() {
        let e = Rbpf::new(SlamOptions { particles: 0, ..SlamOptions::default() }, 1).unwrap_err();
        assert!(e.contains("particles"), "{e}");
    }
}
