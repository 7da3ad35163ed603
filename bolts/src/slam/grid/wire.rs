//! Grids and tiles as they travel between processes, checked as they are
//! read: a grid or tile that fails a check is an error, not a later panic
//! or a silently wrong match.

use std::sync::{Arc, OnceLock};

use serde::{Deserialize, Serialize};
use squall_core::geometry::Real;

use super::TiledGrid;
use super::cell::{Cell, MAX_VISITS};
use super::tile::{Cells, TILE_SIDE, Tile};

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
    type Error = String;

    fn try_from(w: TileWire) -> Result<Self, String> {
        let n = w.cells.len();
        if n != TILE_SIDE * TILE_SIDE {
            return Err(format!("a tile holds {} cells, got {n}", TILE_SIDE * TILE_SIDE));
        }
        let mut cells = Box::<Cells>::default();
        for (i, &c) in w.cells.iter().enumerate() {
            if c.visits > MAX_VISITS || c.hits > c.visits {
                let (x, y) = (i % TILE_SIDE, i / TILE_SIDE);
                return Err(format!(
                    "tile cell ({x}, {y}): {} hits in {} visits (a cell counts at most {MAX_VISITS} visits and no more hits than visits)",
                    c.hits, c.visits
                ));
            }
            cells.set(i, c);
        }
        let rows = |v: Vec<u32>| -> Result<[u32; TILE_SIDE], String> {
            let n = v.len();
            v.try_into().map_err(|_| format!("a tile has {TILE_SIDE} bit rows, got {n}"))
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
    type Error = String;

    fn try_from(w: GridWire) -> Result<Self, String> {
        if !(w.resolution.is_finite() && w.resolution > 0.0) {
            return Err(format!("grid resolution {} is not a positive number of metres", w.resolution));
        }
        if !(w.origin.0.is_finite() && w.origin.1.is_finite()) {
            return Err(format!("grid origin {:?} is not finite", w.origin));
        }
        if !(0.0..=1.0).contains(&w.wall_threshold) {
            return Err(format!("wall threshold {} is not an occupancy in 0..=1", w.wall_threshold));
        }
        let expected = w.tiles_wide.checked_mul(w.tiles_high);
        if expected != Some(w.tiles.len()) {
            return Err(format!(
                "a grid index of {} × {} tiles holds {} entries",
                w.tiles_wide,
                w.tiles_high,
                w.tiles.len()
            ));
        }
        let reach = |min: i64, n: usize| i64::try_from(n).ok().and_then(|n| min.checked_add(n));
        if reach(w.tile_min.0, w.tiles_wide).is_none() || reach(w.tile_min.1, w.tiles_high).is_none() {
            return Err(format!("grid tiles from {:?} reach beyond the coordinates", w.tile_min));
        }
        for (i, tile) in w.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            for (j, cell) in tile.cells.iter().enumerate() {
                let (x, y) = (j % TILE_SIDE, j / TILE_SIDE);
                if cell.hits > 0 && !(cell.mean_x.is_finite() && cell.mean_y.is_finite()) {
                    return Err(format!("tile {i}, cell ({x}, {y}): mean hit point is not finite"));
                }
                let wall = (tile.walls[y] >> x) & 1 == 1;
                let free = (tile.free[y] >> x) & 1 == 1;
                if wall != cell.is_wall(w.wall_threshold) || free != cell.is_free(w.wall_threshold) {
                    return Err(format!(
                        "tile {i}, cell ({x}, {y}): wall and free bits disagree with the cell"
                    ));
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
