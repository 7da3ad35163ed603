//! The scan matcher (GMapping's `ScanMatcher`: `score`,
//! `likelihoodAndScore`, `optimize`).
//!
//! For each beam, the end point is compared with the mean hit point of the
//! nearest wall cell (the grid's wall threshold) within `kernel` cells
//! whose neighbour one step back along the beam is free; the score adds
//! `exp(−d²/σ)` per matched beam and the log-likelihood `−d²/lσ` (or a
//! fixed penalty when nothing matches).
//! `optimize` climbs the score from an initial pose with moves of ±lstep in
//! x and y and ±astep in θ, halving the steps when no move improves,
//! `iterations` times; a [`Cutoff`] bounds the pose evaluations.
//!
//! Two deliberate changes. Poses are kept on a lattice of the finest step,
//! and a pose the climb has scored before is not scored again (it was not
//! better then, and the current score has only risen since), which saves
//! evaluations without changing the path. And GMapping locates the "free"
//! cell with `world2map(pfree − phit)` where `pfree` lies δ²√2 before the
//! hit, which only works through the map's offset; here it is the cell one
//! step back along the beam, as intended.
//!
//! One addition, [`Matcher::refine`]: when the climb matches too few beams
//! (odometry far off), a wide coarse search looks further.

use crate::slam::grid::{FIXED_BITS, TiledGrid};
use crate::slam::options::{Cutoff, SlamOptions};
use squall_core::geometry::{Pose2, Real, round_small};
use squall_core::sensor::LaserReading;

/// GMapping's log-likelihood of a beam that matches nothing, before
/// division by lσ.
const NULL_LIKELIHOOD: Real = -0.5;

/// One beam to match: its range and the (cos, sin) of its angle in the
/// laser frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Beam {
    range: Real,
    cos: Real,
    sin: Real,
}

impl Beam {
    /// (cos, sin) of the beam's direction with the laser at the heading
    /// whose (cos, sin) are (`c`, `s`): a rotation, no trigonometry.
    #[inline]
    fn turned(&self, c: Real, s: Real) -> (Real, Real) {
        (c * self.cos - s * self.sin, s * self.cos + c * self.sin)
    }
}

/// A reading prepared for matching: usable beams only.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PreparedScan {
    beams: Vec<Beam>,
    laser_offset: Pose2,
}

impl PreparedScan {
    /// Keeps valid beams up to `max_urange`, every (lskip+1)-th.
    pub fn new(scan: &LaserReading, o: &SlamOptions) -> Self {
        let beams = (0..scan.ranges.len())
            .filter(|&i| {
                i % (o.lskip + 1) == 0 && scan.is_valid(i) && Real::from(scan.ranges[i]) <= o.max_urange
            })
            .map(|i| {
                let (sin, cos) = scan.beam_angle(i).sin_cos();
                Beam { range: Real::from(scan.ranges[i]), cos, sin }
            })
            .collect();
        PreparedScan { beams, laser_offset: scan.laser_offset }
    }

    /// Every `stride`-th beam of this scan, into `out` (reused, so that
    /// nothing is allocated once warm): a coarse search scores many poses
    /// far apart, where a quarter of the beams tells them apart as well as
    /// all of them do.
    pub fn every_nth_into(&self, stride: usize, out: &mut PreparedScan) {
        out.beams.clear();
        out.beams.extend(self.beams.iter().step_by(stride.max(1)));
        out.laser_offset = self.laser_offset;
    }

    /// Beams that will be matched.
    pub fn len(&self) -> usize {
        self.beams.len()
    }

    /// Whether no beam is usable.
    pub fn is_empty(&self) -> bool {
        self.beams.is_empty()
    }
}

/// A beam seen with the laser at one heading: its end point relative to
/// the laser (world frame), in metres and in the grid's fixed-point cells
/// ([`TiledGrid::fixed_length`]), and the cell step from the end point back
/// towards the laser.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Direction {
    dx: Real,
    dy: Real,
    fixed: (i64, i64),
    back: (i64, i64),
    /// `back` as a number 0..9 (the beam cache's key).
    back_code: u32,
}

/// A step back (each component in −1..=1) as a number 0..9.
#[inline]
fn back_code(back: (i64, i64)) -> u32 {
    (back.0 + 3 * back.1 + 4) as u32
}

/// `round(−c·√2)`: the step back along a beam whose direction has
/// component `c`, one of −1, 0, 1.
#[inline]
fn step_back(c: Real) -> i64 {
    const HALF_STEP: Real = 0.5 * std::f64::consts::FRAC_1_SQRT_2;
    i64::from(c <= -HALF_STEP) - i64::from(c >= HALF_STEP)
}

/// A scan's beam directions at one heading.
#[derive(Debug, Clone, Default, PartialEq)]
struct Turned {
    dirs: Vec<Direction>,
    /// Whether every beam is shorter than 2³⁰ cells: then, with the laser
    /// anywhere [`TiledGrid::fixed_of`] places it, every end point's cell
    /// fits in an `i32` (the cache's key) without a check per beam.
    short: bool,
}

/// Beam length, in fixed-point units, up to which [`Turned::short`] holds.
const SHORT_BEAM: i64 = 1 << (30 + FIXED_BITS);

/// The directions of every beam with the laser at heading `theta`. Moves
/// that only translate keep the heading, so the hill climber computes these
/// once per heading rather than once per pose; each beam's direction is
/// its laser-frame direction rotated, with no trigonometry per beam.
fn directions(grid: &TiledGrid, scan: &PreparedScan, theta: Real, out: &mut Turned) {
    let (s, c) = theta.sin_cos();
    out.dirs.clear();
    out.dirs.extend(scan.beams.iter().map(|b| {
        let (cos, sin) = b.turned(c, s);
        let (dx, dy) = (b.range * cos, b.range * sin);
        let back = (step_back(cos), step_back(sin));
        Direction {
            dx,
            dy,
            fixed: (grid.fixed_length(dx), grid.fixed_length(dy)),
            back,
            back_code: back_code(back),
        }
    }));
    out.short = out.dirs.iter().all(|d| d.fixed.0.abs() < SHORT_BEAM && d.fixed.1.abs() < SHORT_BEAM);
}

/// 2^(−j/16) for j = 0..16.
const EXP2_SIXTEENTHS: [Real; 16] = [
    1.0,
    0.957_603_280_698_573_7,
    0.917_004_043_204_671_2,
    0.878_126_080_186_649_7,
    0.840_896_415_253_714_5,
    0.805_245_165_974_627_1,
    0.771_105_412_703_970_4,
    0.738_413_072_969_749_7,
    std::f64::consts::FRAC_1_SQRT_2,
    0.677_127_773_468_446_3,
    0.648_419_777_325_504_8,
    0.620_928_906_036_742,
    0.594_603_557_501_360_5,
    0.569_394_317_378_345_8,
    0.545_253_866_332_628_8,
    0.522_136_891_213_706_9,
];

/// e^(−x) for x ≥ 0 to about 1e-15 relative, 0 from 700 on; inline and
/// branch-free, so that a loop of them runs at the processor's throughput
/// (the score takes one per matched beam, and a libm call there cost a
/// tenth of the run).
#[inline(always)]
fn exp_neg(x: Real) -> Real {
    let clamped = x.min(700.0);
    // e^(−x) = 2^(−n/16) · e^(−r), n = round(16 x / ln 2), |r| ≤ ln 2 / 32.
    let (rounded, n) = round_small(clamped * (16.0 * std::f64::consts::LOG2_E));
    let t = rounded * (std::f64::consts::LN_2 / 16.0) - clamped;
    let p = 1.0
        + t * (1.0 + t * (0.5 + t * (1.0 / 6.0 + t * (1.0 / 24.0 + t * (1.0 / 120.0 + t * (1.0 / 720.0))))));
    let v = p * EXP2_SIXTEENTHS[(n & 15) as usize] * Real::from_bits(((1023 - (n >> 4)) as u64) << 52);
    if x < 700.0 { v } else { 0.0 }
}

/// What a climb remembers of the map: for each (cell, step back) it has
/// looked at, the candidate mean hit points there, in a direct-mapped
/// table whose slot holds up to [`INLINE`] candidates itself, so that a
/// beam costs one slot read and a branch-free minimum. The climb's steps
/// are a cell or less, so its poses keep landing beams in the same few
/// cells of each beam's neighbourhood, and those are read from the map
/// once. The result is exactly that of [`TiledGrid::nearest_backed_wall`].
#[derive(Debug)]
struct BeamCache {
    slots: Box<[Slot; CACHE_SLOTS]>,
    /// Slots of other generations are empty: forgetting a map is a counter
    /// increment, not a pass over the table.
    generation: u32,
    /// Candidates beyond a slot's first [`INLINE`] (a window with more
    /// walls than that is rare).
    overflow: Vec<(f32, f32)>,
}

/// Candidates a slot holds itself.
const INLINE: usize = 4;

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
const CACHE_CAPACITY: usize = 1 << 14;
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
    fn forget(&mut self) {
        self.overflow.clear();
        self.generation += 1;
        if self.generation == GENERATIONS {
            self.slots.fill(EMPTY_SLOT);
            self.generation = 1;
        }
    }

    /// [`TiledGrid::nearest_backed_wall`] for an end point `hit` in cell `c`.
    #[inline(always)]
    fn nearest(
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

    /// For each beam of `run` (at most [`BOUND_CHECK_BEAMS`]) with the laser
    /// at `laser` (whose fixed-point position is `base`): the exponents
    /// d²·`per_sigma` of the beams that match, packed in order into
    /// `exponents`; returns how many matched. [`Self::nearest`] beam by
    /// beam, as one loop with no call and no branch but the cache's.
    /// `SHORT`: the beams are [`Turned::short`], so no cell needs a check
    /// that it fits the cache's key.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn match_run<const SHORT: bool>(
        &mut self,
        grid: &TiledGrid,
        laser: &LaserAt,
        base: (i64, i64),
        run: &[Direction],
        k: i64,
        per_sigma: Real,
        exponents: &mut [Real; BOUND_CHECK_BEAMS],
    ) -> usize {
        let mut matched = 0;
        let mut generation = self.generation << 4;
        for d in run {
            let c = ((base.0 + d.fixed.0) >> FIXED_BITS, (base.1 + d.fixed.1) >> FIXED_BITS);
            let hit = ((laser.x + d.dx) as f32, (laser.y + d.dy) as f32);
            let key = if SHORT { Some(packed_cell(c)) } else { cell_key(c) };
            let best = match key {
                Some(key) => {
                    self.cached_distance(grid, c, key, hit, (d.back, d.back_code), k, &mut generation)
                }
                None => uncached_nearest(grid, c, hit, d.back, k).map_or(f32::INFINITY, |d2| d2 as f32),
            };
            // `matched` never exceeds the beams seen, fewer than the
            // buffer's length: the mask only spares a bounds check.
            exponents[matched & (BOUND_CHECK_BEAMS - 1)] = Real::from(best) * per_sigma;
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

/// Where the laser is for one pose being scored: in metres and in the
/// grid's fixed-point cells (`None` for a pose beyond any map).
#[derive(Debug, Clone, Copy)]
struct LaserAt {
    x: Real,
    y: Real,
    fixed: Option<(i64, i64)>,
}

impl LaserAt {
    #[inline]
    fn new(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan) -> Self {
        let laser = pose.compose(&scan.laser_offset);
        LaserAt { x: laser.x, y: laser.y, fixed: grid.fixed_of(laser.x, laser.y) }
    }

    /// For each beam of `dirs` (any run of a scan's directions at this
    /// laser's heading), the squared distance from its end point to the
    /// best mean hit: calls `each(Some(d²))` or `each(None)` per beam.
    #[inline]
    fn match_beams(
        &self,
        grid: &TiledGrid,
        dirs: &[Direction],
        o: &SlamOptions,
        cache: &mut BeamCache,
        mut each: impl FnMut(Option<Real>),
    ) {
        let Some(base) = self.fixed else {
            // A pose beyond any map (garbage odometry): matched uncached.
            for d in dirs {
                each(grid.nearest_backed_wall((self.x + d.dx, self.y + d.dy), d.back, o.kernel));
            }
            return;
        };
        for d in dirs {
            let cell = ((base.0 + d.fixed.0) >> FIXED_BITS, (base.1 + d.fixed.1) >> FIXED_BITS);
            let hit = ((self.x + d.dx) as f32, (self.y + d.dy) as f32);
            each(cache.nearest(grid, cell, hit, d.back, d.back_code, o.kernel));
        }
    }
}

/// Beams scored between checks of whether a pose can still beat the one
/// to beat (see [`score_with`]). A power of two: [`BeamCache::match_run`]
/// masks its buffer index with it.
const BOUND_CHECK_BEAMS: usize = 16;
const _: () = assert!(BOUND_CHECK_BEAMS.is_power_of_two());

/// Slack for float rounding in the bound of [`score_with`]: far above the
/// rounding of a sum of a few thousand terms of at most 1, far below any
/// difference between scores that matters.
const BOUND_SLACK: Real = 1e-6;

fn laser_heading(pose: &Pose2, scan: &PreparedScan) -> Real {
    pose.compose(&scan.laser_offset).theta
}

/// The score: the sum over matched beams of e^(−d²/σ), or `None` once it is
/// certain not to exceed `to_beat`. Each beam adds at most 1, so a pose
/// whose partial sum plus the beams left cannot reach `to_beat` is given up
/// early: most of a climb's candidates lose, many of them clearly. The sum
/// is the same, term by term and in order, as without the bound. Within a
/// run of beams, the exponents are gathered first and exponentiated in a
/// second loop whose iterations are independent.
#[allow(clippy::too_many_arguments)]
fn score_with(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    turned: &Turned,
    o: &SlamOptions,
    cache: &mut BeamCache,
    to_beat: Real,
) -> Option<Real> {
    let per_sigma = 1.0 / o.sigma;
    let laser = LaserAt::new(grid, pose, scan);
    let mut exponents = [0.0; BOUND_CHECK_BEAMS];
    let mut s: Real = 0.0;
    let mut left = turned.dirs.len();
    for run in turned.dirs.chunks(BOUND_CHECK_BEAMS) {
        // Matched beams' exponents only, packed without a branch: a beam
        // that matches nothing adds e^(−∞) = 0, which changes no sum.
        let matched = match laser.fixed {
            Some(base) if turned.short => {
                cache.match_run::<true>(grid, &laser, base, run, o.kernel, per_sigma, &mut exponents)
            }
            Some(base) => {
                cache.match_run::<false>(grid, &laser, base, run, o.kernel, per_sigma, &mut exponents)
            }
            None => {
                let mut matched = 0;
                laser.match_beams(grid, run, o, cache, |d2| {
                    if let Some(d2) = d2 {
                        exponents[matched] = d2 * per_sigma;
                        matched += 1;
                    }
                });
                matched
            }
        };
        for &x in &exponents[..matched] {
            s += exp_neg(x);
        }
        left -= run.len();
        if s + left as Real + BOUND_SLACK < to_beat {
            return None;
        }
    }
    Some(s)
}

/// The matching score of `pose` (higher is better).
pub fn score(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Real {
    let mut turned = Turned::default();
    directions(grid, scan, laser_heading(pose, scan), &mut turned);
    score_with(grid, pose, scan, &turned, o, &mut BeamCache::default(), Real::NEG_INFINITY)
        .expect("nothing is beaten by −∞")
}

/// (score, log-likelihood, beams matched) of `pose`.
pub fn likelihood_and_score(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    o: &SlamOptions,
) -> (Real, Real, usize) {
    Matcher::default().likelihood(grid, pose, scan, o)
}

fn likelihood_with(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    turned: &Turned,
    o: &SlamOptions,
    cache: &mut BeamCache,
) -> (Real, Real, usize) {
    let (mut s, mut l, mut n) = (0.0, 0.0, 0);
    let no_hit = NULL_LIKELIHOOD / o.lsigma;
    let per_sigma = 1.0 / o.sigma;
    LaserAt::new(grid, pose, scan).match_beams(grid, &turned.dirs, o, cache, |d2| match d2 {
        Some(d2) => {
            s += exp_neg(d2 * per_sigma);
            l += -d2 / o.lsigma;
            n += 1;
        }
        None => l += no_hit,
    });
    (s, l, n)
}

/// Beams of `scan` whose end point, with the robot at `pose`, lies in a
/// cell `grid` has seen (crossed or hit): how much of the view a map
/// covers.
pub fn covered_beams(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan) -> usize {
    let laser = pose.compose(&scan.laser_offset);
    let (s, c) = laser.theta.sin_cos();
    let seen = |b: &&Beam| {
        let (cos, sin) = b.turned(c, s);
        grid.get(grid.cell_of(laser.x + b.range * cos, laser.y + b.range * sin)).visits > 0
    };
    scan.beams.iter().filter(seen).count()
}

/// The outcome of one particle's scan matching.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Matched {
    /// The best pose found.
    pub pose: Pose2,
    /// Its score.
    pub score: Real,
    /// Pose evaluations spent (the quantity the cutoff bounds).
    pub evaluations: u32,
    /// The log-likelihood of the scan at `pose` (see
    /// [`likelihood_and_score`]): the particle's weight update.
    pub log_likelihood: Real,
    /// Beams that found a wall at `pose`.
    pub matched_beams: usize,
}

/// Hill-climbs the score from `init` (GMapping's `optimize`), with scratch
/// memory of its own; a filter keeps a [`Matcher`] instead.
pub fn optimize(grid: &TiledGrid, init: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Matched {
    Matcher::default().optimize(grid, init, scan, o)
}

/// Steps a side of the wide search's grid (7 × 7 × 7 poses).
const WIDE_SEARCH_STEPS: i32 = 3;

/// The wide search's grid scores every this many beams; the climb from its
/// best pose scores them all.
const WIDE_SEARCH_BEAM_STRIDE: usize = 4;

/// The scan matcher's scratch memory (candidate cache, beam directions,
/// poses scored), kept from particle to particle and reading to reading so
/// that matching allocates nothing once warm.
#[derive(Debug, Default)]
pub struct Matcher {
    cache: BeamCache,
    /// The climb's beam directions by heading.
    headings: Headings,
    /// The wide search's beam directions at its heading.
    turned: Turned,
    seen: Vec<Lattice>,
    /// The wide search's subsample of the scan.
    coarse_scan: PreparedScan,
}

impl Matcher {
    /// A particle's scan matching: the climb from its predicted pose and,
    /// when that matches fewer than `wide_search_below` of the beams
    /// (odometry far off, as in the Intel log) and no cutoff bounds the
    /// work, a wide search whose pose is kept if it scores
    /// `wide_search_margin` times higher. Evaluations of both are counted.
    pub fn refine(
        &mut self,
        grid: &TiledGrid,
        predicted: &Pose2,
        scan: &PreparedScan,
        o: &SlamOptions,
    ) -> Matched {
        let m = self.optimize(grid, predicted, scan, o);
        let weak = (m.matched_beams as Real) < o.wide_search_below * scan.len() as Real;
        if o.cutoff != Cutoff::Unbounded || !weak {
            return m;
        }
        let (reach, turn) = (o.wide_search_reach, o.wide_search_turn);
        let wide = self.wide_search(grid, predicted, scan, o, reach, turn, WIDE_SEARCH_STEPS);
        let evaluations = m.evaluations + wide.evaluations;
        if wide.score > m.score * o.wide_search_margin {
            Matched { evaluations, ..wide }
        } else {
            Matched { evaluations, ..m }
        }
    }

    /// [`likelihood_and_score`] with this matcher's scratch memory (no
    /// allocation once warm).
    pub fn likelihood(
        &mut self,
        grid: &TiledGrid,
        pose: &Pose2,
        scan: &PreparedScan,
        o: &SlamOptions,
    ) -> (Real, Real, usize) {
        self.cache.forget();
        directions(grid, scan, laser_heading(pose, scan), &mut self.turned);
        likelihood_with(grid, pose, scan, &self.turned, o, &mut self.cache)
    }

    /// Hill-climbs the score from `init` (GMapping's `optimize`).
    pub fn optimize(
        &mut self,
        grid: &TiledGrid,
        init: &Pose2,
        scan: &PreparedScan,
        o: &SlamOptions,
    ) -> Matched {
        self.cache.forget();
        self.climb(grid, init, scan, o)
    }

    /// A coarse search of a wide window around `init` (±`reach` metres,
    /// ±`turn` radians, in `steps` steps a side) on every
    /// [`WIDE_SEARCH_BEAM_STRIDE`]-th beam, then a climb on all beams from
    /// its best pose: for readings the climb from `init` could not match
    /// well.
    #[allow(clippy::too_many_arguments)]
    pub fn wide_search(
        &mut self,
        grid: &TiledGrid,
        init: &Pose2,
        scan: &PreparedScan,
        o: &SlamOptions,
        reach: Real,
        turn: Real,
        steps: i32,
    ) -> Matched {
        self.cache.forget();
        scan.every_nth_into(WIDE_SEARCH_BEAM_STRIDE, &mut self.coarse_scan);
        let coarse = &self.coarse_scan;
        let mut best = (Real::NEG_INFINITY, *init);
        let mut evaluations = 0;
        for a in -steps..=steps {
            let theta = init.theta + turn * Real::from(a) / Real::from(steps);
            directions(
                grid,
                coarse,
                laser_heading(&Pose2::new(init.x, init.y, theta), scan),
                &mut self.turned,
            );
            for i in -steps..=steps {
                for j in -steps..=steps {
                    let pose = Pose2::new(
                        init.x + reach * Real::from(i) / Real::from(steps),
                        init.y + reach * Real::from(j) / Real::from(steps),
                        theta,
                    );
                    let s = score_with(grid, &pose, coarse, &self.turned, o, &mut self.cache, best.0);
                    evaluations += 1;
                    if let Some(s) = s.filter(|&s| s > best.0) {
                        best = (s, pose);
                    }
                }
            }
        }
        // The climb reads the same map: the candidates cached so far stay.
        let mut m = self.climb(grid, &best.1, scan, o);
        m.evaluations += evaluations;
        m
    }

    /// The hill climb on `grid` with whatever the cache holds for it.
    fn climb(&mut self, grid: &TiledGrid, init: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Matched {
        let limit = match o.cutoff {
            Cutoff::Unbounded => u32::MAX,
            Cutoff::Evaluations(n) => n,
        };
        // Poses lie on a lattice around `init` whose unit is the finest
        // step, so a pose reached twice is recognised exactly and scored
        // once.
        let finest = (1i64 << o.iterations) as Real;
        let unit = (o.lstep / finest, o.astep / finest);
        let pose_at = |p: Lattice| {
            Pose2::new(
                init.x + p.0 as Real * unit.0,
                init.y + p.1 as Real * unit.0,
                init.theta + p.2 as Real * unit.1,
            )
        };
        let Matcher { cache, headings, seen, .. } = self;
        seen.clear();
        headings.forget();
        let mut current: Lattice = (0, 0, 0);
        let mut current_heading =
            headings.slot(0, [usize::MAX; 2], |v| directions(grid, scan, laser_heading(init, scan), v));
        let mut current_score =
            score_with(grid, init, scan, headings.at(current_heading), o, cache, Real::NEG_INFINITY)
                .expect("nothing is beaten by −∞");
        seen.push(current);
        let mut evaluations = 1;
        let mut step = 1i64 << o.iterations;
        let mut refinement = 0;
        let mut best_score = -1.0;
        loop {
            if best_score >= current_score {
                refinement += 1;
                step /= 2;
            }
            best_score = current_score;
            let mut best_local = current;
            let mut best_heading = current_heading;
            let moves =
                [(step, 0, 0), (-step, 0, 0), (0, -step, 0), (0, step, 0), (0, 0, step), (0, 0, -step)];
            for (dx, dy, dt) in moves {
                if evaluations >= limit {
                    break;
                }
                let at = (current.0 + dx, current.1 + dy, current.2 + dt);
                if seen.contains(&at) {
                    // Scored before and not kept then: it cannot beat the
                    // current pose, whose score only rose since.
                    continue;
                }
                let candidate = pose_at(at);
                let heading = if dt == 0 {
                    current_heading
                } else {
                    headings.slot(at.2, [current_heading, best_heading], |v| {
                        directions(grid, scan, laser_heading(&candidate, scan), v)
                    })
                };
                let s = score_with(grid, &candidate, scan, headings.at(heading), o, cache, current_score);
                evaluations += 1;
                seen.push(at);
                if let Some(s) = s.filter(|&s| s > current_score) {
                    current_score = s;
                    best_local = at;
                    best_heading = heading;
                }
            }
            current_heading = best_heading;
            current = best_local;
            let improving = current_score > best_score;
            if evaluations >= limit || !(improving || refinement < o.iterations) {
                break;
            }
        }
        let pose = pose_at(current);
        let (_, log_likelihood, matched_beams) =
            likelihood_with(grid, &pose, scan, headings.at(current_heading), o, cache);
        Matched { pose, score: current_score, evaluations, log_likelihood, matched_beams }
    }
}

/// Beam directions at the few headings a climb keeps coming back to, by
/// lattice heading: a turn's candidates are the current heading ± the step,
/// the same two again after every move that only translates, so most are
/// computed once per climb rather than once per turn.
#[derive(Debug, Default)]
struct Headings {
    entries: [(Option<i64>, Turned); HEADINGS],
    /// The entry to reuse next.
    next: usize,
}

/// Headings a climb keeps: the current one, the best turn so far and two
/// more.
const HEADINGS: usize = 4;

impl Headings {
    /// Forgets every heading (another climb: another start, scan or grid).
    fn forget(&mut self) {
        for entry in &mut self.entries {
            entry.0 = None;
        }
    }

    /// The entry holding the directions at lattice heading `index`, filled
    /// by `fill` if none does, in an entry other than the two in `keep`.
    fn slot(&mut self, index: i64, keep: [usize; 2], fill: impl FnOnce(&mut Turned)) -> usize {
        if let Some(found) = self.entries.iter().position(|e| e.0 == Some(index)) {
            return found;
        }
        let mut victim = self.next % HEADINGS;
        while keep.contains(&victim) {
            victim = (victim + 1) % HEADINGS;
        }
        self.next = victim + 1;
        let entry = &mut self.entries[victim];
        entry.0 = Some(index);
        fill(&mut entry.1);
        victim
    }

    /// The directions in entry `slot`.
    fn at(&self, slot: usize) -> &Turned {
        &self.entries[slot].1
    }
}

/// A pose on the hill climber's lattice: (x, y, θ) in finest steps from
/// the initial pose.
type Lattice = (i64, i64, i64);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::scenes::{mapped, room, scan_of};

    /// The room mapped from three poses, the true pose of the scan to
    /// match, default options and that scan.
    fn scene() -> (TiledGrid, Pose2, SlamOptions, PreparedScan) {
        let world = room();
        let truth = Pose2::new(3.3, 1.7, 0.4);
        let grid = mapped(&world, &[truth, Pose2::new(1.0, 4.0, -1.0), Pose2::new(6.5, 1.5, 2.0)]);
        let o = SlamOptions::default();
        let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
        (grid, truth, o, scan)
    }

    /// The score as the grid's own kernel search gives it, beam by beam in
    /// order, with nothing cached (d²/σ as the matcher rounds it: times
    /// 1/σ).
    fn reference_score(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Real {
        let per_sigma = 1.0 / o.sigma;
        let laser = pose.compose(&scan.laser_offset);
        let (s, c) = laser.theta.sin_cos();
        let mut score = 0.0;
        for b in &scan.beams {
            let (cos, sin) = b.turned(c, s);
            let end = (laser.x + b.range * cos, laser.y + b.range * sin);
            if let Some(d2) = grid.nearest_backed_wall(end, (step_back(cos), step_back(sin)), o.kernel) {
                score += exp_neg(d2 * per_sigma);
            }
        }
        score
    }

    #[test]
    fn a_prepared_scan_keeps_every_lskip_plus_first_valid_beam_within_range() {
        let mut reading = scan_of(&room(), &Pose2::new(3.3, 1.7, 0.4));
        reading.ranges[..8].copy_from_slice(&[1.0, 2.0, 0.0, 3.0, 90.0, 4.0, 5.0, 6.0]);
        reading.ranges.truncate(8);
        reading.range_max = 100.0;
        let ranges = |lskip, max_urange| {
            let o = SlamOptions { lskip, max_urange, ..SlamOptions::default() };
            PreparedScan::new(&reading, &o).beams.iter().map(|b| b.range).collect::<Vec<_>>()
        };
        // Beam 2 is no return, beam 4 beyond max_urange.
        assert_eq!(ranges(0, 80.0), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(ranges(1, 80.0), [1.0, 5.0]);
        assert_eq!(ranges(3, 80.0), [1.0]);
        assert_eq!(ranges(1, 100.0), [1.0, 90.0, 5.0]);
        assert_eq!(SlamOptions::default().lskip, 1, "the default matches every other beam");
    }

    #[test]
    fn the_score_is_the_grid_kernel_search_summed() {
        let (grid, truth, o, scan) = scene();
        // A beam whose cell lies beyond ±2³¹ cells: the scan is no longer
        // short, and that beam is matched uncached. (Beam 8: with the
        // default lskip of 1 only even beams are matched.)
        let mut far_reading = scan_of(&room(), &truth);
        far_reading.range_max = 1e9;
        far_reading.ranges[8] = 2e8;
        let far_options = SlamOptions { max_urange: 1e9, ..o.clone() };
        let far = PreparedScan::new(&far_reading, &far_options);
        let mut cache = BeamCache::default();
        for (scan, o, short) in [(&scan, &o, true), (&far, &far_options, false)] {
            for (i, dx) in [-0.3, -0.05, 0.0, 0.02, 0.2].into_iter().enumerate() {
                let pose = Pose2::new(truth.x + dx, truth.y - dx, truth.theta + 0.5 * dx);
                let mut turned = Turned::default();
                directions(&grid, scan, laser_heading(&pose, scan), &mut turned);
                assert_eq!(turned.short, short);
                let want = reference_score(&grid, &pose, scan, o);
                assert!(want > 10.0, "pose {i} matches beams ({want})");
                for _ in 0..2 {
                    // Cold, then from the cache: the same sum, bit for bit.
                    let got = score_with(&grid, &pose, scan, &turned, o, &mut cache, Real::NEG_INFINITY);
                    assert_eq!(got.map(Real::to_bits), Some(want.to_bits()), "pose {i}, short {short}");
                }
            }
        }
    }

    #[test]
    fn a_bounded_score_gives_up_only_on_poses_that_cannot_win() {
        let (grid, truth, o, scan) = scene();
        let mut cache = BeamCache::default();
        let (mut dirs, mut given_up) = (Turned::default(), 0);
        for (i, dx) in [-0.3, -0.05, 0.0, 0.02, 0.2].into_iter().enumerate() {
            let pose = Pose2::new(truth.x + dx, truth.y - dx, truth.theta + 0.5 * dx);
            directions(&grid, &scan, laser_heading(&pose, &scan), &mut dirs);
            let full = score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, Real::NEG_INFINITY).unwrap();
            assert!(full > 10.0, "pose {i} matches beams ({full})");
            for to_beat in [full - 1.0, full - 1e-9, full, full + 1e-9, full + 0.5, full + 5.0, 1e6] {
                match score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, to_beat) {
                    // The same sum, bit for bit.
                    Some(s) => assert_eq!(s.to_bits(), full.to_bits(), "pose {i}, to beat {to_beat}"),
                    None => {
                        assert!(full <= to_beat, "pose {i} scores {full} > {to_beat} but was given up");
                        given_up += 1;
                    }
                }
            }
            // Nothing can beat a score above one per beam: given up early.
            assert_eq!(score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, 1e6), None);
        }
        assert!(given_up >= 10, "poses that cannot win are given up ({given_up})");
    }

    #[test]
    fn the_cache_answers_as_the_grid_does() {
        use rand::{RngExt, SeedableRng};
        let (grid, _, _, _) = scene();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut cache = BeamCache::default();
        let (mut matched, mut overflowing) = (0, 0);
        // Wider kernels' windows hold more walls than a slot does; kernel 4
        // runs without forgetting, so that the overflow's bound is reached.
        for k in [1, 2, 4] {
            for round in 0..40_000 {
                if round == 0 || (k < 4 && round % 5_000 == 0) {
                    cache.forget();
                }
                let hit = (rng.random::<f64>() * 8.0, rng.random::<f64>() * 6.0);
                let back = (rng.random_range(-1..=1), rng.random_range(-1..=1));
                let want = grid.nearest_backed_wall(hit, back, k);
                let (cell, end) = (grid.cell_of(hit.0, hit.1), (hit.0 as f32, hit.1 as f32));
                assert_eq!(
                    cache.nearest(&grid, cell, end, back, back_code(back), k),
                    want,
                    "{hit:?} {back:?} k {k}"
                );
                // Asked again, from the cache.
                assert_eq!(
                    cache.nearest(&grid, cell, end, back, back_code(back), k),
                    want,
                    "{hit:?} {back:?} k {k}, cached"
                );
                matched += usize::from(want.is_some());
                let mut found = 0;
                grid.backed_walls(grid.cell_of(hit.0, hit.1), back, k, |_, _| found += 1);
                overflowing += usize::from(found > INLINE);
            }
        }
        assert!(
            matched > 1_000 && overflowing > 100,
            "the test reaches walls ({matched}) and overflows ({overflowing})"
        );
        // The overflow's bound starts the cache over rather than growing.
        assert!(cache.generation > 1 + 17, "the cache started over {} times", cache.generation - 18);
        assert!(cache.overflow.len() <= CACHE_CAPACITY + 81, "{}", cache.overflow.len());
    }

    #[test]
    fn the_inline_exponential_matches_libm() {
        for i in 0..20_000 {
            let x = i as Real * 1e-3;
            let (got, want) = (exp_neg(x), (-x).exp());
            assert!((got - want).abs() <= 1e-13 * want, "{x}: {got} vs {want}");
        }
        assert!(exp_neg(300.0) > 0.0 && exp_neg(800.0) == 0.0 && exp_neg(Real::INFINITY) == 0.0);
    }

    #[test]
    fn the_step_back_rounds_like_gmapping() {
        for i in 0..=3600 {
            let a = (i as Real / 10.0).to_radians();
            let (s, c) = a.sin_cos();
            for v in [c, s] {
                let want = (-v * std::f64::consts::SQRT_2).round() as i64;
                // Away from the rounding boundary the two agree exactly.
                if ((v * std::f64::consts::SQRT_2).abs() - 0.5).abs() > 1e-9 {
                    assert_eq!(step_back(v), want, "{v}");
                }
            }
        }
    }

    #[test]
    fn recovers_known_offsets() {
        use rand::{RngExt, SeedableRng};
        let (grid, truth, o, scan) = scene();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12345);
        for _ in 0..20 {
            let mut r = || rng.random::<f64>() - 0.5;
            let start = Pose2::new(truth.x + 0.2 * r(), truth.y + 0.2 * r(), truth.theta + 0.1 * r());
            let m = optimize(&grid, &start, &scan, &o);
            assert!(m.pose.distance(&truth) < 0.02, "from {start:?}: {:?}", m.pose);
            assert!((m.pose.theta - truth.theta).abs() < 0.01, "from {start:?}: {:?}", m.pose);
            assert_eq!(m.log_likelihood, likelihood_and_score(&grid, &m.pose, &scan, &o).1);
        }
    }

    #[test]
    fn the_wide_search_recovers_an_offset_the_climb_cannot() {
        let (grid, truth, o, scan) = scene();
        let start = Pose2::new(3.55, 1.45, 0.52);
        let wide = Matcher::default().wide_search(&grid, &start, &scan, &o, 0.3, 0.15, 3);
        assert!(wide.pose.distance(&truth) < 0.02, "{:?}", wide.pose);
        assert!(wide.evaluations > 343, "the grid and the climb are counted: {}", wide.evaluations);
        let climb = optimize(&grid, &start, &scan, &o);
        assert!(climb.score < wide.score, "{} vs {}", climb.score, wide.score);
    }

    #[test]
    fn a_reused_matcher_forgets_the_previous_map() {
        let (grid, truth, o, scan) = scene();
        // Another map: the same room seen from a pose 0.3 m off, so its
        // walls (and cached candidates) lie elsewhere.
        let shifted = mapped(&room(), &[Pose2::new(3.0, 1.7, 0.4)]);
        let mut reused = Matcher::default();
        let on_grid = reused.optimize(&grid, &truth, &scan, &o);
        let start = Pose2::new(3.35, 1.65, 0.42);
        let again = reused.optimize(&shifted, &start, &scan, &o);
        assert_eq!(again, optimize(&shifted, &start, &scan, &o), "as if fresh");
        assert_ne!(again.pose, on_grid.pose);
        assert_eq!(reused.optimize(&grid, &truth, &scan, &o), on_grid);
    }

    #[test]
    fn the_true_pose_scores_best_and_likelihood_agrees() {
        let world = room();
        let truth = Pose2::new(3.3, 1.7, 0.4);
        let grid = mapped(&world, &[truth]);
        let o = SlamOptions::default();
        let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
        let off = Pose2::new(3.4, 1.7, 0.4);
        assert!(score(&grid, &truth, &scan, &o) > score(&grid, &off, &scan, &o));
        let (s, l, n) = likelihood_and_score(&grid, &truth, &scan, &o);
        let (_, l_off, _) = likelihood_and_score(&grid, &off, &scan, &o);
        assert!(s > 0.0 && 10 * n > 8 * scan.beams.len() && l > l_off, "{s} {l} {n} {l_off}");
        // The same from a matcher that last matched on another map.
        let mut reused = Matcher::default();
        reused.optimize(&mapped(&world, &[off]), &off, &scan, &o);
        assert_eq!(reused.likelihood(&grid, &truth, &scan, &o), (s, l, n));
    }

    #[test]
    fn the_cutoff_bounds_evaluations() {
        let world = room();
        let truth = Pose2::new(3.3, 1.7, 0.4);
        let grid = mapped(&world, &[truth]);
        let start = Pose2::new(3.45, 1.6, 0.45);
        let free = optimize(
            &grid,
            &start,
            &PreparedScan::new(&scan_of(&world, &truth), &SlamOptions::default()),
            &SlamOptions::default(),
        );
        let o = SlamOptions { cutoff: Cutoff::Evaluations(10), ..SlamOptions::default() };
        let cut = optimize(&grid, &start, &PreparedScan::new(&scan_of(&world, &truth), &o), &o);
        assert!(free.evaluations > 10, "{}", free.evaluations);
        assert_eq!(cut.evaluations, 10);
        assert!(cut.score <= free.score);
    }
}
