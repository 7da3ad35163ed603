//! The matcher against hand-made scenes: scores equal to the grid's own
//! kernel search, climbs that find the true pose, bounds that never change
//! a result.

use super::beam_cache::{CACHE_CAPACITY, INLINE};
use super::fast_exp::exp_neg;
use super::scan::{back_code, step_back};
use super::*;
use crate::slam::scenes::{mapped, room, scan_of};

/// The room mapped from three poses, the true pose of the scan to
/// match, default options and that scan.
fn scene() -> (TiledGrid, Pose2, SlamOptions, PreparedScan) {
    let world = room();
    let truth = Pose2::new(3.3, 1.7, 0.4);
    let grid = mapped(&world, &[truth, Pose2::new(1.0, 4.0, -1.0), Pose2::new(6.5, 1.5, 2.0)]);
    let o = SlamOptions::default();
    let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
    (grid, truth, o, scan)
}

/// The score as the grid's own kernel search gives it, beam by beam in
/// order, with nothing cached (d²/σ as the matcher rounds it: times
/// 1/σ).
fn reference_score(grid: &TiledGrid, pose: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Real {
    let per_sigma = 1.0 / o.sigma;
    let laser = pose.compose(&scan.laser_offset);
    let (s, c) = laser.theta.sin_cos();
    let mut score = 0.0;
    for b in &scan.beams {
        let (cos, sin) = b.turned(c, s);
        let end = (laser.x + b.range * cos, laser.y + b.range * sin);
        if let Some(d2) = grid.nearest_backed_wall(end, (step_back(cos), step_back(sin)), o.kernel) {
            score += exp_neg(d2 * per_sigma);
        }
    }
    score
}

#[test]
fn a_prepared_scan_keeps_every_lskip_plus_first_valid_beam_within_range() {
    let mut reading = scan_of(&room(), &Pose2::new(3.3, 1.7, 0.4));
    reading.ranges[..8].copy_from_slice(&[1.0, 2.0, 0.0, 3.0, 90.0, 4.0, 5.0, 6.0]);
    reading.ranges.truncate(8);
    reading.range_max = 100.0;
    let ranges = |lskip, max_urange| {
        let o = SlamOptions { lskip, max_urange, ..SlamOptions::default() };
        PreparedScan::new(&reading, &o).beams.iter().map(|b| b.range).collect::<Vec<_>>()
    };
    // Beam 2 is no return, beam 4 beyond max_urange: 6 of 8 usable. With
    // lskip 1 a full scan would be matched with 4 beams; 6 / 4 rounds to
    // a stride of 2, with lskip 3 (budget 2) to 3.
    assert_eq!(ranges(0, 80.0), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert_eq!(ranges(1, 80.0), [1.0, 5.0]);
    assert_eq!(ranges(3, 80.0), [1.0, 3.0, 5.0]);
    assert_eq!(ranges(1, 100.0), [1.0, 90.0, 5.0]);
    assert_eq!(SlamOptions::default().lskip, 1, "the default matches every other beam");
}

#[test]
fn a_sparse_scan_keeps_every_beam_and_each_counts_for_less() {
    let o = SlamOptions::default();
    let full = scan_of(&room(), &Pose2::new(3.3, 1.7, 0.4));
    let dense = PreparedScan::new(&full, &o);
    assert_eq!((dense.len(), dense.per_beam()), (180, 1.0), "every other beam of 360, each a full one");
    // Open space: only 160 of the 360 beams return (fewer than 3/4 of the
    // 180 a full scan is matched with, so the stride rounds to 1).
    let mut open = full.clone();
    open.ranges[160..].fill(open.range_max as f32);
    let sparse = PreparedScan::new(&open, &o);
    assert_eq!(sparse.len(), 160, "every returning beam");
    assert_eq!(sparse.per_beam(), 0.5, "each stands for half of a full scan's beam");
    // At 3/4 and above, every other beam, as for a full scan.
    open.ranges[..270].copy_from_slice(&full.ranges[..270]);
    let most = PreparedScan::new(&open, &o);
    assert_eq!((most.len(), most.per_beam()), (135, 1.0));
    let mut coarse = PreparedScan::default();
    sparse.every_nth_into(4, &mut coarse);
    assert_eq!((coarse.len(), coarse.per_beam()), (40, 0.5), "a coarse pass keeps the weight");
}

#[test]
fn the_score_is_the_grid_kernel_search_summed() {
    let (grid, truth, o, scan) = scene();
    // A beam whose cell lies beyond ±2³¹ cells: the scan is no longer
    // short, and that beam is matched uncached. (Beam 8: with the
    // default lskip of 1 only even beams are matched.)
    let mut far_reading = scan_of(&room(), &truth);
    far_reading.range_max = 1e9;
    far_reading.ranges[8] = 2e8;
    let far_options = SlamOptions { max_urange: 1e9, ..o.clone() };
    let far = PreparedScan::new(&far_reading, &far_options);
    let mut cache = BeamCache::default();
    for (scan, o, short) in [(&scan, &o, true), (&far, &far_options, false)] {
        for (i, dx) in [-0.3, -0.05, 0.0, 0.02, 0.2].into_iter().enumerate() {
            let pose = Pose2::new(truth.x + dx, truth.y - dx, truth.theta + 0.5 * dx);
            let mut turned = Turned::default();
            directions(&grid, scan, laser_heading(&pose, scan), &mut turned);
            assert_eq!(turned.short, short);
            let want = reference_score(&grid, &pose, scan, o);
            assert!(want > 10.0, "pose {i} matches beams ({want})");
            for _ in 0..2 {
                // Cold, then from the cache: the same sum, bit for bit.
                let got = score_with(&grid, &pose, scan, &turned, o, &mut cache, Real::NEG_INFINITY);
                assert_eq!(got.map(Real::to_bits), Some(want.to_bits()), "pose {i}, short {short}");
            }
        }
    }
}

#[test]
fn a_bounded_score_gives_up_only_on_poses_that_cannot_win() {
    let (grid, truth, o, scan) = scene();
    let mut cache = BeamCache::default();
    let (mut dirs, mut given_up) = (Turned::default(), 0);
    for (i, dx) in [-0.3, -0.05, 0.0, 0.02, 0.2].into_iter().enumerate() {
        let pose = Pose2::new(truth.x + dx, truth.y - dx, truth.theta + 0.5 * dx);
        directions(&grid, &scan, laser_heading(&pose, &scan), &mut dirs);
        let full = score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, Real::NEG_INFINITY).unwrap();
        assert!(full > 10.0, "pose {i} matches beams ({full})");
        for to_beat in [full - 1.0, full - 1e-9, full, full + 1e-9, full + 0.5, full + 5.0, 1e6] {
            match score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, to_beat) {
                // The same sum, bit for bit.
                Some(s) => assert_eq!(s.to_bits(), full.to_bits(), "pose {i}, to beat {to_beat}"),
                None => {
                    assert!(full <= to_beat, "pose {i} scores {full} > {to_beat} but was given up");
                    given_up += 1;
                }
            }
        }
        // Nothing can beat a score above one per beam: given up early.
        assert_eq!(score_with(&grid, &pose, &scan, &dirs, &o, &mut cache, 1e6), None);
    }
    assert!(given_up >= 10, "poses that cannot win are given up ({given_up})");
}

#[test]
fn the_cache_answers_as_the_grid_does() {
    use rand::{RngExt, SeedableRng};
    let (grid, _, _, _) = scene();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut cache = BeamCache::default();
    let (mut matched, mut overflowing) = (0, 0);
    // Wider kernels' windows hold more walls than a slot does; kernel 4
    // runs without forgetting, so that the overflow's bound is reached.
    for k in [1, 2, 4] {
        for round in 0..40_000 {
            if round == 0 || (k < 4 && round % 5_000 == 0) {
                cache.forget();
            }
            let hit = (rng.random::<f64>() * 8.0, rng.random::<f64>() * 6.0);
            let back = (rng.random_range(-1..=1), rng.random_range(-1..=1));
            let want = grid.nearest_backed_wall(hit, back, k);
            let (cell, end) = (grid.cell_of(hit.0, hit.1), (hit.0 as f32, hit.1 as f32));
            assert_eq!(
                cache.nearest(&grid, cell, end, back, back_code(back), k),
                want,
                "{hit:?} {back:?} k {k}"
            );
            // Asked again, from the cache.
            assert_eq!(
                cache.nearest(&grid, cell, end, back, back_code(back), k),
                want,
                "{hit:?} {back:?} k {k}, cached"
            );
            matched += usize::from(want.is_some());
            let mut found = 0;
            grid.backed_walls(grid.cell_of(hit.0, hit.1), back, k, |_, _| found += 1);
            overflowing += usize::from(found > INLINE);
        }
    }
    assert!(
        matched > 1_000 && overflowing > 100,
        "the test reaches walls ({matched}) and overflows ({overflowing})"
    );
    // The overflow's bound starts the cache over rather than growing.
    assert!(cache.generation > 1 + 17, "the cache started over {} times", cache.generation - 18);
    assert!(cache.overflow.len() <= CACHE_CAPACITY + 81, "{}", cache.overflow.len());
}

#[test]
fn the_inline_exponential_matches_libm() {
    for i in 0..20_000 {
        let x = i as Real * 1e-3;
        let (got, want) = (exp_neg(x), (-x).exp());
        assert!((got - want).abs() <= 1e-13 * want, "{x}: {got} vs {want}");
    }
    assert!(exp_neg(300.0) > 0.0 && exp_neg(800.0) == 0.0 && exp_neg(Real::INFINITY) == 0.0);
}

#[test]
fn the_step_back_rounds_like_gmapping() {
    for i in 0..=3600 {
        let a = (i as Real / 10.0).to_radians();
        let (s, c) = a.sin_cos();
        for v in [c, s] {
            let want = (-v * std::f64::consts::SQRT_2).round() as i64;
            // Away from the rounding boundary the two agree exactly.
            if ((v * std::f64::consts::SQRT_2).abs() - 0.5).abs() > 1e-9 {
                assert_eq!(step_back(v), want, "{v}");
            }
        }
    }
}

#[test]
fn recovers_known_offsets() {
    use rand::{RngExt, SeedableRng};
    let (grid, truth, o, scan) = scene();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12345);
    for _ in 0..20 {
        let mut r = || rng.random::<f64>() - 0.5;
        let start = Pose2::new(truth.x + 0.2 * r(), truth.y + 0.2 * r(), truth.theta + 0.1 * r());
        let m = optimize(&grid, &start, &scan, &o);
        assert!(m.pose.distance(&truth) < 0.02, "from {start:?}: {:?}", m.pose);
        assert!((m.pose.theta - truth.theta).abs() < 0.01, "from {start:?}: {:?}", m.pose);
        assert_eq!(m.log_likelihood, likelihood_and_score(&grid, &m.pose, &scan, &o).1);
    }
}

#[test]
fn the_wide_search_recovers_an_offset_the_climb_cannot() {
    let (grid, truth, o, scan) = scene();
    let start = Pose2::new(3.55, 1.45, 0.52);
    let wide = Matcher::default().wide_search(&grid, &start, &scan, &o, 0.3, 0.15, 3);
    assert!(wide.pose.distance(&truth) < 0.02, "{:?}", wide.pose);
    assert!(wide.evaluations > 343, "the grid and the climb are counted: {}", wide.evaluations);
    let climb = optimize(&grid, &start, &scan, &o);
    assert!(climb.score < wide.score, "{} vs {}", climb.score, wide.score);
}

/// The wide search's grid as a plain scan in row order (heading, x, y)
/// with the reference score: its first best pose.
fn wide_grid_by_rows(grid: &TiledGrid, init: &Pose2, scan: &PreparedScan, o: &SlamOptions) -> Pose2 {
    let (reach, turn, steps) = (0.3, 0.15, 3);
    let mut coarse = PreparedScan::default();
    scan.every_nth_into(WIDE_SEARCH_BEAM_STRIDE, &mut coarse);
    let mut best = (Real::NEG_INFINITY, *init);
    for a in -steps..=steps {
        for i in -steps..=steps {
            for j in -steps..=steps {
                let f = |k: i32| Real::from(k) / Real::from(steps);
                let pose = Pose2::new(init.x + reach * f(i), init.y + reach * f(j), init.theta + turn * f(a));
                let s = reference_score(grid, &pose, &coarse, o);
                if s > best.0 {
                    best = (s, pose);
                }
            }
        }
    }
    best.1
}

#[test]
fn the_wide_search_finds_what_a_scan_in_row_order_finds() {
    let (grid, truth, o, scan) = scene();
    let mut matcher = Matcher::default();
    for start in [Pose2::new(3.55, 1.45, 0.52), Pose2::new(3.1, 1.9, 0.3), truth] {
        let wide = matcher.wide_search(&grid, &start, &scan, &o, 0.3, 0.15, 3);
        let by_rows = wide_grid_by_rows(&grid, &start, &scan, &o);
        let climbed = optimize(&grid, &by_rows, &scan, &o);
        assert_eq!((wide.pose, wide.score), (climbed.pose, climbed.score), "from {start:?}");
    }
    // Where every pose ties (nothing mapped), the first in row order wins.
    let nowhere = Pose2::new(500.0, 500.0, 0.0);
    let wide = matcher.wide_search(&grid, &nowhere, &scan, &o, 0.3, 0.15, 3);
    assert_eq!(wide.score, 0.0);
    assert_eq!(wide.pose, wide_grid_by_rows(&grid, &nowhere, &scan, &o));
    assert_eq!(wide.pose, Pose2::new(499.7, 499.7, -0.15));
}

#[test]
fn a_reused_matcher_forgets_the_previous_map() {
    let (grid, truth, o, scan) = scene();
    // Another map: the same room seen from a pose 0.3 m off, so its
    // walls (and cached candidates) lie elsewhere.
    let shifted = mapped(&room(), &[Pose2::new(3.0, 1.7, 0.4)]);
    let mut reused = Matcher::default();
    let on_grid = reused.optimize(&grid, &truth, &scan, &o);
    let start = Pose2::new(3.35, 1.65, 0.42);
    let again = reused.optimize(&shifted, &start, &scan, &o);
    assert_eq!(again, optimize(&shifted, &start, &scan, &o), "as if fresh");
    assert_ne!(again.pose, on_grid.pose);
    assert_eq!(reused.optimize(&grid, &truth, &scan, &o), on_grid);
}

#[test]
fn the_true_pose_scores_best_and_likelihood_agrees() {
    let world = room();
    let truth = Pose2::new(3.3, 1.7, 0.4);
    let grid = mapped(&world, &[truth]);
    let o = SlamOptions::default();
    let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
    let off = Pose2::new(3.4, 1.7, 0.4);
    assert!(score(&grid, &truth, &scan, &o) > score(&grid, &off, &scan, &o));
    let (s, l, n) = likelihood_and_score(&grid, &truth, &scan, &o);
    let (_, l_off, _) = likelihood_and_score(&grid, &off, &scan, &o);
    assert!(s > 0.0 && 10 * n > 8 * scan.beams.len() && l > l_off, "{s} {l} {n} {l_off}");
    // The same from a matcher that last matched on another map.
    let mut reused = Matcher::default();
    reused.optimize(&mapped(&world, &[off]), &off, &scan, &o);
    assert_eq!(reused.likelihood(&grid, &truth, &scan, &o), (s, l, n));
}

#[test]
fn the_cutoff_bounds_evaluations() {
    let world = room();
    let truth = Pose2::new(3.3, 1.7, 0.4);
    let grid = mapped(&world, &[truth]);
    let start = Pose2::new(3.45, 1.6, 0.45);
    let free = optimize(
        &grid,
        &start,
        &PreparedScan::new(&scan_of(&world, &truth), &SlamOptions::default()),
        &SlamOptions::default(),
    );
    let o = SlamOptions { cutoff: Cutoff::Evaluations(10), ..SlamOptions::default() };
    let cut = optimize(&grid, &start, &PreparedScan::new(&scan_of(&world, &truth), &o), &o);
    assert!(free.evaluations > 10, "{}", free.evaluations);
    assert_eq!(cut.evaluations, 10);
    assert!(cut.score <= free.score);
}

/// Eigenvalues of the 2 × 2 translation block of an information matrix,
/// least first, with the least one's direction.
fn translation_eigen(h: &squall_core::covariance::Mat3) -> (Real, Real, (Real, Real)) {
    let (a, b, d) = (h[0][0], h[0][1], h[1][1]);
    let mean = (a + d) / 2.0;
    let spread = (((a - d) / 2.0).powi(2) + b * b).sqrt();
    let least = mean - spread;
    // (b, least − a) is an eigenvector for the least eigenvalue (or x when b = 0).
    let v = if b.abs() > 1e-12 {
        (b, least - a)
    } else if a <= d {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let n = v.0.hypot(v.1);
    (least, mean + spread, (v.0 / n, v.1 / n))
}

#[test]
fn a_corridor_scan_says_nothing_along_the_corridor() {
    // Two walls 2 m apart, 40 m long, along x at 30°: the scan from the
    // middle fixes the position across the corridor and the heading, not
    // the position along it.
    let (s, c) = 30f64.to_radians().sin_cos();
    let at = |x: Real, y: Real| (10.0 + c * x - s * y, 10.0 + s * x + c * y);
    let wall = |y: Real| {
        let (a, b) = (at(-20.0, y), at(20.0, y));
        format!("{},{},{},{}\n", a.0, a.1, b.0, b.1)
    };
    let world = squall_core::linemap::LineMap::parse("corridor", &(wall(-1.0) + &wall(1.0))).unwrap();
    let centre = at(0.0, 0.0);
    let truth = Pose2::new(centre.0, centre.1, 30f64.to_radians() + 0.2);
    let grid = mapped(&world, &[truth, Pose2::new(at(1.0, 0.3).0, at(1.0, 0.3).1, 0.9)]);
    let o = SlamOptions::default();
    let scan = PreparedScan::new(&scan_of(&world, &truth), &o);
    let h = Matcher::default().information(&grid, &truth, &scan, &o);
    let (least, most, along) = translation_eigen(&h);
    assert!(least < 1e-3 * most, "along the corridor {least} against across {most}");
    assert!((along.0 * c + along.1 * s).abs() > 0.99, "the blind direction is the corridor's: {along:?}");
    assert!(h[2][2] > 1e4, "the walls fix the heading: {}", h[2][2]);
}

#[test]
fn a_room_scan_fixes_every_direction() {
    let (grid, truth, o, scan) = scene();
    let h = Matcher::default().information(&grid, &truth, &scan, &o);
    let (least, most, _) = translation_eigen(&h);
    assert!(least > 0.1 * most, "{least} against {most}");
    assert!(h[2][2] > 1e4);
    // Symmetric, and nothing matched on an empty map.
    assert!((h[0][2] - h[2][0]).abs() < 1e-9 && (h[0][1] - h[1][0]).abs() < 1e-9);
    let empty = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
    assert_eq!(Matcher::default().information(&empty, &truth, &scan, &o), squall_core::covariance::ZERO);
}
