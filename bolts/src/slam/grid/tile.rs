//! Tiles: square blocks of cells with one bit row per wall and per free
//! cell, shared between particles' maps until written.

use std::sync::OnceLock;

use serde::{Deserialize, Serialize};
use squall_core::geometry::Real;

use super::cell::{Cell, MAX_VISITS};
use super::wire::TileWire;

/// Cells per tile side is `1 << TILE_SHIFT`.
pub const TILE_SHIFT: u32 = 5;
/// Cells per tile side.
pub const TILE_SIDE: usize = 1 << TILE_SHIFT;
/// A cell's place within its tile is its coordinates masked with this.
pub(super) const TILE_MASK: i64 = TILE_SIDE as i64 - 1;

/// Bytes one tile occupies.
pub const TILE_BYTES: usize = std::mem::size_of::<Cells>() + 8 * TILE_SIDE;

/// A square block of cells, with one bit per cell saying whether it is a
/// wall and one saying whether it is free, so the scan matcher finds the
/// few candidate cells of a beam with bit operations before reading any.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "TileWire", try_from = "TileWire")]
pub struct Tile {
    pub(super) cells: Box<Cells>,
    /// Bit x of `walls[y]`: cell (x, y) of the tile is a wall.
    pub(super) walls: [u32; TILE_SIDE],
    /// Bit x of `free[y]`: cell (x, y) is free (see [`Cell::is_free`]).
    pub(super) free: [u32; TILE_SIDE],
    /// The cells' digest once computed; every write clears it.
    pub(super) digest: OnceLock<u128>,
}

/// Cells held as two arrays: the counts, which every beam crossing a cell
/// reads and writes, and the mean hit points, which only hits and the scan
/// matcher read. Integration streams through the counts alone, half the
/// bytes of whole cells (it waits on memory, not on arithmetic).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Cells {
    pub(super) counts: [Counts; TILE_SIDE * TILE_SIDE],
    pub(super) means: [[f32; 2]; TILE_SIDE * TILE_SIDE],
}

/// A cell's hits and visits (see [`Cell`]), in 16 bits each: integration
/// reads and writes these for every cell a beam crosses, and at half the
/// bytes it waits on memory less.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Counts {
    pub(super) hits: u16,
    pub(super) visits: u16,
}

impl Default for Cells {
    fn default() -> Self {
        Cells { counts: [Counts::default(); TILE_SIDE * TILE_SIDE], means: [[0.0; 2]; TILE_SIDE * TILE_SIDE] }
    }
}

impl Cells {
    /// Cell `i` (row-major) as one value.
    #[inline]
    pub(super) fn get(&self, i: usize) -> Cell {
        let (Counts { hits, visits }, [mean_x, mean_y]) = (self.counts[i], self.means[i]);
        Cell { mean_x, mean_y, hits: hits.into(), visits: visits.into() }
    }

    /// Stores cell `i`, whose counts must be countable (at most
    /// [`MAX_VISITS`] visits, no more hits than visits).
    #[inline]
    pub(super) fn set(&mut self, i: usize, c: Cell) {
        debug_assert!(c.visits <= MAX_VISITS && c.hits <= c.visits, "{c:?}");
        self.counts[i] = Counts { hits: c.hits as u16, visits: c.visits as u16 };
        self.means[i] = [c.mean_x, c.mean_y];
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = Cell> + '_ {
        (0..TILE_SIDE * TILE_SIDE).map(|i| self.get(i))
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
            cells: Box::default(),
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
            for y in 0..TILE_SIDE {
                for (x, bytes) in row.chunks_exact_mut(16).enumerate() {
                    let c = self.cells.get(y * TILE_SIDE + x);
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

    /// A beam crossed cell `i` (row-major). A cell no beam ended in stays free
    /// whatever its visits, so its bits stand (most cells a beam crosses);
    /// a full count goes the general way, which halves it.
    #[inline]
    pub(super) fn visit(&mut self, i: usize, threshold: Real) {
        let counts = &mut self.cells.counts[i];
        if counts.hits == 0 && threshold > 0.0 && counts.visits < u16::MAX {
            counts.visits += 1;
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
