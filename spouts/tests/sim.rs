//! The simulator: determinism, its log readable as a real one, ground truth
//! consistent with its relations, a laser consistent with the world, and
//! odometry that drifts.

use squall_core::eval::relations::{self, read_relations};
use squall_core::trajectory::Trajectory;
use squall_spouts::carmen::{Laser, ReadOptions, Record, read_log};
use squall_spouts::sim::office::office;
use squall_spouts::sim::output::write_run;
use squall_spouts::sim::{SimConfig, SimEvent, Simulation};

fn run(seed: u64, secs: f64) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let config = SimConfig { seed, duration_secs: secs, ..SimConfig::default() };
    write_run(Simulation::new(office(seed, 3, 2), config).unwrap(), dir.path()).unwrap();
    dir
}

#[test]
fn same_seed_same_run() {
    let (a, b, c) = (run(5, 60.0), run(5, 60.0), run(6, 60.0));
    let read = |d: &tempfile::TempDir| std::fs::read(d.path().join("sim.clf")).unwrap();
    assert_eq!(read(&a), read(&b));
    assert_ne!(read(&a), read(&c));
}

#[test]
fn the_log_reads_like_a_real_one_and_the_truth_scores_zero() {
    let dir = run(1, 300.0);
    let records = read_log(&dir.path().join("sim.clf"), ReadOptions::default()).unwrap();
    let scans: Vec<_> = records
        .iter()
        .filter_map(|r| match r {
            Record::Scan(Laser::Front, s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(scans.len(), 3000);
    assert_eq!(scans[0].range_max, 30.0, "the PARAM lines carry the laser's range");
    let truth = Trajectory::read_tum(&dir.path().join("ground_truth.tum")).unwrap();
    assert_eq!(truth.len(), 3000);
    let rel = read_relations(&dir.path().join("sim.relations")).unwrap();
    let score = relations::score(&truth, &rel);
    assert_eq!(score.matched, rel.len());
    assert!(score.trans_mean < 1e-5 && score.rot_mean_deg < 1e-3, "{score:?}");
    let mut odometry = Trajectory::default();
    for s in &scans {
        odometry.push(s.stamp, s.odometry);
    }
    let drift = relations::score(&odometry, &rel);
    assert!(drift.trans_mean > 0.05, "odometry should drift: {drift:?}");
}

#[test]
fn routes_close_loops() {
    let dir = run(2, 300.0);
    let text = std::fs::read_to_string(dir.path().join("sim.relations")).unwrap();
    let long_gaps = text
        .lines()
        .filter(|l| {
            let v: Vec<f64> = l.split(' ').take(2).map(|f| f.parse().unwrap()).collect();
            v[1] - v[0] >= 30.0
        })
        .count();
    assert!(long_gaps >= 10, "only {long_gaps} loop relations in 5 minutes");
}

#[test]
fn the_laser_sees_the_walls_from_the_true_pose() {
    let floor = office(3, 3, 2);
    let world = floor.world.clone();
    let sim =
        Simulation::new(floor, SimConfig { seed: 3, duration_secs: 20.0, ..SimConfig::default() }).unwrap();
    let mut checked = 0;
    for event in sim {
        if let SimEvent::Scan(scan, truth) = event {
            for i in (0..scan.ranges.len()).step_by(17) {
                let angle = truth.theta + scan.beam_angle(i);
                let expected = world.cast((truth.x, truth.y), angle, scan.range_max);
                let r = f64::from(scan.ranges[i]);
                match expected {
                    Some(e) if scan.is_valid(i) => assert!((r - e).abs() < 0.06, "beam {i}: {r} vs {e}"),
                    Some(_) => {} // a dropout
                    None => assert!(!scan.is_valid(i), "beam {i} returned {r} with no wall in range"),
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 1000);
}
