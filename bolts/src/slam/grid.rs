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

use serde::{Deserialize, Serialize};
use std::sync::{Arc, OnceLock};

use squall_core::geometry::{Real, round_small};

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

/// Fraction bits of [`TiledGrid::fixed_of`]'s fixed-point positions: a
/// position is off by at most 2⁻²⁴ cells (3 nm at 5 cm cells).
pub const FIXED_BITS: u32 = 24;
const FIXED_ONE: Real = (1u64 << FIXED_BITS) as Real;

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
}

/// A square block of cells, with one bit per cell saying whether it is a
/// wall and one saying whether it is free, so the scan matcher finds the
/// few candidate cells of a beam with bit operations before reading any.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "TileWire", try_from = "TileWire")]
pub struct Tile {
    cells: Box<Cells>,
    /// Bit x of `walls[y]`: cell (x, y) of the tile is a wall.
    walls: [u32; TILE_SIDE],
    /// Bit x of `free[y]`: cell (x, y) is free (see [`Cell::is_free`]).
    free: [u32; TILE_SIDE],
    /// The cells' digest once computed; every write clears it.
    digest: OnceLock<u128>,
}

/// Cells held as two arrays: the counts, which every beam crossing a cell
/// reads and writes, and the mean hit points, which only hits and the scan
/// matcher read. Integration streams through the counts alone, half the
/// bytes of whole cells (it waits on memory, not on arithmetic).
#[derive(Debug, Clone, PartialEq)]
struct Cells {
    counts: [Counts; TILE_SIDE * TILE_SIDE],
    means: [[f32; 2]; TILE_SIDE * TILE_SIDE],
}

/// A cell's hits and visits (see [`Cell`]), in 16 bits each: integration
/// reads and writes these for every cell a beam crosses, and at half the
/// bytes it waits on memory less.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Counts {
    hits: u16,
    visits: u16,
}

/// The most visits a cell counts. A visit beyond halves the cell's hits and
/// visits: the occupancy the wall test reads stays (to within one hit), and
/// later beams weigh a little more. A cell reaches this only after tens of
/// thousands of beams crossed it (none does in the logs of this repository).
pub const MAX_VISITS: u32 = u16::MAX as u32;

impl Cell {
    /// Halves hits and visits while visits exceed [`MAX_VISITS`], and
    /// keeps hits at most visits.
    #[inline]
    fn keep_countable(&mut self) {
        while self.visits > MAX_VISITS {
            self.visits /= 2;
            self.hits /= 2;
        }
        self.hits = self.hits.min(self.visits);
    }
}

impl Default for Cells {
    fn default() -> Self {
        Cells { counts: [Counts::default(); TILE_SIDE * TILE_SIDE], means: [[0.0; 2]; TILE_SIDE * TILE_SIDE] }
    }
}

impl Cells {
    /// Cell `i` (row-major) as one value.
    #[inline]
    fn get(&self, i: usize) -> Cell {
        let (Counts { hits, visits }, [mean_x, mean_y]) = (self.counts[i], self.means[i]);
        Cell { mean_x, mean_y, hits: hits.into(), visits: visits.into() }
    }

    /// Stores cell `i`, whose counts must be countable (at most
    /// [`MAX_VISITS`] visits, no more hits than visits).
    #[inline]
    fn set(&mut self, i: usize, c: Cell) {
        debug_assert!(c.visits <= MAX_VISITS && c.hits <= c.visits, "{c:?}");
        self.counts[i] = Counts { hits: c.hits as u16, visits: c.visits as u16 };
        self.means[i] = [c.mean_x, c.mean_y];
    }

    fn iter(&self) -> impl Iterator<Item = Cell> + '_ {
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

/// A tile as it travels between processes: its cells row by row and its
/// bit rows.
#[derive(Serialize, Deserialize)]
struct TileWire {
    cells: Vec<Cell>,
    walls: Vec<u32>,
    free: Vec<u32>,
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
    fn visit(&mut self, i: usize, threshold: Real) {
        let counts = &mut self.cells.counts[i];
        if counts.hits == 0 && threshold > 0.0 && counts.visits < u16::MAX {
            counts.visits += 1;
        } else {
            self.update(i % TILE_SIDE, i / TILE_SIDE, threshold, |cell| cell.visits += 1);
        }
    }

    /// Changes cell (`x`, `y`) of the tile with `f` and keeps its bits.
    #[inline]
    fn update(&mut self, x: usize, y: usize, threshold: Real, f: impl FnOnce(&mut Cell)) {
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

/// Hashes tile addresses for [`TiledGrid::distinct_tiles`], which runs
/// every reading over every particle's tiles: an address is unique already,
/// so a multiplication and a fold spread it (with SipHash, the default,
/// hashing took about 4% of a whole ACES run, `perf`; with this, 1.8%).
#[derive(Debug, Default)]
struct AddressHasher(u64);

impl std::hash::Hasher for AddressHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 29)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_usize(b as usize ^ self.0 as usize);
        }
    }

    fn write_usize(&mut self, n: usize) {
        self.0 = (n as u64).wrapping_mul(squall_topology::hash::GOLDEN_GAMMA);
    }
}

type BuildAddressHasher = std::hash::BuildHasherDefault<AddressHasher>;

/// Bytes one tile occupies.
pub const TILE_BYTES: usize = std::mem::size_of::<Cells>() + 8 * TILE_SIDE;

/// Occupancy above which a cell is a wall, unless set otherwise.
pub const DEFAULT_WALL_THRESHOLD: Real = 0.1;

impl Cell {
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
}

/// An occupancy grid that grows on demand; cell (0, 0) is at world
/// (`origin`), cells are `resolution` metres.
///
/// A grid that arrives from elsewhere (another process, a file) is checked
/// as it is read: a finite positive resolution, an index whose size
/// matches its dimensions, finite mean hit points, and wall and free bits
/// that agree with the cells. A grid that fails is an error, not a later
/// panic or a silently wrong match.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(into = "GridWire", try_from = "GridWire")]
pub struct TiledGrid {
    resolution: Real,
    /// 1 / `resolution`: a cell lookup multiplies rather than divides.
    per_metre: Real,
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
    #[serde(skip)]
    clones: u64,
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

impl TiledGrid {
    /// An empty grid whose walls are cells with occupancy above
    /// [`DEFAULT_WALL_THRESHOLD`].
    pub fn new(resolution: Real, origin: (Real, Real)) -> Self {
        TiledGrid {
            resolution,
            per_metre: 1.0 / resolution,
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
        (floor((x - self.origin.0) * self.per_metre), floor((y - self.origin.1) * self.per_metre))
    }

    /// The position (`x`, `y`) in cells, as fixed-point numbers with
    /// [`FIXED_BITS`] fraction bits, so that a scan matcher finds a beam's
    /// cell by adding the beam's [`Self::fixed_length`]s and shifting
    /// (`>> FIXED_BITS` is a floor) rather than flooring floats per beam.
    /// `None` beyond 2³⁰ cells of the origin (tens of thousands of
    /// kilometres), where such sums could overflow.
    #[inline]
    pub fn fixed_of(&self, x: Real, y: Real) -> Option<(i64, i64)> {
        const LIMIT: Real = (1u64 << (30 + FIXED_BITS)) as Real;
        let scale = self.per_metre * FIXED_ONE;
        let (fx, fy) = ((x - self.origin.0) * scale, (y - self.origin.1) * scale);
        (fx.abs() < LIMIT && fy.abs() < LIMIT).then_some((fx as i64, fy as i64))
    }

    /// A displacement of `metres` in [`Self::fixed_of`]'s units (saturating
    /// far beyond any range a laser measures).
    #[inline]
    pub fn fixed_length(&self, metres: Real) -> i64 {
        let v = metres * self.per_metre * FIXED_ONE;
        if v.abs() < (1u64 << 50) as Real { round_small(v).1 } else { v as i64 }
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
            Some(t) => t.cells.get(((c.1 & TILE_MASK) as usize) * TILE_SIDE + (c.0 & TILE_MASK) as usize),
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

    /// The tile at `slot`, created if missing, cloned first if another map
    /// shares it.
    #[inline]
    fn tile_mut(&mut self, slot: usize) -> &mut Tile {
        let entry = self.tiles[slot].get_or_insert_with(|| Arc::new(Tile::default()));
        if Arc::strong_count(entry) > 1 {
            self.clones += 1;
        }
        let tile = Arc::make_mut(entry);
        // Every write goes through here: the content is about to change.
        tile.digest.take();
        tile
    }

    /// Changes cell `c` with `f`: its tile is created, or cloned if another
    /// map shares it; the wall and free bits follow the new value. Counts
    /// past [`MAX_VISITS`] are halved, and hits kept at most visits.
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
        self.tile_mut(slot).update((c.0 & TILE_MASK) as usize, (c.1 & TILE_MASK) as usize, threshold, f);
    }

    /// Adds one beam from cell `from` to cell `to`: every cell on the line
    /// before `to` gets a visit; `to` gets a hit at `end` if given, nothing
    /// otherwise (a beam cut at the usable range). The line is walked tile
    /// by tile, so each tile is looked up and made writable once per beam.
    pub fn add_beam(&mut self, from: (i64, i64), to: (i64, i64), end: Option<(f32, f32)>) {
        self.reserve_cells((from.0.min(to.0), from.1.min(to.1)), (from.0.max(to.0), from.1.max(to.1)));
        let threshold = self.wall_threshold;
        // Bresenham's line (as `LineStepper` walks it), in the coordinates
        // of the tile at hand: a step is an add, leaving the tile a compare,
        // and the end is reached after max(|dx|, |dy|) steps.
        let d = ((to.0 - from.0).abs(), -(to.1 - from.1).abs());
        let step = (if from.0 < to.0 { 1 } else { -1 }, if from.1 < to.1 { 1 } else { -1 });
        let mut err = d.0 + d.1;
        let mut remaining = d.0.max(-d.1);
        let mut c = from;
        loop {
            let key = (c.0 >> TILE_SHIFT, c.1 >> TILE_SHIFT);
            let slot = self.slot(key).expect("the beam's box is reserved");
            let tile = self.tile_mut(slot);
            let (mut x, mut y) = (c.0 & TILE_MASK, c.1 & TILE_MASK);
            loop {
                if remaining == 0 {
                    if let Some((ex, ey)) = end {
                        tile.update(x as usize, y as usize, threshold, |cell| cell.add_hit(ex, ey));
                    }
                    return;
                }
                tile.visit(y as usize * TILE_SIDE + x as usize, threshold);
                let e2 = 2 * err;
                if e2 >= d.1 {
                    err += d.1;
                    x += step.0;
                }
                if e2 <= d.0 {
                    err += d.0;
                    y += step.1;
                }
                remaining -= 1;
                if (x as u64) >= TILE_SIDE as u64 || (y as u64) >= TILE_SIDE as u64 {
                    break;
                }
            }
            c = ((key.0 << TILE_SHIFT) + x, (key.1 << TILE_SHIFT) + y);
        }
    }

    /// GMapping's kernel search for one beam: the squared distance (m²)
    /// from the beam's end point `hit` to the nearest mean hit point among
    /// the wall cells within `k` cells of it whose neighbour at `back` (one
    /// step back towards the laser, each component in −1..=1) is free;
    /// `None` if there is none. `k` is at most 14.
    #[inline]
    pub fn nearest_backed_wall(&self, hit: (Real, Real), back: (i64, i64), k: i64) -> Option<Real> {
        let (hx, hy) = (hit.0 as f32, hit.1 as f32);
        let mut best = f32::INFINITY;
        self.backed_walls(self.cell_of(hit.0, hit.1), back, k, |mx, my| {
            best = best.min((hx - mx).powi(2) + (hy - my).powi(2));
        });
        (best < f32::INFINITY).then_some(Real::from(best))
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
        let Some(t) = self
            .slot((centre.0 >> TILE_SHIFT, centre.1 >> TILE_SHIFT))
            .and_then(|s| self.tiles[s].as_deref())
        else {
            return;
        };
        let width = (1u32 << (2 * k + 1)) - 1;
        let x0 = (lx - k) as u32;
        let bx = (lx - k + back.0) as u32;
        for y in (ly - k) as usize..=(ly + k) as usize {
            let walls = (t.walls[y] >> x0) & width;
            if walls == 0 {
                continue;
            }
            let free = (t.free[(y as i64 + back.1) as usize] >> bx) & width;
            let mut candidates = walls & free;
            while candidates != 0 {
                let x = x0 as usize + candidates.trailing_zeros() as usize;
                candidates &= candidates - 1;
                let [mx, my] = t.cells.means[y * TILE_SIDE + x];
                visit(mx, my);
            }
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
                    let [mx, my] =
                        t.cells.means[((y & TILE_MASK) as usize) * TILE_SIDE + (x & TILE_MASK) as usize];
                    visit(mx, my);
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

    /// Tiles of this grid that none of `others` holds in the same place:
    /// what it adds to them when it is their copy or they are its (a copy
    /// keeps each shared tile in its place). Unlike
    /// [`Self::distinct_tiles`], no hashing: cheap enough per particle.
    pub fn tiles_beyond(&self, others: &[&TiledGrid]) -> usize {
        let held_by = |o: &TiledGrid, key: (i64, i64), tile: &Arc<Tile>| {
            o.slot(key).and_then(|i| o.tiles[i].as_ref()).is_some_and(|t| Arc::ptr_eq(t, tile))
        };
        let mut beyond = 0;
        for (slot, tile) in self.tiles.iter().enumerate() {
            let Some(tile) = tile else { continue };
            let key = (
                self.tile_min.0 + (slot % self.tiles_wide) as i64,
                self.tile_min.1 + (slot / self.tiles_wide) as i64,
            );
            beyond += usize::from(!others.iter().any(|o| held_by(o, key, tile)));
        }
        beyond
    }

    /// Distinct tiles over several grids (shared tiles counted once), and
    /// their bytes: the memory the maps really take.
    pub fn distinct_tiles<'a>(grids: impl IntoIterator<Item = &'a TiledGrid>) -> (usize, usize) {
        let mut seen = std::collections::HashSet::<_, BuildAddressHasher>::default();
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_grid_survives_the_wire_and_a_damaged_one_is_refused() {
        let mut g = TiledGrid::new(0.05, (1.0, -2.0));
        for x in -40..40 {
            g.update((x, 3), |c| c.add_hit(x as f32 * 0.05, 0.15));
            g.update((x, 2), |c| c.visits += 1);
        }
        let bytes = postcard::to_stdvec(&g).unwrap();
        let back: TiledGrid = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(back.tile_count(), g.tile_count());
        for x in -45..45 {
            for y in 0..5 {
                assert_eq!(back.get((x, y)), g.get((x, y)), "({x}, {y})");
            }
        }
        assert_eq!(back.cell_of(0.3, 0.3), g.cell_of(0.3, 0.3));
        let wire = || GridWire::from(g.clone());
        let refused = |w: GridWire| TiledGrid::try_from(w).unwrap_err();
        assert!(refused(GridWire { resolution: 0.0, ..wire() }).contains("resolution"));
        assert!(refused(GridWire { origin: (Real::NAN, 0.0), ..wire() }).contains("origin"));
        assert!(refused(GridWire { wall_threshold: 2.0, ..wire() }).contains("threshold"));
        assert!(refused(GridWire { tiles_wide: wire().tiles_wide + 1, ..wire() }).contains("holds"));
        assert!(refused(GridWire { tiles_wide: usize::MAX, tiles_high: 2, ..wire() }).contains("holds"));
        let mut flipped = wire();
        let tile = flipped.tiles.iter_mut().flatten().next().unwrap();
        Arc::make_mut(tile).walls[3] ^= 1;
        assert!(refused(flipped).contains("bits disagree"));
        let mut poisoned = wire();
        let tile = poisoned.tiles.iter_mut().flatten().find(|t| t.cells.iter().any(|c| c.hits > 0)).unwrap();
        let cells = &mut Arc::make_mut(tile).cells;
        let i = cells.counts.iter().position(|c| c.hits > 0).unwrap();
        cells.means[i][0] = f32::INFINITY;
        assert!(refused(poisoned).contains("not finite"));
        // Damaged bytes: an error or a valid grid, never a panic.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..500 {
            let mut bad = bytes.clone();
            let i = rng.random_range(0..bad.len());
            bad[i] = rng.random();
            if let Ok(grid) = postcard::from_bytes::<TiledGrid>(&bad) {
                let _ = grid.get((0, 3));
            }
        }
    }

    #[test]
    fn fixed_point_cells_agree_with_cell_of() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let g = TiledGrid::new(0.05, (-3.2, 7.9));
        let to_cell = |f: (i64, i64)| (f.0 >> FIXED_BITS, f.1 >> FIXED_BITS);
        let mut checked = 0;
        for _ in 0..100_000 {
            let laser = (rng.random_range(-500.0..500.0), rng.random_range(-500.0..500.0));
            let beam = (rng.random_range(-80.0..80.0), rng.random_range(-80.0..80.0));
            let end = (laser.0 + beam.0, laser.1 + beam.1);
            let want = g.cell_of(end.0, end.1);
            // Within a few 2⁻²⁴ cells of a cell's edge either side may win.
            let inside = |v: f64| {
                let frac = v / 0.05 - (v / 0.05).floor();
                frac > 1e-6 && frac < 1.0 - 1e-6
            };
            if !(inside(end.0 + 3.2) && inside(end.1 - 7.9)) {
                continue;
            }
            let base = g.fixed_of(laser.0, laser.1).unwrap();
            let cell = to_cell((base.0 + g.fixed_length(beam.0), base.1 + g.fixed_length(beam.1)));
            assert_eq!(cell, want, "laser {laser:?} beam {beam:?}");
            checked += 1;
        }
        assert!(checked > 99_000, "{checked}");
        assert_eq!(g.fixed_of(1e9, 0.0), None, "beyond 2^30 cells");
        assert_eq!(g.fixed_length(0.05), 1 << FIXED_BITS);
        assert_eq!(g.fixed_length(-0.05), -(1 << FIXED_BITS));
    }

    #[test]
    fn cells_anywhere_grow_the_grid() {
        let mut g = TiledGrid::new(0.05, (0.0, 0.0));
        for c in [(0, 0), (-1, -1), (100, -300), (-5000, 7000)] {
            g.update(c, |cell| {
                cell.hits += 3;
                cell.visits += 3;
            });
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
        assert_eq!((b.tiles_beyond(&[&a]), a.tiles_beyond(&[&b]), b.tiles_beyond(&[])), (1, 1, 4));
        assert_eq!(a.tiles_beyond(&[&b, &a]), 0);
        // Shared tiles are found by place even after an index grew.
        b.update((-500, 300), |c| c.hits += 1);
        assert_eq!((b.tiles_beyond(&[&a]), a.tiles_beyond(&[&b])), (2, 1));
        assert_eq!(a.get((5, 0)).hits, 0, "the original is untouched");
        assert_eq!(b.get((5, 0)).hits, 1);
    }

    #[test]
    fn exports_the_explored_area() {
        let mut g = TiledGrid::new(0.5, (10.0, 20.0));
        g.update((1, 2), |c| *c = Cell { hits: 1, visits: 4, ..Cell::default() });
        g.update((-1, 0), |c| c.visits = 2);
        let o = g.to_occupancy();
        assert_eq!((o.width, o.height), (64, 32), "two tiles side by side");
        assert_eq!(o.origin, (10.0 - 32.0 * 0.5, 20.0));
        let (x, y) = o.cell_of(10.75, 21.25).unwrap();
        assert_eq!(o.get(x, y), 25);
        let (x, y) = o.cell_of(10.0 - 0.25, 20.25).unwrap();
        assert_eq!(o.get(x, y), 0, "visited, never hit: free");
        assert_eq!(o.get(0, 0), squall_core::occupancy::UNKNOWN);
    }

    #[test]
    fn integer_floor_matches_floor() {
        for v in [-2.5, -2.0, -1e-12, 0.0, 1e-12, 0.999_999, 1.0, 3.7, -1e9 - 0.5, 1e12 + 0.25] {
            assert_eq!(floor(v), v.floor() as i64, "{v}");
        }
    }

    #[test]
    fn kernel_search_matches_a_cell_by_cell_search() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0));
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // Cells over four tiles around the origin: walls, free cells and
        // cells at the threshold (neither).
        for _ in 0..1500 {
            let c = (rng.random_range(-40..40), rng.random_range(-40..40));
            let (hits, visits) = match rng.random_range(0..3) {
                0 => (rng.random_range(1..4), 4),
                1 => (0, rng.random_range(1..6)),
                _ => (1, 10),
            };
            let m = (c.0 as f32 * 0.1 + 0.05, c.1 as f32 * 0.1 + 0.02);
            g.update(c, |cell| *cell = Cell { mean_x: m.0, mean_y: m.1, hits, visits });
        }
        let reference = |hit: (Real, Real), back: (i64, i64), k: i64| {
            let c = g.cell_of(hit.0, hit.1);
            let mut best: Option<f32> = None;
            for y in c.1 - k..=c.1 + k {
                for x in c.0 - k..=c.0 + k {
                    let cell = g.get((x, y));
                    let behind = g.get((x + back.0, y + back.1));
                    let wall = cell.visits > 0 && cell.hits as Real > 0.1 * cell.visits as Real;
                    let free = behind.visits == 0 || (behind.hits as Real) < 0.1 * behind.visits as Real;
                    if wall && free {
                        let d2 = (hit.0 as f32 - cell.mean_x).powi(2) + (hit.1 as f32 - cell.mean_y).powi(2);
                        best = Some(best.map_or(d2, |b| b.min(d2)));
                    }
                }
            }
            best.map(Real::from)
        };
        let mut matched = 0;
        for _ in 0..3000 {
            let hit = (rng.random_range(-4.5..4.5), rng.random_range(-4.5..4.5));
            for back in [(-1, -1), (-1, 0), (0, 1), (1, 1), (1, -1), (0, 0)] {
                for k in [0, 1, 2] {
                    let got = g.nearest_backed_wall(hit, back, k);
                    assert_eq!(got, reference(hit, back, k), "{hit:?} back {back:?} k {k}");
                    matched += usize::from(got.is_some());
                }
            }
        }
        assert!(matched > 10_000, "the data exercises matches: {matched}");
    }

    #[test]
    fn a_beam_updates_the_cells_of_its_line_across_tiles() {
        let mut fast = TiledGrid::new(0.1, (0.0, 0.0));
        let mut slow = TiledGrid::new(0.1, (0.0, 0.0));
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for i in 0..400 {
            let from = (rng.random_range(-10..10), rng.random_range(-10..10));
            let to = (rng.random_range(-100..100), rng.random_range(-100..100));
            let end = (i % 3 != 0).then_some((to.0 as f32 * 0.1 + 0.03, to.1 as f32 * 0.1 + 0.07));
            fast.add_beam(from, to, end);
            squall_core::geometry::line_cells(from, to, |c| {
                if c != to {
                    slow.update(c, |cell| cell.visits += 1);
                }
            });
            if let Some((x, y)) = end {
                slow.update(to, |cell| cell.add_hit(x, y));
            }
        }
        assert_eq!(fast.cell_bounds(), slow.cell_bounds());
        let ((x0, y0), (x1, y1)) = fast.cell_bounds().unwrap();
        for y in y0..=y1 {
            for x in x0..=x1 {
                assert_eq!(fast.get((x, y)), slow.get((x, y)), "({x}, {y})");
            }
        }
        // The bits agree too: every window finds the same wall.
        for y in y0..=y1 {
            for x in x0..=x1 {
                let hit = (x as Real * 0.1 + 0.05, y as Real * 0.1 + 0.05);
                assert_eq!(
                    fast.nearest_backed_wall(hit, (1, 0), 1),
                    slow.nearest_backed_wall(hit, (1, 0), 1)
                );
            }
        }
    }

    #[test]
    fn a_shared_tile_is_cloned_once_per_beam() {
        let mut a = TiledGrid::new(0.1, (0.0, 0.0));
        a.add_beam((0, 0), (20, 0), Some((2.05, 0.05)));
        let mut b = a.clone();
        b.take_clone_count();
        b.add_beam((0, 1), (25, 1), Some((2.55, 0.15)));
        assert_eq!(b.take_clone_count(), 1, "26 cells, one tile, one clone");
        assert_eq!(a.get((5, 1)).visits, 0, "the original is untouched");
    }

    #[test]
    fn counts_past_the_limit_are_halved() {
        let mut g = TiledGrid::new(0.1, (0.0, 0.0));
        let n = MAX_VISITS + 1;
        for _ in 0..n {
            g.add_beam((0, 0), (2, 0), Some((0.25, 0.05)));
        }
        // A crossed cell (no hits) and the end cell (all hits) each saw one
        // visit more than a cell counts: halved.
        let crossed = g.get((1, 0));
        assert_eq!((crossed.hits, crossed.visits), (0, n / 2));
        let end = g.get((2, 0));
        assert_eq!((end.hits, end.visits), (n / 2, n / 2));
        assert!(end.is_wall(g.wall_threshold()) && crossed.is_free(g.wall_threshold()));
        // And they go on counting from there.
        g.add_beam((0, 0), (2, 0), Some((0.25, 0.05)));
        assert_eq!(g.get((1, 0)).visits, n / 2 + 1);
        assert_eq!((g.get((2, 0)).hits, g.get((2, 0)).visits), (n / 2 + 1, n / 2 + 1));
        // A write of any value keeps the counts countable.
        g.update((5, 5), |c| *c = Cell { hits: 9, visits: 3 * MAX_VISITS, ..Cell::default() });
        let c = g.get((5, 5));
        assert!(c.visits <= MAX_VISITS && c.hits <= c.visits, "{c:?}");
    }

    #[test]
    fn a_tile_from_the_wire_with_uncountable_cells_is_refused() {
        let wire = |c: Cell| TileWire {
            cells: vec![c; TILE_SIDE * TILE_SIDE],
            walls: vec![0; TILE_SIDE],
            free: vec![u32::MAX; TILE_SIDE],
        };
        let e = Tile::try_from(wire(Cell { visits: MAX_VISITS + 1, ..Cell::default() })).unwrap_err();
        assert!(e.contains("65536 visits") && e.contains("(0, 0)"), "{e}");
        let e = Tile::try_from(wire(Cell { hits: 2, visits: 1, ..Cell::default() })).unwrap_err();
        assert!(e.contains("2 hits in 1 visits"), "{e}");
        assert!(Tile::try_from(wire(Cell { visits: MAX_VISITS, ..Cell::default() })).is_ok());
    }

    #[test]
    fn occupancy_and_mean_hit() {
        let mut c = Cell { visits: 1, ..Cell::default() };
        for (x, y) in [(0.5, 2.0), (1.0, 3.0), (1.5, 4.0)] {
            c.add_hit(x, y);
        }
        assert_eq!(c.occupancy(), Some(0.75));
        assert_eq!(c.mean(), Some((1.0, 3.0)));
        assert_eq!(Cell::default().occupancy(), None);
    }
}
