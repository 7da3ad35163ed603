//! A submap's likelihood field and its max-pooled levels, for exact
//! branch-and-bound correlative matching (Olson 2009; Hess et al. 2016).
//!
//! The field holds, per cell, how likely a beam ending there is given the
//! submap's hits: a Gaussian of the distance to the nearest hit, stored as
//! a byte. Level h holds, per cell, the largest value over the 2ʰ × 2ʰ
//! cells whose corner it is, so the sum of level-h values under a scan's
//! points bounds the score of every translation within that square of
//! offsets: the bound the search prunes with.

use squall_core::geometry::Real;

/// Largest value of a cell (a hit).
pub(crate) const FULL: Real = 255.0;

/// The likelihood field of a set of points and its max-pooled levels.
#[derive(Debug, Clone)]
pub(crate) struct Field {
    /// Metres per cell.
    pub resolution: Real,
    /// Position of cell (0, 0)'s corner, in the submap's frame.
    pub origin: (Real, Real),
    /// Cells along x and y.
    pub size: (usize, usize),
    /// Level h at `levels[h]`, row-major, `size.0 × size.1` each.
    levels: Vec<Vec<u8>>,
}

impl Field {
    /// The field of `points` (in the submap's frame) at `resolution`, each
    /// hit spread as a Gaussian of standard deviation `sigma` metres, with
    /// `depth` max-pooled levels above it, and room around the points for
    /// a search `margin` metres wide.
    pub(crate) fn build(
        points: &[(Real, Real)],
        resolution: Real,
        sigma: Real,
        depth: usize,
        margin: Real,
    ) -> Self {
        let spread = (3.0 * sigma / resolution).ceil() as i64;
        let (mut lo, mut hi) = ((Real::INFINITY, Real::INFINITY), (Real::NEG_INFINITY, Real::NEG_INFINITY));
        for &(x, y) in points {
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        if points.is_empty() {
            (lo, hi) = ((0.0, 0.0), (0.0, 0.0));
        }
        let pad = margin + (spread + 1) as Real * resolution;
        let origin = (lo.0 - pad, lo.1 - pad);
        let size = (
            ((hi.0 - lo.0 + 2.0 * pad) / resolution).ceil() as usize + 1,
            ((hi.1 - lo.1 + 2.0 * pad) / resolution).ceil() as usize + 1,
        );
        let mut base = vec![0u8; size.0 * size.1];
        // Each cell takes the Gaussian of its centre's distance to the
        // nearest point (within the spread): exact to the point, not to
        // its cell.
        for &(x, y) in points {
            let cx = ((x - origin.0) / resolution).floor() as i64;
            let cy = ((y - origin.1) / resolution).floor() as i64;
            for gy in cy - spread..=cy + spread {
                for gx in cx - spread..=cx + spread {
                    let dx = origin.0 + (gx as Real + 0.5) * resolution - x;
                    let dy = origin.1 + (gy as Real + 0.5) * resolution - y;
                    let value = (FULL * (-0.5 * (dx * dx + dy * dy) / (sigma * sigma)).exp()).round() as u8;
                    let cell = &mut base[gy as usize * size.0 + gx as usize];
                    *cell = (*cell).max(value);
                }
            }
        }
        let mut levels = vec![base];
        let (w, rows) = size;
        for h in 1..=depth {
            // Level h from level h − 1: the larger of a cell and the one
            // half a window on, along x, then along y (separable).
            let half = 1usize << (h - 1);
            let below = &levels[h - 1];
            let mut along_x = vec![0u8; w * rows];
            for (row, out) in below.chunks_exact(w).zip(along_x.chunks_exact_mut(w)) {
                for x in 0..w {
                    out[x] = if x + half < w { row[x].max(row[x + half]) } else { row[x] };
                }
            }
            let mut level = along_x.clone();
            for y in 0..rows.saturating_sub(half) {
                let (top, bottom) =
                    (&along_x[y * w..(y + 1) * w], &along_x[(y + half) * w..(y + half + 1) * w]);
                for ((out, &a), &b) in level[y * w..(y + 1) * w].iter_mut().zip(top).zip(bottom) {
                    *out = a.max(b);
                }
            }
            levels.push(level);
        }
        Field { resolution, origin, size, levels }
    }

    /// The highest level.
    pub(crate) fn depth(&self) -> usize {
        self.levels.len() - 1
    }

    /// Level `h`'s value at cell `(x, y)`; 0 outside the field.
    #[inline]
    pub(crate) fn at(&self, h: usize, x: i64, y: i64) -> u8 {
        if x < 0 || y < 0 || x >= self.size.0 as i64 || y >= self.size.1 as i64 {
            return 0;
        }
        self.levels[h][y as usize * self.size.0 + x as usize]
    }

    /// The base field at a point, interpolated bilinearly, in 0..=1, and
    /// its gradient per metre.
    pub(crate) fn interpolate(&self, x: Real, y: Real) -> (Real, Real, Real) {
        let fx = (x - self.origin.0) / self.resolution - 0.5;
        let fy = (y - self.origin.1) / self.resolution - 0.5;
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let v = |dx: i64, dy: i64| Real::from(self.at(0, x0 + dx, y0 + dy)) / FULL;
        let (v00, v10, v01, v11) = (v(0, 0), v(1, 0), v(0, 1), v(1, 1));
        let value = (1.0 - ty) * ((1.0 - tx) * v00 + tx * v10) + ty * ((1.0 - tx) * v01 + tx * v11);
        let dx = ((1.0 - ty) * (v10 - v00) + ty * (v11 - v01)) / self.resolution;
        let dy = ((1.0 - tx) * (v01 - v00) + tx * (v11 - v10)) / self.resolution;
        (value, dx, dy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_level_bounds_the_cells_it_covers() {
        let points: Vec<(Real, Real)> = (0..40).map(|i| (0.1 * i as Real, (0.3 * i as Real).sin())).collect();
        let field = Field::build(&points, 0.05, 0.05, 4, 0.5);
        for h in 1..=field.depth() {
            let side = 1i64 << h;
            for y in (0..field.size.1 as i64).step_by(7) {
                for x in (0..field.size.0 as i64).step_by(5) {
                    let mut largest = 0;
                    for dy in 0..side {
                        for dx in 0..side {
                            largest = largest.max(field.at(0, x + dx, y + dy));
                        }
                    }
                    assert_eq!(field.at(h, x, y), largest, "level {h} at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn a_hit_is_full_and_fades_with_distance() {
        let field = Field::build(&[(1.0, 1.0)], 0.05, 0.05, 2, 0.0);
        let (at_hit, _, _) = field.interpolate(1.0, 1.0);
        let (near, _, _) = field.interpolate(1.05, 1.0);
        let (far, _, _) = field.interpolate(1.3, 1.0);
        assert!(at_hit > 0.5 && near < at_hit && far == 0.0, "{at_hit} {near} {far}");
    }
}
