//! Diagnostic: does the likelihood prefer the truth? Tracks one seed's
//! simulated depth frames as `squall localize --input depth` does (50
//! particles at the true start, growing to 2000 when lost, people
//! walking, no boxes) and prints, per frame: the points, the injected
//! count, the heaviest particle's distance and heading error, the
//! log-likelihood refined from the truth and from the heaviest particle,
//! and by the points' distance from the camera (0–2, 2–4, 4–6, 6–8 m):
//! how many there are, how many match a wall at the truth, and their
//! log-likelihood there. A truth that scores below a particle elsewhere is
//! a likelihood that prefers a wrong pose; points the truth cannot match
//! at one distance are what the model gets wrong there.
//!
//! `cargo run --release --example truth_fit -- MAP SEED [SECONDS [NOISE_PER_Z2 [PEOPLE]]]`
//!
//! NOISE_PER_Z2 (default 0.0015, the simulated D435's) is the camera's
//! noise law for FSPF's `noise_per_z2` and CGR's `noise_per_r2` both; 0
//! gives the defaults' fixed ε. PEOPLE defaults to 5, as the simulator's.
//!
//! With `ALL_LINES=1` in the environment, each distance bin also says
//! how many points match with every wall of the map as the scene, and
//! how many with any normal accepted and no outlier cap (are the scene
//! lists or the normals to blame?). With `DUMP_AT=SECONDS`, the frame at
//! that time lists every seventh point beyond 4 m: where it lies at the
//! truth, its normal's direction, and the wall its ray meets.
//!
//! With `KIDNAP_AT=SECONDS` the robot is carried 5–20 m then, as
//! `squall localize --kidnap-at` does; `CORRELATION` sets CGR's (default
//! 20, the depth path's). Each row also says, at the truth and at the
//! heaviest particle, how many points matched (m), how many fell short of
//! the map (s) and the widest run of short points (w, metres).
//!
//! See docs/decisions/0026.

use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_bolts::cgr::measurement::{CgrOptions, evaluate};
use squall_bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall_bolts::cgr::observation::Observation2d;
use squall_bolts::cgr::scene_grid::SceneGrid;
use squall_bolts::pf::Filter;
use squall_bolts::pf::model::{Injection, ParticleModel};
use squall_core::depth_render::{DepthCamera, Props};
use squall_core::geometry::normalize_angle;
use squall_spouts::sim::people::Crowd;
use squall_spouts::sim::{Kidnap, SimConfig, SimEvent, Simulation, Start, floor_for};

/// Bins of the points' distance from the camera, metres.
const BINS: [(f64, f64); 4] = [(0.0, 2.0), (2.0, 4.0), (4.0, 6.0), (6.0, 8.0)];

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (map, seed) = (&a[0], a[1].parse::<u64>().unwrap());
    let seconds: f64 = a.get(2).map_or(20.0, |s| s.parse().unwrap());
    let noise: f64 = a.get(3).map_or(0.0015, |s| s.parse().unwrap());
    let people: usize = a.get(4).map_or(5, |s| s.parse().unwrap());
    let floor = floor_for(map, seed).unwrap();
    let world = Arc::new(floor.world.clone());
    let camera = DepthCamera::d435_on_robot();
    let cgr = CgrOptions {
        occlusion_fits: true,
        leave_out_corners: true,
        newton_step: true,
        noise_per_r2: noise,
        correlation: std::env::var("CORRELATION").map_or(20.0, |c| c.parse().unwrap()),
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
        duration_secs: seconds,
        scan_hz: 10.0,
        range_max: 8.0,
        beams: 2,
        start: Start::Drawn,
        kidnap: std::env::var("KIDNAP_AT").ok().map(|k| Kidnap {
            at_secs: k.parse().unwrap(),
            min_m: 5.0,
            max_m: 20.0,
        }),
        ..SimConfig::default()
    };
    let mut crowd = Crowd::new(&floor, people, seed).unwrap();
    let walked = floor.clone();
    let sim = Simulation::new(floor, config).unwrap();
    let fspf = FspfOptions { noise_per_z2: noise, ..FspfOptions::default() };
    let mut planes_filter = PlaneFilter::new(fspf, camera.intrinsics);
    let (mut rng, mut noise_rng) = (ChaCha8Rng::seed_from_u64(seed), ChaCha8Rng::seed_from_u64(seed ^ 1));
    let mut planes = PlaneFiltered::default();
    let mut filter: Option<Filter<CgrModel>> = None;
    let model = CgrModel::new(world.clone(), Some(grid.clone()), options.clone()).unwrap();
    let mut correct_rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut crowd_time, mut totals) = (0.0, [(0usize, 0usize, 0.0f64); BINS.len()]);
    println!("    t points inj best_m best_deg ll_truth ll_best | by distance: points matched ll");
    for event in sim {
        let SimEvent::Scan(scan, truth) = event else { continue };
        crowd.advance(&walked, scan.stamp - crowd_time);
        crowd_time = scan.stamp;
        let walkers = crowd.people(&walked);
        let image = camera.render(&world, Props { boxes: &[], people: &walkers }, &truth, &mut noise_rng);
        planes_filter.filter(&image, &mut rng, &mut planes);
        let obs = Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, scan.stamp, scan.odometry);
        let filter = filter.get_or_insert_with(|| {
            let options = LocalizeOptions { init: Init::Known(truth), ..options.clone() };
            let model = CgrModel::new(world.clone(), Some(grid.clone()), options).unwrap();
            Filter::new(model, seed, 1).unwrap()
        });
        let Some(report) = filter.process(&obs) else { continue };
        let Some(&(best, _)) = report.weighed.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else { continue };
        let (mut at_truth, mut at_best) = (truth, best);
        let truth_ll = model.correct(&mut at_truth, &obs, &mut (), &mut correct_rng).log_likelihood;
        let best_ll = model.correct(&mut at_best, &obs, &mut (), &mut correct_rng).log_likelihood;
        let lines = grid.lines_at(at_truth.x, at_truth.y).unwrap_or(&[]);
        let mut row = String::new();
        for (k, &(near, far)) in BINS.iter().enumerate() {
            let mut part = Observation2d { points: Vec::new(), normals: Vec::new(), ..obs.clone() };
            for (p, n) in obs.points.iter().zip(&obs.normals) {
                let r = (f64::from(p[0]) - obs.sensor.0).hypot(f64::from(p[1]) - obs.sensor.1);
                if (near..far).contains(&r) {
                    part.points.push(*p);
                    part.normals.push(*n);
                }
            }
            let e = evaluate(&world, lines, &at_truth, &part, &options.cgr);
            row += &format!(" {:4} {:4} {:7.1}", part.points.len(), e.matched, e.log_likelihood);
            if std::env::var("ALL_LINES").is_ok() {
                let all: Vec<u32> = (0..world.walls.len() as u32).collect();
                let e = evaluate(&world, &all, &at_truth, &part, &options.cgr);
                let wide =
                    CgrOptions { normal_tolerance_deg: 90.0, outlier_sigmas: 100.0, ..options.cgr.clone() };
                let w = evaluate(&world, lines, &at_truth, &part, &wide);
                row += &format!(
                    " (all lines: {} short {}; any normal, no cap: {})",
                    e.matched, e.short, w.matched
                );
            }
            totals[k].0 += part.points.len();
            totals[k].1 += e.matched;
            totals[k].2 += e.log_likelihood;
        }
        if std::env::var("DUMP_AT").is_ok_and(|t| (t.parse::<f64>().unwrap() - obs.stamp).abs() < 0.05) {
            let t = at_truth;
            let (s, c) = t.theta.sin_cos();
            let sensor =
                (t.x + c * obs.sensor.0 - s * obs.sensor.1, t.y + s * obs.sensor.0 + c * obs.sensor.1);
            for (p, n) in obs.points.iter().zip(&obs.normals).step_by(7) {
                let (px, py) = (f64::from(p[0]), f64::from(p[1]));
                let r = (px - obs.sensor.0).hypot(py - obs.sensor.1);
                if r < 4.0 {
                    continue;
                }
                let q = (t.x + c * px - s * py, t.y + s * px + c * py);
                let nw =
                    (c * f64::from(n[0]) - s * f64::from(n[1]), s * f64::from(n[0]) + c * f64::from(n[1]));
                let hit = squall_core::visibility::first_hit(&world, lines.iter().copied(), sensor, q);
                let wall = hit.map(|(l, _)| {
                    let w = &world.walls[l as usize];
                    ((w.b.1 - w.a.1).atan2(w.b.0 - w.a.0).to_degrees(), *w)
                });
                println!(
                    "   r={r:.2} q=({:.2},{:.2}) normal={:.0}deg wall={:?}",
                    q.0,
                    q.1,
                    nw.1.atan2(nw.0).to_degrees(),
                    wall
                );
            }
        }
        let heading = normalize_angle(best.theta - truth.theta).to_degrees();
        let parts = |pose: &squall_core::geometry::Pose2| {
            let lines = grid.lines_at(pose.x, pose.y).unwrap_or(&[]);
            let e = evaluate(&world, lines, pose, &obs, &options.cgr);
            format!("m{} s{} w{:.1}", e.matched, e.short, e.widest_short_run())
        };
        row = format!(" truth {} best {} |{row}", parts(&at_truth), parts(&at_best));
        println!(
            "{:5.1} {:6} {:3} {:6.3} {:8.2} {:8.1} {:7.1} |{row}",
            obs.stamp,
            obs.points.len(),
            report.injected,
            best.distance(&truth),
            heading,
            truth_ll,
            best_ll
        );
    }
    for (&(near, far), (points, matched, ll)) in BINS.iter().zip(totals) {
        let share = matched as f64 / points.max(1) as f64;
        println!("summary {near}-{far} m: points={points} matched={share:.3} ll_at_truth={ll:.1}");
    }
}
