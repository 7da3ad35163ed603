//! Measures a depth camera's noise against depth on real frames: every
//! 7×7-pixel patch with depth in all its pixels gets a least-squares
//! plane (depth against pixel offsets; over 7 pixels a wall is flat),
//! and its residual RMS is binned by the patch's depth. Prints, per
//! half-metre bin, the lower quartile and median RMS and the median over
//! z², the coefficient of a stereo camera's z² noise law (what
//! `FspfOptions::noise_per_z2` takes). Patches on edges and clutter
//! raise the upper tail; the median is the plane's.
//!
//! Then FSPF runs on every frame with the fixed ε and with the noise
//! law 0.001 z², and the share of valid pixels and of kept points beyond
//! 4 m is printed: what the fixed ε leaves of the far walls.
//!
//! `cargo run --release --example depth_noise -- [DIR]` (default
//! `../shared/data/depth/d435`, the real D435 frames).
//!
//! See docs/decisions/0025.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall_core::camera::{DepthImage, Intrinsics};

/// Half the patch side, pixels.
const HALF: i64 = 3;

/// Bin width, metres.
const BIN: f64 = 0.5;

/// Far, metres: where the fixed ε and the camera's noise part.
const FAR: f64 = 4.0;

fn main() {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "../shared/data/depth/d435".into());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{dir}: {e}"))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    files.sort();
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); 24];
    let mut patch = Vec::with_capacity(((2 * HALF + 1) * (2 * HALF + 1)) as usize);
    for file in &files {
        let image = DepthImage::load_png(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let (w, h) = (image.width as i64, image.height as i64);
        // Patches on a grid, not overlapping.
        for r0 in (HALF..h - HALF).step_by((2 * HALF + 2) as usize) {
            'patch: for c0 in (HALF..w - HALF).step_by((2 * HALF + 2) as usize) {
                patch.clear();
                for r in r0 - HALF..=r0 + HALF {
                    for c in c0 - HALF..=c0 + HALF {
                        let d = image.depth_mm[(r * w + c) as usize];
                        if d == 0 {
                            continue 'patch;
                        }
                        patch.push(((c - c0) as f64, (r - r0) as f64, f64::from(d) * 1e-3));
                    }
                }
                // z = mean + b x + c y: on a grid centred on the patch the
                // three fits are independent.
                let n = patch.len() as f64;
                let mean = patch.iter().map(|p| p.2).sum::<f64>() / n;
                let sxx: f64 = patch.iter().map(|p| p.0 * p.0).sum();
                let syy: f64 = patch.iter().map(|p| p.1 * p.1).sum();
                let b = patch.iter().map(|p| p.0 * (p.2 - mean)).sum::<f64>() / sxx;
                let c = patch.iter().map(|p| p.1 * (p.2 - mean)).sum::<f64>() / syy;
                let rss: f64 = patch.iter().map(|p| (p.2 - mean - b * p.0 - c * p.1).powi(2)).sum();
                if let Some(bin) = bins.get_mut((mean / BIN) as usize) {
                    bin.push((rss / (n - 3.0)).sqrt());
                }
            }
        }
    }
    println!("{} frames from {dir}", files.len());
    println!("depth_m  patches  rms_q25_m  rms_median_m  median_over_z2");
    for (i, bin) in bins.iter_mut().enumerate() {
        if bin.len() < 30 {
            continue;
        }
        bin.sort_by(f64::total_cmp);
        let z = (i as f64 + 0.5) * BIN;
        let median = bin[bin.len() / 2];
        println!(
            "{z:7.2} {:8} {:10.4} {:13.4} {:15.5}",
            bin.len(),
            bin[bin.len() / 4],
            median,
            median / (z * z)
        );
    }
    let far_pixels: f64 = {
        let (mut far, mut all) = (0usize, 0usize);
        for file in &files {
            let image = DepthImage::load_png(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            all += image.depth_mm.iter().filter(|&&d| d != 0).count();
            far += image.depth_mm.iter().filter(|&&d| f64::from(d) * 1e-3 > FAR).count();
        }
        far as f64 / all as f64
    };
    println!("valid pixels beyond {FAR} m: {:.1}%", 100.0 * far_pixels);
    for noise_per_z2 in [0.0, 0.001] {
        let options = FspfOptions { noise_per_z2, ..FspfOptions::default() };
        let mut filter = PlaneFilter::new(options, Intrinsics::D435);
        let (mut rng, mut out) = (ChaCha8Rng::seed_from_u64(1), PlaneFiltered::default());
        let (mut far, mut all) = (0usize, 0usize);
        for file in &files {
            let image = DepthImage::load_png(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            filter.filter(&image, &mut rng, &mut out);
            all += out.points.len();
            far += out.points.iter().filter(|p| f64::from(p[2]) > FAR).count();
        }
        println!(
            "FSPF, noise_per_z2 = {noise_per_z2}: {all} points, {:.1}% beyond {FAR} m",
            100.0 * far as f64 / all.max(1) as f64
        );
    }
}
