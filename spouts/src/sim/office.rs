//! A procedurally generated office floor: corridors on a grid (so the
//! robot's routes close loops), blocks of rooms between them with doors, and
//! furniture in the rooms. The same seed gives the same floor.

use rand::RngExt;
use squall_core::geometry::Real;

use squall_core::linemap::{LineMap, Segment};
use squall_core::random::stream_for_purpose;

use crate::{Error, Result};

/// Corridor width, metres.
pub const CORRIDOR_WIDTH: Real = 2.0;
const DOOR_WIDTH: Real = 1.0;

/// How the robot chooses where to go on a floor's graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// At each node, a random next corridor (least used first): for graphs
    /// of long corridors.
    RandomWalk,
    /// Drive the shortest path to a rarely visited node, then pick another:
    /// for dense roadmaps.
    Explore,
}

/// A world with a graph of places to drive between.
#[derive(Debug, Clone)]
pub struct Floor {
    /// The walls.
    pub world: LineMap,
    /// Corridor intersections (centre points), metres.
    pub nodes: Vec<(Real, Real)>,
    /// Pairs of node indices joined by a straight, clear path.
    pub edges: Vec<(usize, usize)>,
    /// How routes are chosen.
    pub route: Route,
}

impl Floor {
    /// Checks that the floor has a node and that its edges join nodes it
    /// has: what the simulator and the people walking it index by.
    pub fn check(&self) -> Result<()> {
        if self.nodes.is_empty() {
            return Err(Error::EmptyFloor);
        }
        let nodes = self.nodes.len();
        match self.edges.iter().find(|&&(a, b)| a >= nodes || b >= nodes) {
            Some(&(a, b)) => Err(Error::EdgeOutOfRange { a, b, nodes }),
            None => Ok(()),
        }
    }

    /// Indices of the nodes joined to `node`.
    pub fn neighbours(&self, node: usize) -> impl Iterator<Item = usize> + '_ {
        self.edges.iter().filter_map(move |&(a, b)| {
            if a == node {
                Some(b)
            } else if b == node {
                Some(a)
            } else {
                None
            }
        })
    }
}

/// Pushes the wall from `a` to `b`.
pub(crate) fn wall(walls: &mut Vec<Segment>, a: (Real, Real), b: (Real, Real)) {
    walls.push(Segment { a, b });
}

/// A wall from `a` to `b` (axis-aligned) with a door gap starting `at`
/// metres from `a`.
fn wall_with_door(walls: &mut Vec<Segment>, a: (Real, Real), b: (Real, Real), at: Real) {
    let length = (b.0 - a.0).hypot(b.1 - a.1);
    let (ux, uy) = ((b.0 - a.0) / length, (b.1 - a.1) / length);
    let p = |d: Real| (a.0 + ux * d, a.1 + uy * d);
    wall(walls, a, p(at));
    wall(walls, p(at + DOOR_WIDTH), b);
}

pub(crate) fn rect(walls: &mut Vec<Segment>, x0: Real, y0: Real, x1: Real, y1: Real) {
    wall(walls, (x0, y0), (x1, y0));
    wall(walls, (x1, y0), (x1, y1));
    wall(walls, (x1, y1), (x0, y1));
    wall(walls, (x0, y1), (x0, y0));
}

/// Generates a floor of `columns` × `rows` blocks (each at least 1).
pub fn office(seed: u64, columns: usize, rows: usize) -> Floor {
    let mut rng = stream_for_purpose(seed, "office layout");
    let cw = CORRIDOR_WIDTH;
    let widths: Vec<Real> = (0..columns).map(|_| rng.random_range(7.0..11.0)).collect();
    let heights: Vec<Real> = (0..rows).map(|_| rng.random_range(6.0..9.0)).collect();
    // Left/bottom edge of corridor k.
    let edges_from = |sizes: &[Real]| {
        let mut edges = vec![0.0];
        let mut last = 0.0;
        for size in sizes {
            last = last + cw + size;
            edges.push(last);
        }
        edges
    };
    let (xs, ys) = (edges_from(&widths), edges_from(&heights));
    let (x_end, y_end) = (xs[columns] + cw, ys[rows] + cw);
    let mut walls = Vec::new();
    rect(&mut walls, 0.0, 0.0, x_end, y_end);
    for i in 0..columns {
        for j in 0..rows {
            let (x0, x1) = (xs[i] + cw, xs[i + 1]);
            let (y0, y1) = (ys[j] + cw, ys[j + 1]);
            let xm = x0 + (x1 - x0) * rng.random_range(0.4..0.6);
            // Left room: door in the bottom or top wall; right room likewise.
            let door = |rng: &mut rand_chacha::ChaCha8Rng, from: Real, to: Real| {
                rng.random_range(0.5..(to - from - DOOR_WIDTH - 0.5))
            };
            let (left_door, right_door) = (door(&mut rng, x0, xm), door(&mut rng, xm, x1));
            if rng.random_bool(0.5) {
                wall_with_door(&mut walls, (x0, y0), (xm, y0), left_door);
                wall(&mut walls, (x0, y1), (xm, y1));
            } else {
                wall(&mut walls, (x0, y0), (xm, y0));
                wall_with_door(&mut walls, (x0, y1), (xm, y1), left_door);
            }
            if rng.random_bool(0.5) {
                wall_with_door(&mut walls, (xm, y0), (x1, y0), right_door);
                wall(&mut walls, (xm, y1), (x1, y1));
            } else {
                wall(&mut walls, (xm, y0), (x1, y0));
                wall_with_door(&mut walls, (xm, y1), (x1, y1), right_door);
            }
            // Side walls; the divider has a door too.
            let side_door = rng.random_range(0.5..(y1 - y0 - DOOR_WIDTH - 0.5));
            wall_with_door(&mut walls, (x0, y0), (x0, y1), side_door);
            wall(&mut walls, (x1, y0), (x1, y1));
            wall_with_door(
                &mut walls,
                (xm, y0),
                (xm, y1),
                rng.random_range(0.5..(y1 - y0 - DOOR_WIDTH - 0.5)),
            );
            // Furniture: a box or two per room.
            for (rx0, rx1) in [(x0, xm), (xm, x1)] {
                for _ in 0..rng.random_range(1..3) {
                    let s = rng.random_range(0.5..1.0);
                    let bx = rng.random_range(rx0 + 0.6..rx1 - 0.6 - s);
                    let by = rng.random_range(y0 + 0.6..y1 - 0.6 - s);
                    rect(&mut walls, bx, by, bx + s, by + s);
                }
            }
        }
    }
    // Features along the outer corridors: pillars every few metres.
    let mut x = 3.0;
    while x < x_end - 3.0 {
        for y in [0.0, y_end - 0.3] {
            rect(&mut walls, x, y, x + 0.3, y + 0.3);
        }
        x += rng.random_range(4.0..7.0);
    }
    let mut nodes = Vec::new();
    for &y in &ys {
        for &x in &xs {
            nodes.push((x + cw / 2.0, y + cw / 2.0));
        }
    }
    let index = |i: usize, j: usize| j * (columns + 1) + i;
    let mut edges = Vec::new();
    for j in 0..=rows {
        for i in 0..=columns {
            if i < columns {
                edges.push((index(i, j), index(i + 1, j)));
            }
            if j < rows {
                edges.push((index(i, j), index(i, j + 1)));
            }
        }
    }
    Floor { world: LineMap { walls }, nodes, edges, route: Route::RandomWalk }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_floor_and_corridors_are_clear() {
        let a = office(7, 3, 2);
        assert_eq!(a.world, office(7, 3, 2).world);
        assert_ne!(a.world, office(8, 3, 2).world);
        assert_eq!(a.nodes.len(), 12);
        assert_eq!(a.edges.len(), 17);
        for &(i, j) in &a.edges {
            assert!(a.world.clear(a.nodes[i], a.nodes[j]), "corridor {i}-{j} is blocked");
        }
        // The building is closed: every ray from a corridor hits a wall.
        for k in 0..36 {
            let angle = k as f64 * std::f64::consts::PI / 18.0;
            assert!(a.world.cast(a.nodes[5], angle, 200.0).is_some());
        }
    }
}
