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
/// its score reaches `min_score`: branch and bound, then refinement.
pub(crate) fn search(
    field: &Field,
    points: &[(Real, Real)],
    window: Window,
    min_score: Real,
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
    descend(&mut roots, reach_cells, &bound, &mut best, &mut best_bound);
    let best = best?;
    let (theta, _) = headings[best.heading];
    let coarse = Pose2::new(
        window.around.x + best.offset.0 as Real * r,
        window.around.y + best.offset.1 as Real * r,
        theta,
    );
    let refined = refine(field, points, coarse);
    (refined.score >= min_score).then_some(refined)
}

/// Depth-first over `candidates`, best bound first, pruning every branch
/// whose bound cannot beat the best leaf found.
fn descend(
    candidates: &mut [Candidate],
    reach: i64,
    bound: &impl Fn(&Candidate) -> u32,
    best: &mut Option<Candidate>,
    best_bound: &mut u32,
) {
    candidates.sort_by_key(|c| std::cmp::Reverse(c.bound));
    for c in candidates.iter() {
        if c.bound <= *best_bound {
            return;
        }
        if c.level == 0 {
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
        descend(&mut children, reach, bound, best, best_bound);
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
    Found { pose: best.0, score: best.1, curvature }
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
        let found =
            search(&field, &points, Window { around: guess, reach: 1.5, turn: 0.35 }, 0.5).expect("a match");
        assert!(found.pose.distance(&truth) < 0.02, "{:?}", found.pose);
        assert!((found.pose.theta - truth.theta).abs() < 0.005, "{:?}", found.pose);
        assert!(found.score > 0.8, "{}", found.score);
        // A window that does not hold the truth finds no match that good.
        let elsewhere = Window { around: Pose2::new(-3.0, -3.0, 2.0), reach: 0.5, turn: 0.1 };
        assert!(search(&field, &points, elsewhere, 0.5).is_none());
    }
}
