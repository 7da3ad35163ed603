//! The odometry motion model (GMapping's `drawFromMotion`): the odometry
//! step from `old` to `new`, expressed in `old`'s frame, perturbed with
//! Gaussian noise that grows with the translation and the rotation, then
//! applied to a particle's pose.

use rand::Rng;

use serde::{Deserialize, Serialize};

use crate::covariance::{Mat3, add, diagonal, mul, symmetric, transpose};
use crate::geometry::{Pose2, Real, normalize_angle};
use crate::random::standard_normal;

/// The motion model's noise: how much translation and rotation error one
/// metre of travel and one radian of turning add (GMapping's srr, srt, str,
/// stt).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionNoise {
    /// Translation noise per metre of translation.
    pub srr: Real,
    /// Rotation noise per metre of translation.
    pub srt: Real,
    /// Translation noise per radian of rotation.
    pub str: Real,
    /// Rotation noise per radian of rotation.
    pub stt: Real,
}

/// The standard deviations (x, y, θ) of the noise the model adds to an
/// odometry step `d` (in the earlier pose's frame): each grows with the
/// step's translation and rotation, as in GMapping (the sideways term is
/// `0.3 · srr`).
pub fn step_deviations(d: &Pose2, o: &MotionNoise) -> [Real; 3] {
    let sxy = 0.3 * o.srr;
    [
        o.srr * d.x.abs() + o.str * d.theta.abs() + sxy * d.y.abs(),
        o.srr * d.y.abs() + o.str * d.theta.abs() + sxy * d.x.abs(),
        o.stt * d.theta.abs() + o.srt * d.x.hypot(d.y),
    ]
}

/// `pose` moved by the odometry step `old → new`, with noise.
pub fn sample_motion<R: Rng + ?Sized>(
    pose: &Pose2,
    old: &Pose2,
    new: &Pose2,
    o: &MotionNoise,
    rng: &mut R,
) -> Pose2 {
    let d = new.relative_to(old);
    let [sx, sy, st] = step_deviations(&d, o);
    let x = d.x + standard_normal(rng) * sx;
    let y = d.y + standard_normal(rng) * sy;
    let theta = d.theta + standard_normal(rng) * st;
    pose.compose(&Pose2::new(x, y, normalize_angle(theta)))
}

/// `pose` moved by the odometry step `old → new` without noise, and
/// `covariance` (world frame, x, y, θ) grown by the step: the earlier
/// uncertainty carried through the step (a heading error swings the
/// translation) plus the step's own noise ([`step_deviations`]) turned
/// into the world frame. Over many steps this is the spread of
/// [`sample_motion`]'s draws, to first order.
pub fn propagate_motion(
    pose: &Pose2,
    covariance: &mut Mat3,
    old: &Pose2,
    new: &Pose2,
    o: &MotionNoise,
) -> Pose2 {
    let d = new.relative_to(old);
    let (s, c) = pose.theta.sin_cos();
    // ∂(pose ⊕ d)/∂pose and ∂(pose ⊕ (d + n))/∂n.
    let f = [[1.0, 0.0, -(s * d.x + c * d.y)], [0.0, 1.0, c * d.x - s * d.y], [0.0, 0.0, 1.0]];
    let g = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    let [sx, sy, st] = step_deviations(&d, o);
    let q = diagonal([sx * sx, sy * sy, st * st]);
    let carried = mul(&mul(&f, covariance), &transpose(&f));
    let added = mul(&mul(&g, &q), &transpose(&g));
    *covariance = symmetric(&add(&carried, &added));
    pose.compose(&d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::covariance::ZERO;
    use rand::SeedableRng;

    /// GMapping's default noise (srr 0.1, srt 0.2, str 0.1, stt 0.2).
    const GMAPPING: MotionNoise = MotionNoise { srr: 0.1, srt: 0.2, str: 0.1, stt: 0.2 };

    #[test]
    fn samples_have_the_model_mean_and_spread() {
        let o = GMAPPING;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let (old, new) =
            (Pose2::new(2.0, 1.0, 0.5), Pose2::new(2.0, 1.0, 0.5).compose(&Pose2::new(1.0, 0.0, 0.2)));
        let start = Pose2::new(-3.0, 4.0, 1.0);
        let n = 20_000;
        let samples: Vec<Pose2> = (0..n).map(|_| sample_motion(&start, &old, &new, &o, &mut rng)).collect();
        let local: Vec<Pose2> = samples.iter().map(|s| s.relative_to(&start)).collect();
        let mean = |f: fn(&Pose2) -> f64| local.iter().map(f).sum::<f64>() / n as f64;
        let sd = |f: fn(&Pose2) -> f64, m: f64| {
            (local.iter().map(|p| (f(p) - m).powi(2)).sum::<f64>() / n as f64).sqrt()
        };
        let (mx, my, mt) = (mean(|p| p.x), mean(|p| p.y), mean(|p| p.theta));
        assert!((mx - 1.0).abs() < 0.01 && my.abs() < 0.01 && (mt - 0.2).abs() < 0.01, "{mx} {my} {mt}");
        // σx = srr·1 + str·0.2 = 0.12; σy = str·0.2 + 0.3·srr·1 = 0.05; σθ = stt·0.2 + srt·1 = 0.24.
        // (x and y mix slightly with θ after composing; loose bounds.)
        assert!((sd(|p| p.x, mx) - 0.12).abs() < 0.01, "{}", sd(|p| p.x, mx));
        assert!((sd(|p| p.theta, mt) - 0.24).abs() < 0.01, "{}", sd(|p| p.theta, mt));
    }

    #[test]
    fn no_motion_no_noise() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let p = Pose2::new(1.0, 2.0, 3.0);
        let o = Pose2::new(5.0, 5.0, 0.1);
        let moved = sample_motion(&p, &o, &o, &GMAPPING, &mut rng);
        assert!(moved.distance(&p) < 1e-12 && (moved.theta - p.theta).abs() < 1e-12, "{moved:?}");
    }

    #[test]
    fn propagated_covariance_is_the_spread_of_the_draws() {
        // Ten steps of 0.15 m with a slight turn: the heading noise of the
        // early steps swings the later translation sideways.
        let step = Pose2::new(0.15, 0.0, 0.03);
        let odometry: Vec<Pose2> = (0..=10)
            .scan(Pose2::new(0.0, 0.0, 0.3), |p, _| Some(std::mem::replace(p, p.compose(&step))))
            .collect();
        let start = Pose2::new(1.0, -2.0, 0.7);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 20_000;
        let ends: Vec<Pose2> = (0..n)
            .map(|_| {
                odometry.windows(2).fold(start, |p, w| sample_motion(&p, &w[0], &w[1], &GMAPPING, &mut rng))
            })
            .collect();
        let (mut cov, mut mean) = (ZERO, start);
        for w in odometry.windows(2) {
            mean = propagate_motion(&mean, &mut cov, &w[0], &w[1], &GMAPPING);
        }
        let v = |p: &Pose2| [p.x - mean.x, p.y - mean.y, normalize_angle(p.theta - mean.theta)];
        for i in 0..3 {
            for j in 0..3 {
                let sampled = ends.iter().map(|p| v(p)[i] * v(p)[j]).sum::<Real>() / n as Real;
                let scale = (cov[i][i] * cov[j][j]).sqrt();
                assert!((sampled - cov[i][j]).abs() < 0.08 * scale, "({i},{j}): {sampled} vs {}", cov[i][j]);
            }
        }
        let m = |k: usize| ends.iter().map(|p| v(p)[k]).sum::<Real>() / n as Real;
        assert!(m(0).abs() < 0.01 && m(1).abs() < 0.01 && m(2).abs() < 0.01);
    }
}
