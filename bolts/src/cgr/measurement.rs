//! The measurement model of thesis eq. 4.2 and its gradient (eq. 4.3),
//! and Corrective Gradient Refinement: each observed point is matched to
//! the wall of the observable scene that the ray from the sensor through
//! it meets first; points with no such wall, or whose normal disagrees
//! with the wall's, count as outliers; the rest contribute −d²/(2fσ²) to
//! the log-likelihood, d being the point's distance to its wall's line,
//! capped at `outlier_sigmas` σ (an outlier counts as that far off).

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use crate::cgr::observation::Observation2d;
use squall_core::geometry::{Pose2, Real};
use squall_core::linemap::LineMap;
use squall_core::visibility::first_hit;

/// Measurement and refinement settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CgrOptions {
    /// σ: standard deviation of a point's distance to its wall, metres.
    /// The default is 0.05.
    pub sigma: Real,
    /// A sensor whose error grows with range: a point r metres from the
    /// sensor has σ² + (this × r²)² as its variance, so that far points
    /// of a stereo depth camera (D435: σ(z) ≈ 0.0015 z² simulated, 0.001
    /// on real frames, 7 cm at 7 m) count as what they are, neither
    /// outliers nor as sure as near ones; the outlier cap scales with it.
    /// For use with FSPF's `noise_per_z2`, which keeps such points; with
    /// `leave_out_corners`, points at a wall's end whose normal disagrees
    /// are then left out (within 0.25 m, `BLEND_REACH`). Not yet the depth path's
    /// default (decisions 0025, 0026). 0 for a laser, whose error hardly
    /// grows within its range. The default is 0.
    pub noise_per_r2: Real,
    /// f: correlation between points (each counts 1/f). The default is 5.
    pub correlation: Real,
    /// A point is used only if its normal is within this angle of its
    /// wall's, degrees. The default is 30.
    pub normal_tolerance_deg: Real,
    /// Walls farther than this are not in the observable scene, and
    /// points farther from the sensor are left out, metres. The default
    /// is 8.
    pub range: Real,
    /// Gradient steps per particle per observation. The default is 3.
    pub refine_iterations: u32,
    /// A point farther than this many σ from its wall, or with no wall or
    /// a disagreeing normal, counts as that far off: poses that explain
    /// nothing are not better than poses that explain something badly
    /// (which matters when the particles start anywhere). The default is 3.
    pub outlier_sigmas: Real,
    /// In the test for a lost robot (augmented MCL's fit, not the
    /// weights), count the points short of the map (in front of walls:
    /// people, boxes) as fitting. For a depth camera, whose narrow view a
    /// person or a box a metre away fills; not for a 180° laser, which such
    /// things hide only in part, and whose points short of the walls it
    /// expects are how a kidnapping shows. The default is false.
    pub occlusion_fits: bool,
    /// With `occlusion_fits`, the widest thing the map leaves out that
    /// can stand in view (a person, a box, a cart), metres: where short
    /// points fill a wider stretch of the view (at their distance), they
    /// are not an obstacle but walls the map does not have there, a place
    /// other than the pose's, and every short point counts as an outlier
    /// in the test for a lost robot ([`Evaluation::widest_short_run`]).
    /// The default is 1.
    pub occluder_size: Real,
    /// Leave out, rather than count as outliers, the points whose normal
    /// disagrees with the wall their ray meets but agrees with a wall
    /// within the outlier cap of them (a corner, a jamb): see
    /// `at_corner`. For a depth camera, whose plane-filtered normals are
    /// those of the surface sampled; not for a laser, whose normals
    /// across a door's edge are neither wall's. The default is false.
    pub leave_out_corners: bool,
    /// End refinement with a Gauss–Newton step with the whole curvature,
    /// kept if the likelihood rises ([`newton_step`]), so that particles
    /// are weighed at their likelihood's peak. For a depth camera, whose
    /// thousand points make the peak a few millimetres wide; measured on
    /// the laser it let look-alike places briefly outweigh a tracked set
    /// (decision 0023). The default is false.
    pub newton_step: bool,
}

impl Default for CgrOptions {
    fn default() -> Self {
        CgrOptions {
            sigma: 0.05,
            noise_per_r2: 0.0,
            correlation: 5.0,
            normal_tolerance_deg: 30.0,
            range: 8.0,
            refine_iterations: 3,
            outlier_sigmas: 3.0,
            occlusion_fits: false,
            occluder_size: 1.0,
            leave_out_corners: false,
            newton_step: false,
        }
    }
}

impl CgrOptions {
    /// What an outlier adds to the log-likelihood: a point
    /// `outlier_sigmas` σ off, counted 1/f.
    pub fn outlier_log_likelihood(&self) -> Real {
        -0.5 * self.outlier_sigmas * self.outlier_sigmas / self.correlation
    }

    /// Checks every range; says which setting is wrong.
    pub fn check(&self) -> crate::Result<()> {
        for (name, v) in [
            ("sigma", self.sigma),
            ("correlation", self.correlation),
            ("range", self.range),
            ("outlier_sigmas", self.outlier_sigmas),
            ("occluder_size", self.occluder_size),
        ] {
            crate::error::positive(name, v)?;
        }
        crate::error::non_negative("noise_per_r2", self.noise_per_r2)?;
        if !(0.0..=90.0).contains(&self.normal_tolerance_deg) {
            let found = self.normal_tolerance_deg;
            return Err(crate::Error::OutOfRange {
                name: "normal_tolerance_deg",
                expected: "in [0, 90]",
                found,
            });
        }
        Ok(())
    }
}

/// The log-likelihood of an observation at a pose, its gradient with
/// respect to (x, y, θ), and the points that found a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluation {
    /// log p(z | x, m) up to a constant.
    pub log_likelihood: Real,
    /// ∂ log p / ∂(x, y, θ).
    pub gradient: [Real; 3],
    /// Σ over used points of the squared derivatives of d (a diagonal
    /// Gauss–Newton curvature, for step sizes), divided by fσ².
    pub curvature: [Real; 3],
    /// The off-diagonal terms of the same Gauss–Newton curvature, (x, y),
    /// (x, θ), (y, θ): with `curvature`, the whole 3 × 3 matrix. Summed
    /// only with [`CgrOptions::newton_step`], zero otherwise.
    pub cross: [Real; 3],
    /// Points used.
    pub matched: usize,
    /// Points short of the map: in front of the wall their ray meets by
    /// more than the outlier cap, or with no wall along their ray. Seen
    /// on something the map does not hold (a person, a box) in free
    /// space, they count as outliers in the likelihood; unlike a point
    /// behind a wall or facing the wrong way, they do not contradict the
    /// pose.
    pub short: usize,
    /// The nearest short point's distance from the sensor in each of
    /// [`SHORT_BINS`] sectors of bearing (robot frame), metres; infinite
    /// where none fell (and everywhere without
    /// [`CgrOptions::occlusion_fits`], which alone reads them): each run of sectors with short points is
    /// something in the way, as wide as the run's arcs.
    pub short_ranges: [f32; SHORT_BINS],
}

/// Sectors of bearing over the full turn in which short points are
/// gathered, 5.6° each: at 2 m a sector is 0.2 m across.
pub const SHORT_BINS: usize = 64;

impl Default for Evaluation {
    fn default() -> Self {
        Evaluation {
            log_likelihood: 0.0,
            gradient: [0.0; 3],
            curvature: [0.0; 3],
            cross: [0.0; 3],
            matched: 0,
            short: 0,
            short_ranges: [f32::INFINITY; SHORT_BINS],
        }
    }
}

impl Evaluation {
    /// Counts a short point `(dx, dy)` from the sensor (robot frame), and
    /// with `sectors` gathers it into [`Self::short_ranges`] (only the
    /// lost test with `occlusion_fits` reads them).
    fn add_short(&mut self, dx: Real, dy: Real, sectors: bool) {
        self.short += 1;
        if !sectors {
            return;
        }
        let turn = dy.atan2(dx) / std::f64::consts::TAU + 0.5;
        let bin = ((turn * SHORT_BINS as Real) as usize).min(SHORT_BINS - 1);
        let r = &mut self.short_ranges[bin];
        *r = r.min(dx.hypot(dy) as f32);
    }

    /// How wide the widest thing in the way is, metres: over each run of
    /// adjacent sectors holding short points (wrapping round), the sum of
    /// their arcs at the nearest short point's distance; 0 without short
    /// points. A person or a box fills a few sectors close up or one far
    /// off; the walls of another place fill the view at metres.
    pub fn widest_short_run(&self) -> Real {
        let sector = std::f64::consts::TAU / SHORT_BINS as Real;
        let arc = |k: usize| Real::from(self.short_ranges[k % SHORT_BINS]) * sector;
        let held = |k: usize| self.short_ranges[k % SHORT_BINS].is_finite();
        // Start after an empty sector, so that a run across the wrap is
        // measured whole; a full circle of short points is one run.
        let Some(start) = (0..SHORT_BINS).find(|&k| !held(k)) else {
            return (0..SHORT_BINS).map(arc).sum();
        };
        let (mut widest, mut run): (Real, Real) = (0.0, 0.0);
        for k in start + 1..=start + SHORT_BINS {
            if held(k) {
                run += arc(k);
                widest = widest.max(run);
            } else {
                run = 0.0;
            }
        }
        widest
    }
}

/// Evaluates the observation at `pose` against the walls `lines` of `map`
/// (the observable scene there).
pub fn evaluate(
    map: &LineMap,
    lines: &[u32],
    pose: &Pose2,
    obs: &Observation2d,
    o: &CgrOptions,
) -> Evaluation {
    let (s, c) = pose.theta.sin_cos();
    let sensor = (pose.x + c * obs.sensor.0 - s * obs.sensor.1, pose.y + s * obs.sensor.0 + c * obs.sensor.1);
    let (fixed_per_variance, fixed_cap) =
        (1.0 / (o.correlation * o.sigma * o.sigma), o.outlier_sigmas * o.sigma);
    let min_cos = o.normal_tolerance_deg.to_radians().cos();
    let outlier = o.outlier_log_likelihood();
    let range2 = o.range * o.range;
    let mut e = Evaluation::default();
    for (p, n) in obs.points.iter().zip(&obs.normals) {
        let (px, py) = (Real::from(p[0]), Real::from(p[1]));
        let r2 = (px - obs.sensor.0).powi(2) + (py - obs.sensor.1).powi(2);
        if r2 > range2 {
            // Beyond the observable scene, which holds the walls within
            // `range`: nothing to match the point to, and no sign either
            // way (a depth camera's 8 m of depth reach 9.7 m at the edges
            // of its 69° view; a laser's points are cut at its range).
            continue;
        }
        let (per_variance, cap) = if o.noise_per_r2 > 0.0 {
            let ranged = o.noise_per_r2 * r2;
            let variance = o.sigma * o.sigma + ranged * ranged;
            (1.0 / (o.correlation * variance), o.outlier_sigmas * variance.sqrt())
        } else {
            (fixed_per_variance, fixed_cap)
        };
        let q = (pose.x + c * px - s * py, pose.y + s * px + c * py);
        let Some((line, _)) = first_hit(map, lines.iter().copied(), sensor, q) else {
            // Nothing on the map along the ray: the point is on something
            // the map does not hold, in free space.
            e.log_likelihood += outlier;
            e.add_short(px - obs.sensor.0, py - obs.sensor.1, o.occlusion_fits);
            continue;
        };
        let w = &map.walls[line as usize];
        let (lx, ly) = unit_normal(w);
        let (nx, ny) = (Real::from(n[0]), Real::from(n[1]));
        let (wx, wy) = (c * nx - s * ny, s * nx + c * ny);
        let d = lx * (q.0 - w.a.0) + ly * (q.1 - w.a.1);
        if d.abs() > cap {
            e.log_likelihood += outlier;
            // On the sensor's side of the wall the ray meets: in front of it.
            let sensor_side = lx * (sensor.0 - w.a.0) + ly * (sensor.1 - w.a.1);
            if d * sensor_side > 0.0 {
                e.add_short(px - obs.sensor.0, py - obs.sensor.1, o.occlusion_fits);
            }
            continue;
        }
        if (lx * wx + ly * wy).abs() < min_cos {
            // At a corner the point tells nothing either way; elsewhere it
            // faces the wrong way for this pose.
            let blended = o.noise_per_r2 > 0.0 && near_an_end(w, q, BLEND_REACH);
            if !(o.leave_out_corners && (blended || at_corner(map, lines, q, (wx, wy), min_cos, cap))) {
                e.log_likelihood += outlier;
            }
            continue;
        }
        // ∂q/∂θ = R'(θ) p.
        let (dqx, dqy) = (-s * px - c * py, c * px - s * py);
        let dd = [lx, ly, lx * dqx + ly * dqy];
        e.log_likelihood -= 0.5 * d * d * per_variance;
        for (k, dk) in dd.into_iter().enumerate() {
            e.gradient[k] -= d * dk * per_variance;
            e.curvature[k] += dk * dk * per_variance;
        }
        // Only the Newton step reads the off-diagonal terms.
        if o.newton_step {
            e.cross[0] += dd[0] * dd[1] * per_variance;
            e.cross[1] += dd[0] * dd[2] * per_variance;
            e.cross[2] += dd[1] * dd[2] * per_variance;
        }
        e.matched += 1;
    }
    e
}

/// With a range-dependent noise (`noise_per_r2`, for the far points that
/// FSPF's `noise_per_z2` keeps), how near the end of the wall its ray
/// meets a point whose normal disagrees is left out with
/// `leave_out_corners`, metres. An FSPF neighbourhood is 0.5 m across
/// (`plane_size`): within half of that of a corner or a door's jamb it
/// may span both faces, and at the tolerance far walls need (16 cm at
/// 6 m) it passes as one plane whose normal is a blend of the two, which
/// no wall of the map has. Counted as outliers, such points cost the true
/// pose (CVAP6 seed 4: 121 points of a jamb 6–8 m away, −107 in one
/// frame; decision 0026).
const BLEND_REACH: Real = 0.25;

/// Whether `q` lies within `reach` of either end of `w`.
fn near_an_end(w: &squall_core::linemap::Segment, q: (Real, Real), reach: Real) -> bool {
    [w.a, w.b].iter().any(|end| (q.0 - end.0).hypot(q.1 - end.1) <= reach)
}

/// A wall's unit normal (its direction turned left).
fn unit_normal(w: &squall_core::linemap::Segment) -> (Real, Real) {
    let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
    let len = (ex * ex + ey * ey).sqrt();
    (-ey / len, ex / len)
}

/// Whether a point `q`, on the wall its ray meets but facing along it
/// (world normal `normal`), lies within `cap` of a wall among `lines`
/// whose direction its normal agrees with: a corner, or a wall's end
/// where a jamb or a pillar turns. The point lies on both walls; the ray
/// meets one, the surface it was sampled from may be the other, and a
/// normal estimated across the edge may be neither's. Such a point is
/// left out, as the thesis leaves out every point whose normal disagrees
/// (§4.2.1): counted as an outlier, every corner in view would cost the
/// true pose what a blank wall does not cost a wrong one, while corners
/// are what tell places apart; matched to the other wall, a laser's
/// normals across a door's edge pinned the pose to the jamb (decision
/// 0023).
fn at_corner(
    map: &LineMap,
    lines: &[u32],
    q: (Real, Real),
    normal: (Real, Real),
    min_cos: Real,
    cap: Real,
) -> bool {
    lines.iter().any(|&id| {
        let w = &map.walls[id as usize];
        let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
        let len2 = ex * ex + ey * ey;
        if len2 <= 0.0 {
            return false;
        }
        let (lx, ly) = unit_normal(w);
        if (lx * normal.0 + ly * normal.1).abs() < min_cos {
            return false;
        }
        let t = (((q.0 - w.a.0) * ex + (q.1 - w.a.1) * ey) / len2).clamp(0.0, 1.0);
        (q.0 - w.a.0 - t * ex).hypot(q.1 - w.a.1 - t * ey) <= cap
    })
}

/// The Gauss–Newton step to the likelihood's peak from the pose `e` was
/// taken at (evaluated with [`CgrOptions::newton_step`], so that `e`
/// holds the whole curvature), H⁻¹g with its translation damped and the
/// step cut to [`MAX_STEP`] as refinement's steps are; `None` when it
/// would raise the log-likelihood by less than [`MIN_NEWTON_RISE`] (the
/// pose is at its peak) or the curvature is singular.
pub fn newton_step(e: &Evaluation) -> Option<[Real; 3]> {
    let [a, d, f] = e.curvature;
    let [b, c, g] = e.cross;
    // Translation damped as refinement's steps are: a view of one wall
    // leaves the pose all but free along it, and an undamped step there
    // follows the noise up to the largest step (a tracked set slid 0.26 m
    // along a wall, CVAP7 seed 8; decision 0023). A tiny ridge keeps
    // heading-only views solvable.
    let damping = TRANSLATION_DAMPING * (a + d);
    let ridge = 1e-9 * (a + d + f) + Real::MIN_POSITIVE;
    let h = [[a + damping + ridge, b, c], [b, d + damping + ridge, g], [c, g, f + ridge]];
    let step = solve3(&h, &e.gradient)?;
    let rise: Real = step.iter().zip(&e.gradient).map(|(s, g)| s * g).sum();
    if !(rise.is_finite() && 0.5 * rise >= MIN_NEWTON_RISE) {
        return None;
    }
    let scale = (MAX_STEP.0 / step[0].hypot(step[1])).min(MAX_STEP.1 / step[2].abs()).min(1.0);
    Some(step.map(|s| s * scale))
}

/// A Newton step predicted to raise the log-likelihood by less than this
/// is not taken (nor evaluated).
const MIN_NEWTON_RISE: Real = 0.01;

/// x with h x = b for a symmetric positive definite `h` (Cholesky);
/// `None` when `h` is not.
fn solve3(h: &[[Real; 3]; 3], b: &[Real; 3]) -> Option<[Real; 3]> {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let sum: Real = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let v = h[i][i] - sum;
                if v.is_nan() || v <= 0.0 {
                    return None;
                }
                l[i][i] = v.sqrt();
            } else {
                l[i][j] = (h[i][j] - sum) / l[j][j];
            }
        }
    }
    let mut y = [0.0; 3];
    for i in 0..3 {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<Real>()) / l[i][i];
    }
    let mut x = [0.0; 3];
    for i in (0..3).rev() {
        x[i] = (y[i] - (i + 1..3).map(|k| l[k][i] * x[k]).sum::<Real>()) / l[i][i];
    }
    Some(x)
}

/// The largest move of one refinement step: metres, radians.
const MAX_STEP: (Real, Real) = (0.2, 0.1);
/// The damping of each translation axis, as a share of the two axes'
/// summed curvature.
const TRANSLATION_DAMPING: Real = 0.1;

/// Corrective Gradient Refinement of one pose: up to `refine_iterations`
/// steps along the gradient, each scaled by the inverse diagonal
/// curvature (translation damped), kept within [`MAX_STEP`], and halved until the likelihood
/// rises (walls re-matched at every step). Returns the refined pose, its
/// evaluation and the evaluations spent.
pub fn refine<'a>(
    map: &LineMap,
    lines_at: &mut impl FnMut(&Pose2) -> Cow<'a, [u32]>,
    pose: &Pose2,
    obs: &Observation2d,
    o: &CgrOptions,
) -> (Pose2, Evaluation, u32) {
    let mut lines = lines_at(pose);
    let mut best = (*pose, evaluate(map, &lines, pose, obs, o));
    let mut evaluations = 1;
    for _ in 0..o.refine_iterations {
        let (p, e) = best;
        if e.matched == 0 {
            break;
        }
        // Along a direction the points hardly constrain (down a corridor,
        // seen by a narrow camera) the diagonal Gauss–Newton step divides
        // by almost nothing, and a likelihood that is flat there accepts
        // it: the particles would wander along the corridor. The
        // translation axes are damped by a share of their summed
        // curvature (Levenberg–Marquardt), and every step stays within a
        // trust region.
        let damping = TRANSLATION_DAMPING * (e.curvature[0] + e.curvature[1]);
        let step: [Real; 3] = std::array::from_fn(|k| {
            let c = e.curvature[k] + if k < 2 { damping } else { 0.0 };
            if c > 0.0 { e.gradient[k] / c } else { 0.0 }
        });
        let translation = step[0].hypot(step[1]);
        let mut scale = (MAX_STEP.0 / translation).min(MAX_STEP.1 / step[2].abs()).min(1.0);
        let mut improved = false;
        for _ in 0..4 {
            let candidate =
                Pose2::new(p.x + scale * step[0], p.y + scale * step[1], p.theta + scale * step[2]);
            lines = lines_at(&candidate);
            let ce = evaluate(map, &lines, &candidate, obs, o);
            evaluations += 1;
            if ce.matched > 0 && ce.log_likelihood > e.log_likelihood {
                best = (candidate, ce);
                improved = true;
                break;
            }
            scale *= 0.5;
        }
        if !improved {
            break;
        }
    }
    // A last Gauss–Newton step with the whole curvature, kept if the
    // likelihood rises: the damped diagonal steps stop a centimetre or
    // two short of the peak, and with a depth frame's thousand points
    // the likelihood is so sharp there that those centimetres cost more
    // than being at the wrong place, so weights taken there would rank
    // particles by how close their last step came, not by where they
    // are (docs/decisions/0023).
    if let Some(step) = newton_step(&best.1).filter(|_| o.newton_step && best.1.matched > 0) {
        let p = best.0;
        let candidate = Pose2::new(p.x + step[0], p.y + step[1], p.theta + step[2]);
        let lines = lines_at(&candidate);
        let ce = evaluate(map, &lines, &candidate, obs, o);
        evaluations += 1;
        if ce.matched > 0 && ce.log_likelihood > best.1.log_likelihood {
            best = (candidate, ce);
        }
    }
    (best.0, best.1, evaluations)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use squall_core::depth_render::{Clutter, DepthCamera, Person, Props};
    use squall_core::visibility::observable_scene;

    use crate::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};

    fn room() -> LineMap {
        LineMap::parse("room", "0,0,10,0\n10,0,10,10\n10,10,0,10\n0,10,0,0\n4,6,6,6\n6,6,6,7\n").unwrap()
    }

    /// What a perfect 360° laser sees from `truth`, as an observation.
    fn observe(map: &LineMap, truth: &Pose2) -> Observation2d {
        let mut o = Observation2d::default();
        for i in 0..360 {
            let a = (i as Real).to_radians();
            let Some(r) = map.cast((truth.x, truth.y), truth.theta + a, 8.0) else { continue };
            let (px, py) = (r * a.cos(), r * a.sin());
            // The wall's normal, in the robot frame, facing the sensor.
            let (line, _) = first_hit(
                map,
                0..map.walls.len() as u32,
                (truth.x, truth.y),
                (truth.x + r * (truth.theta + a).cos(), truth.y + r * (truth.theta + a).sin()),
            )
            .unwrap();
            let w = &map.walls[line as usize];
            let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
            let len = ex.hypot(ey);
            let (mut nx, mut ny) = (-ey / len, ex / len);
            let (s, c) = (-truth.theta).sin_cos();
            (nx, ny) = (c * nx - s * ny, s * nx + c * ny);
            if nx * px + ny * py > 0.0 {
                (nx, ny) = (-nx, -ny);
            }
            o.points.push([px as f32, py as f32]);
            o.normals.push([nx as f32, ny as f32]);
        }
        o
    }

    fn scene_ids(map: &LineMap, p: &Pose2) -> Vec<u32> {
        let mut ids: Vec<u32> = observable_scene(map, (p.x, p.y), 8.0).iter().map(|v| v.line).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    #[test]
    fn things_in_the_way_are_measured_one_by_one_across_the_view() {
        let mut e = Evaluation::default();
        assert_eq!(e.widest_short_run(), 0.0);
        // A person 0.5 m across at 2 m, 30° left, and a box 0.4 m across
        // at 1 m, 30° right: two things, each narrow.
        let along = |e: &mut Evaluation, bearing_deg: Real, range: Real, width: Real| {
            let b = bearing_deg.to_radians();
            for k in 0..=20 {
                let t = width * (k as Real / 20.0 - 0.5);
                e.add_short(range * b.cos() - t * b.sin(), range * b.sin() + t * b.cos(), true);
            }
        };
        along(&mut e, 30.0, 2.0, 0.5);
        along(&mut e, -30.0, 1.0, 0.4);
        let w = e.widest_short_run();
        assert!((0.4..=0.8).contains(&w), "{w}");
        // A wall 4 m across at 3 m: another place's.
        along(&mut e, 0.0, 3.0, 4.0);
        let w = e.widest_short_run();
        assert!(w > 3.0, "{w}");
        // Behind the sensor, across the bearing where sectors wrap round:
        // one thing, measured whole.
        let mut behind = Evaluation::default();
        along(&mut behind, 180.0, 2.0, 0.9);
        let w = behind.widest_short_run();
        assert!((0.8..=1.3).contains(&w), "{w}");
    }

    #[test]
    fn points_in_front_of_their_wall_or_with_none_along_the_ray_are_short_and_points_behind_it_are_not() {
        let map = room();
        let truth = Pose2::new(3.0, 3.0, 0.4);
        let o = CgrOptions::default();
        let ids = scene_ids(&map, &truth);
        let clean = evaluate(&map, &ids, &truth, &observe(&map, &truth), &o);
        assert_eq!(clean.short, 0, "{clean:?}");
        // Points seen head-on (so that a move along the ray moves them off
        // the wall's line too), alternately pulled halfway to the sensor
        // (something unmapped in the way) and pushed 0.5 m past their wall
        // (what a wrong pose sees).
        let mut obs = observe(&map, &truth);
        let head_on: Vec<usize> = (0..obs.points.len())
            .filter(|&k| {
                let (p, n) = (obs.points[k], obs.normals[k]);
                let r = p[0].hypot(p[1]);
                // Pushed, still within range (beyond it a point is left out).
                r > 1.0 && r < o.range as f32 - 0.5 && (p[0] * n[0] + p[1] * n[1]).abs() / r > 0.7
            })
            .step_by(5)
            .collect();
        let (mut pulled, mut pushed) = (0, 0);
        for (i, &k) in head_on.iter().enumerate() {
            let p = obs.points[k];
            let scale = if i % 2 == 0 { 0.5 } else { 1.0 + 0.5 / p[0].hypot(p[1]) };
            obs.points[k] = [p[0] * scale, p[1] * scale];
            if i % 2 == 0 { pulled += 1 } else { pushed += 1 }
        }
        assert!(pulled > 10 && pushed > 10, "{pulled} pulled, {pushed} pushed");
        let e = evaluate(&map, &ids, &truth, &obs, &o);
        assert_eq!(e.short, pulled, "{e:?}");
        assert_eq!(e.matched, obs.points.len() - pulled - pushed, "{e:?}");
        let expected = (pulled + pushed) as Real * o.outlier_log_likelihood();
        assert!((e.log_likelihood - expected).abs() < 1e-6, "{} vs {expected}", e.log_likelihood);
        // A point with no wall along its ray is short too.
        let wall = LineMap::parse("wall", "2,-1,2,1\n").unwrap();
        let obs = Observation2d {
            points: vec![[2.0, 0.0], [1.0, 3.0]],
            normals: vec![[-1.0, 0.0], [-1.0, 0.0]],
            ..Observation2d::default()
        };
        let e = evaluate(&wall, &[0], &Pose2::IDENTITY, &obs, &o);
        assert_eq!((e.matched, e.short), (1, 1), "{e:?}");
    }

    #[test]
    fn the_true_pose_is_a_maximum_and_the_gradient_matches_finite_differences() {
        let map = room();
        let truth = Pose2::new(3.0, 3.0, 0.4);
        let obs = observe(&map, &truth);
        let o = CgrOptions::default();
        let at_truth = evaluate(&map, &scene_ids(&map, &truth), &truth, &obs, &o);
        assert!(at_truth.matched > 300 && at_truth.log_likelihood > -1e-6, "{at_truth:?}");
        let off = Pose2::new(3.04, 2.97, 0.41);
        let lines = scene_ids(&map, &off);
        let e = evaluate(&map, &lines, &off, &obs, &o);
        assert!(e.log_likelihood < at_truth.log_likelihood - 1.0);
        let h = 1e-6;
        for k in 0..3 {
            let mut q = [off.x, off.y, off.theta];
            q[k] += h;
            let plus = evaluate(&map, &lines, &Pose2::new(q[0], q[1], q[2]), &obs, &o).log_likelihood;
            q[k] -= 2.0 * h;
            let minus = evaluate(&map, &lines, &Pose2::new(q[0], q[1], q[2]), &obs, &o).log_likelihood;
            let numeric = (plus - minus) / (2.0 * h);
            assert!(
                (numeric - e.gradient[k]).abs() <= 1e-4 * numeric.abs().max(1.0),
                "component {k}: analytic {} vs numeric {numeric}",
                e.gradient[k]
            );
        }
    }

    #[test]
    fn refinement_pulls_a_pose_back_to_the_truth() {
        let map = room();
        let truth = Pose2::new(3.0, 3.0, 0.4);
        let obs = observe(&map, &truth);
        let o = CgrOptions { refine_iterations: 10, ..CgrOptions::default() };
        let start = Pose2::new(3.08, 2.93, 0.43);
        let (refined, e, evaluations) =
            refine(&map, &mut |p| Cow::Owned(scene_ids(&map, p)), &start, &obs, &o);
        assert!(evaluations > 1 && e.matched > 300);
        assert!(refined.distance(&truth) < 0.005, "{refined:?}");
        assert!((refined.theta - truth.theta).abs() < 0.002, "{refined:?}");
    }

    #[test]
    fn fspf_on_a_rendered_frame_finds_walls_that_match_the_map_at_the_true_pose() {
        // A small room: its walls within 3.5 m, where the noise (σ = 0.0015
        // z²) stays under FSPF's 2 cm tolerance.
        let map = LineMap::parse("small", "0,0,5,0\n5,0,5,4\n5,4,0,4\n0,4,0,0\n").unwrap();
        let camera = DepthCamera::d435_on_robot();
        let truth = Pose2::new(1.8, 1.6, 0.4);
        let clutter = [Clutter { min: (3.4, 2.2), max: (3.8, 2.6), height: 0.7 }];
        let people = [Person { centre: (3.0, 3.0), radius: 0.25, height: 1.7 }];
        let props = Props { boxes: &clutter, people: &people };
        let image = camera.render(&map, props, &truth, &mut ChaCha8Rng::seed_from_u64(2));
        let mut filter = PlaneFilter::new(FspfOptions::default(), camera.intrinsics);
        let mut planes = PlaneFiltered::default();
        let lines: Vec<u32> = (0..map.walls.len() as u32).collect();
        let o = CgrOptions::default();
        let world = |p: &[f32; 2]| truth.compose(&Pose2::new(f64::from(p[0]), f64::from(p[1]), 0.0));
        let on_person = |w: &Pose2| (w.x - 3.0).hypot(w.y - 3.0) < 0.4;
        let on_box = |w: &Pose2| (3.3..3.9).contains(&w.x) && (2.1..2.7).contains(&w.y);
        // The person is a small part of the frame: FSPF keeps a
        // neighbourhood of them in some runs only, so the counts are over
        // several.
        let (mut points, mut people_points, mut clutter_points, mut matched) = (0, 0, 0, 0);
        for seed in 0..8 {
            filter.filter(&image, &mut ChaCha8Rng::seed_from_u64(seed), &mut planes);
            let obs = Observation2d::from_plane_filtered(&planes, &camera.mount, 0.5, 0.0, truth);
            assert!(obs.points.len() > 200, "{} wall points", obs.points.len());
            let at_truth = evaluate(&map, &lines, &truth, &obs, &o);
            let off = evaluate(&map, &lines, &Pose2::new(2.2, 2.4, 0.45), &obs, &o);
            assert!(at_truth.log_likelihood > off.log_likelihood + 10.0, "{at_truth:?} vs {off:?}");
            points += obs.points.len();
            people_points += obs.points.iter().map(world).filter(on_person).count();
            clutter_points += obs.points.iter().map(world).filter(|w| on_person(w) || on_box(w)).count();
            matched += at_truth.matched;
        }
        // The person's and the box's points match no wall; the walls' do.
        assert!(people_points > 20, "{people_points} points on the person");
        let wall_points = points - clutter_points;
        assert!(matched * 10 > wall_points * 8, "{matched} of {wall_points} matched");
        assert!(matched <= wall_points + clutter_points / 10, "{matched} matched");
    }

    #[test]
    fn a_range_dependent_noise_weighs_far_points_by_their_error() {
        // One wall along x = 7; the sensor at the origin looking along +x.
        let map = LineMap::parse("wall", "7,-5,7,5\n").unwrap();
        let lines = [0];
        let at = |x: f32| Observation2d {
            points: vec![[x, 0.0]],
            normals: vec![[-1.0, 0.0]],
            ..Observation2d::default()
        };
        let fixed = CgrOptions::default();
        let ranged = CgrOptions { noise_per_r2: 0.0015, ..CgrOptions::default() };
        // 20 cm behind the wall: beyond the 3σ cap of a fixed σ = 5 cm, an
        // outlier; within it once the camera's 8 cm at 7.2 m is added.
        let far = at(7.2);
        let e = evaluate(&map, &lines, &Pose2::IDENTITY, &far, &fixed);
        assert_eq!((e.matched, e.log_likelihood), (0, fixed.outlier_log_likelihood()));
        let e = evaluate(&map, &lines, &Pose2::IDENTITY, &far, &ranged);
        let variance = 0.05f64.powi(2) + (0.0015f64 * 7.2 * 7.2).powi(2);
        let expected = -0.5 * 0.2f64.powi(2) / (5.0 * variance);
        assert_eq!(e.matched, 1);
        assert!((e.log_likelihood - expected).abs() < 1e-6, "{} vs {expected}", e.log_likelihood);
        // Near the sensor the added noise is nothing: the same as fixed.
        let near_map = LineMap::parse("near", "1,-5,1,5\n").unwrap();
        let near = at(1.05);
        let a = evaluate(&near_map, &lines, &Pose2::IDENTITY, &near, &fixed).log_likelihood;
        let b = evaluate(&near_map, &lines, &Pose2::IDENTITY, &near, &ranged).log_likelihood;
        assert!((a - b).abs() < 0.01 * a.abs(), "{a} vs {b}");
        assert!(ranged.check().is_ok());
        assert!(CgrOptions { noise_per_r2: -1.0, ..ranged }.check().is_err());
        // Beyond `range` (8 m) a point is left out: neither matched nor an
        // outlier, nor short.
        let beyond_map = LineMap::parse("beyond", "9,-5,9,5\n").unwrap();
        for o in [&fixed, &ranged] {
            let e = evaluate(&beyond_map, &lines, &Pose2::IDENTITY, &at(9.3), o);
            assert_eq!((e.matched, e.log_likelihood, e.short), (0, 0.0, 0));
        }
    }

    #[test]
    fn a_point_at_a_corner_facing_the_other_wall_is_left_out_not_an_outlier() {
        let map = room();
        let robot = Pose2::new(5.0, 3.0, 0.0);
        let o = CgrOptions { leave_out_corners: true, ..CgrOptions::default() };
        let one = |point: [f32; 2], normal: [f32; 2], o: &CgrOptions| {
            let obs =
                Observation2d { points: vec![point], normals: vec![normal], ..Observation2d::default() };
            evaluate(&map, &scene_ids(&map, &robot), &robot, &obs, o)
        };
        // At (9.99, 0.02), 2 cm above the south wall and 1 cm short of the
        // east one: the ray meets the east wall first, the point was
        // sampled from the south wall (its normal faces north).
        let corner = one([4.99, -2.98], [0.0, 1.0], &o);
        assert_eq!((corner.matched, corner.log_likelihood), (0, 0.0), "left out: {corner:?}");
        // Without the setting, an outlier.
        let strict = one([4.99, -2.98], [0.0, 1.0], &CgrOptions::default());
        assert_eq!(strict.log_likelihood, o.outlier_log_likelihood(), "{strict:?}");
        // Mid-wall, the same normal has no wall near to agree with.
        let mid = one([5.0, -1.5], [0.0, 1.0], &o);
        assert_eq!((mid.matched, mid.log_likelihood), (0, o.outlier_log_likelihood()), "{mid:?}");
    }

    #[test]
    fn a_far_patchs_blended_normal_near_a_wall_end_is_left_out_only_with_the_noise_law() {
        // A wall along y = 0 from x = 0 to 4, seen from (2, 3): a point on
        // it 0.1 m from its end, and one at its middle, both with a normal
        // 45° off the wall's (a patch across a jamb, or a wrong pose).
        let wall = LineMap::parse("wall", "0,0,4,0\n").unwrap();
        let pose = Pose2::new(2.0, 3.0, 0.0);
        let tilted = [std::f32::consts::FRAC_1_SQRT_2, std::f32::consts::FRAC_1_SQRT_2];
        let seen = |x: f32| Observation2d {
            points: vec![[x - 2.0, -3.0]],
            normals: vec![tilted],
            ..Observation2d::default()
        };
        let depth = CgrOptions { leave_out_corners: true, noise_per_r2: 0.0015, ..CgrOptions::default() };
        let outlier = depth.outlier_log_likelihood();
        let ll = |x: f32, o: &CgrOptions| evaluate(&wall, &[0], &pose, &seen(x), o).log_likelihood;
        assert_eq!(ll(0.1, &depth), 0.0, "near the end: left out");
        assert!((ll(2.0, &depth) - outlier).abs() < 1e-12, "mid-wall: an outlier");
        // Without the noise law (no far patches) or without leaving out
        // corners, it is an outlier wherever it lies.
        let fixed = CgrOptions { noise_per_r2: 0.0, ..depth.clone() };
        assert!((ll(0.1, &fixed) - outlier).abs() < 1e-12);
        let counted = CgrOptions { leave_out_corners: false, ..depth };
        assert!((ll(0.1, &counted) - outlier).abs() < 1e-12);
    }

    #[test]
    fn refinement_ends_at_the_peak_a_near_pose_falls_short_of() {
        // The room without its box: nothing hides anything.
        let map = LineMap::parse("square", "0,0,10,0\n10,0,10,10\n10,10,0,10\n0,10,0,0\n").unwrap();
        let truth = Pose2::new(3.0, 3.0, 0.4);
        let obs = observe(&map, &truth);
        let o = CgrOptions { newton_step: true, ..CgrOptions::default() };
        let at = |p: &Pose2| evaluate(&map, &scene_ids(&map, p), p, &obs, &o);
        let peak = at(&truth);
        assert!(newton_step(&peak).is_none(), "at the peak: no step");
        let mut lines_at = |p: &Pose2| Cow::Owned(scene_ids(&map, p));
        for near in [Pose2::new(3.03, 2.98, 0.4), Pose2::new(2.98, 3.03, 0.41), Pose2::new(3.0, 3.0, 0.42)] {
            let short = peak.log_likelihood - at(&near).log_likelihood;
            assert!(short > 3.0, "{near:?} is {short} below the peak");
            // Without the setting and without damped steps, nothing moves.
            let none = CgrOptions { refine_iterations: 0, newton_step: false, ..o.clone() };
            assert_eq!(refine(&map, &mut lines_at, &near, &obs, &none).0, near);
            // The Newton step alone (no damped steps) closes most of the
            // gap; its translation damped, not all of it.
            let alone = CgrOptions { refine_iterations: 0, ..o.clone() };
            let (pose, e, evaluations) = refine(&map, &mut lines_at, &near, &obs, &alone);
            assert_eq!(evaluations, 2);
            let (gap, left) = (near.distance(&truth), pose.distance(&truth));
            assert!(left <= 0.25 * gap + 1e-3, "{pose:?}");
            assert!(
                peak.log_likelihood - e.log_likelihood < 0.25 * short,
                "{short}: {} vs {}",
                e.log_likelihood,
                peak.log_likelihood
            );
        }
        // Far off, the step is cut to refinement's largest.
        let far = at(&Pose2::new(3.6, 3.1, 0.4));
        let step = newton_step(&far).expect("far below the peak");
        assert!(
            step[0].hypot(step[1]) <= MAX_STEP.0 + 1e-12 && step[2].abs() <= MAX_STEP.1 + 1e-12,
            "{step:?}"
        );
    }
}
