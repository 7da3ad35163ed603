//! The readings robots stream: laser scans with the odometry pose at their
//! stamp, and odometry alone. Every source (CARMEN logs, ROS 2 bags, the
//! simulator, live robots) emits these types, so SLAM and localization bolts
//! do not care where a reading came from.

use serde::{Deserialize, Serialize};

use crate::geometry::{Pose2, Real};

/// Checks a scan's geometry against what a laser can be: at most
/// [`MAX_BEAMS`](squall_topology::bounds::MAX_BEAMS) beams, a finite
/// first angle and step, spanning at most one turn
/// ([`MAX_SCAN_SPAN`](squall_topology::bounds::MAX_SCAN_SPAN)). Readers
/// call it on every scan they decode, so that a corrupt record (a million
/// beams over 2800 turns) is an error naming it, not work and memory
/// spent on it.
pub fn check_scan_geometry(beams: usize, angle_min: Real, angle_increment: Real) -> Result<(), String> {
    use squall_topology::bounds::{MAX_BEAMS, MAX_SCAN_SPAN};
    if beams > MAX_BEAMS {
        return Err(format!("{beams} beams: expected at most {MAX_BEAMS} (no laser has more)"));
    }
    if !(angle_min.is_finite() && angle_increment.is_finite()) {
        return Err(format!(
            "angle_min {angle_min} and angle_increment {angle_increment}: expected finite angles"
        ));
    }
    let span = angle_increment.abs() * beams.saturating_sub(1) as Real;
    if span > MAX_SCAN_SPAN {
        return Err(format!(
            "{beams} beams {angle_increment} rad apart span {:.1} turns: expected at most one turn",
            span / std::f64::consts::TAU
        ));
    }
    Ok(())
}

/// One planar laser scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LaserReading {
    /// Time of the scan, seconds (the log's or bag's own clock).
    pub stamp: f64,
    /// Ranges, metres, beam i at `angle_min + i * angle_increment` in the
    /// laser's frame. A range ≤ `range_min` or ≥ `range_max` is "no return".
    pub ranges: Vec<f32>,
    /// Angle of the first beam, radians.
    pub angle_min: Real,
    /// Angle between beams, radians.
    pub angle_increment: Real,
    /// Smallest valid range, metres.
    pub range_min: Real,
    /// Largest valid range, metres; readings at or above it are no return.
    pub range_max: Real,
    /// Odometry pose of the robot at `stamp`.
    pub odometry: Pose2,
    /// Pose of the laser in the robot's frame.
    pub laser_offset: Pose2,
}

impl LaserReading {
    /// Checks the scan's geometry against what a laser can be (see
    /// [`check_scan_geometry`]).
    pub fn check_geometry(&self) -> Result<(), String> {
        check_scan_geometry(self.ranges.len(), self.angle_min, self.angle_increment)
    }

    /// Whether beam `i` measured something.
    pub fn is_valid(&self, i: usize) -> bool {
        let r = Real::from(self.ranges[i]);
        r.is_finite() && r > self.range_min && r < self.range_max
    }

    /// Angle of beam `i` in the laser's frame.
    pub fn beam_angle(&self, i: usize) -> Real {
        self.angle_min + i as Real * self.angle_increment
    }

    /// Where beam `i` ends, in the robot's frame (whether or not it
    /// measured something: see [`Self::is_valid`]).
    pub fn end_point(&self, i: usize) -> (Real, Real) {
        let (r, a) = (Real::from(self.ranges[i]), self.beam_angle(i));
        let p = self.laser_offset.compose(&Pose2::new(r * a.cos(), r * a.sin(), 0.0));
        (p.x, p.y)
    }
}

/// An odometry pose on its own (between scans).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Time, seconds.
    pub stamp: f64,
    /// The pose.
    pub pose: Pose2,
    /// Forward velocity, m/s (0 if unknown).
    pub linear_velocity: Real,
    /// Turn rate, rad/s (0 if unknown).
    pub angular_velocity: Real,
}

/// A pose estimate at a time (e.g. a filter's output for one reading).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Time, seconds.
    pub stamp: f64,
    /// The pose.
    pub pose: Pose2,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_return_readings_are_invalid() {
        let r = LaserReading {
            stamp: 0.0,
            ranges: vec![0.0, 1.0, 50.0, 81.83, f32::NAN],
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 4.0,
            range_min: 0.0,
            range_max: 50.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::IDENTITY,
        };
        let valid: Vec<bool> = (0..5).map(|i| r.is_valid(i)).collect();
        assert_eq!(valid, [false, true, false, false, false]);
        assert!((r.beam_angle(4) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn a_beams_end_point_is_in_the_robots_frame() {
        // A laser 0.2 m ahead of the robot's centre, turned left by 90°:
        // its beam straight ahead (index 2, angle 0) ends 1 m to the
        // robot's left of the laser.
        let r = LaserReading {
            stamp: 0.0,
            ranges: vec![1.0; 5],
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 4.0,
            range_min: 0.0,
            range_max: 50.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::new(0.2, 0.0, std::f64::consts::FRAC_PI_2),
        };
        let (x, y) = r.end_point(2);
        assert!((x - 0.2).abs() < 1e-12 && (y - 1.0).abs() < 1e-12, "({x}, {y})");
        let (x, y) = r.end_point(0);
        assert!((x - 1.2).abs() < 1e-12 && y.abs() < 1e-12, "({x}, {y})");
    }
}
