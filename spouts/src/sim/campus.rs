//! A generated open site: a 320 × 220 m fenced campus with a few buildings
//! and scattered posts (trees, lamp posts) between them. Most of a long
//! laser's beams meet nothing or a distant wall, so scan matching is
//! weakly constrained: the world where a matcher must trust the motion
//! model along the directions the scan cannot pin down. The same seed
//! gives the same site.

use rand::RngExt;
use squall_core::geometry::Real;
use squall_core::linemap::{LineMap, Segment};
use squall_core::random::stream_for_purpose;

use super::office::{Floor, rect};
use super::roadmap::{RoadmapError, roadmap};

/// The site's extent in x and y, metres.
pub const SITE: (Real, Real) = (320.0, 220.0);

/// The laser range the campus is meant for, metres: outdoor scanners
/// reach 80 m.
pub const CAMPUS_RANGE: Real = 80.0;

/// The robot's top speed on the campus, m/s: a brisk walk, so that ten
/// minutes cover about 860 m (seed 1) and cross earlier paths.
pub const CAMPUS_SPEED: Real = 1.5;

/// Roadmap spacing on the campus, metres: coarser than indoors, where the
/// free space is large.
const SPACING: Real = 2.0;
/// Clearance from walls and posts, metres.
const MARGIN: Real = 1.5;

/// Buildings are placed one per cell of a 4 × 3 grid, where a cell gets
/// one.
const CELLS: (usize, usize) = (4, 3);

/// Generates the campus for `seed`.
pub fn campus(seed: u64) -> Result<Floor, RoadmapError> {
    let mut rng = stream_for_purpose(seed, "campus layout");
    let mut walls: Vec<Segment> = Vec::new();
    rect(&mut walls, 0.0, 0.0, SITE.0, SITE.1);
    let cell = (SITE.0 / CELLS.0 as Real, SITE.1 / CELLS.1 as Real);
    let mut buildings = Vec::new();
    for i in 0..CELLS.0 {
        for j in 0..CELLS.1 {
            if !rng.random_bool(0.6) {
                continue;
            }
            let (w, h) = (rng.random_range(15.0..40.0), rng.random_range(12.0..30.0));
            // At least 12 m of street on every side of the cell.
            let x0 = i as Real * cell.0 + rng.random_range(12.0..(cell.0 - w - 12.0));
            let y0 = j as Real * cell.1 + rng.random_range(12.0..(cell.1 - h - 12.0));
            rect(&mut walls, x0, y0, x0 + w, y0 + h);
            buildings.push((x0, y0, x0 + w, y0 + h));
        }
    }
    // Posts: 0.5 m squares at least 4 m from buildings and the fence.
    let near_building = |x: Real, y: Real| {
        buildings.iter().any(|&(x0, y0, x1, y1)| x > x0 - 4.0 && x < x1 + 4.0 && y > y0 - 4.0 && y < y1 + 4.0)
    };
    let mut posts = 0;
    while posts < 60 {
        let (x, y) = (rng.random_range(4.0..SITE.0 - 4.0), rng.random_range(4.0..SITE.1 - 4.0));
        if near_building(x, y) {
            continue;
        }
        rect(&mut walls, x - 0.25, y - 0.25, x + 0.25, y + 0.25);
        posts += 1;
    }
    roadmap(LineMap { walls }, SPACING, MARGIN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_campus_is_large_open_and_drivable() {
        let a = campus(3).unwrap();
        assert_eq!(a.world, campus(3).unwrap().world);
        assert_ne!(a.world, campus(4).unwrap().world);
        let (x0, y0, x1, y1) = a.world.bounds();
        assert!(x1 - x0 >= 300.0 && y1 - y0 >= 200.0, "{:?}", a.world.bounds());
        // Few walls: the fence, a dozen buildings at most, 60 posts.
        assert!(a.world.walls.len() <= 4 + 4 * 12 + 4 * 60);
        // The roadmap spans the site, outside the buildings.
        let spread = |f: fn(&(Real, Real)) -> Real| {
            let v: Vec<Real> = a.nodes.iter().map(f).collect();
            v.iter().cloned().fold(Real::MIN, Real::max) - v.iter().cloned().fold(Real::MAX, Real::min)
        };
        assert!(spread(|p| p.0) > 300.0 && spread(|p| p.1) > 200.0);
        for &(i, j) in a.edges.iter().take(500) {
            assert!(a.world.clear(a.nodes[i], a.nodes[j]));
        }
    }
}
