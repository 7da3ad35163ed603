//! Matching a scan against a submap over a wide window: exact branch and
//! bound over translations for each heading (Hess et al. 2016, after Olson
//! 2009), then a continuous refinement on the interpolated field.

use squall_core::covariance::{Mat3, ZERO};
use squall_core::geometry::{Pose2, Real};

use super::field::{FULL, Field};

/// A scan's pose in a submap's frame and how well its points fit there:
/// the mean field value under them, in 0..=1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Found {
    /// The pose.
    pub pose: Pose2,
    /// Mean field value under the points.
    pub score: Real,
    /// The fit's curvature at the pose, Σ ∇f ∇fᵀ over the points with
    /// respect to (x, y, θ) in the submap's frame: how sharply each
    /// direction is pinned (a corridor's axis hardly at all).
    pub curvature: Mat3,
    /// A pose away from it (0.5 m or 0.1 rad) that scores within 90% of
    /// it, if any was looked for and found: a ridge (a corridor's axis) or repeated structure
    /// (doors, rooms alike), where the match may be the wrong copy.
    pub rival: Option<Pose2>,
}

/// Where to look: around `around`, up to `reach` metres and `turn`
/// radians from it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Window {
    /// The centre of the search.
    pub around: Pose2,
    /// Metres each way in x and y.
    pub reach: Real,
    /// Radians each way.
    pub turn: Real,
}

/// Points the branch and bound scores at most.
const BRANCH_POINTS: usize = 80;

/// A rival pose at least this far from the best (metres, radians)...
const UNIQUE_APART: (Real, Real) = (0.5, 0.1);

/// ...that scores this fraction of the best makes the match ambiguous.
const UNIQUE_RATIO: Real = 0.9;

/// The leaves far enough from `best` to be its rivals.
#[derive(Debug, Clone, Copy)]
struct Apart {
    best: Candidate,
    cells: i64,
    headings: usize,
}

impl Apart {
    /// Whether `c` is away from the best in position or heading.
    fn holds(&self, c: &Candidate) -> bool {
        let (dx, dy) = (c.offset.0 - self.best.offset.0, c.offset.1 - self.best.offset.1);
        dx * dx + dy * dy >= self.cells * self.cells || c.heading.abs_diff(self.best.heading) >= self.headings
    }
}

/// A candidate: a heading, a cell offset and the level whose square of
/// offsets it stands for, with its bound (sum of byte values).
#[derive(Debug, Clone, Copy)]
struct Candidate {
    heading: usize,
    offset: (i64, i64),
    level: usize,
    bound: u32,
}

/// The best pose in `window` for `points` (robot frame) on `field`, if
/// its score reaches `min_score`: branch and bound, then refinement. Its
/// rival (see [`Found::rival`]) is looked for only if `wants_rival` says
/// so of the match, since it takes a second descent.
pub(crate) fn search(
    field: &Field,
    points: &[(Real, Real)],
    window: Window,
    min_score: Real,
    wants_rival: impl FnOnce(&Found) -> bool,
) -> Option<Found> {
    if points.is_empty() {
        return None;
    }
    let r = field.resolution;
    // The branch and bound scores an even subset of the points; the
    // refinement all of them.
    let stride = points.len().div_ceil(BRANCH_POINTS);
    let coarse_points: Vec<(Real, Real)> = points.iter().step_by(stride).copied().collect();
    let farthest = points.iter().map(|p| p.0.hypot(p.1)).fold(r, Real::max);
    // A heading step that moves the farthest point by about one cell.
    let step = (1.0 - r * r / (2.0 * farthest * farthest)).clamp(-1.0, 1.0).acos().max(1e-4);
    let half_headings = (window.turn / step).ceil() as i64;
    let reach_cells = (window.reach / r).ceil() as i64;
    // Each heading's points, as cells of the field at the window's centre.
    let headings: Vec<(Real, Vec<(i64, i64)>)> = (-half_headings..=half_headings)
        .map(|k| {
            let theta = window.around.theta + k as Real * step;
            let pose = Pose2 { x: window.around.x, y: window.around.y, theta };
            let (s, c) = theta.sin_cos();
            let cells = coarse_points
                .iter()
                .map(|&(px, py)| {
                    let (x, y) = (pose.x + c * px - s * py, pose.y + s * px + c * py);
                    (((x - field.origin.0) / r).floor() as i64, ((y - field.origin.1) / r).floor() as i64)
                })
                .collect();
            (theta, cells)
        })
        .collect();
    let bound = |c: &Candidate| -> u32 {
        headings[c.heading]
            .1
            .iter()
            .map(|&(x, y)| u32::from(field.at(c.level, x + c.offset.0, y + c.offset.1)))
            .sum()
    };
    let top = field.depth();
    let side = 1i64 << top;
    let mut roots = Vec::new();
    for heading in 0..headings.len() {
        let mut x = -reach_cells;
        while x <= reach_cells {
            let mut y = -reach_cells;
            while y <= reach_cells {
                let mut c = Candidate { heading, offset: (x, y), level: top, bound: 0 };
                c.bound = bound(&c);
                roots.push(c);
                y += side;
            }
            x += side;
        }
    }
    let threshold = (min_score * FULL * coarse_points.len() as Real).ceil() as u32;
    let mut best: Option<Candidate> = None;
    let mut best_bound = threshold.saturating_sub(1);
    descend(&mut roots, reach_cells, &bound, None, &mut best, &mut best_bound);
    let best = best?;
    let pose_of = |c: &Candidate| {
        Pose2::new(
            window.around.x + c.offset.0 as Real * r,
            window.around.y + c.offset.1 as Real * r,
            headings[c.heading].0,
        )
    };
    let mut refined = refine(field, points, pose_of(&best));
    if refined.score < min_score {
        return None;
    }
    if wants_rival(&refined) {
        // A rival: a pose away from the best (beyond a few cells or
        // heading steps) that scores nearly as well, as in a corridor
        // whose doors repeat or among rooms alike. The roots are sorted
        // already (stably), so the second descent sees them as the first.
        let apart = Apart {
            best,
            cells: (UNIQUE_APART.0 / r).ceil() as i64,
            headings: (UNIQUE_APART.1 / step).ceil() as usize,
        };
        let mut rival: Option<Candidate> = None;
        let mut rival_bound = ((UNIQUE_RATIO * Real::from(best.bound)).ceil() as u32).saturating_sub(1);
        descend(&mut roots, reach_cells, &bound, Some(&apart), &mut rival, &mut rival_bound);
        refined.rival = rival.as_ref().map(pose_of);
    }
    Some(refined)
}

/// Depth-first over `candidates`, best bound first, pruning every branch
/// whose bound cannot beat the best leaf found; leaves `excluded` holds
/// not are skipped.
fn descend(
    candidates: &mut [Candidate],
    reach: i64,
    bound: &impl Fn(&Candidate) -> u32,
    excluded: Option<&Apart>,
    best: &mut Option<Candidate>,
    best_bound: &mut u32,
) {
    candidates.sort_by_key(|c| std::cmp::Reverse(c.bound));
    for c in candidates.iter() {
        if c.bound <= *best_bound {
            return;
        }
        if c.level == 0 {
            if excluded.is_some_and(|e| !e.holds(c)) {
                continue;
            }
            *best = Some(*c);
            *best_bound = c.bound;
            continue;
        }
        let half = 1i64 << (c.level - 1);
        let mut children: Vec<Candidate> = [(0, 0), (half, 0), (0, half), (half, half)]
            .iter()
            .map(|&(dx, dy)| (c.offset.0 + dx, c.offset.1 + dy))
            .filter(|&(x, y)| x <= reach && y <= reach)
            .map(|offset| {
                let mut child = Candidate { heading: c.heading, offset, level: c.level - 1, bound: 0 };
                child.bound = bound(&child);
                child
            })
            .collect();
        descend(&mut children, reach, bound, excluded, best, best_bound);
    }
}

/// The mean interpolated field value under `points` at `pose`.
pub(crate) fn score(field: &Field, points: &[(Real, Real)], pose: &Pose2) -> Real {
    let (s, c) = pose.theta.sin_cos();
    let total: Real = points
        .iter()
        .map(|&(px, py)| field.interpolate(pose.x + c * px - s * py, pose.y + s * px + c * py).0)
        .sum();
    total / points.len().max(1) as Real
}

/// The Gauss–Newton system of Σ (1 − f(pose ⊕ p))² at `pose`: JᵀJ and
/// Jᵀr.
fn normal_equations(field: &Field, points: &[(Real, Real)], pose: &Pose2) -> (Mat3, [Real; 3]) {
    let (s, c) = pose.theta.sin_cos();
    let mut h = ZERO;
    let mut g = [0.0; 3];
    for &(px, py) in points {
        let (x, y) = (pose.x + c * px - s * py, pose.y + s * px + c * py);
        let (v, dx, dy) = field.interpolate(x, y);
        let residual = 1.0 - v;
        // d(residual)/d(x, y, θ).
        let j = [-dx, -dy, -(dx * (-s * px - c * py) + dy * (c * px - s * py))];
        for a in 0..3 {
            g[a] += j[a] * residual;
            for b in 0..3 {
                h[a][b] += j[a] * j[b];
            }
        }
    }
    (h, g)
}

/// Gauss–Newton on Σ (1 − f(pose ⊕ p))² from `start`, a few damped steps,
/// keeping the best-scoring pose seen, with the curvature there.
fn refine(field: &Field, points: &[(Real, Real)], start: Pose2) -> Found {
    let mut best = (start, score(field, points, &start));
    for _ in 0..10 {
        let pose = best.0;
        let (mut h, g) = normal_equations(field, points, &pose);
        for (a, row) in h.iter_mut().enumerate() {
            row[a] = row[a] * 1.1 + 1e-9;
        }
        let Some(inv) = squall_core::covariance::inverse(&h) else { break };
        let d = squall_core::covariance::apply(&inv, g);
        let next = Pose2::new(pose.x - d[0], pose.y - d[1], pose.theta - d[2]);
        let next_score = score(field, points, &next);
        if next_score <= best.1 {
            break;
        }
        best = (next, next_score);
        if d[0].abs().max(d[1].abs()) < 1e-4 && d[2].abs() < 1e-5 {
            break;
        }
    }
    let (curvature, _) = normal_equations(field, points, &best.0);
    Found { pose: best.0, score: best.1, curvature, rival: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An L-shaped room corner and a wall stub: points every 2 cm.
    fn room() -> Vec<(Real, Real)> {
        let mut points = Vec::new();
        for i in 0..300 {
            let t = i as Real * 0.02;
            points.push((t, 0.0));
            points.push((0.0, t));
            points.push((3.0, 1.0 + 0.5 * t.min(2.0)));
        }
        points
    }

    #[test]
    fn finds_a_pose_far_from_the_guess() {
        let map = room();
        let field = Field::build(&map, 0.05, 0.05, 5, 2.5);
        let truth = Pose2::new(1.5, 1.2, 0.3);
        // The scan: the map's points as the robot at `truth` sees them.
        let inverse = truth.inverse();
        let points: Vec<(Real, Real)> = map
            .iter()
            .step_by(7)
            .map(|&(x, y)| {
                let p = inverse.compose(&Pose2::new(x, y, 0.0));
                (p.x, p.y)
            })
            .collect();
        let guess = Pose2::new(2.4, 0.6, 0.1);
        let found = search(&field, &points, Window { around: guess, reach: 1.5, turn: 0.35 }, 0.5, |_| true)
            .expect("a match");
        assert!(found.pose.distance(&truth) < 0.02, "{:?}", found.pose);
        assert!((found.pose.theta - truth.theta).abs() < 0.005, "{:?}", found.pose);
        assert!(found.score > 0.8, "{}", found.score);
        assert!(found.rival.is_none(), "the room's corner has no double: {:?}", found.rival);
        // A window that does not hold the truth finds no match that good.
        let elsewhere = Window { around: Pose2::new(-3.0, -3.0, 2.0), reach: 0.5, turn: 0.1 };
        assert!(search(&field, &points, elsewhere, 0.5, |_| true).is_none());
    }

    #[test]
    fn repeated_structure_has_a_rival() {
        // A wall with a post every metre: seen from close by, one stretch
        // of it looks like the next.
        let mut map = Vec::new();
        for i in 0..600 {
            let x = i as Real * 0.02;
            map.push((x, 0.0));
            if i % 50 < 5 {
                map.push((x, 0.1));
            }
        }
        let field = Field::build(&map, 0.05, 0.05, 5, 2.5);
        let truth = Pose2::new(6.0, 1.0, 0.0);
        let points: Vec<(Real, Real)> = map
            .iter()
            .filter(|p| (p.0 - truth.x).abs() < 1.2)
            .map(|&(x, y)| (x - truth.x, y - truth.y))
            .collect();
        let found = search(&field, &points, Window { around: truth, reach: 1.5, turn: 0.1 }, 0.3, |_| true)
            .expect("a match");
        let rival = found.rival.expect("a post a metre on");
        assert!((rival.x - found.pose.x).abs() > 0.5, "{rival:?} against {:?}", found.pose);
    }
}
