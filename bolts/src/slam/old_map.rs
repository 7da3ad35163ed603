//! Matching against a particle's own older map, for re-entering an area
//! mapped long ago (squall's addition; GMapping has nothing like it).
//!
//! After a long loop a particle comes back to a mapped area a few tenths
//! of a metre off. Its climb then aligns the scan with what it mapped on
//! the way back, the latest walls, which sit that far from the old ones;
//! the old walls match poorly and the map doubles. Searching the current
//! map more widely does not help, since the latest walls keep winning
//! near the predicted pose. The map as it was some readings ago holds the
//! old walls alone: each particle keeps such a snapshot (tiles shared with
//! its map, so a snapshot costs only the tiles written since), and when a
//! climb matches only part of the view where that snapshot covers it, a
//! wide search against the snapshot looks for the old walls. A pose that
//! matches them much better, and scores about as well on the whole map
//! after a climb there, replaces the climb's.

use serde::{Deserialize, Serialize};

use crate::slam::grid::TiledGrid;
use crate::slam::matcher::{Matched, Matcher, PreparedScan, covered_beams};
use crate::slam::options::{Cutoff, SlamOptions};
use squall_core::geometry::Real;

/// Snapshots of a particle's map: `recent` taken at the last multiple of
/// the age, `old` at the one before (shared tiles, see the module docs).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MapHistory {
    /// Updates of the map so far.
    pub updates: u64,
    /// The map at the latest snapshot.
    pub recent: Option<TiledGrid>,
    /// The map at the snapshot before: the one searched.
    pub old: Option<TiledGrid>,
}

impl MapHistory {
    /// Counts an update of `map`; every `age`-th (none for 0) moves the
    /// recent snapshot to old and takes a new one.
    pub fn record(&mut self, map: &TiledGrid, age: usize) {
        self.updates += 1;
        if age > 0 && self.updates.is_multiple_of(age as u64) {
            self.old = self.recent.take();
            self.recent = Some(map.clone());
        }
    }

    /// The snapshots held.
    pub fn grids(&self) -> impl Iterator<Item = &TiledGrid> {
        self.recent.iter().chain(self.old.iter())
    }
}

/// Grid steps a side of the old-map search (13 × 13 × 13 poses): at the
/// default reach, 0.1 m apart, two cells, so that every pose within the
/// reach lies within a cell of one the search scores.
const OLD_MAP_STEPS: i32 = 6;

/// A climb matching fewer than this fraction of the beams is lost rather
/// than re-entering (odometry far off, as in the Intel log): the wide
/// search's business, and there the old map offers too many wrong
/// matches.
const LOST: Real = 0.5;

/// The old map must cover at least this fraction of the view for the
/// search to run: elsewhere the robot explores, and a poor match there says
/// nothing about an old area.
const COVERED: Real = 0.5;

/// The search's pose must match at least this fraction of the beams on the
/// old map...
const MATCHED: Real = 0.5;

/// ...score this many times what the climb's pose scores on the old map...
const MARGIN: Real = 1.3;

/// ...and, after a climb from it on the whole map, at least this fraction
/// of the climb's own score there.
const KEEP: Real = 0.9;

/// The old-map search for one particle whose climb on `map` gave
/// `climbed`: the better match it finds, or `climbed` if the search was
/// not needed, could not run or found nothing better; either way with the
/// search's evaluations added.
pub(crate) fn search_old_map(
    matcher: &mut Matcher,
    map: &TiledGrid,
    history: &MapHistory,
    climbed: Matched,
    scan: &PreparedScan,
    o: &SlamOptions,
) -> Matched {
    let beams = scan.len() as Real;
    let matched = climbed.matched_beams as Real;
    let weak = (LOST * beams..o.old_map_below * beams).contains(&matched);
    let Some(old) = history.old.as_ref().filter(|_| weak && o.cutoff == Cutoff::Unbounded) else {
        return climbed;
    };
    if (covered_beams(old, &climbed.pose, scan) as Real) < COVERED * beams {
        return climbed;
    }
    let (here, _, _) = matcher.likelihood(old, &climbed.pose, scan, o);
    let found =
        matcher.wide_search(old, &climbed.pose, scan, o, o.old_map_reach, o.old_map_turn, OLD_MAP_STEPS);
    let evaluations = climbed.evaluations + found.evaluations;
    if found.score <= MARGIN * here || (found.matched_beams as Real) < MATCHED * beams {
        return Matched { evaluations, ..climbed };
    }
    let refined = matcher.optimize(map, &found.pose, scan, o);
    let evaluations = evaluations + refined.evaluations;
    if refined.score >= KEEP * climbed.score {
        Matched { evaluations, ..refined }
    } else {
        Matched { evaluations, ..climbed }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::integrate::integrate_scan;
    use crate::slam::scenes::{mapped, room, scan_of};
    use squall_core::geometry::Pose2;

    #[test]
    fn snapshots_are_taken_every_age_updates_and_share_tiles() {
        let mut map = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
        let mut history = MapHistory::default();
        let hit = |map: &mut TiledGrid, i: i64| map.update((i, 0), |c| c.add_hit(i as f32 * 0.05, 0.0));
        for i in 1..=7 {
            hit(&mut map, i);
            history.record(&map, 3);
        }
        let hits = |g: &TiledGrid| (1..=7).filter(|&i| g.get((i, 0)).hits > 0).count();
        assert_eq!(history.updates, 7);
        assert_eq!(history.recent.as_ref().map(hits), Some(6), "the map at update 6");
        assert_eq!(history.old.as_ref().map(hits), Some(3), "the map at update 3");
        // Far from the cells written since, a snapshot shares the map's tiles.
        hit(&mut map, 1000);
        let (distinct, _) = TiledGrid::distinct_tiles(std::iter::once(&map).chain(history.grids()));
        assert_eq!(distinct, 4, "a tile for each of the three versions of row 0, one for cell 1000");
        let mut never = MapHistory::default();
        (0..10).for_each(|_| never.record(&map, 0));
        assert!(never.grids().next().is_none(), "age 0 takes no snapshot");
    }

    /// The room mapped long ago (`old`), and the map now: the old one plus
    /// half-scans the particle placed `drift` off on its way back, so that
    /// a climb from its drifted belief aligns the scan with those and
    /// leaves the rest of the view unmatched. Returns (old, now, truth,
    /// scan, the climb from the belief).
    fn reentry(drift: (f64, f64, f64)) -> (TiledGrid, TiledGrid, Pose2, PreparedScan, Matched) {
        let world = room();
        let truth = Pose2::new(3.3, 1.7, 0.4);
        let old = mapped(&world, &[truth, Pose2::new(1.0, 4.0, -1.0), Pose2::new(6.5, 1.5, 2.0)]);
        let off = |p: &Pose2| Pose2::new(p.x + drift.0, p.y + drift.1, p.theta + drift.2);
        let mut now = old.clone();
        for p in [Pose2::new(2.8, 1.6, 0.4), Pose2::new(3.1, 1.7, 0.4)] {
            let mut half = scan_of(&world, &p);
            half.ranges[180..].fill(half.range_max as f32);
            integrate_scan(&mut now, &off(&p), &half, 20.0);
        }
        let scan = PreparedScan::new(&scan_of(&world, &truth), &SlamOptions::default());
        let climbed = Matcher::default().refine(&now, &off(&truth), &scan, &SlamOptions::default());
        (old, now, truth, scan, climbed)
    }

    #[test]
    fn the_old_map_brings_a_drifted_particle_back() {
        let o = SlamOptions::default();
        let (old, now, truth, scan, climbed) = reentry((0.4, 0.3, 0.03));
        assert!(climbed.pose.distance(&truth) > 0.2, "the climb keeps the drift: {:?}", climbed.pose);
        assert!((climbed.matched_beams as Real) < o.old_map_below * scan.len() as Real, "a weak match");
        let history = MapHistory { updates: 100, recent: None, old: Some(old) };
        let found = search_old_map(&mut Matcher::default(), &now, &history, climbed, &scan, &o);
        assert!(found.pose.distance(&truth) < 0.03, "{:?} vs {truth:?}", found.pose);
        assert!((found.pose.theta - truth.theta).abs() < 0.01, "{:?}", found.pose);
        assert!(found.evaluations > climbed.evaluations + 13 * 13 * 13, "the search is counted");
        assert!(found.score > climbed.score);
    }

    #[test]
    fn the_search_runs_only_where_it_is_meant_to() {
        let o = SlamOptions::default();
        let (old, now, _, scan, climbed) = reentry((0.4, 0.3, 0.03));
        let mut matcher = Matcher::default();
        let with_old = |old: Option<TiledGrid>| MapHistory { updates: 100, recent: None, old };
        let search =
            |m: &mut Matcher, h: &MapHistory, o: &SlamOptions| search_old_map(m, &now, h, climbed, &scan, o);
        // No snapshot yet; an old map that does not cover the view (the
        // robot explores); a cutoff; the search turned off.
        assert_eq!(search(&mut matcher, &with_old(None), &o), climbed);
        let elsewhere = mapped(&room(), &[Pose2::new(30.0, 30.0, 0.0)]);
        assert_eq!(search(&mut matcher, &with_old(Some(elsewhere)), &o), climbed);
        let history = with_old(Some(old));
        let bounded = SlamOptions { cutoff: Cutoff::Evaluations(140), ..o.clone() };
        assert_eq!(search(&mut matcher, &history, &bounded), climbed);
        let off = SlamOptions { old_map_below: 0.0, ..o.clone() };
        assert_eq!(search(&mut matcher, &history, &off), climbed);
        // A particle that never drifted matches well: nothing to search.
        let (old, now, _, scan, aligned) = reentry((0.0, 0.0, 0.0));
        let history = with_old(Some(old));
        assert_eq!(search_old_map(&mut matcher, &now, &history, aligned, &scan, &o), aligned);
    }
}
