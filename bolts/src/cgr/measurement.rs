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
    /// f: correlation between points (each counts 1/f). The default is 5.
    pub correlation: Real,
    /// A point is used only if its normal is within this angle of its
    /// wall's, degrees. The default is 30.
    pub normal_tolerance_deg: Real,
    /// Walls farther than this are not in the observable scene, metres.
    /// The default is 8.
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
}

impl Default for CgrOptions {
    fn default() -> Self {
        CgrOptions {
            sigma: 0.05,
            correlation: 5.0,
            normal_tolerance_deg: 30.0,
            range: 8.0,
            refine_iterations: 3,
            outlier_sigmas: 3.0,
            occlusion_fits: false,
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
        ] {
            crate::error::positive(name, v)?;
        }
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
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Evaluation {
    /// log p(z | x, m) up to a constant.
    pub log_likelihood: Real,
    /// ∂ log p / ∂(x, y, θ).
    pub gradient: [Real; 3],
    /// Σ over used points of the squared derivatives of d (a diagonal
    /// Gauss–Newton curvature, for step sizes), divided by fσ².
    pub curvature: [Real; 3],
    /// Points used.
    pub matched: usize,
    /// Points short of the map: in front of the wall their ray meets by
    /// more than the outlier cap, or with no wall along their ray. Seen
    /// on something the map does not hold (a person, a box) in free
    /// space, they count as outliers in the likelihood; unlike a point
    /// behind a wall or facing the wrong way, they do not contradict the
    /// pose.
    pub short: usize,
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
    let per_variance = 1.0 / (o.correlation * o.sigma * o.sigma);
    let min_cos = o.normal_tolerance_deg.to_radians().cos();
    let cap = o.outlier_sigmas * o.sigma;
    let outlier = o.outlier_log_likelihood();
    let mut e = Evaluation::default();
    for (p, n) in obs.points.iter().zip(&obs.normals) {
        let (px, py) = (Real::from(p[0]), Real::from(p[1]));
        let q = (pose.x + c * px - s * py, pose.y + s * px + c * py);
        let Some((line, _)) = first_hit(map, lines.iter().copied(), sensor, q) else {
            // Nothing on the map along the ray: the point is on something
            // the map does not hold, in free space.
            e.log_likelihood += outlier;
            e.short += 1;
            continue;
        };
        let w = &map.walls[line as usize];
        let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
        let len = (ex * ex + ey * ey).sqrt();
        let (lx, ly) = (-ey / len, ex / len);
        let (nx, ny) = (Real::from(n[0]), Real::from(n[1]));
        let (wx, wy) = (c * nx - s * ny, s * nx + c * ny);
        let d = lx * (q.0 - w.a.0) + ly * (q.1 - w.a.1);
        if d.abs() > cap {
            e.log_likelihood += outlier;
            // On the sensor's side of the wall the ray meets: in front of it.
            let sensor_side = lx * (sensor.0 - w.a.0) + ly * (sensor.1 - w.a.1);
            e.short += usize::from(d * sensor_side > 0.0);
            continue;
        }
        if (lx * wx + ly * wy).abs() < min_cos {
            e.log_likelihood += outlier;
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
        e.matched += 1;
    }
    e
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
                r > 1.0 && (p[0] * n[0] + p[1] * n[1]).abs() / r > 0.7
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
}
