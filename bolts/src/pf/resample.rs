//! Weights and selective resampling (GMapping's `normalize` and
//! `uniform_resampler`).

use crate::geometry::Real;

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

/// Low-variance (systematic) resampling: `weights.len()` indices, drawn
/// with one random offset `u` in [0, 1).
pub fn low_variance(weights: &[Real], u: Real) -> Vec<usize> {
    let n = weights.len();
    let step = 1.0 / n as Real;
    let mut out = Vec::with_capacity(n);
    let (mut i, mut cumulative) = (0, weights[0]);
    for m in 0..n {
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
            let picks = low_variance(&weights, k as f64 / 1000.0);
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
            let n = low_variance(&weights, k as f64 / 100.0).iter().filter(|&&p| p == 0).count();
            assert!((2..=3).contains(&n));
        }
    }
}
