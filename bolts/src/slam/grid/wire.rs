//! Grids and tiles as they travel between processes, checked as they are
//! read: a grid or tile that fails a check is an error, not a later panic
//! or a silently wrong match.

use std::sync::{Arc, OnceLock};

use serde::{Deserialize, Serialize};
use squall_core::geometry::Real;

use super::TiledGrid;
use super::cell::{Cell, MAX_VISITS};
use super::tile::{Cells, TILE_SIDE, Tile};
pub use crate::error::GridWireError;

/// A tile as it travels between processes: its cells row by row and its
/// bit rows.
#[derive(Serialize, Deserialize)]
pub(super) struct TileWire {
    pub(super) cells: Vec<Cell>,
    pub(super) walls: Vec<u32>,
    pub(super) free: Vec<u32>,
}

impl From<Tile> for TileWire {
    fn from(t: Tile) -> Self {
        TileWire { cells: t.cells.iter().collect(), walls: t.walls.to_vec(), free: t.free.to_vec() }
    }
}

impl TryFrom<TileWire> for Tile {
    type Error = GridWireError;

    fn try_from(w: TileWire) -> Result<Self, GridWireError> {
        let n = w.cells.len();
        if n != TILE_SIDE * TILE_SIDE {
            return Err(GridWireError::TileCells { expected: TILE_SIDE * TILE_SIDE, got: n });
        }
        let mut cells = Cells::default();
        for (i, &c) in w.cells.iter().enumerate() {
            if c.visits > MAX_VISITS || c.hits > c.visits {
                let (x, y) = (i % TILE_SIDE, i / TILE_SIDE);
                return Err(GridWireError::CellCounts {
                    x,
                    y,
                    hits: c.hits,
                    visits: c.visits,
                    max_visits: MAX_VISITS,
                });
            }
            cells.set(i, c);
        }
        cells.shrink_to_fit();
        let rows = |v: Vec<u32>| -> Result<[u32; TILE_SIDE], GridWireError> {
            let n = v.len();
            v.try_into().map_err(|_| GridWireError::BitRows { expected: TILE_SIDE, got: n })
        };
        Ok(Tile { cells, walls: rows(w.walls)?, free: rows(w.free)?, digest: OnceLock::new() })
    }
}

/// A grid as it travels: everything but the derived per-metre factor and
/// the clone counter, with its index entries as `T` (tiles themselves, or
/// a transfer's references to them).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct GridWire<T = Option<Arc<Tile>>> {
    pub(crate) resolution: Real,
    pub(crate) origin: (Real, Real),
    pub(crate) tile_min: (i64, i64),
    pub(crate) tiles_wide: usize,
    pub(crate) tiles_high: usize,
    pub(crate) tiles: Vec<T>,
    pub(crate) wall_threshold: Real,
}

impl<T> GridWire<T> {
    /// The same grid with its index entries turned into `U`s.
    pub(crate) fn map_tiles<U>(self, mut f: impl FnMut(T) -> U) -> GridWire<U> {
        let Ok(mapped) = self.try_map_tiles(|t| Ok::<_, std::convert::Infallible>(f(t)));
        mapped
    }

    /// The same grid with its index entries turned into `U`s (stopping at
    /// the first error).
    pub(crate) fn try_map_tiles<U, E>(self, f: impl FnMut(T) -> Result<U, E>) -> Result<GridWire<U>, E> {
        let tiles = self.tiles.into_iter().map(f).collect::<Result<_, E>>()?;
        Ok(GridWire {
            resolution: self.resolution,
            origin: self.origin,
            tile_min: self.tile_min,
            tiles_wide: self.tiles_wide,
            tiles_high: self.tiles_high,
            tiles,
            wall_threshold: self.wall_threshold,
        })
    }
}

impl From<TiledGrid> for GridWire {
    fn from(g: TiledGrid) -> Self {
        GridWire {
            resolution: g.resolution,
            origin: g.origin,
            tile_min: g.tile_min,
            tiles_wide: g.tiles_wide,
            tiles_high: g.tiles_high,
            tiles: g.tiles,
            wall_threshold: g.wall_threshold,
        }
    }
}

impl TryFrom<GridWire> for TiledGrid {
    type Error = GridWireError;

    fn try_from(w: GridWire) -> Result<Self, GridWireError> {
        if !(w.resolution.is_finite() && w.resolution > 0.0) {
            return Err(GridWireError::Resolution(w.resolution));
        }
        if !(w.origin.0.is_finite() && w.origin.1.is_finite()) {
            return Err(GridWireError::Origin(w.origin));
        }
        if !(0.0..=1.0).contains(&w.wall_threshold) {
            return Err(GridWireError::WallThreshold(w.wall_threshold));
        }
        let expected = w.tiles_wide.checked_mul(w.tiles_high);
        if expected != Some(w.tiles.len()) {
            let (wide, high, entries) = (w.tiles_wide, w.tiles_high, w.tiles.len());
            return Err(GridWireError::IndexSize { wide, high, entries });
        }
        let reach = |min: i64, n: usize| i64::try_from(n).ok().and_then(|n| min.checked_add(n));
        if reach(w.tile_min.0, w.tiles_wide).is_none() || reach(w.tile_min.1, w.tiles_high).is_none() {
            return Err(GridWireError::Reach(w.tile_min));
        }
        for (i, tile) in w.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            for (j, cell) in tile.cells.iter().enumerate() {
                let (x, y) = (j % TILE_SIDE, j / TILE_SIDE);
                if cell.hits > 0 && !(cell.mean_x.is_finite() && cell.mean_y.is_finite()) {
                    return Err(GridWireError::MeanHit { tile: i, x, y });
                }
                let wall = (tile.walls[y] >> x) & 1 == 1;
                let free = (tile.free[y] >> x) & 1 == 1;
                if wall != cell.is_wall(w.wall_threshold) || free != cell.is_free(w.wall_threshold) {
                    return Err(GridWireError::Bits { tile: i, x, y });
                }
            }
        }
        Ok(TiledGrid {
            resolution: w.resolution,
            per_metre: 1.0 / w.resolution,
            origin: w.origin,
            tile_min: w.tile_min,
            tiles_wide: w.tiles_wide,
            tiles_high: w.tiles_high,
            tiles: w.tiles,
            wall_threshold: w.wall_threshold,
            clones: 0,
        })
    }
}
