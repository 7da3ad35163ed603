//! A generated building with one long loop: a corridor round a block of
//! rooms, and nothing across it, so the robot drives a few hundred metres
//! before it sees a place again. The world where a loop closes only after
//! the odometry has drifted tens of metres and turned through more than a
//! right angle (bad odometry, `--odometry bad`, drifts 0.5–0.8° per metre)
//! and the scan matcher's own drift along featureless stretches has added
//! up: what a loop search against the whole map must bridge. The same
//! seed gives the same building.

use rand::RngExt;
use squall_core::geometry::Real;

use squall_core::linemap::{LineMap, Segment};
use squall_core::random::stream_for_purpose;

use super::office::{CORRIDOR_WIDTH, Floor, Route, rect, wall};

/// The generated loop's world name.
pub const RING_WORLD: &str = "ring";

/// A room's door, metres (an interior door; the office's are 1 m).
const DOOR_WIDTH: Real = 0.9;

/// How deep the rooms along the corridor reach into the block, metres.
const ROOM_DEPTH: Real = 6.0;

/// One long side of the block: rooms of random widths along the wall from
/// `x0` to `x1` at height `y`, reaching `depth` metres into the block
/// (negative: downwards), each with a door onto the corridor; a stretch
/// without rooms now and then (a blank wall, a featureless corridor).
fn rooms_along(
    walls: &mut Vec<Segment>,
    rng: &mut rand_chacha::ChaCha8Rng,
    (x0, x1): (Real, Real),
    y: Real,
    depth: Real,
) {
    let back = y + depth;
    wall(walls, (x0, back), (x1, back));
    let mut x = x0;
    while x < x1 {
        let width = rng.random_range(4.0..9.0_f64).min(x1 - x);
        let end = x + width;
        if width > DOOR_WIDTH + 1.0 && rng.random_bool(0.6) {
            let door = x + rng.random_range(0.5..(width - DOOR_WIDTH - 0.5));
            wall(walls, (x, y), (door, y));
            wall(walls, (door + DOOR_WIDTH, y), (end, y));
        } else {
            wall(walls, (x, y), (end, y));
        }
        if end < x1 {
            wall(walls, (end, y), (end, back));
        }
        x = end;
    }
}

/// Generates the ring building for `seed`: a block 80–110 × 24–34 m, the
/// corridor round it `CORRIDOR_WIDTH` wide, rooms along the block's long
/// sides, pillars here and there along the outer wall, and the route round
/// and round the corridor.
pub fn ring(seed: u64) -> Floor {
    let mut rng = stream_for_purpose(seed, "ring layout");
    let cw = CORRIDOR_WIDTH;
    let (block_w, block_h) = (rng.random_range(80.0..110.0), rng.random_range(24.0..34.0));
    let (x_end, y_end) = (block_w + 2.0 * cw, block_h + 2.0 * cw);
    let mut walls = Vec::new();
    rect(&mut walls, 0.0, 0.0, x_end, y_end);
    let (bx0, by0, bx1, by1) = (cw, cw, cw + block_w, cw + block_h);
    // The block's short sides are blank walls; its long sides hold rooms.
    wall(&mut walls, (bx0, by0), (bx0, by1));
    wall(&mut walls, (bx1, by0), (bx1, by1));
    rooms_along(&mut walls, &mut rng, (bx0, bx1), by0, ROOM_DEPTH);
    rooms_along(&mut walls, &mut rng, (bx0, bx1), by1, -ROOM_DEPTH);
    // Pillars against the outer wall, far apart: between them a stretch of
    // corridor shows only its two side walls.
    let mut x = 3.0;
    while x < x_end - 3.0 {
        let y = if rng.random_bool(0.5) { 0.0 } else { y_end - 0.3 };
        rect(&mut walls, x, y, x + 0.3, y + 0.3);
        x += rng.random_range(6.0..18.0);
    }
    let (lo, hi) = (cw / 2.0, (x_end - cw / 2.0, y_end - cw / 2.0));
    let nodes = vec![(lo, lo), (hi.0, lo), hi, (lo, hi.1)];
    let edges = vec![(0, 1), (1, 2), (2, 3), (3, 0)];
    Floor { world: LineMap { walls }, nodes, edges, route: Route::RandomWalk }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_corridor_goes_round_clear_of_every_wall() {
        for seed in 0..5 {
            let floor = ring(seed);
            floor.check().unwrap();
            for &(a, b) in &floor.edges {
                assert!(floor.world.clear(floor.nodes[a], floor.nodes[b]), "seed {seed}: {a}–{b} blocked");
            }
            // One loop of at least 200 m.
            let length: Real = floor
                .edges
                .iter()
                .map(|&(a, b)| {
                    let (p, q) = (floor.nodes[a], floor.nodes[b]);
                    (q.0 - p.0).hypot(q.1 - p.1)
                })
                .sum();
            assert!(length > 200.0, "seed {seed}: {length} m");
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_building() {
        assert_eq!(ring(3).world.walls, ring(3).world.walls);
        assert_ne!(ring(3).world.walls, ring(4).world.walls);
    }
}
