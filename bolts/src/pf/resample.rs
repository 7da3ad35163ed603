//! Weights and resampling: GMapping's `normalize`, and three ways to draw
//! the new set — low variance over all particles (GMapping's
//! `uniform_resampler`, the default), the thesis's sparse ring graph (each
//! particle draws among itself and its two neighbours, so nothing needs
//! the global picture but the neighbours' weights), and global aggregation
//! (each particle draws independently from the whole set's cumulative
//! weights, computed once).

use rand::RngExt;
use serde::{Deserialize, Serialize};

use squall_core::geometry::Real;
use squall_core::random::stream_for_step;

/// How the new particle set is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// Systematic resampling over all particles: one random offset.
    #[default]
    LowVariance,
    /// The thesis's sparse cyclic graph: particle i draws from i−1, i, i+1.
    Ring,
    /// GraphLab-style global aggregation: one cumulative sum, then an
    /// independent draw per particle.
    Aggregation,
}

/// The parents of `count` new particles under `scheme`, with draws keyed
/// by the run seed, the reading and the particle (the ring draws one per
/// old particle, whatever `count`).
pub fn draw(scheme: Scheme, weights: &[Real], seed: u64, step: u64, count: usize) -> Vec<usize> {
    let n = weights.len();
    match scheme {
        Scheme::LowVariance => {
            let u = stream_for_step(seed, step, u64::MAX).random::<Real>();
            low_variance(weights, u, count)
        }
        Scheme::Ring => (0..n)
            .map(|i| {
                let neighbours = [(i + n - 1) % n, i, (i + 1) % n];
                let total: Real = neighbours.iter().map(|&j| weights[j]).sum();
                let beta = stream_for_step(seed, step, i as u64).random::<Real>() * total;
                let mut cumulative = 0.0;
                for &j in &neighbours {
                    cumulative += weights[j];
                    if cumulative >= beta && weights[j] > 0.0 {
                        return j;
                    }
                }
                i
            })
            .collect(),
        Scheme::Aggregation => {
            let mut cumulative = Vec::with_capacity(n);
            let mut sum = 0.0;
            for w in weights {
                sum += w;
                cumulative.push(sum);
            }
            (0..count)
                .map(|i| {
                    let beta = stream_for_step(seed, step, i as u64).random::<Real>() * sum;
                    cumulative.partition_point(|&c| c < beta).min(n - 1)
                })
                .collect()
        }
    }
}

/// Normalized weights from accumulated log-likelihoods, smoothed by
/// dividing by `ogain` × N (GMapping's `normalize`), and Neff = 1 / Σ w².
pub fn normalize(log_weights: &[Real], ogain: Real) -> (Vec<Real>, Real) {
    let n = log_weights.len();
    let gain = 1.0 / (ogain * n as Real);
    let max = log_weights.iter().copied().fold(Real::NEG_INFINITY, Real::max);
    let mut w: Vec<Real> = log_weights.iter().map(|l| (gain * (l - max)).exp()).collect();
    let sum: Real = w.iter().sum();
    w.iter_mut().for_each(|x| *x /= sum);
    let neff = 1.0 / w.iter().map(|x| x * x).sum::<Real>();
    (w, neff)
}

/// Low-variance (systematic) resampling: `count` indices into `weights`,
/// drawn with one random offset `u` in [0, 1).
pub fn low_variance(weights: &[Real], u: Real, count: usize) -> Vec<usize> {
    let n = weights.len();
    let step = 1.0 / count as Real;
    let mut out = Vec::with_capacity(count);
    let (mut i, mut cumulative) = (0, weights[0]);
    for m in 0..count {
        let target = (u + m as Real) * step;
        while target > cumulative && i + 1 < n {
            i += 1;
            cumulative += weights[i];
        }
        out.push(i);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frequencies(scheme: Scheme, weights: &[Real], runs: u64) -> Vec<Real> {
        let mut counts = vec![0usize; weights.len()];
        for step in 0..runs {
            for p in draw(scheme, weights, 3, step, weights.len()) {
                counts[p] += 1;
            }
        }
        counts.iter().map(|&c| c as Real / (runs as usize * weights.len()) as Real).collect()
    }

    #[test]
    fn aggregation_draws_in_proportion_to_weight() {
        let weights = [0.5, 0.1, 0.3, 0.1];
        let f = frequencies(Scheme::Aggregation, &weights, 5000);
        for (f, w) in f.iter().zip(weights) {
            assert!((f - w).abs() < 0.01, "{f} vs {w}");
        }
    }

    #[test]
    fn the_ring_draws_only_from_neighbours_and_favours_weight() {
        let weights = [0.0, 0.0, 0.9, 0.0, 0.0, 0.1];
        for step in 0..200 {
            let picks = draw(Scheme::Ring, &weights, 3, step, 6);
            assert_eq!(picks.len(), 6);
            for (i, &p) in picks.iter().enumerate() {
                let d = (p + 6 - i) % 6;
                assert!(d == 0 || d == 1 || d == 5, "particle {i} drew {p}, not a neighbour");
                assert!(weights[p] > 0.0 || weights[(i + 5) % 6] + weights[i] + weights[(i + 1) % 6] == 0.0);
            }
            // Particle 0 sees 5 (0.1) and 1 (0): it always takes 5.
            assert_eq!(picks[0], 5);
        }
        let f = frequencies(Scheme::Ring, &weights, 2000);
        assert!(f[2] > 0.4, "the heavy particle spreads to its neighbours: {f:?}");
    }

    #[test]
    fn low_variance_through_draw_is_the_systematic_scheme() {
        let weights = [0.25; 4];
        assert_eq!(draw(Scheme::LowVariance, &weights, 1, 1, 4), vec![0, 1, 2, 3]);
        assert_eq!(draw(Scheme::LowVariance, &weights, 1, 1, 8), vec![0, 0, 1, 1, 2, 2, 3, 3]);
    }

    #[test]
    fn equal_weights_give_full_neff() {
        let (w, neff) = normalize(&[-3.0, -3.0, -3.0, -3.0], 3.0);
        assert!(w.iter().all(|x| (x - 0.25).abs() < 1e-12));
        assert!((neff - 4.0).abs() < 1e-9);
        let (_, neff) = normalize(&[0.0, -500.0, -500.0, -500.0], 3.0);
        assert!(neff < 1.5, "one dominant particle: {neff}");
    }

    #[test]
    fn resampling_keeps_the_count_and_follows_the_weights() {
        let weights = [0.7, 0.1, 0.15, 0.05];
        let mut counts = [0usize; 4];
        for k in 0..1000 {
            let picks = low_variance(&weights, k as f64 / 1000.0, 4);
            assert_eq!(picks.len(), 4);
            assert!(picks.windows(2).all(|w| w[0] <= w[1]), "systematic picks are ordered");
            for p in picks {
                counts[p] += 1;
            }
        }
        for (c, w) in counts.iter().zip(weights) {
            assert!((*c as f64 / 4000.0 - w).abs() < 0.01, "{counts:?}");
        }
        // Low variance: a 0.7 particle is picked 2 or 3 times of 4, never 0 or 4.
        for k in 0..100 {
            let n = low_variance(&weights, k as f64 / 100.0, 4).iter().filter(|&&p| p == 0).count();
            assert!((2..=3).contains(&n));
        }
    }
}
