//! The odometry motion model (GMapping's `drawFromMotion`): the odometry
//! step from `old` to `new`, expressed in `old`'s frame, perturbed with
//! Gaussian noise that grows with the translation and the rotation, then
//! applied to a particle's pose.

use rand::Rng;

use serde::{Deserialize, Serialize};

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

/// `pose` moved by the odometry step `old → new`, with noise.
pub fn sample_motion<R: Rng + ?Sized>(
    pose: &Pose2,
    old: &Pose2,
    new: &Pose2,
    o: &MotionNoise,
    rng: &mut R,
) -> Pose2 {
    let d = new.relative_to(old);
    let sxy = 0.3 * o.srr;
    let x = d.x + standard_normal(rng) * (o.srr * d.x.abs() + o.str * d.theta.abs() + sxy * d.y.abs());
    let y = d.y + standard_normal(rng) * (o.srr * d.y.abs() + o.str * d.theta.abs() + sxy * d.x.abs());
    let theta = d.theta + standard_normal(rng) * (o.stt * d.theta.abs() + o.srt * d.x.hypot(d.y));
    pose.compose(&Pose2::new(x, y, normalize_angle(theta)))
}

#[cfg(test)]
mod tests {
    use super::*;
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
}
