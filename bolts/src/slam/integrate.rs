//! Adding a scan to a grid (GMapping's `registerScan`): every cell a beam
//! crosses gets a visit; the cell where it ends gets a visit, a hit and the
//! end point. Beams at or beyond the laser's range limit, or at zero, are no
//! returns and are skipped; beams longer than the usable range are cut there
//! and mark free space only.

use crate::slam::grid::TiledGrid;
use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::LaserReading;

/// Adds `scan`, taken with the robot at `robot` (world frame), to `grid`,
/// using beams up to `usable_range` metres. Returns the beams used.
pub(crate) fn integrate_scan(
    grid: &mut TiledGrid,
    robot: &Pose2,
    scan: &LaserReading,
    usable_range: Real,
) -> usize {
    let laser = robot.compose(&scan.laser_offset);
    let start = grid.cell_of(laser.x, laser.y);
    let mut used = 0;
    for (i, &r) in scan.ranges.iter().enumerate() {
        if !scan.is_valid(i) {
            continue;
        }
        let (range, cut) =
            if Real::from(r) > usable_range { (usable_range, true) } else { (Real::from(r), false) };
        let angle = laser.theta + scan.beam_angle(i);
        let end = (laser.x + range * angle.cos(), laser.y + range * angle.sin());
        let end_cell = grid.cell_of(end.0, end.1);
        grid.add_beam(start, end_cell, (!cut).then_some((end.0 as f32, end.1 as f32)));
        used += 1;
    }
    used
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(ranges: Vec<f32>, angle_min: Real, increment: Real) -> LaserReading {
        LaserReading {
            stamp: 0.0,
            ranges,
            angle_min,
            angle_increment: increment,
            range_min: 0.0,
            range_max: 50.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::IDENTITY,
        }
    }

    #[test]
    fn a_beam_frees_its_path_and_marks_its_end() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
        // Robot at (0.05, 0.05) facing +x; one beam straight ahead, 1.03 m.
        let robot = Pose2::new(0.05, 0.05, 0.0);
        assert_eq!(integrate_scan(&mut g, &robot, &scan(vec![1.03], 0.0, 0.0), 30.0), 1);
        for x in 0..10 {
            let c = g.get((x, 0));
            assert_eq!((c.visits, c.hits), (1, 0), "cell {x} is free");
        }
        let end = g.get((10, 0));
        assert_eq!((end.visits, end.hits), (1, 1));
        let (mx, my) = end.mean().unwrap();
        assert!((mx - 1.08).abs() < 1e-6 && (my - 0.05).abs() < 1e-6, "{mx} {my}");
        assert_eq!(g.get((11, 0)).visits, 0, "nothing beyond the end");
    }

    #[test]
    fn no_returns_are_skipped_and_long_beams_only_free_space() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
        let robot = Pose2::new(0.05, 0.05, 0.0);
        // 50.0 = the range limit (no return), 0 = invalid, 3.0 > usable 2.0.
        let s = scan(vec![50.0, 0.0, 3.0], 0.0, std::f64::consts::FRAC_PI_2);
        assert_eq!(integrate_scan(&mut g, &robot, &s, 2.0), 1);
        // Only the third beam (pointing −x... at angle π) was used, cut at 2 m.
        let hits: u32 = (-30..30).map(|x| g.get((x, 0)).hits).sum();
        assert_eq!(hits, 0, "a cut beam marks no hit");
        assert_eq!(g.get((-19, 0)).visits, 1);
        assert_eq!(g.get((1, 0)).visits, 0, "the no-return beam along +x left nothing");
    }

    #[test]
    fn the_laser_offset_moves_the_beams() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
        let mut s = scan(vec![0.5], 0.0, 0.0);
        s.laser_offset = Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        integrate_scan(&mut g, &Pose2::new(0.05, 0.05, 0.0), &s, 30.0);
        assert_eq!(g.get((0, 5)).hits, 1, "a laser turned 90° looks along +y");
    }
}
