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

mod beam_cache;
mod fast_exp;
mod headings;
mod information;
mod scan;
mod score;
#[cfg(test)]
mod tests;

use squall_core::geometry::{Pose2, Real};

use crate::slam::grid::TiledGrid;
use crate::slam::options::{Cutoff, SlamOptions};
use beam_cache::BeamCache;
use headings::{Headings, Lattice};
pub(crate) use scan::PreparedScan;
use scan::{Turned, directions, laser_heading};
pub(crate) use score::covered_beams;
#[cfg(test)]
use score::{likelihood_and_score, score};
use score::{likelihood_with, score_with};

/// The outcome of one particle's scan matching.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Matched {
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
/// memory of its own; a filter keeps a [`Matcher`] instead. The tests'
/// reference.
#[cfg(test)]
pub(crate) fn optimize(grid: &TiledGrid, init: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Matched {
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
pub(crate) struct Matcher {
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
    pub(crate) fn refine(
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
    pub(crate) fn likelihood(
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
    pub(crate) fn optimize(
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
    pub(crate) fn wide_search(
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
