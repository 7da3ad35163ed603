//! The resampler's view of the particle set: accumulated log-weights,
//! Neff, selective resampling and the lineage tree from which the best
//! trajectory is read. It never sees a particle's state, only what the
//! matchers report: a pose and a log-likelihood per slot.

use std::sync::Arc;

use rand::RngExt;
use squall_core::geometry::{Pose2, Real};

use crate::pf::kld::Kld;
use crate::pf::model::Injection;
use crate::pf::resample::{Scheme, draw, normalize};
use squall_core::random::stream_for_step;

/// Offset of the random streams that decide injections (slot j uses
/// `INJECTION_STREAM + j`), apart from every particle's own stream.
pub const INJECTION_STREAM: u64 = 1 << 40;

/// Offset of the random streams of corrections (slot j uses
/// `CORRECTION_STREAM + j`), apart from prediction's and injection's.
pub const CORRECTION_STREAM: u64 = 1 << 41;

/// A pose a particle held at a correcting reading, linked to its
/// ancestor's.
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

impl Drop for Node {
    /// Unlinks the lineage iteratively. Dropped the default way, a chain
    /// as long as the run (one node per correcting reading) is freed one
    /// stack frame per node: a simulated run of 1.6 million readings
    /// overflowed the resampler thread's stack at its end (found by the
    /// soak bench).
    fn drop(&mut self) {
        let mut next = self.parent.take();
        while let Some(node) = next {
            match Arc::try_unwrap(node) {
                Ok(mut node) => next = node.parent.take(),
                // Another lineage still holds it (and what it leads to).
                Err(_) => break,
            }
        }
    }
}

/// What the resampler decided for one correcting reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// Neff before resampling.
    pub neff: Real,
    /// New slot j descends from old slot `parents[j]` (the identity when
    /// the set was not resampled).
    pub parents: Vec<usize>,
    /// Whether the set was resampled.
    pub resampled: bool,
    /// The slot of the best particle (highest lineage weight) after the
    /// decision.
    pub best: usize,
    /// The normalized weights before resampling, by old slot.
    pub weights: Vec<Real>,
    /// New slots to redraw at random (augmented MCL), in order.
    pub fresh: Vec<usize>,
}

/// Weights and lineage of every particle slot.
#[derive(Debug, Clone)]
pub struct Population {
    seed: u64,
    /// Log-likelihood accumulated since the last resampling.
    log_weights: Vec<Real>,
    /// Log-likelihood accumulated over the whole lineage (never reset):
    /// what "best particle" means, as in GMapping's `weightSum`.
    lineage_weights: Vec<Real>,
    nodes: Vec<Arc<Node>>,
    /// log of augmented MCL's slow and fast averages of the mean
    /// likelihood.
    averages: Option<(Real, Real)>,
    /// Particles at the start: the weights' smoothing is per particle of
    /// the starting set, so that a set KLD-sampling resizes keeps it.
    start_len: usize,
}

impl Population {
    /// One slot per pose, at the first reading.
    pub fn start(poses: &[Pose2], seed: u64, stamp: f64, odometry: Pose2) -> Self {
        let n = poses.len();
        Population {
            seed,
            log_weights: vec![0.0; n],
            lineage_weights: vec![0.0; n],
            nodes: poses.iter().map(|&pose| Arc::new(Node { stamp, pose, odometry, parent: None })).collect(),
            averages: None,
            start_len: n,
        }
    }

    /// Particles in the set.
    pub fn len(&self) -> usize {
        self.log_weights.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.log_weights.is_empty()
    }

    /// Takes the corrected reading `step` (its stamp and odometry) with
    /// each slot's refined pose and log-likelihood, in slot order: weights,
    /// Neff, resampling by `scheme` below `threshold` × N (weights smoothed
    /// by `smoothing` × N at the start), and the lineage extended by the
    /// new poses. With `kld`, a resampling draws as many particles as
    /// KLD-sampling asks for (the ring, which draws each slot from its
    /// neighbours, keeps the count).
    #[allow(clippy::too_many_arguments)]
    pub fn correct(
        &mut self,
        step: u64,
        mark: (f64, Pose2),
        reports: &[(Pose2, Real)],
        smoothing: Real,
        threshold: Real,
        scheme: Scheme,
        injection: Option<(Injection, &[Real])>,
        kld: Option<Kld>,
    ) -> crate::Result<Decision> {
        if reports.len() != self.len() {
            return Err(crate::Error::ReportCount { particles: self.len(), reports: reports.len() });
        }
        for (slot, &(_, l)) in reports.iter().enumerate() {
            self.log_weights[slot] += l;
            self.lineage_weights[slot] += l;
        }
        let share = match injection {
            Some((i, fits)) => self.injection_share(fits, i),
            None => 0.0,
        };
        let n = self.len();
        let (weights, neff) = normalize(&self.log_weights, smoothing * self.start_len as Real / n as Real);
        // The ring draws each slot from its neighbours: it keeps the count.
        let kld = kld.filter(|_| scheme != Scheme::Ring);
        // A set KLD-sampling sizes grows when the fit drops: the share to
        // redraw is of the most particles it may hold, not of the few a
        // robot already found needs, so a lost robot is searched for with
        // as many draws as a global start.
        let grown = kld
            .filter(|_| share > 0.0)
            .map(|k| ((share * k.max as Real).ceil() as usize).clamp(k.min, k.max));
        // Redrawn particles join a resampled set, whose weights start
        // equal: in a set kept as it was, a redrawn one would inherit the
        // weight its slot had gathered for another pose.
        let resampled = neff < threshold * n as Real || grown.is_some() || share > 0.0;
        let count = match kld {
            Some(k) if resampled => {
                k.count(&weights, |i| reports[i].0, self.seed, step).max(grown.unwrap_or(0))
            }
            _ => n,
        };
        let mut parents =
            if resampled { draw(scheme, &weights, self.seed, step, count) } else { (0..n).collect() };
        if resampled {
            self.avoid_lost(&mut parents);
        }
        let (stamp, odometry) = mark;
        let nodes: Vec<Arc<Node>> = parents
            .iter()
            .map(|&p| {
                let parent = Some(self.nodes[p].clone());
                Arc::new(Node { stamp, pose: reports[p].0, odometry, parent })
            })
            .collect();
        self.nodes = nodes;
        if resampled {
            self.lineage_weights = parents.iter().map(|&p| self.lineage_weights[p]).collect();
            self.log_weights = vec![0.0; parents.len()];
        }
        let fresh = match share > 0.0 {
            true => (0..self.len())
                .filter(|&j| {
                    stream_for_step(self.seed, step, INJECTION_STREAM + j as u64).random::<Real>() < share
                })
                .collect(),
            false => Vec::new(),
        };
        Ok(Decision { neff, parents, resampled, best: self.best(), weights, fresh })
    }

    /// Updates augmented MCL's averages with this reading's best fit
    /// (`fits`: each slot's log fit) and returns the share of the slots to
    /// redraw: 1 − fast/slow · e^min_drop, at least `lost_share` once that
    /// is positive, 0 while it is not; each slot drawn with that
    /// probability. The best fit, not the mean: a set spread out by a
    /// turn fits worse on average while its best particles still fit, and
    /// that is no reason to think the robot lost.
    fn injection_share(&mut self, fits: &[Real], i: Injection) -> Real {
        let best = fits.iter().copied().fold(Real::NEG_INFINITY, Real::max);
        if !best.is_finite() {
            return 0.0;
        }
        let blend = |old: Real, alpha: Real| {
            let (a, b) = ((1.0 - alpha).ln() + old, alpha.ln() + best);
            let m = a.max(b);
            m + ((a - m).exp() + (b - m).exp()).ln()
        };
        let (slow, fast) = match self.averages {
            None => (best, best),
            Some((slow, fast)) => (blend(slow, i.alpha_slow), blend(fast, i.alpha_fast)),
        };
        self.averages = Some((slow, fast));
        let share = 1.0 - (fast - slow + i.min_drop).exp();
        tracing::debug!(best, fast, slow, share, "augmented MCL");
        if share > 0.0 { share.max(i.lost_share) } else { 0.0 }
    }

    /// Replaces a lost parent (a draw can land on a weightless slot at
    /// the end of the cumulative sum) by the nearest live one before it,
    /// else after it.
    fn avoid_lost(&self, parents: &mut [usize]) {
        let live = |p: usize| self.log_weights[p] != Real::NEG_INFINITY;
        for parent in parents.iter_mut() {
            let p = *parent;
            if live(p) {
                continue;
            }
            let before = (0..p).rev().find(|&q| live(q));
            if let Some(q) = before.or_else(|| (p + 1..self.len()).find(|&q| live(q))) {
                *parent = q;
            }
        }
    }

    /// Marks `slot` lost (its state went with a process): it weighs
    /// nothing, so it is neither the best nor drawn as a parent.
    pub fn lose(&mut self, slot: usize) {
        self.log_weights[slot] = Real::NEG_INFINITY;
        self.lineage_weights[slot] = Real::NEG_INFINITY;
    }

    /// The slot with the highest lineage weight (the last of equals).
    pub fn best(&self) -> usize {
        self.lineage_weights.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(slot, _)| slot)
    }

    /// The latest node of a slot.
    pub fn node(&self, slot: usize) -> &Arc<Node> {
        &self.nodes[slot]
    }

    /// A slot's lineage weight.
    pub fn lineage_weight(&self, slot: usize) -> Real {
        self.lineage_weights[slot]
    }

    /// The best particle's corrected poses, oldest first: (stamp, pose,
    /// odometry).
    pub fn best_trajectory(&self) -> Vec<(f64, Pose2, Pose2)> {
        let mut out = Vec::new();
        let mut node = self.nodes.get(self.best()).cloned();
        while let Some(n) = node {
            out.push((n.stamp, n.pose, n.odometry));
            node = n.parent.clone();
        }
        out.reverse();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: Real) -> Pose2 {
        Pose2::new(x, 0.0, 0.0)
    }

    #[test]
    fn a_lineage_as_long_as_a_days_run_is_dropped_without_recursion() {
        // Three million readings (more than three days at 10 Hz) on a
        // thread with a 256 KiB stack: dropped recursively this overflows.
        let dropped = std::thread::Builder::new()
            .stack_size(256 << 10)
            .spawn(|| {
                let mut node = Arc::new(Node {
                    stamp: 0.0,
                    pose: Pose2::IDENTITY,
                    odometry: Pose2::IDENTITY,
                    parent: None,
                });
                for i in 1..3_000_000 {
                    let parent = Some(node);
                    node = Arc::new(Node {
                        stamp: i as f64,
                        pose: Pose2::IDENTITY,
                        odometry: Pose2::IDENTITY,
                        parent,
                    });
                }
                // A second lineage sharing the tail keeps it alive.
                let sibling = Node {
                    stamp: 0.5,
                    pose: Pose2::IDENTITY,
                    odometry: Pose2::IDENTITY,
                    parent: Some(node.clone()),
                };
                drop(node);
                assert_eq!(sibling.parent.as_ref().map(|p| p.stamp), Some(2_999_999.0));
                drop(sibling);
            })
            .unwrap()
            .join();
        assert!(dropped.is_ok());
    }

    #[test]
    fn resampling_favours_weight_and_the_lineage_follows_the_parents() {
        let mut p = Population::start(&[at(0.0); 4], 7, 0.0, at(0.0));
        let reports: Vec<(Pose2, Real)> =
            [(1.0, -900.0), (2.0, 0.0), (3.0, -900.0), (4.0, -900.0)].map(|(x, l)| (at(x), l)).to_vec();
        let d = p.correct(1, (1.0, at(1.0)), &reports, 3.0, 0.5, Scheme::LowVariance, None, None).unwrap();
        assert!(d.resampled && d.neff < 2.0, "{d:?}");
        assert_eq!(d.parents, vec![1, 1, 1, 1]);
        assert_eq!(d.best, 3, "equal lineage weights: the last slot");
        let t = p.best_trajectory();
        assert_eq!(t.iter().map(|n| n.1.x).collect::<Vec<_>>(), vec![0.0, 2.0]);
    }

    #[test]
    fn kld_sampling_resizes_the_set_and_the_lineage_follows() {
        // 400 particles over 40 places, 10 m apart: one place fits.
        let n = 400;
        let mut p = Population::start(&vec![at(0.0); n], 7, 0.0, at(0.0));
        let kld = Some(Kld::new(20, n));
        let reports: Vec<(Pose2, Real)> =
            (0..n).map(|j| (at(10.0 * (j % 40) as Real), if j % 40 == 3 { 0.0 } else { -50.0 })).collect();
        let d = p
            .correct(1, (1.0, at(1.0)), &reports, 1.0 / n as Real, 0.5, Scheme::LowVariance, None, kld)
            .unwrap();
        assert!(d.resampled);
        assert_eq!(d.parents.len(), 20, "one place found: the fewest particles");
        assert_eq!(p.len(), 20);
        assert!(d.parents.iter().all(|&j| j % 40 == 3), "{:?}", d.parents);
        assert!(p.best_trajectory().last().is_some_and(|n| n.1.x == 30.0));
        // The next reading reports for the new set; a spread set grows it
        // back, up to the most.
        let spread: Vec<(Pose2, Real)> =
            (0..20).map(|j| (Pose2::new(3.0 * j as Real, 0.0, 0.3 * j as Real), -(j as Real))).collect();
        assert!(
            p.correct(2, (2.0, at(2.0)), &reports, 1.0 / n as Real, 0.5, Scheme::LowVariance, None, kld)
                .is_err()
        );
        let d = p
            .correct(2, (2.0, at(2.0)), &spread, 1.0 / n as Real, 2.0, Scheme::LowVariance, None, kld)
            .unwrap();
        assert!(d.parents.len() > 20 && p.len() == d.parents.len(), "{}", d.parents.len());
        // Without KLD the count stays.
        let mut q = Population::start(&vec![at(0.0); n], 7, 0.0, at(0.0));
        let d = q
            .correct(1, (1.0, at(1.0)), &reports, 1.0 / n as Real, 0.5, Scheme::LowVariance, None, None)
            .unwrap();
        assert_eq!(d.parents.len(), n);
    }

    #[test]
    fn lost_slots_are_never_drawn_nor_the_best() {
        // Slot 3 was lost with its process; slot 2, the heaviest, survives.
        let mut p = Population::start(&[at(0.0); 4], 7, 0.0, at(0.0));
        p.lose(3);
        assert_ne!(p.best(), 3);
        let reports: Vec<(Pose2, Real)> = [(1.0, -5.0), (2.0, -5.0), (3.0, 0.0), (4.0, Real::NEG_INFINITY)]
            .map(|(x, l)| (at(x), l))
            .to_vec();
        // An infinite threshold forces resampling, as after a loss.
        let d = p
            .correct(1, (1.0, at(1.0)), &reports, 3.0, Real::INFINITY, Scheme::LowVariance, None, None)
            .unwrap();
        assert!(d.resampled);
        assert!(!d.parents.contains(&3), "{:?}", d.parents);
        assert_eq!(d.weights[3], 0.0);
        assert_eq!(d.parents.len(), 4);
        assert!(d.parents.contains(&2), "{:?}", d.parents);
    }

    #[test]
    fn without_resampling_weights_accumulate_and_slots_keep_their_parents() {
        let mut p = Population::start(&[at(0.0); 3], 7, 0.0, at(0.0));
        let reports = vec![(at(1.0), -1.0), (at(2.0), -1.1), (at(3.0), -1.2)];
        let d = p.correct(1, (1.0, at(1.0)), &reports, 3.0, 0.5, Scheme::LowVariance, None, None).unwrap();
        assert!(!d.resampled);
        assert_eq!((d.parents, d.best), (vec![0, 1, 2], 0));
        assert_eq!(p.lineage_weight(2), -1.2);
        let d = p
            .correct(
                2,
                (2.0, at(2.0)),
                &[(at(1.0), -5.0), (at(2.0), 0.0), (at(3.0), 0.0)],
                3.0,
                0.5,
                Scheme::LowVariance,
                None,
                None,
            )
            .unwrap();
        assert_eq!(d.best, 1);
    }

    #[test]
    fn a_spread_set_whose_best_still_fits_injects_nothing() {
        let mut p = Population::start(&[at(0.0); 100], 7, 0.0, at(0.0));
        let injection = Some(Injection { alpha_slow: 0.01, alpha_fast: 0.5, min_drop: 0.1, lost_share: 0.0 });
        let reports = vec![(at(1.0), -1.0); 100];
        for step in 1..=40 {
            // After step 10 all but a few particles fit badly.
            let fits: Vec<Real> = (0..100).map(|j| if step <= 10 || j < 5 { -0.05 } else { -0.9 }).collect();
            let d = p
                .correct(
                    step,
                    (step as f64, at(0.0)),
                    &reports,
                    1.0 / 100.0,
                    0.5,
                    Scheme::LowVariance,
                    injection.map(|i| (i, &fits[..])),
                    None,
                )
                .unwrap();
            assert!(d.fresh.is_empty(), "step {step}: {} injected", d.fresh.len());
        }
    }

    #[test]
    fn injection_starts_when_the_fit_drops_and_not_before() {
        let mut p = Population::start(&[at(0.0); 200], 7, 0.0, at(0.0));
        let injection = Some(Injection { alpha_slow: 0.01, alpha_fast: 0.5, min_drop: 0.1, lost_share: 0.0 });
        let reports = vec![(at(1.0), -1.0); 200];
        let correct = |p: &mut Population, step: u64, fit: Real| {
            let fits = vec![fit; 200];
            p.correct(
                step,
                (step as f64, at(0.0)),
                &reports,
                1.0 / 200.0,
                0.5,
                Scheme::LowVariance,
                injection.map(|i| (i, &fits[..])),
                None,
            )
            .unwrap()
            .fresh
        };
        for step in 1..=20 {
            assert!(correct(&mut p, step, -0.05).is_empty(), "a steady fit injects nothing");
        }
        // A dip within the dead band injects nothing either.
        for step in 21..=23 {
            assert!(correct(&mut p, step, -0.12).is_empty(), "a small dip injects nothing");
        }
        for step in 24..=30 {
            assert!(correct(&mut p, step, -0.05).is_empty(), "a steady fit injects nothing");
        }
        // The fit per point drops by 0.7: fast/slow falls towards e^−0.7,
        // and the share redrawn towards 1 − e^(−0.7 + 0.1).
        let mut fresh = Vec::new();
        for step in 31..=40 {
            fresh = correct(&mut p, step, -0.75);
        }
        let share = fresh.len() as Real / 200.0;
        assert!(share > 0.2 && share < 0.6, "share injected {share}");
        assert!(fresh.windows(2).all(|w| w[0] < w[1]), "fresh slots in order");
        // Deterministic: the same history picks the same slots.
        let mut q = Population::start(&[at(0.0); 200], 7, 0.0, at(0.0));
        for (step, fit) in (1..=40).zip([-0.05; 20].into_iter().chain([-0.12; 3]).chain([-0.05; 7])) {
            correct(&mut q, step, fit);
        }
        let mut again = Vec::new();
        for step in 31..=40 {
            again = correct(&mut q, step, -0.75);
        }
        assert_eq!(fresh, again);
    }

    #[test]
    fn a_lost_set_grows_to_at_least_the_lost_share_of_the_most_particles() {
        let injection = Some(Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1, lost_share: 0.5 });
        // One reading: every particle at one place, all fitting `fit`.
        let correct = |p: &mut Population, step: u64, fit: Real, kld: Option<Kld>| {
            let n = p.len();
            let (reports, fits) = (vec![(at(0.0), -1.0); n], vec![fit; n]);
            let mark = (step as f64, at(0.0));
            let scheme = Scheme::LowVariance;
            p.correct(step, mark, &reports, 1.0 / 50.0, 0.5, scheme, injection.map(|i| (i, &fits[..])), kld)
                .unwrap()
        };
        // 50 particles tracking one place, allowed up to 2000.
        let kld = Some(Kld::new(50, 2000));
        let mut p = Population::start(&[at(0.0); 50], 7, 0.0, at(0.0));
        for step in 1..=20 {
            let d = correct(&mut p, step, -0.05, kld);
            assert!(d.fresh.is_empty() && p.len() == 50, "tracking stays at 50 ({})", p.len());
        }
        // The first scan after the kidnapping: the fit drops by 2 per
        // point, fast/slow by 0.3 of that, past the dead band.
        let d = correct(&mut p, 21, -2.05, kld);
        assert!(d.resampled, "a lost set is resampled to grow");
        assert!(p.len() >= 1000, "grown to half the most particles: {}", p.len());
        let share = d.fresh.len() as Real / p.len() as Real;
        assert!((0.45..0.6).contains(&share), "at least half redrawn: {share}");
        // Without KLD-sampling the set keeps its size; the share holds.
        let mut fixed = Population::start(&[at(0.0); 50], 7, 0.0, at(0.0));
        for step in 1..=20 {
            correct(&mut fixed, step, -0.05, None);
        }
        let d = correct(&mut fixed, 21, -2.05, None);
        assert!(d.resampled, "redrawn particles join a resampled set, their weights equal");
        assert_eq!(fixed.len(), 50);
        assert!(d.fresh.len() >= 15, "about half of 50 redrawn: {}", d.fresh.len());
    }
}
