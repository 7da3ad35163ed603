//! The beam cache: what a climb remembers of the map, so that a beam costs
//! one table read and a branch-free minimum.

use squall_core::geometry::Real;

use super::scan::{Direction, back_code};
use crate::slam::grid::{FIXED_BITS, TiledGrid};

/// What a climb remembers of the map: for each (cell, step back) it has
/// looked at, the candidate mean hit points there, in a direct-mapped
/// table whose slot holds up to [`INLINE`] candidates itself, so that a
/// beam costs one slot read and a branch-free minimum. The climb's steps
/// are a cell or less, so its poses keep landing beams in the same few
/// cells of each beam's neighbourhood, and those are read from the map
/// once. The result is exactly that of [`TiledGrid::nearest_backed_wall`].
#[derive(Debug)]
pub(super) struct BeamCache {
    slots: Box<[Slot; CACHE_SLOTS]>,
    /// Slots of other generations are empty: forgetting a map is a counter
    /// increment, not a pass over the table.
    pub(super) generation: u32,
    /// Candidates beyond a slot's first [`INLINE`] (a window with more
    /// walls than that is rare).
    pub(super) overflow: Vec<(f32, f32)>,
}

/// Candidates a slot holds itself.
pub(super) const INLINE: usize = 4;

/// One remembered (cell, step back) and its candidates: the first
/// [`INLINE`] in `xs`/`ys` (unused ones at infinity, so that they never
/// win), the rest in the overflow from `overflow_start`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(16))]
struct Slot {
    /// First, so that each is one aligned vector load.
    xs: [f32; INLINE],
    ys: [f32; INLINE],
    /// The cell, packed by [`cell_key`].
    key: u64,
    /// The generation in the high bits, the step back in the low four.
    tag: u32,
    overflow_start: u32,
    /// Candidates beyond the inline ones.
    overflow_len: u16,
}

// `nearest_inline_sse` loads `xs` and `ys` as aligned vectors.
const _: () = assert!(
    std::mem::offset_of!(Slot, xs) % 16 == 0
        && std::mem::offset_of!(Slot, ys) % 16 == 0
        && std::mem::align_of::<Slot>() >= 16
);

const EMPTY_SLOT: Slot = Slot {
    key: 0,
    tag: 0,
    overflow_len: 0,
    overflow_start: 0,
    xs: [f32::INFINITY; INLINE],
    ys: [f32::INFINITY; INLINE],
};
/// Table slots (a power of two).
const CACHE_SLOTS: usize = 1 << 13;
/// Overflow candidates kept before the cache starts over (bounds its
/// memory).
pub(super) const CACHE_CAPACITY: usize = 1 << 14;
/// Generations fit the tag's 28 high bits.
const GENERATIONS: u32 = 1 << 28;

impl Default for BeamCache {
    fn default() -> Self {
        BeamCache {
            slots: vec![EMPTY_SLOT; CACHE_SLOTS].into_boxed_slice().try_into().expect("CACHE_SLOTS slots"),
            generation: 1,
            overflow: Vec::new(),
        }
    }
}

impl BeamCache {
    /// Empties the cache (before matching against another map).
    pub(super) fn forget(&mut self) {
        self.overflow.clear();
        self.generation += 1;
        if self.generation == GENERATIONS {
            self.slots.fill(EMPTY_SLOT);
            self.generation = 1;
        }
    }

    /// [`TiledGrid::nearest_backed_wall`] for an end point `hit` in cell `c`.
    #[inline(always)]
    pub(super) fn nearest(
        &mut self,
        grid: &TiledGrid,
        c: (i64, i64),
        hit: (f32, f32),
        back: (i64, i64),
        back_code: u32,
        k: i64,
    ) -> Option<Real> {
        let Some(key) = cell_key(c) else {
            return uncached_nearest(grid, c, hit, back, k);
        };
        let best = self.cached_distance(grid, c, key, hit, (back, back_code), k, &mut (self.generation << 4));
        (best < f32::INFINITY).then_some(Real::from(best))
    }

    /// The least squared distance from `hit` to the candidates of cell `c`
    /// (packed: `key`) seen with step back `back` (and its code), from the
    /// table, filling the cell's slot first if it does not hold it.
    /// `generation` is the current generation shifted into a tag, kept by
    /// the caller across a run of beams; a fill that empties the table
    /// renews it.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn cached_distance(
        &mut self,
        grid: &TiledGrid,
        c: (i64, i64),
        key: u64,
        hit: (f32, f32),
        (back, back_code): ((i64, i64), u32),
        k: i64,
        generation: &mut u32,
    ) -> f32 {
        let index = slot_index(key, back_code);
        if !self.holds(index, key, *generation | back_code) {
            self.fill(index, grid, c, key, back, k);
            *generation = self.generation << 4;
        }
        self.distance(index, hit)
    }

    /// Whether slot `index` holds the cell `key` with `tag` (the current
    /// generation and the step back).
    #[inline(always)]
    fn holds(&self, index: usize, key: u64, tag: u32) -> bool {
        let slot = &self.slots[index];
        slot.tag == tag && slot.key == key
    }

    /// Stores in slot `index` the candidates of cell `c` (packed: `key`)
    /// seen with step back `back`. Out of line: the hot loop stays small.
    #[inline(never)]
    fn fill(&mut self, index: usize, grid: &TiledGrid, c: (i64, i64), key: u64, back: (i64, i64), k: i64) {
        if self.overflow.len() > CACHE_CAPACITY {
            self.forget();
        }
        let tag = (self.generation << 4) | back_code(back);
        let BeamCache { slots, overflow, .. } = self;
        let slot = &mut slots[index];
        *slot = Slot { key, tag, ..EMPTY_SLOT };
        let start = overflow.len();
        let mut found = 0;
        grid.backed_walls(c, back, k, |mx, my| {
            if found < INLINE {
                slot.xs[found] = mx;
                slot.ys[found] = my;
            } else {
                overflow.push((mx, my));
            }
            found += 1;
        });
        if found > INLINE {
            slot.overflow_start = start as u32;
            slot.overflow_len = (found - INLINE) as u16;
        }
    }

    /// The least squared distance from `hit` to the candidates of slot
    /// `index` (infinite if it has none).
    #[inline(always)]
    fn distance(&self, index: usize, hit: (f32, f32)) -> f32 {
        let slot = &self.slots[index];
        let best = nearest_inline(slot, hit.0, hit.1);
        if slot.overflow_len > 0 { self.overflow_distance(slot, hit, best) } else { best }
    }

    /// [`Self::distance`] over a slot's overflow candidates.
    #[cold]
    fn overflow_distance(&self, slot: &Slot, hit: (f32, f32), mut best: f32) -> f32 {
        let start = slot.overflow_start as usize;
        for &(mx, my) in &self.overflow[start..start + slot.overflow_len as usize] {
            best = best.min((hit.0 - mx).powi(2) + (hit.1 - my).powi(2));
        }
        best
    }

    /// For each beam of `run` (at most `N`, a power of two) with the laser
    /// at `laser` (whose fixed-point position is `base`): the exponents
    /// d²·`per_sigma` of the beams that match, packed in order into
    /// `exponents`; returns how many matched. [`Self::nearest`] beam by
    /// beam, as one loop with no call and no branch but the cache's.
    /// `SHORT`: the beams are [`Turned::short`](super::scan::Turned::short), so no cell needs a check
    /// that it fits the cache's key.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn match_run<const SHORT: bool, const N: usize>(
        &mut self,
        grid: &TiledGrid,
        laser: (Real, Real),
        base: (i64, i64),
        run: &[Direction],
        k: i64,
        per_sigma: Real,
        exponents: &mut [Real; N],
    ) -> usize {
        const { assert!(N.is_power_of_two()) };
        let mut matched = 0;
        let mut generation = self.generation << 4;
        for d in run {
            let c = ((base.0 + d.fixed.0) >> FIXED_BITS, (base.1 + d.fixed.1) >> FIXED_BITS);
            let hit = ((laser.0 + d.dx) as f32, (laser.1 + d.dy) as f32);
            let key = if SHORT { Some(packed_cell(c)) } else { cell_key(c) };
            let best = match key {
                Some(key) => {
                    self.cached_distance(grid, c, key, hit, (d.back, d.back_code), k, &mut generation)
                }
                None => uncached_nearest(grid, c, hit, d.back, k).map_or(f32::INFINITY, |d2| d2 as f32),
            };
            // `matched` never exceeds the beams seen, fewer than the
            // buffer's length: the mask only spares a bounds check.
            exponents[matched & (N - 1)] = Real::from(best) * per_sigma;
            matched += usize::from(best < f32::INFINITY);
        }
        matched
    }
}

/// A cell as one number (the cache's key), `None` beyond ±2³¹ cells
/// (thousands of kilometres), which are not cached.
#[inline(always)]
fn cell_key(c: (i64, i64)) -> Option<u64> {
    let fits = i32::try_from(c.0).is_ok() && i32::try_from(c.1).is_ok();
    fits.then(|| packed_cell(c))
}

/// The cache's key of a cell known to fit an `i32` each way.
#[inline(always)]
fn packed_cell(c: (i64, i64)) -> u64 {
    u64::from(c.0 as u32) | (u64::from(c.1 as u32) << 32)
}

/// The table slot of the cell packed as `key`, seen with step back
/// `back_code`.
#[inline(always)]
fn slot_index(key: u64, back_code: u32) -> usize {
    let (x, y) = (key as u32, (key >> 32) as u32);
    let hash = x.wrapping_mul(0x9e37_79b1) ^ y.wrapping_mul(0x85eb_ca77) ^ back_code;
    (hash.wrapping_mul(0xc2b2_ae3d) >> (32 - CACHE_SLOTS.trailing_zeros())) as usize
}

/// [`TiledGrid::nearest_backed_wall`] for cells the cache does not hold.
#[cold]
fn uncached_nearest(
    grid: &TiledGrid,
    c: (i64, i64),
    hit: (f32, f32),
    back: (i64, i64),
    k: i64,
) -> Option<Real> {
    let (hx, hy) = hit;
    let mut best = f32::INFINITY;
    grid.backed_walls(c, back, k, |mx, my| best = best.min((hx - mx).powi(2) + (hy - my).powi(2)));
    (best < f32::INFINITY).then_some(Real::from(best))
}

/// The least squared distance from (`hx`, `hy`) to a slot's inline
/// candidates: the four lanes of one SSE vector (the compiler does not
/// vectorize the scalar form, and this is a fifth of a beam's cost). No
/// operand is NaN, so the vector minimum is the scalar one.
#[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
#[inline(always)]
fn nearest_inline(slot: &Slot, hx: f32, hy: f32) -> f32 {
    // SAFETY: the build enables SSE (the `cfg` above; every x86-64
    // processor has it), which is all `nearest_inline_sse` requires.
    unsafe { nearest_inline_sse(slot, hx, hy) }
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
#[target_feature(enable = "sse")]
#[inline]
fn nearest_inline_sse(slot: &Slot, hx: f32, hy: f32) -> f32 {
    use std::arch::x86_64::{
        _mm_add_ps, _mm_cvtss_f32, _mm_load_ps, _mm_min_ps, _mm_mul_ps, _mm_set1_ps, _mm_shuffle_ps,
        _mm_sub_ps,
    };
    // SAFETY: each is a [f32; 4] at the start of a 16-byte-aligned slot (or
    // 16 bytes after it): 16 readable, aligned bytes. (Built from lanes,
    // the compiler loads them piece by piece.)
    let (xs, ys) = unsafe { (_mm_load_ps(slot.xs.as_ptr()), _mm_load_ps(slot.ys.as_ptr())) };
    let dx = _mm_sub_ps(_mm_set1_ps(hx), xs);
    let dy = _mm_sub_ps(_mm_set1_ps(hy), ys);
    let d = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy));
    let d = _mm_min_ps(d, _mm_shuffle_ps::<0b01_00_11_10>(d, d));
    _mm_cvtss_f32(_mm_min_ps(d, _mm_shuffle_ps::<0b10_11_00_01>(d, d)))
}

/// The least squared distance from (`hx`, `hy`) to a slot's inline
/// candidates.
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
#[inline(always)]
fn nearest_inline(slot: &Slot, hx: f32, hy: f32) -> f32 {
    let d: [f32; INLINE] = std::array::from_fn(|i| {
        let (dx, dy) = (hx - slot.xs[i], hy - slot.ys[i]);
        dx * dx + dy * dy
    });
    let lesser = |a: f32, b: f32| if a < b { a } else { b };
    lesser(lesser(d[0], d[2]), lesser(d[1], d[3]))
}
