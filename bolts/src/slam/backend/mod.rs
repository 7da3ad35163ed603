//! The pose-graph back end: loop closures on the best lineage, found by a
//! wide branch-and-bound search against submaps of its own older scans,
//! and the trajectory and map bent to fit them (the global SLAM of Hess et
//! al. 2016, behind GMapping's particle filter as its front end).
//!
//! The particle filter closes a loop only where some particle happens to
//! come back close enough for its matcher to snap onto the old walls; a
//! loop that comes back further off (odometry whose heading drifts, a long
//! way round) leaves the map bent and doubled. After the run, the best
//! lineage is turned into a graph: a node every metre or so, each joined
//! to the next by the lineage's own motion between them (the chain), and
//! the nodes grouped into submaps of a few consecutive scans each.
//!
//! Walking the nodes in order, each (every `search_every`-th, with enough
//! points to pin a pose) is matched against the nearest older submaps that
//! its current estimate lies within `reach` of, over ± `reach` and
//! ± `turn`. A match whose points fit the submap well becomes a loop
//! constraint whose information follows the match's own curvature, so a
//! corridor's match holds the heading and the position across it but
//! hardly the position along it. A loop that agrees with the poses so far
//! is added at once. One that disagrees is dropped if the scan scores a
//! pose that agrees nearly as well (repeated doors or rooms), and otherwise
//! waits for a second match, a few nodes on, that moves the robot the same
//! way; then both are added
//! and the graph is optimized, so that the next searches start from poses
//! already corrected. At the end the whole graph is optimized, then again
//! with the loops under a Cauchy loss, so that a loop the others do not
//! bear out counts for little.
//!
//! The result is a correction of what is written, not of the filter: each
//! scan's pose moves with the nodes around it, and the map is rebuilt from
//! the nodes' scans along the corrected poses. With no loop found, the
//! poses are the lineage's, bit for bit. Everything here is a pure function
//! of the lineage and its scans, so any number of matcher tasks gives the
//! same result.

mod bolt;
mod field;
mod graph;
mod search;

pub use bolt::Backend;

use serde::{Deserialize, Serialize};

use squall_core::covariance::{Mat3, ZERO, diagonal, mul, transpose};
use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::sensor::LaserReading;

use crate::pf::trajectory::blend;
use field::Field;
use graph::{Constraint, constraint_chi2, optimize, optimize_from};
use search::{Found, Window, search};

/// The back end's settings: the params of the `slam.backend` bolt.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackendOptions {
    /// Whether loops are closed on the best lineage after the run.
    pub enabled: bool,
    /// A node every this many metres of odometry travel...
    pub node_distance: Real,
    /// ...or radians of turning.
    pub node_turn: Real,
    /// Consecutive nodes per submap.
    pub submap_nodes: usize,
    /// Beams used for loop search up to this range, metres.
    pub range: Real,
    /// Metres each way the loop search covers around the estimate.
    pub reach: Real,
    /// Radians each way the loop search covers.
    pub turn: Real,
    /// Least mean field value under a scan's points for a loop.
    pub min_score: Real,
    /// A submap is searched only once the path since its last node is
    /// this long, metres (nearer, the chain already holds it).
    pub min_loop_path: Real,
    /// Every this many nodes is searched.
    pub search_every: usize,
    /// A loop found mid-run bends at most this many of the latest nodes,
    /// the older ones held (a local optimization, as in ORB-SLAM's local
    /// bundle adjustment); the whole graph is optimized at the end and
    /// whenever it has doubled since it last was. Bounds the cost of a
    /// long run's loops: without it every loop re-optimizes the whole
    /// graph, and a run that comes back to the same rooms for hours costs
    /// time quadratic in its length.
    pub window_nodes: usize,
    /// Cell size of the submaps' fields, metres.
    pub resolution: Real,
    /// Beams used up to this range when the map is rebuilt along the
    /// corrected poses, metres (the matcher's `max_urange`).
    pub map_range: Real,
}

impl Default for BackendOptions {
    fn default() -> Self {
        BackendOptions {
            enabled: true,
            node_distance: 1.0,
            node_turn: 0.5,
            submap_nodes: 10,
            range: 15.0,
            reach: 2.0,
            turn: 0.3,
            min_score: 0.55,
            min_loop_path: 30.0,
            search_every: 2,
            window_nodes: 1000,
            resolution: 0.05,
            map_range: 80.0,
        }
    }
}

impl BackendOptions {
    /// Why these settings cannot run, naming the setting.
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("node_distance", self.node_distance),
            ("node_turn", self.node_turn),
            ("range", self.range),
            ("reach", self.reach),
            ("turn", self.turn),
            ("resolution", self.resolution),
            ("map_range", self.map_range),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a finite number > 0, got {v}"));
            }
        }
        if !(self.min_loop_path.is_finite() && self.min_loop_path >= 0.0) {
            return Err(format!("min_loop_path must be a finite number ≥ 0, got {}", self.min_loop_path));
        }
        if !(0.0..=1.0).contains(&self.min_score) {
            return Err(format!("min_score must be in [0, 1], got {}", self.min_score));
        }
        if self.submap_nodes == 0 || self.search_every == 0 || self.window_nodes < 2 {
            return Err("submap_nodes and search_every must be ≥ 1, window_nodes ≥ 2".to_string());
        }
        if self.reach / self.resolution > 2000.0 || self.range / self.resolution > 4000.0 {
            return Err(format!(
                "reach and range must stay within 2000 and 4000 cells of resolution {} m",
                self.resolution
            ));
        }
        Ok(())
    }
}

/// Standard deviation of a loop constraint: the match's precision after
/// refinement (metres, radians).
const LOOP_SIGMA: (Real, Real) = (0.05, 0.01);

/// Standard deviation of the chain between two nodes: a fixed part and
/// a part per metre travelled (metres, radians).
const CHAIN_SIGMA: (Real, Real) = (0.01, 0.002);
const CHAIN_SIGMA_PER_METRE: (Real, Real) = (0.02, 0.005);

/// A loop whose squared error at the poses so far is within this (χ² of
/// three degrees of freedom at 99%) agrees with them and is added at once.
const CONSISTENT_CHI2: Real = 11.34;

/// A loop that disagrees is added only with a second one, found within
/// this many searches of its node, that moves the robot the same way.
const VERIFY_WITHIN: usize = 3;

/// Two corrections agree if they place a node within this of each other
/// (metres, radians): about five loop standard deviations.
const AGREE: (Real, Real) = (0.25, 0.05);

/// A node is searched only if its scan has this many points (after
/// thinning, within `range`): fewer, a few metres of wall, and a match
/// can slide along them.
const MIN_POINTS: usize = 80;

/// Submaps searched per node at most, the nearest: in a small building
/// every node is near many, and the nearest say the most.
const CANDIDATES_PER_NODE: usize = 3;

/// Submap fields kept built at once.
const KEPT_FIELDS: usize = 8;

/// Points per scan kept for the search: at most one per cell of this
/// size, metres.
const VOXEL: Real = 0.1;

/// Gauss–Newton steps after a loop that disagrees with the poses so far,
/// and at the end.
const STEPS_INCREMENTAL: usize = 2;
const STEPS_FINAL: usize = 10;

/// What the back end found, for the metrics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct BackendReport {
    /// Nodes of the graph.
    pub nodes: usize,
    /// Searches run.
    pub searches: usize,
    /// Loop constraints added.
    pub loops: usize,
    /// Optimizations run.
    pub optimizations: usize,
    /// Of those, the ones over the whole graph (the rest bent only the
    /// latest `window_nodes`).
    pub full_optimizations: usize,
    /// Largest move of a node by the optimization, metres.
    pub largest_move: Real,
}

/// A scan kept as a node: its stamp and its points (robot frame).
#[derive(Debug, Clone, PartialEq)]
pub struct NodeScan {
    /// The scan's stamp.
    pub stamp: f64,
    /// Beam end points in the robot's frame, thinned.
    pub points: Vec<(Real, Real)>,
}

/// Picks the scans that become nodes, from the readings as they come:
/// the first, then one whenever the odometry has moved `node_distance` or
/// turned `node_turn` since the last. It keeps the readings whole, for
/// the map rebuilt at the end.
#[derive(Debug, Clone)]
pub struct NodePicker {
    options: BackendOptions,
    last: Option<Pose2>,
    readings: Vec<LaserReading>,
}

impl NodePicker {
    /// A picker with `options`.
    pub fn new(options: BackendOptions) -> Self {
        NodePicker { options, last: None, readings: Vec::new() }
    }

    /// Offers a reading; keeps it if it is due.
    pub fn offer(&mut self, scan: &LaserReading) {
        if let Some(last) = self.last {
            let d = scan.odometry.relative_to(&last);
            if d.x.hypot(d.y) < self.options.node_distance && d.theta.abs() < self.options.node_turn {
                return;
            }
        }
        self.last = Some(scan.odometry);
        self.readings.push(scan.clone());
    }

    /// The readings kept, oldest first.
    pub fn readings(&self) -> &[LaserReading] {
        &self.readings
    }

    /// The nodes: each kept reading's stamp and thinned points.
    pub fn nodes(&self) -> Vec<NodeScan> {
        self.readings
            .iter()
            .map(|r| NodeScan { stamp: r.stamp, points: thinned_points(r, self.options.range) })
            .collect()
    }
}

/// The end points of `scan`'s beams up to `range` metres, in the robot's
/// frame, at most one per `VOXEL` cell.
fn thinned_points(scan: &LaserReading, range: Real) -> Vec<(Real, Real)> {
    let mut seen = std::collections::HashSet::new();
    let mut points = Vec::new();
    for i in 0..scan.ranges.len() {
        if !scan.is_valid(i) || Real::from(scan.ranges[i]) > range {
            continue;
        }
        let r = Real::from(scan.ranges[i]);
        let beam = scan.laser_offset.compose(&Pose2::new(0.0, 0.0, scan.beam_angle(i)));
        let (s, c) = beam.theta.sin_cos();
        let (x, y) = (beam.x + c * r, beam.y + s * r);
        if seen.insert(((x / VOXEL).floor() as i64, (y / VOXEL).floor() as i64)) {
            points.push((x, y));
        }
    }
    points
}

/// Submap `k`'s nodes: a run of consecutive ones, and the one it is
/// anchored to (its middle).
fn submap_nodes(k: usize, per: usize, nodes: usize) -> (std::ops::Range<usize>, usize) {
    let range = k * per..((k + 1) * per).min(nodes);
    let anchor = (range.start + range.end - 1) / 2;
    (range, anchor)
}

/// The poses of `trajectory` (stamp, pose: every scan, oldest first)
/// corrected by the loops closed between `nodes`, and what was found.
/// Nodes whose stamp is not in the trajectory are left out.
pub fn close_loops(
    trajectory: &[(f64, Pose2)],
    nodes: &[NodeScan],
    options: &BackendOptions,
) -> (Vec<(f64, Pose2)>, BackendReport) {
    let mut report = BackendReport::default();
    // Each node's index in the trajectory.
    let mut at = Vec::with_capacity(nodes.len());
    let mut kept = Vec::with_capacity(nodes.len());
    let mut i = 0;
    for node in nodes {
        while i < trajectory.len() && trajectory[i].0 < node.stamp {
            i += 1;
        }
        if i < trajectory.len() && trajectory[i].0 == node.stamp && !node.points.is_empty() {
            at.push(i);
            kept.push(node);
        }
    }
    let n = kept.len();
    report.nodes = n;
    if !options.enabled || n < 2 * options.submap_nodes.max(1) {
        return (trajectory.to_vec(), report);
    }
    let front: Vec<Pose2> = at.iter().map(|&i| trajectory[i].1).collect();
    // Path length along the lineage at each node.
    let mut path = vec![0.0; n];
    for k in 1..n {
        path[k] = path[k - 1] + front[k].distance(&front[k - 1]);
    }
    let chain: Vec<Constraint> = (1..n)
        .map(|k| {
            let measured = front[k].relative_to(&front[k - 1]);
            let metres = measured.x.hypot(measured.y);
            let sxy = CHAIN_SIGMA.0 + CHAIN_SIGMA_PER_METRE.0 * metres;
            let st = CHAIN_SIGMA.1 + CHAIN_SIGMA_PER_METRE.1 * (metres + measured.theta.abs());
            Constraint {
                from: k - 1,
                to: k,
                measured,
                information: diagonal([1.0 / (sxy * sxy), 1.0 / (sxy * sxy), 1.0 / (st * st)]),
                robust: false,
            }
        })
        .collect();
    let mut loops: Vec<Constraint> = Vec::new();
    // The node searched when each loop was added: a loop's `to` is at most
    // that, so the loops touching the nodes from k on were all added at k
    // or later, a suffix of `loops`.
    let mut added_at: Vec<usize> = Vec::new();
    let per = options.submap_nodes.max(1);
    let submaps = n.div_ceil(per);
    // The nodes' estimates up to the one searched; a node not reached yet
    // is `carry ∘ front`, moved rigidly with the last node optimized.
    let mut estimate: Vec<Pose2> = Vec::with_capacity(n);
    let mut carry = Pose2::IDENTITY;
    let mut nearby = SubmapIndex::new(options.reach);
    // Nodes in the graph at the last optimization over all of it.
    let mut last_full = 0;
    let mut fields: Vec<Option<Field>> = vec![None; submaps];
    let mut built_order: Vec<usize> = Vec::new();
    // A match that disagrees with the poses so far, waiting for a second
    // one that implies the same correction: (its constraint, its node, the
    // correction).
    let mut pending: Option<(Constraint, usize, Pose2)> = None;
    let (reach, turn) = (options.reach, options.turn);
    let window = options.window_nodes.max(2);
    for j in (0..n).step_by(options.search_every.max(1)) {
        while estimate.len() <= j {
            estimate.push(carry.compose(&front[estimate.len()]));
        }
        if kept[j].points.len() < MIN_POINTS {
            continue;
        }
        // Submaps no local optimization will move again (all their nodes
        // before the window of any later one) join the index.
        nearby.settle(j.saturating_sub(window), per, &estimate);
        let mut disagrees = false;
        // The old enough submaps near node j, nearest first.
        let mut candidates: Vec<(Real, usize)> = nearby
            .near(&estimate[j], (j + 1) / per)
            .filter_map(|s| {
                let (members, _) = submap_nodes(s, per, n);
                if members.end > j || path[j] - path[members.end - 1] < options.min_loop_path {
                    return None;
                }
                let nearest =
                    members.map(|m| estimate[m].distance(&estimate[j])).fold(Real::INFINITY, Real::min);
                (nearest <= reach).then_some((nearest, s))
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        candidates.truncate(CANDIDATES_PER_NODE);
        for &(_, s) in &candidates {
            let (members, anchor) = submap_nodes(s, per, n);
            let field = fields[s].get_or_insert_with(|| {
                built_order.push(s);
                build_field(&kept, &front, members.clone(), anchor, options)
            });
            let window = Window { around: estimate[j].relative_to(&estimate[anchor]), reach, turn };
            report.searches += 1;
            let constraint = |found: &Found| Constraint {
                from: anchor,
                to: j,
                measured: found.pose,
                information: loop_information(&found.curvature, &found.pose),
                robust: false,
            };
            // The rival matters only to a match that would move the poses.
            let moves = |found: &Found| constraint_chi2(&constraint(found), &estimate) > CONSISTENT_CHI2;
            let Some(found) = search(field, &kept[j].points, window, options.min_score, moves) else {
                continue;
            };
            let c = constraint(&found);
            if constraint_chi2(&c, &estimate) <= CONSISTENT_CHI2 {
                loops.push(c);
                added_at.push(j);
                report.loops += 1;
                continue;
            }
            // Where the scan scores a pose that agrees with the poses so far
            // nearly as well (doors or rooms alike), it gives no reason to
            // move them.
            let rival_agrees = |rival: Pose2| {
                constraint_chi2(&Constraint { measured: rival, ..c }, &estimate) <= CONSISTENT_CHI2
            };
            if found.rival.is_some_and(rival_agrees) {
                continue;
            }
            // Where this match would put node j, as a motion of the world.
            let correction = estimate[anchor].compose(&found.pose).compose(&estimate[j].inverse());
            match pending.take() {
                Some((first, at_node, earlier))
                    if j - at_node <= VERIFY_WITHIN * options.search_every
                        && agree(&earlier, &correction, &estimate[j]) =>
                {
                    loops.extend([first, c]);
                    added_at.extend([j, j]);
                    report.loops += 2;
                    disagrees = true;
                }
                _ => pending = Some((c, j, correction)),
            }
        }
        // Keep a few fields: the robot tends to come back to the same ones.
        while built_order.len() > KEPT_FIELDS {
            let old = built_order.remove(0);
            fields[old] = None;
        }
        if disagrees {
            // The whole graph while it fits the window, and each time it
            // has doubled; otherwise only the latest nodes, the older held.
            let first_free = if j < window || j + 1 >= 2 * last_full { 0 } else { j + 1 - window };
            let recent = added_at.partition_point(|&at| at < first_free);
            let touching = chain[first_free.saturating_sub(1)..j]
                .iter()
                .chain(loops[recent..].iter().filter(|c| c.to >= first_free))
                .copied()
                .collect::<Vec<_>>();
            optimize_from(&mut estimate[..=j], first_free, &touching, STEPS_INCREMENTAL);
            report.optimizations += 1;
            if first_free == 0 {
                report.full_optimizations += 1;
                last_full = j + 1;
                nearby.clear();
            }
            // The nodes not yet in the graph follow node j rigidly.
            carry = estimate[j].compose(&front[j].inverse());
        }
    }
    if report.loops == 0 {
        return (trajectory.to_vec(), report);
    }
    while estimate.len() < n {
        estimate.push(carry.compose(&front[estimate.len()]));
    }
    let mut constraints = chain;
    constraints.extend(loops);
    optimize(&mut estimate, &constraints, STEPS_FINAL);
    // Then again with the loops under the robust loss, so that a loop the
    // others do not bear out counts for little.
    for c in constraints.iter_mut().filter(|c| c.to != c.from + 1) {
        c.robust = true;
    }
    optimize(&mut estimate, &constraints, STEPS_FINAL);
    report.optimizations += 2;
    report.full_optimizations += 2;
    report.largest_move = estimate.iter().zip(&front).map(|(e, f)| e.distance(f)).fold(0.0, Real::max);
    (apply_corrections(trajectory, &at, &front, &estimate), report)
}

/// The submaps by where their nodes are: each settled submap (one whose
/// nodes no local optimization moves again) listed in the cells of its
/// nodes' estimates, so that the submaps near a node are found without
/// looking at every one; the unsettled ones, the latest few, are listed
/// whole. Cleared when an optimization over the whole graph moves the
/// settled ones.
#[derive(Debug)]
struct SubmapIndex {
    /// Cell size, the search's reach: a node within it of another lies in
    /// the other's cell or one of the eight around.
    cell: Real,
    cells: std::collections::HashMap<(i64, i64), Vec<usize>>,
    /// Submaps `0..settled` are in `cells`.
    settled: usize,
}

impl SubmapIndex {
    fn new(cell: Real) -> Self {
        SubmapIndex { cell, cells: std::collections::HashMap::new(), settled: 0 }
    }

    fn key(&self, p: &Pose2) -> (i64, i64) {
        ((p.x / self.cell).floor() as i64, (p.y / self.cell).floor() as i64)
    }

    /// Lists every submap whose nodes all lie before `held` (of `per`
    /// nodes each) by its nodes' `estimate`s.
    fn settle(&mut self, held: usize, per: usize, estimate: &[Pose2]) {
        while (self.settled + 1) * per <= held {
            let s = self.settled;
            for p in &estimate[s * per..(s + 1) * per] {
                let list = self.cells.entry(self.key(p)).or_default();
                if list.last() != Some(&s) {
                    list.push(s);
                }
            }
            self.settled += 1;
        }
    }

    /// Forgets every submap's place (the whole graph moved).
    fn clear(&mut self) {
        self.cells.clear();
        self.settled = 0;
    }

    /// The submaps that may have a node within a cell of `at`, each once:
    /// the settled ones listed near it, then every unsettled one before
    /// `upto`.
    fn near(&self, at: &Pose2, upto: usize) -> impl Iterator<Item = usize> {
        let (cx, cy) = self.key(at);
        let mut listed: Vec<usize> = (-1..=1)
            .flat_map(|dx| (-1..=1).map(move |dy| (cx.saturating_add(dx), cy.saturating_add(dy))))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
            .collect();
        listed.sort_unstable();
        listed.dedup();
        listed.into_iter().chain(self.settled..upto.max(self.settled))
    }
}

/// The field of submap `members`, in `anchor`'s frame, placed by the
/// lineage's own poses.
fn build_field(
    nodes: &[&NodeScan],
    front: &[Pose2],
    members: std::ops::Range<usize>,
    anchor: usize,
    options: &BackendOptions,
) -> Field {
    let mut points = Vec::new();
    for m in members {
        let local = front[m].relative_to(&front[anchor]);
        let (s, c) = local.theta.sin_cos();
        points
            .extend(nodes[m].points.iter().map(|&(x, y)| (local.x + c * x - s * y, local.y + s * x + c * y)));
    }
    let depth = ((options.reach / options.resolution).log2().ceil() as usize).clamp(1, 6);
    Field::build(&points, options.resolution, options.resolution, depth, options.reach)
}

/// A loop's information, shaped by the match's `curvature` (in the
/// submap's frame) and scaled so that its best-pinned position direction
/// and its heading have the standard deviations of `LOOP_SIGMA`: a match
/// in a corridor holds the heading and the position across it, and
/// barely the position along it (degeneracy-aware, after Zhang, Kaess and
/// Singh 2016). The constraint's error is taken in the frame of the
/// measured pose, so the position block is rotated into it.
fn loop_information(curvature: &Mat3, measured: &Pose2) -> Mat3 {
    let (a, b, c) = (curvature[0][0], curvature[0][1], curvature[1][1]);
    let largest = 0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let turning = curvature[2][2];
    if !(largest > 0.0 && turning > 0.0) {
        return ZERO;
    }
    let scale = diagonal([
        1.0 / (LOOP_SIGMA.0 * largest.sqrt()),
        1.0 / (LOOP_SIGMA.0 * largest.sqrt()),
        1.0 / (LOOP_SIGMA.1 * turning.sqrt()),
    ]);
    let shaped = mul(&mul(&scale, curvature), &scale);
    // Into the measured pose's frame: Rᵀ on the position block.
    let (s, co) = measured.theta.sin_cos();
    let rotation = [[co, -s, 0.0], [s, co, 0.0], [0.0, 0.0, 1.0]];
    mul(&transpose(&rotation), &mul(&shaped, &rotation))
}

/// Whether the corrections `a` and `b` (motions of the world) put `node`
/// in the same place.
fn agree(a: &Pose2, b: &Pose2, node: &Pose2) -> bool {
    let (pa, pb) = (a.compose(node), b.compose(node));
    pa.distance(&pb) <= AGREE.0 && normalize_angle(pa.theta - pb.theta).abs() <= AGREE.1
}

/// Every pose of `trajectory` moved with its nodes: between two nodes, the
/// two nodes' corrections applied and blended by the path travelled.
fn apply_corrections(
    trajectory: &[(f64, Pose2)],
    at: &[usize],
    front: &[Pose2],
    corrected: &[Pose2],
) -> Vec<(f64, Pose2)> {
    let corrections: Vec<Pose2> = corrected.iter().zip(front).map(|(c, f)| c.compose(&f.inverse())).collect();
    let mut along = vec![0.0; trajectory.len()];
    for i in 1..trajectory.len() {
        along[i] = along[i - 1] + trajectory[i].1.distance(&trajectory[i - 1].1);
    }
    let mut k = 0;
    trajectory
        .iter()
        .enumerate()
        .map(|(i, &(stamp, pose))| {
            while k + 1 < at.len() && at[k + 1] <= i {
                k += 1;
            }
            let a = corrections[k].compose(&pose);
            if i <= at[k] || k + 1 == at.len() {
                return (stamp, a);
            }
            let b = corrections[k + 1].compose(&pose);
            let span = along[at[k + 1]] - along[at[k]];
            let f = if span > 0.0 { (along[i] - along[at[k]]) / span } else { 0.0 };
            (stamp, blend(&a, &b, f))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::scenes::scan_of;
    use squall_core::linemap::LineMap;

    /// A loop corridor 4 m wide around a 16 × 8 m block, with pillars and
    /// door recesses so that no stretch of it is featureless.
    fn corridor() -> LineMap {
        let mut lines = String::from(
            "0,0,24,0\n24,0,24,16\n24,16,0,16\n0,16,0,0\n4,4,20,4\n20,4,20,12\n20,12,4,12\n4,12,4,4\n",
        );
        for &(x, y) in &[(7.0, 1.0), (13.0, 3.0), (22.5, 7.0), (16.0, 13.5), (9.0, 15.0), (1.5, 9.0)] {
            let s = 0.4;
            lines += &format!("{x},{y},{},{y}\n{},{y},{},{}\n", x + s, x + s, x + s, y + s);
        }
        LineMap::parse("corridor", &lines).unwrap()
    }

    /// The true path: around the corridor's middle once, then 12 m more,
    /// a scan every 0.25 m.
    fn truth() -> Vec<Pose2> {
        let corners = [(2.0, 2.0), (22.0, 2.0), (22.0, 14.0), (2.0, 14.0), (2.0, 2.0), (14.0, 2.0)];
        let mut poses = Vec::new();
        for w in corners.windows(2) {
            let ((x0, y0), (x1, y1)): ((Real, Real), (Real, Real)) = (w[0], w[1]);
            let heading = (y1 - y0).atan2(x1 - x0);
            let steps = ((x1 - x0).hypot(y1 - y0) / 0.25).round() as usize;
            for k in 0..steps {
                let f = k as Real / steps as Real;
                poses.push(Pose2::new(x0 + f * (x1 - x0), y0 + f * (y1 - y0), heading));
            }
        }
        poses
    }

    /// The truth as a front end that drifts in heading by `per_step`
    /// radians a scan would report it.
    fn drifting(truth: &[Pose2], per_step: Real) -> Vec<Pose2> {
        let mut out = vec![truth[0]];
        for (k, w) in truth.windows(2).enumerate() {
            let step = w[1].relative_to(&w[0]);
            let bent = Pose2::new(step.x, step.y, step.theta + per_step * (k % 3) as Real);
            out.push(out[k].compose(&bent));
        }
        out
    }

    /// Runs the back end on scans of `truth` placed by `front`.
    fn run(truth: &[Pose2], front: &[Pose2], options: &BackendOptions) -> (Vec<(f64, Pose2)>, BackendReport) {
        let world = corridor();
        let mut picker = NodePicker::new(*options);
        for (k, (t, f)) in truth.iter().zip(front).enumerate() {
            let mut scan = scan_of(&world, t);
            scan.stamp = k as f64;
            scan.odometry = *f;
            picker.offer(&scan);
        }
        let trajectory: Vec<(f64, Pose2)> = front.iter().enumerate().map(|(k, p)| (k as f64, *p)).collect();
        close_loops(&trajectory, &picker.nodes(), options)
    }

    fn mean_error(poses: &[(f64, Pose2)], truth: &[Pose2]) -> Real {
        poses.iter().zip(truth).map(|(p, t)| p.1.distance(t)).sum::<Real>() / truth.len() as Real
    }

    #[test]
    fn a_loop_that_comes_back_off_is_closed() {
        let truth = truth();
        let front = drifting(&truth, 0.0012);
        let before = mean_error(&front.iter().map(|p| (0.0, *p)).collect::<Vec<_>>(), &truth);
        let closing = front.last().unwrap().distance(truth.last().unwrap());
        assert!(closing > 0.5, "the front end comes back {closing} m off");
        let (poses, report) = run(&truth, &front, &BackendOptions::default());
        assert!(report.loops >= 2, "{report:?}");
        let after = mean_error(&poses, &truth);
        let closing_after = poses.last().unwrap().1.distance(truth.last().unwrap());
        assert!(after < 0.5 * before, "mean error {before} -> {after} m ({report:?})");
        assert!(closing_after < 0.2 * closing, "end {closing} -> {closing_after} m");
    }

    #[test]
    fn without_a_loop_the_poses_stay_bit_for_bit() {
        let truth = truth();
        let front = drifting(&truth, 0.0012);
        // A path shorter than a loop: only the first 40 m.
        let (truth, front) = (&truth[..160], &front[..160]);
        let (poses, report) = run(truth, front, &BackendOptions::default());
        assert_eq!(report.loops, 0);
        assert!(poses.iter().zip(front).all(|(p, f)| p.1 == *f));
    }

    #[test]
    fn switched_off_the_loop_stays_open() {
        let truth = truth();
        let front = drifting(&truth, 0.0012);
        let off = BackendOptions { enabled: false, ..BackendOptions::default() };
        let (poses, report) = run(&truth, &front, &off);
        assert_eq!((report.searches, report.loops), (0, 0));
        assert!(poses.iter().zip(&front).all(|(p, f)| p.1 == *f));
    }

    #[test]
    fn bad_settings_are_named() {
        let e = BackendOptions { reach: 0.0, ..BackendOptions::default() }.check().unwrap_err();
        assert!(e.contains("reach"), "{e}");
        let e = BackendOptions { min_score: 1.5, ..BackendOptions::default() }.check().unwrap_err();
        assert!(e.contains("min_score"), "{e}");
        let e = BackendOptions { resolution: 1e-6, ..BackendOptions::default() }.check().unwrap_err();
        assert!(e.contains("cells"), "{e}");
        assert!(BackendOptions::default().check().is_ok());
    }

    /// [`truth`]'s loop around the corridor driven `laps` times, then the
    /// 12 m past the start.
    fn laps(laps: usize) -> Vec<Pose2> {
        let one = truth();
        // One lap is the corridor's four sides; the tail beyond it is the
        // 12 m past the start.
        let lap = one.len() - 48;
        let mut poses: Vec<Pose2> = (0..laps).flat_map(|_| one[..lap].iter().copied()).collect();
        poses.extend_from_slice(&one[lap..]);
        poses
    }

    #[test]
    fn a_window_bends_only_the_latest_nodes_and_still_closes_the_loops() {
        let truth = laps(3);
        let front = drifting(&truth, 0.0012);
        let before = mean_error(&front.iter().map(|p| (0.0, *p)).collect::<Vec<_>>(), &truth);
        let (whole, whole_report) = run(&truth, &front, &BackendOptions::default());
        let small = BackendOptions { window_nodes: 20, ..BackendOptions::default() };
        let (windowed, report) = run(&truth, &front, &small);
        // Some loops mid-run were optimized over the window only.
        assert!(report.full_optimizations < report.optimizations, "{report:?}");
        assert_eq!(whole_report.full_optimizations, whole_report.optimizations, "{whole_report:?}");
        let (after_whole, after_window) = (mean_error(&whole, &truth), mean_error(&windowed, &truth));
        assert!(after_window < 0.5 * before, "mean error {before} -> {after_window} m ({report:?})");
        assert!(after_window < 1.5 * after_whole + 0.02, "window {after_window} m, whole {after_whole} m");
    }

    #[test]
    fn the_index_finds_every_submap_within_reach() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (per, reach) = (4, 2.0);
        let estimate: Vec<Pose2> = (0..400)
            .map(|_| Pose2::new(rng.random_range(-15.0..15.0), rng.random_range(-15.0..15.0), 0.0))
            .collect();
        let mut index = SubmapIndex::new(reach);
        index.settle(250, per, &estimate);
        assert_eq!(index.settled, 62);
        for _ in 0..200 {
            let at = Pose2::new(rng.random_range(-16.0..16.0), rng.random_range(-16.0..16.0), 0.0);
            let within = |s: &usize| (s * per..(s + 1) * per).any(|m| estimate[m].distance(&at) <= reach);
            let brute: Vec<usize> = (0..100).filter(within).collect();
            let mut found: Vec<usize> = index.near(&at, 100).filter(within).collect();
            found.sort_unstable();
            assert_eq!(found, brute);
        }
    }
}
