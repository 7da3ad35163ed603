//! Per-particle occupancy grids, tiled and copy-on-write.
//!
//! A cell keeps what GMapping's `PointAccumulator` keeps: how often a beam
//! ended in it (hits), how often a beam crossed or ended in it (visits), and
//! the sum of the hit points, whose mean the scan matcher compares with beam
//! end points. Cells live in square tiles shared between particles through
//! `Arc`: copying a particle's map copies tile pointers, and writing to a
//! tile clones it only if another map still shares it. The tile index is a
//! dense array that grows as the robot explores, so a lookup is two
//! indexings, with no hashing and no atomic operation.

mod cell;
mod export;
mod kernel;
mod memory;
#[cfg(test)]
mod tests;
mod tile;
mod trace;
mod wire;

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use squall_core::geometry::{Real, round_small};

pub(crate) use cell::Cell;
pub use cell::DEFAULT_WALL_THRESHOLD;
use tile::TILE_MASK;
pub(crate) use tile::{TILE_SHIFT, TILE_SIDE, Tile};
pub(crate) use wire::GridWire;
pub use wire::GridWireError;

/// Extra tiles added on a side when the index grows.
const GROWTH_SLACK: i64 = 2;

/// ⌊v⌋ as an integer, without a libm call (the build targets baseline
/// x86-64, where `f64::floor` is a function call). Exact for |v| < 2⁶³.
#[inline]
fn floor(v: Real) -> i64 {
    let t = v as i64;
    if (t as Real) > v { t - 1 } else { t }
}

/// Fraction bits of [`TiledGrid::fixed_of`]'s fixed-point positions: a
/// position is off by at most 2⁻²⁴ cells (3 nm at 5 cm cells).
pub const FIXED_BITS: u32 = 24;
const FIXED_ONE: Real = (1u64 << FIXED_BITS) as Real;

/// An occupancy grid that grows on demand; cell (0, 0) is at world
/// (`origin`), cells are `resolution` metres.
///
/// A grid that arrives from elsewhere (another process, a file) is checked
/// as it is read: a finite positive resolution, an index whose size
/// matches its dimensions, finite mean hit points, and wall and free bits
/// that agree with the cells. A grid that fails is an error, not a later
/// panic or a silently wrong match.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "GridWire", try_from = "GridWire")]
pub struct TiledGrid {
    resolution: Real,
    /// 1 / `resolution`: a cell lookup multiplies rather than divides.
    per_metre: Real,
    origin: (Real, Real),
    /// Tile coordinates of `tiles[0]`.
    tile_min: (i64, i64),
    /// Tiles per row of the index.
    tiles_wide: usize,
    tiles_high: usize,
    tiles: Vec<Option<Arc<Tile>>>,
    /// Occupancy above which a cell counts as a wall.
    wall_threshold: Real,
    /// Tiles cloned because they were shared (copy-on-write), since the
    /// counter was last taken.
    #[serde(skip)]
    clones: u64,
}

impl TiledGrid {
    /// An empty grid whose walls are cells with occupancy above
    /// [`DEFAULT_WALL_THRESHOLD`]; an error if `resolution` is not a
    /// positive number of metres.
    pub fn new(resolution: Real, origin: (Real, Real)) -> crate::Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(crate::Error::Resolution(resolution));
        }
        Ok(TiledGrid {
            resolution,
            per_metre: 1.0 / resolution,
            origin,
            tile_min: (0, 0),
            tiles_wide: 0,
            tiles_high: 0,
            tiles: Vec::new(),
            wall_threshold: DEFAULT_WALL_THRESHOLD,
            clones: 0,
        })
    }

    /// The same, with walls above `threshold` (set before any update).
    /// An error if `threshold` is not an occupancy in 0..=1, or if the grid
    /// already holds cells (their wall and free bits follow the threshold).
    pub fn with_wall_threshold(mut self, threshold: Real) -> crate::Result<Self> {
        if !(0.0..=1.0).contains(&threshold) {
            return Err(crate::Error::WallThreshold(threshold));
        }
        if !self.tiles.is_empty() {
            return Err(crate::Error::Setting(
                "the wall threshold is set before the grid holds cells".into(),
            ));
        }
        self.wall_threshold = threshold;
        Ok(self)
    }

    /// Occupancy above which a cell is a wall.
    pub fn wall_threshold(&self) -> Real {
        self.wall_threshold
    }

    /// The bytes of the tile index of a square map `side` metres wide of
    /// `resolution`-metre cells: one slot per tile, the index being dense.
    pub(crate) fn index_bytes(side: Real, resolution: Real) -> Real {
        let tiles_a_side = side / resolution / TILE_SIDE as Real;
        tiles_a_side * tiles_a_side * std::mem::size_of::<Option<Arc<Tile>>>() as Real
    }

    /// Metres per cell.
    pub fn resolution(&self) -> Real {
        self.resolution
    }

    /// The cell containing world point (`x`, `y`).
    #[inline]
    pub fn cell_of(&self, x: Real, y: Real) -> (i64, i64) {
        (floor((x - self.origin.0) * self.per_metre), floor((y - self.origin.1) * self.per_metre))
    }

    /// The position (`x`, `y`) in cells, as fixed-point numbers with
    /// [`FIXED_BITS`] fraction bits, so that a scan matcher finds a beam's
    /// cell by adding the beam's [`Self::fixed_length`]s and shifting
    /// (`>> FIXED_BITS` is a floor) rather than flooring floats per beam.
    /// `None` beyond 2³⁰ cells of the origin (tens of thousands of
    /// kilometres), where such sums could overflow.
    #[inline]
    pub fn fixed_of(&self, x: Real, y: Real) -> Option<(i64, i64)> {
        const LIMIT: Real = (1u64 << (30 + FIXED_BITS)) as Real;
        let scale = self.per_metre * FIXED_ONE;
        let (fx, fy) = ((x - self.origin.0) * scale, (y - self.origin.1) * scale);
        (fx.abs() < LIMIT && fy.abs() < LIMIT).then_some((fx as i64, fy as i64))
    }

    /// A displacement of `metres` in [`Self::fixed_of`]'s units (saturating
    /// far beyond any range a laser measures).
    #[inline]
    pub fn fixed_length(&self, metres: Real) -> i64 {
        let v = metres * self.per_metre * FIXED_ONE;
        if v.abs() < (1u64 << 50) as Real { round_small(v).1 } else { v as i64 }
    }

    fn slot(&self, tile: (i64, i64)) -> Option<usize> {
        let (i, j) = (tile.0 - self.tile_min.0, tile.1 - self.tile_min.1);
        (i >= 0 && j >= 0 && (i as usize) < self.tiles_wide && (j as usize) < self.tiles_high)
            .then(|| j as usize * self.tiles_wide + i as usize)
    }

    /// The tile holding cell `c`, if one does.
    #[inline]
    fn tile_at(&self, c: (i64, i64)) -> Option<&Tile> {
        self.slot((c.0 >> TILE_SHIFT, c.1 >> TILE_SHIFT)).and_then(|s| self.tiles[s].as_deref())
    }

    /// The cell `c`; unvisited (default) outside the explored area.
    #[inline]
    pub fn get(&self, c: (i64, i64)) -> Cell {
        match self.tile_at(c) {
            Some(t) => t.cells.get(((c.1 & TILE_MASK) as usize) * TILE_SIDE + (c.0 & TILE_MASK) as usize),
            None => Cell::default(),
        }
    }

    /// Grows the tile index so that tiles `lo..=hi` have slots.
    fn reserve(&mut self, lo: (i64, i64), hi: (i64, i64)) {
        if self.tiles_wide > 0 {
            let max =
                (self.tile_min.0 + self.tiles_wide as i64 - 1, self.tile_min.1 + self.tiles_high as i64 - 1);
            if lo.0 >= self.tile_min.0 && lo.1 >= self.tile_min.1 && hi.0 <= max.0 && hi.1 <= max.1 {
                return;
            }
        }
        let (mut new_lo, mut new_hi) = (lo, hi);
        if self.tiles_wide > 0 {
            // Grow with slack on the side that needs it, so that a robot
            // exploring does not regrow the index at every step.
            let max =
                (self.tile_min.0 + self.tiles_wide as i64 - 1, self.tile_min.1 + self.tiles_high as i64 - 1);
            let below = |need: i64, have: i64| if need < have { need - GROWTH_SLACK } else { have };
            let above = |need: i64, have: i64| if need > have { need + GROWTH_SLACK } else { have };
            new_lo = (below(lo.0, self.tile_min.0), below(lo.1, self.tile_min.1));
            new_hi = (above(hi.0, max.0), above(hi.1, max.1));
        }
        let (wide, high) = ((new_hi.0 - new_lo.0 + 1) as usize, (new_hi.1 - new_lo.1 + 1) as usize);
        let mut tiles = vec![None; wide * high];
        for j in 0..self.tiles_high {
            for i in 0..self.tiles_wide {
                let (ti, tj) = (self.tile_min.0 + i as i64 - new_lo.0, self.tile_min.1 + j as i64 - new_lo.1);
                tiles[tj as usize * wide + ti as usize] = self.tiles[j * self.tiles_wide + i].take();
            }
        }
        self.tiles = tiles;
        self.tile_min = new_lo;
        self.tiles_wide = wide;
        self.tiles_high = high;
    }

    /// Makes sure every cell in the box `lo..=hi` can be written without
    /// growing (call before a scan's updates).
    pub fn reserve_cells(&mut self, lo: (i64, i64), hi: (i64, i64)) {
        self.reserve((lo.0 >> TILE_SHIFT, lo.1 >> TILE_SHIFT), (hi.0 >> TILE_SHIFT, hi.1 >> TILE_SHIFT));
    }

    /// The tile at `slot`, created if missing, cloned first if another map
    /// shares it.
    #[inline]
    fn tile_mut(&mut self, slot: usize) -> &mut Tile {
        let entry = self.tiles[slot].get_or_insert_with(|| Arc::new(Tile::default()));
        if Arc::strong_count(entry) > 1 {
            self.clones += 1;
        }
        let tile = Arc::make_mut(entry);
        // Every write goes through here: the content is about to change.
        tile.digest.take();
        tile
    }

    /// Changes cell `c` with `f`: its tile is created, or cloned if another
    /// map shares it; the wall and free bits follow the new value. Counts
    /// past [`MAX_VISITS`] are halved, and hits kept at most visits.
    #[inline]
    pub fn update(&mut self, c: (i64, i64), f: impl FnOnce(&mut Cell)) {
        let tile = (c.0 >> TILE_SHIFT, c.1 >> TILE_SHIFT);
        let slot = match self.slot(tile) {
            Some(s) => s,
            None => {
                self.reserve(tile, tile);
                self.slot(tile).expect("reserved")
            }
        };
        let threshold = self.wall_threshold;
        self.tile_mut(slot).update((c.0 & TILE_MASK) as usize, (c.1 & TILE_MASK) as usize, threshold, f);
    }
}
