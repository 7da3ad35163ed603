//! The serial RBPF on a simulated run: its trajectory must be closer to the
//! ground truth than the raw odometry it started from.

use squall::bolts::eval::{ground_truth, trajectory::Trajectory};
use squall::bolts::slam::{filter::Rbpf, options::SlamOptions};
use squall::spouts::sim::office::office;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

#[test]
fn slam_beats_odometry_on_a_simulated_office() {
    let config = SimConfig { seed: 3, duration_secs: 180.0, ..SimConfig::default() };
    let sim = Simulation::new(office(3, 3, 2), config);
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
