//! Recovery from kidnapping: the robot, tracked well on a building's line
//! map, is carried elsewhere without its odometry noticing; with
//! augmented MCL and a set KLD-sampling sizes (50 to 2000 particles, as
//! `squall localize` runs the laser), the filter must find it again
//! within a bounded time.

use std::sync::Arc;

use squall::bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall::bolts::cgr::observation::Observation2d;
use squall::bolts::cgr::scene_grid::SceneGrid;
use squall::bolts::pf::Filter;
use squall::bolts::pf::model::Injection;
use squall::core::geometry::Pose2;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation, floor_for};

/// Scans per second of the simulated laser.
const SCAN_HZ: f64 = 10.0;

/// The run on line map `world` (in the shared data) with augmented MCL:
/// tracked from the true start, kidnapped at `at` seconds to where the
/// robot is `skip` seconds later (odometry shows no motion over the jump).
/// Returns (kidnap distance m, position error per scan after the
/// kidnapping, the most particles the set held after it).
fn kidnapped(world: &str, at: f64, skip: f64) -> (f64, Vec<f64>, usize) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/linemaps").join(world);
    assert!(path.exists(), "missing {}: this test reads the shared data set", path.display());
    let floor = floor_for(path.to_str().unwrap(), 4).unwrap();
    let map = Arc::new(floor.world.clone());
    let config =
        SimConfig { seed: 4, duration_secs: at + skip + 40.0, scan_hz: SCAN_HZ, ..SimConfig::default() };
    let events: Vec<(Observation2d, Pose2)> = Simulation::new(floor, config)
        .unwrap()
        .filter_map(|e| match e {
            SimEvent::Scan(s, truth) => Some((Observation2d::from_laser(&s, 8.0), truth)),
            SimEvent::Odom(_) => None,
        })
        .collect();
    let (k, j) = ((at * SCAN_HZ) as usize, ((at + skip) * SCAN_HZ) as usize);
    // After the jump, odometry continues from where it was at the kidnapping.
    let (before, after) = (events[k].0.odometry, events[j].0.odometry);
    let carried: Vec<(Observation2d, Pose2)> = events[..k]
        .iter()
        .cloned()
        .chain(events[j..].iter().map(|(obs, truth)| {
            let odometry = before.compose(&obs.odometry.relative_to(&after));
            (Observation2d { odometry, ..obs.clone() }, *truth)
        }))
        .collect();
    let options = LocalizeOptions {
        particles: 2000,
        min_particles: 50,
        init: Init::Known(events[0].1),
        injection: Some(Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1, lost_share: 0.5 }),
        ..LocalizeOptions::default()
    };
    let grid = Arc::new(SceneGrid::build(&map, 0.2, 8.0, 2).unwrap());
    let mut filter = Filter::new(CgrModel::new(map, Some(grid), options).unwrap(), 11, 1).unwrap();
    let (mut errors, mut most) = (Vec::new(), 0);
    for (i, (obs, truth)) in carried.iter().enumerate() {
        filter.process(obs);
        if i >= k {
            most = most.max(filter.population().map_or(0, |p| p.len()));
            errors.push(filter.estimate(&obs.odometry).unwrap().distance(truth));
        }
    }
    (events[k].1.distance(&events[j].1), errors, most)
}

#[test]
fn a_kidnapped_robot_is_found_again() {
    // CVAP7 with the simulated laser: tracked for 20 s, then carried to
    // where the robot is 15 s later, 40 s more.
    let (distance, errors, most) = kidnapped("CVAP7_vector.txt", 20.0, 15.0);
    let line: Vec<String> = errors.iter().step_by(10).map(|e| format!("{e:.2}")).collect();
    eprintln!("carried {distance:.1} m; error each second after: {}", line.join(" "));
    assert!(distance > 5.0, "the kidnapping moves the robot ({distance:.1} m)");
    assert!(errors[0] > 5.0, "the filter is lost at first ({:.2} m)", errors[0]);
    assert!(most >= 1000, "a lost robot searches with at least half the most particles ({most})");
    let found = errors.iter().position(|&e| e < 0.2).map(|i| i as f64 / SCAN_HZ).expect("found again");
    assert!(found < 5.0, "found after {found} s");
    // Kept from then on: a look-alike place may win for a moment when the
    // scan fits badly even at the truth, but not for long.
    let after = &errors[(found * SCAN_HZ) as usize..];
    let kept = after.iter().filter(|&&e| e < 0.2).count() as f64 / after.len() as f64;
    assert!(kept > 0.9, "within 0.2 m for {:.0}% of the time after", 100.0 * kept);
    let last = &errors[errors.len() - 30..];
    assert!(last.iter().all(|&e| e < 0.2), "lost at the end: {last:?}");
}
