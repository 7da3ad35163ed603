//! The live robot link (feature `cluster`; seed 003's gateway without a
//! broker): `live.ingest` takes a robot's scans and odometry over zenoh
//! and emits readings on `scan`; `live.publish` sends the estimated poses,
//! the map and the `map → odom` correction back.
//!
//! In the `ros2` format (the default) squall is a ROS 2 node as rmw_zenoh
//! makes one ([`node`], [`crate::rmw_zenoh`]): it subscribes to `/scan`
//! (`sensor_msgs/LaserScan`), `/odom` (`nav_msgs/Odometry`) and `/tf`
//! (`odom → base_link`, used instead of `/odom` when the robot broadcasts
//! it), and publishes `/pose` (`geometry_msgs/PoseStamped`), `/map`
//! (`nav_msgs/OccupancyGrid`, transient-local: a late subscriber gets the
//! last one) and `/tf` (`map → odom` at the pose rate), with rmw_zenoh's
//! keys, attachments and liveliness tokens. In the `squall` format it
//! sends squall's own postcard messages on plain keys (the topic without
//! its leading slash): a `LaserReading` with its odometry in,
//! `PoseStamped` and `OccupancyGrid` out.
//! Components of one process that name the same endpoints share one
//! session and one node, so a robot that connects to it reaches both.

pub mod node;
pub mod odometry;

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use squall_core::geometry::Pose2;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::{LaserReading, PoseStamped};
use squall_topology::cluster::config::{
    LIVE_LINK_RISK, TlsSpec, exposed_endpoint, exposure_refusal, exposure_warning, mismatched_endpoint,
};
use squall_topology::cluster::session::{
    RefusedPeers, SessionOptions, endpoints, shared, shared_with_refusals,
};
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
    Tuple,
};
use zenoh::handlers::{FifoChannel, FifoChannelHandler, RingChannel, RingChannelHandler};
use zenoh::sample::Sample;

use crate::rmw_zenoh::{self, Attachment, Qos, qualified};
use crate::rosbag2::messages;
use node::{RosNode, RosPublisher, RosSubscription};
use odometry::OdometryTrack;

/// How messages are encoded on the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    /// ROS 2 over rmw_zenoh: CDR messages on rmw_zenoh's keys, with its
    /// attachments and liveliness tokens (`cdr` is the older name).
    #[default]
    #[serde(alias = "cdr")]
    Ros2,
    /// squall's postcard messages on plain keys.
    Squall,
}

/// The topics a ROS 2 robot uses, as `ros2 topic list` shows them.
pub const SCAN_TOPIC: &str = "/scan";
/// Odometry's topic.
pub const ODOM_TOPIC: &str = "/odom";
/// Transforms' topic.
pub const TF_TOPIC: &str = "/tf";
/// The estimated poses' topic.
pub const POSE_TOPIC: &str = "/pose";
/// The map's topic.
pub const MAP_TOPIC: &str = "/map";

fn scan_topic() -> String {
    SCAN_TOPIC.into()
}
fn odom_topic() -> String {
    ODOM_TOPIC.into()
}
fn tf_topic() -> String {
    TF_TOPIC.into()
}
fn pose_topic() -> String {
    POSE_TOPIC.into()
}
fn map_topic() -> String {
    MAP_TOPIC.into()
}
fn map_frame() -> String {
    "map".into()
}
fn odom_frame() -> String {
    "odom".into()
}
fn base_frame() -> String {
    "base_link".into()
}
fn node_name() -> String {
    "squall".into()
}

/// The plain key the `squall` format uses for `topic`.
pub fn squall_key(topic: &str) -> &str {
    topic.trim_start_matches('/')
}

/// Where the link is and how it speaks, common to both components
/// (flattened into each one's parameters, which refuse what neither
/// knows: [`no_unknown`]).
#[derive(Debug, Deserialize)]
struct LinkParams {
    #[serde(default)]
    listen: Vec<String>,
    #[serde(default)]
    connect: Vec<String>,
    #[serde(default)]
    format: Format,
    tls: Option<TlsParams>,
    /// Allows plain `tcp/` endpoints beyond loopback, without mutual TLS
    /// (a network the user trusts); every run then warns.
    #[serde(default)]
    insecure: bool,
    /// With `tls`: the only robots (certificate common names) the link
    /// talks to; others are refused, logged by name and counted.
    allow_robots: Option<Vec<String>>,
    /// ROS domain id (`ROS_DOMAIN_ID`).
    #[serde(default)]
    domain_id: u32,
    /// The ROS 2 node squall appears as.
    #[serde(default = "node_name")]
    node: String,
    #[serde(default = "odom_topic")]
    odom_topic: String,
    #[serde(default = "tf_topic")]
    tf_topic: String,
    /// The robot's odometry frame and its own frame: the transform between
    /// them on `/tf` is its odometry.
    #[serde(default = "odom_frame")]
    odom_frame: String,
    #[serde(default = "base_frame")]
    base_frame: String,
}

/// A link's checked parameters.
#[derive(Debug)]
struct Link {
    options: SessionOptions,
    /// What to warn of: the plain endpoints beyond loopback that
    /// `insecure = true` allowed.
    warnings: Vec<String>,
    format: Format,
    domain: u32,
    node: String,
    odom_topic: String,
    tf_topic: String,
    odom_frame: String,
    base_frame: String,
}

/// A topic name checked as ROS 2 checks one, fully qualified.
fn topic(what: &str, name: &str) -> Result<String, ParamError> {
    qualified(name).map_err(|e| ParamError::new(format!("{what}: {e}")))
}

impl Link {
    fn from_params(p: LinkParams) -> Result<Link, ParamError> {
        rmw_zenoh::node_name(&p.node).map_err(|e| ParamError::new(format!("node: {e}")))?;
        let options = session_options(&p.listen, &p.connect, p.tls, p.allow_robots)?;
        let endpoints = || options.listen.iter().chain(&options.connect);
        if let Some(exposed) = exposed_endpoint(endpoints())
            && !p.insecure
        {
            return Err(ParamError::new(exposure_refusal(exposed, LIVE_LINK_RISK, "set `insecure = true`")));
        }
        let warnings =
            endpoints().filter(|e| e.is_exposed()).map(|e| exposure_warning(e, LIVE_LINK_RISK)).collect();
        Ok(Link {
            options,
            warnings,
            format: p.format,
            domain: p.domain_id,
            node: p.node,
            odom_topic: topic("odom_topic", &p.odom_topic)?,
            tf_topic: topic("tf_topic", &p.tf_topic)?,
            odom_frame: p.odom_frame,
            base_frame: p.base_frame,
        })
    }
}

/// Counts a sample without rmw_zenoh's attachment (a publisher that is
/// not rmw_zenoh's: taken, counted).
fn check_attachment(sample: &Sample, out: &mut Emitter) {
    let valid = sample.attachment().is_some_and(|a| Attachment::decode(&a.to_bytes()).is_some());
    if !valid {
        out.count("without_attachment", 1);
    }
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
    allow: Option<Vec<String>>,
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
    match &allow {
        Some(_) if tls.is_none() => {
            return Err(ParamError::new(
                "allow_robots needs `tls`: robots are known by their certificate's common name",
            ));
        }
        Some(names) if names.is_empty() || names.iter().any(|n| n.trim().is_empty()) => {
            return Err(ParamError::new("allow_robots: expected the robots' certificate names, none empty"));
        }
        _ => {}
    }
    Ok(SessionOptions { listen, connect, tls, allow })
}

/// Refuses parameters neither the link nor the component knows.
fn no_unknown(unknown: &toml::Table, known: &[&str]) -> Result<(), ParamError> {
    match unknown.keys().next() {
        None => Ok(()),
        Some(key) => {
            Err(ParamError::new(format!("unknown field `{key}`, expected one of {}", known.join(", "))))
        }
    }
}

const LINK_FIELDS: [&str; 12] = [
    "listen",
    "connect",
    "format",
    "tls",
    "insecure",
    "allow_robots",
    "domain_id",
    "node",
    "odom_topic",
    "tf_topic",
    "odom_frame",
    "base_frame",
];

#[derive(Debug, Deserialize)]
struct IngestParams {
    #[serde(flatten)]
    link: LinkParams,
    #[serde(default = "scan_topic")]
    scan_topic: String,
    /// End the stream once the robot has gone quiet: nothing has arrived
    /// for this long after its first scan. Before the first scan the link
    /// waits for a robot however long it takes.
    idle_secs: Option<f64>,
    /// The laser's pose on the robot (x, y, θ), for ROS 2 scans.
    #[serde(default)]
    laser_offset: [f64; 3],
    #[serde(flatten)]
    unknown: toml::Table,
}

/// What `live.ingest` listens to.
#[derive(Debug)]
enum Inputs {
    Ros2 {
        _node: std::sync::Arc<RosNode>,
        scans: RosSubscription<FifoChannelHandler<Sample>>,
        odometry: RosSubscription<FifoChannelHandler<Sample>>,
        tf: RosSubscription<FifoChannelHandler<Sample>>,
    },
    Squall(zenoh::pubsub::Subscriber<FifoChannelHandler<Sample>>),
}

/// `live.ingest`: a robot's scans (with odometry) from zenoh, on `scan`.
/// Metrics: `scans_received`, `scans_without_odometry` (ROS 2 scans
/// outside the odometry received: dropped, counted), `malformed`
/// (messages that did not decode: dropped, counted),
/// `without_attachment` (ROS 2 samples without rmw_zenoh's attachment:
/// taken, counted), `odometry_from_tf` (1 once the robot's `/tf` carries
/// the odometry).
#[derive(Debug)]
pub struct LiveIngest {
    link: Link,
    scan_topic: String,
    idle: Option<Duration>,
    /// Whether a scan has arrived: the idle timer runs only after one has.
    heard: bool,
    laser_offset: Pose2,
    inputs: Option<Inputs>,
    odometry: OdometryTrack,
    /// Scans emitted, for the progress display (no total: the robot
    /// decides when it ends).
    readings: ReadingCounter,
    /// Robots refused by `allow_robots` so far, and how many of them are
    /// counted in the metrics.
    refused: Option<(RefusedPeers, u64)>,
}

impl LiveIngest {
    /// Builds it from `p`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: IngestParams = p.parse()?;
        no_unknown(
            &params.unknown,
            &[&LINK_FIELDS[..], &["scan_topic", "idle_secs", "laser_offset"]].concat(),
        )?;
        let idle = params
            .idle_secs
            .map(|s| squall_topology::bounds::wait_secs("idle_secs", s, false))
            .transpose()
            .map_err(ParamError::new)?;
        let [x, y, theta] = params.laser_offset;
        let link = Link::from_params(params.link)?;
        let odometry = OdometryTrack::new(&link.odom_frame, &link.base_frame);
        Ok(LiveIngest {
            scan_topic: topic("scan_topic", &params.scan_topic)?,
            link,
            idle,
            heard: false,
            laser_offset: Pose2::new(x, y, theta),
            inputs: None,
            odometry,
            readings: ReadingCounter::default(),
            refused: None,
        })
    }

    /// The reading a ROS 2 scan makes, with odometry interpolated at its
    /// stamp; `None` if the odometry received does not cover it.
    fn ros2_reading(&self, scan: messages::LaserScan) -> Option<LaserReading> {
        let odometry = self.odometry.at(scan.header.stamp)?;
        Some(scan.into_reading(odometry, self.laser_offset))
    }

    /// Emits `reading` if it is one; counts it as malformed otherwise.
    async fn emit(&mut self, reading: Option<LaserReading>, out: &mut Emitter) -> Result<bool, BoxError> {
        match reading {
            Some(r) if r.ranges.len() >= 2 => {
                out.emit("scan", r).await?;
                self.readings.add(1);
                Ok(true)
            }
            _ => {
                out.count("malformed", 1);
                Ok(false)
            }
        }
    }
}

/// The next sample of `subscriber`, or never once it has closed.
async fn next_of(subscriber: &FifoChannelHandler<Sample>) -> Option<Sample> {
    subscriber.recv_async().await.ok()
}

impl Spout for LiveIngest {
    fn declare(&self, d: &mut Declarer) {
        d.output::<LaserReading>("scan");
        self.link.warnings.iter().for_each(|w| _ = d.exposes(w.clone()));
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.readings = ctx.readings("scans", || None);
        let (session, refused) = shared_with_refusals(&self.link.options).await?;
        self.refused = refused.map(|r| (r, 0));
        self.inputs = Some(match self.link.format {
            Format::Ros2 => {
                let node = RosNode::shared(&session, self.link.domain, &self.link.node).await?;
                let fifo = || FifoChannel::new(256);
                Inputs::Ros2 {
                    scans: node.subscription(&self.scan_topic, &rmw_zenoh::LASER_SCAN, fifo()).await?,
                    odometry: node.subscription(&self.link.odom_topic, &rmw_zenoh::ODOMETRY, fifo()).await?,
                    tf: node.subscription(&self.link.tf_topic, &rmw_zenoh::TF_MESSAGE, fifo()).await?,
                    _node: node,
                }
            }
            Format::Squall => {
                Inputs::Squall(session.declare_subscriber(squall_key(&self.scan_topic).to_string()).await?)
            }
        });
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let status = self.next_scan(out).await;
        // Robots refused since (each logged by name as it linked).
        if let Some((refused, counted)) = &mut self.refused {
            let now = refused.load(std::sync::atomic::Ordering::Relaxed);
            out.count("robots_refused", now - *counted);
            *counted = now;
        }
        status
    }
}

impl LiveIngest {
    /// Waits for the next scan (odometry meanwhile) and emits it, or ends.
    async fn next_scan(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        loop {
            let idle = async {
                match self.idle {
                    Some(d) if self.heard => tokio::time::sleep(d).await,
                    _ => std::future::pending().await,
                }
            };
            match self.inputs.as_ref().ok_or("live.ingest: not opened")? {
                Inputs::Squall(scans) => {
                    tokio::select! {
                        sample = scans.recv_async() => {
                            let Ok(sample) = sample else { return Ok(SpoutStatus::Done) };
                            self.heard = true;
                            out.count("scans_received", 1);
                            // A scan no laser could make counts as malformed.
                            let reading = postcard::from_bytes::<LaserReading>(&sample.payload().to_bytes())
                                .ok()
                                .filter(|r| r.check_geometry().is_ok());
                            if self.emit(reading, out).await? {
                                return Ok(SpoutStatus::Continue);
                            }
                        }
                        () = idle => return Ok(SpoutStatus::Done),
                    }
                }
                Inputs::Ros2 { scans, odometry, tf, .. } => {
                    // Odometry first: a robot sends the odometry for a scan
                    // before the scan, and the scan needs it.
                    tokio::select! {
                        biased;
                        Some(sample) = next_of(&tf.subscriber) => {
                            check_attachment(&sample, out);
                            let from_tf = self.odometry.from_tf();
                            if self.odometry.take_tf(&sample.payload().to_bytes()).is_err() {
                                out.count("malformed", 1);
                            }
                            if !from_tf && self.odometry.from_tf() {
                                out.count("odometry_from_tf", 1);
                            }
                        }
                        Some(sample) = next_of(&odometry.subscriber) => {
                            check_attachment(&sample, out);
                            if self.odometry.take_odometry(&sample.payload().to_bytes()).is_err() {
                                out.count("malformed", 1);
                            }
                        }
                        sample = scans.subscriber.recv_async() => {
                            let Ok(sample) = sample else { return Ok(SpoutStatus::Done) };
                            check_attachment(&sample, out);
                            self.heard = true;
                            out.count("scans_received", 1);
                            let reading = match messages::laser_scan(&sample.payload().to_bytes()) {
                                Ok(scan) => match self.ros2_reading(scan) {
                                    Some(r) => Some(r),
                                    None => {
                                        out.count("scans_without_odometry", 1);
                                        continue;
                                    }
                                },
                                Err(_) => None,
                            };
                            if self.emit(reading, out).await? {
                                return Ok(SpoutStatus::Continue);
                            }
                        }
                        () = idle => return Ok(SpoutStatus::Done),
                    }
                }
            }
        }
    }
}

#[derive(Debug, Deserialize)]
struct PublishParams {
    #[serde(flatten)]
    link: LinkParams,
    #[serde(default = "pose_topic")]
    pose_topic: String,
    #[serde(default = "map_topic")]
    map_topic: String,
    /// Send a map at most this often, seconds (0: every one received).
    #[serde(default)]
    map_interval_secs: f64,
    /// The map frame: the poses', the map's and the correction's parent.
    #[serde(default = "map_frame")]
    frame_id: String,
    #[serde(flatten)]
    unknown: toml::Table,
}

/// Where a message goes: a ROS 2 publisher, or a plain key.
#[derive(Debug)]
enum Out {
    Ros2(RosPublisher),
    Squall(zenoh::pubsub::Publisher<'static>),
}

impl Out {
    /// Sends `bytes` if anyone subscribes, counting it as `sent` or, with
    /// no subscriber (zenoh would drop it without a word), as `unheard`;
    /// whether it was sent.
    async fn send_counted(
        &mut self,
        bytes: Vec<u8>,
        out: &mut Emitter,
        names: (&str, &str),
    ) -> Result<bool, BoxError> {
        match self {
            Out::Ros2(p) => send_ros2(p, bytes, out, names).await,
            Out::Squall(p) => {
                if !p.matching_status().await?.matching() {
                    out.count(names.1, 1);
                    return Ok(false);
                }
                p.put(bytes).await?;
                out.count(names.0, 1);
                Ok(true)
            }
        }
    }
}

/// [`Out::send_counted`] for a ROS 2 publisher. A transient-local one
/// (the map) publishes even when nobody listens: its cache keeps the
/// sample for a subscriber that comes later (counted as `unheard` all the
/// same).
async fn send_ros2(
    p: &mut RosPublisher,
    bytes: Vec<u8>,
    out: &mut Emitter,
    (sent, unheard): (&str, &str),
) -> Result<bool, BoxError> {
    let matching = p.matching().await?;
    if matching || p.transient_local() {
        p.put(bytes).await?;
    }
    out.count(if matching { sent } else { unheard }, 1);
    Ok(matching)
}

/// `live.publish`'s publishers, and in the ROS 2 format the transform
/// publisher and the odometry it places the correction with.
#[derive(Debug)]
struct Outputs {
    poses: Out,
    maps: Out,
    ros2: Option<Ros2Outputs>,
}

#[derive(Debug)]
struct Ros2Outputs {
    _node: std::sync::Arc<RosNode>,
    tf: RosPublisher,
    odometry: RosSubscription<RingChannelHandler<Sample>>,
    transforms: RosSubscription<RingChannelHandler<Sample>>,
    track: OdometryTrack,
}

/// `live.publish`: every `PoseStamped` it receives goes to the robot on
/// `pose_topic`, and in the ROS 2 format the correction `map → odom` (the
/// pose composed with the inverse of the robot's odometry at its stamp)
/// on `/tf`; `OccupancyGrid`s (the best particle's map) on `map_topic`, at
/// most every `map_interval_secs` (those in between are skipped and
/// counted). A message waits for room on a busy link rather than being
/// dropped; one that no subscriber would receive (no robot listening) is
/// not sent and is counted instead. Metrics: `poses_sent`,
/// `poses_unheard`, `transforms_sent`, `transforms_unheard`,
/// `transforms_without_odometry`, `maps_sent`, `maps_unheard`,
/// `maps_skipped`, `map_bytes`.
#[derive(Debug)]
pub struct LivePublish {
    link: Link,
    topics: (String, String),
    map_interval: Duration,
    last_map: Option<std::time::Instant>,
    frame_id: String,
    outputs: Option<Outputs>,
}

impl LivePublish {
    /// Builds it from `p`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: PublishParams = p.parse()?;
        let own = ["pose_topic", "map_topic", "map_interval_secs", "frame_id"];
        no_unknown(&params.unknown, &[&LINK_FIELDS[..], &own].concat())?;
        let map_interval =
            squall_topology::bounds::wait_secs("map_interval_secs", params.map_interval_secs, true)
                .map_err(ParamError::new)?;
        Ok(LivePublish {
            topics: (topic("pose_topic", &params.pose_topic)?, topic("map_topic", &params.map_topic)?),
            link: Link::from_params(params.link)?,
            map_interval,
            last_map: None,
            frame_id: params.frame_id,
            outputs: None,
        })
    }

    /// Sends the correction `map → odom` that puts the robot's odometry at
    /// `pose` (in the ROS 2 format).
    async fn send_correction(&mut self, pose: &PoseStamped, out: &mut Emitter) -> Result<(), BoxError> {
        let Some(ros2) = self.outputs.as_mut().and_then(|o| o.ros2.as_mut()) else { return Ok(()) };
        // The odometry heard since the last pose (the ring keeps the
        // newest when nobody takes them).
        while let Ok(Some(sample)) = ros2.transforms.subscriber.try_recv() {
            let _ = ros2.track.take_tf(&sample.payload().to_bytes());
        }
        while let Ok(Some(sample)) = ros2.odometry.subscriber.try_recv() {
            let _ = ros2.track.take_odometry(&sample.payload().to_bytes());
        }
        let Some(odometry) = ros2.track.at(pose.stamp) else {
            out.count("transforms_without_odometry", 1);
            return Ok(());
        };
        let correction = pose.pose.compose(&odometry.inverse());
        let bytes = messages::tf_message_cdr(&[messages::TransformOut {
            stamp: pose.stamp,
            frame_id: &self.frame_id,
            child_frame_id: &self.link.odom_frame,
            pose: correction,
        }]);
        send_ros2(&mut ros2.tf, bytes, out, ("transforms_sent", "transforms_unheard")).await?;
        Ok(())
    }
}

impl Bolt for LivePublish {
    fn declare(&self, d: &mut Declarer) {
        d.input::<PoseStamped>().input::<OccupancyGrid>();
        self.link.warnings.iter().for_each(|w| _ = d.exposes(w.clone()));
    }

    async fn prepare(&mut self, _ctx: &TaskContext) -> Result<(), BoxError> {
        let session = shared(&self.link.options).await?;
        let (pose_topic, map_topic) = &self.topics;
        self.outputs = Some(match self.link.format {
            Format::Ros2 => {
                let node = RosNode::shared(&session, self.link.domain, &self.link.node).await?;
                // tf2's broadcasters keep 100 transforms.
                let tf_qos = Qos { depth: 100, ..Qos::DEFAULT };
                let ring = || RingChannel::new(256);
                Outputs {
                    poses: Out::Ros2(
                        node.publisher(pose_topic, &rmw_zenoh::POSE_STAMPED, Qos::DEFAULT).await?,
                    ),
                    maps: Out::Ros2(node.publisher(map_topic, &rmw_zenoh::OCCUPANCY_GRID, Qos::MAP).await?),
                    ros2: Some(Ros2Outputs {
                        tf: node.publisher(&self.link.tf_topic, &rmw_zenoh::TF_MESSAGE, tf_qos).await?,
                        odometry: node
                            .subscription(&self.link.odom_topic, &rmw_zenoh::ODOMETRY, ring())
                            .await?,
                        transforms: node
                            .subscription(&self.link.tf_topic, &rmw_zenoh::TF_MESSAGE, ring())
                            .await?,
                        track: OdometryTrack::new(&self.link.odom_frame, &self.link.base_frame),
                        _node: node,
                    }),
                }
            }
            Format::Squall => {
                let declare = |topic: &String| {
                    session
                        .declare_publisher(squall_key(topic).to_string())
                        .congestion_control(zenoh::qos::CongestionControl::Block)
                };
                Outputs {
                    poses: Out::Squall(declare(pose_topic).await?),
                    maps: Out::Squall(declare(map_topic).await?),
                    ros2: None,
                }
            }
        });
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let format = self.link.format;
        if let Some(pose) = input.get::<PoseStamped>() {
            let bytes = match format {
                Format::Ros2 => messages::pose_stamped(pose.stamp, &self.frame_id, &pose.pose),
                Format::Squall => postcard::to_stdvec(pose)?,
            };
            let outputs = self.outputs.as_mut().ok_or("live.publish: not prepared")?;
            outputs.poses.send_counted(bytes, out, ("poses_sent", "poses_unheard")).await?;
            return self.send_correction(pose, out).await;
        }
        let map = input.get::<OccupancyGrid>().ok_or("live.publish takes PoseStamped and OccupancyGrid")?;
        if self.last_map.is_some_and(|at| at.elapsed() < self.map_interval) {
            // A newer one will follow; the robot gets maps at the interval.
            out.count("maps_skipped", 1);
            return Ok(());
        }
        self.last_map = Some(std::time::Instant::now());
        let bytes = match format {
            Format::Ros2 => messages::occupancy_grid(&messages::OccupancyGridMsg {
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
        let outputs = self.outputs.as_mut().ok_or("live.publish: not prepared")?;
        if outputs.maps.send_counted(bytes, out, ("maps_sent", "maps_unheard")).await? {
            out.count("map_bytes", length);
        }
        Ok(())
    }
}
