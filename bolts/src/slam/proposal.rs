//! GMapping's improved proposal (Grisetti, Stachniss & Burgard 2007), in
//! closed form: the scan's likelihood around the matched pose, as a
//! Gaussian with the scan's information matrix, times the motion model's
//! Gaussian around the odometry's prediction. A particle's new pose is
//! drawn from the product, and its weight gains the product's integral.
//!
//! What this buys over taking the matched pose: along a direction the scan
//! cannot pin down (a long corridor, open space), the information is near
//! zero and the pose follows the odometry, not wherever the climb drifted;
//! where both constrain, each counts by its certainty; and a match that
//! strays far from the odometry, where the odometry is sure, weighs less.

use rand::Rng;
use squall_core::covariance::{
    IDENTITY, Mat3, add, apply, cholesky, determinant, diagonal, inverse, mul, quadratic,
};
use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::random::standard_normal;

/// Variance added to the motion's covariance so that it can be inverted
/// when the robot has barely moved (m², rad²): a millimetre, a few
/// hundredths of a degree.
const MOTION_FLOOR: Real = 1e-6;

/// A particle's draw from the proposal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Drawn {
    /// The new pose.
    pub pose: Pose2,
    /// The proposal's mean.
    pub mean: Pose2,
    /// The log of the proposal's normaliser beyond the likelihood at the
    /// matched pose: how well odometry and scan agree (≤ 0 up to the
    /// determinant term).
    pub log_agreement: Real,
}

/// Where a particle's climb starts: `predicted` with the motion's noise
/// (covariance `motion`, world frame x, y, θ) drawn, so that relatives
/// explore different modes.
pub(crate) fn noisy_start<R: Rng + ?Sized>(predicted: &Pose2, motion: &Mat3, rng: &mut R) -> Pose2 {
    let e = [standard_normal(rng), standard_normal(rng), standard_normal(rng)];
    let n = apply(&cholesky(&add(motion, &diagonal([MOTION_FLOOR; 3]))), e);
    Pose2::new(predicted.x + n[0], predicted.y + n[1], normalize_angle(predicted.theta + n[2]))
}

/// Draws a pose from the product of the scan's Gaussian (mean `matched`,
/// information `information`, world frame x, y, θ) and the motion's
/// (mean `predicted`, covariance `motion`).
pub(crate) fn draw<R: Rng + ?Sized>(
    matched: &Pose2,
    information: &Mat3,
    predicted: &Pose2,
    motion: &Mat3,
    rng: &mut R,
) -> Drawn {
    let motion = add(motion, &diagonal([MOTION_FLOOR; 3]));
    let prior = inverse(&motion).expect("a covariance plus a positive floor is invertible");
    let posterior = inverse(&add(information, &prior)).expect("positive definite");
    let offset =
        [predicted.x - matched.x, predicted.y - matched.y, normalize_angle(predicted.theta - matched.theta)];
    let shift = apply(&mul(&posterior, &prior), offset);
    let l = cholesky(&posterior);
    let e = [standard_normal(rng), standard_normal(rng), standard_normal(rng)];
    let noise = apply(&l, e);
    let centre = [matched.x + shift[0], matched.y + shift[1], matched.theta + shift[2]];
    let mean = Pose2::new(centre[0], centre[1], normalize_angle(centre[2]));
    let pose = Pose2::new(centre[0] + noise[0], centre[1] + noise[1], normalize_angle(centre[2] + noise[2]));
    // ∫ exp(−½ (x − m)ᵀ H (x − m)) N(x; p, Σ) dx
    //   = |I + ΣH|^(−½) exp(−½ dᵀ H (I + ΣH)⁻¹ d), d = p − m,
    // which holds for a singular H (a direction the scan cannot see).
    let coupled = add(&IDENTITY, &mul(&motion, information));
    let log_agreement = match inverse(&coupled) {
        Some(inv) => -0.5 * determinant(&coupled).ln() - 0.5 * quadratic(&mul(information, &inv), offset),
        None => 0.0,
    };
    Drawn { pose, mean, log_agreement }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use squall_core::covariance::ZERO;

    fn diag(a: Real, b: Real, c: Real) -> Mat3 {
        diagonal([a, b, c])
    }

    fn draws(information: &Mat3, motion: &Mat3) -> (Vec<Drawn>, Pose2, Pose2) {
        let matched = Pose2::new(1.0, 2.0, 0.3);
        let predicted = Pose2::new(1.2, 1.9, 0.25);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        (
            (0..20_000).map(|_| draw(&matched, information, &predicted, motion, &mut rng)).collect(),
            matched,
            predicted,
        )
    }

    fn mean(d: &[Drawn], f: fn(&Pose2) -> Real) -> Real {
        d.iter().map(|d| f(&d.pose)).sum::<Real>() / d.len() as Real
    }

    #[test]
    fn where_the_scan_is_blind_the_pose_follows_the_odometry() {
        // A corridor along x: the scan pins y and θ hard, x not at all.
        let (d, matched, predicted) = draws(&diag(0.0, 1e6, 1e6), &diag(0.01, 0.01, 0.01));
        assert!((mean(&d, |p| p.x) - predicted.x).abs() < 0.003, "{}", mean(&d, |p| p.x));
        assert!((mean(&d, |p| p.y) - matched.y).abs() < 0.001);
        assert!((mean(&d, |p| p.theta) - matched.theta).abs() < 0.001);
        let sd_x =
            (d.iter().map(|d| (d.pose.x - predicted.x).powi(2)).sum::<Real>() / d.len() as Real).sqrt();
        assert!((sd_x - 0.1).abs() < 0.005, "the motion's spread along the corridor: {sd_x}");
    }

    #[test]
    fn each_counts_by_its_certainty() {
        // Equal certainty in x: the mean halfway; the spread 1/√2 of each.
        let (d, matched, predicted) = draws(&diag(100.0, 100.0, 100.0), &diag(0.01, 0.01, 0.01));
        let half = (matched.x + predicted.x) / 2.0;
        assert!((mean(&d, |p| p.x) - half).abs() < 0.003, "{} vs {half}", mean(&d, |p| p.x));
        let sd = (d.iter().map(|d| (d.pose.x - half).powi(2)).sum::<Real>() / d.len() as Real).sqrt();
        assert!((sd - 0.1 / 2f64.sqrt()).abs() < 0.003, "{sd}");
    }

    /// One draw with matched pose (1, 2, 0.3) and a fixed stream.
    fn draw_once(information: &Mat3, predicted: &Pose2, motion: &Mat3) -> Drawn {
        let matched = Pose2::new(1.0, 2.0, 0.3);
        draw(&matched, information, predicted, motion, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1))
    }

    #[test]
    fn disagreement_where_both_are_sure_costs_weight() {
        let (sure, tight) = (diag(1e4, 1e4, 1e4), diag(1e-4, 1e-4, 1e-4));
        let agree = draw_once(&sure, &Pose2::new(1.0, 2.0, 0.3), &tight);
        let apart = draw_once(&sure, &Pose2::new(1.1, 2.0, 0.3), &tight);
        // d = 0.1 m with a combined variance of 2·10⁻⁴ m²: 25 nats.
        assert!((agree.log_agreement - apart.log_agreement - 25.0).abs() < 0.5, "{agree:?} {apart:?}");
        // A blind scan learns nothing: no cost, the motion's draw.
        let blind = draw_once(&ZERO, &Pose2::new(5.0, 5.0, 1.0), &ZERO);
        assert_eq!(blind.log_agreement, 0.0);
        assert!(blind.pose.distance(&Pose2::new(5.0, 5.0, 1.0)) < 0.01);
    }
}
