//! The filter with its particles split over K shards, exchanging states
//! after every resampling, must give exactly the K = 1 result: the same
//! trajectory, bit for bit, and the same best map. This is what lets the
//! parallel topology promise K-independent output.

use std::path::Path;

use squall::bolts::slam::{filter::Rbpf, options::SlamOptions};
use squall::core::geometry::Pose2;
use squall::core::occupancy::OccupancyGrid;
use squall::core::sensor::LaserReading;
use squall::spouts::carmen::{ReadOptions, read_front_scans};
use squall::spouts::sim::office::office;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

/// The trajectory, the best map, and the particles moved between shards.
fn run(
    scans: &[LaserReading],
    options: &SlamOptions,
    shards: usize,
) -> (Vec<(f64, Pose2)>, OccupancyGrid, usize) {
    let mut filter = Rbpf::sharded(options.clone(), 5, shards).unwrap();
    let mut moved = 0;
    for s in scans {
        if let Some(report) = filter.process(s) {
            moved += report.moved.particles;
        }
    }
    let poses = filter.lineage_poses(scans.iter().map(|s| (s.stamp, s.odometry)));
    (poses, filter.best().unwrap().map.to_occupancy(), moved)
}

fn assert_shards_agree(
    scans: &[LaserReading],
    options: &SlamOptions,
    shards: impl IntoIterator<Item = usize>,
) {
    let (poses, map, moved) = run(scans, options, 1);
    assert_eq!(moved, 0, "one shard moves nothing");
    assert_eq!(poses.len(), scans.len());
    let mut moved_somewhere = false;
    for k in shards {
        let (p, m, moved) = run(scans, options, k);
        assert!(p == poses, "K = {k}: the trajectory differs from K = 1");
        assert!(m == map, "K = {k}: the best map differs from K = 1");
        moved_somewhere |= moved > 0;
    }
    assert!(moved_somewhere, "no run resampled across shards: the exchange went untested");
}

#[test]
fn shards_reproduce_the_serial_filter_on_the_simulator() {
    let config = SimConfig { seed: 2, duration_secs: 90.0, ..SimConfig::default() };
    let scans: Vec<LaserReading> = Simulation::new(office(2, 2, 2), config)
        .unwrap()
        .filter_map(|e| match e {
            SimEvent::Scan(s, _) => Some(s),
            SimEvent::Odom(_) => None,
        })
        .collect();
    let options = SlamOptions { particles: 12, max_urange: 30.0, ..SlamOptions::default() };
    assert_shards_agree(&scans, &options, 2..=8);
}

#[test]
fn shards_reproduce_the_serial_filter_on_aces() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/laser/aces.clf");
    assert!(path.exists(), "missing {}: this test reads the shared data set", path.display());
    let scans: Vec<LaserReading> =
        read_front_scans(&path, ReadOptions::default()).expect("ACES parses").into_iter().take(500).collect();
    assert_shards_agree(&scans, &SlamOptions::default(), [2, 3, 4]);
}
