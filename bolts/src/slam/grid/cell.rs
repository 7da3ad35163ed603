//! One cell of a grid: what GMapping's `PointAccumulator` keeps (hits,
//! visits, the mean hit point), whether it reads as a wall or as free, and
//! the limit of its counts.

use serde::{Deserialize, Serialize};
use squall_core::geometry::Real;

/// What one cell has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// Mean x of the beam end points in this cell, metres (kept as a mean
    /// so the scan matcher reads it without dividing).
    pub mean_x: f32,
    /// Their mean y, metres.
    pub mean_y: f32,
    /// Beams that ended here.
    pub hits: u32,
    /// Beams that crossed or ended here.
    pub visits: u32,
}

/// The most visits a cell counts. A visit beyond halves the cell's hits and
/// visits: the occupancy the wall test reads stays (to within one hit), and
/// later beams weigh a little more. A cell reaches this only after tens of
/// thousands of beams crossed it (none does in the logs of this repository).
pub const MAX_VISITS: u32 = u16::MAX as u32;

/// Occupancy above which a cell is a wall, unless set otherwise.
pub const DEFAULT_WALL_THRESHOLD: Real = 0.1;

impl Cell {
    /// Occupancy probability (hits / visits); `None` if never visited.
    pub fn occupancy(&self) -> Option<Real> {
        (self.visits > 0).then(|| Real::from(self.hits) / Real::from(self.visits))
    }

    /// Mean of the hit points, if any beam ended here.
    pub fn mean(&self) -> Option<(Real, Real)> {
        (self.hits > 0).then(|| (Real::from(self.mean_x), Real::from(self.mean_y)))
    }

    /// A beam ended here, at (`x`, `y`).
    #[inline]
    pub fn add_hit(&mut self, x: f32, y: f32) {
        self.visits += 1;
        self.hits += 1;
        let n = self.hits as f32;
        self.mean_x += (x - self.mean_x) / n;
        self.mean_y += (y - self.mean_y) / n;
    }

    /// Whether hits/visits exceeds `threshold` (compared without dividing).
    #[inline]
    pub fn is_wall(&self, threshold: Real) -> bool {
        self.visits > 0 && Real::from(self.hits) > threshold * Real::from(self.visits)
    }

    /// Whether the cell is free for matching: hits/visits below the
    /// threshold, or never visited (GMapping reads unknown cells as
    /// occupancy −1).
    #[inline]
    pub fn is_free(&self, threshold: Real) -> bool {
        self.visits == 0 || Real::from(self.hits) < threshold * Real::from(self.visits)
    }

    /// Halves hits and visits while visits exceed [`MAX_VISITS`], and
    /// keeps hits at most visits.
    #[inline]
    pub(super) fn keep_countable(&mut self) {
        while self.visits > MAX_VISITS {
            self.visits /= 2;
            self.hits /= 2;
        }
        self.hits = self.hits.min(self.visits);
    }
}
