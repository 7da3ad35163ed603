//! SLAM speed, as seed 003's Table 1: median milliseconds per processed
//! reading for 20, 30, 60 and 100 particles, scan-matching cutoff none vs 140,
//! on the first 1500 scans of ACES and on 60 s of the simulated office with
//! a 640-beam laser (Simbad's). The defaults match every other beam
//! (`lskip` 1; integration still uses them all); a third row per data set
//! matches every beam, as GMapping's ROS default (`lskip` 0) does, the
//! C++ GMapping's setting in docs/results/slam-speed.md's comparison. Single thread, one
//! run per cell.
//!
//!     cargo bench --bench slam
//!
//! Needs `../shared/data` beside the repository.

use std::path::Path;
use std::time::Instant;

use squall::bolts::slam::filter::Rbpf;
use squall::bolts::slam::options::{Cutoff, SlamOptions};
use squall::core::sensor::LaserReading;
use squall::spouts::carmen::{ReadOptions, read_front_scans};
use squall::spouts::sim::office::office;
use squall::spouts::sim::{SimConfig, SimEvent, Simulation};

fn aces() -> Vec<LaserReading> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/laser/aces.clf");
    assert!(path.exists(), "missing {}: this bench reads the shared data set", path.display());
    read_front_scans(&path, ReadOptions::default()).expect("ACES parses").into_iter().take(1500).collect()
}

fn simbad_like() -> Vec<LaserReading> {
    let config = SimConfig { seed: 1, duration_secs: 60.0, beams: 640, ..SimConfig::default() };
    Simulation::new(office(1, 3, 2), config)
        .expect("a valid simulation")
        .filter_map(|e| match e {
            SimEvent::Scan(s, _) => Some(s),
            SimEvent::Odom(_) => None,
        })
        .collect()
}

/// Median ms per processed reading.
fn run(scans: &[LaserReading], particles: usize, cutoff: Cutoff, lskip: usize, max_urange: f64) -> f64 {
    let options = SlamOptions { particles, cutoff, lskip, max_urange, ..SlamOptions::default() };
    let mut filter = Rbpf::new(options, 42).expect("valid options");
    let mut times = Vec::new();
    for s in scans {
        let started = Instant::now();
        if filter.process(s).is_some() {
            times.push(started.elapsed().as_secs_f64() * 1e3);
        }
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let datasets =
        [("ACES (1500 scans)", aces(), 80.0), ("simulated office, 640 beams", simbad_like(), 30.0)];
    println!("median ms per processed reading (single thread)");
    println!("{:<30} {:>14} {:>8} {:>8} {:>8} {:>8}", "data set", "setting", "20 p", "30 p", "60 p", "100 p");
    for (name, scans, range) in &datasets {
        let rows = [
            ("none", Cutoff::Unbounded, 1),
            ("140", Cutoff::Evaluations(140), 1),
            ("none, lskip 0", Cutoff::Unbounded, 0),
        ];
        for (label, cutoff, lskip) in rows {
            let cells: Vec<f64> =
                [20, 30, 60, 100].iter().map(|&p| run(scans, p, cutoff, lskip, *range)).collect();
            println!(
                "{name:<30} {label:>14} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
                cells[0], cells[1], cells[2], cells[3]
            );
        }
    }
}
