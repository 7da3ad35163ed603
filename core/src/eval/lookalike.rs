//! Could the sensor have told the robot's place from the one a localizer
//! chose? The test behind a missed global start or kidnapping: a
//! localizer that settles in a wrong place either lost information it had
//! (a filter's miss) or never had any (a look-alike place, which no
//! localizer could have told from the truth with that sensor in that
//! time).
//!
//! Take the rigid offset D that carries the true pose onto the estimate at
//! the time it was wrong. The "twin" path D ∘ truth is what a hypothesis at
//! the estimate follows with the same odometry. Cast the sensor's rays in
//! the map from both paths, frame by frame: a ray tells them apart when
//! its two ranges differ by more than 3σ of the sensor's range noise (at
//! least [`MAP_ERROR`]), or one meets a wall within range and the other
//! does not. A frame tells them apart when [`FRAME_SHARE`] of its rays do.
//! The map alone is compared, not the run's readings: people and boxes
//! make a reading differ from both paths, not tell them apart.

use crate::geometry::{Pose2, Real, normalize_angle};
use crate::linemap::LineMap;
use crate::trajectory::Trajectory;

/// The smallest range difference that counts, metres: a line map's own
/// error tells nothing. Maps drawn from floor plans are good to some
/// centimetres: the shared maps' rows of identical offices, 9 m apart,
/// are drawn with walls 2–4 cm (CVAP6) and 6–7 cm (CVAP7) apart from one
/// office to the next.
pub const MAP_ERROR: Real = 0.1;

/// A frame tells the places apart when this share of its rays does: one or
/// two rays grazing a wall's end differ with the few centimetres and
/// tenths of a degree by which an estimate can be right and still off.
pub const FRAME_SHARE: Real = 0.1;

/// A planar sensor's rays and range noise.
#[derive(Debug, Clone, PartialEq)]
pub struct Fan {
    /// Bearings of the rays in the sensor's frame, radians.
    pub bearings: Vec<Real>,
    /// Walls beyond this are not seen, metres.
    pub range: Real,
    /// Range noise σ(r) = `sigma` + `sigma_per_r2` · r², metres.
    pub sigma: Real,
    /// See `sigma` (a depth camera's error grows with the square of range).
    pub sigma_per_r2: Real,
}

impl Fan {
    /// `rays` bearings spread evenly over `fov` radians, centred ahead.
    pub fn even(fov: Real, rays: usize, range: Real, sigma: Real, sigma_per_r2: Real) -> Fan {
        let step = if rays > 1 { fov / (rays - 1) as Real } else { 0.0 };
        let first = if rays > 1 { -fov / 2.0 } else { 0.0 };
        Fan { bearings: (0..rays).map(|i| first + step * i as Real).collect(), range, sigma, sigma_per_r2 }
    }

    /// How far apart two ranges at about `r` must be to tell them apart.
    fn margin(&self, r: Real) -> Real {
        (3.0 * (self.sigma + self.sigma_per_r2 * r * r)).max(MAP_ERROR)
    }

    /// The rays whose ranges from `a` and from `b` tell the poses apart.
    pub fn telling_rays(&self, map: &LineMap, a: &Pose2, b: &Pose2) -> usize {
        self.bearings
            .iter()
            .filter(|&&bearing| {
                let from_a = map.cast((a.x, a.y), normalize_angle(a.theta + bearing), self.range);
                let from_b = map.cast((b.x, b.y), normalize_angle(b.theta + bearing), self.range);
                match (from_a, from_b) {
                    (None, None) => false,
                    (Some(r), None) | (None, Some(r)) => r < self.range - self.margin(r),
                    (Some(r), Some(s)) => (r - s).abs() > self.margin(r.min(s)),
                }
            })
            .count()
    }

    /// Whether a frame at `a` and one at `b` tell the poses apart.
    pub fn tells_apart(&self, map: &LineMap, a: &Pose2, b: &Pose2) -> bool {
        self.telling_rays(map, a, b) as Real >= FRAME_SHARE * self.bearings.len() as Real
    }
}

/// The true path against its twin over a window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lookalike {
    /// Seconds of the run at which the estimate was taken (wrong).
    pub at: f64,
    /// How far the estimate lay from the truth then, metres and degrees.
    pub distance_m: Real,
    /// See `distance_m`.
    pub heading_deg: Real,
    /// Frames compared (the truth's poses in the window).
    pub frames: usize,
    /// Frames that told the truth from the twin.
    pub telling_frames: usize,
}

impl Lookalike {
    /// No frame told the two places apart: a place no localizer could
    /// have told from the truth with this sensor in this time.
    pub fn is_lookalike(&self) -> bool {
        self.frames > 0 && self.telling_frames == 0
    }
}

/// Compares, over the truth's poses with stamps in `(from, to]`, the true
/// path with the twin through `estimate`'s pose at `to`. `None` when
/// either trajectory has no pose at `to`.
pub fn compare(
    map: &LineMap,
    fan: &Fan,
    estimate: &Trajectory,
    truth: &Trajectory,
    from: f64,
    to: f64,
) -> Option<Lookalike> {
    let tolerance = super::relations::STAMP_TOLERANCE;
    let (wrong, true_then) = (estimate.at(to, tolerance)?, truth.at(to, tolerance)?);
    let offset = wrong.compose(&true_then.inverse());
    let (mut frames, mut telling_frames) = (0, 0);
    for (_, pose) in truth.stamps.iter().zip(&truth.poses).filter(|(t, _)| **t > from && **t <= to) {
        frames += 1;
        telling_frames += usize::from(fan.tells_apart(map, pose, &offset.compose(pose)));
    }
    Some(Lookalike {
        at: to,
        distance_m: wrong.distance(&true_then),
        heading_deg: normalize_angle(wrong.theta - true_then.theta).to_degrees(),
        frames,
        telling_frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linemap::Segment;

    /// Two identical 3 m × 3 m rooms side by side, 10 m apart, and a third
    /// like them but with a pillar in it.
    fn rooms() -> LineMap {
        let mut walls = Vec::new();
        for x0 in [0.0, 10.0, 20.0] {
            let corners = [(x0, 0.0), (x0 + 3.0, 0.0), (x0 + 3.0, 3.0), (x0, 3.0)];
            for i in 0..4 {
                walls.push(Segment { a: corners[i], b: corners[(i + 1) % 4] });
            }
        }
        walls.push(Segment { a: (21.0, 2.0), b: (22.0, 2.0) });
        LineMap { walls }
    }

    fn path(x0: Real) -> Trajectory {
        let mut t = Trajectory::default();
        for i in 0..=10 {
            t.push(f64::from(i) * 0.1, Pose2::new(x0 + 1.0 + 0.1 * Real::from(i), 1.0, 0.5));
        }
        t
    }

    fn laser() -> Fan {
        Fan::even(std::f64::consts::PI, 181, 8.0, 0.01, 0.0)
    }

    #[test]
    fn an_identical_room_is_a_lookalike_and_one_with_a_pillar_is_not() {
        let (map, truth) = (rooms(), path(0.0));
        let twin = compare(&map, &laser(), &path(10.0), &truth, 0.0, 1.0).unwrap();
        assert_eq!((twin.frames, twin.telling_frames), (10, 0));
        assert!(twin.is_lookalike() && (twin.distance_m - 10.0).abs() < 1e-9);
        let pillar = compare(&map, &laser(), &path(20.0), &truth, 0.0, 1.0).unwrap();
        assert_eq!(pillar.telling_frames, 10, "the pillar is in view from every pose");
        assert!(!pillar.is_lookalike());
    }

    #[test]
    fn a_place_turned_round_tells_itself_apart() {
        let (map, truth) = (rooms(), path(0.0));
        let mut turned = Trajectory::default();
        for (t, p) in truth.stamps.iter().zip(&truth.poses) {
            turned.push(*t, Pose2::new(p.x, p.y, p.theta + std::f64::consts::PI));
        }
        let c = compare(&map, &laser(), &turned, &truth, 0.0, 1.0).unwrap();
        assert!(c.telling_frames > 0 && !c.is_lookalike());
    }

    #[test]
    fn a_range_difference_within_the_noise_tells_nothing() {
        let map = rooms();
        let (a, b) = (Pose2::new(1.5, 1.5, 0.0), Pose2::new(1.5 + 0.01, 1.5, 0.0));
        assert_eq!(laser().telling_rays(&map, &a, &b), 0, "1 cm is within the map's error");
        let c = Pose2::new(1.5 + 0.07, 1.5, 0.0);
        assert_eq!(laser().telling_rays(&map, &a, &c), 0, "nor 7 cm");
        let far = Pose2::new(1.5 + 0.3, 1.5, 0.0);
        assert!(laser().tells_apart(&map, &a, &far));
        // A depth camera's σ grows with the range: 0.0015 r² at 8 m is 10 cm.
        let depth = Fan::even(55f64.to_radians(), 55, 8.0, 0.0, 0.0015);
        assert!((depth.margin(8.0) - 0.288).abs() < 1e-9 && depth.margin(1.0) == MAP_ERROR);
    }

    #[test]
    fn no_pose_at_the_time_asked_is_no_comparison() {
        let (map, truth) = (rooms(), path(0.0));
        assert_eq!(compare(&map, &laser(), &path(10.0), &truth, 0.0, 5.0), None);
    }
}
