//! Tiles: square blocks of cells with one bit row per wall and per free
//! cell, shared between particles' maps until written.

use std::sync::OnceLock;

use serde::{Deserialize, Serialize};
use squall_core::geometry::Real;

use super::cell::{Cell, MAX_VISITS};
use super::wire::TileWire;

/// Cells per tile side is `1 << TILE_SHIFT`.
pub(crate) const TILE_SHIFT: u32 = 5;
/// Cells per tile side.
pub(crate) const TILE_SIDE: usize = 1 << TILE_SHIFT;
/// A cell's place within its tile is its coordinates masked with this.
pub(super) const TILE_MASK: i64 = TILE_SIDE as i64 - 1;

/// Cells per tile.
const CELLS: usize = TILE_SIDE * TILE_SIDE;

/// A square block of cells, with one bit per cell saying whether it is a
/// wall and one saying whether it is free, so the scan matcher finds the
/// few candidate cells of a beam with bit operations before reading any.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "TileWire", try_from = "TileWire")]
pub struct Tile {
    pub(super) cells: Cells,
    /// Bit x of `walls[y]`: cell (x, y) of the tile is a wall.
    pub(super) walls: [u32; TILE_SIDE],
    /// Bit x of `free[y]`: cell (x, y) is free (see [`Cell::is_free`]).
    pub(super) free: [u32; TILE_SIDE],
    /// The cells' digest once computed; every write clears it.
    pub(super) digest: OnceLock<u128>,
}

/// A tile's cells: the visits of every cell, which every beam crossing a
/// cell reads and writes, and the hits and mean hit point of only the
/// cells some beam ended in. Beams end in few cells (2–6% of a tile's
/// cells over a whole ACES run at 100 particles), so a tile takes about a
/// quarter of the bytes whole cells would (2.5 KiB and 12 bytes a hit
/// cell, against 12.25 KiB): particles' maps, which differ in every tile
/// their recent scans crossed, are most of SLAM's memory (decision 0012).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Cells {
    /// Visits of every cell, row-major.
    visits: [u16; CELLS],
    /// Bit x of `hit_rows[y]`: cell (x, y) has an entry in `hit` (it was
    /// hit once; its hits may since have been halved to none).
    hit_rows: [u32; TILE_SIDE],
    /// Entries of `hit` for the rows before row y.
    row_starts: [u16; TILE_SIDE],
    /// The hit cells, row-major.
    hit: Vec<HitCell>,
}

/// A hit cell's hits and mean hit point.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HitCell {
    hits: u16,
    mean: [f32; 2],
}

impl Default for Cells {
    fn default() -> Self {
        Cells { visits: [0; CELLS], hit_rows: [0; TILE_SIDE], row_starts: [0; TILE_SIDE], hit: Vec::new() }
    }
}

impl Cells {
    /// Where cell (`x`, `y`)'s entry is or would go in `hit`: the entries
    /// of the cells before it.
    #[inline]
    fn rank(&self, x: usize, y: usize) -> usize {
        usize::from(self.row_starts[y]) + (self.hit_rows[y] & ((1u32 << x) - 1)).count_ones() as usize
    }

    /// The entry in `hit` of cell (`x`, `y`), if it has one.
    #[inline]
    fn entry(&self, x: usize, y: usize) -> Option<usize> {
        ((self.hit_rows[y] >> x) & 1 == 1).then(|| self.rank(x, y))
    }

    /// Whether cell `i` (row-major) was ever hit.
    #[inline]
    fn was_hit(&self, i: usize) -> bool {
        (self.hit_rows[i / TILE_SIDE] >> (i % TILE_SIDE)) & 1 == 1
    }

    /// Cell `i` (row-major) as one value.
    #[inline]
    pub(super) fn get(&self, i: usize) -> Cell {
        let visits = self.visits[i].into();
        match self.entry(i % TILE_SIDE, i / TILE_SIDE) {
            Some(k) => {
                let HitCell { hits, mean: [mean_x, mean_y] } = self.hit[k];
                Cell { mean_x, mean_y, hits: hits.into(), visits }
            }
            None => Cell { visits, ..Cell::default() },
        }
    }

    /// The mean hit point of cell (`x`, `y`), which a beam ended in (a
    /// wall cell); the origin for a cell never hit.
    #[inline]
    pub(super) fn mean(&self, x: usize, y: usize) -> [f32; 2] {
        debug_assert!(self.entry(x, y).is_some(), "({x}, {y}) was never hit");
        self.entry(x, y).map_or([0.0; 2], |k| self.hit[k].mean)
    }

    /// Stores cell `i`, whose counts must be countable (at most
    /// [`MAX_VISITS`] visits, no more hits than visits).
    #[inline]
    pub(super) fn set(&mut self, i: usize, c: Cell) {
        debug_assert!(c.visits <= MAX_VISITS && c.hits <= c.visits, "{c:?}");
        self.visits[i] = c.visits as u16;
        let value = HitCell { hits: c.hits as u16, mean: [c.mean_x, c.mean_y] };
        let (x, y) = (i % TILE_SIDE, i / TILE_SIDE);
        match self.entry(x, y) {
            Some(k) => self.hit[k] = value,
            None if value.hits > 0 || value.mean != [0.0; 2] => {
                let k = self.rank(x, y);
                if self.hit.len() == self.hit.capacity() {
                    // Grow by an eighth, not double: most tiles are
                    // copies, and a copy's spare room is memory lost.
                    self.hit.reserve_exact((self.hit.len() / 8).max(4));
                }
                self.hit.insert(k, value);
                self.hit_rows[y] |= 1 << x;
                for start in &mut self.row_starts[y + 1..] {
                    *start += 1;
                }
            }
            None => {}
        }
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = Cell> + '_ {
        let mut hit = self.hit.iter();
        (0..CELLS).map(move |i| {
            let visits = self.visits[i].into();
            match self.was_hit(i).then(|| hit.next()).flatten() {
                Some(&HitCell { hits, mean: [mean_x, mean_y] }) => {
                    Cell { mean_x, mean_y, hits: hits.into(), visits }
                }
                None => Cell { visits, ..Cell::default() },
            }
        })
    }

    /// Drops the hit cells' spare room.
    pub(super) fn shrink_to_fit(&mut self) {
        self.hit.shrink_to_fit();
    }

    /// Bytes the hit cells take beyond the cells' own, with their spare
    /// room.
    fn hit_bytes(&self) -> usize {
        self.hit.capacity() * std::mem::size_of::<HitCell>()
    }
}

impl PartialEq for Tile {
    fn eq(&self, other: &Self) -> bool {
        self.cells == other.cells && self.walls == other.walls && self.free == other.free
    }
}

impl Default for Tile {
    fn default() -> Self {
        Tile {
            cells: Cells::default(),
            walls: [0; TILE_SIDE],
            free: [u32::MAX; TILE_SIDE],
            digest: OnceLock::new(),
        }
    }
}

impl Tile {
    /// A 128-bit digest of the cells (XXH3, the same in every process):
    /// the tile's address in transfers, so a receiver that holds a tile
    /// with this digest is not sent it again. Computed once per content.
    pub fn digest(&self) -> u128 {
        *self.digest.get_or_init(|| {
            // A row's cells as little-endian bytes at a time: one hasher
            // call per row, not four per cell.
            let mut hasher = xxhash_rust::xxh3::Xxh3::new();
            let mut row = [0u8; 16 * TILE_SIDE];
            let mut cells = self.cells.iter();
            for _ in 0..TILE_SIDE {
                for (bytes, c) in row.chunks_exact_mut(16).zip(cells.by_ref()) {
                    bytes[..4].copy_from_slice(&c.mean_x.to_le_bytes());
                    bytes[4..8].copy_from_slice(&c.mean_y.to_le_bytes());
                    bytes[8..12].copy_from_slice(&c.hits.to_le_bytes());
                    bytes[12..].copy_from_slice(&c.visits.to_le_bytes());
                }
                hasher.update(&row);
            }
            hasher.digest128()
        })
    }

    /// Bytes the tile takes.
    pub(crate) fn bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.cells.hit_bytes()
    }

    /// The mean hit point of wall cell (`x`, `y`).
    #[inline]
    pub(super) fn wall_mean(&self, x: usize, y: usize) -> [f32; 2] {
        self.cells.mean(x, y)
    }

    /// A beam crossed cell `i` (row-major). A cell no beam ended in stays free
    /// whatever its visits, so its bits stand (most cells a beam crosses);
    /// a full count goes the general way, which halves it.
    #[inline]
    pub(super) fn visit(&mut self, i: usize, threshold: Real) {
        if !self.cells.was_hit(i) && threshold > 0.0 && self.cells.visits[i] < u16::MAX {
            self.cells.visits[i] += 1;
        } else {
            self.update(i % TILE_SIDE, i / TILE_SIDE, threshold, |cell| cell.visits += 1);
        }
    }

    /// Changes cell (`x`, `y`) of the tile with `f` and keeps its bits.
    #[inline]
    pub(super) fn update(&mut self, x: usize, y: usize, threshold: Real, f: impl FnOnce(&mut Cell)) {
        let i = y * TILE_SIDE + x;
        let mut cell = self.cells.get(i);
        f(&mut cell);
        cell.keep_countable();
        self.cells.set(i, cell);
        let (wall, free) = (cell.is_wall(threshold), cell.is_free(threshold));
        self.walls[y] = (self.walls[y] & !(1 << x)) | (u32::from(wall) << x);
        self.free[y] = (self.free[y] & !(1 << x)) | (u32::from(free) << x);
    }
}
