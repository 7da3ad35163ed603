//! A 2D pose graph: poses joined by relative-pose constraints, optimized by
//! Gauss–Newton with a robust loss on the loop constraints.
//!
//! The graph is a chain (each node joined to the next by the front end's
//! motion between them) plus a few loop constraints between distant nodes.
//! Each Gauss–Newton step solves the normal equations H δ = −g by conjugate
//! gradients preconditioned with H's block-tridiagonal part (the chain and
//! every block on the diagonal), which is factored exactly in O(N). What
//! the preconditioner leaves out are the loops' off-diagonal blocks, of
//! rank at most 6 per loop, so CG converges in at most 6 L + 1 iterations
//! for L loops in exact arithmetic, and in far fewer in practice: a sparse
//! direct solver's fill-in is not needed for a chain with a few chords.

use squall_core::covariance::{Mat3, ZERO, add, apply, inverse, mul, scale, transpose};
use squall_core::geometry::{Pose2, Real, normalize_angle};

/// A relative-pose constraint: node `to` seen from node `from` is
/// `measured`, with information (inverse covariance) `information`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Constraint {
    /// The node the measurement is taken from.
    pub from: usize,
    /// The node measured.
    pub to: usize,
    /// `to`'s pose in `from`'s frame.
    pub measured: Pose2,
    /// Inverse covariance of the measurement, in `(x, y, θ)` of `from`'s
    /// frame rotated into the measurement's.
    pub information: Mat3,
    /// Whether the robust loss applies (loops, not the chain).
    pub robust: bool,
}

/// The Cauchy loss's scale, in standard deviations: a loop whose error is
/// this many σ counts half as much as a consistent one; one at 10 σ counts
/// about a tenth. A wrong loop (a corridor matched one door off) is thus
/// outvoted by the chain rather than bending it.
const CAUCHY_SIGMAS: Real = 3.0;

/// The error of `c` at the poses `a` (its `from`) and `b` (its `to`):
/// `measured⁻¹ ⊕ a⁻¹ ⊕ b` as `(x, y, θ)`, and its Jacobians with respect
/// to `a` and `b`.
fn error_and_jacobians(c: &Constraint, a: &Pose2, b: &Pose2) -> ([Real; 3], Mat3, Mat3) {
    let (sa, ca) = a.theta.sin_cos();
    let (sz, cz) = c.measured.theta.sin_cos();
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    // Rᵃᵀ (tb − ta), then Rᶻᵀ (that − tz).
    let (lx, ly) = (ca * dx + sa * dy, -sa * dx + ca * dy);
    let (ex, ey) = (lx - c.measured.x, ly - c.measured.y);
    let e = [cz * ex + sz * ey, -sz * ex + cz * ey, normalize_angle(b.theta - a.theta - c.measured.theta)];
    // d(Rᵃᵀ (tb − ta)) / dθa.
    let (gx, gy) = (-sa * dx + ca * dy, -ca * dx - sa * dy);
    let rz = |x: Real, y: Real| (cz * x + sz * y, -sz * x + cz * y);
    let (r00, r10) = rz(ca, -sa);
    let (r01, r11) = rz(sa, ca);
    let (t0, t1) = rz(gx, gy);
    let jb = [[r00, r01, 0.0], [r10, r11, 0.0], [0.0, 0.0, 1.0]];
    let ja = [[-r00, -r01, t0], [-r10, -r11, t1], [0.0, 0.0, -1.0]];
    (e, ja, jb)
}

/// `e · (Ω e)`: the squared error in standard deviations.
fn chi2(information: &Mat3, e: &[Real; 3]) -> Real {
    let w = apply(information, *e);
    e[0] * w[0] + e[1] * w[1] + e[2] * w[2]
}

/// The robust weight of a constraint whose squared error is `chi2`.
fn cauchy(chi2: Real) -> Real {
    1.0 / (1.0 + chi2 / (CAUCHY_SIGMAS * CAUCHY_SIGMAS))
}

/// The normal equations of one Gauss–Newton step: diagonal blocks, the
/// chain's blocks (i, i+1), and the loops' off-diagonal blocks.
struct Normal {
    diagonal: Vec<Mat3>,
    chain: Vec<Mat3>,
    chords: Vec<(usize, usize, Mat3)>,
    gradient: Vec<[Real; 3]>,
}

impl Normal {
    /// `H v`.
    fn apply(&self, v: &[[Real; 3]], out: &mut [[Real; 3]]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = apply(&self.diagonal[i], v[i]);
        }
        for (i, b) in self.chain.iter().enumerate() {
            add_to(&mut out[i], apply(b, v[i + 1]));
            add_to(&mut out[i + 1], apply(&transpose(b), v[i]));
        }
        for &(i, j, ref b) in &self.chords {
            add_to(&mut out[i], apply(b, v[j]));
            add_to(&mut out[j], apply(&transpose(b), v[i]));
        }
    }
}

fn add_to(a: &mut [Real; 3], b: [Real; 3]) {
    a[0] += b[0];
    a[1] += b[1];
    a[2] += b[2];
}

fn dot(a: &[[Real; 3]], b: &[[Real; 3]]) -> Real {
    a.iter().zip(b).map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2]).sum()
}

/// The block-tridiagonal part of H, factored: `Sᵢ⁻¹` and the blocks above
/// the diagonal (block LDLᵀ, the Thomas algorithm on 3 × 3 blocks).
struct Tridiagonal {
    inverse_pivots: Vec<Mat3>,
    upper: Vec<Mat3>,
}

impl Tridiagonal {
    fn factor(n: &Normal) -> Option<Self> {
        let mut inverse_pivots = Vec::with_capacity(n.diagonal.len());
        let mut previous: Option<(Mat3, Mat3)> = None;
        for (i, d) in n.diagonal.iter().enumerate() {
            let pivot = match previous {
                // Sᵢ = Aᵢ − Bᵢ₋₁ᵀ Sᵢ₋₁⁻¹ Bᵢ₋₁.
                Some((s_inv, b)) => {
                    let correction = mul(&transpose(&b), &mul(&s_inv, &b));
                    add(d, &scale(&correction, -1.0))
                }
                None => *d,
            };
            let s_inv = inverse(&pivot)?;
            inverse_pivots.push(s_inv);
            previous = n.chain.get(i).map(|b| (s_inv, *b));
        }
        Some(Tridiagonal { inverse_pivots, upper: n.chain.clone() })
    }

    /// `x = M⁻¹ r`.
    fn solve(&self, r: &[[Real; 3]], x: &mut [[Real; 3]]) {
        let n = r.len();
        // Forward: yᵢ = rᵢ − Bᵢ₋₁ᵀ Sᵢ₋₁⁻¹ yᵢ₋₁ (held in x).
        x[0] = r[0];
        for i in 1..n {
            let t = apply(&transpose(&self.upper[i - 1]), apply(&self.inverse_pivots[i - 1], x[i - 1]));
            x[i] = [r[i][0] - t[0], r[i][1] - t[1], r[i][2] - t[2]];
        }
        // Back: xᵢ = Sᵢ⁻¹ (yᵢ − Bᵢ xᵢ₊₁).
        x[n - 1] = apply(&self.inverse_pivots[n - 1], x[n - 1]);
        for i in (0..n - 1).rev() {
            let t = apply(&self.upper[i], x[i + 1]);
            x[i] = apply(&self.inverse_pivots[i], [x[i][0] - t[0], x[i][1] - t[1], x[i][2] - t[2]]);
        }
    }
}

/// Conjugate-gradient iterations at most per Gauss–Newton step.
const MAX_CG_ITERATIONS: usize = 200;

/// Information of the prior that holds node 0 where it is (the gauge).
const ANCHOR: Real = 1e9;

/// The poses that best fit `constraints` (`chain` ones join every node to
/// the next; the rest are loops under a Cauchy loss), starting from
/// `poses`, after at most `iterations` Gauss–Newton steps. Node 0 stays
/// put. Stops early once a step moves no pose by more than 1e-6 m or rad.
pub(crate) fn optimize(poses: &mut [Pose2], constraints: &[Constraint], iterations: usize) {
    optimize_from(poses, 0, constraints, iterations);
}

/// As [`optimize`], with the nodes before `first_free` held where they are:
/// a constraint between a held node and a free one pulls only the free
/// one, and one between held nodes is ignored. The free nodes must be
/// joined to each other by the chain and, unless `first_free` is 0, the
/// first of them to the node before it; the cost of a step is that of the
/// free nodes and the constraints given, however many are held.
pub(crate) fn optimize_from(
    poses: &mut [Pose2],
    first_free: usize,
    constraints: &[Constraint],
    iterations: usize,
) {
    if poses.len() < first_free + 2 {
        return;
    }
    for _ in 0..iterations {
        let Some(normal) = linearize(poses, first_free, constraints) else { return };
        let Some(step) = solve(&normal) else { return };
        let mut largest: Real = 0.0;
        for (p, d) in poses[first_free..].iter_mut().zip(&step) {
            *p = Pose2::new(p.x - d[0], p.y - d[1], p.theta - d[2]);
            largest = largest.max(d[0].abs()).max(d[1].abs()).max(d[2].abs());
        }
        if largest < 1e-6 {
            break;
        }
    }
}

/// The normal equations of the free nodes (`first_free..`) at `poses`,
/// indexed from the first free one; `None` if the chain is broken (a free
/// node not joined to the next).
fn linearize(poses: &[Pose2], first_free: usize, constraints: &[Constraint]) -> Option<Normal> {
    let n = poses.len() - first_free;
    let mut normal = Normal {
        diagonal: vec![ZERO; n],
        chain: vec![ZERO; n - 1],
        chords: Vec::new(),
        gradient: vec![[0.0; 3]; n],
    };
    if first_free == 0 {
        normal.diagonal[0] = [[ANCHOR, 0.0, 0.0], [0.0, ANCHOR, 0.0], [0.0, 0.0, ANCHOR]];
    }
    let mut joined = vec![false; n - 1];
    for c in constraints {
        let (free_from, free_to) = (c.from >= first_free, c.to >= first_free);
        if !(free_from || free_to) {
            continue;
        }
        let (e, ja, jb) = error_and_jacobians(c, &poses[c.from], &poses[c.to]);
        let weight = if c.robust { cauchy(chi2(&c.information, &e)) } else { 1.0 };
        let omega = scale(&c.information, weight);
        let (jat, jbt) = (transpose(&ja), transpose(&jb));
        let (ja_o, jb_o) = (mul(&jat, &omega), mul(&jbt, &omega));
        let (i, j) = (c.from.wrapping_sub(first_free), c.to.wrapping_sub(first_free));
        if free_from {
            normal.diagonal[i] = add(&normal.diagonal[i], &mul(&ja_o, &ja));
            add_to(&mut normal.gradient[i], apply(&ja_o, e));
        }
        if free_to {
            normal.diagonal[j] = add(&normal.diagonal[j], &mul(&jb_o, &jb));
            add_to(&mut normal.gradient[j], apply(&jb_o, e));
        }
        if !(free_from && free_to) {
            continue;
        }
        let (lo, hi, block) = if i < j { (i, j, mul(&ja_o, &jb)) } else { (j, i, mul(&jb_o, &ja)) };
        if hi == lo + 1 && !c.robust {
            normal.chain[lo] = add(&normal.chain[lo], &block);
            joined[lo] = true;
        } else if hi != lo {
            normal.chords.push((lo, hi, block));
        }
    }
    joined.iter().all(|&j| j).then_some(normal)
}

/// H δ = g by preconditioned conjugate gradients (see the module docs).
fn solve(normal: &Normal) -> Option<Vec<[Real; 3]>> {
    let n = normal.diagonal.len();
    let preconditioner = Tridiagonal::factor(normal)?;
    let b = &normal.gradient;
    let mut x = vec![[0.0; 3]; n];
    preconditioner.solve(b, &mut x);
    if normal.chords.is_empty() {
        return Some(x);
    }
    let mut hx = vec![[0.0; 3]; n];
    normal.apply(&x, &mut hx);
    let mut r: Vec<[Real; 3]> =
        b.iter().zip(&hx).map(|(b, h)| [b[0] - h[0], b[1] - h[1], b[2] - h[2]]).collect();
    let mut z = vec![[0.0; 3]; n];
    preconditioner.solve(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let target = 1e-12 * dot(b, b).max(Real::MIN_POSITIVE);
    let mut hp = vec![[0.0; 3]; n];
    for _ in 0..(6 * normal.chords.len() + 10).min(MAX_CG_ITERATIONS) {
        if dot(&r, &r) <= target {
            break;
        }
        normal.apply(&p, &mut hp);
        let php = dot(&p, &hp);
        if php <= 0.0 {
            break;
        }
        let alpha = rz / php;
        for i in 0..n {
            for k in 0..3 {
                x[i][k] += alpha * p[i][k];
                r[i][k] -= alpha * hp[i][k];
            }
        }
        preconditioner.solve(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            for k in 0..3 {
                p[i][k] = z[i][k] + beta * p[i][k];
            }
        }
    }
    Some(x)
}

/// The squared error, in standard deviations, of `c` at `poses`.
pub(crate) fn constraint_chi2(c: &Constraint, poses: &[Pose2]) -> Real {
    let (e, _, _) = error_and_jacobians(c, &poses[c.from], &poses[c.to]);
    chi2(&c.information, &e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use squall_core::covariance::diagonal;

    fn info(sigma_xy: Real, sigma_theta: Real) -> Mat3 {
        diagonal([
            1.0 / (sigma_xy * sigma_xy),
            1.0 / (sigma_xy * sigma_xy),
            1.0 / (sigma_theta * sigma_theta),
        ])
    }

    /// A square loop of `n` nodes a side apart 1 m, driven anticlockwise.
    fn square(side: usize) -> Vec<Pose2> {
        let mut poses = vec![Pose2::IDENTITY];
        for k in 0..4 * side {
            let turn = if (k + 1) % side == 0 { std::f64::consts::FRAC_PI_2 } else { 0.0 };
            let last = *poses.last().unwrap();
            poses.push(last.compose(&Pose2::new(1.0, 0.0, turn)));
        }
        poses
    }

    fn chain(truth: &[Pose2], bias: Pose2) -> Vec<Constraint> {
        truth
            .windows(2)
            .enumerate()
            .map(|(i, w)| Constraint {
                from: i,
                to: i + 1,
                measured: w[1].relative_to(&w[0]).compose(&bias),
                information: info(0.02, 0.005),
                robust: false,
            })
            .collect()
    }

    fn dead_reckoned(constraints: &[Constraint]) -> Vec<Pose2> {
        let mut poses = vec![Pose2::IDENTITY];
        for c in constraints {
            let last = *poses.last().unwrap();
            poses.push(last.compose(&c.measured));
        }
        poses
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let c = Constraint {
            from: 0,
            to: 1,
            measured: Pose2::new(0.7, -0.2, 0.3),
            information: info(1.0, 1.0),
            robust: false,
        };
        let (a, b) = (Pose2::new(1.0, 2.0, 0.4), Pose2::new(1.9, 2.1, 0.5));
        let (_, ja, jb) = error_and_jacobians(&c, &a, &b);
        let h = 1e-6;
        for k in 0..3 {
            let bump = |p: &Pose2| {
                let mut v = [p.x, p.y, p.theta];
                v[k] += h;
                Pose2 { x: v[0], y: v[1], theta: v[2] }
            };
            let (ep, _, _) = error_and_jacobians(&c, &bump(&a), &b);
            let (em, _, _) = error_and_jacobians(&c, &a, &b);
            let (fp, _, _) = error_and_jacobians(&c, &a, &bump(&b));
            for r in 0..3 {
                assert!(((ep[r] - em[r]) / h - ja[r][k]).abs() < 1e-5, "ja[{r}][{k}]");
                assert!(((fp[r] - em[r]) / h - jb[r][k]).abs() < 1e-5, "jb[{r}][{k}]");
            }
        }
    }

    #[test]
    fn a_chain_alone_keeps_its_poses() {
        let truth = square(5);
        let constraints = chain(&truth, Pose2::IDENTITY);
        let mut poses = dead_reckoned(&constraints);
        optimize(&mut poses, &constraints, 5);
        for (p, t) in poses.iter().zip(&truth) {
            assert!(p.distance(t) < 1e-9 && normalize_angle(p.theta - t.theta).abs() < 1e-9);
        }
    }

    /// A square whose every step turns 0.01 rad too far, so that it does
    /// not close, and a loop constraint from its last node to its first:
    /// the truth, the constraints (the loop last) and the dead-reckoned
    /// poses.
    fn drifting_square_with_its_loop() -> (Vec<Pose2>, Vec<Constraint>, Vec<Pose2>) {
        let truth = square(10);
        let mut constraints = chain(&truth, Pose2::new(0.0, 0.0, 0.01));
        let poses = dead_reckoned(&constraints);
        let last = truth.len() - 1;
        constraints.push(Constraint {
            from: 0,
            to: last,
            measured: truth[last].relative_to(&truth[0]),
            information: info(0.02, 0.005),
            robust: false,
        });
        (truth, constraints, poses)
    }

    #[test]
    fn a_loop_closure_pulls_a_drifting_chain_back() {
        let (truth, constraints, mut poses) = drifting_square_with_its_loop();
        let last = truth.len() - 1;
        let drift = poses[last].distance(&truth[last]);
        assert!(drift > 1.0, "the chain drifts {drift} m");
        optimize(&mut poses, &constraints, 10);
        let worst = poses.iter().zip(&truth).map(|(p, t)| p.distance(t)).fold(0.0, Real::max);
        assert!(worst < 0.1 * drift, "worst {worst} m after closing, drift was {drift}");
        assert!(poses[last].distance(&truth[last]) < 0.05);
    }

    #[test]
    fn a_wrong_loop_is_outvoted_by_the_chain() {
        let truth = square(10);
        let mut constraints = chain(&truth, Pose2::IDENTITY);
        let mut poses = dead_reckoned(&constraints);
        // Node 20 said to be 3 m off from node 0: a false match.
        constraints.push(Constraint {
            from: 0,
            to: 20,
            measured: truth[20].relative_to(&truth[0]).compose(&Pose2::new(3.0, 0.0, 0.0)),
            information: info(0.05, 0.01),
            robust: true,
        });
        optimize(&mut poses, &constraints, 10);
        let worst = poses.iter().zip(&truth).map(|(p, t)| p.distance(t)).fold(0.0, Real::max);
        // Without the loss, the chain would take about half the 3 m.
        assert!(worst < 0.3, "a wrong loop moved a pose {worst} m");
    }

    #[test]
    fn held_nodes_stay_and_the_free_ones_take_the_loop() {
        let (truth, constraints, start) = drifting_square_with_its_loop();
        let last = truth.len() - 1;
        let loop_error = |poses: &[Pose2]| constraint_chi2(constraints.last().unwrap(), poses);
        // Only the last ten nodes free: the others stay bit for bit, and
        // the loop's error falls all the same.
        let mut held = start.clone();
        optimize_from(&mut held, last - 9, &constraints, 10);
        assert!(held[..last - 9].iter().zip(&start).all(|(h, s)| h == s));
        assert!(held[last - 9..].iter().zip(&start[last - 9..]).any(|(h, s)| h != s));
        assert!(
            loop_error(&held) < 0.01 * loop_error(&start),
            "{} -> {}",
            loop_error(&start),
            loop_error(&held)
        );
        // With none held it is the whole graph's optimization, exactly.
        let (mut all, mut from_zero) = (start.clone(), start.clone());
        optimize(&mut all, &constraints, 10);
        optimize_from(&mut from_zero, 0, &constraints, 10);
        assert_eq!(all, from_zero);
    }
}
