//! Diagnostic: where does a global start lose the robot? Runs the serial
//! filter as `squall localize --init global` runs it (2000 particles down
//! to 50, augmented MCL, the scene grid) on one seed's simulated frames
//! (no clutter, no people) and prints, per frame, against the truth: the
//! particles within 0.5 m and 10° of it after correction and their share
//! of the weight, the heaviest particle's distance, and how many near ones
//! the new set keeps.
//!
//! `cargo run --release --example filter_trace -- MAP SEED depth|laser [SECONDS [CORRELATION [KIDNAP_AT]]]`
//!
//! With KIDNAP_AT the run starts tracked (50 particles at the true
//! start, growing to 2000 when lost) and the robot is carried 5–20 m
//! at that second, as `squall localize --kidnap-at` does.
//!
//! See docs/decisions/0023.

use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_bolts::cgr::measurement::CgrOptions;
use squall_bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall_bolts::cgr::observation::Observation2d;
use squall_bolts::cgr::scene_grid::SceneGrid;
use squall_bolts::pf::Filter;
use squall_bolts::pf::model::Injection;
use squall_core::depth_render::{DepthCamera, Props};
use squall_core::geometry::{Pose2, normalize_angle};
use squall_spouts::sim::{Kidnap, SimConfig, SimEvent, Simulation, Start, floor_for};

/// A particle this near the truth has found the robot (metres, degrees).
const NEAR: (f64, f64) = (0.5, 10.0);

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (map, seed, input) = (&a[0], a[1].parse::<u64>().unwrap(), a[2].as_str());
    let seconds: f64 = a.get(3).map_or(12.0, |s| s.parse().unwrap());
    let depth = input == "depth";
    let floor = floor_for(map, seed).unwrap();
    let world = Arc::new(floor.world.clone());
    let correlation = a.get(4).map_or(CgrOptions::default().correlation, |c| c.parse().unwrap());
    let cgr = CgrOptions {
        occlusion_fits: depth,
        leave_out_corners: depth,
        newton_step: depth,
        correlation,
        ..CgrOptions::default()
    };
    let grid = SceneGrid::build(&world, 0.2, cgr.range, 2).unwrap();
    let options = LocalizeOptions {
        particles: 2000,
        min_particles: 50,
        cgr,
        init: Init::Global,
        injection: Some(Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1, lost_share: 0.5 }),
        ..LocalizeOptions::default()
    };
    let kidnap = a.get(5).map(|k| Kidnap { at_secs: k.parse().unwrap(), min_m: 5.0, max_m: 20.0 });
    let grid = Arc::new(grid);
    let mut filter: Option<Filter<CgrModel>> = None;
    let config = SimConfig {
        seed,
        duration_secs: seconds,
        scan_hz: 10.0,
        range_max: 8.0,
        beams: if depth { 2 } else { SimConfig::default().beams },
        start: Start::Drawn,
        kidnap,
        ..SimConfig::default()
    };
    let sim = Simulation::new(floor, config).unwrap();
    let camera = DepthCamera::d435_on_robot();
    let mut planes_filter = PlaneFilter::new(FspfOptions::default(), camera.intrinsics);
    let (mut rng, mut noise) = (ChaCha8Rng::seed_from_u64(seed), ChaCha8Rng::seed_from_u64(seed ^ 1));
    let mut planes = PlaneFiltered::default();
    let near = |p: &Pose2, truth: &Pose2| {
        p.distance(truth) <= NEAR.0 && normalize_angle(p.theta - truth.theta).abs() <= NEAR.1.to_radians()
    };
    println!("points    t     N  near  near_w    best_w  best_d  kept   next  injected  neff");
    for event in sim {
        let SimEvent::Scan(scan, truth) = event else { continue };
        let obs = if depth {
            let image = camera.render(&world, Props { boxes: &[], people: &[] }, &truth, &mut noise);
            planes_filter.filter(&image, &mut rng, &mut planes);
            Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, scan.stamp, scan.odometry)
        } else {
            Observation2d::from_laser(&scan, 8.0)
        };
        let filter = filter.get_or_insert_with(|| {
            let init = if kidnap.is_some() { Init::Known(truth) } else { Init::Global };
            let options = LocalizeOptions { init, ..options.clone() };
            let model = CgrModel::new(world.clone(), Some(grid.clone()), options).unwrap();
            Filter::new(model, seed, 1).unwrap()
        });
        let Some(report) = filter.process(&obs) else { continue };
        if report.weighed.is_empty() {
            continue;
        }
        let n = report.weighed.len();
        let near_w: f64 = report.weighed.iter().filter(|(p, _)| near(p, &truth)).map(|(_, w)| w).sum();
        let near_n = report.weighed.iter().filter(|(p, _)| near(p, &truth)).count();
        let (best, best_w) = report
            .weighed
            .iter()
            .fold((Pose2::IDENTITY, -1.0), |b, &(p, w)| if w > b.1 { (p, w) } else { b });
        let near_best = report
            .weighed
            .iter()
            .filter(|(p, _)| near(p, &truth))
            .fold((f64::NAN, -1.0), |b, &(p, w)| if w > b.1 { (p.distance(&truth), w) } else { b });
        let kept = filter.states().iter().filter(|p| near(p, &truth)).count();
        println!(
            "{:5} {:5.1} {:5} {:5} {:7.4} {:9.2e} {:7.2} {:5} {:6} {:9} {:5.0}",
            obs.points.len(),
            scan.stamp,
            n,
            near_n,
            near_w,
            best_w,
            best.distance(&truth),
            kept,
            filter.states().len(),
            report.injected,
            report.neff
        );
        if near_n > 0 {
            println!(
                "      near's heaviest: {:.3} m off, weight {:.2e}; heaviest at {:.2} {:.2} {:.3}, truth {:.2} {:.2} {:.3}",
                near_best.0, near_best.1, best.x, best.y, best.theta, truth.x, truth.y, truth.theta
            );
        }
    }
}
