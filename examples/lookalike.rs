//! Diagnostic: does a wrong place fit a simulated run's readings as well
//! as the truth? Replays `depth_sim` (no clutter, no people) or `sim`
//! frames on a line map for one seed, and scores the observations of
//! `[0, t_end]` along two paths carried back from `t_end` by odometry:
//! one from the true pose there and one from a given pose. Each frame's
//! pose is refined by CGR first, as the filter does.
//!
//! `cargo run --release --example lookalike -- MAP SEED depth|laser T_END X Y THETA`
//!
//! (X, Y, THETA): the wrong place, e.g. a run's estimate at `T_END` from its
//! `trajectory.tum`. A sum far below the truth's says the readings told the
//! places apart and the filter lost the truth; a sum as high says the
//! sensor could not tell them apart (docs/decisions/0020).

use std::borrow::Cow;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_bolts::cgr::measurement::{CgrOptions, refine};
use squall_bolts::cgr::observation::Observation2d;
use squall_core::depth_render::{DepthCamera, Props};
use squall_core::geometry::Pose2;
use squall_core::visibility::observable_scene;
use squall_spouts::sim::{SimConfig, SimEvent, Simulation, Start, floor_for};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let (map, seed, input) = (&a[0], a[1].parse::<u64>().unwrap(), a[2].as_str());
    let t_end: f64 = a[3].parse().unwrap();
    let hyp = Pose2::new(a[4].parse().unwrap(), a[5].parse().unwrap(), a[6].parse().unwrap());
    let floor = floor_for(map, seed).unwrap();
    let world = floor.world.clone();
    let depth = input == "depth";
    let config = SimConfig {
        seed,
        duration_secs: t_end + 0.05,
        scan_hz: 10.0,
        range_max: 8.0,
        beams: if depth { 2 } else { SimConfig::default().beams },
        start: Start::Drawn,
        ..SimConfig::default()
    };
    let sim = Simulation::new(floor, config).unwrap();
    let camera = DepthCamera::d435_on_robot();
    let mut filter = PlaneFilter::new(FspfOptions::default(), camera.intrinsics);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut noise = ChaCha8Rng::seed_from_u64(seed ^ 1);
    let mut planes = PlaneFiltered::default();
    let mut frames = Vec::new();
    for event in sim {
        let SimEvent::Scan(scan, truth) = event else { continue };
        let obs = if depth {
            let image = camera.render(&world, Props { boxes: &[], people: &[] }, &truth, &mut noise);
            filter.filter(&image, &mut rng, &mut planes);
            Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, scan.stamp, scan.odometry)
        } else {
            Observation2d::from_laser(&scan, 8.0)
        };
        frames.push((obs, truth));
    }
    let (last, truth_end) = frames.last().map(|(o, t)| (o.odometry, *t)).unwrap();
    let o = CgrOptions::default();
    let mut lines_at = |p: &Pose2| -> Cow<'static, [u32]> {
        let mut ids: Vec<u32> =
            observable_scene(&world, (p.x, p.y), o.range).iter().map(|v| v.line).collect();
        ids.sort_unstable();
        ids.dedup();
        Cow::Owned(ids)
    };
    let (mut st, mut sh) = (0.0, 0.0);
    for (k, (obs, _)) in frames.iter().enumerate() {
        let back = obs.odometry.relative_to(&last);
        let mut score = |end: &Pose2| {
            let p = end.compose(&back);
            let (_, e, _) = refine(&world, &mut lines_at, &p, obs, &o);
            e.log_likelihood
        };
        let (lt, lh) = (score(&truth_end), score(&hyp));
        st += lt;
        sh += lh;
        if k % 10 == 0 || k + 1 == frames.len() {
            println!(
                "t={:5.1} points={:4} truth {:9.1} hyp {:9.1} | sums truth {:10.1} hyp {:10.1} (hyp − truth {:+.1})",
                obs.stamp,
                obs.points.len(),
                lt,
                lh,
                st,
                sh,
                sh - st
            );
        }
    }
}
