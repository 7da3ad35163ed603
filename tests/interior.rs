//! The inside of every shared building map, and of the simulated worlds:
//! every pose the simulated robot drives through is inside, and the world
//! beyond the outline is not.

use squall::core::geometry::Pose2;
use squall::core::interior::{DEFAULT_OPENING, Interior};
use squall::spouts::sim::{SimConfig, SimEvent, Simulation, floor_for};

mod common;
use common::shared_data;

/// The true poses of the simulated robot in `world` over `seconds`.
fn driven(world: &str, seed: u64, seconds: f64) -> Vec<Pose2> {
    let floor = floor_for(world, seed).unwrap();
    let config = SimConfig { seed, duration_secs: seconds, range_max: 8.0, ..SimConfig::default() };
    Simulation::new(floor, config)
        .unwrap()
        .filter_map(|e| match e {
            SimEvent::Scan(_, truth) => Some(truth),
            SimEvent::Odom(_) => None,
        })
        .collect()
}

#[test]
fn every_shared_building_holds_the_robots_path_and_excludes_the_world_around_it() {
    for name in ["CVAP6", "CVAP7", "EDSH120", "GHC7"] {
        let path = shared_data(&format!("linemaps/{name}_vector.txt"));
        let map = squall::core::linemap::LineMap::load(std::path::Path::new(&path)).unwrap();
        let inside = Interior::of(&map, DEFAULT_OPENING).unwrap();
        let (x0, y0, x1, y1) = map.bounds();
        let box_area = (x1 - x0) * (y1 - y0);
        eprintln!("{name}: {:.0} m² inside of a {box_area:.0} m² bounding box", inside.area());
        assert!(inside.area() > 0.2 * box_area && inside.area() < box_area, "{name}: {}", inside.area());
        // The robot drives the building's roadmap: every pose it passes is
        // inside, on three seeds (routes differ by seed).
        for seed in 1..=3 {
            let poses = driven(&path, seed, 300.0);
            let out: Vec<&Pose2> = poses.iter().filter(|p| !inside.contains(p.x, p.y)).collect();
            assert!(
                out.is_empty(),
                "{name} seed {seed}: {} of {} poses outside, first {:?}",
                out.len(),
                poses.len(),
                out[0]
            );
        }
        // Beyond the outline, a metre past the bounding box on every side.
        let (mx, my) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        for (x, y) in [(x0 - 1.0, my), (x1 + 1.0, my), (mx, y0 - 1.0), (mx, y1 + 1.0), (x0 - 40.0, y0 - 40.0)]
        {
            assert!(!inside.contains(x, y), "{name}: ({x:.1}, {y:.1}) is outside");
        }
    }
}

#[test]
fn the_simulated_worlds_hold_the_robots_path() {
    for world in ["office", "campus"] {
        let floor = floor_for(world, 1).unwrap();
        let inside = Interior::of(&floor.world, DEFAULT_OPENING).unwrap();
        let (x0, y0, x1, y1) = floor.world.bounds();
        eprintln!(
            "{world}: {:.0} m² inside of a {:.0} m² bounding box",
            inside.area(),
            (x1 - x0) * (y1 - y0)
        );
        assert!(!inside.is_empty(), "{world}");
        for p in driven(world, 1, 300.0) {
            assert!(inside.contains(p.x, p.y), "{world}: {p:?}");
        }
    }
}
