//! The serial RBPF on a simulated run: its trajectory must be closer to the
//! ground truth than the raw odometry it started from.

use squall::bolts::slam::{filter::Rbpf, options::SlamOptions};
use squall::core::eval::ground_truth;
use squall::core::eval::relations::{Relation, parse_relations, score};
use squall::core::sensor::LaserReading;
use squall::core::trajectory::Trajectory;
use squall::spouts::sim::office::office;
use squall::spouts::sim::output::relations;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

/// A serial run's trajectories: the truth, the raw odometry and the
/// final best lineage.
struct Run {
    truth: Trajectory,
    odometry: Trajectory,
    slam: Trajectory,
}

/// Runs the serial filter (`options`, seed `seed`) over every scan of
/// `sim`, each scan first passed to `alter` with its event's index.
fn run_lineage(
    sim: Simulation,
    options: SlamOptions,
    seed: u64,
    mut alter: impl FnMut(usize, &mut LaserReading),
) -> Run {
    let mut filter = Rbpf::new(options, seed).unwrap();
    let (mut truth, mut odometry, mut scans) = (Trajectory::default(), Trajectory::default(), Vec::new());
    for (k, event) in sim.enumerate() {
        if let SimEvent::Scan(mut scan, true_pose) = event {
            alter(k, &mut scan);
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
    Run { truth, odometry, slam }
}

/// The simulator's relations of `truth`: (local, loop), each as many as
/// the simulator counted.
fn local_and_loop_relations(truth: &Trajectory) -> (Vec<Relation>, Vec<Relation>) {
    let (text, local, loops) = relations(truth);
    let lines = |skip: usize, take: usize| -> String {
        text.lines().skip(skip).take(take).map(|l| format!("{l}\n")).collect()
    };
    let split = (
        parse_relations("local", &lines(0, local)).unwrap(),
        parse_relations("loops", &lines(local, usize::MAX)).unwrap(),
    );
    assert_eq!((split.0.len(), split.1.len()), (local, loops));
    split
}

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
    let config = SimConfig { seed: 5, duration_secs: 300.0, ..SimConfig::default() };
    let sim = Simulation::new(office(3, 3, 2), config).unwrap();
    let options = SlamOptions { particles: 15, max_urange: 30.0, ..SlamOptions::default() };
    let Run { truth, odometry, slam } = run_lineage(sim, options, 11, |_, _| ());
    let (_, loop_relations) = local_and_loop_relations(&truth);
    let loops = loop_relations.len();
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

/// The error over every relation (local and loop) of two minutes on the
/// campus with good odometry, for SLAM's final lineage with `proposal`
/// and for the raw odometry.
fn campus_error(proposal: squall::bolts::slam::options::Proposal) -> (f64, f64) {
    use squall::spouts::sim::campus::campus;
    use squall::spouts::sim::{OdometryQuality, laser_range_for, top_speed_for};

    let config = SimConfig {
        seed: 1,
        duration_secs: 120.0,
        odometry: OdometryQuality::Good,
        range_max: laser_range_for("campus"),
        max_speed: top_speed_for("campus"),
        ..SimConfig::default()
    };
    let sim = Simulation::new(campus(1).unwrap(), config).unwrap();
    let options = SlamOptions { particles: 10, proposal, ..SlamOptions::default() };
    let Run { truth, odometry, slam } = run_lineage(sim, options, 3, |_, _| ());
    let (mut all, loops) = local_and_loop_relations(&truth);
    all.extend(loops);
    (score(&slam, &all).trans_mean, score(&odometry, &all).trans_mean)
}

/// On the open campus most beams meet nothing. Matched with every other
/// beam, its scans kept few, and both proposals wandered from a good
/// odometry (2 min: the Gaussian 0.050 m, GMapping's 0.106 m). Matched with
/// every returning beam, each counting for its share of the view
/// (`PreparedScan::new`), both keep to about a centimetre (measured 0.0126
/// and 0.0115 m; the odometry 0.0040 m).
#[test]
fn on_the_open_campus_both_proposals_keep_close_to_the_truth() {
    use squall::bolts::slam::options::Proposal;
    let (gaussian, odometry) = campus_error(Proposal::Gaussian);
    let (climb, _) = campus_error(Proposal::Climb);
    eprintln!(
        "campus, 120 s, good odometry: gaussian {gaussian:.4} m, climb {climb:.4} m, odometry {odometry:.4} m"
    );
    assert!(gaussian < 0.02, "gaussian {gaussian:.4} m");
    assert!(climb < 0.02, "climb {climb:.4} m");
}

/// Some lasers report each scan with its own start angle and beam count
/// (held-out logs do). SLAM reads every scan by its own geometry: the
/// same run with scans trimmed differently at both ends keeps its local
/// accuracy. (Whole-run ATE is no measure here: over a short run it
/// swings with whether a loop closed, 0.05–0.56 m for trims that drop a
/// degree or two of the view.)
#[test]
fn scans_whose_start_angle_and_beam_count_vary_are_mapped_as_well() {
    let local_error = |trim: bool| -> f64 {
        let config = SimConfig { seed: 3, duration_secs: 150.0, ..SimConfig::default() };
        let sim = Simulation::new(office(3, 3, 2), config).unwrap();
        let options = SlamOptions { particles: 10, max_urange: 30.0, ..SlamOptions::default() };
        let Run { truth, slam, .. } = run_lineage(sim, options, 7, |k, scan| {
            if trim {
                // 0–6 beams off the start, 0–4 off the end.
                let (start, end) = (k % 7, (k * 3) % 5);
                scan.ranges = scan.ranges[start..scan.ranges.len() - end].to_vec();
                scan.angle_min += start as f64 * scan.angle_increment;
            }
        });
        score(&slam, &local_and_loop_relations(&truth).0).trans_mean
    };
    let (whole, trimmed) = (local_error(false), local_error(true));
    eprintln!("local relation error: fixed scans {whole:.4} m, varying scans {trimmed:.4} m");
    assert!(
        trimmed < 0.05 && trimmed < 1.3 * whole + 0.005,
        "varying {trimmed:.4} m against fixed {whole:.4} m"
    );
}
