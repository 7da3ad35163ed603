//! The serial RBPF on a simulated run: its trajectory must be closer to the
//! ground truth than the raw odometry it started from.

use squall::bolts::slam::{filter::Rbpf, options::SlamOptions};
use squall::core::eval::ground_truth;
use squall::core::trajectory::Trajectory;
use squall::spouts::sim::office::office;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

#[test]
fn slam_beats_odometry_on_a_simulated_office() {
    let config = SimConfig { seed: 3, duration_secs: 180.0, ..SimConfig::default() };
    let sim = Simulation::new(office(3, 3, 2), config).unwrap();
    let options = SlamOptions { particles: 10, max_urange: 30.0, ..SlamOptions::default() };
    let mut filter = Rbpf::new(options, 7).unwrap();
    let (mut truth, mut odometry, mut slam) =
        (Trajectory::default(), Trajectory::default(), Trajectory::default());
    let mut processed = 0;
    for event in sim {
        if let SimEvent::Scan(scan, true_pose) = event {
            processed += usize::from(filter.process(&scan).is_some());
            truth.push(scan.stamp, true_pose);
            odometry.push(scan.stamp, scan.odometry);
            slam.push(scan.stamp, filter.estimate(&scan.odometry).unwrap());
        }
    }
    let raw = ground_truth::score(&odometry, &truth);
    let est = ground_truth::score(&slam, &truth);
    eprintln!("{processed} processed; ATE: SLAM {:.3} m, odometry {:.3} m", est.ate_rmse, raw.ate_rmse);
    assert!(processed > 50, "{processed} processed readings");
    assert!(
        est.ate_rmse < 0.5 * raw.ate_rmse && est.ate_rmse < 0.3,
        "SLAM ATE {:.3} m vs odometry {:.3} m",
        est.ate_rmse,
        raw.ate_rmse
    );
}

/// A run that comes back to where it has been: the relations between the
/// first and the later visit (the loop relations) must hold in the final
/// best trajectory, which they cannot if the loop was not closed.
#[test]
fn a_simulated_run_closes_its_loops() {
    use squall::core::eval::relations::{parse_relations, score};
    use squall::spouts::sim::output::relations;

    let config = SimConfig { seed: 5, duration_secs: 300.0, ..SimConfig::default() };
    let sim = Simulation::new(office(3, 3, 2), config).unwrap();
    let options = SlamOptions { particles: 15, max_urange: 30.0, ..SlamOptions::default() };
    let mut filter = Rbpf::new(options, 11).unwrap();
    let (mut truth, mut odometry, mut scans) = (Trajectory::default(), Trajectory::default(), Vec::new());
    for event in sim {
        if let SimEvent::Scan(scan, true_pose) = event {
            filter.process(&scan);
            truth.push(scan.stamp, true_pose);
            odometry.push(scan.stamp, scan.odometry);
            scans.push((scan.stamp, scan.odometry));
        }
    }
    let mut slam = Trajectory::default();
    for (stamp, pose) in filter.lineage_poses(scans) {
        slam.push(stamp, pose);
    }
    let (text, local, loops) = relations(&truth);
    let loop_lines: String = text.lines().skip(local).map(|l| format!("{l}\n")).collect();
    let loop_relations = parse_relations("loops", &loop_lines).unwrap();
    assert_eq!(loop_relations.len(), loops);
    assert!(loops >= 5, "the route revisits places: {loops} loop relations");
    let (est, raw) = (score(&slam, &loop_relations), score(&odometry, &loop_relations));
    eprintln!("{loops} loop relations: SLAM {:.3} m, odometry {:.3} m", est.trans_mean, raw.trans_mean);
    assert_eq!(est.matched, loops);
    assert!(
        est.trans_mean < 0.1 && est.trans_mean < 0.25 * raw.trans_mean,
        "loop error: SLAM {:.3} m vs odometry {:.3} m",
        est.trans_mean,
        raw.trans_mean
    );
}
