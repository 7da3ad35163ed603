//! Scan-to-scan matching (laser odometry): the motion between two
//! processed scans, from the scans alone, with its covariance.
//!
//! SLAM's output smoother (squall-bolts' `pf::smoother`) fuses three
//! estimates of each step between processed scans: the best lineage's, the
//! odometry's and this one; the clock-offset estimate ([`crate::clock`])
//! compares its turns with the odometry's. Its error is its own: it uses no map, so it shares neither the
//! lineage's slow wander against its map nor the wheels' slip. Over one
//! step indoors it is better than both (decision 0014).
//!
//! Point-to-line ICP (Censi's PL-ICP without its closed form; Chen and
//! Medioni's point-to-plane in 2-D): the later scan's points, moved by the
//! odometry's guess, are paired with their nearest points of the earlier
//! scan, and the distance to the line through each one's neighbours is
//! minimised by Gauss–Newton, with a pairing distance that shrinks as the
//! match settles. The covariance is the residual's variance times the
//! inverse of JᵀJ: degenerate where the scene is (along a corridor), which
//! is what the smoother needs to trust the odometry there. Its scale is
//! not trusted: the smoother fits one per component.

use serde::{Deserialize, Serialize};

use crate::covariance::{Mat3, ZERO, apply, inverse};
use crate::geometry::{Pose2, Real};
use crate::sensor::LaserReading;

/// A measurement of the motion between two consecutive processed
/// readings made apart from a filter (for SLAM, the later scan matched
/// against the earlier one), with its covariance, whose scale the
/// smoother does not trust and fits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeasuredStep {
    /// The motion, in the earlier reading's frame.
    pub motion: Pose2,
    /// Its covariance in (x, y, θ), up to scale.
    pub covariance: Mat3,
}

/// Iterations of pairing and Gauss–Newton, at most (a match that has
/// [`SETTLED`] stops early).
const ITERATIONS: usize = 25;
/// Pairing distance at the start, metres; halved every
/// [`SHRINK_EVERY`] iterations down to [`LAST_PAIRING`].
const FIRST_PAIRING: Real = 0.5;
const SHRINK_EVERY: usize = 4;
const LAST_PAIRING: Real = 0.08;
/// Neighbours a line is fitted through, and how flat they must lie: the
/// smaller eigenvalue of their scatter at most this share of the larger.
const LINE_POINTS: usize = 5;
const FLATNESS: Real = 0.05;
/// The Gauss–Newton step (m, rad) below which a match has settled: the
/// iterations left would change only the last bits. (A micrometre saves
/// twice the time but moves the filter's results:
/// docs/results/slam-speed.md.)
const SETTLED: Real = 1e-12;
/// Fewest pairs a match is made from.
const MIN_PAIRS: usize = 10;
/// The grid's cell, metres: the first pairing distance, so a point's
/// candidates lie in its cell and the eight around it.
const CELL: Real = FIRST_PAIRING;
/// Rings of cells searched for a line's neighbours (up to 2 m away: far
/// walls are sampled sparsely by long beams).
const LINE_RINGS: i64 = 4;

/// The earlier scan, indexed for nearest-point queries: its points in the
/// robot's frame, the line normal at each (where its neighbours lie on a
/// line), and a grid over their bounding box: the points of cell c are
/// `order[starts[c]..starts[c + 1]]`, in index order.
struct Reference {
    points: Vec<(Real, Real)>,
    /// Each point's line normal, fitted the first time the point is paired
    /// (`None` until then): most of a scan's points never are.
    normals: Vec<Option<Option<(Real, Real)>>>,
    /// The grid's first cell and its size in cells.
    corner: (i64, i64),
    size: (i64, i64),
    starts: Vec<u32>,
    order: Vec<u32>,
}

fn cell_of(p: (Real, Real)) -> (i64, i64) {
    ((p.0 / CELL).floor() as i64, (p.1 / CELL).floor() as i64)
}

impl Reference {
    fn new(points: Vec<(Real, Real)>) -> Self {
        let cells: Vec<(i64, i64)> = points.iter().map(|&p| cell_of(p)).collect();
        let lo = cells.iter().fold((i64::MAX, i64::MAX), |a, c| (a.0.min(c.0), a.1.min(c.1)));
        let hi = cells.iter().fold((i64::MIN, i64::MIN), |a, c| (a.0.max(c.0), a.1.max(c.1)));
        let (corner, size) =
            if cells.is_empty() { ((0, 0), (0, 0)) } else { (lo, (hi.0 - lo.0 + 1, hi.1 - lo.1 + 1)) };
        // Counting sort of the points by cell, keeping index order within
        // each cell.
        let index = |c: (i64, i64)| ((c.1 - corner.1) * size.0 + (c.0 - corner.0)) as usize;
        let mut starts = vec![0u32; (size.0 * size.1) as usize + 1];
        for &c in &cells {
            starts[index(c) + 1] += 1;
        }
        for k in 1..starts.len() {
            starts[k] += starts[k - 1];
        }
        let mut next = starts.clone();
        let mut order = vec![0u32; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            let slot = &mut next[index(c)];
            order[*slot as usize] = i as u32;
            *slot += 1;
        }
        let normals = vec![None; points.len()];
        Reference { points, normals, corner, size, starts, order }
    }

    /// The line normal at point `i` (see [`Self::normal_at`]), fitted once.
    fn normal(&mut self, i: usize) -> Option<(Real, Real)> {
        if let Some(n) = self.normals[i] {
            return n;
        }
        let n = self.normal_at(i);
        self.normals[i] = Some(n);
        n
    }

    /// Indices of the points in the cell `c` (none outside the grid).
    fn in_cell(&self, c: (i64, i64)) -> &[u32] {
        let (x, y) = (c.0 - self.corner.0, c.1 - self.corner.1);
        if x < 0 || y < 0 || x >= self.size.0 || y >= self.size.1 {
            return &[];
        }
        let k = (y * self.size.0 + x) as usize;
        &self.order[self.starts[k] as usize..self.starts[k + 1] as usize]
    }

    /// Calls `f` with the index and squared distance of every point in
    /// the cells `rings` or fewer cells from `p`'s.
    fn around(&self, p: (Real, Real), rings: i64, mut f: impl FnMut(usize, Real)) {
        let (cx, cy) = cell_of(p);
        for gy in cy - rings..=cy + rings {
            for gx in cx - rings..=cx + rings {
                for &i in self.in_cell((gx, gy)) {
                    let q = self.points[i as usize];
                    f(i as usize, (q.0 - p.0).powi(2) + (q.1 - p.1).powi(2));
                }
            }
        }
    }

    /// The nearest point within [`CELL`] of `p` and its squared distance.
    fn nearest(&self, p: (Real, Real)) -> Option<(usize, Real)> {
        let mut best: Option<(usize, Real)> = None;
        self.around(p, 1, |i, d| {
            if best.is_none_or(|b| d < b.1) {
                best = Some((i, d));
            }
        });
        best
    }

    /// The unit normal of the line through point `i` and its nearest
    /// neighbours, if they lie on one.
    fn normal_at(&self, i: usize) -> Option<(Real, Real)> {
        let p = self.points[i];
        let mut nearest = [(usize::MAX, Real::INFINITY); LINE_POINTS];
        self.around(p, LINE_RINGS, |j, d| {
            if d < nearest[LINE_POINTS - 1].1 {
                nearest[LINE_POINTS - 1] = (j, d);
                nearest.sort_unstable_by(|a, b| a.1.total_cmp(&b.1));
            }
        });
        if nearest.iter().any(|n| n.0 == usize::MAX) {
            return None;
        }
        let n = LINE_POINTS as Real;
        let (mx, my) = nearest
            .iter()
            .fold((0.0, 0.0), |(x, y), &(j, _)| (x + self.points[j].0 / n, y + self.points[j].1 / n));
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for &(j, _) in &nearest {
            let (dx, dy) = (self.points[j].0 - mx, self.points[j].1 - my);
            (sxx, sxy, syy) = (sxx + dx * dx, sxy + dx * dy, syy + dy * dy);
        }
        // The normal is the scatter's eigenvector of the smaller eigenvalue.
        let (small, large, normal) = smaller_eigen(sxx, sxy, syy);
        if large <= 1e-12 || small > FLATNESS * large {
            return None;
        }
        Some(normal)
    }
}

/// The eigenvalues (smaller, larger) of the symmetric 2 × 2 matrix
/// [[a, b], [b, c]] and the unit eigenvector of the smaller.
fn smaller_eigen(a: Real, b: Real, c: Real) -> (Real, Real, (Real, Real)) {
    let half_trace = 0.5 * (a + c);
    let root = (0.25 * (a - c).powi(2) + b * b).sqrt();
    let (small, large) = (half_trace - root, half_trace + root);
    // (b, small − a) solves (M − small·I) v = 0 unless b vanishes; then
    // the axes are the eigenvectors.
    let (vx, vy) = if b.abs() > 1e-15 {
        (b, small - a)
    } else if a < c {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let norm = vx.hypot(vy);
    (small, large, (vx / norm, vy / norm))
}

/// The returning beams' end points of `scan` in the robot's frame.
fn points_of(scan: &LaserReading) -> Vec<(Real, Real)> {
    (0..scan.ranges.len()).filter(|&i| scan.is_valid(i)).map(|i| scan.end_point(i)).collect()
}

/// The motion of the robot from `from` to `to` (in `from`'s frame) that
/// best lays `to`'s scan onto `from`'s, starting from the odometry's, with
/// its covariance; `None` where too few points pair up.
pub fn match_scans(from: &LaserReading, to: &LaserReading) -> Option<MeasuredStep> {
    match_scans_from(from, to, to.odometry.relative_to(&from.odometry))
}

/// As [`match_scans`], starting from `guess` (the motion in `from`'s
/// frame) instead of the odometry's.
pub fn match_scans_from(from: &LaserReading, to: &LaserReading, guess: Pose2) -> Option<MeasuredStep> {
    let mut reference = Reference::new(points_of(from));
    let moving = points_of(to);
    let (mut x, mut y, mut theta) = (guess.x, guess.y, guess.theta);
    let mut last = None;
    for iteration in 0..ITERATIONS {
        let pairing = (FIRST_PAIRING * 0.5f64.powi((iteration / SHRINK_EVERY) as i32)).max(LAST_PAIRING);
        let (s, c) = theta.sin_cos();
        let (mut h, mut g, mut squares, mut pairs) = (ZERO, [0.0; 3], 0.0, 0usize);
        for &(px, py) in &moving {
            let p = (x + c * px - s * py, y + s * px + c * py);
            let Some((i, d2)) = reference.nearest(p) else { continue };
            if d2 >= pairing * pairing {
                continue;
            }
            let Some(n) = reference.normal(i) else { continue };
            let q = reference.points[i];
            // Residual: the distance along the normal; its derivative in
            // (x, y, θ).
            let r = n.0 * (p.0 - q.0) + n.1 * (p.1 - q.1);
            let (rx, ry) = (p.0 - x, p.1 - y);
            let j = [n.0, n.1, n.0 * -ry + n.1 * rx];
            for a in 0..3 {
                g[a] += j[a] * r;
                for b in 0..3 {
                    h[a][b] += j[a] * j[b];
                }
            }
            squares += r * r;
            pairs += 1;
        }
        if pairs < MIN_PAIRS {
            return None;
        }
        for (a, row) in h.iter_mut().enumerate() {
            row[a] += 1e-9;
        }
        let inv = inverse(&h)?;
        let d = apply(&inv, g);
        (x, y, theta) = (x - d[0], y - d[1], theta - d[2]);
        last = Some((h, squares / pairs as Real));
        // At the last pairing distance a step this small leaves the pairs
        // as they are: the remaining iterations would repeat this one.
        if pairing <= LAST_PAIRING && d.iter().all(|v| v.abs() < SETTLED) {
            break;
        }
    }
    let (h, variance) = last?;
    let mut regularised = h;
    for (a, row) in regularised.iter_mut().enumerate() {
        row[a] += 1e-6;
    }
    let mut covariance = inverse(&regularised)?.map(|row| row.map(|v| v * variance.max(1e-8)));
    unmeasured_directions(&h, &mut covariance);
    Some(MeasuredStep { motion: Pose2::new(x, y, theta), covariance })
}

/// Pairs' worth of wall that must face a direction for the match to
/// measure the motion along it: as many as a match is made from.
const MIN_SUPPORT: Real = MIN_PAIRS as Real;

/// The variance (m²) given to the motion along a direction the match does
/// not measure: a metre, more than any step between scans.
const UNMEASURED: Real = 1.0;

/// Widens `covariance` along each horizontal direction that fewer than
/// [`MIN_SUPPORT`] pairs pin: the translational block of `h` is Σ n nᵀ
/// over the pairs' unit normals, so its eigenvalues count the pairs
/// facing each way. Along a corridor the smaller counts only the few
/// points on door jambs and pillars, often one or two; the residuals of
/// so few say nothing of how far off the match may be along it, and it is
/// often a tenth of a metre off while its fit claims a centimetre (on
/// the simulated `ring`'s corridors, 391 steps of 12 000 taken for wheel
/// slips, decision 0039). Such a direction is reported as not measured.
fn unmeasured_directions(h: &Mat3, covariance: &mut Mat3) {
    let (small, large, (ux, uy)) = smaller_eigen(h[0][0], h[0][1], h[1][1]);
    if large < MIN_SUPPORT {
        // Neither direction is measured.
        covariance[0][0] += UNMEASURED;
        covariance[1][1] += UNMEASURED;
        return;
    }
    if small >= MIN_SUPPORT {
        return;
    }
    covariance[0][0] += UNMEASURED * ux * ux;
    covariance[0][1] += UNMEASURED * ux * uy;
    covariance[1][0] += UNMEASURED * ux * uy;
    covariance[1][1] += UNMEASURED * uy * uy;
}

#[cfg(test)]
pub(crate) mod room {
    //! A scene for tests of scan matching: a rectangular room with pillars.

    use super::*;

    /// A scan of a rectangular room with half-sizes `half` and the robot
    /// at `pose` (room frame, centre at the origin), 360 beams over 360°,
    /// and square pillars 0.6 m wide at `pillars`.
    pub(crate) fn scan_in_room(
        pose: Pose2,
        odometry: Pose2,
        half: (Real, Real),
        pillars: &[(Real, Real)],
    ) -> LaserReading {
        let beams = 360;
        let increment = std::f64::consts::TAU / beams as Real;
        let ranges = (0..beams)
            .map(|i| {
                let a = pose.theta + i as Real * increment - std::f64::consts::PI;
                let (dx, dy) = (a.cos(), a.sin());
                let mut best = Real::INFINITY;
                for (wall, dir, origin) in [(half.0, dx, pose.x), (-half.0, dx, pose.x)] {
                    if dir.abs() > 1e-12 {
                        let t = (wall - origin) / dir;
                        if t > 0.0 {
                            best = best.min(t);
                        }
                    }
                }
                for (wall, dir, origin) in [(half.1, dy, pose.y), (-half.1, dy, pose.y)] {
                    if dir.abs() > 1e-12 {
                        let t = (wall - origin) / dir;
                        if t > 0.0 {
                            best = best.min(t);
                        }
                    }
                }
                for &(cx, cy) in pillars {
                    for k in 0..4 {
                        let (wall, along) = match k {
                            0 => ((cx - 0.3 - pose.x, dx), (dy, pose.y, cy)),
                            1 => ((cx + 0.3 - pose.x, dx), (dy, pose.y, cy)),
                            2 => ((cy - 0.3 - pose.y, dy), (dx, pose.x, cx)),
                            _ => ((cy + 0.3 - pose.y, dy), (dx, pose.x, cx)),
                        };
                        if wall.1.abs() > 1e-12 {
                            let t = wall.0 / wall.1;
                            let hit = along.1 + t * along.0;
                            if t > 0.0 && (hit - along.2).abs() <= 0.3 {
                                best = best.min(t);
                            }
                        }
                    }
                }
                best as f32
            })
            .collect();
        LaserReading {
            stamp: 0.0,
            ranges,
            angle_min: -std::f64::consts::PI,
            angle_increment: increment,
            range_min: 0.05,
            range_max: 30.0,
            odometry,
            laser_offset: Pose2::IDENTITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use room::scan_in_room;

    #[test]
    fn recovers_the_motion_from_a_wrong_guess() {
        let half = (5.0, 3.0);
        let (a, b) = (Pose2::new(-1.0, -0.5, 0.1), Pose2::new(-0.1, -0.3, 0.25));
        // The odometry is 15 cm and 3° off.
        let from = scan_in_room(a, a, half, &[(2.0, 1.0)]);
        let wrong = a.compose(&b.relative_to(&a).compose(&Pose2::new(0.12, -0.09, 0.05)));
        let to = scan_in_room(b, wrong, half, &[(2.0, 1.0)]);
        let m = match_scans(&from, &to).expect("a room matches");
        let truth = b.relative_to(&a);
        assert!(m.motion.distance(&truth) < 0.005, "{:?} against {truth:?}", m.motion);
        assert!((m.motion.theta - truth.theta).abs() < 0.002);
        // A clean match: a covariance of millimetres or less.
        assert!(m.covariance[0][0] < 1e-4 && m.covariance[1][1] < 1e-4, "{:?}", m.covariance);
    }

    #[test]
    fn a_corridor_leaves_the_motion_along_it_uncertain() {
        // A corridor 200 m long and 2 m wide, beams to 30 m: the walls
        // constrain y and θ, nothing constrains x.
        let half = (100.0, 1.0);
        let (a, b) = (Pose2::new(0.0, 0.2, 0.0), Pose2::new(1.0, 0.1, 0.02));
        let (from, to) = (scan_in_room(a, a, half, &[]), scan_in_room(b, b, half, &[]));
        let m = match_scans(&from, &to).expect("the walls match");
        let along = m.covariance[0][0].sqrt();
        let across = m.covariance[1][1].sqrt();
        assert!(along > 20.0 * across, "along {along} m, across {across} m");
    }

    #[test]
    fn a_corridor_with_one_pillar_does_not_measure_the_motion_along_it() {
        // The corridor above with a pillar far ahead: its face, a few beams
        // wide at 25 m, is all that faces along the corridor. Its
        // residuals alone would claim centimetres; the match reports the
        // motion along x as not measured (a metre or more), across it as
        // before.
        let half = (100.0, 1.0);
        let pillars = [(26.0, 0.6)];
        let (a, b) = (Pose2::new(0.0, 0.2, 0.0), Pose2::new(0.06, 0.2, 0.0));
        let (from, to) = (scan_in_room(a, a, half, &pillars), scan_in_room(b, b, half, &pillars));
        let m = match_scans(&from, &to).expect("the walls match");
        let along = m.covariance[0][0].sqrt();
        let across = m.covariance[1][1].sqrt();
        assert!(along >= 1.0, "along {along} m");
        assert!(across < 0.01, "across {across} m");
        // A room pins both: nothing is widened.
        let room = (5.0, 3.0);
        let (from, to) = (scan_in_room(a, a, room, &[]), scan_in_room(b, b, room, &[]));
        let m = match_scans(&from, &to).expect("the room matches");
        assert!(m.covariance[0][0] < 1e-4 && m.covariance[1][1] < 1e-4, "{:?}", m.covariance);
    }

    #[test]
    fn too_few_points_give_no_match() {
        let a = Pose2::IDENTITY;
        let mut from = scan_in_room(a, a, (5.0, 3.0), &[(2.0, 1.0)]);
        from.ranges.iter_mut().skip(5).for_each(|r| *r = 0.0);
        assert!(match_scans(&from, &from).is_none());
    }
}
