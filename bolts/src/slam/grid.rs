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

use std::sync::Arc;

use crate::geometry::Real;

/// Cells per tile side is `1 << TILE_SHIFT`.
pub const TILE_SHIFT: u32 = 5;
/// Cells per tile side.
pub const TILE_SIDE: usize = 1 << TILE_SHIFT;
const TILE_MASK: i64 = TILE_SIDE as i64 - 1;
/// Extra tiles added on a side when the index grows.
const GROWTH_SLACK: i64 = 2;

/// ⌊v⌋ as an integer, without a libm call (the build targets baseline
/// x86-64, where `f64::floor` is a function call). Exact for |v| < 2⁶³.
#[inline]
fn floor(v: Real) -> i64 {
    let t = v as i64;
    if (t as Real) > v { t - 1 } else { t }
}

/// What one cell has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Cell {
    /// Sum of the x of the beam end points in this cell, metres.
    pub sum_x: f32,
    /// Sum of their y, metres.
    pub sum_y: f32,
    /// Beams that ended here.
    pub hits: u32,
    /// Beams that crossed or ended here.
    pub visits: u32,
}

impl Cell {
    /// Occupancy probability (hits / visits); `None` if never visited.
    pub fn occupancy(&self) -> Option<Real> {
        (self.visits > 0).then(|| Real::from(self.hits) / Real::from(self.visits))
    }

    /// Mean of the hit points, if any beam ended here.
    pub fn mean(&self) -> Option<(Real, Real)> {
        (self.hits > 0).then(|| {
            let n = Real::from(self.hits);
            (Real::from(self.sum_x) / n, Real::from(self.sum_y) / n)
        })
    }
}

/// A square block of cells, with one bit per cell saying whether it is a
/// wall (so the scan matcher can skip the many cells that are not without
/// reading them).
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    cells: Box<[Cell; TILE_SIDE * TILE_SIDE]>,
    /// Bit x of `walls[y]`: cell (x, y) of the tile is a wall.
    walls: [u32; TILE_SIDE],
}

impl Default for Tile {
    fn default() -> Self {
        Tile { cells: Box::new([Cell::default(); TILE_SIDE * TILE_SIDE]), walls: [0; TILE_SIDE] }
    }
}

/// Bytes one tile occupies.
pub const TILE_BYTES: usize = std::mem::size_of::<Cell>() * TILE_SIDE * TILE_SIDE + 4 * TILE_SIDE;

/// Occupancy above which a cell is a wall, unless set otherwise.
pub const DEFAULT_WALL_THRESHOLD: Real = 0.1;

impl Cell {
    /// Whether hits/visits exceeds `threshold` (compared without dividing).
    #[inline]
    pub fn is_wall(&self, threshold: Real) -> bool {
        self.visits > 0 && Real::from(self.hits) > threshold * Real::from(self.visits)
    }
}

/// An occupancy grid that grows on demand; cell (0, 0) is at world
/// (`origin`), cells are `resolution` metres.
#[derive(Debug, Clone)]
pub struct TiledGrid {
    resolution: Real,
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
    clones: u64,
}

impl TiledGrid {
    /// An empty grid whose walls are cells with occupancy above
    /// [`DEFAULT_WALL_THRESHOLD`].
    pub fn new(resolution: Real, origin: (Real, Real)) -> Self {
        TiledGrid {
            resolution,
            origin,
            tile_min: (0, 0),
            tiles_wide: 0,
            tiles_high: 0,
            tiles: Vec::new(),
            wall_threshold: DEFAULT_WALL_THRESHOLD,
            clones: 0,
        }
    }

    /// The same, with walls above `threshold` (set before any update).
    ///
    /// # Panics
    /// If the grid already holds cells.
    pub fn with_wall_threshold(mut self, threshold: Real) -> Self {
        assert!(self.tiles.is_empty(), "the wall threshold is set before the grid holds cells");
        self.wall_threshold = threshold;
        self
    }

    /// Occupancy above which a cell is a wall.
    pub fn wall_threshold(&self) -> Real {
        self.wall_threshold
    }

    /// Metres per cell.
    pub fn resolution(&self) -> Real {
        self.resolution
    }

    /// The cell containing world point (`x`, `y`).
    #[inline]
    pub fn cell_of(&self, x: Real, y: Real) -> (i64, i64) {
        (floor((x - self.origin.0) / self.resolution), floor((y - self.origin.1) / self.resolution))
    }

    fn slot(&self, tile: (i64, i64)) -> Option<usize> {
        let (i, j) = (tile.0 - self.tile_min.0, tile.1 - self.tile_min.1);
        (i >= 0 && j >= 0 && (i as usize) < self.tiles_wide && (j as usize) < self.tiles_high)
            .then(|| j as usize * self.tiles_wide + i as usize)
    }

    /// The cell `c`; unvisited (default) outside the explored area.
    #[inline]
    pub fn get(&self, c: (i64, i64)) -> Cell {
        let tile = (c.0 >> TILE_SHIFT, c.1 >> TILE_SHIFT);
        match self.slot(tile).and_then(|s| self.tiles[s].as_deref()) {
            Some(t) => t.cells[((c.1 & TILE_MASK) as usize) * TILE_SIDE + (c.0 & TILE_MASK) as usize],
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

    /// Changes cell `c` with `f`: its tile is created, or cloned if another
    /// map shares it; the wall bit follows the new value.
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
        let entry = self.tiles[slot].get_or_insert_with(|| Arc::new(Tile::default()));
        if Arc::strong_count(entry) > 1 {
            self.clones += 1;
        }
        let tile = Arc::make_mut(entry);
        let (x, y) = ((c.0 & TILE_MASK) as usize, (c.1 & TILE_MASK) as usize);
        let cell = &mut tile.cells[y * TILE_SIDE + x];
        f(cell);
        if cell.is_wall(threshold) {
            tile.walls[y] |= 1 << x;
        } else {
            tile.walls[y] &= !(1 << x);
        }
    }

    /// Calls `visit(cell, value)` for the walls within `k` cells of
    /// `centre`, column by column (x outer, y inner), reading only the wall
    /// bits of the others.
    #[inline]
    pub fn for_each_wall_in_square(
        &self,
        centre: (i64, i64),
        k: i64,
        mut visit: impl FnMut((i64, i64), Cell),
    ) {
        let (lo, hi) = ((centre.0 - k, centre.1 - k), (centre.0 + k, centre.1 + k));
        let tile = (lo.0 >> TILE_SHIFT, lo.1 >> TILE_SHIFT);
        if (hi.0 >> TILE_SHIFT, hi.1 >> TILE_SHIFT) == tile {
            let Some(t) = self.slot(tile).and_then(|s| self.tiles[s].as_deref()) else { return };
            for x in lo.0..=hi.0 {
                let bx = (x & TILE_MASK) as usize;
                for y in lo.1..=hi.1 {
                    let by = (y & TILE_MASK) as usize;
                    if t.walls[by] >> bx & 1 == 1 {
                        visit((x, y), t.cells[by * TILE_SIDE + bx]);
                    }
                }
            }
        } else {
            for x in lo.0..=hi.0 {
                for y in lo.1..=hi.1 {
                    let cell = self.get((x, y));
                    if cell.is_wall(self.wall_threshold) {
                        visit((x, y), cell);
                    }
                }
            }
        }
    }

    /// Tiles cloned by copy-on-write since the last call.
    pub fn take_clone_count(&mut self) -> u64 {
        std::mem::take(&mut self.clones)
    }

    /// Tiles this grid holds (shared or not).
    pub fn tile_count(&self) -> usize {
        self.tiles.iter().filter(|t| t.is_some()).count()
    }

    /// Distinct tiles over several grids (shared tiles counted once), and
    /// their bytes: the memory the maps really take.
    pub fn distinct_tiles<'a>(grids: impl IntoIterator<Item = &'a TiledGrid>) -> (usize, usize) {
        let mut seen = std::collections::HashSet::new();
        for g in grids {
            for t in g.tiles.iter().flatten() {
                seen.insert(Arc::as_ptr(t));
            }
        }
        (seen.len(), seen.len() * TILE_BYTES)
    }

    /// The explored area's cell bounds (min, max), if any tile exists.
    pub fn cell_bounds(&self) -> Option<((i64, i64), (i64, i64))> {
        let mut lo = (i64::MAX, i64::MAX);
        let mut hi = (i64::MIN, i64::MIN);
        for j in 0..self.tiles_high {
            for i in 0..self.tiles_wide {
                if self.tiles[j * self.tiles_wide + i].is_some() {
                    let t = (self.tile_min.0 + i as i64, self.tile_min.1 + j as i64);
                    lo = (lo.0.min(t.0 << TILE_SHIFT), lo.1.min(t.1 << TILE_SHIFT));
                    hi = (hi.0.max(((t.0 + 1) << TILE_SHIFT) - 1), hi.1.max(((t.1 + 1) << TILE_SHIFT) - 1));
                }
            }
        }
        (lo.0 <= hi.0).then_some((lo, hi))
    }
}

impl TiledGrid {
    /// The explored area as an occupancy grid message: occupancy in percent
    /// for visited cells, unknown elsewhere.
    pub fn to_occupancy(&self) -> crate::map::OccupancyGrid {
        let Some((lo, hi)) = self.cell_bounds() else {
            return crate::map::OccupancyGrid::unknown(0, 0, self.resolution, self.origin);
        };
        let (width, height) = ((hi.0 - lo.0 + 1) as usize, (hi.1 - lo.1 + 1) as usize);
        let corner =
            (self.origin.0 + lo.0 as Real * self.resolution, self.origin.1 + lo.1 as Real * self.resolution);
        let mut grid = crate::map::OccupancyGrid::unknown(width, height, self.resolution, corner);
        for y in 0..height {
            for x in 0..width {
                if let Some(p) = self.get((lo.0 + x as i64, lo.1 + y as i64)).occupancy() {
                    grid.set(x, y, (p * 100.0).round() as i8);
                }
            }
        }
        grid
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_anywhere_grow_the_grid() {
        let mut g = TiledGrid::new(0.05, (0.0, 0.0));
        for c in [(0, 0), (-1, -1), (100, -300), (-5000, 7000)] {
            g.update(c, |cell| cell.hits += 3);
        }
        for c in [(0, 0), (-1, -1), (100, -300), (-5000, 7000)] {
            assert_eq!(g.get(c).hits, 3, "{c:?}");
        }
        assert_eq!(g.get((1, 1)), Cell::default());
        assert_eq!(g.get((1_000_000, 0)), Cell::default());
        assert_eq!(g.tile_count(), 4);
        assert_eq!(g.cell_of(-0.01, 0.06), (-1, 1));
    }

    #[test]
    fn copies_share_tiles_until_written() {
        let mut a = TiledGrid::new(0.1, (0.0, 0.0));
        for x in 0..100 {
            a.update((x, 0), |c| c.visits += 1);
        }
        assert_eq!(a.take_clone_count(), 0);
        let mut b = a.clone();
        assert_eq!(TiledGrid::distinct_tiles([&a, &b]).0, 4, "a copy shares every tile");
        b.update((5, 0), |c| c.hits += 1);
        assert_eq!(b.take_clone_count(), 1, "one write clones one tile");
        b.update((6, 0), |c| c.hits += 1);
        assert_eq!(b.take_clone_count(), 0, "the clone is now b's own");
        assert_eq!(TiledGrid::distinct_tiles([&a, &b]).0, 5);
        assert_eq!(a.get((5, 0)).hits, 0, "the original is untouched");
        assert_eq!(b.get((5, 0)).hits, 1);
    }

    #[test]
    fn exports_the_explored_area() {
        let mut g = TiledGrid::new(0.5, (10.0, 20.0));
        g.update((1, 2), |c| *c = Cell { sum_x: 0.0, sum_y: 0.0, hits: 1, visits: 4 });
        g.update((-1, 0), |c| c.visits = 2);
        let o = g.to_occupancy();
        assert_eq!((o.width, o.height), (64, 32), "two tiles side by side");
        assert_eq!(o.origin, (10.0 - 32.0 * 0.5, 20.0));
        let (x, y) = o.cell_of(10.75, 21.25).unwrap();
        assert_eq!(o.get(x, y), 25);
        let (x, y) = o.cell_of(10.0 - 0.25, 20.25).unwrap();
        assert_eq!(o.get(x, y), 0, "visited, never hit: free");
        assert_eq!(o.get(0, 0), crate::map::UNKNOWN);
    }

    #[test]
    fn integer_floor_matches_floor() {
        for v in [-2.5, -2.0, -1e-12, 0.0, 1e-12, 0.999_999, 1.0, 3.7, -1e9 - 0.5, 1e12 + 0.25] {
            assert_eq!(floor(v), v.floor() as i64, "{v}");
        }
    }

    #[test]
    fn wall_reads_match_single_reads() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0));
        // Occupancies 1/2, 2/13, 3/22 (walls) and 4/4, 5/14 (walls), plus a free cell.
        for (i, c) in [(0, 0), (31, 31), (32, 32), (-1, 5), (15, -33)].into_iter().enumerate() {
            g.update(c, |cell| {
                *cell = Cell { hits: i as u32 + 1, visits: 2 + i as u32 % 3 * 9, ..Cell::default() }
            });
        }
        g.update((1, 1), |c| c.visits = 5);
        // A wall that becomes free again loses its bit.
        g.update((2, 2), |c| *c = Cell { hits: 1, visits: 1, ..Cell::default() });
        g.update((2, 2), |c| c.visits = 100);
        // Centres inside a tile, on tile corners and edges, and in empty space.
        for centre in [(1, 1), (31, 31), (32, 0), (0, -1), (-33, 15), (500, 500), (2, 2)] {
            for k in [0, 1, 2] {
                let mut seen = Vec::new();
                g.for_each_wall_in_square(centre, k, |c, cell| seen.push((c, cell)));
                let mut expected = Vec::new();
                for x in centre.0 - k..=centre.0 + k {
                    for y in centre.1 - k..=centre.1 + k {
                        if g.get((x, y)).is_wall(0.1) {
                            expected.push(((x, y), g.get((x, y))));
                        }
                    }
                }
                assert_eq!(seen, expected, "{centre:?} k {k}");
            }
        }
    }

    #[test]
    fn occupancy_and_mean_hit() {
        let c = Cell { sum_x: 3.0, sum_y: 9.0, hits: 3, visits: 4 };
        assert_eq!(c.occupancy(), Some(0.75));
        assert_eq!(c.mean(), Some((1.0, 3.0)));
        assert_eq!(Cell::default().occupancy(), None);
    }
}
