//! Diagnostic: is a failed kidnap a lack of samples or a lack of
//! information? Runs the serial filter as `squall localize --input depth
//! --kidnap-at` does (50 particles at the true start, growing to 2000
//! when lost; no clutter) and prints, per frame: the wall points the
//! camera gave, the nearest wall within its 55° view by the map, the
//! particles near the robot (0.5 m, 10°) and their weight, the injected
//! count and the heaviest particle's distance. Then, WINDOW seconds after
//! the carry, it takes the rigid offset D that carries the truth onto the
//! heaviest particle and scores, frame by frame over the window, the
//! true path and the "ghost" path D ∘ truth with the filter's own
//! correction: a ghost that scores as well as the truth is a place no
//! filter could tell from the robot's within the window; one far worse
//! is a truth the filter did not sample or did not keep. "blind" counts
//! the window's frames with fewer than 50 points.
//!
//! `cargo run --release --example ghost -- MAP SEED [KIDNAP_AT [WINDOW [NOISE_PER_Z2]]]`
//!
//! NOISE_PER_Z2 (default 0, the defaults' fixed ε) is the camera's noise
//! law for FSPF's `noise_per_z2` and CGR's `noise_per_r2` both: 0.0015,
//! the simulated D435's, keeps walls beyond 3.5 m.
//!
//! See docs/decisions/0025.

use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_bolts::cgr::measurement::CgrOptions;
use squall_bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall_bolts::cgr::observation::Observation2d;
use squall_bolts::cgr::scene_grid::SceneGrid;
use squall_bolts::pf::Filter;
use squall_bolts::pf::model::{Injection, ParticleModel};
use squall_core::depth_render::{DepthCamera, Props};
use squall_core::geometry::{Pose2, normalize_angle};
use squall_spouts::sim::{Kidnap, SimConfig, SimEvent, Simulation, Start, floor_for};

/// A particle this near the truth has found the robot (metres, radians).
const NEAR: (f64, f64) = (0.5, 0.1745);

/// Fewer points than this and a frame shows the filter next to nothing.
const BLIND: usize = 50;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (map, seed) = (&a[0], a[1].parse::<u64>().unwrap());
    let kidnap_at: f64 = a.get(2).map_or(8.0, |s| s.parse().unwrap());
    let window: f64 = a.get(3).map_or(5.0, |s| s.parse().unwrap());
    let noise: f64 = a.get(4).map_or(FspfOptions::default().noise_per_z2, |s| s.parse().unwrap());
    let floor = floor_for(map, seed).unwrap();
    let world = Arc::new(floor.world.clone());
    let camera = DepthCamera::d435_on_robot();
    let cgr = CgrOptions {
        occlusion_fits: true,
        leave_out_corners: true,
        newton_step: true,
        noise_per_r2: noise,
        ..CgrOptions::default()
    };
    let grid = Arc::new(SceneGrid::build(&world, 0.2, cgr.range, 2).unwrap());
    let options = LocalizeOptions {
        particles: 2000,
        min_particles: 50,
        cgr,
        init: Init::Global,
        injection: Some(Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1, lost_share: 0.5 }),
        ..LocalizeOptions::default()
    };
    let config = SimConfig {
        seed,
        duration_secs: kidnap_at + window + 0.5,
        scan_hz: 10.0,
        range_max: 8.0,
        beams: 2,
        start: Start::Drawn,
        kidnap: Some(Kidnap { at_secs: kidnap_at, min_m: 5.0, max_m: 20.0 }),
        ..SimConfig::default()
    };
    let sim = Simulation::new(floor, config).unwrap();
    let fspf = FspfOptions { noise_per_z2: noise, ..FspfOptions::default() };
    let mut planes_filter = PlaneFilter::new(fspf, camera.intrinsics);
    let (mut rng, mut noise_rng) = (ChaCha8Rng::seed_from_u64(seed), ChaCha8Rng::seed_from_u64(seed ^ 1));
    let mut planes = PlaneFiltered::default();
    let mut filter: Option<Filter<CgrModel>> = None;
    // Each frame: the reading, the truth, the heaviest particle.
    let mut frames: Vec<(Observation2d, Pose2, Pose2)> = Vec::new();
    let near = |p: &Pose2, truth: &Pose2| {
        p.distance(truth) <= NEAR.0 && normalize_angle(p.theta - truth.theta).abs() <= NEAR.1
    };
    println!("    t points wall_m  near  near_w injected best_m");
    for event in sim {
        let SimEvent::Scan(scan, truth) = event else { continue };
        let image = camera.render(&world, Props { boxes: &[], people: &[] }, &truth, &mut noise_rng);
        planes_filter.filter(&image, &mut rng, &mut planes);
        let obs = Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, scan.stamp, scan.odometry);
        let filter = filter.get_or_insert_with(|| {
            let options = LocalizeOptions { init: Init::Known(truth), ..options.clone() };
            let model = CgrModel::new(world.clone(), Some(grid.clone()), options).unwrap();
            Filter::new(model, seed, 1).unwrap()
        });
        let Some(report) = filter.process(&obs) else { continue };
        let Some(&(best, _)) = report.weighed.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else { continue };
        let near_n = report.weighed.iter().filter(|(p, _)| near(p, &truth)).count();
        let near_w: f64 = report.weighed.iter().filter(|(p, _)| near(p, &truth)).map(|(_, w)| w).sum();
        let wall = (-27..=27)
            .filter_map(|b| world.cast((truth.x, truth.y), truth.theta + f64::from(b).to_radians(), 100.0))
            .fold(f64::INFINITY, f64::min);
        println!(
            "{:5.1} {:6} {:6.2} {:5} {:7.4} {:8} {:6.2}",
            obs.stamp,
            obs.points.len(),
            wall,
            near_n,
            near_w,
            report.injected,
            best.distance(&truth)
        );
        frames.push((obs, truth, best));
    }
    let start = frames.iter().position(|f| f.0.stamp >= kidnap_at).expect("frames after the carry");
    let end = frames.iter().position(|f| f.0.stamp >= kidnap_at + window).unwrap_or(frames.len() - 1);
    let window_frames = &frames[start..=end];
    let (truth_end, best_end) = (frames[end].1, frames[end].2);
    let blind = window_frames.iter().filter(|f| f.0.points.len() < BLIND).count();
    let ghost = best_end.compose(&truth_end.inverse());
    let model = CgrModel::new(world.clone(), Some(grid.clone()), options).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut truth_ll, mut ghost_ll) = (0.0, 0.0);
    for (obs, truth, _) in window_frames {
        let (mut t, mut g) = (*truth, ghost.compose(truth));
        truth_ll += model.correct(&mut t, obs, &mut (), &mut rng).log_likelihood;
        ghost_ll += model.correct(&mut g, obs, &mut (), &mut rng).log_likelihood;
    }
    println!(
        "summary map={map} seed={seed} heaviest_m={:.2} blind={blind}/{} truth_ll={truth_ll:.1} ghost_ll={ghost_ll:.1}",
        best_end.distance(&truth_end),
        window_frames.len()
    );
}
