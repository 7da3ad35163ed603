//! The whole depth pipeline per frame on one core: FSPF on a rendered
//! 640 × 480 frame, projection to the robot frame, and the CGR filter
//! update with 50 particles and precomputed scenes (the 30
//! frames/s goal), with the measurement settings `squall localize
//! --input depth` sets (the corners left out, refinement ending with a
//! Newton step; decision 0023). Frames are rendered beforehand along a
//! CVAP7 route and not timed.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall::bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall::bolts::cgr::measurement::CgrOptions;
use squall::bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall::bolts::cgr::observation::Observation2d;
use squall::bolts::cgr::scene_grid::SceneGrid;
use squall::bolts::pf::Filter;
use squall::core::depth_render::{DepthCamera, Props};
use squall::spouts::sim::{SimConfig, SimEvent, Simulation, floor_for};

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/linemaps/CVAP7_vector.txt");
    assert!(path.exists(), "missing {}: this bench reads the shared data set", path.display());
    let floor = floor_for(&path.to_string_lossy(), 42).expect("CVAP7 has a roadmap");
    let map = Arc::new(floor.world.clone());
    let config =
        SimConfig { seed: 42, duration_secs: 10.0, beams: 2, range_max: 8.0, ..SimConfig::default() };
    let camera = DepthCamera::d435_on_robot();
    let mut render_rng = ChaCha8Rng::seed_from_u64(1);
    let frames: Vec<_> = Simulation::new(floor, config)
        .expect("a valid simulation")
        .filter_map(|e| match e {
            SimEvent::Scan(scan, truth) => Some((scan.stamp, scan.odometry, truth)),
            SimEvent::Odom(_) => None,
        })
        .map(|(stamp, odometry, truth)| {
            (stamp, odometry, truth, camera.render(&map, Props::default(), &truth, &mut render_rng))
        })
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cache = std::env::temp_dir().join("squall-scenes");
    let (grid, _) = SceneGrid::load_or_build(&map, 0.2, 8.0, threads, &cache).expect("scene cache");
    let cgr = CgrOptions { leave_out_corners: true, newton_step: true, ..CgrOptions::default() };
    let options =
        LocalizeOptions { particles: 50, init: Init::Known(frames[0].2), cgr, ..LocalizeOptions::default() };
    let mut filter =
        Filter::new(CgrModel::new(map.clone(), Some(Arc::new(grid)), options).expect("valid"), 1, 1)
            .expect("one task");
    let mut fspf = PlaneFilter::new(FspfOptions::default(), camera.intrinsics);
    let (mut planes, mut rng) = (PlaneFiltered::default(), ChaCha8Rng::seed_from_u64(2));
    let (mut total, mut fspf_ms, mut points) = (Vec::new(), Vec::new(), Vec::new());
    for (stamp, odometry, _, image) in &frames {
        let started = Instant::now();
        fspf.filter(image, &mut rng, &mut planes);
        let filtered = started.elapsed();
        let obs = Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, *stamp, *odometry);
        filter.process(&obs);
        total.push(started.elapsed().as_secs_f64() * 1e3);
        fspf_ms.push(filtered.as_secs_f64() * 1e3);
        points.push(obs.points.len() as f64);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let whole = median(&mut total);
    let p90 = total[total.len() * 9 / 10];
    println!(
        "depth pipeline, CVAP7, 50 particles, {} frames: median {:.2} ms per frame ({:.0} frames/s), p90 {:.2} ms, FSPF {:.2} ms, {:.0} wall points",
        frames.len(),
        whole,
        1e3 / whole,
        p90,
        median(&mut fspf_ms),
        median(&mut points)
    );
}
