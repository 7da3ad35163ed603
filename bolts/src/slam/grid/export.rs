//! The explored part of a grid as an occupancy grid message.

use squall_core::geometry::Real;

use super::TiledGrid;
use super::tile::TILE_SHIFT;

impl TiledGrid {
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

    /// The explored area as an occupancy grid message: occupancy in percent
    /// for visited cells, unknown elsewhere.
    pub fn to_occupancy(&self) -> squall_core::occupancy::OccupancyGrid {
        let Some((lo, hi)) = self.cell_bounds() else {
            return squall_core::occupancy::OccupancyGrid::unknown(0, 0, self.resolution, self.origin);
        };
        let (width, height) = ((hi.0 - lo.0 + 1) as usize, (hi.1 - lo.1 + 1) as usize);
        let corner =
            (self.origin.0 + lo.0 as Real * self.resolution, self.origin.1 + lo.1 as Real * self.resolution);
        let mut grid = squall_core::occupancy::OccupancyGrid::unknown(width, height, self.resolution, corner);
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
