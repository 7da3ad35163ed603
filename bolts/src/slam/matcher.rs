//! The scan matcher (GMapping's `ScanMatcher`: `score`,
//! `likelihoodAndScore`, `optimize`).
//!
//! For each beam, the end point is compared with the mean hit point of the
//! nearest wall cell (the grid's wall threshold) within `kernel` cells whose
//! neighbour one step back along the beam is free; the score adds `exp(−d²/σ)` per matched beam and
//! the log-likelihood `−d²/lσ` (or a fixed penalty when nothing matches).
//! `optimize` climbs the score from an initial pose with moves of ±lstep in
//! x and y and ±astep in θ, halving the steps when no move improves,
//! `iterations` times; a [`Cutoff`] bounds the pose evaluations.
//!
//! One deliberate change: GMapping locates the "free" cell with
//! `world2map(pfree − phit)` where `pfree` lies δ²√2 before the hit, which
//! only works through the map's offset; here it is the cell one step back
//! along the beam, as intended.

use crate::geometry::{Pose2, Real};
use crate::sensor::LaserReading;
use crate::slam::grid::{Cell, TiledGrid};
use crate::slam::options::{Cutoff, SlamOptions};

/// GMapping's log-likelihood of a beam that matches nothing, before
/// division by lσ.
const NULL_LIKELIHOOD: Real = -0.5;

/// One beam to match: its angle in the laser frame and its range.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Beam {
    angle: Real,
    range: Real,
}

/// A reading prepared for matching: usable beams only.
#[derive(Debug, Clone, PartialEq)]
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
            .map(|i| Beam { angle: scan.beam_angle(i), range: Real::from(scan.ranges[i]) })
            .collect();
        PreparedScan { beams, laser_offset: scan.laser_offset }
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

/// Whether `c` is free for matching: hits/visits below the threshold, or
/// never visited (GMapping reads unknown cells as occupancy −1).
#[inline]
fn is_free(c: &Cell, threshold: Real) -> bool {
    c.visits == 0 || Real::from(c.hits) < threshold * Real::from(c.visits)
}

/// A beam's world direction for one laser heading: (cos, sin) and the
/// cell step from its end point back towards the laser.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Direction {
    cos: Real,
    sin: Real,
    back: (i64, i64),
}

/// The directions of every beam with the laser at heading `theta`. Moves
/// that only translate keep the heading, so the hill climber computes these
/// once per heading rather than once per pose.
fn directions(scan: &PreparedScan, theta: Real, out: &mut Vec<Direction>) {
    out.clear();
    out.extend(scan.beams.iter().map(|b| {
        let (sin, cos) = (theta + b.angle).sin_cos();
        let back = (
            (-cos * std::f64::consts::SQRT_2).round() as i64,
            (-sin * std::f64::consts::SQRT_2).round() as i64,
        );
        Direction { cos, sin, back }
    }));
}

/// For each beam, the squared distance from its end point to the best mean
/// hit; calls `each(Some(d²))` or `each(None)` per beam. `dirs` must be the
/// directions for `pose`'s laser heading.
#[inline]
fn match_beams(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    dirs: &[Direction],
    o: &SlamOptions,
    mut each: impl FnMut(Option<Real>),
) {
    let laser = pose.compose(&scan.laser_offset);
    let k = o.kernel;
    let threshold = grid.wall_threshold();
    for (b, d) in scan.beams.iter().zip(dirs) {
        let hit = (laser.x + b.range * d.cos, laser.y + b.range * d.sin);
        let centre = grid.cell_of(hit.0, hit.1);
        let mut best: Option<Real> = None;
        grid.for_each_wall_in_square(centre, k, |pr, cell| {
            let free = grid.get((pr.0 + d.back.0, pr.1 + d.back.1));
            if !is_free(&free, threshold) {
                return;
            }
            let (mx, my) = cell.mean().expect("an occupied cell has hits");
            let d2 = (hit.0 - mx).powi(2) + (hit.1 - my).powi(2);
            if best.is_none_or(|b| d2 < b) {
                best = Some(d2);
            }
        });
        each(best);
    }
}

fn laser_heading(pose: &Pose2, scan: &PreparedScan) -> Real {
    pose.compose(&scan.laser_offset).theta
}

fn score_with(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    dirs: &[Direction],
    o: &SlamOptions,
) -> Real {
    let mut s = 0.0;
    match_beams(grid, pose, scan, dirs, o, |d2| {
        if let Some(d2) = d2 {
            s += (-d2 / o.sigma).exp();
        }
    });
    s
}

/// The matching score of `pose` (higher is better).
pub fn score(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Real {
    let mut dirs = Vec::with_capacity(scan.beams.len());
    directions(scan, laser_heading(pose, scan), &mut dirs);
    score_with(grid, pose, scan, &dirs, o)
}

/// (score, log-likelihood, beams matched) of `pose`.
pub fn likelihood_and_score(
    grid: &TiledGrid,
    pose: &Pose2,
    scan: &PreparedScan,
    o: &SlamOptions,
) -> (Real, Real, usize) {
    let mut dirs = Vec::with_capacity(scan.beams.len());
    directions(scan, laser_heading(pose, scan), &mut dirs);
    let (mut s, mut l, mut n) = (0.0, 0.0, 0);
    let no_hit = NULL_LIKELIHOOD / o.lsigma;
    match_beams(grid, pose, scan, &dirs, o, |d2| match d2 {
        Some(d2) => {
            s += (-d2 / o.sigma).exp();
            l += -d2 / o.lsigma;
            n += 1;
        }
        None => l += no_hit,
    });
    (s, l, n)
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
}

/// Hill-climbs the score from `init` (GMapping's `optimize`).
pub fn optimize(grid: &TiledGrid, init: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Matched {
    let limit = match o.cutoff {
        Cutoff::Unbounded => u32::MAX,
        Cutoff::Evaluations(n) => n,
    };
    let mut current = *init;
    let mut current_dirs = Vec::with_capacity(scan.beams.len());
    let mut turned_dirs = Vec::with_capacity(scan.beams.len());
    let mut best_turned_dirs = Vec::with_capacity(scan.beams.len());
    directions(scan, laser_heading(&current, scan), &mut current_dirs);
    let mut current_score = score_with(grid, &current, scan, &current_dirs, o);
    let mut evaluations = 1;
    let (mut ld, mut ad) = (o.lstep, o.astep);
    let mut refinement = 0;
    let mut best_score = -1.0;
    loop {
        if best_score >= current_score {
            refinement += 1;
            ld *= 0.5;
            ad *= 0.5;
        }
        best_score = current_score;
        let mut best_local = current;
        let mut best_is_turn = false;
        for (dx, dy, dt) in [
            (ld, 0.0, 0.0),
            (-ld, 0.0, 0.0),
            (0.0, -ld, 0.0),
            (0.0, ld, 0.0),
            (0.0, 0.0, ad),
            (0.0, 0.0, -ad),
        ] {
            if evaluations >= limit {
                break;
            }
            let candidate = Pose2::new(current.x + dx, current.y + dy, current.theta + dt);
            let s = if dt == 0.0 {
                score_with(grid, &candidate, scan, &current_dirs, o)
            } else {
                directions(scan, laser_heading(&candidate, scan), &mut turned_dirs);
                score_with(grid, &candidate, scan, &turned_dirs, o)
            };
            evaluations += 1;
            if s > current_score {
                current_score = s;
                best_local = candidate;
                best_is_turn = dt != 0.0;
                if best_is_turn {
                    std::mem::swap(&mut best_turned_dirs, &mut turned_dirs);
                }
            }
        }
        if best_is_turn {
            std::mem::swap(&mut current_dirs, &mut best_turned_dirs);
        }
        current = best_local;
        let improving = current_score > best_score;
        if evaluations >= limit || !(improving || refinement < o.iterations) {
            break;
        }
    }
    Matched { pose: current, score: current_score, evaluations }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linemap::LineMap;
    use crate::slam::integrate::integrate_scan;

    /// A scan of `world` from `pose` (no noise), 360 beams over 360°.
    fn scan_of(world: &LineMap, pose: &Pose2) -> LaserReading {
        let n = 360;
        let inc = 2.0 * std::f64::consts::PI / n as f64;
        let ranges = (0..n)
            .map(|i| {
                world.cast((pose.x, pose.y), pose.theta + i as f64 * inc, 20.0).map_or(30.0, |r| r as f32)
            })
            .collect();
        LaserReading {
            stamp: 0.0,
            ranges,
            angle_min: 0.0,
            angle_increment: inc,
            range_min: 0.0,
            range_max: 30.0,
            odometry: *pose,
            laser_offset: Pose2::IDENTITY,
        }
    }

    /// An L-shaped room with a pillar: no direction is featureless.
    fn room() -> LineMap {
        LineMap::parse(
            "room",
            "0,0,8,0\n8,0,8,3\n8,3,5,3\n5,3,5,6\n5,6,0,6\n0,6,0,0\n2,2,2.5,2\n2.5,2,2.5,2.5\n2.5,2.5,2,2.5\n2,2.5,2,2\n",
        )
        .unwrap()
    }

    fn mapped(world: &LineMap, poses: &[Pose2]) -> TiledGrid {
        let mut g = TiledGrid::new(0.05, (0.0, 0.0));
        for p in poses {
            integrate_scan(&mut g, p, &scan_of(world, p), 20.0);
        }
        g
    }

    #[test]
    fn recovers_known_offsets() {
        let world = room();
        let truth = Pose2::new(3.3, 1.7, 0.4);
        let grid = mapped(&world, &[truth, Pose2::new(1.0, 4.0, -1.0), Pose2::new(6.5, 1.5, 2.0)]);
        let o = SlamOptions::default();
        let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
        let mut state = 12345u64;
        for _ in 0..20 {
            let mut r = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 33) as f64 / (1u64 << 31) as f64) - 0.5
            };
            let start = Pose2::new(truth.x + 0.2 * r(), truth.y + 0.2 * r(), truth.theta + 0.1 * r());
            let m = optimize(&grid, &start, &scan, &o);
            assert!(m.pose.distance(&truth) < 0.02, "from {start:?}: {:?}", m.pose);
            assert!((m.pose.theta - truth.theta).abs() < 0.01, "from {start:?}: {:?}", m.pose);
        }
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
        assert!(s > 0.0 && n > 300 && l > l_off, "{s} {l} {n} {l_off}");
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
