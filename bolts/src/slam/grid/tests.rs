//! Grids built by hand: the wire format's checks, fixed-point cells,
//! growth, copy-on-write, beams across tiles, the kernel search against a
//! cell-by-cell search, count limits.

use super::cell::MAX_VISITS;
use super::wire::TileWire;
use super::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn a_grid_survives_the_wire_and_a_damaged_one_is_refused() {
    let mut g = TiledGrid::new(0.05, (1.0, -2.0)).unwrap();
    for x in -40..40 {
        g.update((x, 3), |c| c.add_hit(x as f32 * 0.05, 0.15));
        g.update((x, 2), |c| c.visits += 1);
    }
    let bytes = postcard::to_stdvec(&g).unwrap();
    let back: TiledGrid = postcard::from_bytes(&bytes).unwrap();
    assert_eq!(back.tile_count(), g.tile_count());
    for x in -45..45 {
        for y in 0..5 {
            assert_eq!(back.get((x, y)), g.get((x, y)), "({x}, {y})");
        }
    }
    assert_eq!(back.cell_of(0.3, 0.3), g.cell_of(0.3, 0.3));
    let wire = || GridWire::from(g.clone());
    let refused = |w: GridWire| TiledGrid::try_from(w).unwrap_err().to_string();
    assert!(refused(GridWire { resolution: 0.0, ..wire() }).contains("resolution"));
    assert!(refused(GridWire { origin: (Real::NAN, 0.0), ..wire() }).contains("origin"));
    assert!(refused(GridWire { wall_threshold: 2.0, ..wire() }).contains("threshold"));
    assert!(refused(GridWire { tiles_wide: wire().tiles_wide + 1, ..wire() }).contains("holds"));
    assert!(refused(GridWire { tiles_wide: usize::MAX, tiles_high: 2, ..wire() }).contains("holds"));
    let mut flipped = wire();
    let tile = flipped.tiles.iter_mut().flatten().next().unwrap();
    Arc::make_mut(tile).walls[3] ^= 1;
    assert!(refused(flipped).contains("bits disagree"));
    let mut poisoned = wire();
    let tile = poisoned.tiles.iter_mut().flatten().find(|t| t.cells.iter().any(|c| c.hits > 0)).unwrap();
    let cells = &mut Arc::make_mut(tile).cells;
    let i = cells.iter().position(|c| c.hits > 0).unwrap();
    cells.set(i, Cell { mean_x: f32::INFINITY, ..cells.get(i) });
    assert!(refused(poisoned).contains("not finite"));
    // Damaged bytes: an error or a valid grid, never a panic.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..500 {
        let mut bad = bytes.clone();
        let i = rng.random_range(0..bad.len());
        bad[i] = rng.random();
        if let Ok(grid) = postcard::from_bytes::<TiledGrid>(&bad) {
            let _ = grid.get((0, 3));
        }
    }
}

#[test]
fn fixed_point_cells_agree_with_cell_of() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let g = TiledGrid::new(0.05, (-3.2, 7.9)).unwrap();
    let to_cell = |f: (i64, i64)| (f.0 >> FIXED_BITS, f.1 >> FIXED_BITS);
    let mut checked = 0;
    for _ in 0..100_000 {
        let laser = (rng.random_range(-500.0..500.0), rng.random_range(-500.0..500.0));
        let beam = (rng.random_range(-80.0..80.0), rng.random_range(-80.0..80.0));
        let end = (laser.0 + beam.0, laser.1 + beam.1);
        let want = g.cell_of(end.0, end.1);
        // Within a few 2⁻²⁴ cells of a cell's edge either side may win.
        let inside = |v: f64| {
            let frac = v / 0.05 - (v / 0.05).floor();
            frac > 1e-6 && frac < 1.0 - 1e-6
        };
        if !(inside(end.0 + 3.2) && inside(end.1 - 7.9)) {
            continue;
        }
        let base = g.fixed_of(laser.0, laser.1).unwrap();
        let cell = to_cell((base.0 + g.fixed_length(beam.0), base.1 + g.fixed_length(beam.1)));
        assert_eq!(cell, want, "laser {laser:?} beam {beam:?}");
        checked += 1;
    }
    assert!(checked > 99_000, "{checked}");
    assert_eq!(g.fixed_of(1e9, 0.0), None, "beyond 2^30 cells");
    assert_eq!(g.fixed_length(0.05), 1 << FIXED_BITS);
    assert_eq!(g.fixed_length(-0.05), -(1 << FIXED_BITS));
}

#[test]
fn cells_anywhere_grow_the_grid() {
    let mut g = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    for c in [(0, 0), (-1, -1), (100, -300), (-5000, 7000)] {
        g.update(c, |cell| {
            cell.hits += 3;
            cell.visits += 3;
        });
    }
    for c in [(0, 0), (-1, -1), (100, -300), (-5000, 7000)] {
        assert_eq!(g.get(c).hits, 3, "{c:?}");
    }
    assert_eq!(g.get((1, 1)), Cell::default());
    assert_eq!(g.get((1_000_000, 0)), Cell::default());
    assert_eq!(g.tile_count(), 4);
    assert_eq!(g.cell_of(-0.01, 0.06), (-1, 1));
}

#[test]
fn copies_share_tiles_until_written() {
    let mut a = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    for x in 0..100 {
        a.update((x, 0), |c| c.visits += 1);
    }
    assert_eq!(a.take_clone_count(), 0);
    let mut b = a.clone();
    assert_eq!(TiledGrid::distinct_tiles([&a, &b]).0, 4, "a copy shares every tile");
    b.update((5, 0), |c| c.hits += 1);
    assert_eq!(b.take_clone_count(), 1, "one write clones one tile");
    b.update((6, 0), |c| c.hits += 1);
    assert_eq!(b.take_clone_count(), 0, "the clone is now b's own");
    assert_eq!(TiledGrid::distinct_tiles([&a, &b]).0, 5);
    assert_eq!((b.count_beyond(&[&a]), a.count_beyond(&[&b]), b.count_beyond(&[])), (1, 1, 4));
    assert_eq!(a.count_beyond(&[&b, &a]), 0);
    // Shared tiles are found by place even after an index grew.
    b.update((-500, 300), |c| c.hits += 1);
    assert_eq!((b.count_beyond(&[&a]), a.count_beyond(&[&b])), (2, 1));
    assert_eq!(a.get((5, 0)).hits, 0, "the original is untouched");
    assert_eq!(b.get((5, 0)).hits, 1);
}

/// Distinct tiles by brute force: every tile address, once.
fn distinct_by_address(grids: &[&TiledGrid]) -> (usize, usize) {
    let mut seen = std::collections::HashSet::new();
    let bytes = grids
        .iter()
        .flat_map(|g| g.tiles.iter().flatten())
        .filter(|t| seen.insert(Arc::as_ptr(t)))
        .map(|t| t.bytes())
        .sum();
    (seen.len(), bytes)
}

#[test]
fn distinct_tiles_counts_each_tile_once_however_the_grids_lie() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut root = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    for _ in 0..400 {
        let c = (rng.random_range(-200..200), rng.random_range(-200..200));
        root.update(c, |cell| cell.add_hit(0.0, 0.0));
    }
    // Copies that wrote here and there, one of them far off (its index
    // grows), and a snapshot of a copy.
    let mut grids = vec![root.clone(); 5];
    for (k, g) in grids.iter_mut().enumerate() {
        for _ in 0..20 * k {
            let c = (rng.random_range(-300..300), rng.random_range(-300..300));
            g.update(c, |cell| cell.visits += 1);
        }
    }
    grids[4].update((9000, -4000), |cell| cell.visits += 1);
    let snapshot = grids[2].clone();
    grids[2].update((0, 0), |cell| cell.visits += 1);
    grids.push(snapshot);
    // A tile held in two places, as a transfer between processes may
    // leave one.
    let shared = grids[1].tiles.iter().flatten().next().cloned();
    let empty = grids[1].tiles.iter().position(Option::is_none).expect("an empty place");
    grids[1].tiles[empty] = shared;
    let all: Vec<&TiledGrid> = std::iter::once(&root).chain(&grids).collect();
    assert_eq!(TiledGrid::distinct_tiles(all.iter().copied()), distinct_by_address(&all));
    // Grids too far apart for one box of places are counted the same way.
    let mut far = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    far.update((1 << 40, 1 << 40), |cell| cell.visits += 1);
    let with_far: Vec<&TiledGrid> = all.iter().copied().chain([&far]).collect();
    assert_eq!(TiledGrid::distinct_tiles(with_far.iter().copied()), distinct_by_address(&with_far));
    assert_eq!(TiledGrid::distinct_tiles([]), (0, 0));
}

#[test]
fn exports_the_explored_area() {
    let mut g = TiledGrid::new(0.5, (10.0, 20.0)).unwrap();
    g.update((1, 2), |c| *c = Cell { hits: 1, visits: 4, ..Cell::default() });
    g.update((-1, 0), |c| c.visits = 2);
    let o = g.to_occupancy();
    assert_eq!((o.width, o.height), (64, 32), "two tiles side by side");
    assert_eq!(o.origin, (10.0 - 32.0 * 0.5, 20.0));
    let (x, y) = o.cell_of(10.75, 21.25).unwrap();
    assert_eq!(o.get(x, y), 25);
    let (x, y) = o.cell_of(10.0 - 0.25, 20.25).unwrap();
    assert_eq!(o.get(x, y), 0, "visited, never hit: free");
    assert_eq!(o.get(0, 0), squall_core::occupancy::UNKNOWN);
}

#[test]
fn integer_floor_matches_floor() {
    for v in [-2.5, -2.0, -1e-12, 0.0, 1e-12, 0.999_999, 1.0, 3.7, -1e9 - 0.5, 1e12 + 0.25] {
        assert_eq!(floor(v), v.floor() as i64, "{v}");
    }
}

#[test]
fn kernel_search_and_wall_neighbours_match_a_cell_by_cell_search() {
    let mut g = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    // Cells over four tiles around the origin: walls, free cells and
    // cells at the threshold (neither).
    for _ in 0..1500 {
        let c = (rng.random_range(-40..40), rng.random_range(-40..40));
        let (hits, visits) = match rng.random_range(0..3) {
            0 => (rng.random_range(1..4), 4),
            1 => (0, rng.random_range(1..6)),
            _ => (1, 10),
        };
        let m = (c.0 as f32 * 0.1 + 0.05, c.1 as f32 * 0.1 + 0.02);
        g.update(c, |cell| *cell = Cell { mean_x: m.0, mean_y: m.1, hits, visits });
    }
    let reference = |hit: (Real, Real), back: (i64, i64), k: i64| {
        let c = g.cell_of(hit.0, hit.1);
        let mut best: Option<f32> = None;
        for y in c.1 - k..=c.1 + k {
            for x in c.0 - k..=c.0 + k {
                let cell = g.get((x, y));
                let behind = g.get((x + back.0, y + back.1));
                let wall = cell.visits > 0 && cell.hits as Real > 0.1 * cell.visits as Real;
                let free = behind.visits == 0 || (behind.hits as Real) < 0.1 * behind.visits as Real;
                if wall && free {
                    let d2 = (hit.0 as f32 - cell.mean_x).powi(2) + (hit.1 as f32 - cell.mean_y).powi(2);
                    best = Some(best.map_or(d2, |b| b.min(d2)));
                }
            }
        }
        best.map(Real::from)
    };
    let mut matched = 0;
    for _ in 0..3000 {
        let hit = (rng.random_range(-4.5..4.5), rng.random_range(-4.5..4.5));
        for back in [(-1, -1), (-1, 0), (0, 1), (1, 1), (1, -1), (0, 0)] {
            for k in [0, 1, 2] {
                let got = g.nearest_backed_wall(hit, back, k);
                assert_eq!(got, reference(hit, back, k), "{hit:?} back {back:?} k {k}");
                matched += usize::from(got.is_some());
            }
        }
    }
    assert!(matched > 10_000, "the data exercises matches: {matched}");

    // The wall cells around a cell, in the same order, inside a tile and
    // across tiles alike.
    let mut visited = 0;
    for _ in 0..2000 {
        let c = (rng.random_range(-45..45), rng.random_range(-45..45));
        for k in [0, 1, 2, 3] {
            let mut got = Vec::new();
            g.wall_means_around(c, k, |x, y| got.push((x, y)));
            let mut want = Vec::new();
            for y in c.1 - k..=c.1 + k {
                for x in c.0 - k..=c.0 + k {
                    let cell = g.get((x, y));
                    if cell.visits > 0 && cell.hits as Real > 0.1 * cell.visits as Real {
                        want.push((cell.mean_x, cell.mean_y));
                    }
                }
            }
            assert_eq!(got, want, "around {c:?}, k {k}");
            visited += got.len();
        }
    }
    assert!(visited > 1000, "the data has walls around: {visited}");
}

#[test]
fn a_beam_updates_the_cells_of_its_line_across_tiles() {
    let mut fast = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    let mut slow = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for i in 0..400 {
        let from = (rng.random_range(-10..10), rng.random_range(-10..10));
        let to = (rng.random_range(-100..100), rng.random_range(-100..100));
        let end = (i % 3 != 0).then_some((to.0 as f32 * 0.1 + 0.03, to.1 as f32 * 0.1 + 0.07));
        fast.add_beam(from, to, end);
        squall_core::geometry::line_cells(from, to, |c| {
            if c != to {
                slow.update(c, |cell| cell.visits += 1);
            }
        });
        if let Some((x, y)) = end {
            slow.update(to, |cell| cell.add_hit(x, y));
        }
    }
    assert_eq!(fast.cell_bounds(), slow.cell_bounds());
    let ((x0, y0), (x1, y1)) = fast.cell_bounds().unwrap();
    for y in y0..=y1 {
        for x in x0..=x1 {
            assert_eq!(fast.get((x, y)), slow.get((x, y)), "({x}, {y})");
        }
    }
    // The bits agree too: every window finds the same wall.
    for y in y0..=y1 {
        for x in x0..=x1 {
            let hit = (x as Real * 0.1 + 0.05, y as Real * 0.1 + 0.05);
            assert_eq!(fast.nearest_backed_wall(hit, (1, 0), 1), slow.nearest_backed_wall(hit, (1, 0), 1));
        }
    }
}

#[test]
fn a_shared_tile_is_cloned_once_per_beam() {
    let mut a = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    a.add_beam((0, 0), (20, 0), Some((2.05, 0.05)));
    let mut b = a.clone();
    b.take_clone_count();
    b.add_beam((0, 1), (25, 1), Some((2.55, 0.15)));
    assert_eq!(b.take_clone_count(), 1, "26 cells, one tile, one clone");
    assert_eq!(a.get((5, 1)).visits, 0, "the original is untouched");
}

#[test]
fn counts_past_the_limit_are_halved() {
    let mut g = TiledGrid::new(0.1, (0.0, 0.0)).unwrap();
    let n = MAX_VISITS + 1;
    for _ in 0..n {
        g.add_beam((0, 0), (2, 0), Some((0.25, 0.05)));
    }
    // A crossed cell (no hits) and the end cell (all hits) each saw one
    // visit more than a cell counts: halved.
    let crossed = g.get((1, 0));
    assert_eq!((crossed.hits, crossed.visits), (0, n / 2));
    let end = g.get((2, 0));
    assert_eq!((end.hits, end.visits), (n / 2, n / 2));
    assert!(end.is_wall(g.wall_threshold()) && crossed.is_free(g.wall_threshold()));
    // And they go on counting from there.
    g.add_beam((0, 0), (2, 0), Some((0.25, 0.05)));
    assert_eq!(g.get((1, 0)).visits, n / 2 + 1);
    assert_eq!((g.get((2, 0)).hits, g.get((2, 0)).visits), (n / 2 + 1, n / 2 + 1));
    // A write of any value keeps the counts countable.
    g.update((5, 5), |c| *c = Cell { hits: 9, visits: 3 * MAX_VISITS, ..Cell::default() });
    let c = g.get((5, 5));
    assert!(c.visits <= MAX_VISITS && c.hits <= c.visits, "{c:?}");
}

#[test]
fn a_tile_from_the_wire_with_uncountable_cells_is_refused() {
    let wire = |c: Cell| TileWire {
        cells: vec![c; TILE_SIDE * TILE_SIDE],
        walls: vec![0; TILE_SIDE],
        free: vec![u32::MAX; TILE_SIDE],
    };
    let e = Tile::try_from(wire(Cell { visits: MAX_VISITS + 1, ..Cell::default() })).unwrap_err().to_string();
    assert!(e.contains("65536 visits") && e.contains("(0, 0)"), "{e}");
    let e = Tile::try_from(wire(Cell { hits: 2, visits: 1, ..Cell::default() })).unwrap_err().to_string();
    assert!(e.contains("2 hits in 1 visits"), "{e}");
    assert!(Tile::try_from(wire(Cell { visits: MAX_VISITS, ..Cell::default() })).is_ok());
}

#[test]
fn occupancy_and_mean_hit() {
    let mut c = Cell { visits: 1, ..Cell::default() };
    for (x, y) in [(0.5, 2.0), (1.0, 3.0), (1.5, 4.0)] {
        c.add_hit(x, y);
    }
    assert_eq!(c.occupancy(), Some(0.75));
    assert_eq!(c.mean(), Some((1.0, 3.0)));
    assert_eq!(Cell::default().occupancy(), None);
}

#[test]
fn cells_hit_in_any_order_read_back_as_written() {
    // Tiles keep hit cells apart from the rest, in row-major order: hits
    // that arrive out of order insert into the middle of that list, and
    // every cell must still read back as a plain cell-by-cell map holds it.
    let mut rng = ChaCha8Rng::seed_from_u64(29);
    let mut g = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    let mut expected = std::collections::HashMap::<(i64, i64), Cell>::new();
    for _ in 0..6000 {
        let c = (rng.random_range(-40..40), rng.random_range(-40..40));
        let reference = expected.entry(c).or_default();
        if rng.random_bool(0.3) {
            let (x, y) = (rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0));
            g.update(c, |cell| cell.add_hit(x, y));
            reference.add_hit(x, y);
        } else {
            g.add_beam(c, (c.0 + 1, c.1), None);
            reference.visits += 1;
        }
    }
    let copy = g.clone();
    let back: TiledGrid = postcard::from_bytes(&postcard::to_stdvec(&g).unwrap()).unwrap();
    for y in -42..42 {
        for x in -42..42 {
            let want = expected.get(&(x, y)).copied().unwrap_or_default();
            assert_eq!(g.get((x, y)), want, "({x}, {y})");
            assert_eq!(back.get((x, y)), want, "({x}, {y}) from the wire");
        }
    }
    let walls = |g: &TiledGrid| {
        let mut means = Vec::new();
        g.wall_means_around((5, 5), 14, |mx, my| means.push((mx, my)));
        means
    };
    assert!(walls(&g).len() > 20);
    assert_eq!(walls(&copy), walls(&g));
    assert!(g.bytes() < g.tile_count() * (std::mem::size_of::<Cell>() * TILE_SIDE * TILE_SIDE) / 3);
}
