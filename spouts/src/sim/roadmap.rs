//! Routes through an arbitrary line map: a roadmap of free points on a grid
//! (clear of walls by a margin, and enclosed by walls so the robot stays
//! inside the building), joined to their grid neighbours when the straight
//! path between them is clear. The largest connected part is kept.

use std::collections::VecDeque;

use squall_core::geometry::Real;

use super::office::{Floor, Route};
use squall_core::linemap::LineMap;

/// Distance from point `p` to the segment `a`–`b`.
fn point_segment(p: (Real, Real), a: (Real, Real), b: (Real, Real)) -> Real {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 == 0.0 { 0.0 } else { (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0) };
    (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
}

/// Whether every wall is at least `margin` from `p`. A wall whose
/// bounding box lies farther than `margin` in x or y is passed over
/// without measuring: on a building's map nearly all of them.
fn clear_by(world: &LineMap, p: (Real, Real), margin: Real) -> bool {
    world.walls.iter().all(|w| {
        let beyond = |v: Real, a: Real, b: Real| (a.min(b) - v).max(v - a.max(b));
        beyond(p.0, w.a.0, w.b.0) > margin
            || beyond(p.1, w.a.1, w.b.1) > margin
            || point_segment(p, w.a, w.b) >= margin
    })
}

/// Rays cast round a point to tell whether walls surround it...
const RAYS: usize = 16;
/// ...and how many must hit a wall.
const RAYS_HIT: usize = 13;

/// Whether walls surround `p`: at least 13 of 16 rays hit one. Points
/// outside a building see open space over half the circle or more; points
/// inside may look out through a few gaps (doors, holes in the map).
/// Stops casting once the answer is known.
fn enclosed(world: &LineMap, p: (Real, Real), reach: Real) -> bool {
    let (mut hits, mut misses) = (0, 0);
    for k in 0..RAYS {
        match world.blocked(p, k as Real * std::f64::consts::PI / (RAYS / 2) as Real, reach) {
            true => hits += 1,
            false => misses += 1,
        }
        if hits >= RAYS_HIT || misses > RAYS - RAYS_HIT {
            break;
        }
    }
    hits >= RAYS_HIT
}

/// The most grid points a roadmap tests (each against the walls near
/// it): 1000 × 1000, a quarter of a square kilometre at the usual
/// half-metre spacing, some seconds of work.
const MAX_POINTS: usize = 1_000_000;

/// Why a map has no roadmap.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RoadmapError {
    /// No two points of the grid lie inside the walls and clear of them.
    #[error("no free space inside the walls: no two points {spacing} m apart with {margin} m clearance")]
    NoFreeSpace {
        /// The grid's spacing, metres.
        spacing: Real,
        /// The clearance asked for, metres.
        margin: Real,
    },
    /// The grid's spacing is not a positive number of metres.
    #[error("the roadmap's spacing must be a positive number of metres, got {0}")]
    Spacing(Real),
    /// The map is so large for the spacing that the grid's points cannot be
    /// counted.
    #[error("the map is too large for a roadmap with points every {0} m")]
    TooLarge(Real),
}

/// Builds a roadmap with points every `spacing` metres at least `margin`
/// metres from any wall. Errors when no free, enclosed space is found.
pub fn roadmap(world: LineMap, spacing: Real, margin: Real) -> Result<Floor, RoadmapError> {
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(RoadmapError::Spacing(spacing));
    }
    let spacing_asked = spacing;
    let (x0, y0, x1, y1) = world.bounds();
    let reach = (x1 - x0).hypot(y1 - y0);
    // Points per row and rows (the casts saturate; a map without walls has
    // inverted bounds and gets one point, which nothing encloses).
    let points = |extent: Real, spacing: Real| (extent / spacing) as usize;
    // The grid's ids must be countable and fit in a Vec.
    let fits = |n: usize| n <= isize::MAX as usize / std::mem::size_of::<usize>();
    let (mut nx, mut ny) =
        match (points(x1 - x0, spacing).checked_add(1), points(y1 - y0, spacing).checked_add(1)) {
            (Some(nx), Some(ny)) if nx.checked_mul(ny).is_some_and(fits) => (nx, ny),
            _ => return Err(RoadmapError::TooLarge(spacing)),
        };
    // A map far larger than a building (a site kilometres wide) gets a
    // coarser grid rather than hours of work: routes need no finer one.
    // Scaling the spacing by √(points / budget) brings a square site
    // within the budget at once; a long thin one (a single wall
    // kilometres long) needs a few rounds, as its short side stays one
    // point whatever the spacing.
    let mut spacing = spacing;
    while nx * ny > MAX_POINTS {
        spacing *= ((nx * ny) as Real / MAX_POINTS as Real).sqrt().max(1.01);
        (nx, ny) = (points(x1 - x0, spacing) + 1, points(y1 - y0, spacing) + 1);
    }
    if spacing != spacing_asked {
        tracing::info!(spacing, "the map is large: roadmap points every {spacing:.2} m");
    }
    let mut id = vec![usize::MAX; nx * ny];
    let mut nodes = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let p = (x0 + i as Real * spacing, y0 + j as Real * spacing);
            if clear_by(&world, p, margin) && enclosed(&world, p, reach) {
                id[j * nx + i] = nodes.len();
                nodes.push(p);
            }
        }
    }
    let mut adjacency: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for j in 0..ny {
        for i in 0..nx {
            let a = id[j * nx + i];
            if a == usize::MAX {
                continue;
            }
            for (di, dj) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1)] {
                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                if ni < 0 || ni >= nx as i64 || nj >= ny as i64 {
                    continue;
                }
                let b = id[nj as usize * nx + ni as usize];
                if b == usize::MAX {
                    continue;
                }
                let mid = ((nodes[a].0 + nodes[b].0) / 2.0, (nodes[a].1 + nodes[b].1) / 2.0);
                if clear_by(&world, mid, margin) && world.clear(nodes[a], nodes[b]) {
                    adjacency[a].push(b);
                    adjacency[b].push(a);
                }
            }
        }
    }
    // Keep the largest connected component.
    let mut component = vec![usize::MAX; nodes.len()];
    let mut best = (0, 0);
    for start in 0..nodes.len() {
        if component[start] != usize::MAX {
            continue;
        }
        let mut size = 0;
        let mut queue = VecDeque::from([start]);
        component[start] = start;
        while let Some(n) = queue.pop_front() {
            size += 1;
            for &m in &adjacency[n] {
                if component[m] == usize::MAX {
                    component[m] = start;
                    queue.push_back(m);
                }
            }
        }
        if size > best.1 {
            best = (start, size);
        }
    }
    if best.1 < 2 {
        return Err(RoadmapError::NoFreeSpace { spacing, margin });
    }
    let mut new_id = vec![usize::MAX; nodes.len()];
    let mut kept = Vec::new();
    for (n, p) in nodes.iter().enumerate() {
        if component[n] == best.0 {
            new_id[n] = kept.len();
            kept.push(*p);
        }
    }
    let mut edges = Vec::new();
    for (a, list) in adjacency.iter().enumerate() {
        for &b in list {
            if a < b && new_id[a] != usize::MAX {
                edges.push((new_id[a], new_id[b]));
            }
        }
    }
    Ok(Floor { world, nodes: kept, edges, route: Route::Explore })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_closed_room_gets_an_inside_roadmap_only() {
        // A 6 × 4 m room with a 1 m wall stub; the outside is open space.
        let world = LineMap::parse("room", "0,0,6,0\n6,0,6,4\n6,4,0,4\n0,4,0,0\n3,0,3,1\n").unwrap();
        let floor = roadmap(world, 0.5, 0.4).unwrap();
        assert!(floor.nodes.len() > 20);
        assert!(floor.nodes.iter().all(|&(x, y)| x > 0.3 && x < 5.7 && y > 0.3 && y < 3.7));
        for &(a, b) in &floor.edges {
            assert!(floor.world.clear(floor.nodes[a], floor.nodes[b]));
        }
    }

    #[test]
    fn spacings_that_give_no_grid_are_errors() {
        let room = || LineMap::parse("room", "0,0,6,0\n6,0,6,4\n6,4,0,4\n0,4,0,0\n").unwrap();
        for spacing in [0.0, -1.0, Real::NAN, Real::INFINITY] {
            assert!(matches!(roadmap(room(), spacing, 0.4), Err(RoadmapError::Spacing(_))), "{spacing}");
        }
        assert_eq!(roadmap(room(), 1e-300, 0.4).unwrap_err(), RoadmapError::TooLarge(1e-300));
        assert_eq!(
            roadmap(room(), 0.5, 3.0).unwrap_err().to_string(),
            "no free space inside the walls: no two points 0.5 m apart with 3 m clearance"
        );
        let nothing = roadmap(LineMap::default(), 0.5, 0.4).unwrap_err();
        assert!(matches!(nothing, RoadmapError::NoFreeSpace { .. }), "{nothing}");
    }

    #[test]
    fn a_site_a_kilometre_wide_gets_a_coarser_grid() {
        // 2001 × 2001 points at 0.5 m: four times the budget, so points
        // every metre; every node inside, clear of the walls.
        let site =
            LineMap::parse("site", "0,0,1000,0\n1000,0,1000,1000\n1000,1000,0,1000\n0,1000,0,0\n").unwrap();
        let floor = roadmap(site, 0.5, 0.4).unwrap();
        assert!(floor.nodes.len() <= MAX_POINTS, "{} nodes", floor.nodes.len());
        assert!(floor.nodes.len() > MAX_POINTS * 9 / 10, "{} nodes", floor.nodes.len());
        let (a, b) = (floor.nodes[0], floor.nodes[1]);
        let step = (b.0 - a.0).hypot(b.1 - a.1);
        assert!((step - 1.0).abs() < 0.01, "points {step} m apart");
    }

    #[test]
    fn a_wall_ten_billion_kilometres_long_stays_within_the_budget() {
        // 2·10¹³ points in one row at 0.5 m, coarsened until the row fits
        // the budget (the fuzzer once found ids allocated for billions of
        // points: the count was taken at the spacing asked for). The wall
        // encloses nothing, so the answer is no free space.
        let wall = LineMap::parse("wall", "0,0,1e13,0\n").unwrap();
        let err = roadmap(wall, 0.5, 0.4).unwrap_err();
        assert!(matches!(err, RoadmapError::NoFreeSpace { .. }), "{err}");
    }
}
