//! CGR filter update time against the particle count (thesis Fig. 6.4):
//! observable scenes ray cast on demand vs precomputed on a 0.2 m grid, on
//! the whole GHC7 map and on a 30 m × 30 m cut of it. Each cell is the
//! median of 20 updates (predict, refine, weigh, resample) with a
//! simulated 180-beam laser scan of a corridor position.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use squall::bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall::bolts::cgr::observation::Observation2d;
use squall::bolts::cgr::scene_grid::SceneGrid;
use squall::bolts::pf::Filter;
use squall::core::geometry::{Pose2, Real};
use squall::core::linemap::LineMap;
use squall::core::sensor::LaserReading;

/// A perfect 180-beam scan from `pose`, odometry `pose`.
fn scan(map: &LineMap, pose: &Pose2, stamp: f64) -> Observation2d {
    let n = 180;
    let angle_min = -std::f64::consts::FRAC_PI_2;
    let angle_increment = std::f64::consts::PI / (n - 1) as Real;
    let ranges = (0..n)
        .map(|i| {
            map.cast((pose.x, pose.y), pose.theta + angle_min + i as Real * angle_increment, 8.0)
                .unwrap_or(8.0) as f32
        })
        .collect();
    let reading = LaserReading {
        stamp,
        ranges,
        angle_min,
        angle_increment,
        range_min: 0.0,
        range_max: 8.0,
        odometry: *pose,
        laser_offset: Pose2::IDENTITY,
    };
    Observation2d::from_laser(&reading, 8.0)
}

/// Median ms per filter update.
fn run(map: &Arc<LineMap>, grid: Option<Arc<SceneGrid>>, start: Pose2, particles: usize) -> f64 {
    let options = LocalizeOptions {
        particles,
        min_particles: particles,
        init: Init::Known(start),
        ..LocalizeOptions::default()
    };
    let mut filter =
        Filter::new(CgrModel::new(map.clone(), grid, options).expect("valid"), 1, 1).expect("one task");
    filter.process(&scan(map, &start, 0.0));
    let mut times = Vec::new();
    for k in 1..=20 {
        // Creep forward 2 cm per update along the heading.
        let pose = start.compose(&Pose2::new(0.02 * k as Real, 0.0, 0.0));
        let obs = scan(map, &pose, k as f64 * 0.1);
        let started = Instant::now();
        filter.process(&obs);
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/linemaps/GHC7_vector.txt");
    assert!(path.exists(), "missing {}: this bench reads the shared data set", path.display());
    let world = path.to_string_lossy().to_string();
    let floor = squall::spouts::sim::floor_for(&world, 1).expect("GHC7 has a roadmap");
    let full = Arc::new(floor.world.clone());
    let node = floor.nodes[floor.nodes.len() / 2];
    let start = Pose2::new(node.0, node.1, 0.0);
    let inside = |p: (Real, Real)| (p.0 - node.0).abs() <= 15.0 && (p.1 - node.1).abs() <= 15.0;
    let cut = Arc::new(LineMap {
        walls: full.walls.iter().copied().filter(|w| inside(w.a) && inside(w.b)).collect(),
    });
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cache = std::env::temp_dir().join("squall-scenes");
    println!(
        "CGR update, median ms (20 updates per cell), start at corridor node ({:.1}, {:.1})",
        node.0, node.1
    );
    println!(
        "{:>22} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "map / scenes", "20", "50", "100", "200", "500", "1000"
    );
    for (name, map) in [("GHC7", &full), ("GHC7 cut 30 m", &cut)] {
        let started = Instant::now();
        let (grid, built) = SceneGrid::load_or_build(map, 0.2, 8.0, threads, &cache).expect("scene cache");
        let how = if built { "built" } else { "loaded" };
        println!(
            "{name}: {} walls, scene grid {how} in {:.1} s",
            map.walls.len(),
            started.elapsed().as_secs_f64()
        );
        let grid = Arc::new(grid);
        for (label, g) in [("on demand", None), ("precomputed", Some(grid.clone()))] {
            let cells: Vec<String> = [20, 50, 100, 200, 500, 1000]
                .iter()
                .map(|&n| format!("{:>9.2}", run(map, g.clone(), start, n)))
                .collect();
            println!("{:>22} {}", format!("{name}, {label}"), cells.join(" "));
        }
    }
}
