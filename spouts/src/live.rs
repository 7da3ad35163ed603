//! The live robot link (feature `cluster`; seed 003's gateway without a
//! broker): `live.ingest` subscribes to a robot's scans and odometry over
//! zenoh and emits readings on `scan`; `live.publish` sends the estimated
//! poses and, at an interval, the map back. Both speak ROS 2's CDR
//! (`sensor_msgs/LaserScan`, `nav_msgs/Odometry` in,
//! `geometry_msgs/PoseStamped`, `nav_msgs/OccupancyGrid` out, as published
//! over rmw_zenoh) or squall's own postcard messages (`format =
//! "squall"`: a `LaserReading` with its odometry in, `PoseStamped` and
//! `OccupancyGrid` out).
//! Components of one process that name the same endpoints share one
//! session, so a robot that connects to it reaches both.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use squall_core::geometry::Pose2;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::{LaserReading, Odometry, PoseStamped};
use squall_topology::cluster::config::{TlsSpec, mismatched_endpoint};
use squall_topology::cluster::session::{SessionOptions, endpoints, shared};
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
    Tuple,
};

use crate::rosbag2::messages;
use crate::rosbag2::{MAX_EXTRAPOLATION, interpolate};

/// How messages are encoded on the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    /// ROS 2 CDR, as rmw_zenoh carries it.
    #[default]
    Cdr,
    /// squall's postcard messages.
    Squall,
}

/// The default keys, as a ROS 2 robot over rmw_zenoh would name its topics
/// (without the domain and type parts).
pub const SCAN_KEY: &str = "robot/scan";
/// Odometry's default key.
pub const ODOM_KEY: &str = "robot/odom";
/// The estimated poses' default key.
pub const POSE_KEY: &str = "robot/pose";

fn scan_key() -> String {
    SCAN_KEY.into()
}
fn odom_key() -> String {
    ODOM_KEY.into()
}
fn pose_key() -> String {
    POSE_KEY.into()
}
fn map_frame() -> String {
    "map".into()
}
fn map_key() -> String {
    MAP_KEY.into()
}

/// The map's default key.
pub const MAP_KEY: &str = "robot/map";

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct IngestParams {
    #[serde(default)]
    listen: Vec<String>,
    #[serde(default)]
    connect: Vec<String>,
    #[serde(default)]
    format: Format,
    #[serde(default = "scan_key")]
    scan_key: String,
    #[serde(default = "odom_key")]
    odom_key: String,
    tls: Option<TlsParams>,
    /// End the stream once the robot has gone quiet: nothing has arrived
    /// for this long after its first scan. Before the first scan the link
    /// waits for a robot however long it takes.
    idle_secs: Option<f64>,
    /// The laser's pose on the robot (x, y, θ), for CDR scans.
    #[serde(default)]
    laser_offset: [f64; 3],
}

/// Mutual TLS for the link: the robot's certificate must chain to
/// `root_ca`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TlsParams {
    root_ca: PathBuf,
    certificate: PathBuf,
    private_key: PathBuf,
}

fn session_options(
    listen: &[String],
    connect: &[String],
    tls: Option<TlsParams>,
) -> Result<SessionOptions, ParamError> {
    let listen = endpoints(listen).map_err(ParamError::new)?;
    let connect = endpoints(connect).map_err(ParamError::new)?;
    if listen.is_empty() && connect.is_empty() {
        return Err(ParamError::new("expected `listen` or `connect` endpoints (tcp/HOST:PORT)"));
    }
    let tls =
        tls.map(|t| TlsSpec { root_ca: t.root_ca, certificate: t.certificate, private_key: t.private_key });
    if let Some(missing) = tls.as_ref().and_then(TlsSpec::missing_file) {
        return Err(ParamError::new(format!("tls: no such file: {}", missing.display())));
    }
    if let Some(e) = mismatched_endpoint(listen.iter().chain(&connect), tls.is_some()) {
        let why = if tls.is_some() { "with `tls`, endpoints are tls/" } else { "tls/ endpoints need `tls`" };
        return Err(ParamError::new(format!("{e}: {why}")));
    }
    Ok(SessionOptions { listen, connect, tls })
}

type Subscriber = zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// `live.ingest`: a robot's scans (with odometry) from zenoh, on `scan`.
/// Metrics: `scans_received`, `scans_without_odometry` (CDR scans outside
/// the odometry received: dropped, counted), `malformed` (messages that did
/// not decode: dropped, counted).
#[derive(Debug)]
pub struct LiveIngest {
    options: SessionOptions,
    format: Format,
    keys: (String, String),
    idle: Option<Duration>,
    /// Whether a scan has arrived: the idle timer runs only after one has.
    heard: bool,
    laser_offset: Pose2,
    subscribers: Option<(Subscriber, Option<Subscriber>)>,
    /// Odometry received, oldest first (about the last 10 s).
    odometry: Vec<Odometry>,
    /// Scans emitted, for the progress display (no total: the robot
    /// decides when it ends).
    readings: ReadingCounter,
}

impl LiveIngest {
    /// Builds it from `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: IngestParams = p.parse()?;
        let idle = match params.idle_secs {
            Some(s) if !(s.is_finite() && s > 0.0) => {
                return Err(ParamError::new("idle_secs: expected seconds > 0"));
            }
            s => s.map(Duration::from_secs_f64),
        };
        let [x, y, theta] = params.laser_offset;
        Ok(LiveIngest {
            options: session_options(&params.listen, &params.connect, params.tls)?,
            format: params.format,
            keys: (params.scan_key, params.odom_key),
            idle,
            heard: false,
            laser_offset: Pose2::new(x, y, theta),
            subscribers: None,
            odometry: Vec::new(),
            readings: ReadingCounter::default(),
        })
    }

    /// The reading a CDR scan makes, with odometry interpolated at its
    /// stamp; `None` if the odometry received does not cover it.
    fn cdr_reading(&self, scan: messages::LaserScan) -> Option<LaserReading> {
        let odometry = interpolate(&self.odometry, scan.header.stamp)?;
        Some(scan.into_reading(odometry, self.laser_offset))
    }

    /// Keeps `o` if it is newer than the last, and about the last 10 s.
    fn push_odometry(&mut self, o: Odometry) {
        if self.odometry.last().is_some_and(|last| o.stamp <= last.stamp) {
            return;
        }
        let old = self.odometry.partition_point(|first| o.stamp - first.stamp > 10.0 + MAX_EXTRAPOLATION);
        // Drained in batches, so each entry is moved about once.
        if old > 64 {
            self.odometry.drain(..old);
        }
        self.odometry.push(o);
    }
}

impl Spout for LiveIngest {
    fn declare(&self, d: &mut Declarer) {
        d.output::<LaserReading>("scan");
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.readings = ctx.readings("scans", || None);
        let session = shared(&self.options).await?;
        let scans = session.declare_subscriber(self.keys.0.clone()).await?;
        let odometry = match self.format {
            Format::Cdr => Some(session.declare_subscriber(self.keys.1.clone()).await?),
            Format::Squall => None,
        };
        self.subscribers = Some((scans, odometry));
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        loop {
            let (scans, odometry) = self.subscribers.as_ref().ok_or("live.ingest: not opened")?;
            let idle = async {
                match self.idle {
                    Some(d) if self.heard => tokio::time::sleep(d).await,
                    _ => std::future::pending().await,
                }
            };
            let odometry_sample = async {
                match odometry {
                    Some(s) => s.recv_async().await.ok(),
                    None => std::future::pending().await,
                }
            };
            // Odometry first: a robot sends the odometry for a scan before
            // the scan, and the scan needs it.
            tokio::select! {
                biased;
                sample = odometry_sample => {
                    let Some(sample) = sample else { continue };
                    match messages::odometry(&sample.payload().to_bytes()) {
                        Ok(o) => self.push_odometry(o.into_odometry()),
                        Err(_) => out.count("malformed", 1),
                    }
                }
                sample = scans.recv_async() => {
                    let Ok(sample) = sample else { return Ok(SpoutStatus::Done) };
                    let bytes = sample.payload().to_bytes();
                    self.heard = true;
                    out.count("scans_received", 1);
                    let reading = match self.format {
                        Format::Squall => postcard::from_bytes::<LaserReading>(&bytes).ok(),
                        Format::Cdr => match messages::laser_scan(&bytes) {
                            Ok(scan) => {
                                let reading = self.cdr_reading(scan);
                                if reading.is_none() {
                                    out.count("scans_without_odometry", 1);
                                    continue;
                                }
                                reading
                            }
                            Err(_) => None,
                        },
                    };
                    match reading {
                        Some(r) if r.ranges.len() >= 2 => {
                            out.emit("scan", r).await?;
                            self.readings.add(1);
                            return Ok(SpoutStatus::Continue);
                        }
                        _ => out.count("malformed", 1),
                    }
                }
                () = idle => return Ok(SpoutStatus::Done),
            }
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PublishParams {
    #[serde(default)]
    listen: Vec<String>,
    #[serde(default)]
    connect: Vec<String>,
    #[serde(default)]
    format: Format,
    #[serde(default = "pose_key")]
    pose_key: String,
    #[serde(default = "map_key")]
    map_key: String,
    /// Send a map at most this often, seconds (0: every one received).
    #[serde(default)]
    map_interval_secs: f64,
    #[serde(default = "map_frame")]
    frame_id: String,
    tls: Option<TlsParams>,
}

/// `live.publish`: every `PoseStamped` it receives goes to the robot on
/// `pose_key`; `OccupancyGrid`s (the best particle's map) on `map_key`, at
/// most every `map_interval_secs` (those in between are skipped and
/// counted). A message waits for room on a busy link rather than being
/// dropped; one that no subscriber would receive (no robot listening on
/// its key) is not sent and is counted instead. Metrics: `poses_sent`,
/// `poses_unheard`, `maps_sent`, `maps_unheard`, `maps_skipped`,
/// `map_bytes`.
#[derive(Debug)]
pub struct LivePublish {
    options: SessionOptions,
    format: Format,
    keys: (String, String),
    map_interval: Duration,
    last_map: Option<std::time::Instant>,
    frame_id: String,
    /// The pose and map publishers, once prepared.
    publishers: Option<(Publisher, Publisher)>,
}

type Publisher = zenoh::pubsub::Publisher<'static>;

/// Sends `bytes` on `publisher` if anyone subscribes to its key, and
/// counts it as `sent` or, with no subscriber (zenoh would drop it without
/// a word), as `unheard`; whether it was sent.
async fn send_counted(
    publisher: &Publisher,
    bytes: Vec<u8>,
    out: &mut Emitter,
    (sent, unheard): (&str, &str),
) -> Result<bool, BoxError> {
    if !publisher.matching_status().await?.matching() {
        out.count(unheard, 1);
        return Ok(false);
    }
    publisher.put(bytes).await?;
    out.count(sent, 1);
    Ok(true)
}

impl LivePublish {
    /// Builds it from `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: PublishParams = p.parse()?;
        if !(params.map_interval_secs.is_finite() && params.map_interval_secs >= 0.0) {
            return Err(ParamError::new("map_interval_secs: expected seconds ≥ 0"));
        }
        Ok(LivePublish {
            options: session_options(&params.listen, &params.connect, params.tls)?,
            format: params.format,
            keys: (params.pose_key, params.map_key),
            map_interval: Duration::from_secs_f64(params.map_interval_secs),
            last_map: None,
            frame_id: params.frame_id,
            publishers: None,
        })
    }
}

impl Bolt for LivePublish {
    fn declare(&self, d: &mut Declarer) {
        d.input::<PoseStamped>().input::<OccupancyGrid>();
    }

    async fn prepare(&mut self, _ctx: &TaskContext) -> Result<(), BoxError> {
        let session = shared(&self.options).await?;
        let declare = |key: &String| {
            session.declare_publisher(key.clone()).congestion_control(zenoh::qos::CongestionControl::Block)
        };
        self.publishers = Some((declare(&self.keys.0).await?, declare(&self.keys.1).await?));
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let (poses, maps) = self.publishers.as_ref().ok_or("live.publish: not prepared")?;
        if let Some(pose) = input.get::<PoseStamped>() {
            let bytes = match self.format {
                Format::Cdr => messages::pose_stamped(pose.stamp, &self.frame_id, &pose.pose),
                Format::Squall => postcard::to_stdvec(pose)?,
            };
            send_counted(poses, bytes, out, ("poses_sent", "poses_unheard")).await?;
            return Ok(());
        }
        let map = input.get::<OccupancyGrid>().ok_or("live.publish takes PoseStamped and OccupancyGrid")?;
        if self.last_map.is_some_and(|at| at.elapsed() < self.map_interval) {
            // A newer one will follow; the robot gets maps at the interval.
            out.count("maps_skipped", 1);
            return Ok(());
        }
        self.last_map = Some(std::time::Instant::now());
        let bytes = match self.format {
            Format::Cdr => messages::occupancy_grid(&messages::OccupancyGridMsg {
                // The map has no stamp of its own: the time it is sent.
                stamp: std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0.0, |d| d.as_secs_f64()),
                frame_id: &self.frame_id,
                resolution: map.resolution as f32,
                width: u32::try_from(map.width)?,
                height: u32::try_from(map.height)?,
                origin: Pose2::new(map.origin.0, map.origin.1, 0.0),
                data: &map.cells,
            })
            .ok_or("live.publish: a map whose cells do not fill width × height")?,
            Format::Squall => postcard::to_stdvec(map)?,
        };
        let length = bytes.len() as u64;
        if send_counted(maps, bytes, out, ("maps_sent", "maps_unheard")).await? {
            out.count("map_bytes", length);
        }
        Ok(())
    }
}
