//! The simulated robot: a differential drive that follows a seeded random
//! walk over the floor's corridor graph (preferring corridors it has used
//! least, so routes close loops), a laser by ray casting, and wheel odometry
//! with a systematic scale and heading bias plus random noise.

use squall_topology::bounds::{MAX_BEAMS, MAX_SIM_SECS};
use std::collections::{HashMap, VecDeque};
use std::f64::consts::PI;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::odometry_track::interpolate_pose;
use squall_core::sensor::{LaserReading, Odometry};

use super::office::{Floor, Route};
use crate::{Error, Result};
use squall_core::random::{standard_normal, stream_for_purpose};

/// What the simulator can be asked for. The defaults are those of
/// [`SimConfig::default`].
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Seed of every random stream.
    pub seed: u64,
    /// Simulated time, seconds. The default is 600.
    pub duration_secs: Real,
    /// Laser beams over the field of view. The default is 180.
    pub beams: usize,
    /// Field of view, radians. The default is π.
    pub fov: Real,
    /// Laser range, metres; farther walls give no return. The default is 30.
    pub range_max: Real,
    /// Standard deviation of range noise, metres. The default is 0.01.
    pub range_noise: Real,
    /// Probability that a beam returns nothing. The default is 0.002.
    pub dropout: Real,
    /// Scans per second. The default is 10.
    pub scan_hz: Real,
    /// Top speed, m/s. The default is 0.6.
    pub max_speed: Real,
    /// Top turn rate, rad/s. The default is 0.8.
    pub max_turn: Real,
    /// How good the wheel odometry is. The default is
    /// [`OdometryQuality::Poor`].
    pub odometry: OdometryQuality,
    /// Where the robot starts. The default is [`Start::FirstNode`].
    pub start: Start,
    /// Whether, and when, the robot is carried elsewhere without its
    /// odometry noticing. The default is never.
    pub kidnap: Option<Kidnap>,
    /// Faults of real sensors and wheels. The default is none.
    pub faults: Faults,
}

/// Faults of real lasers and wheels that a clean simulation lacks, so
/// that what copes with them can be tested where the truth is known. All
/// are off by default.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Each scan is stamped this long after the laser measured it, s (in
    /// [0, 0.5]), and carries the odometry at its stamp: a driver that
    /// stamps scans on arrival. (On FR079 the scans lag their odometry by
    /// about 0.1 s.)
    pub scan_latency_secs: Real,
    /// Odometry messages per second, in (0, 50]; 0 (the default) sends one
    /// with each scan, with the scan's pose.
    pub odom_hz: Real,
    /// No-return beams read this many metres (each within ±4 cm of it)
    /// instead of the declared range: a laser whose no-return code sits
    /// below its declared maximum, so that its readings look like walls
    /// (one real log declares 80 m and reads 51.05–51.12 for no return).
    pub no_return_m: Option<Real>,
    /// The maximum range the log declares, metres, when it is more than
    /// the laser reaches (FR079 declares 80 m; its longest return is
    /// 36.6 m). The default is the laser's range.
    pub declared_range_m: Option<Real>,
    /// The odometry misjudges every turn by this share, systematically
    /// (0.05: it reports 5% more turning than the robot made), in
    /// (-0.5, 0.5).
    pub turn_scale_error: Real,
    /// Wheel slips, one every this many seconds on average (none by
    /// default): for 2–6 s the robot is held where it stands while its
    /// wheels turn as commanded and the odometry drives on (FR079's robot
    /// stood seven seconds while its odometry reported 0.55 m and −17°).
    pub slip_every_secs: Option<Real>,
}

/// How long a wheel slip lasts, seconds.
const SLIP_SECS: std::ops::Range<Real> = 2.0..6.0;

/// The longest range a log may declare, metres (as `--range-max`).
const MAX_DECLARED_RANGE: Real = 1000.0;
/// The widest jitter of a no-return code, metres.
const NO_RETURN_JITTER: Real = 0.04;

impl Faults {
    /// Checks every setting's range against the laser's `range_max`.
    fn check(&self, range_max: Real) -> Result<()> {
        let declared = self.declared_range_m.unwrap_or(range_max);
        let fault = |what: String| Err(Error::Faults(what));
        if !(0.0..=0.5).contains(&self.scan_latency_secs) {
            return fault(format!("scan_latency_secs must be in [0, 0.5] s, got {}", self.scan_latency_secs));
        }
        if !(self.odom_hz == 0.0 || (self.odom_hz > 0.0 && self.odom_hz <= PHYSICS_HZ)) {
            return fault(format!("odom_hz must be 0 or in (0, {PHYSICS_HZ}], got {}", self.odom_hz));
        }
        if self.declared_range_m.is_some()
            && !(declared.is_finite() && declared >= range_max && declared <= MAX_DECLARED_RANGE)
        {
            return fault(format!(
                "declared_range_m must be at least the laser's range ({range_max} m) and at most {} m, got {declared}",
                MAX_DECLARED_RANGE
            ));
        }
        if let Some(code) = self.no_return_m
            && !(code.is_finite()
                && code > range_max + NO_RETURN_JITTER
                && code + NO_RETURN_JITTER < declared)
        {
            return fault(format!(
                "the no-return code (no_return_m, --no-return) must lie beyond the laser's range ({range_max} m) and below the declared range ({declared} m: declared_range_m, --declared-range), got {code}"
            ));
        }
        if let Some(every) = self.slip_every_secs
            && !(every.is_finite() && every >= 10.0)
        {
            return fault(format!("slip_every_secs must be at least 10 s, got {every}"));
        }
        if self.turn_scale_error.is_nan() || self.turn_scale_error.abs() >= 0.5 {
            return fault(format!("turn_scale_error must be in (-0.5, 0.5), got {}", self.turn_scale_error));
        }
        Ok(())
    }
}

/// A kidnapping: at `at_secs` the robot is lifted and set down at a place
/// of the roadmap drawn per seed, between `min_m` and `max_m` (straight
/// line) from where it stood, facing along its corridor. The odometry
/// goes on from where it was, as if nothing had happened: what a
/// localizer must notice and recover from.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Kidnap {
    /// When, seconds from the start.
    pub at_secs: Real,
    /// The shortest carry, metres.
    #[serde(default = "Kidnap::default_min_m")]
    pub min_m: Real,
    /// The longest carry, metres.
    #[serde(default = "Kidnap::default_max_m")]
    pub max_m: Real,
}

impl Kidnap {
    /// The shortest carry unless told otherwise: past what tracking can
    /// bridge, metres.
    pub const DEFAULT_MIN_M: Real = 5.0;
    /// The longest carry unless told otherwise, metres.
    pub const DEFAULT_MAX_M: Real = 20.0;

    fn default_min_m() -> Real {
        Self::DEFAULT_MIN_M
    }

    fn default_max_m() -> Real {
        Self::DEFAULT_MAX_M
    }
}

/// Where and when a kidnapping carried the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Carry {
    /// The instant, seconds: the scans after it see the new place.
    pub stamp: Real,
    /// Where the robot was lifted.
    pub from: Pose2,
    /// Where it was set down.
    pub to: Pose2,
}

impl Carry {
    /// The carry's straight-line length, metres.
    pub fn distance(&self) -> Real {
        self.from.distance(&self.to)
    }
}

/// Places drawn for a kidnapping before the one nearest to the asked
/// distances is taken: on a floor that has places that far apart, one is
/// found within a few dozen draws.
const KIDNAP_DRAWS: usize = 10_000;

/// Where a simulated robot starts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// At the floor's first node, facing its first neighbour: the same
    /// start for every seed (SLAM's simulated runs).
    #[default]
    FirstNode,
    /// Anywhere on the floor's roadmap, drawn per seed: a corridor drawn
    /// in proportion to its length, a place along it, either way along it.
    /// A localizer's claims then rest on many starts, not one.
    Drawn,
}

/// How good a simulated robot's wheel odometry is: a systematic scale error
/// and heading drift per metre (drawn once per run, each within its range
/// and of either sign), and random noise per step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OdometryQuality {
    /// A well-calibrated robot: 0.2–0.5% scale error, 0.02–0.05° of heading
    /// drift per metre, 1% noise.
    Good,
    /// A typical indoor robot: 1–2% scale error, 0.15–0.35°/m heading
    /// drift, 3% noise.
    #[default]
    Poor,
    /// The worst real robots: 3–5% scale error and 0.5–0.8°/m heading
    /// drift, 5% noise. Over the ~340 m of a 10-minute run in the office
    /// the heading drifts by some 240° (about 100° with `Poor`, 14° with
    /// `Good`).
    Bad,
}

/// The numbers of an [`OdometryQuality`].
#[derive(Debug, Clone)]
struct OdometryErrors {
    /// Range of the relative distance error.
    scale: std::ops::Range<Real>,
    /// Range of the heading drift, degrees per metre.
    heading_deg_per_m: std::ops::Range<Real>,
    /// Noise of the distance, relative.
    trans_noise: Real,
    /// Noise of a turn, relative.
    rot_noise: Real,
    /// Noise of the heading per metre driven, radians.
    rot_noise_per_m: Real,
}

impl OdometryQuality {
    fn errors(self) -> OdometryErrors {
        let (scale, heading_deg_per_m, trans_noise, rot_noise, rot_noise_per_m) = match self {
            OdometryQuality::Good => (0.002..0.005, 0.02..0.05, 0.01, 0.01, 0.003),
            OdometryQuality::Poor => (0.01..0.02, 0.15..0.35, 0.03, 0.03, 0.01),
            OdometryQuality::Bad => (0.03..0.05, 0.5..0.8, 0.05, 0.05, 0.02),
        };
        OdometryErrors { scale, heading_deg_per_m, trans_noise, rot_noise, rot_noise_per_m }
    }
}

impl OdometryQuality {
    /// Every quality, with the name that selects it.
    const NAMED: [(OdometryQuality, &'static str); 3] =
        [(OdometryQuality::Good, "good"), (OdometryQuality::Poor, "poor"), (OdometryQuality::Bad, "bad")];

    /// The quality's name: `good`, `poor` or `bad`.
    pub fn name(self) -> &'static str {
        Self::NAMED.iter().find(|(q, _)| *q == self).map_or("", |(_, name)| name)
    }
}

impl std::str::FromStr for OdometryQuality {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::NAMED
            .iter()
            .find(|(_, name)| *name == s)
            .map(|(q, _)| *q)
            .ok_or_else(|| Error::OdometryQuality(s.to_string()))
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            seed: 0,
            duration_secs: 600.0,
            beams: 180,
            fov: PI,
            range_max: 30.0,
            range_noise: 0.01,
            dropout: 0.002,
            scan_hz: 10.0,
            max_speed: 0.6,
            max_turn: 0.8,
            odometry: OdometryQuality::default(),
            start: Start::default(),
            kidnap: None,
            faults: Faults::default(),
        }
    }
}

impl SimConfig {
    /// Checks every setting's range; says which is wrong.
    pub fn check(&self) -> Result<()> {
        let positive = |v: Real| v.is_finite() && v > 0.0;
        if !(positive(self.duration_secs) && self.duration_secs <= MAX_SIM_SECS) {
            return Err(Error::Duration(self.duration_secs));
        }
        if !(2..=MAX_BEAMS).contains(&self.beams) {
            return Err(Error::Beams(self.beams));
        }
        if !(positive(self.fov) && self.fov <= 2.0 * PI) {
            return Err(Error::FieldOfView(self.fov));
        }
        let noise_ok = self.range_noise.is_finite() && self.range_noise >= 0.0;
        if !positive(self.range_max) || !noise_ok || !(0.0..=1.0).contains(&self.dropout) {
            let (range_max, range_noise, dropout) = (self.range_max, self.range_noise, self.dropout);
            return Err(Error::Laser { range_max, range_noise, dropout });
        }
        if !positive(self.scan_hz) || !positive(self.max_speed) || !positive(self.max_turn) {
            let (scan_hz, max_speed, max_turn) = (self.scan_hz, self.max_speed, self.max_turn);
            return Err(Error::Motion { scan_hz, max_speed, max_turn });
        }
        self.faults.check(self.range_max)?;
        if let Some(k) = self.kidnap {
            let at_ok = k.at_secs.is_finite() && k.at_secs >= 0.0 && k.at_secs < self.duration_secs;
            let carry_ok = k.min_m.is_finite() && k.max_m.is_finite() && 0.0 <= k.min_m && k.min_m <= k.max_m;
            if !(at_ok && carry_ok) {
                return Err(Error::Kidnap { at_secs: k.at_secs, min_m: k.min_m, max_m: k.max_m });
            }
        }
        Ok(())
    }
}

/// Physics steps per second.
const PHYSICS_HZ: Real = 50.0;

/// One output of the simulation.
#[derive(Debug, Clone, PartialEq)]
pub enum SimEvent {
    /// A scan (odometry pose inside) and the true pose at its stamp.
    Scan(LaserReading, Pose2),
    /// An odometry message.
    Odom(Odometry),
}

/// Runs the robot through the floor; an iterator of events in time order.
#[derive(Debug)]
pub struct Simulation {
    floor: Floor,
    config: SimConfig,
    truth: Pose2,
    odometry: Pose2,
    step: u64,
    steps: u64,
    steps_per_scan: u64,
    target: usize,
    previous: usize,
    visits: HashMap<(usize, usize), u32>,
    node_visits: Vec<u32>,
    plan: VecDeque<usize>,
    route_rng: ChaCha8Rng,
    slip_rng: ChaCha8Rng,
    /// Physics steps left of the wheel slip under way.
    slipping: u64,
    /// Wheel slips so far.
    slips: u64,
    odom_rng: ChaCha8Rng,
    laser_rng: ChaCha8Rng,
    /// Relative error of the odometry's distance (systematic).
    scale_bias: Real,
    /// Heading drift per metre driven, radians (systematic).
    heading_bias: Real,
    /// The odometry's errors.
    errors: OdometryErrors,
    /// Events due, in order.
    outbox: VecDeque<SimEvent>,
    /// Scans measured and not yet stamped (with a scan latency), with
    /// the true pose they were measured at.
    in_flight: VecDeque<(LaserReading, Pose2)>,
    /// The odometry before the last physics step, to interpolate at a
    /// stamp between steps.
    odometry_before: Pose2,
    steps_per_odom: Option<u64>,
    /// The kidnapping, once it happened.
    carried: Option<Carry>,
}

/// A start on `floor`'s roadmap: (pose, the node it comes from, the node it
/// heads for). A corridor (edge) drawn in proportion to its length, a
/// place along it, facing either of its ends.
fn drawn_start(floor: &Floor, rng: &mut ChaCha8Rng) -> (Pose2, usize, usize) {
    let length = |&(a, b): &(usize, usize)| {
        let (p, q) = (floor.nodes[a], floor.nodes[b]);
        (q.0 - p.0).hypot(q.1 - p.1)
    };
    let total: Real = floor.edges.iter().map(length).sum();
    let mut at = rng.random::<Real>() * total;
    let mut edge = floor.edges[floor.edges.len() - 1];
    for e in &floor.edges {
        if at < length(e) {
            edge = *e;
            break;
        }
        at -= length(e);
    }
    let (from, to) = if rng.random_bool(0.5) { edge } else { (edge.1, edge.0) };
    let (p, q) = (floor.nodes[from], floor.nodes[to]);
    let u = rng.random::<Real>();
    let pose = Pose2::new(p.0 + u * (q.0 - p.0), p.1 + u * (q.1 - p.1), (q.1 - p.1).atan2(q.0 - p.0));
    (pose, from, to)
}

impl Simulation {
    /// Starts the robot as `config.start` says: at the floor's first node,
    /// facing its first neighbour, or drawn on the roadmap. An error if a setting is out of range
    /// ([`SimConfig::check`]), the floor is malformed ([`Floor::check`]) or
    /// no edge leaves its first node.
    pub fn new(floor: Floor, config: SimConfig) -> Result<Self> {
        config.check()?;
        floor.check()?;
        let first = floor.neighbours(0).next().ok_or(Error::Stranded)?;
        let mut bias_rng = stream_for_purpose(config.seed, "odometry bias");
        let sign = |rng: &mut ChaCha8Rng| if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let errors = config.odometry.errors();
        let scale_bias = sign(&mut bias_rng) * bias_rng.random_range(errors.scale.clone());
        let heading_bias =
            sign(&mut bias_rng) * bias_rng.random_range(errors.heading_deg_per_m.clone()).to_radians();
        let (truth, previous, target) = match config.start {
            Start::FirstNode => {
                let start = floor.nodes[0];
                let heading = (floor.nodes[first].1 - start.1).atan2(floor.nodes[first].0 - start.0);
                (Pose2::new(start.0, start.1, heading), 0, first)
            }
            Start::Drawn => drawn_start(&floor, &mut stream_for_purpose(config.seed, "start")),
        };
        let steps_per_scan = (PHYSICS_HZ / config.scan_hz).round().max(1.0) as u64;
        let floor_nodes = floor.nodes.len();
        let steps_per_odom = (config.faults.odom_hz > 0.0)
            .then(|| (PHYSICS_HZ / config.faults.odom_hz).round().max(1.0) as u64);
        Ok(Simulation {
            steps: (config.duration_secs * PHYSICS_HZ) as u64,
            route_rng: stream_for_purpose(config.seed, "route"),
            slip_rng: stream_for_purpose(config.seed, "wheel slip"),
            slipping: 0,
            slips: 0,
            odom_rng: stream_for_purpose(config.seed, "odometry noise"),
            laser_rng: stream_for_purpose(config.seed, "laser noise"),
            odometry: truth,
            truth,
            floor,
            config,
            step: 0,
            steps_per_scan,
            target,
            previous,
            visits: HashMap::new(),
            node_visits: vec![0; floor_nodes],
            plan: VecDeque::new(),
            scale_bias,
            heading_bias,
            errors,
            outbox: VecDeque::new(),
            in_flight: VecDeque::new(),
            odometry_before: truth,
            steps_per_odom,
            carried: None,
        })
    }

    /// Wheel slips so far.
    pub fn slips(&self) -> u64 {
        self.slips
    }

    /// The floor being simulated.
    pub fn floor(&self) -> &Floor {
        &self.floor
    }

    /// Where and when the robot was kidnapped, once it has been.
    pub fn carried(&self) -> Option<Carry> {
        self.carried
    }

    /// Carries the robot as `kidnap` says: the first drawn place of the
    /// roadmap whose distance from here lies within the asked range, else
    /// (after [`KIDNAP_DRAWS`] draws) the draw nearest to it. The route
    /// goes on from the new place's corridor; the odometry does not move.
    fn kidnap(&mut self, kidnap: Kidnap) {
        let mut rng = stream_for_purpose(self.config.seed, "kidnap");
        let outside = |d: Real| (kidnap.min_m - d).max(d - kidnap.max_m).max(0.0);
        let mut best: Option<(Real, (Pose2, usize, usize))> = None;
        for _ in 0..KIDNAP_DRAWS {
            let place = drawn_start(&self.floor, &mut rng);
            let miss = outside(place.0.distance(&self.truth));
            if best.as_ref().is_none_or(|(m, _)| miss < *m) {
                best = Some((miss, place));
            }
            if miss == 0.0 {
                break;
            }
        }
        let Some((_, (to, from_node, to_node))) = best else { return };
        self.carried = Some(Carry { stamp: self.stamp(), from: self.truth, to });
        self.truth = to;
        self.previous = from_node;
        self.target = to_node;
        self.plan.clear();
    }

    fn stamp(&self) -> Real {
        self.step as Real / PHYSICS_HZ
    }

    fn choose_next(&mut self) {
        self.node_visits[self.target] += 1;
        if self.floor.route == Route::Explore {
            return self.explore_next();
        }
        let here = self.target;
        let options: Vec<usize> = self.floor.neighbours(here).filter(|&n| n != self.previous).collect();
        let options = if options.is_empty() { vec![self.previous] } else { options };
        let key = |a: usize, b: usize| (a.min(b), a.max(b));
        let nodes = &self.floor.nodes;
        let heading =
            |from: usize, to: usize| (nodes[to].1 - nodes[from].1).atan2(nodes[to].0 - nodes[from].0);
        let arriving = heading(self.previous, here);
        // Least-used corridors first (routes close loops), and straight on
        // rather than turning (no zig-zag on a dense roadmap).
        let weights: Vec<Real> = options
            .iter()
            .map(|&n| {
                let visits = Real::from(*self.visits.get(&key(here, n)).unwrap_or(&0));
                let straightness = (1.0 + normalize_angle(heading(here, n) - arriving).cos()) / 2.0;
                (0.1 + straightness * straightness) / (1.0 + visits)
            })
            .collect();
        let mut pick = self.route_rng.random::<Real>() * weights.iter().sum::<Real>();
        let mut next = options[options.len() - 1];
        for (&n, w) in options.iter().zip(&weights) {
            if pick < *w {
                next = n;
                break;
            }
            pick -= w;
        }
        *self.visits.entry(key(here, next)).or_default() += 1;
        self.previous = here;
        self.target = next;
    }

    /// Next node on the way to a rarely visited place; a new place when the
    /// last one is reached.
    fn explore_next(&mut self) {
        let here = self.target;
        if self.plan.is_empty() {
            // `new` checked that the floor has nodes, so the range is not
            // empty, and the minimum of 12 candidates exists.
            let n = self.floor.nodes.len();
            let goal = (0..12)
                .map(|_| self.route_rng.random_range(0..n))
                .min_by_key(|&g| (self.node_visits[g], usize::MAX - g))
                .unwrap_or(here);
            self.plan = self.shortest_path(here, goal);
        }
        // String pulling: skip plan nodes while the straight line stays clear.
        let nodes = &self.floor.nodes;
        let mut skipped = 0;
        while skipped < 8 && self.plan.len() >= 2 && self.floor.world.clear(nodes[here], nodes[self.plan[1]])
        {
            self.plan.pop_front();
            skipped += 1;
        }
        self.previous = here;
        self.target = self.plan.pop_front().unwrap_or(self.previous);
    }

    /// Nodes after `from` on a shortest (fewest edges) path to `to`.
    fn shortest_path(&self, from: usize, to: usize) -> VecDeque<usize> {
        let n = self.floor.nodes.len();
        let mut adjacency: Vec<Vec<usize>> = vec![Vec::new(); n];
        for &(a, b) in &self.floor.edges {
            adjacency[a].push(b);
            adjacency[b].push(a);
        }
        let mut parent = vec![usize::MAX; n];
        parent[from] = from;
        let mut queue = VecDeque::from([from]);
        while let Some(v) = queue.pop_front() {
            if v == to {
                break;
            }
            for &w in &adjacency[v] {
                if parent[w] == usize::MAX {
                    parent[w] = v;
                    queue.push_back(w);
                }
            }
        }
        let mut path = VecDeque::new();
        let mut v = to;
        while parent[v] != usize::MAX && v != from {
            path.push_front(v);
            v = parent[v];
        }
        path
    }

    /// One physics step: steer to the target node, move, integrate the
    /// noisy odometry.
    fn advance(&mut self) {
        let dt = 1.0 / PHYSICS_HZ;
        let (tx, ty) = self.floor.nodes[self.target];
        if (tx - self.truth.x).hypot(ty - self.truth.y) < 0.15 {
            self.choose_next();
        }
        let (tx, ty) = self.floor.nodes[self.target];
        let error = normalize_angle((ty - self.truth.y).atan2(tx - self.truth.x) - self.truth.theta);
        let turn = (2.0 * error).clamp(-self.config.max_turn, self.config.max_turn);
        let speed = self.config.max_speed * error.cos().max(0.0).powi(4);
        let (d_trans, d_rot) = (speed * dt, turn * dt);
        if let Some(every) = self.config.faults.slip_every_secs
            && self.slipping == 0
            && self.slip_rng.random_bool((dt / every).min(1.0))
        {
            self.slipping = (self.slip_rng.random_range(SLIP_SECS) * PHYSICS_HZ) as u64;
            self.slips += 1;
        }
        if self.slipping > 0 {
            // Held: the wheels turn, the robot does not.
            self.slipping -= 1;
        } else {
            self.truth = self.truth.compose(&Pose2::new(d_trans, 0.0, d_rot));
        }
        let rng = &mut self.odom_rng;
        let e = &self.errors;
        let o_trans =
            d_trans * (1.0 + self.scale_bias) + e.trans_noise * d_trans.abs() * standard_normal(rng);
        let o_rot = d_rot * (1.0 + self.config.faults.turn_scale_error)
            + self.heading_bias * d_trans.abs()
            + (e.rot_noise * d_rot.abs() + e.rot_noise_per_m * d_trans.abs()) * standard_normal(rng);
        self.odometry_before = self.odometry;
        self.odometry = self.odometry.compose(&Pose2::new(o_trans, 0.0, o_rot));
        self.step += 1;
    }

    fn scan(&mut self) -> LaserReading {
        let c = &self.config;
        let increment = c.fov / (c.beams - 1) as Real;
        let angle_min = -c.fov / 2.0;
        let ranges = (0..c.beams)
            .map(|i| {
                let angle = self.truth.theta + angle_min + i as Real * increment;
                let hit = self.floor.world.cast((self.truth.x, self.truth.y), angle, c.range_max);
                let dropped = self.laser_rng.random_bool(c.dropout);
                match hit {
                    Some(r) if !dropped => {
                        (r + c.range_noise * standard_normal(&mut self.laser_rng)).max(0.0) as f32
                    }
                    _ => match c.faults.no_return_m {
                        Some(code) => {
                            (code + NO_RETURN_JITTER * (2.0 * self.laser_rng.random::<Real>() - 1.0)) as f32
                        }
                        None => c.range_max as f32,
                    },
                }
            })
            .collect();
        LaserReading {
            stamp: self.stamp(),
            ranges,
            angle_min,
            angle_increment: increment,
            range_min: 0.0,
            range_max: c.faults.declared_range_m.unwrap_or(c.range_max),
            odometry: self.odometry,
            laser_offset: Pose2::IDENTITY,
        }
    }
}

/// An odometry message of `pose` at `stamp` (the simulator reports no
/// velocities).
fn odometry_message(stamp: Real, pose: Pose2) -> Odometry {
    Odometry { stamp, pose, linear_velocity: 0.0, angular_velocity: 0.0 }
}

impl Iterator for Simulation {
    type Item = SimEvent;

    fn next(&mut self) -> Option<SimEvent> {
        while self.outbox.is_empty() && self.step < self.steps {
            if let Some(k) = self.config.kidnap
                && self.carried.is_none()
                && self.stamp() >= k.at_secs
            {
                self.kidnap(k);
            }
            self.advance();
            let now = self.stamp();
            if let Some(every) = self.steps_per_odom
                && self.step.is_multiple_of(every)
            {
                self.outbox.push_back(SimEvent::Odom(odometry_message(now, self.odometry)));
            }
            if self.step.is_multiple_of(self.steps_per_scan) {
                let mut scan = self.scan();
                scan.stamp = now + self.config.faults.scan_latency_secs;
                self.in_flight.push_back((scan, self.truth));
            }
            // Scans whose stamp has come carry the odometry at it,
            // interpolated within the physics step.
            while self.in_flight.front().is_some_and(|(s, _)| s.stamp <= now + 1e-9) {
                let (mut scan, truth) = self.in_flight.pop_front().expect("a scan in flight");
                let step_start = now - 1.0 / PHYSICS_HZ;
                scan.odometry = if scan.stamp < now {
                    interpolate_pose(step_start, &self.odometry_before, now, &self.odometry, scan.stamp)
                } else {
                    self.odometry
                };
                if self.steps_per_odom.is_none() {
                    self.outbox.push_back(SimEvent::Odom(odometry_message(scan.stamp, scan.odometry)));
                }
                self.outbox.push_back(SimEvent::Scan(scan, truth));
            }
        }
        // Scans still in flight when the run ends arrive as the robot
        // stands: with the odometry where it stopped.
        if self.outbox.is_empty()
            && let Some((mut scan, truth)) = self.in_flight.pop_front()
        {
            scan.odometry = self.odometry;
            if self.steps_per_odom.is_none() {
                self.outbox.push_back(SimEvent::Odom(odometry_message(scan.stamp, scan.odometry)));
            }
            self.outbox.push_back(SimEvent::Scan(scan, truth));
        }
        self.outbox.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use super::super::office::office;
    use super::*;

    /// The heading error the odometry accumulates over a run (unwrapped,
    /// degrees, the largest in magnitude) and the distance driven.
    fn heading_drift(odometry: OdometryQuality, seed: u64) -> (Real, Real) {
        let config = SimConfig { seed, odometry, ..SimConfig::default() };
        let (mut drift, mut worst, mut driven) = (0.0_f64, 0.0_f64, 0.0);
        let mut last: Option<(Pose2, Pose2)> = None;
        for event in Simulation::new(office(seed, 3, 2), config).unwrap() {
            let SimEvent::Scan(scan, truth) = event else { continue };
            if let Some((odo, was)) = last {
                let turned = |from: &Pose2, to: &Pose2| normalize_angle(to.theta - from.theta);
                drift += turned(&odo, &scan.odometry) - turned(&was, &truth);
                driven += (truth.x - was.x).hypot(truth.y - was.y);
            }
            worst = if drift.abs() > worst.abs() { drift } else { worst };
            last = Some((scan.odometry, truth));
        }
        (worst.abs().to_degrees(), driven)
    }

    /// Whether `p` lies within `within` metres of a corridor (edge) of
    /// `floor`'s roadmap.
    fn on_corridor(floor: &Floor, p: &Pose2, within: Real) -> bool {
        floor.edges.iter().any(|&(a, b)| {
            let (p0, p1) = (floor.nodes[a], floor.nodes[b]);
            let (dx, dy) = (p1.0 - p0.0, p1.1 - p0.1);
            let t = (((p.x - p0.0) * dx + (p.y - p0.1) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            (p0.0 + t * dx - p.x).hypot(p0.1 + t * dy - p.y) < within
        })
    }

    #[test]
    fn drawn_starts_differ_by_seed_and_lie_on_the_roadmap() {
        let first_pose = |seed: u64, start: Start| {
            let config = SimConfig { seed, start, duration_secs: 1.0, ..SimConfig::default() };
            Simulation::new(office(1, 3, 2), config)
                .unwrap()
                .find_map(|e| match e {
                    SimEvent::Scan(_, truth) => Some(truth),
                    SimEvent::Odom(_) => None,
                })
                .unwrap()
        };
        let floor = office(1, 3, 2);
        // The first node's start is every seed's.
        assert_eq!(first_pose(1, Start::FirstNode), first_pose(2, Start::FirstNode));
        let drawn: Vec<Pose2> = (1..=20).map(|seed| first_pose(seed, Start::Drawn)).collect();
        assert_eq!(drawn[0], first_pose(1, Start::Drawn), "the same seed, the same start");
        for (i, p) in drawn.iter().enumerate() {
            // Within a step of a corridor of the roadmap (the first scan
            // comes after a physics step).
            assert!(on_corridor(&floor, p, 0.05), "seed {}: {p:?}", i + 1);
            let far = drawn.iter().filter(|q| q.distance(p) > 2.0).count();
            assert!(far >= 15, "seed {}: starts spread over the floor, {far} of 20 farther than 2 m", i + 1);
        }
    }

    #[test]
    fn faults_reach_the_readings() {
        let faults = Faults {
            scan_latency_secs: 0.1,
            odom_hz: 50.0,
            no_return_m: Some(51.1),
            declared_range_m: Some(80.0),
            turn_scale_error: 0.05,
            slip_every_secs: None,
        };
        let config = SimConfig { seed: 2, duration_secs: 120.0, faults, ..SimConfig::default() };
        let events: Vec<SimEvent> = Simulation::new(office(1, 3, 2), config).unwrap().collect();
        let odometry: Vec<&Odometry> =
            events.iter().filter_map(|e| if let SimEvent::Odom(o) = e { Some(o) } else { None }).collect();
        let scans: Vec<(&LaserReading, &Pose2)> = events
            .iter()
            .filter_map(|e| if let SimEvent::Scan(s, t) = e { Some((s, t)) } else { None })
            .collect();
        assert_eq!((odometry.len(), scans.len()), (6000, 1200));
        // Stamped 0.1 s late, carrying the odometry at the stamp (not the
        // measurement): the stream interpolated there.
        assert!((scans[0].0.stamp - 0.2).abs() < 1e-9, "{}", scans[0].0.stamp);
        let at = |t: Real| odometry.iter().find(|o| (o.stamp - t).abs() < 1e-9).map(|o| o.pose);
        assert_eq!(at(scans[10].0.stamp), Some(scans[10].0.odometry));
        // The declared range and the no-return code below it.
        let (mut codes, mut beyond) = (0, 0);
        for (s, _) in &scans {
            assert_eq!(s.range_max, 80.0);
            for &r in &s.ranges {
                let r = Real::from(r);
                if (51.06..=51.14).contains(&r) {
                    codes += 1;
                } else if r > 30.0 {
                    beyond += 1;
                }
            }
        }
        assert!(codes > 100 && beyond == 0, "{codes} no-return codes, {beyond} other readings beyond 30 m");
        // The odometry reports 5% more of every turn than the same run
        // without the fault (whose noise and drift are the same).
        let turned = |faults: Faults| {
            let config = SimConfig { seed: 2, duration_secs: 120.0, faults, ..SimConfig::default() };
            let odometry: Vec<Pose2> = Simulation::new(office(1, 3, 2), config)
                .unwrap()
                .filter_map(|e| if let SimEvent::Scan(s, _) = e { Some(s.odometry) } else { None })
                .collect();
            odometry.windows(2).map(|w| normalize_angle(w[1].theta - w[0].theta).abs()).sum::<Real>()
        };
        let ratio =
            turned(Faults { turn_scale_error: 0.05, ..Faults::default() }) / turned(Faults::default());
        assert!((1.04..1.06).contains(&ratio), "turn ratio {ratio}");
        // Out of range, each says what is allowed.
        for (bad, says) in [
            (Faults { scan_latency_secs: 0.6, ..Faults::default() }, "scan_latency_secs must be in [0, 0.5]"),
            (Faults { odom_hz: 60.0, ..Faults::default() }, "odom_hz must be 0 or in (0, 50]"),
            (Faults { no_return_m: Some(51.0), ..Faults::default() }, "below the declared range (30 m"),
            (
                Faults { turn_scale_error: f64::NAN, ..Faults::default() },
                "turn_scale_error must be in (-0.5, 0.5)",
            ),
        ] {
            let e = SimConfig { faults: bad, ..SimConfig::default() }.check().unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
    }

    #[test]
    fn a_kidnapping_carries_the_robot_the_drawn_distance_and_the_odometry_does_not_notice() {
        let floor = office(1, 3, 2);
        let kidnap = Kidnap { at_secs: 5.0, min_m: 5.0, max_m: 20.0 };
        let mut carries = Vec::new();
        for seed in 1..=10 {
            let config = SimConfig { seed, duration_secs: 8.0, kidnap: Some(kidnap), ..SimConfig::default() };
            let mut sim = Simulation::new(floor.clone(), config).unwrap();
            let scans: Vec<(Real, Pose2, Pose2)> = sim
                .by_ref()
                .filter_map(|e| match e {
                    SimEvent::Scan(s, truth) => Some((s.stamp, s.odometry, truth)),
                    SimEvent::Odom(_) => None,
                })
                .collect();
            let carry = sim.carried().expect("kidnapped");
            assert!((5.0..=20.0).contains(&carry.distance()), "seed {seed}: {carry:?}");
            assert!((5.0..5.1).contains(&carry.stamp), "seed {seed}: at {}", carry.stamp);
            // Between the scans around the instant, the truth jumps by the
            // carry and the odometry moves by one scan's drive.
            let i = scans.iter().position(|s| s.0 > carry.stamp).unwrap();
            let (before, after) = (&scans[i - 1], &scans[i]);
            assert!(before.2.distance(&after.2) > carry.distance() - 0.2, "seed {seed}");
            assert!(before.1.distance(&after.1) < 0.1, "seed {seed}: the odometry jumped");
            // The new place is on a corridor of the roadmap.
            assert!(on_corridor(&floor, &carry.to, 1e-9), "seed {seed}: {:?}", carry.to);
            carries.push(carry.to);
        }
        assert!(carries.windows(2).all(|w| w[0] != w[1]), "each seed its own carry");
        let bad = SimConfig { duration_secs: 4.0, kidnap: Some(kidnap), ..SimConfig::default() };
        assert!(
            bad.check().unwrap_err().to_string().starts_with("a kidnapping needs 0 ≤ at_secs < the duration")
        );
        let backwards = Kidnap { min_m: 9.0, max_m: 3.0, ..kidnap };
        assert!(SimConfig { kidnap: Some(backwards), ..SimConfig::default() }.check().is_err());
    }

    #[test]
    fn odometry_qualities_drift_as_documented() {
        for seed in [1, 2] {
            let (good, driven) = heading_drift(OdometryQuality::Good, seed);
            let (poor, _) = heading_drift(OdometryQuality::Poor, seed);
            let (bad, _) = heading_drift(OdometryQuality::Bad, seed);
            // The default 10-minute run drives a few hundred metres.
            assert!((150.0..400.0).contains(&driven), "{driven} m");
            assert!(good < 0.1 * driven, "good: {good}° over {driven} m");
            assert!(good < poor && poor < bad, "{good}° < {poor}° < {bad}°");
            assert!(bad >= 90.0, "bad odometry drifts {bad}° over {driven} m");
        }
        assert_eq!(SimConfig::default().odometry, OdometryQuality::Poor);
        assert_eq!("bad".parse::<OdometryQuality>().unwrap(), OdometryQuality::Bad);
        let e = "awful".parse::<OdometryQuality>().unwrap_err().to_string();
        assert_eq!(e, "odometry must be good, poor or bad, got \"awful\"");
    }

    #[test]
    fn a_bad_setting_says_which() {
        let c = SimConfig::default();
        let e = |c: SimConfig| c.check().unwrap_err().to_string();
        let duration = "duration_secs must be > 0 s and at most 1000000000 s (stamps keep a microsecond's resolution), got";
        assert_eq!(e(SimConfig { duration_secs: 0.0, ..c.clone() }), format!("{duration} 0"));
        assert_eq!(e(SimConfig { duration_secs: 1e300, ..c.clone() }), format!("{duration} 1e300"));
        assert_eq!(e(SimConfig { beams: 1, ..c.clone() }), "beams must be in 2..=65536, got 1");
        assert_eq!(e(SimConfig { beams: 1 << 20, ..c.clone() }), "beams must be in 2..=65536, got 1048576");
        assert_eq!(e(SimConfig { fov: 0.0, ..c.clone() }), "field of view must be in (0°, 360°], got 0°");
        assert_eq!(
            e(SimConfig { dropout: 1.5, ..c.clone() }),
            "range_max must be > 0, range_noise ≥ 0 and dropout in [0, 1]"
        );
        assert_eq!(
            e(SimConfig { max_turn: -1.0, ..c.clone() }),
            "scan rate, speed and turn rate must be > 0"
        );
        assert!(c.check().is_ok());
    }

    #[test]
    fn a_bad_config_or_floor_is_an_error_not_a_panic() {
        let config = SimConfig { duration_secs: 1.0, ..SimConfig::default() };
        let e = |floor: Floor, config: SimConfig| Simulation::new(floor, config).unwrap_err().to_string();
        // Zero beams would underflow the beam spacing; a dropout above 1 is
        // no probability.
        assert!(e(office(1, 1, 1), SimConfig { beams: 0, ..config.clone() }).starts_with("beams must"));
        assert!(e(office(1, 1, 1), SimConfig { dropout: 2.0, ..config.clone() }).contains("dropout"));
        let floor = office(1, 1, 1);
        assert_eq!(e(Floor { nodes: Vec::new(), ..floor.clone() }, config.clone()), "the floor has no nodes");
        assert_eq!(
            e(Floor { edges: vec![(0, 1), (1, 9)], ..floor.clone() }, config.clone()),
            "the floor's edge 1–9 names a node it does not have (it has 4)"
        );
        assert_eq!(
            e(Floor { edges: vec![(1, 2)], ..floor.clone() }, config.clone()),
            "the floor's first node has no edge: the robot has nowhere to drive"
        );
        // No columns and no rows: one node, nowhere to drive.
        assert!(e(office(1, 0, 0), config.clone()).contains("nowhere to drive"));
        assert!(Simulation::new(floor, config).unwrap().count() > 0);
    }
}
