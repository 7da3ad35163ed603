//! Localization on a line map as a [`ParticleModel`]: the odometry motion
//! model predicts, Corrective Gradient Refinement moves each particle up
//! the measurement likelihood, the likelihood at the refined pose weighs
//! it. The observable scene comes from a precomputed grid when there is
//! one, else it is ray cast on demand. Where the robot cannot be (outside
//! the building, within a thick wall: [`Interior`]) no pose is proposed; a
//! particle that moves there is drawn again where the reading supports,
//! and one that stays there weighs nothing beside those inside.

use std::borrow::Cow;
use std::sync::Arc;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::cgr::measurement::{CgrOptions, Evaluation, refine};
use crate::cgr::observation::Observation2d;
use crate::cgr::scene_grid::SceneGrid;
use crate::pf::kld::Kld;
use crate::pf::model::{Correction, Injection, ParticleModel};
use crate::pf::resample::Scheme;
use crate::slam::model::OdometryStep;
use squall_core::geometry::{Pose2, Real};
use squall_core::interior::{DEFAULT_OPENING, Interior};
use squall_core::linemap::LineMap;
use squall_core::motion::{MotionNoise, sample_motion};
use squall_core::visibility::observable_scene;

/// Where the particles start.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// Tracking: every particle at this pose.
    Known(Pose2),
    /// Global localization: poses the first reading supports (one of its
    /// points on a wall; see `CgrModel::propose`), uniform over the
    /// building's inside (the map's bounding box without one) where no
    /// such pose is found.
    Global,
}

/// Localization settings.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizeOptions {
    /// Particles at the start: with `min_particles` fewer, the most
    /// KLD-sampling keeps.
    pub particles: usize,
    /// The fewest particles KLD-sampling keeps once the set has found the
    /// robot; equal to `particles`, the set keeps its size.
    pub min_particles: usize,
    /// Measurement and refinement.
    pub cgr: CgrOptions,
    /// Motion noise.
    pub motion: MotionNoise,
    /// Where the particles start.
    pub init: Init,
    /// How the new set is drawn.
    pub resampling: Scheme,
    /// Resample below this fraction of N (Neff).
    pub resample_threshold: Real,
    /// Random particles injected when observations stop fitting (augmented
    /// MCL, meant for recovery from kidnapping); `None`, the default, turns
    /// it off. Not yet shown to recover a kidnapped robot here.
    pub injection: Option<Injection>,
    /// Keep the particles inside the building, closing gaps in its outline
    /// narrower than this many metres (see [`Interior`]); `None` lets them
    /// anywhere.
    pub inside_opening: Option<Real>,
}

impl Default for LocalizeOptions {
    fn default() -> Self {
        LocalizeOptions {
            particles: 50,
            min_particles: 50,
            cgr: CgrOptions::default(),
            motion: MotionNoise { srr: 0.1, srt: 0.2, str: 0.1, stt: 0.2 },
            init: Init::Global,
            resampling: Scheme::LowVariance,
            resample_threshold: 0.5,
            injection: None,
            inside_opening: Some(DEFAULT_OPENING),
        }
    }
}

/// The model: the map, its precomputed scenes if any, the settings.
#[derive(Debug, Clone)]
pub struct CgrModel {
    map: Arc<LineMap>,
    scenes: Option<Arc<SceneGrid>>,
    options: LocalizeOptions,
    /// Running total of wall lengths, wall by wall (for drawing a wall
    /// in proportion to its length).
    wall_lengths: Vec<Real>,
    /// Each wall as an oriented line (`None` for a zero-length one), for
    /// proposals, which test every wall.
    lines: Vec<Option<Line>>,
    /// Where the robot can be; `None` where not asked for, or where the
    /// map encloses nothing (an open site).
    interior: Option<Arc<Interior>>,
}

/// What a pose where the robot cannot be adds to its log-likelihood: the
/// map's prior there is zero, and e^(−10⁴) is zero beside any fit; finite,
/// so that a set wholly outside (a map whose inside is drawn wrong) keeps
/// the weights its fits give.
const OUTSIDE_LOG_PRIOR: Real = -1e4;

/// Draws an injected pose tries before it falls back to a uniform one.
const PROPOSAL_TRIES: usize = 20;

impl CgrModel {
    /// The model; errors name the wrong setting.
    pub fn new(
        map: Arc<LineMap>,
        scenes: Option<Arc<SceneGrid>>,
        options: LocalizeOptions,
    ) -> crate::Result<Self> {
        options.cgr.check()?;
        if options.particles == 0 {
            return Err(crate::Error::Setting("particles must be at least 1".into()));
        }
        if options.min_particles > options.particles {
            return Err(crate::Error::Setting(format!(
                "min_particles ({}) must be at most particles ({}): the fewest KLD-sampling keeps",
                options.min_particles, options.particles
            )));
        }
        if options.min_particles < options.particles {
            let kld = Kld::new(options.min_particles, options.particles);
            kld.check()?;
            if options.resampling == Scheme::Ring {
                return Err(crate::Error::Setting(
                    "min_particles below particles (KLD-sampling) needs low_variance or aggregation \
                     resampling: the ring keeps the set's size"
                        .into(),
                ));
            }
        }
        if let Some(i) = options.injection {
            if !(0.0 < i.alpha_slow && i.alpha_slow < i.alpha_fast && i.alpha_fast <= 1.0) {
                return Err(crate::Error::Setting(format!(
                    "injection rates must satisfy 0 < alpha_slow < alpha_fast ≤ 1, got {} and {}",
                    i.alpha_slow, i.alpha_fast
                )));
            }
            if !(i.min_drop >= 0.0 && i.min_drop.is_finite()) {
                let found = i.min_drop;
                return Err(crate::Error::OutOfRange {
                    name: "min_drop",
                    expected: "a finite number ≥ 0",
                    found,
                });
            }
            if !(0.0..=1.0).contains(&i.lost_share) {
                let found = i.lost_share;
                return Err(crate::Error::OutOfRange {
                    name: "lost_share",
                    expected: "a share in [0, 1]",
                    found,
                });
            }
        }
        let wall_lengths = map
            .walls
            .iter()
            .scan(0.0, |total, w| {
                *total += (w.b.0 - w.a.0).hypot(w.b.1 - w.a.1);
                Some(*total)
            })
            .collect();
        let interior = match options.inside_opening {
            Some(opening) => {
                let interior = Interior::of(&map, opening)?;
                if interior.is_empty() {
                    tracing::warn!(
                        "the map encloses no region (gaps in its outline wider than {opening} m): \
                         particles are not kept inside"
                    );
                }
                (!interior.is_empty()).then(|| Arc::new(interior))
            }
            None => None,
        };
        let lines = map.walls.iter().map(Line::of).collect();
        Ok(CgrModel { map, scenes, options, wall_lengths, lines, interior })
    }

    /// Whether the robot can be at `pose`'s position (anywhere, without an
    /// inside).
    pub fn can_be_at(&self, pose: &Pose2) -> bool {
        self.interior.as_ref().is_none_or(|i| i.contains(pose.x, pose.y))
    }

    /// A pose drawn uniformly over the inside, or over the map's bounding
    /// box without one.
    fn uniform(&self, rng: &mut ChaCha8Rng) -> Pose2 {
        let theta = (rng.random::<Real>() * 2.0 - 1.0) * std::f64::consts::PI;
        if let Some((x, y)) = self.interior.as_ref().and_then(|i| i.sample(rng)) {
            return Pose2::new(x, y, theta);
        }
        let (x0, y0, x1, y1) = self.map.bounds();
        Pose2::new(x0 + rng.random::<Real>() * (x1 - x0), y0 + rng.random::<Real>() * (y1 - y0), theta)
    }

    /// A pose the reading supports, or `None` when the draw fails (no
    /// points, or a place hidden from the sensor or where the robot cannot
    /// be). One observed point, drawn at random, is put on a wall drawn in
    /// proportion to length, facing it as its normal says: that fixes the
    /// heading. Where the reading holds a second point on a surface at
    /// least [`CORNER_ANGLE`] apart, the position is then fixed too: that
    /// point lies on a wall of the matching direction, drawn among those
    /// where both points land on their walls (a corner or a pair of walls
    /// seen together), and the two line constraints are solved for the
    /// position. Otherwise the first point's place along its wall is drawn
    /// at random. Either way the sensor must see both places. A draw of a
    /// uniform pose would almost never land within CGR's reach of the
    /// robot; a one-point draw lands on the right wall but anywhere along
    /// it; a two-point draw is the robot's pose whenever both walls are
    /// the right ones.
    fn propose(&self, obs: &Observation2d, rng: &mut ChaCha8Rng) -> Option<Pose2> {
        let total = *self.wall_lengths.last()?;
        if obs.points.is_empty() || total <= 0.0 {
            return None;
        }
        let i = rng.random_range(0..obs.points.len());
        let p = point(obs, i);
        let n = local_normal(obs, i);
        let min_sin = CORNER_ANGLE.to_radians().sin();
        let second = (0..CORNER_TRIES).find_map(|_| {
            let j = rng.random_range(0..obs.points.len());
            let m = local_normal(obs, j);
            ((n.0 * m.1 - n.1 * m.0).abs() >= min_sin).then_some((j, m))
        });
        let at = rng.random::<Real>() * total;
        let a = self.wall_lengths.partition_point(|&l| l <= at).min(self.map.walls.len() - 1);
        let wall_a = self.lines[a].as_ref()?;
        // The wall's normal on a side drawn at random; the observed normal
        // faces the sensor, so turned onto it the sensor is on that side.
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let facing = (wall_a.normal.0 * side, wall_a.normal.1 * side);
        let theta = squall_core::geometry::normalize_angle(facing.1.atan2(facing.0) - n.1.atan2(n.0));
        let (s, c) = theta.sin_cos();
        let turn = |v: (Real, Real)| (c * v.0 - s * v.1, s * v.0 + c * v.1);
        let sensor_at = |robot: (Real, Real)| {
            let offset = turn(obs.sensor);
            (robot.0 + offset.0, robot.1 + offset.1)
        };
        let robot = match second {
            Some((j, m)) => {
                let (q, m) = (point(obs, j), turn(m));
                let min_cos = self.options.cgr.normal_tolerance_deg.to_radians().cos();
                // Reservoir sampling: one of the matching walls, uniformly,
                // without collecting them.
                let mut chosen = None;
                let mut found = 0u32;
                for (b, wall_b) in self.lines.iter().enumerate() {
                    let Some(wall_b) = wall_b.as_ref().filter(|_| b != a) else { continue };
                    // Either side: the observed normal faces the sensor,
                    // which puts it on the side the point was seen from.
                    if (wall_b.normal.0 * m.0 + wall_b.normal.1 * m.1).abs() < min_cos {
                        continue;
                    }
                    let Some(robot) = solve(wall_a, turn(p), wall_b, turn(q)) else { continue };
                    let on = |line: &Line, v: (Real, Real)| line.covers((robot.0 + v.0, robot.1 + v.1));
                    if !(on(wall_a, turn(p)) && on(wall_b, turn(q))) {
                        continue;
                    }
                    found += 1;
                    if rng.random_range(0..found) == 0 {
                        chosen = Some(robot);
                    }
                }
                let robot = chosen?;
                let sensor = sensor_at(robot);
                let seen = |v: (Real, Real)| sees(&self.map, sensor, (robot.0 + v.0, robot.1 + v.1));
                if !(seen(turn(p)) && seen(turn(q))) {
                    return None;
                }
                robot
            }
            None => {
                let w = &self.map.walls[a];
                let u = rng.random::<Real>();
                let on_wall = (w.a.0 + u * (w.b.0 - w.a.0), w.a.1 + u * (w.b.1 - w.a.1));
                let v = turn(p);
                let robot = (on_wall.0 - v.0, on_wall.1 - v.1);
                if !sees(&self.map, sensor_at(robot), on_wall) {
                    return None;
                }
                robot
            }
        };
        let pose = Pose2::new(robot.0, robot.1, theta);
        self.can_be_at(&pose).then_some(pose)
    }

    /// The walls visible from `pose`: the grid's cell if the pose is on the
    /// grid, else ray cast.
    fn lines_at(&self, pose: &Pose2) -> Cow<'_, [u32]> {
        if let Some(lines) = self.scenes.as_ref().and_then(|g| g.lines_at(pose.x, pose.y)) {
            return Cow::Borrowed(lines);
        }
        let mut ids: Vec<u32> = observable_scene(&self.map, (pose.x, pose.y), self.options.cgr.range)
            .iter()
            .map(|v| v.line)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        Cow::Owned(ids)
    }
}

/// How well a reading fits a pose, for telling a lost robot (augmented
/// MCL): the log-likelihood per point. With `occlusion_fits`, the points
/// short of the map (people, boxes: in free space, in front of the walls)
/// count as fitting: any pose would see them so, and a person or a box
/// filling a depth camera's view is no sign of being lost, while points
/// behind walls or facing the wrong way are; unless they fill a stretch of
/// the view wider than `occluder_size`, as another place's walls do. −∞
/// for a reading without points, which the injection rule passes over.
/// The fit is how well the points lie on the walls, whatever weight the
/// particles give each of them: it is counted at the default correlation
/// ([`FIT_CORRELATION`]) however `correlation` is set, so that the
/// injection rule's dead band (`min_drop`) means the same drop of fit.
fn fit(e: &Evaluation, input: &Observation2d, o: &CgrOptions) -> Real {
    let points = input.points.len();
    if points == 0 {
        return Real::NEG_INFINITY;
    }
    let obstacles = e.widest_short_run() <= o.occluder_size;
    let short = if o.occlusion_fits && obstacles { e.short as Real } else { 0.0 };
    let per_point = (e.log_likelihood - short * o.outlier_log_likelihood()) / points as Real;
    per_point * (o.correlation / FIT_CORRELATION)
}

/// The correlation the fit of a reading is counted at (each point 1/5):
/// `CgrOptions::correlation`'s default, in whose units `min_drop` is set.
const FIT_CORRELATION: Real = 5.0;

/// Two observed surfaces at least this far apart in direction, degrees,
/// fix a proposed pose's position (see `CgrModel::propose`).
const CORNER_ANGLE: Real = 30.0;

/// Draws of a second point on a surface of another direction before a
/// proposal falls back to one point.
const CORNER_TRIES: usize = 8;

/// Points within this distance of a point, on a surface of nearly its
/// direction, average into its normal, metres: one beam's normal comes
/// from its two neighbours and is off by degrees, which at a few metres
/// puts a proposed pose tens of centimetres off.
const NORMAL_RADIUS: Real = 0.4;

/// An observed point, robot frame.
fn point(obs: &Observation2d, i: usize) -> (Real, Real) {
    (Real::from(obs.points[i][0]), Real::from(obs.points[i][1]))
}

/// Normals within this angle of a point's, degrees, are of its surface.
const SAME_SURFACE_DEG: Real = 30.0;

/// The unit normal at point `i` averaged over the points near it whose
/// normals agree within [`SAME_SURFACE_DEG`] (a local fit of its surface).
fn local_normal(obs: &Observation2d, i: usize) -> (Real, Real) {
    let (p, n) = (obs.points[i], obs.normals[i]);
    let min_cos = SAME_SURFACE_DEG.to_radians().cos();
    let (mut sx, mut sy) = (0.0, 0.0);
    for (q, m) in obs.points.iter().zip(&obs.normals) {
        let (dx, dy) = (Real::from(q[0] - p[0]), Real::from(q[1] - p[1]));
        let agree = Real::from(m[0] * n[0] + m[1] * n[1]);
        if dx * dx + dy * dy <= NORMAL_RADIUS * NORMAL_RADIUS && agree >= min_cos {
            (sx, sy) = (sx + Real::from(m[0]), sy + Real::from(m[1]));
        }
    }
    let norm = sx.hypot(sy);
    if norm > 0.0 { (sx / norm, sy / norm) } else { (Real::from(n[0]), Real::from(n[1])) }
}

/// A wall as an oriented line: unit direction and normal, its first end
/// and its length.
#[derive(Debug, Clone)]
struct Line {
    a: (Real, Real),
    direction: (Real, Real),
    normal: (Real, Real),
    length: Real,
}

/// How far past its ends a point may land on a wall, metres (the map's
/// walls end where the mapper stopped them, not exactly at corners).
const END_TOLERANCE: Real = 0.2;

impl Line {
    fn of(w: &squall_core::linemap::Segment) -> Option<Line> {
        let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
        let length = ex.hypot(ey);
        (length > 0.0).then(|| {
            let direction = (ex / length, ey / length);
            Line { a: w.a, direction, normal: (-direction.1, direction.0), length }
        })
    }

    /// The line's offset along its normal: n · x = offset on the line.
    fn offset(&self) -> Real {
        self.normal.0 * self.a.0 + self.normal.1 * self.a.1
    }

    /// Whether `x` (on the line) lies within the wall's extent.
    fn covers(&self, x: (Real, Real)) -> bool {
        let t = (x.0 - self.a.0) * self.direction.0 + (x.1 - self.a.1) * self.direction.1;
        (-END_TOLERANCE..=self.length + END_TOLERANCE).contains(&t)
    }
}

/// The robot position r at which r + `u` lies on `a`'s line and r + `v`
/// on `b`'s; `None` when the lines are nearly parallel.
fn solve(a: &Line, u: (Real, Real), b: &Line, v: (Real, Real)) -> Option<(Real, Real)> {
    let (na, nb) = (a.normal, b.normal);
    let det = na.0 * nb.1 - na.1 * nb.0;
    if det.abs() < 0.25 {
        return None;
    }
    let ra = a.offset() - (na.0 * u.0 + na.1 * u.1);
    let rb = b.offset() - (nb.0 * v.0 + nb.1 * v.1);
    Some(((ra * nb.1 - na.1 * rb) / det, (na.0 * rb - ra * nb.0) / det))
}

/// Whether a ray from `sensor` reaches `target` on a wall unblocked
/// (stopping 1 cm short, so the wall itself does not block it).
fn sees(map: &LineMap, sensor: (Real, Real), target: (Real, Real)) -> bool {
    let (dx, dy) = (target.0 - sensor.0, target.1 - sensor.1);
    let d = dx.hypot(dy);
    let short = if d > 0.01 { (target.0 - 0.01 * dx / d, target.1 - 0.01 * dy / d) } else { sensor };
    map.clear(sensor, short)
}

impl ParticleModel for CgrModel {
    type Input = Observation2d;
    type Control = OdometryStep;
    type State = Pose2;
    type Scratch = ();
    type Gate = ();

    /// A known start begins with the fewest particles (tracking needs no
    /// more; the set grows towards `particles` only when the robot is
    /// lost, see [`Population::correct`](crate::pf::population::Population::correct)),
    /// a global one with the most.
    fn particles(&self) -> usize {
        match self.options.init {
            Init::Known(_) => self.options.min_particles,
            Init::Global => self.options.particles,
        }
    }

    fn start(&self, _: &Observation2d) -> Pose2 {
        match self.options.init {
            Init::Known(p) => p,
            Init::Global => Pose2::IDENTITY,
        }
    }

    fn scatter(&self, pose: &mut Pose2, first: &Observation2d, rng: &mut ChaCha8Rng) {
        if self.options.init == Init::Global {
            self.inject(pose, first, rng);
        }
    }

    fn injection(&self) -> Option<Injection> {
        self.options.injection
    }

    fn kld(&self) -> Option<Kld> {
        let o = &self.options;
        (o.min_particles < o.particles).then(|| Kld::new(o.min_particles, o.particles))
    }

    fn inject(&self, pose: &mut Pose2, reading: &Observation2d, rng: &mut ChaCha8Rng) {
        *pose =
            (0..PROPOSAL_TRIES).find_map(|_| self.propose(reading, rng)).unwrap_or_else(|| self.uniform(rng));
    }

    fn mark(&self, input: &Observation2d) -> (f64, Pose2) {
        (input.stamp, input.odometry)
    }

    fn control(&self, previous: &Observation2d, input: &Observation2d) -> OdometryStep {
        OdometryStep { stamp: input.stamp, from: previous.odometry, to: input.odometry }
    }

    fn gate(&self, (): &mut (), _: &OdometryStep) -> bool {
        true
    }

    fn predict(&self, pose: &mut Pose2, step: &OdometryStep, rng: &mut ChaCha8Rng) {
        *pose = sample_motion(pose, &step.from, &step.to, &self.options.motion, rng);
    }

    fn correct(
        &self,
        pose: &mut Pose2,
        input: &Observation2d,
        (): &mut (),
        rng: &mut ChaCha8Rng,
    ) -> Correction {
        // A particle where the robot cannot be carries no hypothesis: it is
        // drawn again where the reading supports (sensor resetting, Lenser
        // and Veloso 2000), so a set that drifts out of the building
        // through a wall comes back to places the scan fits.
        if !self.can_be_at(pose)
            && let Some(drawn) = (0..PROPOSAL_TRIES).find_map(|_| self.propose(input, rng))
        {
            *pose = drawn;
        }
        let (refined, e, evaluations) =
            refine(&self.map, &mut |p: &Pose2| self.lines_at(p), pose, input, &self.options.cgr);
        *pose = refined;
        let prior = if self.can_be_at(pose) { 0.0 } else { OUTSIDE_LOG_PRIOR };
        Correction {
            log_likelihood: e.log_likelihood + prior,
            evaluations,
            fit: fit(&e, input, &self.options.cgr),
        }
    }

    fn pose(&self, pose: &Pose2) -> Pose2 {
        *pose
    }

    fn state_bytes(&self, _: &Pose2) -> u64 {
        std::mem::size_of::<Pose2>() as u64
    }

    fn resample_threshold(&self) -> Real {
        self.options.resample_threshold
    }

    fn resampling(&self) -> Scheme {
        self.options.resampling
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use squall_core::linemap::Segment;

    /// A 10 × 6 m room with a 1 m door in its south wall.
    fn room() -> Arc<LineMap> {
        let s = |a: (Real, Real), b: (Real, Real)| Segment { a, b };
        Arc::new(LineMap {
            walls: vec![
                s((0.0, 0.0), (4.0, 0.0)),
                s((5.0, 0.0), (10.0, 0.0)),
                s((10.0, 0.0), (10.0, 6.0)),
                s((10.0, 6.0), (0.0, 6.0)),
                s((0.0, 6.0), (0.0, 0.0)),
            ],
        })
    }

    /// The robot at (5, 3) facing east sees the east wall (x = 10) from
    /// y = 1 to 5, its normal facing back.
    fn east_wall_seen() -> Observation2d {
        let points: Vec<[f32; 2]> = (0..41).map(|k| [5.0, -2.0 + 0.1 * k as f32]).collect();
        let normals = vec![[-1.0, 0.0]; points.len()];
        Observation2d { points, normals, ..Observation2d::default() }
    }

    fn model(keep_inside: bool) -> CgrModel {
        let inside_opening = keep_inside.then_some(DEFAULT_OPENING);
        CgrModel::new(room(), None, LocalizeOptions { inside_opening, ..LocalizeOptions::default() }).unwrap()
    }

    #[test]
    fn no_pose_is_proposed_outside_the_building() {
        let obs = east_wall_seen();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let draws = |m: &CgrModel, rng: &mut ChaCha8Rng| -> Vec<Pose2> {
            (0..2000).filter_map(|_| m.propose(&obs, rng)).collect()
        };
        // The room, and the inside's tolerance beyond its walls (a doorway).
        let room_box = |p: &Pose2| (-0.3..=10.3).contains(&p.x) && (-0.3..=6.3).contains(&p.y);
        let kept = draws(&model(true), &mut rng);
        let bad: Vec<&Pose2> = kept.iter().filter(|p| !room_box(p)).collect();
        assert!(kept.len() > 200 && bad.is_empty(), "{} drawn, {bad:?}", kept.len());
        // Without the inside, the outer walls seen from outside are
        // proposals too.
        let free = draws(&model(false), &mut rng);
        assert!(free.iter().filter(|p| !room_box(p)).count() > 100, "{} drawn", free.len());
        // Global starts land inside as well.
        let m = model(true);
        for _ in 0..200 {
            let mut p = Pose2::new(50.0, 50.0, 0.0);
            m.scatter(&mut p, &obs, &mut rng);
            assert!(room_box(&p), "{p:?}");
        }
    }

    /// The robot at (5, 3) facing east sees the east wall and the north
    /// wall's corner with it.
    fn corner_seen() -> Observation2d {
        let mut obs = east_wall_seen();
        for k in 0..31 {
            obs.points.push([2.0 + 0.1 * k as f32, 3.0]);
            obs.normals.push([0.0, -1.0]);
        }
        obs
    }

    #[test]
    fn two_surfaces_seen_fix_the_proposed_position() {
        let m = model(true);
        let truth = Pose2::new(5.0, 3.0, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let share_at_truth = |obs: &Observation2d, rng: &mut ChaCha8Rng| {
            let drawn: Vec<Pose2> = (0..4000).filter_map(|_| m.propose(obs, rng)).collect();
            let at = drawn
                .iter()
                .filter(|p| p.distance(&truth) < 0.01 && (p.theta - truth.theta).abs() < 0.01)
                .count();
            at as Real / drawn.len() as Real
        };
        // One wall seen: the place along it is a guess.
        assert!(share_at_truth(&east_wall_seen(), &mut rng) < 0.01);
        // Two: every draw that takes both walls right is the pose itself.
        let share = share_at_truth(&corner_seen(), &mut rng);
        assert!(share > 0.05, "{share}");
    }

    #[test]
    fn a_particle_outside_is_drawn_again_where_the_reading_fits() {
        let obs = east_wall_seen();
        let m = model(true);
        let inside = Pose2::new(5.0, 3.0, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let at_truth = m.correct(&mut inside.clone(), &obs, &mut (), &mut rng).log_likelihood;
        let mut outside = Pose2::new(15.0, 3.0, 0.0);
        let c = m.correct(&mut outside, &obs, &mut (), &mut rng);
        assert!(m.can_be_at(&outside), "drawn again: {outside:?}");
        assert!(c.log_likelihood > OUTSIDE_LOG_PRIOR / 2.0, "weighed by its fit alone: {c:?}");
        // With nothing to draw from, it stays, and weighs nothing beside a
        // particle inside.
        let mut stuck = Pose2::new(15.0, 3.0, 0.0);
        let blind = Observation2d::default();
        let c = m.correct(&mut stuck, &blind, &mut (), &mut rng);
        assert!(!m.can_be_at(&stuck) && c.log_likelihood < at_truth + OUTSIDE_LOG_PRIOR / 2.0, "{c:?}");
        // Without the inside, nothing changes for it.
        let mut free = Pose2::new(15.0, 3.0, 0.0);
        let c = model(false).correct(&mut free, &blind, &mut (), &mut rng);
        assert!(free.x > 12.0 && c.log_likelihood > OUTSIDE_LOG_PRIOR / 2.0, "{free:?} {c:?}");
    }

    /// Points at 1.5 m ahead of the robot, `width` metres across, facing
    /// it: at (5, 3) facing east in the room they lie in free space, 3.5 m
    /// short of the east wall.
    fn surface_ahead(width: f32) -> Observation2d {
        let n = 41;
        let points: Vec<[f32; 2]> =
            (0..n).map(|k| [1.5, width * (k as f32 / (n - 1) as f32 - 0.5)]).collect();
        let normals = vec![[-1.0, 0.0]; n];
        Observation2d { points, normals, ..Observation2d::default() }
    }

    #[test]
    fn an_obstacle_in_view_fits_and_a_place_the_map_lacks_does_not() {
        let at = Pose2::new(5.0, 3.0, 0.0);
        let with = |occlusion_fits: bool| {
            let cgr = CgrOptions { occlusion_fits, refine_iterations: 0, ..CgrOptions::default() };
            CgrModel::new(room(), None, LocalizeOptions { cgr, ..LocalizeOptions::default() }).unwrap()
        };
        let fit_of = |m: &CgrModel, obs: &Observation2d| {
            let mut pose = at;
            let c = m.correct(&mut pose, obs, &mut (), &mut ChaCha8Rng::seed_from_u64(1));
            assert_eq!(pose, at, "no refinement asked for");
            c.fit
        };
        let outliers = CgrOptions::default().outlier_log_likelihood();
        // A person or a box 0.5 m across filling the view: every point
        // short of the map, and no sign of being lost.
        let person = surface_ahead(0.5);
        assert!(fit_of(&with(true), &person).abs() < 1e-12);
        assert!((fit_of(&with(false), &person) - outliers).abs() < 1e-12);
        // A wall 3 m across where the map has open floor: the view of
        // another place (a kidnapped robot's), however it is counted.
        let elsewhere = surface_ahead(3.0);
        assert!((fit_of(&with(true), &elsewhere) - outliers).abs() < 1e-12);
        // Either side of the widest obstacle (1 m by default, measured in
        // sectors of 5.6°, 0.15 m at this distance).
        assert!(fit_of(&with(true), &surface_ahead(0.6)).abs() < 1e-12);
        assert!((fit_of(&with(true), &surface_ahead(1.6)) - outliers).abs() < 1e-12);
    }

    #[test]
    fn the_fit_does_not_depend_on_how_much_each_point_weighs() {
        // The same wall 3 m across where the map has open floor, weighed
        // with each point counted 1/5 and 1/20: the particles' weights
        // differ fourfold, the fit augmented MCL watches does not.
        let at = Pose2::new(5.0, 3.0, 0.0);
        let correct = |correlation: Real| {
            let cgr = CgrOptions { correlation, refine_iterations: 0, ..CgrOptions::default() };
            let m =
                CgrModel::new(room(), None, LocalizeOptions { cgr, ..LocalizeOptions::default() }).unwrap();
            m.correct(&mut at.clone(), &surface_ahead(3.0), &mut (), &mut ChaCha8Rng::seed_from_u64(1))
        };
        let (five, twenty) = (correct(5.0), correct(20.0));
        assert!((five.log_likelihood - 4.0 * twenty.log_likelihood).abs() < 1e-9);
        assert!(five.fit < 0.0 && (five.fit - twenty.fit).abs() < 1e-12, "{} {}", five.fit, twenty.fit);
    }

    #[test]
    fn a_map_that_encloses_nothing_keeps_no_one_out() {
        // The room without its east and west walls: open on two sides.
        let open = Arc::new(LineMap { walls: room().walls[..2].to_vec() });
        let m = CgrModel::new(open, None, LocalizeOptions::default()).unwrap();
        assert!(m.can_be_at(&Pose2::new(50.0, -50.0, 0.0)));
    }
}
