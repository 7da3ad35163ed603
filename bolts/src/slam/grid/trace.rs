//! Beams into a grid: every cell a beam crosses gets a visit and the one it
//! ends in a hit, walked tile by tile.

use super::TiledGrid;
use super::tile::{TILE_MASK, TILE_SHIFT, TILE_SIDE};

impl TiledGrid {
    /// Adds one beam from cell `from` to cell `to`: every cell on the line
    /// before `to` gets a visit; `to` gets a hit at `end` if given, nothing
    /// otherwise (a beam cut at the usable range). The line is walked tile
    /// by tile, so each tile is looked up and made writable once per beam.
    pub fn add_beam(&mut self, from: (i64, i64), to: (i64, i64), end: Option<(f32, f32)>) {
        self.reserve_cells((from.0.min(to.0), from.1.min(to.1)), (from.0.max(to.0), from.1.max(to.1)));
        let threshold = self.wall_threshold;
        // Bresenham's line (as `LineStepper` walks it), in the coordinates
        // of the tile at hand: a step is an add, leaving the tile a compare,
        // and the end is reached after max(|dx|, |dy|) steps.
        let d = ((to.0 - from.0).abs(), -(to.1 - from.1).abs());
        let step = (if from.0 < to.0 { 1 } else { -1 }, if from.1 < to.1 { 1 } else { -1 });
        let mut err = d.0 + d.1;
        let mut remaining = d.0.max(-d.1);
        let mut c = from;
        loop {
            let key = (c.0 >> TILE_SHIFT, c.1 >> TILE_SHIFT);
            let slot = self.slot(key).expect("the beam's box is reserved");
            let tile = self.tile_mut(slot);
            let (mut x, mut y) = (c.0 & TILE_MASK, c.1 & TILE_MASK);
            loop {
                if remaining == 0 {
                    if let Some((ex, ey)) = end {
                        tile.update(x as usize, y as usize, threshold, |cell| cell.add_hit(ex, ey));
                    }
                    return;
                }
                tile.visit(y as usize * TILE_SIDE + x as usize, threshold);
                let e2 = 2 * err;
                if e2 >= d.1 {
                    err += d.1;
                    x += step.0;
                }
                if e2 <= d.0 {
                    err += d.0;
                    y += step.1;
                }
                remaining -= 1;
                if (x as u64) >= TILE_SIDE as u64 || (y as u64) >= TILE_SIDE as u64 {
                    break;
                }
            }
            c = ((key.0 << TILE_SHIFT) + x, (key.1 << TILE_SHIFT) + y);
        }
    }
}
