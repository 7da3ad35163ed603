//! The odometry motion model (GMapping's `drawFromMotion`): the odometry
//! step from `old` to `new`, expressed in `old`'s frame, perturbed with
//! Gaussian noise that grows with the translation and the rotation, then
//! applied to a particle's pose.

use rand::Rng;

use serde::{Deserialize, Serialize};

use crate::covariance::{Mat3, add, diagonal, mul, symmetric, transpose};
use crate::geometry::{Pose2, Real, normalize_angle};
use crate::random::standard_normal;

mod turn_error;
pub use turn_error::{TurnErrorEstimate, TurnErrorPrior};

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

/// For `pose ⊕ d`: its Jacobian in `pose` (how an earlier error is
/// carried through the step) and in noise added to `d` (the step's own
/// error turned into the world frame).
fn step_jacobians(pose: &Pose2, d: &Pose2) -> (Mat3, Mat3) {
    let (s, c) = pose.theta.sin_cos();
    let f = [[1.0, 0.0, -(s * d.x + c * d.y)], [0.0, 1.0, c * d.x - s * d.y], [0.0, 0.0, 1.0]];
    let g = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    (f, g)
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
    let (f, g) = step_jacobians(pose, &d);
    let [sx, sy, st] = step_deviations(&d, o);
    let q = diagonal([sx * sx, sy * sy, st * st]);
    let carried = mul(&mul(&f, covariance), &transpose(&f));
    let added = mul(&mul(&g, &q), &transpose(&g));
    *covariance = symmetric(&add(&carried, &added));
    pose.compose(&d)
}

/// The standard deviations (x, y, θ) that a step's translation adds
/// (GMapping's `srr` and `srt` terms of [`step_deviations`]).
fn drive_deviations(d: &Pose2, o: &MotionNoise) -> [Real; 3] {
    let sxy = 0.3 * o.srr;
    [o.srr * d.x.abs() + sxy * d.y.abs(), o.srr * d.y.abs() + sxy * d.x.abs(), o.srt * d.x.hypot(d.y)]
}

/// The uncertainty of an odometry prediction since some pose (world frame
/// x, y, θ), with the error of turning systematic and that of driving
/// drawn afresh at every reading.
///
/// A differential drive misjudges a turn by its wheel base and by the
/// wheels' slip, which bias every reading of one turn the same way, so a
/// turn's standard deviations add over its readings: a quarter turn
/// reported in forty readings is as uncertain as one reported in one.
/// With each reading's noise drawn afresh, as GMapping's model does, it
/// would be √40 times surer, and a robot whose odometry under-reports its
/// turns by a fifth ends one many deviations off. The turn's heading error
/// is `turn_error` per radian turned, its position error `str` per radian
/// (GMapping's); the error of driving keeps GMapping's model (`srr`,
/// `srt`), whose defaults are set for it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionSpread {
    /// The turns' error: a matrix `A` that maps one standard-normal draw
    /// per component to the prediction's error (covariance `A Aᵀ`).
    pub turn: Mat3,
    /// The driving's error: its covariance.
    pub drive: Mat3,
    /// The odometry's turning since the spread began (sum of its
    /// absolute turns, radians).
    pub turned: Real,
    /// ...and its driving, metres.
    pub driven: Real,
}

impl MotionSpread {
    /// `pose` moved by the odometry step `old → new` without noise, and
    /// the spread grown by the step: the error so far carried through it
    /// (a heading error swings the translation), plus the step's own.
    pub fn propagate(
        &mut self,
        pose: &Pose2,
        old: &Pose2,
        new: &Pose2,
        o: &MotionNoise,
        turn_error: Real,
    ) -> Pose2 {
        let d = new.relative_to(old);
        let (f, g) = step_jacobians(pose, &d);
        let turn = d.theta.abs();
        let deviations = diagonal([o.str * turn, o.str * turn, turn_error * turn]);
        self.turn = add(&mul(&f, &self.turn), &mul(&g, &deviations));
        let [dx, dy, dt] = drive_deviations(&d, o);
        let carried = mul(&mul(&f, &self.drive), &transpose(&f));
        let added = mul(&mul(&g, &diagonal([dx * dx, dy * dy, dt * dt])), &transpose(&g));
        self.drive = symmetric(&add(&carried, &added));
        self.turned += turn;
        self.driven += d.x.hypot(d.y);
        pose.compose(&d)
    }

    /// The prediction's covariance.
    pub fn covariance(&self) -> Mat3 {
        symmetric(&add(&mul(&self.turn, &transpose(&self.turn)), &self.drive))
    }
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

    /// The covariances of `total` reported in `n` readings: by
    /// [`MotionSpread`] with GMapping's `stt` as the turn error, and by
    /// [`propagate_motion`].
    fn spread_over(total: &Pose2, n: usize, o: &MotionNoise) -> (Mat3, Mat3) {
        let start = Pose2::new(1.0, 2.0, 0.4);
        let step = Pose2::new(total.x / n as Real, total.y / n as Real, total.theta / n as Real);
        let odometry: Vec<Pose2> =
            (0..=n).scan(start, |p, _| Some(std::mem::replace(p, p.compose(&step)))).collect();
        let (mut spread, mut cov, mut pose) = (MotionSpread::default(), ZERO, start);
        for w in odometry.windows(2) {
            propagate_motion(&pose, &mut cov, &w[0], &w[1], o);
            pose = spread.propagate(&pose, &w[0], &w[1], o, o.stt);
        }
        (spread.covariance(), cov)
    }

    #[test]
    fn a_turns_spread_does_not_depend_on_how_often_odometry_arrives() {
        let quarter = Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let [_, _, st] = step_deviations(&quarter, &GMAPPING);
        let (once, _) = spread_over(&quarter, 1, &GMAPPING);
        let (forty, fresh) = spread_over(&quarter, 40, &GMAPPING);
        assert!((once[2][2].sqrt() - st).abs() < 1e-12, "one reading: the step's σθ");
        assert!((forty[2][2].sqrt() - st).abs() < 1e-9, "forty readings: {}", forty[2][2].sqrt());
        // Each reading's noise drawn afresh: √40 times surer.
        assert!((fresh[2][2].sqrt() * 40f64.sqrt() - st).abs() < 1e-9);
    }

    #[test]
    fn driving_straight_keeps_gmappings_model() {
        let drive = Pose2::new(2.0, 0.0, 0.0);
        for n in [1, 40] {
            let (spread, cov) = spread_over(&drive, n, &GMAPPING);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((spread[i][j] - cov[i][j]).abs() < 1e-12, "n {n} ({i},{j})");
                }
            }
        }
    }

    #[test]
    fn a_turns_heading_error_swings_a_later_drive() {
        // A turn, then a noiseless drive of 3 m: across the drive, the
        // turn's 0.1 m plus 3 m times its 0.2 rad.
        let turn_only = MotionNoise { srr: 0.0, srt: 0.0, str: 0.1, stt: 0.0 };
        let turn = (Pose2::new(0.0, 0.0, 0.0), Pose2::new(0.0, 0.0, 1.0));
        let drive = (turn.1, turn.1.compose(&Pose2::new(3.0, 0.0, 0.0)));
        let mut spread = MotionSpread::default();
        let p = spread.propagate(&Pose2::new(0.0, 0.0, 0.0), &turn.0, &turn.1, &turn_only, 0.2);
        spread.propagate(&p, &drive.0, &drive.1, &turn_only, 0.2);
        let cov = spread.covariance();
        let (s, c) = 1f64.sin_cos();
        let across = (s * s * cov[0][0] - 2.0 * s * c * cov[0][1] + c * c * cov[1][1]).sqrt();
        assert!((across - (0.1f64.powi(2) + 0.6f64.powi(2)).sqrt()).abs() < 1e-9, "{across}");
    }
}
