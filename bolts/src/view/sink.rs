//! `sink.foxglove`: publishes whatever streams it subscribes to as
//! Foxglove channels (see [`convert`](super::convert) for the schemas):
//!
//! | message | channel | schema |
//! | --- | --- | --- |
//! | laser scan | `/scan` | `foxglove.LaserScan` in `laser` |
//! | pose on stream S | `/S`, and every pose so far on `/S/path` (throttled) | `foxglove.PoseInFrame`, `foxglove.PosesInFrame` in `map` |
//! | occupancy grid on stream S | `/S` (throttled) | `foxglove.Grid` in `map` |
//! | particle set | `/particles`, and weights on `/particles/weights` | `foxglove.PosesInFrame` |
//! | hypotheses | `/hypotheses` | `foxglove.PosesInFrame` |
//! | plane-filtered or scan points | `/points` | `foxglove.PointCloud` in `base_link` |
//! | odometry (of scans, points, `odom`) | `/tf` | `foxglove.FrameTransforms`: `odom → base_link`, and `base_link → laser` |
//! | a pose on stream `tf_from` | `/tf` | `map → odom` (the estimate against odometry) |
//! | the line map (`line_map` param) | `/line_map`, once | `foxglove.SceneUpdate` |
//!
//! Throttled channels (`map_hz`, `path_hz`) publish at most that often by
//! the readings' own clock and by the wall's: a robot's live run gets
//! them at the rate asked, and a log replayed a hundred times faster than
//! it was recorded does not flood its viewers (a recording of it then
//! holds fewer maps). The last of each is published when the run ends.
//! Messages of other types are counted (`not_shown`), not published.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::{Duration, Instant};

use foxglove::messages::{
    FrameTransform, FrameTransforms, Grid, LaserScan, PointCloud, PoseInFrame, PosesInFrame, SceneUpdate,
};
use foxglove::{Channel, Encode, RawChannel, ToUnixNanos};
use serde::Deserialize;
use squall_core::geometry::{Pose2, Real};
use squall_core::linemap::LineMap;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::{LaserReading, Odometry, PoseStamped};
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Source, TaskContext, Tuple};

use super::convert::{self, BASE_LINK, LASER, MAP, ODOM};
use super::{context, latch, live_context};
use crate::cgr::observation::Observation2d;
use crate::pf::ParticleSet;
use crate::pf::modes::Hypotheses;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct SinkParams {
    /// Occupancy grids published per second of the readings' clock.
    map_hz: Real,
    /// Trajectory paths published per second of the readings' clock.
    path_hz: Real,
    /// The stream whose poses place `map → odom`.
    tf_from: String,
    /// A line map to publish once, on `/line_map`.
    line_map: Option<String>,
}

impl Default for SinkParams {
    fn default() -> Self {
        SinkParams { map_hz: 1.0, path_hz: 0.2, tf_from: "pose".into(), line_map: None }
    }
}

/// Odometry poses, and estimates, kept at most while waiting for the
/// other of their stamp to place `map → odom` (they arrive on different
/// inputs, in either order; what is older than the last pair goes).
const UNPAIRED_KEPT: usize = 1 << 16;

/// Drops every entry of `waiting` up to `key`.
fn forget_through(waiting: &mut BTreeMap<u64, Pose2>, key: u64) {
    while let Some(first) = waiting.first_entry().filter(|e| *e.key() <= key) {
        first.remove();
    }
}

/// Keeps `pose` at `stamp` in `waiting`, the oldest going past
/// [`UNPAIRED_KEPT`].
fn keep(waiting: &mut BTreeMap<u64, Pose2>, stamp: f64, pose: Pose2) {
    waiting.insert(stamp.max(0.0).to_bits(), pose);
    if waiting.len() > UNPAIRED_KEPT {
        waiting.pop_first();
    }
}

/// The spacing of a published path's poses: metres, radians.
const PATH_STEP: (Real, Real) = (0.1, 0.1);

/// How often a live viewer gets a message of one topic at most: what a
/// screen shows. A recording gets every message; a log replayed many
/// times faster than real time would otherwise send a viewer thousands a
/// second, and the sending costs the robot's computer more than the run.
const LIVE_PERIOD: Duration = Duration::from_millis(33);

/// One topic's channels: every message into the recording context, at
/// most one a [`LIVE_PERIOD`] into the live one.
struct Outlet<T: Encode> {
    recorded: Channel<T>,
    /// Sent through [`latch::send`], which encodes `T` itself.
    live: Arc<RawChannel>,
    live_at: Option<Instant>,
}

/// Channels of one schema by topic, made when first used.
struct Topics<T: Encode> {
    outlets: HashMap<String, Outlet<T>>,
    /// Messages live viewers did not get (throttled).
    held_back: u64,
}

impl<T: Encode> Default for Topics<T> {
    fn default() -> Self {
        Topics { outlets: HashMap::new(), held_back: 0 }
    }
}

impl<T: Encode> Topics<T> {
    fn outlet(&mut self, topic: &str) -> &mut Outlet<T> {
        if !self.outlets.contains_key(topic) {
            let live = live_context()
                .channel_builder(topic)
                .message_encoding(T::get_message_encoding())
                .schema(T::get_schema())
                .build_raw()
                .expect("a message encoding is given");
            let outlet = Outlet { recorded: context().channel_builder(topic).build(), live, live_at: None };
            self.outlets.insert(topic.to_string(), outlet);
        }
        self.outlets.get_mut(topic).expect("inserted above")
    }

    /// Logs `msg` for the recording, and for live viewers if one is due.
    fn log(&mut self, topic: &str, msg: &T, stamp: f64) {
        self.outlet(topic).recorded.log_with_time(msg, convert::timestamp(stamp));
        if let Some(live) = self.live_due(topic) {
            latch::send(live, msg, convert::timestamp(stamp).to_unix_nanos());
        }
    }

    /// The live channel of `topic` if a message is due there (counted as
    /// sent): anyone watches it, or a live server runs (to latch it for
    /// viewers to come). Else `None`, counted as held back when someone
    /// watches.
    fn live_due(&mut self, topic: &str) -> Option<&Arc<RawChannel>> {
        let mut held_back = 0;
        let o = self.outlets.get_mut(topic)?;
        let watched = o.live.has_sinks();
        let due = (watched || latch::enabled()) && {
            let now = Instant::now();
            let due = o.live_at.is_none_or(|at| now.duration_since(at) >= LIVE_PERIOD);
            if due {
                o.live_at = Some(now);
            } else {
                held_back = 1;
            }
            due
        };
        if watched {
            self.held_back += held_back;
        }
        let o = self.outlets.get(topic)?;
        due.then_some(&o.live)
    }
}

/// A throttled stream: the latest value, and when one was last published
/// (by the readings' clock and by the wall's).
struct Throttled<T> {
    period: f64,
    last: Option<(f64, Instant)>,
    pending: Option<T>,
}

impl<T> Throttled<T> {
    fn new(hz: Real) -> Self {
        Throttled { period: if hz > 0.0 { 1.0 / hz } else { f64::INFINITY }, last: None, pending: None }
    }

    /// Keeps `value`; returns it if one is due at `stamp` (a period after
    /// the last on both clocks).
    fn offer(&mut self, value: T, stamp: f64) -> Option<T> {
        let now = Instant::now();
        let due = self.last.is_none_or(|(at, wall)| {
            stamp >= at + self.period && now.duration_since(wall).as_secs_f64() >= self.period
        });
        if due {
            self.last = Some((stamp, now));
            self.pending = None;
            Some(value)
        } else {
            self.pending = Some(value);
            None
        }
    }
}

/// Publishes its inputs to Foxglove (see the module's table).
pub struct FoxgloveSink {
    p: SinkParams,
    /// The latest reading stamp seen: the clock of maps, which have none.
    now: f64,
    /// The last odometry stamp, to publish each once.
    last_odometry: Option<f64>,
    /// Odometry and estimates by stamp (`f64::to_bits`, which orders
    /// non-negative stamps), waiting for their pair.
    odometry: BTreeMap<u64, Pose2>,
    estimates: BTreeMap<u64, Pose2>,
    maps: HashMap<String, Throttled<Arc<OccupancyGrid>>>,
    paths: HashMap<String, (Vec<Pose2>, Throttled<()>)>,
    scans: Topics<LaserScan>,
    pose: Topics<PoseInFrame>,
    poses: Topics<PosesInFrame>,
    grids: Topics<Grid>,
    clouds: Topics<PointCloud>,
    tf: Topics<FrameTransforms>,
    scenes: Topics<SceneUpdate>,
    weights: Topics<Weights>,
    line_map: Option<LineMap>,
    /// Where the scanner sits on the robot, once a scan has said.
    laser: Option<Pose2>,
    /// The latest transform of each frame not yet sent live.
    latest_tf: BTreeMap<String, FrameTransform>,
    /// Messages held back from live viewers, as last counted.
    held_back_counted: u64,
}

/// The particles' weights, in the order of `/particles`' poses.
#[derive(Debug, Clone, foxglove::Encode)]
pub struct Weights {
    /// Seconds.
    pub stamp: f64,
    /// Each particle's weight; they sum to 1.
    pub weights: Vec<f64>,
}

impl std::fmt::Debug for FoxgloveSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FoxgloveSink").field("now", &self.now).finish_non_exhaustive()
    }
}

impl FoxgloveSink {
    /// Builds the sink from its params (see the module's docs).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: SinkParams = p.parse()?;
        if p.parallelism() != 1 {
            return Err(ParamError::new("sink.foxglove publishes one view: use parallelism 1"));
        }
        if !(params.map_hz >= 0.0 && params.path_hz >= 0.0) {
            return Err(ParamError::new("map_hz and path_hz must be 0 (only at the end) or more"));
        }
        let line_map = match &params.line_map {
            None => None,
            Some(path) => {
                squall_topology::confine::check_read(std::path::Path::new(path))
                    .map_err(|e| ParamError::new(format!("line_map: {e}")))?;
                let text = std::fs::read_to_string(path)
                    .map_err(|e| ParamError::new(format!("line_map {path}: {e}")))?;
                Some(LineMap::parse(path, &text).map_err(|e| ParamError::new(e.to_string()))?)
            }
        };
        Ok(FoxgloveSink {
            p: params,
            now: 0.0,
            last_odometry: None,
            odometry: BTreeMap::new(),
            estimates: BTreeMap::new(),
            maps: HashMap::new(),
            paths: HashMap::new(),
            scans: Topics::default(),
            pose: Topics::default(),
            poses: Topics::default(),
            grids: Topics::default(),
            clouds: Topics::default(),
            tf: Topics::default(),
            scenes: Topics::default(),
            weights: Topics::default(),
            line_map,
            laser: None,
            latest_tf: BTreeMap::new(),
            held_back_counted: 0,
        })
    }

    /// Publishes `odom → base_link` at `stamp` (once per stamp, with
    /// `base_link → laser` once a scan has placed it: the SDK keeps no
    /// latched messages for late subscribers) and keeps it for `map →
    /// odom`.
    fn odometry(&mut self, stamp: f64, odometry: Pose2) {
        if self.last_odometry.is_some_and(|s| s >= stamp) {
            return;
        }
        self.last_odometry = Some(stamp);
        keep(&mut self.odometry, stamp, odometry);
        self.pair(stamp);
        let mut transforms = vec![convert::transform(ODOM, BASE_LINK, &odometry, stamp)];
        if let Some(laser) = &self.laser {
            transforms.push(convert::transform(BASE_LINK, LASER, laser, stamp));
        }
        self.transforms(transforms, stamp);
    }

    /// Records `transforms` on `/tf`; live viewers get, when one is due,
    /// the latest transform of every frame (so the latched `/tf` places
    /// every frame).
    fn transforms(&mut self, transforms: Vec<FrameTransform>, stamp: f64) {
        for t in &transforms {
            self.latest_tf.insert(t.child_frame_id.clone(), t.clone());
        }
        let msg = FrameTransforms { transforms };
        self.tf.outlet("/tf").recorded.log_with_time(&msg, convert::timestamp(stamp));
        if let Some(live) = self.tf.live_due("/tf") {
            let latest = FrameTransforms { transforms: self.latest_tf.values().cloned().collect() };
            latch::send(live, &latest, convert::timestamp(stamp).to_unix_nanos());
        }
    }

    fn scan(&mut self, r: &LaserReading) {
        self.now = self.now.max(r.stamp);
        self.laser = Some(r.laser_offset);
        self.odometry(r.stamp, r.odometry);
        self.scans.log("/scan", &convert::laser_scan(r), r.stamp);
    }

    fn pose_on(&mut self, stream: &str, p: &PoseStamped) {
        self.now = self.now.max(p.stamp);
        self.pose.log(&format!("/{stream}"), &convert::pose_in_map(&p.pose, p.stamp), p.stamp);
        if stream == self.p.tf_from {
            keep(&mut self.estimates, p.stamp, p.pose);
            self.pair(p.stamp);
        }
        let path_hz = self.p.path_hz;
        let (path, throttle) =
            self.paths.entry(stream.to_string()).or_insert_with(|| (Vec::new(), Throttled::new(path_hz)));
        // A path for the eye: a pose where the robot has moved or turned
        // a display's worth since the last kept, and the latest.
        let moved = path.last().is_none_or(|last: &Pose2| {
            (p.pose.x - last.x).hypot(p.pose.y - last.y) >= PATH_STEP.0
                || squall_core::geometry::normalize_angle(p.pose.theta - last.theta).abs() >= PATH_STEP.1
        });
        if moved {
            path.push(p.pose);
        }
        if throttle.offer((), p.stamp).is_some() {
            let latest = (!moved).then_some(&p.pose);
            let msg = convert::poses_in_map(path.iter().chain(latest), p.stamp);
            self.poses.log(&format!("/{stream}/path"), &msg, p.stamp);
        }
    }

    /// Messages live viewers did not get so far (throttled).
    fn held_back(&self) -> u64 {
        self.scans.held_back
            + self.pose.held_back
            + self.poses.held_back
            + self.grids.held_back
            + self.clouds.held_back
            + self.tf.held_back
            + self.scenes.held_back
            + self.weights.held_back
    }

    /// Publishes `map → odom` at `stamp` once both its odometry and its
    /// estimate are in, and forgets what is older.
    fn pair(&mut self, stamp: f64) {
        let key = stamp.max(0.0).to_bits();
        let (Some(&odom), Some(&estimate)) = (self.odometry.get(&key), self.estimates.get(&key)) else {
            return;
        };
        forget_through(&mut self.odometry, key);
        forget_through(&mut self.estimates, key);
        let map_to_odom = estimate.compose(&odom.inverse());
        self.transforms(vec![convert::transform(MAP, ODOM, &map_to_odom, stamp)], stamp);
    }

    fn map_on(&mut self, stream: &str, g: Arc<OccupancyGrid>) {
        let map_hz = self.p.map_hz;
        let throttle = self.maps.entry(stream.to_string()).or_insert_with(|| Throttled::new(map_hz));
        if let Some(g) = throttle.offer(g, self.now) {
            self.grids.log(&format!("/{stream}"), &convert::grid(&g, self.now), self.now);
        }
    }
}

impl Bolt for FoxgloveSink {
    fn declare(&self, d: &mut Declarer) {
        d.any_input();
    }

    async fn prepare(&mut self, _: &TaskContext) -> Result<(), BoxError> {
        if let Some(map) = self.line_map.take() {
            self.scenes.log("/line_map", &convert::line_map(&map, 0.0), 0.0);
        }
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let stream: Arc<str> = match input.source() {
            Source::Stream { stream, .. } => stream.clone(),
            Source::Peer { .. } => "peer".into(),
        };
        if let Some(r) = input.get::<LaserReading>() {
            self.scan(r);
        } else if let Some(p) = input.get::<PoseStamped>() {
            self.pose_on(&stream, p);
        } else if input.is::<OccupancyGrid>() {
            let grid = input.into_arc::<OccupancyGrid>().map_err(|_| "an occupancy grid")?;
            self.map_on(&stream, grid);
        } else if let Some(o) = input.get::<Observation2d>() {
            self.now = self.now.max(o.stamp);
            self.odometry(o.stamp, o.odometry);
            self.clouds.log("/points", &convert::points(o), o.stamp);
        } else if let Some(o) = input.get::<Odometry>() {
            self.now = self.now.max(o.stamp);
            self.odometry(o.stamp, o.pose);
        } else if let Some(s) = input.get::<ParticleSet>() {
            self.poses.log("/particles", &convert::poses_in_map(s.poses.iter(), s.stamp), s.stamp);
            let w = Weights { stamp: s.stamp, weights: s.weights.clone() };
            self.weights.log("/particles/weights", &w, s.stamp);
        } else if let Some(h) = input.get::<Hypotheses>() {
            let modes: Vec<Pose2> = h.modes.iter().map(|m| m.pose).collect();
            self.poses.log("/hypotheses", &convert::poses_in_map(modes.iter(), h.stamp), h.stamp);
        } else {
            out.count("not_shown", 1);
            return Ok(());
        }
        out.count("published", 1);
        let held_back = self.held_back();
        if held_back > self.held_back_counted {
            out.count("live_held_back", held_back - self.held_back_counted);
            self.held_back_counted = held_back;
        }
        Ok(())
    }

    async fn finish(&mut self, _: &mut Emitter) -> Result<(), BoxError> {
        // The last of each throttled stream, so that a recording ends with
        // the final map and the whole trajectory.
        let now = self.now;
        let maps: Vec<(String, Arc<OccupancyGrid>)> =
            self.maps.iter_mut().filter_map(|(s, t)| Some((s.clone(), t.pending.take()?))).collect();
        for (stream, g) in maps {
            self.grids.log(&format!("/{stream}"), &convert::grid(&g, now), now);
        }
        for (stream, (path, throttle)) in &mut self.paths {
            if throttle.pending.take().is_some() {
                self.poses.log(&format!("/{stream}/path"), &convert::poses_in_map(path.iter(), now), now);
            }
        }
        Ok(())
    }
}
