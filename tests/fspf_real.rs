//! FSPF on the real D435 frames (`../shared/data/depth/d435`, no ground
//! truth): the points it keeps must lie on the scene's planes. Each kept
//! point's plane (its position and normal) is checked against the full
//! depth data around it — every valid pixel within 8 px — which FSPF never
//! looked at as a whole: on a real plane nearly all of them fit.

use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall::bolts::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use squall::core::camera::{DepthImage, Intrinsics};

/// Fraction of the valid pixels within `radius` px of `p` that lie within
/// 2 cm of the plane through `p` with normal `n`.
fn support(image: &DepthImage, k: &Intrinsics, p: [f32; 3], n: [f32; 3], radius: i64) -> f64 {
    let col = (k.fx * f64::from(p[0] / p[2]) + k.cx).round() as i64;
    let row = (k.fy * f64::from(p[1] / p[2]) + k.cy).round() as i64;
    let (mut on, mut all) = (0, 0);
    for r in (row - radius).max(0)..=(row + radius).min(image.height as i64 - 1) {
        for c in (col - radius).max(0)..=(col + radius).min(image.width as i64 - 1) {
            if let Some(q) = image.point(r as usize, c as usize, k) {
                all += 1;
                let d = (0..3).map(|i| (q[i] - p[i]) * n[i]).sum::<f32>();
                on += usize::from(d.abs() < 0.02);
            }
        }
    }
    if all == 0 { 0.0 } else { on as f64 / all as f64 }
}

#[test]
fn fspf_keeps_points_on_the_planes_of_real_frames() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/depth/d435");
    assert!(dir.exists(), "missing {}: this test reads the shared data set", dir.display());
    let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert_eq!(files.len(), 49, "the D435 sequence has 49 frames");
    let k = Intrinsics::D435;
    let mut filter = PlaneFilter::new(FspfOptions::default(), k);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut out = PlaneFiltered::default();
    let mut supports = Vec::new();
    for file in files.iter().step_by(6) {
        let image = DepthImage::load_png(file).unwrap();
        filter.filter(&image, &mut rng, &mut out);
        // Some frames hold few half-metre planes: FSPF then stops at k_max.
        assert!(out.points.len() + out.outliers.len() > 0, "{}: nothing sampled", file.display());
        for (p, n) in out.points.iter().zip(&out.normals).step_by(20) {
            supports.push(support(&image, &k, *p, *n, 8));
        }
    }
    assert!(supports.len() > 500, "{} points checked", supports.len());
    supports.sort_by(f64::total_cmp);
    let median = supports[supports.len() / 2];
    let planar = supports.iter().filter(|&&s| s >= 0.6).count() as f64 / supports.len() as f64;
    eprintln!("{} points: median support {median:.2}, {:.0}% at 0.6 or more", supports.len(), planar * 100.0);
    assert!(median >= 0.8, "median support {median:.2}");
    assert!(
        planar >= 0.8,
        "only {:.0}% of kept points sit on a plane of their neighbourhood",
        planar * 100.0
    );
}
