//! CGR localization with laser input on the simulated office: tracking
//! from a known start stays on the true trajectory, and K shards give the
//! same result as one.

use std::sync::Arc;

use squall::bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall::bolts::cgr::observation::Observation2d;
use squall::bolts::cgr::scene_grid::SceneGrid;
use squall::bolts::pf::Filter;
use squall::core::geometry::Pose2;
use squall::spouts::sim::office::office;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

/// (mean position error m, max position error m, mean heading error rad).
fn track(shards: usize) -> (f64, f64, f64, Vec<Pose2>) {
    let floor = office(4, 2, 2);
    let map = Arc::new(floor.world.clone());
    let config = SimConfig { seed: 4, duration_secs: 120.0, ..SimConfig::default() };
    let events: Vec<(Observation2d, Pose2)> = Simulation::new(floor, config)
        .unwrap()
        .filter_map(|e| match e {
            SimEvent::Scan(s, truth) => Some((Observation2d::from_laser(&s, 8.0), truth)),
            SimEvent::Odom(_) => None,
        })
        .collect();
    // Tracking: the particles start at the true first pose.
    let options = LocalizeOptions { init: Init::Known(events[0].1), ..LocalizeOptions::default() };
    // Scenes precomputed on a 0.2 m grid, as a run would load them.
    let grid = Arc::new(SceneGrid::build(&map, 0.2, 8.0, 2).unwrap());
    let mut filter = Filter::new(CgrModel::new(map, Some(grid), options).unwrap(), 11, shards).unwrap();
    let (mut sum, mut max, mut heading, mut n) = (0.0, 0.0f64, 0.0, 0.0);
    let mut poses = Vec::new();
    for (obs, truth) in &events {
        filter.process(obs);
        let p = filter.estimate(&obs.odometry).unwrap();
        let e = p.distance(truth);
        sum += e;
        max = max.max(e);
        heading += squall::core::geometry::normalize_angle(p.theta - truth.theta).abs();
        n += 1.0;
        poses.push(p);
    }
    (sum / n, max, heading / n, poses)
}

#[test]
fn tracking_from_a_known_start_stays_on_the_trajectory() {
    let (mean, max, heading, _) = track(1);
    eprintln!("mean {mean:.3} m, max {max:.3} m, heading {:.2}°", heading.to_degrees());
    assert!(mean < 0.05, "mean position error {mean:.3} m");
    assert!(max < 0.3, "diverged: max error {max:.3} m");
    assert!(heading.to_degrees() < 1.0, "mean heading error {:.2}°", heading.to_degrees());
}

#[test]
fn two_shards_track_exactly_as_one() {
    assert!(track(1).3 == track(2).3);
}
