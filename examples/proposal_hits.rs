//! Diagnostic: how often does a global start's proposal land near the
//! robot? For one line map and a few seeds, simulates the start of a run
//! (no clutter, no people) and, at frames every second for the first
//! ten, draws proposals from the frame as a global start draws its
//! particles (`CgrModel`'s `inject`), counting those within 0.5 m and
//! 10° of the true pose. Compares three sensors at the same poses: the
//! depth camera (plane filtered), the laser cut to the camera's 55° and
//! 3.5 m, and the full 180° laser at 8 m.
//!
//! `cargo run --release --example proposal_hits -- MAP SEEDS [DRAWS]`
//!
//! SEEDS: e.g. `1-5`. DRAWS per frame, default 2000 (a global start's
//! particles). See docs/decisions/0020.

use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_bolts::cgr::model::{CgrModel, Init, LocalizeOptions};
use squall_bolts::cgr::observation::Observation2d;
use squall_bolts::pf::ParticleModel;
use squall_core::depth_render::{DepthCamera, Props};
use squall_core::geometry::{Pose2, normalize_angle};
use squall_core::sensor::LaserReading;
use squall_spouts::sim::{SimConfig, SimEvent, Simulation, Start, floor_for};

/// A proposal this near the truth is within CGR's reach (metres, degrees).
const NEAR: (f64, f64) = (0.5, 10.0);

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let map = &a[0];
    let (lo, hi) = a[1].split_once('-').map_or_else(
        || (a[1].parse::<u64>().unwrap(), a[1].parse::<u64>().unwrap()),
        |(l, h)| (l.parse().unwrap(), h.parse().unwrap()),
    );
    let draws: usize = a.get(2).map_or(2000, |d| d.parse().unwrap());
    let camera = DepthCamera::d435_on_robot();
    println!("seed    t  | depth: points hits | laser 55° 3.5 m: points hits | laser 180° 8 m: points hits");
    let mut totals = [0usize; 3];
    for seed in lo..=hi {
        let floor = floor_for(map, seed).unwrap();
        let world = Arc::new(floor.world.clone());
        let options = LocalizeOptions { init: Init::Global, particles: draws, ..LocalizeOptions::default() };
        let model = CgrModel::new(world.clone(), None, options).unwrap();
        let config = SimConfig {
            seed,
            duration_secs: 10.05,
            scan_hz: 10.0,
            range_max: 8.0,
            beams: 720,
            fov: 2.0 * std::f64::consts::PI,
            start: Start::Drawn,
            ..SimConfig::default()
        };
        let sim = Simulation::new(floor, config).unwrap();
        let mut filter = PlaneFilter::new(FspfOptions::default(), camera.intrinsics);
        let (mut rng, mut noise) = (ChaCha8Rng::seed_from_u64(seed), ChaCha8Rng::seed_from_u64(seed ^ 1));
        let mut planes = PlaneFiltered::default();
        let mut k = 0;
        for event in sim {
            let SimEvent::Scan(scan, truth) = event else { continue };
            k += 1;
            if (k - 1) % 10 != 0 {
                continue;
            }
            let image = camera.render(&world, Props { boxes: &[], people: &[] }, &truth, &mut noise);
            filter.filter(&image, &mut rng, &mut planes);
            let depth =
                Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, scan.stamp, scan.odometry);
            let narrow = Observation2d::from_laser(&cut(&scan, 55f64.to_radians(), 3.5), 3.5);
            let wide = Observation2d::from_laser(&cut(&scan, std::f64::consts::PI, 8.0), 8.0);
            let mut row = format!("{seed:4} {:4.1} ", scan.stamp);
            for (i, obs) in [&depth, &narrow, &wide].into_iter().enumerate() {
                let mut draw = ChaCha8Rng::seed_from_u64(seed * 1000 + k as u64);
                let hits = (0..draws)
                    .filter(|_| {
                        let mut p = Pose2::IDENTITY;
                        model.inject(&mut p, obs, &mut draw);
                        p.distance(&truth) <= NEAR.0
                            && normalize_angle(p.theta - truth.theta).abs() <= NEAR.1.to_radians()
                    })
                    .count();
                totals[i] += hits;
                row += &format!("| {:6} {:5} ", obs.points.len(), hits);
            }
            println!("{row}");
        }
    }
    println!("total hits: depth {}, laser 55° {}, laser 180° {}", totals[0], totals[1], totals[2]);
}

/// `scan` (a full circle) cut to `fov` radians centred ahead and `range`
/// metres.
fn cut(scan: &LaserReading, fov: f64, range: f32) -> LaserReading {
    let keep: Vec<usize> =
        (0..scan.ranges.len()).filter(|&i| scan.beam_angle(i).abs() <= fov / 2.0).collect();
    let first = keep[0];
    LaserReading {
        ranges: keep
            .iter()
            .map(|&i| if scan.ranges[i] <= range { scan.ranges[i] } else { f32::INFINITY })
            .collect(),
        angle_min: scan.beam_angle(first),
        range_max: range.into(),
        ..scan.clone()
    }
}
