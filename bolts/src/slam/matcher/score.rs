//! The score and the likelihood of a pose: each beam's end point against
//! the nearest wall's mean hit point (GMapping's `score` and
//! `likelihoodAndScore`), with a bound that gives up on poses that cannot
//! win.

use squall_core::geometry::{Pose2, Real};

use super::Matcher;
use super::beam_cache::BeamCache;
use super::fast_exp::exp_neg;
use super::scan::{Beam, Direction, PreparedScan, Turned, directions, laser_heading};
use crate::slam::grid::{FIXED_BITS, TiledGrid};
use crate::slam::options::SlamOptions;

/// GMapping's log-likelihood of a beam that matches nothing, before
/// division by lσ.
const NULL_LIKELIHOOD: Real = -0.5;

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

/// The score: the sum over matched beams of e^(−d²/σ), or `None` once it is
/// certain not to exceed `to_beat`. Each beam adds at most 1, so a pose
/// whose partial sum plus the beams left cannot reach `to_beat` is given up
/// early: most of a climb's candidates lose, many of them clearly. The sum
/// is the same, term by term and in order, as without the bound. Within a
/// run of beams, the exponents are gathered first and exponentiated in a
/// second loop whose iterations are independent.
#[allow(clippy::too_many_arguments)]
pub(super) fn score_with(
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
            Some(base) if turned.short => cache.match_run::<true, BOUND_CHECK_BEAMS>(
                grid,
                (laser.x, laser.y),
                base,
                run,
                o.kernel,
                per_sigma,
                &mut exponents,
            ),
            Some(base) => cache.match_run::<false, BOUND_CHECK_BEAMS>(
                grid,
                (laser.x, laser.y),
                base,
                run,
                o.kernel,
                per_sigma,
                &mut exponents,
            ),
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

pub(super) fn likelihood_with(
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
