//! A scan prepared for matching: the usable beams with their directions in
//! the laser frame, and those directions turned to one heading, in metres
//! and in the grid's fixed-point cells, with each end point's step back
//! towards the laser.

use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::LaserReading;

use crate::slam::grid::{FIXED_BITS, TiledGrid};
use crate::slam::options::SlamOptions;

/// One beam to match: its range and the (cos, sin) of its angle in the
/// laser frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Beam {
    pub(super) range: Real,
    pub(super) cos: Real,
    pub(super) sin: Real,
}

impl Beam {
    /// (cos, sin) of the beam's direction with the laser at the heading
    /// whose (cos, sin) are (`c`, `s`): a rotation, no trigonometry.
    #[inline]
    pub(super) fn turned(&self, c: Real, s: Real) -> (Real, Real) {
        (c * self.cos - s * self.sin, s * self.cos + c * self.sin)
    }
}

/// A reading prepared for matching: usable beams only.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PreparedScan {
    pub(super) beams: Vec<Beam>,
    pub(super) laser_offset: Pose2,
    /// What each beam matched counts for in the particle's weight and the
    /// scan's information: the share of the laser's view it stands for,
    /// relative to a full scan thinned by `lskip` (1 there; see
    /// [`PreparedScan::new`]).
    per_beam: Real,
}

impl Default for PreparedScan {
    fn default() -> Self {
        PreparedScan { beams: Vec::new(), laser_offset: Pose2::default(), per_beam: 1.0 }
    }
}

impl PreparedScan {
    /// Keeps the usable beams (valid, up to `max_urange`), every
    /// `stride`-th. `lskip` sets the budget: a scan whose beams all return
    /// is matched with every (lskip+1)-th, which saves time where
    /// neighbouring beams see the same wall (decision 0001). A scan whose
    /// beams mostly see nothing (open space, a long-range laser outdoors)
    /// would be left with few beams that way; its stride is the whole
    /// number nearest to its usable beams over the budget (at least 1), so
    /// it is matched with about as many beams as a full scan, and never
    /// more. Each beam then counts for `stride / (lskip+1)` of a full
    /// scan's beam in the weight and the information: how much a scan
    /// tells about the pose depends on what the laser saw, not on how
    /// densely the matcher samples it, so the filter's confidence is the
    /// same whatever the stride.
    pub(crate) fn new(scan: &LaserReading, o: &SlamOptions) -> Self {
        let usable = |i: &usize| scan.is_valid(*i) && Real::from(scan.ranges[*i]) <= o.max_urange;
        let thinned = o.lskip + 1;
        let budget = scan.ranges.len().div_ceil(thinned).max(1);
        let returns = (0..scan.ranges.len()).filter(usable).count();
        let stride = ((returns as Real / budget as Real).round() as usize).clamp(1, thinned);
        let beams = (0..scan.ranges.len())
            .filter(|i| i % stride == 0 && usable(i))
            .map(|i| {
                let (sin, cos) = scan.beam_angle(i).sin_cos();
                Beam { range: Real::from(scan.ranges[i]), cos, sin }
            })
            .collect();
        PreparedScan { beams, laser_offset: scan.laser_offset, per_beam: stride as Real / thinned as Real }
    }

    /// What a matched beam counts for in the weight and the information
    /// (see [`PreparedScan::new`]).
    pub(crate) fn per_beam(&self) -> Real {
        self.per_beam
    }

    /// Every `stride`-th beam of this scan, into `out` (reused, so that
    /// nothing is allocated once warm): a coarse search scores many poses
    /// far apart, where a quarter of the beams tells them apart as well as
    /// all of them do.
    pub(crate) fn every_nth_into(&self, stride: usize, out: &mut PreparedScan) {
        out.beams.clear();
        out.beams.extend(self.beams.iter().step_by(stride.max(1)));
        out.laser_offset = self.laser_offset;
        out.per_beam = self.per_beam;
    }

    /// Beams that will be matched.
    pub(crate) fn len(&self) -> usize {
        self.beams.len()
    }
}

/// A beam seen with the laser at one heading: its end point relative to
/// the laser (world frame), in metres and in the grid's fixed-point cells
/// ([`TiledGrid::fixed_length`]), and the cell step from the end point back
/// towards the laser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Direction {
    pub(super) dx: Real,
    pub(super) dy: Real,
    pub(super) fixed: (i64, i64),
    pub(super) back: (i64, i64),
    /// `back` as a number 0..9 (the beam cache's key).
    pub(super) back_code: u32,
}

/// A step back (each component in −1..=1) as a number 0..9.
#[inline]
pub(super) fn back_code(back: (i64, i64)) -> u32 {
    (back.0 + 3 * back.1 + 4) as u32
}

/// `round(−c·√2)`: the step back along a beam whose direction has
/// component `c`, one of −1, 0, 1.
#[inline]
pub(super) fn step_back(c: Real) -> i64 {
    const HALF_STEP: Real = 0.5 * std::f64::consts::FRAC_1_SQRT_2;
    i64::from(c <= -HALF_STEP) - i64::from(c >= HALF_STEP)
}

/// A scan's beam directions at one heading.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Turned {
    pub(super) dirs: Vec<Direction>,
    /// Whether every beam is shorter than 2³⁰ cells: then, with the laser
    /// anywhere [`TiledGrid::fixed_of`] places it, every end point's cell
    /// fits in an `i32` (the cache's key) without a check per beam.
    pub(super) short: bool,
}

/// Beam length, in fixed-point units, up to which [`Turned::short`] holds.
pub(super) const SHORT_BEAM: i64 = 1 << (30 + FIXED_BITS);

/// The directions of every beam with the laser at heading `theta`. Moves
/// that only translate keep the heading, so the hill climber computes these
/// once per heading rather than once per pose; each beam's direction is
/// its laser-frame direction rotated, with no trigonometry per beam.
pub(super) fn directions(grid: &TiledGrid, scan: &PreparedScan, theta: Real, out: &mut Turned) {
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

/// The laser's heading with the robot at `pose`.
pub(super) fn laser_heading(pose: &Pose2, scan: &PreparedScan) -> Real {
    pose.compose(&scan.laser_offset).theta
}
