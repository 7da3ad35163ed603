//! What localization matches against the map: 2-D points in the robot
//! frame with the unit normals of the surfaces they lie on, from a laser
//! scan (normals from neighbouring beams) or from plane-filtered depth
//! (points on near-horizontal planes — floor, ceiling — dropped).

use serde::{Deserialize, Serialize};

use crate::cgr::fspf::PlaneFiltered;
use squall_core::camera::CameraMount;
use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::LaserReading;

/// Points and normals seen at one instant.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Observation2d {
    /// Seconds.
    pub stamp: f64,
    /// The odometry pose then.
    pub odometry: Pose2,
    /// The sensor's position in the robot frame (rays start there).
    pub sensor: (Real, Real),
    /// Points, robot frame, metres.
    pub points: Vec<[f32; 2]>,
    /// Unit normal of each point's surface, robot frame, facing the sensor.
    pub normals: Vec<[f32; 2]>,
}

/// Neighbouring beams farther apart than this fraction of the range do
/// not define a surface.
const MAX_GAP: Real = 0.1;

impl Observation2d {
    /// The points of a laser scan's valid beams up to `max_range`, each with
    /// the normal of the line through its two neighbours (beams without two
    /// close valid neighbours are left out).
    pub fn from_laser(scan: &LaserReading, max_range: Real) -> Self {
        let n = scan.ranges.len();
        let point = |i: usize| -> Option<(Real, Real)> {
            let r = Real::from(scan.ranges[i]);
            (scan.is_valid(i) && r <= max_range).then(|| scan.end_point(i))
        };
        let sensor = (scan.laser_offset.x, scan.laser_offset.y);
        let mut out = Observation2d { stamp: scan.stamp, odometry: scan.odometry, sensor, ..Self::default() };
        for i in 1..n.saturating_sub(1) {
            let (Some(prev), Some(p), Some(next)) = (point(i - 1), point(i), point(i + 1)) else { continue };
            let range = (p.0 - sensor.0).hypot(p.1 - sensor.1);
            let gap = |q: (Real, Real)| (q.0 - p.0).hypot(q.1 - p.1);
            if gap(prev) > MAX_GAP * range || gap(next) > MAX_GAP * range {
                continue;
            }
            let (tx, ty) = (next.0 - prev.0, next.1 - prev.1);
            let norm = tx.hypot(ty);
            if norm == 0.0 {
                continue;
            }
            let (mut nx, mut ny) = (-ty / norm, tx / norm);
            if nx * (p.0 - sensor.0) + ny * (p.1 - sensor.1) > 0.0 {
                (nx, ny) = (-nx, -ny);
            }
            out.points.push([p.0 as f32, p.1 as f32]);
            out.normals.push([nx as f32, ny as f32]);
        }
        out
    }

    /// Plane-filtered depth points as seen from a camera mounted at
    /// `mount`: points whose normal is within `max_normal_tilt` radians of
    /// vertical (floor, ceiling) are dropped, the rest projected to the
    /// floor plane with their normals.
    pub fn from_plane_filtered(
        filtered: &PlaneFiltered,
        mount: &CameraMount,
        max_normal_tilt: Real,
        stamp: f64,
        odometry: Pose2,
    ) -> Self {
        let (st, ct) = (mount.tilt.sin() as f32, mount.tilt.cos() as f32);
        let (sy, cy) = (mount.yaw.sin() as f32, mount.yaw.cos() as f32);
        // Camera (x right, y down, z forward), pitched down by `tilt`, to
        // robot axes (x forward, y left, z up).
        let to_robot = |v: [f32; 3]| -> [f32; 3] {
            let (x, y, z) = (v[0], v[1], v[2]);
            let forward = z * ct - y * st;
            let down = z * st + y * ct;
            [forward, -x, -down]
        };
        let vertical = (max_normal_tilt.cos()) as f32;
        let mut out = Observation2d { stamp, odometry, sensor: (mount.x, mount.y), ..Self::default() };
        for (p, n) in filtered.points.iter().zip(&filtered.normals) {
            let n = to_robot(*n);
            if n[2].abs() >= vertical {
                continue;
            }
            let p = to_robot(*p);
            let horizontal = n[0].hypot(n[1]);
            let (nx, ny) = (n[0] / horizontal, n[1] / horizontal);
            out.points.push([mount.x as f32 + cy * p[0] - sy * p[1], mount.y as f32 + sy * p[0] + cy * p[1]]);
            out.normals.push([cy * nx - sy * ny, sy * nx + cy * ny]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_laser_facing_a_wall_gives_points_with_normals_towards_it() {
        // A wall at x = 2 seen by 61 beams over ±30°.
        let angle_min: Real = -std::f64::consts::FRAC_PI_6;
        let angle_increment: Real = std::f64::consts::FRAC_PI_3 / 60.0;
        let ranges =
            (0..61).map(|i| (2.0 / (angle_min + i as Real * angle_increment).cos()) as f32).collect();
        let scan = LaserReading {
            stamp: 1.0,
            ranges,
            angle_min,
            angle_increment,
            range_min: 0.0,
            range_max: 30.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::IDENTITY,
        };
        let o = Observation2d::from_laser(&scan, 30.0);
        assert_eq!(o.points.len(), 59, "the two end beams lack a neighbour");
        for (p, n) in o.points.iter().zip(&o.normals) {
            assert!((p[0] - 2.0).abs() < 1e-4, "{p:?}");
            assert!((n[0] + 1.0).abs() < 1e-4 && n[1].abs() < 1e-3, "{n:?} faces the sensor");
        }
    }

    #[test]
    fn depth_points_on_the_floor_are_dropped_and_walls_projected() {
        // A camera 1 m up, level, looking forward: a wall point 3 m ahead
        // (normal towards the camera) and a floor point (normal up).
        let filtered = PlaneFiltered {
            points: vec![[0.5, 0.2, 3.0], [0.0, 1.0, 2.0]],
            normals: vec![[0.0, 0.0, -1.0], [0.0, -1.0, 0.0]],
            outliers: vec![],
            iterations: 1,
            valid_pixels: 2,
        };
        let mount = CameraMount { x: 0.1, y: 0.0, height: 1.0, tilt: 0.0, yaw: 0.0 };
        let o = Observation2d::from_plane_filtered(&filtered, &mount, 0.5, 0.0, Pose2::IDENTITY);
        assert_eq!(o.points.len(), 1);
        assert!((o.points[0][0] - 3.1).abs() < 1e-6 && (o.points[0][1] + 0.5).abs() < 1e-6, "{:?}", o.points);
        assert!((o.normals[0][0] + 1.0).abs() < 1e-6, "{:?}", o.normals);
        // Tilted down by 90°: the camera looks at the floor; its forward
        // axis is then straight down and the floor's normal stays vertical.
        let down = CameraMount { tilt: std::f64::consts::FRAC_PI_2, ..mount };
        let floor =
            PlaneFiltered { points: vec![[0.0, 0.0, 1.0]], normals: vec![[0.0, 0.0, -1.0]], ..filtered };
        assert!(
            Observation2d::from_plane_filtered(&floor, &down, 0.5, 0.0, Pose2::IDENTITY).points.is_empty()
        );
    }
}
