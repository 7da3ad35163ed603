//! The occupancy grid as it travels on streams and is written to disk:
//! shaped like ROS's `nav_msgs/OccupancyGrid` so it can be published as is.

use serde::{Deserialize, Serialize};

use crate::geometry::Real;

/// Value of a cell that was never observed.
pub const UNKNOWN: i8 = -1;

/// A 2-D occupancy grid: row-major, row 0 at the bottom (lowest y), cells
/// of `resolution` metres, cell (0, 0)'s corner at `origin`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Cells per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Metres per cell.
    pub resolution: Real,
    /// World position (m) of the lower-left corner of cell (0, 0).
    pub origin: (Real, Real),
    /// Occupancy probability in percent (0..=100), or [`UNKNOWN`].
    pub cells: Vec<i8>,
}

impl OccupancyGrid {
    /// A grid of unknown cells.
    pub fn unknown(width: usize, height: usize, resolution: Real, origin: (Real, Real)) -> Self {
        OccupancyGrid { width, height, resolution, origin, cells: vec![UNKNOWN; width * height] }
    }

    /// The cell at column `x`, row `y`.
    ///
    /// # Panics
    ///
    /// If the cell lies outside the grid, as slice indexing does: callers
    /// index with cells they got from the grid ([`cell_of`](Self::cell_of),
    /// its width and height); checking again would cost the hot loops.
    pub fn get(&self, x: usize, y: usize) -> i8 {
        self.cells[y * self.width + x]
    }

    /// Sets the cell at column `x`, row `y`.
    ///
    /// # Panics
    ///
    /// If the cell lies outside the grid (see [`get`](Self::get)).
    pub fn set(&mut self, x: usize, y: usize, value: i8) {
        self.cells[y * self.width + x] = value;
    }

    /// The cell containing world point (`wx`, `wy`), if inside the grid.
    pub fn cell_of(&self, wx: Real, wy: Real) -> Option<(usize, usize)> {
        let cx = ((wx - self.origin.0) / self.resolution).floor();
        let cy = ((wy - self.origin.1) / self.resolution).floor();
        (cx >= 0.0 && cy >= 0.0 && (cx as usize) < self.width && (cy as usize) < self.height)
            .then_some((cx as usize, cy as usize))
    }
}
