//! Synthetic scenes for the SLAM unit tests: a room, scans of it without
//! noise, and maps built from them.

use crate::slam::grid::TiledGrid;
use crate::slam::integrate::integrate_scan;
use squall_core::geometry::Pose2;
use squall_core::linemap::LineMap;
use squall_core::sensor::LaserReading;

/// A scan of `world` from `pose` (no noise), 360 beams over 360°.
pub(super) fn scan_of(world: &LineMap, pose: &Pose2) -> LaserReading {
    let n = 360;
    let inc = 2.0 * std::f64::consts::PI / n as f64;
    let ranges = (0..n)
        .map(|i| world.cast((pose.x, pose.y), pose.theta + i as f64 * inc, 20.0).map_or(30.0, |r| r as f32))
        .collect();
    LaserReading {
        stamp: 0.0,
        ranges,
        angle_min: 0.0,
        angle_increment: inc,
        range_min: 0.0,
        range_max: 30.0,
        odometry: *pose,
        laser_offset: Pose2::IDENTITY,
    }
}

/// An L-shaped room with a pillar: no direction is featureless.
pub(super) fn room() -> LineMap {
    LineMap::parse(
        "room",
        "0,0,8,0\n8,0,8,3\n8,3,5,3\n5,3,5,6\n5,6,0,6\n0,6,0,0\n2,2,2.5,2\n2.5,2,2.5,2.5\n2.5,2.5,2,2.5\n2,2.5,2,2\n",
    )
    .unwrap()
}

/// `world` mapped (5 cm cells) from `poses`, scans without noise.
pub(super) fn mapped(world: &LineMap, poses: &[Pose2]) -> TiledGrid {
    let mut g = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    for p in poses {
        integrate_scan(&mut g, p, &scan_of(world, p), 20.0);
    }
    g
}
