//! Fast Sampling Plane Filtering on the real D435 frames in
//! `../shared/data/depth/d435` (640 × 480, real noise and holes): median
//! milliseconds per frame, single thread, default settings (Biswas &
//! Veloso report 1.39 ms per 640 × 480 frame).

use std::path::Path;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall::bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall::core::camera::{DepthImage, Intrinsics};

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/depth/d435");
    assert!(dir.exists(), "missing {}: this bench reads the shared data set", dir.display());
    let mut files: Vec<_> =
        std::fs::read_dir(&dir).expect("readable").map(|e| e.expect("entry").path()).collect();
    files.sort();
    let frames: Vec<DepthImage> =
        files.iter().map(|f| DepthImage::load_png(f).expect("a depth PNG")).collect();
    let mut filter = PlaneFilter::new(FspfOptions::default(), Intrinsics::D435);
    let mut out = PlaneFiltered::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut times = Vec::new();
    let (mut points, mut iterations) = (Vec::new(), Vec::new());
    for _round in 0..20 {
        for f in &frames {
            let started = Instant::now();
            filter.filter(f, &mut rng, &mut out);
            times.push(started.elapsed().as_secs_f64() * 1e3);
            points.push(out.points.len());
            iterations.push(out.iterations);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut p: Vec<f64> = points.iter().map(|&x| x as f64).collect();
    let mut it: Vec<f64> = iterations.iter().map(|&x| x as f64).collect();
    println!(
        "FSPF on {} D435 frames × 20: median {:.3} ms per frame, {:.0} points, {:.0} neighbourhoods tried",
        frames.len(),
        median(&mut times),
        median(&mut p),
        median(&mut it)
    );
}
