//! GMapping's kernel search: the wall cells near a beam's end point whose
//! neighbour back towards the laser is free, found with bit operations on
//! the tiles' wall and free rows.

use squall_core::geometry::Real;

use super::TiledGrid;
use super::tile::{TILE_MASK, TILE_SHIFT, TILE_SIDE, Tile};

impl TiledGrid {
    /// GMapping's kernel search for one beam: the squared distance (m²)
    /// from the beam's end point `hit` to the nearest mean hit point among
    /// the wall cells within `k` cells of it whose neighbour at `back` (one
    /// step back towards the laser, each component in −1..=1) is free;
    /// `None` if there is none. `k` is at most 14.
    #[inline]
    pub fn nearest_backed_wall(&self, hit: (Real, Real), back: (i64, i64), k: i64) -> Option<Real> {
        self.nearest_backed_mean(hit, back, k).map(|(d2, _)| d2)
    }

    /// [`Self::nearest_backed_wall`] with the mean hit point it found (the
    /// first of equally near ones, row by row).
    #[inline]
    pub fn nearest_backed_mean(
        &self,
        hit: (Real, Real),
        back: (i64, i64),
        k: i64,
    ) -> Option<(Real, (Real, Real))> {
        let (hx, hy) = (hit.0 as f32, hit.1 as f32);
        let mut best = (f32::INFINITY, (0.0f32, 0.0f32));
        self.backed_walls(self.cell_of(hit.0, hit.1), back, k, |mx, my| {
            let d2 = (hx - mx).powi(2) + (hy - my).powi(2);
            if d2 < best.0 {
                best = (d2, (mx, my));
            }
        });
        let (d2, (mx, my)) = best;
        (d2 < f32::INFINITY).then(|| (Real::from(d2), (Real::from(mx), Real::from(my))))
    }

    /// The candidates of [`Self::nearest_backed_wall`] around cell
    /// `centre`: calls `visit(mean x, mean y)` for each wall cell within
    /// `k` cells whose neighbour at `back` is free, row by row. The scan
    /// matcher caches these per beam, since a beam's end point stays in
    /// one cell over many poses of a climb.
    #[inline(always)]
    pub fn backed_walls(
        &self,
        centre: (i64, i64),
        back: (i64, i64),
        k: i64,
        mut visit: impl FnMut(f32, f32),
    ) {
        let (lx, ly) = (centre.0 & TILE_MASK, centre.1 & TILE_MASK);
        let reach = k + 1;
        debug_assert!((0..=14).contains(&k), "a window row fits in 32 bits");
        if lx < reach || ly < reach || lx + reach > TILE_MASK || ly + reach > TILE_MASK {
            return self.backed_walls_across_tiles(centre, back, k, visit);
        }
        // The window and its back neighbours lie in one tile: find the
        // candidates with bit operations.
        let Some(t) = self.tile_at(centre) else { return };
        let width = (1u32 << (2 * k + 1)) - 1;
        let x0 = (lx - k) as u32;
        let bx = (lx - k + back.0) as u32;
        for y in (ly - k) as usize..=(ly + k) as usize {
            let walls = (t.walls[y] >> x0) & width;
            if walls == 0 {
                continue;
            }
            let free = (t.free[(y as i64 + back.1) as usize] >> bx) & width;
            visit_row_means(t, y, x0 as usize, walls & free, &mut visit);
        }
    }

    /// [`Self::backed_walls`] for windows that cross tiles: the bits are
    /// gathered row by row. Kept out of line so the one-tile path stays
    /// small.
    #[inline(never)]
    fn backed_walls_across_tiles(
        &self,
        c: (i64, i64),
        back: (i64, i64),
        k: i64,
        mut visit: impl FnMut(f32, f32),
    ) {
        // The window and its back neighbours span cells c ± (k + 1): at
        // most two tiles each way (2k + 3 < 32), looked up once.
        let corner = (c.0 - k - 1, c.1 - k - 1);
        let (tx, ty) = (corner.0 >> TILE_SHIFT, corner.1 >> TILE_SHIFT);
        let tile_at = |i: i64, j: i64| self.slot((tx + i, ty + j)).and_then(|s| self.tiles[s].as_deref());
        let tiles = [[tile_at(0, 0), tile_at(1, 0)], [tile_at(0, 1), tile_at(1, 1)]];
        let tile_of =
            |x: i64, y: i64| tiles[((y >> TILE_SHIFT) - ty) as usize][((x >> TILE_SHIFT) - tx) as usize];
        let n = 2 * k + 1;
        let mask = (1u64 << n) - 1;
        // The walls and free bits of the n cells from (x, y) along +x, bit
        // i for cell x + i: the row's two tiles side by side in one word.
        let row = |x: i64, y: i64| -> (u32, u32) {
            let ly = (y & TILE_MASK) as usize;
            let pair = &tiles[((y >> TILE_SHIFT) - ty) as usize];
            let bits = |t: Option<&Tile>| {
                t.map_or((0, u64::from(u32::MAX)), |t| (u64::from(t.walls[ly]), u64::from(t.free[ly])))
            };
            let ((w0, f0), (w1, f1)) = (bits(pair[0]), bits(pair[1]));
            let shift = x - (tx << TILE_SHIFT);
            let (walls, free) = (w0 | w1 << TILE_SIDE, f0 | f1 << TILE_SIDE);
            (((walls >> shift) & mask) as u32, ((free >> shift) & mask) as u32)
        };
        for y in c.1 - k..=c.1 + k {
            let (walls, _) = row(c.0 - k, y);
            if walls == 0 {
                continue;
            }
            let (_, free) = row(c.0 - k + back.0, y + back.1);
            let mut candidates = walls & free;
            while candidates != 0 {
                let x = c.0 - k + i64::from(candidates.trailing_zeros());
                candidates &= candidates - 1;
                if let Some(t) = tile_of(x, y) {
                    let [mx, my] = t.wall_mean((x & TILE_MASK) as usize, (y & TILE_MASK) as usize);
                    visit(mx, my);
                }
            }
        }
    }

    /// Calls `visit(mean x, mean y)` for every wall cell within `k` cells
    /// of `centre` (at most 14), row by row from the lowest, each row
    /// from the left: the wall cells around a hit, from which the scan's
    /// information takes the wall's direction. Within one tile the walls
    /// are found from the tile's bits; across tiles cell by cell.
    #[inline]
    pub fn wall_means_around(&self, centre: (i64, i64), k: i64, mut visit: impl FnMut(f32, f32)) {
        debug_assert!((0..=14).contains(&k), "a window row fits in 32 bits");
        let (lx, ly) = (centre.0 & TILE_MASK, centre.1 & TILE_MASK);
        if lx < k || ly < k || lx + k > TILE_MASK || ly + k > TILE_MASK {
            for y in centre.1 - k..=centre.1 + k {
                for x in centre.0 - k..=centre.0 + k {
                    let cell = self.get((x, y));
                    if cell.is_wall(self.wall_threshold) {
                        visit(cell.mean_x, cell.mean_y);
                    }
                }
            }
            return;
        }
        let Some(t) = self.tile_at(centre) else { return };
        let width = (1u32 << (2 * k + 1)) - 1;
        let x0 = (lx - k) as u32;
        for y in (ly - k) as usize..=(ly + k) as usize {
            visit_row_means(t, y, x0 as usize, (t.walls[y] >> x0) & width, &mut visit);
        }
    }
}

/// Calls `visit(mean x, mean y)` for each cell of row `y` of `t` whose bit
/// is set in `bits` (bit i: column `x0 + i`), from the left.
#[inline(always)]
fn visit_row_means(t: &Tile, y: usize, x0: usize, mut bits: u32, visit: &mut impl FnMut(f32, f32)) {
    while bits != 0 {
        let x = x0 + bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let [mx, my] = t.wall_mean(x, y);
        visit(mx, my);
    }
}
