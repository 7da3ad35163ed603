//! How far a robot's odometry misjudges its turns, learned from the
//! corrections of one estimate's history (a particle's lineage).
//!
//! Robots differ by a factor of three or four here (decision 0016: over
//! half-radian turns, ACES's odometry is off by 6% RMS, Intel's by 20%,
//! MIT CSAIL's by 24%; a simulated robot's by under 1%), so no one setting
//! fits them: too narrow and a robot that misjudges its turns loses its
//! heading at the first fast turn; too wide and the particles spread where
//! the odometry was right. Every correction measures the error it corrects:
//! the heading the scan matched minus the odometry's prediction, over a
//! known amount of turning and driving since the last one.
//!
//! The model is that of [`super::MotionSpread`]: a turn's heading error is
//! systematic over the readings between two corrections, so its variance
//! grows with the square of the angle turned, `a t²`; driving's heading
//! error grows with the distance driven, here also taken as systematic
//! over the interval, `b d²` (its part is only estimated to be kept out of
//! `a`: the spread keeps GMapping's `srt` for it). The two are fitted to
//! the squared innovations by least squares, a variance-component
//! regression, from running sums: ten numbers per lineage, copied
//! with the particle, so that the estimate is a pure function of the
//! lineage and any number of tasks reproduces one task's run.
//!
//! An innovation also holds the matcher's own heading noise, twice: the
//! heading matched now and, through the pose it left, the one matched at
//! the correction before. For white matcher noise of variance σ² that
//! adds 2σ² to every squared innovation and makes successive innovations
//! correlate by −σ² (`r_k = e_k + m_k − m_{k−1}`), while the odometry's
//! errors of two intervals are independent. The lag-one covariance
//! measures σ² and the regression is fitted to what is left, so that the
//! estimate is the odometry's error alone, which is what the proposal's
//! motion model is for (the scan's information carries the matcher's;
//! what each version learned on the development logs: decision 0016).
//!
//! Until the lineage has turned enough, a prior holds the estimate: the
//! configured `turn_error`, worth [`PRIOR_TURNS`] turns of the update
//! angle. A correction that moves the heading far more than the estimate
//! allows (a loop closed by the old-map or wide search, a climb that
//! jumped to another mode) is counted at three standard deviations, not
//! its own size, so that one jump cannot teach the filter that the robot's
//! turns are wild.

use serde::{Deserialize, Serialize};

use crate::geometry::Real;

/// How many turns of the update angle the prior is worth: about a
/// minute's turning, after which a lineage's own corrections dominate.
/// (After n turns the estimate's relative standard error is about
/// √(2/n); ten turns make the prior's own worth ±45%.)
const PRIOR_TURNS: Real = 10.0;

/// Innovations beyond this many standard deviations of the estimate count
/// at this many.
const CLIP_DEVIATIONS: Real = 3.0;

/// How many pairs of successive innovations the matcher-noise estimate's
/// prior of zero is worth, so that a few chance negative products do not
/// take a share of every innovation away.
const PRIOR_PAIRS: Real = 10.0;

/// What the estimate starts from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnErrorPrior {
    /// The turn error assumed before any correction, as a share of the turn.
    pub turn_error: Real,
    /// The angle of a typical turn between corrections (the filter's
    /// update angle), radians: the prior counts ten of them.
    pub turn: Real,
    /// Heading innovations within this (radians) are never clipped: the
    /// scale below which a correction's heading is the matcher's own
    /// resolution rather than the odometry's error.
    pub resolution: Real,
}

/// Running sums of the regression `r² − 2σ² = a t² + b d²` over a
/// lineage's corrections: r the heading innovation, t the angle turned
/// (sum of the odometry's absolute turns) and d the distance driven since
/// the correction before, σ² the matcher's heading noise from the
/// innovations' lag-one covariance.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TurnErrorEstimate {
    t4: Real,
    t2d2: Real,
    d4: Real,
    t2: Real,
    d2: Real,
    r2t2: Real,
    r2d2: Real,
    /// Sum of the products of successive innovations, and their count.
    lag: Real,
    pairs: Real,
    /// The last innovation, as counted (`None` before the first).
    last: Option<Real>,
}

impl TurnErrorEstimate {
    /// The matcher's heading noise variance, rad²: minus the innovations'
    /// lag-one covariance, shrunk towards zero, never negative.
    pub fn matcher_noise(&self) -> Real {
        (-self.lag / (self.pairs + PRIOR_PAIRS)).max(0.0)
    }

    /// The two variance rates (a per radian², b per metre²) that best fit
    /// the corrections so far, less the matcher's noise, and the prior,
    /// neither negative.
    fn rates(&self, prior: &TurnErrorPrior) -> (Real, Real) {
        let pseudo = PRIOR_TURNS * prior.turn.powi(4);
        let t4 = self.t4 + pseudo;
        let noise = 2.0 * self.matcher_noise();
        let r2t2 = self.r2t2 - noise * self.t2 + pseudo * prior.turn_error * prior.turn_error;
        let r2d2 = self.r2d2 - noise * self.d2;
        let det = t4 * self.d4 - self.t2d2 * self.t2d2;
        if self.d4 > 0.0 && det > Real::EPSILON * t4 * self.d4 {
            let a = (r2t2 * self.d4 - r2d2 * self.t2d2) / det;
            let b = (r2d2 * t4 - r2t2 * self.t2d2) / det;
            if a >= 0.0 && b >= 0.0 {
                return (a, b);
            }
            if a < 0.0 {
                // All of it is driving's: one rate, fitted alone.
                return (0.0, (r2d2 / self.d4).max(0.0));
            }
        }
        ((r2t2 / t4).max(0.0), 0.0)
    }

    /// The odometry's heading error per radian turned (one standard
    /// deviation).
    pub fn turn_error(&self, prior: &TurnErrorPrior) -> Real {
        self.rates(prior).0.sqrt()
    }

    /// Adds one correction: the heading innovation `heading_error`
    /// (matched minus predicted, radians) after turning `turned` radians
    /// and driving `driven` metres.
    pub fn observe(&mut self, turned: Real, driven: Real, heading_error: Real, prior: &TurnErrorPrior) {
        if !(turned.is_finite() && driven.is_finite() && heading_error.is_finite()) {
            return;
        }
        let (a, b) = self.rates(prior);
        let (t2, d2) = (turned * turned, driven * driven);
        let variance = a * t2 + b * d2 + 2.0 * self.matcher_noise();
        let allowed = (CLIP_DEVIATIONS * CLIP_DEVIATIONS * variance + prior.resolution.powi(2)).sqrt();
        let r = heading_error.clamp(-allowed, allowed);
        let r2 = r * r;
        self.t4 += t2 * t2;
        self.t2d2 += t2 * d2;
        self.d4 += d2 * d2;
        self.t2 += t2;
        self.d2 += d2;
        self.r2t2 += r2 * t2;
        self.r2d2 += r2 * d2;
        if let Some(last) = self.last {
            self.lag += r * last;
            self.pairs += 1.0;
        }
        self.last = Some(r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::standard_normal;
    use rand::SeedableRng;

    const PRIOR: TurnErrorPrior = TurnErrorPrior { turn_error: 0.1, turn: 0.5, resolution: 0.05 };

    /// `n` corrections of a robot whose turns are off by `turn_error` per
    /// radian and whose driving adds `drive_error` radians per metre,
    /// systematic within each interval: half of them turn-triggered
    /// (0.5–0.7 rad, up to 0.3 m), half drive-triggered (1 m, up to 0.1 rad).
    fn learned(turn_error: Real, drive_error: Real, n: usize, seed: u64) -> TurnErrorEstimate {
        learned_through_a_matcher(turn_error, drive_error, 0.0, n, seed)
    }

    /// As [`learned`], each correction's heading also off by the matcher's
    /// white noise of `matcher` radians, which the pose it leaves carries
    /// into the next innovation.
    fn learned_through_a_matcher(
        turn_error: Real,
        drive_error: Real,
        matcher: Real,
        n: usize,
        seed: u64,
    ) -> TurnErrorEstimate {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut e = TurnErrorEstimate::default();
        let mut left = 0.0;
        for k in 0..n {
            let u = |rng: &mut rand_chacha::ChaCha8Rng| (standard_normal(rng).abs()).min(1.0);
            let (t, d) = if k % 2 == 0 {
                (0.5 + 0.2 * u(&mut rng), 0.3 * u(&mut rng))
            } else {
                (0.1 * u(&mut rng), 1.0)
            };
            let matched = matcher * standard_normal(&mut rng);
            let r = turn_error * t * standard_normal(&mut rng)
                + drive_error * d * standard_normal(&mut rng)
                + matched
                - left;
            left = matched;
            e.observe(t, d, r, &PRIOR);
        }
        e
    }

    #[test]
    fn without_corrections_the_prior_holds() {
        assert!((TurnErrorEstimate::default().turn_error(&PRIOR) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_lineage_learns_its_robots_turn_error() {
        for (truth, seed) in [(0.01, 1), (0.06, 2), (0.2, 3), (0.3, 4)] {
            let e = learned(truth, 0.0, 1000, seed).turn_error(&PRIOR);
            assert!((e - truth).abs() < 0.15 * truth + 0.01, "true {truth}: learned {e}");
        }
    }

    #[test]
    fn driving_heading_error_is_not_taken_for_turning() {
        // 5 cm per metre driven, turns exact: the turns' estimate stays
        // small, where a fit of turns alone would take the driving's share.
        let e = learned(0.0, 0.05, 1000, 5).turn_error(&PRIOR);
        assert!(e < 0.03, "{e}");
    }

    #[test]
    fn the_matchers_own_noise_is_not_taken_for_the_odometrys() {
        // 0.02 rad of matcher noise, twice in every innovation, is as much
        // as a 0.06 turn error over a 0.6 rad turn: taken for turning it
        // would make the estimate about 0.08.
        let e = learned_through_a_matcher(0.06, 0.0, 0.02, 2000, 8);
        let noise = e.matcher_noise();
        assert!((noise.sqrt() - 0.02).abs() < 0.003, "matcher noise {}", noise.sqrt());
        let turn_error = e.turn_error(&PRIOR);
        assert!((turn_error - 0.06).abs() < 0.008, "{turn_error}");
        // Exact odometry: nearly nothing is left for the turns.
        let exact = learned_through_a_matcher(0.0, 0.0, 0.02, 2000, 9).turn_error(&PRIOR);
        assert!(exact < 0.02, "{exact}");
    }

    #[test]
    fn one_jump_does_not_teach_wild_turns() {
        let mut e = learned(0.05, 0.0, 200, 6);
        let before = e.turn_error(&PRIOR);
        // A loop closed in one correction: the heading moves by a radian.
        e.observe(0.5, 0.2, 1.0, &PRIOR);
        let after = e.turn_error(&PRIOR);
        assert!(after < 1.2 * before, "{before} → {after}");
        // Unclipped it would have been about √(1/(200/2 · 0.5⁴ + …)) ≈ 0.4.
        assert!(after < 0.1, "{after}");
    }

    #[test]
    fn the_estimate_survives_nonsense() {
        let mut e = learned(0.1, 0.0, 50, 7);
        let before = e;
        e.observe(Real::NAN, 1.0, 0.1, &PRIOR);
        e.observe(0.5, Real::INFINITY, 0.1, &PRIOR);
        assert_eq!(e, before);
        // No motion at all: nothing to learn, nothing broken.
        e.observe(0.0, 0.0, 0.01, &PRIOR);
        assert!(e.turn_error(&PRIOR).is_finite());
    }
}
