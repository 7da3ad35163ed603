//! The output trajectory's smoother: the best lineage's corrected poses
//! fused with the odometry between them, each weighted by noise estimated
//! from the run itself.
//!
//! A particle's corrected pose at each processed scan carries the scan
//! matcher's error, which is white, or nearly: it does not add up from scan
//! to scan, since every scan is matched against the same map. The odometry
//! between two processed scans carries its own error, which does add up.
//! Over a few metres odometry is the better of the two, over a loop the
//! matcher is; the filter weighs them with the motion model's settings
//! (GMapping's defaults, chosen for the particles' spread, not for a given
//! robot) and the matcher's information (one map cell per beam, beams
//! taken as independent), so its path follows every wobble of the matcher.
//!
//! After the run the whole lineage is at hand, and the two errors can be
//! told apart by how they grow: the difference between the lineage's and
//! the odometry's motion over m processed scans has variance 2R + mQ,
//! where R is the matcher's error at one scan and Q the odometry's per
//! step (Mehra's separation of measurement and process noise, taken over
//! spans rather than one lag, since the matcher's errors at neighbouring
//! scans are not quite independent). Systematic odometry error (a scale
//! error, a drift per metre) is fitted first, as a linear function of the
//! odometry's own motion, and removed, as in odometry calibration. A
//! least-squares smoother then finds the poses that best fit both: the
//! corrected poses with R, the calibrated odometry between them with Q.
//! Where the matcher shows no error of its own (R near zero), the poses
//! stay as they are.
//!
//! Where the model also measures each step itself (for SLAM, each
//! processed scan matched against the one before: `Smoother::Scans`, the
//! default), the three estimates of every step tell the noises apart
//! directly (see [`three_way`]), which the growth model cannot where the
//! lineage wanders slowly against its map.
//!
//! The result is the trajectory written out, not the filter's state: the
//! particles, their maps and weights are untouched, and the smoother is a
//! pure function of the lineage, so any number of matcher tasks writes
//! the same trajectory.

use serde::{Deserialize, Serialize};

use squall_core::covariance::{
    IDENTITY, Mat3, ZERO, add, apply, diagonal, inverse, mul, quadratic, scale, transpose,
};
use squall_core::geometry::{Pose2, Real, normalize_angle};

use super::trajectory::Corrected;

/// What is done to the best lineage's poses before they are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Smoother {
    /// Fused with the calibrated odometry and the model's own measurement
    /// of each step (for SLAM, scan-to-scan matching), the three noises
    /// told apart by the three-cornered hat (see [`smooth`]); as
    /// `Odometry` where the model measures too few steps.
    #[default]
    Scans,
    /// Fused with the calibrated odometry, noise estimated from the run
    /// (see the module docs).
    Odometry,
    /// Written as the filter corrected them.
    None,
}

/// Longest span, in processed scans, over which the growth of the
/// lineage-minus-odometry variance is fitted: long enough that errors of
/// the matcher correlated over a few neighbouring scans count as its own
/// (about 20 m of travel at the default update distance), short enough
/// that the odometry's heading error has not yet curved its growth.
const MAX_SPAN: usize = 20;

/// Fewer steps than this and the noise is not estimated: the poses are
/// kept as they are.
const MIN_STEPS: usize = 4 * MAX_SPAN;

/// Smallest variance either noise is given (m², rad²): a hundredth of a
/// millimetre, so that the system stays well conditioned.
const FLOOR: Real = 1e-10;

pub use squall_core::scan_match::MeasuredStep;

/// χ² with three degrees of freedom at 0.999: a step whose measurement and
/// odometry differ by more, given both their noises, has one of them
/// wrong (a failed match, a wheel slip) and is fused without the match.
const AGREEMENT: Real = 16.27;

/// Outliers, for the noises' estimate: a difference more than this many
/// robust standard deviations from the median.
const OUTLIER: Real = 6.0;

/// The poses of `corrected` as `smoother` says, each with its stamp and
/// odometry; `measured[k]` is the model's measurement of the step from
/// processed reading k to k + 1, where it made one.
pub(crate) fn smooth(
    corrected: &[Corrected],
    smoother: Smoother,
    measured: &[Option<MeasuredStep>],
) -> Vec<Corrected> {
    let steps = corrected.len().saturating_sub(1);
    if smoother == Smoother::None || steps < MIN_STEPS {
        return corrected.to_vec();
    }
    // Per step: the lineage's motion a, the odometry's u, and the
    // difference between them, u⁻¹a, as (x, y, θ).
    let lineage: Vec<Pose2> = corrected.windows(2).map(|w| w[1].1.relative_to(&w[0].1)).collect();
    let odometry: Vec<Pose2> = corrected.windows(2).map(|w| w[1].2.relative_to(&w[0].2)).collect();
    let raw: Vec<[Real; 3]> = lineage.iter().zip(&odometry).map(|(a, u)| vector(&a.relative_to(u))).collect();
    let systematic = fit_systematic(&odometry, &raw);
    let residual: Vec<[Real; 3]> =
        raw.iter().zip(&odometry).map(|(e, u)| sub(*e, apply(&systematic, vector(u)))).collect();
    let three_way = if smoother == Smoother::Scans { three_way(&lineage, &residual, measured) } else { None };
    let (prior, fused) = three_way.unwrap_or_else(|| {
        let (matcher, step) = noise(&residual);
        let information = diagonal(step.map(|v| 1.0 / v));
        (matcher, residual.iter().map(|&e| (information, e)).collect())
    });
    let deltas = solve(&lineage, &fused, prior);
    corrected
        .iter()
        .zip(deltas)
        .map(|(&(stamp, pose, odometry), d)| (stamp, pose.compose(&Pose2::new(d[0], d[1], d[2])), odometry))
        .collect()
}

fn vector(p: &Pose2) -> [Real; 3] {
    [p.x, p.y, normalize_angle(p.theta)]
}

fn sub(a: [Real; 3], b: [Real; 3]) -> [Real; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The systematic odometry error: the matrix S for which the lineage's
/// motion differs from the odometry's u by about S·u, by least squares
/// (zero if the odometry's motions do not span x, y and θ).
fn fit_systematic(odometry: &[Pose2], differences: &[[Real; 3]]) -> Mat3 {
    let (mut normal, mut cross) = (ZERO, ZERO);
    for (u, e) in odometry.iter().zip(differences) {
        let u = vector(u);
        for i in 0..3 {
            for j in 0..3 {
                normal[i][j] += u[i] * u[j];
                cross[i][j] += e[i] * u[j];
            }
        }
    }
    // S = (Σ e uᵀ)(Σ u uᵀ)⁻¹, if the normal matrix is well conditioned.
    let trace = normal[0][0] + normal[1][1] + normal[2][2];
    let ridge = diagonal([trace * 1e-9; 3]);
    inverse(&add(&normal, &ridge)).map_or(ZERO, |inv| mul(&cross, &inv))
}

/// The matcher's variance at one scan (R) and the odometry's per step (Q),
/// per component: a line fitted to the variance of the differences summed
/// over spans of 1 to [`MAX_SPAN`] steps has intercept 2R and slope Q.
fn noise(residual: &[[Real; 3]]) -> ([Real; 3], [Real; 3]) {
    let n = residual.len();
    let mean: [Real; 3] = std::array::from_fn(|c| residual.iter().map(|e| e[c]).sum::<Real>() / n as Real);
    let mut cumulative = vec![[0.0; 3]; n + 1];
    for (k, e) in residual.iter().enumerate() {
        cumulative[k + 1] = std::array::from_fn(|c| cumulative[k][c] + e[c] - mean[c]);
    }
    let (mut matcher, mut step) = ([FLOOR; 3], [FLOOR; 3]);
    for c in 0..3 {
        // Least squares of V(m) = α + β m over m = 1..=MAX_SPAN.
        let (mut sm, mut smm, mut sv, mut smv) = (0.0, 0.0, 0.0, 0.0);
        for m in 1..=MAX_SPAN {
            let spans = n + 1 - m;
            let v = (0..spans).map(|k| (cumulative[k + m][c] - cumulative[k][c]).powi(2)).sum::<Real>()
                / spans as Real;
            let m = m as Real;
            (sm, smm, sv, smv) = (sm + m, smm + m * m, sv + v, smv + m * v);
        }
        let count = MAX_SPAN as Real;
        let slope = (count * smv - sm * sv) / (count * smm - sm * sm);
        let intercept = (sv - slope * sm) / count;
        matcher[c] = (intercept / 2.0).max(FLOOR);
        step[c] = slope.max(FLOOR);
    }
    (matcher, step)
}

/// Per step, the information of its residual and the residual (Qₖ⁻¹, eₖ).
type Steps = Vec<(Mat3, [Real; 3])>;

/// Each step's odometry fused with the model's measurement of it, and
/// the lineage's variance per processed reading; `None` if too few steps
/// were measured to tell the noises apart.
///
/// Three estimates of the same motions with independent errors (the
/// lineage's, the calibrated odometry's, the measurement's) give their
/// three variances from the variances of their pairwise differences
/// alone: σ²ₒ = (V(o−l) + V(o−s) − V(l−s)) / 2 and likewise (the
/// three-cornered hat of clock comparisons). This replaces the two-way
/// fit's growth model, which cannot tell a lineage that wanders slowly
/// against its map from odometry that drifts (decision 0014). Per
/// component, the hat is taken over the steps whose measurement is
/// well constrained in that component (predicted variance at most the
/// median), where the measurement's error is least tied to the scene the
/// lineage also sees; the variances are robust (median absolute
/// deviation) and none is set below the standard error of its own
/// estimate. The hat's measurement variance over those steps gives the
/// scale of the measurement's covariance, which then weighs every
/// step, with its degenerate directions (a corridor) left to the
/// odometry.
fn three_way(
    lineage: &[Pose2],
    odometry: &[[Real; 3]],
    measured: &[Option<MeasuredStep>],
) -> Option<([Real; 3], Steps)> {
    if measured.len() != lineage.len() || measured.iter().flatten().count() < MIN_STEPS {
        return None;
    }
    // The lineage's step against the measured one, as (x, y, θ).
    let against: Vec<Option<([Real; 3], [Real; 3])>> = lineage
        .iter()
        .zip(measured)
        .map(|(a, m)| m.map(|m| (vector(&a.relative_to(&m.motion)), diagonal_of(&m.covariance))))
        .collect();
    let (mut odometry_var, mut lineage_var, mut scale) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    for c in 0..3 {
        let predicted: Vec<Real> = against.iter().flatten().map(|m| m.1[c]).collect();
        let limit = median(predicted);
        let mut pairs: Vec<(Real, Real, Real)> = Vec::new();
        for (o, m) in odometry.iter().zip(&against) {
            if let Some((s, var)) = m
                && var[c] <= limit
            {
                pairs.push((o[c], s[c], var[c]));
            }
        }
        let differences: Vec<Real> = pairs.iter().map(|p| p.1 - p.0).collect();
        let (centre, spread) = (median(differences.clone()), robust_sd(&differences));
        pairs.retain(|p| (p.1 - p.0 - centre).abs() < OUTLIER * spread + 1e-12);
        if pairs.len() < MIN_STEPS / 2 {
            return None;
        }
        let variance = |f: &dyn Fn(&(Real, Real, Real)) -> Real| {
            robust_sd(&pairs.iter().map(f).collect::<Vec<_>>()).powi(2)
        };
        let v_ol = variance(&|p| p.0);
        let v_ls = variance(&|p| p.1);
        let v_os = variance(&|p| p.1 - p.0);
        // A median-absolute-deviation variance from n samples has a
        // standard error of about 1.65 · V · √(2/n).
        let n = pairs.len() as Real;
        let error = |v: Real| 1.65 * v * (2.0 / n).sqrt();
        let floor = (error(v_ol).powi(2) + error(v_os).powi(2) + error(v_ls).powi(2)).sqrt() / 2.0;
        odometry_var[c] = ((v_ol + v_os - v_ls) / 2.0).max(floor).max(FLOOR);
        lineage_var[c] = ((v_ol + v_ls - v_os) / 2.0).max(floor).max(FLOOR);
        let measured_var = ((v_os + v_ls - v_ol) / 2.0).max(floor).max(FLOOR);
        scale[c] = measured_var / median(pairs.iter().map(|p| p.2).collect()).max(FLOOR);
    }
    let root = scale.map(Real::sqrt);
    let odometry_information = diagonal(odometry_var.map(|v| 1.0 / v));
    let fused = odometry
        .iter()
        .zip(measured)
        .zip(&against)
        .map(|((&o, m), a)| {
            let (Some(m), Some((s, _))) = (m, a) else { return (odometry_information, o) };
            let covariance: Mat3 =
                std::array::from_fn(|i| std::array::from_fn(|j| root[i] * m.covariance[i][j] * root[j]));
            let difference = sub(*s, o);
            let both = add(&covariance, &diagonal(odometry_var));
            let agrees = inverse(&both).is_some_and(|inv| quadratic(&inv, difference) < AGREEMENT);
            match inverse(&covariance) {
                Some(measurement_information) if agrees => {
                    let information = add(&odometry_information, &measurement_information);
                    let pull = add3(apply(&odometry_information, o), apply(&measurement_information, *s));
                    inverse(&information)
                        .map_or((odometry_information, o), |c| (information, apply(&c, pull)))
                }
                _ => (odometry_information, o),
            }
        })
        .collect();
    Some((lineage_var, fused))
}

fn diagonal_of(a: &Mat3) -> [Real; 3] {
    [a[0][0], a[1][1], a[2][2]]
}

/// The median of `values` (the mean of the middle two for an even count;
/// 0 for none).
fn median(mut values: Vec<Real>) -> Real {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_unstable_by(Real::total_cmp);
    let n = values.len();
    if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) }
}

/// A robust standard deviation: 1.4826 times the median absolute
/// deviation from the median.
fn robust_sd(values: &[Real]) -> Real {
    let centre = median(values.to_vec());
    1.4826 * median(values.iter().map(|v| (v - centre).abs()).collect())
}

/// The SE(2) adjoint of `p`: how a small motion in the frame after `p`
/// reads in the frame before it.
fn adjoint(p: &Pose2) -> Mat3 {
    let (s, c) = p.theta.sin_cos();
    [[c, -s, p.y], [s, c, -p.x], [0.0, 0.0, 1.0]]
}

/// The corrections δₖ (each applied on the right of pose k) minimising
/// Σ δₖᵀR⁻¹δₖ + Σ rₖᵀQₖ⁻¹rₖ, where rₖ = eₖ + δₖ − Adj(aₖ)⁻¹δₖ₋₁ is the
/// step's residual linearised at the lineage, `steps[k]` = (Qₖ⁻¹, eₖ) and
/// R is diagonal, `matcher`. The system is block tridiagonal: one forward
/// elimination and one back substitution.
fn solve(lineage: &[Pose2], steps: &[(Mat3, [Real; 3])], matcher: [Real; 3]) -> Vec<[Real; 3]> {
    let nodes = lineage.len() + 1;
    let prior = diagonal(matcher.map(|v| 1.0 / v));
    // Diagonal blocks, blocks above the diagonal (node k with k + 1), and
    // the gradient.
    let mut diag = vec![prior; nodes];
    let mut upper = vec![ZERO; nodes - 1];
    let mut gradient = vec![[0.0; 3]; nodes];
    for (k, (a, (odometry, e))) in lineage.iter().zip(steps).enumerate() {
        let back = inverse(&adjoint(a)).unwrap_or(IDENTITY);
        let back_t = transpose(&back);
        // rₖ₊₁ = e + δₖ₊₁ − back·δₖ.
        diag[k + 1] = add(&diag[k + 1], odometry);
        diag[k] = add(&diag[k], &mul(&back_t, &mul(odometry, &back)));
        upper[k] = scale(&mul(&back_t, odometry), -1.0);
        let pull = apply(odometry, *e);
        gradient[k + 1] = add3(gradient[k + 1], pull);
        gradient[k] = sub(gradient[k], apply(&back_t, pull));
    }
    // Block forward elimination of H δ = −g, keeping each pivot's inverse
    // for the back substitution.
    let pivot_inverse = |pivot: &Mat3| inverse(pivot).unwrap_or(ZERO);
    let mut inverses = Vec::with_capacity(nodes);
    let mut rhs = Vec::with_capacity(nodes);
    inverses.push(pivot_inverse(&diag[0]));
    rhs.push(gradient[0].map(|v| -v));
    for k in 1..nodes {
        let lower = transpose(&upper[k - 1]);
        let factor = mul(&lower, &inverses[k - 1]);
        inverses.push(pivot_inverse(&add(&diag[k], &scale(&mul(&factor, &upper[k - 1]), -1.0))));
        rhs.push(sub(gradient[k].map(|v| -v), apply(&factor, rhs[k - 1])));
    }
    let mut deltas = vec![[0.0; 3]; nodes];
    for k in (0..nodes).rev() {
        let known = if k + 1 < nodes { apply(&upper[k], deltas[k + 1]) } else { [0.0; 3] };
        deltas[k] = apply(&inverses[k], sub(rhs[k], known));
    }
    deltas
}

fn add3(a: [Real; 3], b: [Real; 3]) -> [Real; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use squall_core::random::standard_normal;

    /// A robot driving a wavy path, 1 m per processed scan: the truth, the
    /// odometry (2% too long, with 1 cm and 5 mrad of noise per step) and a
    /// lineage that is the truth with `jitter` metres of white error.
    fn run(steps: usize, jitter: Real) -> (Vec<Pose2>, Vec<Corrected>) {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let (mut truth, mut odometry) = (vec![Pose2::IDENTITY], vec![Pose2::IDENTITY]);
        for k in 0..steps {
            let turn = 0.3 * (k as Real * 0.15).sin();
            let step = Pose2::new(1.0, 0.0, turn);
            truth.push(truth[k].compose(&step));
            let measured = Pose2::new(
                1.02 + 0.01 * standard_normal(&mut rng),
                0.01 * standard_normal(&mut rng),
                turn + 0.005 * standard_normal(&mut rng),
            );
            odometry.push(odometry[k].compose(&measured));
        }
        let corrected = truth
            .iter()
            .zip(&odometry)
            .enumerate()
            .map(|(k, (t, o))| {
                let e = Pose2::new(
                    jitter * standard_normal(&mut rng),
                    jitter * standard_normal(&mut rng),
                    0.2 * jitter * standard_normal(&mut rng),
                );
                (k as f64, t.compose(&e), *o)
            })
            .collect();
        (truth, corrected)
    }

    /// Mean translational error of the motions over `span` steps.
    fn relation_error(truth: &[Pose2], poses: &[Corrected], span: usize) -> Real {
        let errors: Vec<Real> = (span..truth.len())
            .map(|k| {
                let estimated = poses[k].1.relative_to(&poses[k - span].1);
                let e = estimated.relative_to(&truth[k].relative_to(&truth[k - span]));
                e.x.hypot(e.y)
            })
            .collect();
        errors.iter().sum::<Real>() / errors.len() as Real
    }

    #[test]
    fn a_jittery_lineage_follows_the_odometry_locally_and_the_lineage_far() {
        let (truth, corrected) = run(400, 0.02);
        let smoothed = smooth(&corrected, Smoother::Odometry, &[]);
        assert_eq!(smoothed.len(), corrected.len());
        let (before, after) = (relation_error(&truth, &corrected, 1), relation_error(&truth, &smoothed, 1));
        assert!(after < 0.5 * before, "one step: {after} against {before}");
        // Odometry alone drifts by 2% and more; the smoothed poses stay
        // with the lineage over long spans.
        let far = relation_error(&truth, &smoothed, 100);
        assert!(far < relation_error(&truth, &corrected, 100) + 0.01, "100 steps: {far}");
        for (s, c) in smoothed.iter().zip(&corrected) {
            assert_eq!((s.0, s.2), (c.0, c.2), "stamps and odometry stay");
        }
    }

    /// The run of [`run`], but the lineage wanders: its error is a slow
    /// process (each step keeps 95% of it and adds `walk` metres, as a
    /// particle's map drifts under it and back), which the growth model
    /// takes for odometry noise; and each step is also measured, with
    /// `measurement` metres of error along x and y and a tenth of it in
    /// θ, except along x in every third step, where the measurement is
    /// blind (a corridor): its error there is 1 m and its covariance says
    /// so.
    #[allow(clippy::type_complexity)]
    fn measured_run(
        steps: usize,
        walk: Real,
        measurement: Real,
    ) -> (Vec<Pose2>, Vec<Corrected>, Vec<Option<MeasuredStep>>) {
        let (truth, mut corrected) = run(steps, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(29);
        let mut offset = [0.0; 3];
        for c in corrected.iter_mut().skip(1) {
            offset = [
                0.95 * offset[0] + walk * standard_normal(&mut rng),
                0.95 * offset[1] + walk * standard_normal(&mut rng),
                0.95 * offset[2] + 0.1 * walk * standard_normal(&mut rng),
            ];
            c.1 = c.1.compose(&Pose2::new(offset[0], offset[1], offset[2]));
        }
        let measured = truth
            .windows(2)
            .enumerate()
            .map(|(k, w)| {
                let blind = k % 3 == 1;
                let along = if blind { 1.0 } else { measurement };
                let error = Pose2::new(
                    along * standard_normal(&mut rng),
                    measurement * standard_normal(&mut rng),
                    0.1 * measurement * standard_normal(&mut rng),
                );
                let covariance = diagonal([along.powi(2), measurement.powi(2), (0.1 * measurement).powi(2)]);
                // The covariance's scale is not trusted: give it wrong by 3.
                Some(MeasuredStep {
                    motion: w[1].relative_to(&w[0]).compose(&error),
                    covariance: scale(&covariance, 9.0),
                })
            })
            .collect();
        (truth, corrected, measured)
    }

    #[test]
    fn a_third_measurement_tells_a_wandering_lineage_from_the_odometry() {
        // A lineage that walks 3 cm per step, odometry with 1 cm of noise
        // per step (and 2% scale), a measurement of 5 mm: the growth model
        // cannot tell which of lineage and odometry walks, the hat can.
        let (truth, corrected, measured) = measured_run(600, 0.03, 0.005);
        let two_way = smooth(&corrected, Smoother::Odometry, &measured);
        let three_way = smooth(&corrected, Smoother::Scans, &measured);
        for span in [1, 10] {
            let (two, three) =
                (relation_error(&truth, &two_way, span), relation_error(&truth, &three_way, span));
            assert!(three < 0.6 * two, "{span} steps: three-way {three} against two-way {two}");
        }
        // Without measurements, or too few, it is the two-way smoother.
        assert_eq!(smooth(&corrected, Smoother::Scans, &[]), two_way);
        let sparse: Vec<Option<MeasuredStep>> =
            measured.iter().enumerate().map(|(k, m)| if k < MIN_STEPS - 1 { *m } else { None }).collect();
        assert_eq!(smooth(&corrected, Smoother::Scans, &sparse), two_way);
    }

    #[test]
    fn a_blind_or_failed_measurement_does_not_pull_the_poses() {
        let (truth, corrected, measured) = measured_run(600, 0.03, 0.005);
        let clean = smooth(&corrected, Smoother::Scans, &measured);
        // Every tenth measurement fails: 5 m and 1 rad off, with the
        // covariance of a good match.
        let failed: Vec<Option<MeasuredStep>> = measured
            .iter()
            .enumerate()
            .map(|(k, m)| {
                m.map(|m| {
                    if k % 10 == 0 {
                        MeasuredStep { motion: m.motion.compose(&Pose2::new(5.0, -5.0, 1.0)), ..m }
                    } else {
                        m
                    }
                })
            })
            .collect();
        let smoothed = smooth(&corrected, Smoother::Scans, &failed);
        let (before, after) = (relation_error(&truth, &clean, 1), relation_error(&truth, &smoothed, 1));
        assert!(after < before + 0.003, "one step: {after} with failed matches, {before} without");
        // The blind steps (1 m of error along x) left x to the odometry:
        // the one-step error stays far below the blind measurement's.
        assert!(before < 0.02, "{before}");
    }

    #[test]
    fn the_noise_is_told_apart_by_how_it_grows() {
        let (_, corrected) = run(2000, 0.02);
        let lineage: Vec<Pose2> = corrected.windows(2).map(|w| w[1].1.relative_to(&w[0].1)).collect();
        let odometry: Vec<Pose2> = corrected.windows(2).map(|w| w[1].2.relative_to(&w[0].2)).collect();
        let raw: Vec<[Real; 3]> =
            lineage.iter().zip(&odometry).map(|(a, u)| vector(&a.relative_to(u))).collect();
        let systematic = fit_systematic(&odometry, &raw);
        // The lineage's steps are 2% shorter than the odometry's.
        assert!((systematic[0][0] + 0.02).abs() < 0.003, "{systematic:?}");
        let residual: Vec<[Real; 3]> =
            raw.iter().zip(&odometry).map(|(e, u)| sub(*e, apply(&systematic, vector(u)))).collect();
        let (matcher, step) = noise(&residual);
        for c in 0..2 {
            let (r, q) = (matcher[c].sqrt(), step[c].sqrt());
            assert!((r - 0.02).abs() < 0.004, "the lineage's 2 cm: {r}");
            assert!(q < 0.02, "the odometry's noise per step: {q}");
        }
    }

    #[test]
    fn an_odometry_glitch_moves_poses_by_centimetres() {
        let (truth, corrected) = run(400, 0.02);
        let clean = smooth(&corrected, Smoother::Odometry, &[]);
        for size in [0.5, 2.0, 20.0] {
            // The odometry jumps sideways at step 200, and stays jumped.
            let jump = Pose2::new(0.0, size, 0.3 * size);
            let glitched: Vec<Corrected> = corrected
                .iter()
                .enumerate()
                .map(|(k, &(t, p, o))| (t, p, if k >= 200 { jump.compose(&o) } else { o }))
                .collect();
            let smoothed = smooth(&glitched, Smoother::Odometry, &[]);
            let moved = smoothed.iter().zip(&clean).map(|(s, c)| s.1.distance(&c.1)).fold(0.0, Real::max);
            // The glitch's step inflates the odometry's noise a little and
            // bends the systematic fit a little: poses move by a
            // centimetre or two (measured: 1.2, 1.0 and 2.5 cm), within the
            // lineage's own 2 cm jitter, and the smoothing stays.
            assert!(moved < 0.03, "a {size} m glitch moved poses by {moved} m");
            let (before, after) =
                (relation_error(&truth, &corrected, 1), relation_error(&truth, &smoothed, 1));
            assert!(after < 0.5 * before, "{size} m glitch, one step: {after} against {before}");
        }
    }

    #[test]
    fn an_exact_lineage_barely_moves_and_short_ones_stay_as_they_are() {
        let (truth, corrected) = run(400, 0.0);
        let smoothed = smooth(&corrected, Smoother::Odometry, &[]);
        // Over 400 steps the noise estimate is itself uncertain and finds
        // a few millimetres of error in the lineage: the poses move by
        // that much, a fifth of a map cell at most.
        let moved: Vec<Real> = smoothed.iter().zip(&truth).map(|(s, t)| s.1.distance(t)).collect();
        let mean = moved.iter().sum::<Real>() / moved.len() as Real;
        let most = moved.iter().copied().fold(0.0, Real::max);
        assert!(mean < 0.003 && most < 0.01, "moved {mean} on average, {most} at most");
        let (_, short) = run(MIN_STEPS - 1, 0.02);
        assert_eq!(smooth(&short, Smoother::Odometry, &[]), short);
        let (_, long) = run(400, 0.02);
        assert_eq!(smooth(&long, Smoother::None, &[]), long);
    }
}
