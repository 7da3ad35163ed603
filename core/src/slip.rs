//! Wheel slip: where the wheels and the laser disagree about a step by
//! more than both their noises allow, the wheels are wrong.
//!
//! Wheels slip, spin on a threshold, or turn while a person holds the
//! robot: on FR079 the robot stands in a small room for seven seconds
//! while its odometry reports 0.55 m and −17° of motion, and the laser,
//! matched scan to scan, sees it turn +9° on the spot (as the reference
//! trajectory has it). A filter that trusts the odometry's step there
//! leaves the room 60–70° off and builds the rest of the building rotated.
//!
//! Each step between consecutive scans is measured twice: by the odometry
//! and by matching the two scans ([`crate::scan_match`]). Their difference
//! is tested against the sum of their covariances (the odometry's from the
//! motion model's noise, [`crate::motion::step_deviations`], with a floor
//! for the wheels' resolution; the match's from its fit, with a floor for
//! the laser's). Beyond χ² at 0.999 with three degrees of freedom the step
//! is a slip: it is replaced by the fusion of the two with the odometry's
//! covariance inflated, so that the laser's motion wins wherever the scans
//! constrain it and the odometry's is kept where they do not (along a
//! featureless corridor). Every later scan's odometry moves rigidly with
//! the correction, so only the slipped step changes; where no step ever
//! slips the poses are the odometry's bit for bit.
//!
//! A scan match that fails (a wrong minimum whose fit claims centimetres)
//! also looks like a slip. So a step is taken as slipped only where the
//! scans' own motion closes a cycle: the scan two back, matched to this
//! one directly, agrees with the two steps chained. A wrong match does not
//! close it; a slip the wheels made does. On ACES this removes the false
//! slips that otherwise cost 7 cm (decision 0036).

use crate::covariance::{Mat3, add, apply, inverse, quadratic};
use crate::geometry::{Pose2, Real, normalize_angle};
use crate::motion::{MotionNoise, step_deviations};
use crate::scan_match::{MeasuredStep, match_scans, match_scans_from};
use crate::sensor::LaserReading;

/// χ² with three degrees of freedom at 0.999.
const SLIP_CHI2: Real = 16.27;
/// The odometry's noise per step: GMapping's defaults, the motion model
/// SLAM samples from.
const WHEELS: MotionNoise = MotionNoise { srr: 0.1, srt: 0.2, str: 0.1, stt: 0.2 };
/// The wheels' resolution: the least deviation (m, rad) of a step.
const WHEELS_FLOOR: (Real, Real) = (0.005, 0.005);
/// The laser's: the least deviation (m, rad) of a scan match, which its
/// fit underestimates (neighbouring beams share their errors).
const MATCH_FLOOR: (Real, Real) = (0.005, 0.003);
/// How far a slipped step's odometry is still trusted: its covariance
/// times this.
const SLIPPED_INFLATION: Real = 100.0;

/// Finds and mends slipped steps in a stream of scans; see the module
/// docs.
#[derive(Debug, Default)]
pub struct SlipGuard {
    previous: Option<LaserReading>,
    /// The scan before the previous one, and the scans' motion from it to
    /// the previous.
    before: Option<(LaserReading, MeasuredStep)>,
    /// The previous scan's mended pose.
    previous_mended: Option<Pose2>,
    /// The rigid correction applied to the odometry since the first slip.
    correction: Option<Pose2>,
    slips: u64,
    steps: u64,
}

impl SlipGuard {
    /// A guard that has seen nothing.
    pub fn new() -> Self {
        SlipGuard::default()
    }

    /// `reading` with its odometry mended.
    pub fn mend(&mut self, mut reading: LaserReading) -> LaserReading {
        let raw = reading.odometry;
        let mut measured = None;
        let previous = self.previous.take();
        let mended = match (&previous, self.previous_mended) {
            (Some(previous), Some(previous_mended)) => {
                self.steps += 1;
                measured = match_scans(previous, &reading);
                let step = measured.and_then(|m| slipped_step(previous, &reading, &m));
                let step = step.filter(|_| match (&self.before, measured) {
                    (Some((before, first)), Some(second)) => consistent(before, first, &second, &reading),
                    _ => false,
                });
                match step {
                    Some(step) => {
                        self.slips += 1;
                        let mended = previous_mended.compose(&step);
                        self.correction = Some(mended.compose(&raw.inverse()));
                        mended
                    }
                    None => self.correction.map_or(raw, |c| c.compose(&raw)),
                }
            }
            _ => raw,
        };
        reading.odometry = mended;
        let mut kept = reading.clone();
        kept.odometry = raw;
        self.before = previous.zip(measured);
        self.previous = Some(kept);
        self.previous_mended = Some(mended);
        reading
    }

    /// Steps found slipped, and steps tested.
    pub fn counts(&self) -> (u64, u64) {
        (self.slips, self.steps)
    }
}

/// Whether the scans' two steps `first` (from `before` to the scan
/// between) and `second` (from it to `to`) agree with `to` matched to
/// `before` directly, from the two chained: a wrong match (a minimum a
/// door's width off) does not close this cycle, a slip the wheels made
/// does.
fn consistent(before: &LaserReading, first: &MeasuredStep, second: &MeasuredStep, to: &LaserReading) -> bool {
    let chained = first.motion.compose(&second.motion);
    let Some(direct) = match_scans_from(before, to, chained) else { return false };
    let r = direct.motion.relative_to(&chained);
    r.x.hypot(r.y) <= CYCLE.0 && normalize_angle(r.theta).abs() <= CYCLE.1
}

/// How far (m, rad) a cycle of three scan matches may fail to close: a
/// few times a match's own error.
const CYCLE: (Real, Real) = (0.02, 0.01);

/// The covariance of an odometry step `d`.
fn wheel_covariance(d: &Pose2, inflation: Real) -> Mat3 {
    let [sx, sy, st] = step_deviations(d, &WHEELS);
    let var = |s: Real, floor: Real| inflation * (s * s + floor * floor);
    [
        [var(sx, WHEELS_FLOOR.0), 0.0, 0.0],
        [0.0, var(sy, WHEELS_FLOOR.0), 0.0],
        [0.0, 0.0, var(st, WHEELS_FLOOR.1)],
    ]
}

/// The mended step from `from` to `to` if the wheels slipped; `None` if
/// they agree with the scans (or the scans do not match).
fn slipped_step(from: &LaserReading, to: &LaserReading, scans: &MeasuredStep) -> Option<Pose2> {
    let wheels = to.odometry.relative_to(&from.odometry);
    let mut laser = scans.covariance;
    laser[0][0] += MATCH_FLOOR.0 * MATCH_FLOOR.0;
    laser[1][1] += MATCH_FLOOR.0 * MATCH_FLOOR.0;
    laser[2][2] += MATCH_FLOOR.1 * MATCH_FLOOR.1;
    let m = scans.motion;
    let e = [m.x - wheels.x, m.y - wheels.y, normalize_angle(m.theta - wheels.theta)];
    let both = inverse(&add(&wheel_covariance(&wheels, 1.0), &laser))?;
    if quadratic(&both, e) <= SLIP_CHI2 {
        return None;
    }
    // Information-weighted fusion, the wheels' step barely trusted.
    let wi = inverse(&wheel_covariance(&wheels, SLIPPED_INFLATION))?;
    let li = inverse(&laser)?;
    let total = inverse(&add(&wi, &li))?;
    let wv = apply(&wi, [wheels.x, wheels.y, wheels.theta]);
    let lv = apply(&li, [m.x, m.y, wheels.theta + e[2]]);
    let fused = apply(&total, [wv[0] + lv[0], wv[1] + lv[1], wv[2] + lv[2]]);
    Some(Pose2::new(fused[0], fused[1], normalize_angle(fused[2])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan_match::room::scan_in_room;

    const HALF: (Real, Real) = (5.0, 3.0);
    const PILLARS: [(Real, Real); 2] = [(2.0, 1.0), (-2.5, -1.2)];

    /// Scans of a robot driving and turning gently along `truth`, with the
    /// odometry `odometry(k)` attached.
    fn run(truth: impl Fn(usize) -> Pose2, odometry: impl Fn(usize) -> Pose2) -> (SlipGuard, Vec<Pose2>) {
        let mut guard = SlipGuard::new();
        let mended = (0..60)
            .map(|k| guard.mend(scan_in_room(truth(k), odometry(k), HALF, &PILLARS)).odometry)
            .collect();
        (guard, mended)
    }

    fn driving(k: usize) -> Pose2 {
        Pose2::new(-2.0 + 0.03 * k as Real, 0.2 * (0.1 * k as Real).sin(), 0.2 * (0.07 * k as Real).sin())
    }

    #[test]
    fn odometry_that_agrees_with_the_scans_is_kept_bit_for_bit() {
        // Odometry 2% long and a little noisy: within its noise.
        let odometry = |k: usize| {
            Pose2::new(driving(k).x * 1.02, driving(k).y, driving(k).theta + 0.002 * (k as Real).sin())
        };
        let (guard, mended) = run(driving, odometry);
        assert_eq!(guard.counts(), (0, 59));
        assert!(mended.iter().enumerate().all(|(k, p)| *p == odometry(k)));
    }

    #[test]
    fn a_slip_is_mended_and_the_poses_after_it_move_with_it() {
        // From scan 20 to 30 the robot stands and turns +9°, while its
        // wheels report 0.4 m of travel and −17° of turning.
        let truth = |k: usize| match k {
            0..=20 => driving(k),
            21..=30 => {
                let p = driving(20);
                Pose2::new(p.x, p.y, p.theta + 9f64.to_radians() * (k - 20) as Real / 10.0)
            }
            _ => {
                let p = driving(20);
                Pose2::new(p.x, p.y, p.theta + 9f64.to_radians()).compose(&Pose2::new(
                    0.03 * (k - 30) as Real,
                    0.0,
                    0.0,
                ))
            }
        };
        let odometry = |k: usize| match k {
            0..=20 => truth(k),
            21..=30 => {
                let p = driving(20);
                let f = (k - 20) as Real / 10.0;
                p.compose(&Pose2::new(0.4 * f, 0.0, -17f64.to_radians() * f))
            }
            _ => {
                let p = driving(20).compose(&Pose2::new(0.4, 0.0, -17f64.to_radians()));
                p.compose(&Pose2::new(0.03 * (k - 30) as Real, 0.0, 0.0))
            }
        };
        let (guard, mended) = run(truth, odometry);
        let (slips, steps) = guard.counts();
        assert!((5..=10).contains(&slips), "{slips} of {steps} steps slipped");
        // The mended motion from before the slip to the end is the truth's.
        let true_motion = truth(59).relative_to(&truth(15));
        let mended_motion = mended[59].relative_to(&mended[15]);
        let raw_motion = odometry(59).relative_to(&odometry(15));
        let error =
            |m: &Pose2| (m.distance(&true_motion), normalize_angle(m.theta - true_motion.theta).abs());
        assert!(error(&raw_motion).0 > 0.3, "{:?}", error(&raw_motion));
        let (d, a) = error(&mended_motion);
        assert!(d < 0.03 && a < 0.01, "mended {d} m, {a} rad off");
    }
}
