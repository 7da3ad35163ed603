//! Observable scenes on the real GHC7 line map (the thesis's GHC7 data
//! set): on-demand ray casting (thesis Alg. 4.3) per query, and building
//! and querying the precomputed grid on a 20 m × 20 m cut of the map
//! (0.2 m cells, 8 m range).

use std::path::Path;
use std::time::Instant;

use squall::bolts::cgr::scene_grid::SceneGrid;
use squall::core::linemap::LineMap;
use squall::core::visibility::observable_scene;

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/linemaps/GHC7_vector.txt");
    assert!(path.exists(), "missing {}: this bench reads the shared data set", path.display());
    let map = LineMap::load(&path).expect("GHC7 parses");
    let (x0, y0, x1, y1) = map.bounds();
    // A fixed lattice of query points over the map.
    let queries: Vec<(f64, f64)> = (0..20)
        .flat_map(|i| {
            (0..20).map(move |j| {
                (x0 + (x1 - x0) * (i as f64 + 0.5) / 20.0, y0 + (y1 - y0) * (j as f64 + 0.5) / 20.0)
            })
        })
        .collect();
    let mut times = Vec::new();
    let mut visible = 0;
    for &q in &queries {
        let started = Instant::now();
        visible += observable_scene(&map, q, 8.0).len();
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "GHC7 ({} walls): on-demand scene, 8 m: median {:.3} ms per query ({} queries, {:.1} pieces each)",
        map.walls.len(),
        times[times.len() / 2],
        queries.len(),
        visible as f64 / queries.len() as f64
    );
    // A 20 m × 20 m cut around the map's centre.
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let inside = |p: (f64, f64)| (p.0 - cx).abs() <= 10.0 && (p.1 - cy).abs() <= 10.0;
    let cut = LineMap { walls: map.walls.iter().copied().filter(|w| inside(w.a) && inside(w.b)).collect() };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let started = Instant::now();
    let grid = SceneGrid::build(&cut, 0.2, 8.0, threads).expect("valid cell and range");
    let build = started.elapsed().as_secs_f64();
    let (w, h) = grid.size();
    let started = Instant::now();
    let mut found = 0usize;
    for i in 0..100_000 {
        let (x, y) = (cx - 9.9 + (i % 317) as f64 * 0.0625, cy - 9.9 + (i % 311) as f64 * 0.0637);
        found += grid.lines_at(x, y).map_or(0, <[u32]>::len);
    }
    let lookup_ns = started.elapsed().as_secs_f64() * 1e9 / 100_000.0;
    println!(
        "GHC7 cut ({} walls): grid {w} × {h} cells built in {build:.2} s on {threads} threads, {} entries; lookup {lookup_ns:.1} ns ({found} ids read)",
        cut.walls.len(),
        grid.entries()
    );
}
