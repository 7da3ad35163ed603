//! `squall robot`: plays a log as a robot would over the live link (scans
//! and odometry published in real time, or faster), takes the poses that
//! come back, and reports the round trip (scan sent → its pose received)
//! and the readings that got no pose (dropped by a live dispatcher, or
//! lost).

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use squall_core::sensor::{LaserReading, PoseStamped};
use squall_spouts::carmen::{ReadOptions, read_front_scans};
use squall_spouts::live::node::RosNode;
use squall_spouts::live::{Format, MAP_TOPIC, ODOM_TOPIC, POSE_TOPIC, SCAN_TOPIC, squall_key};
use squall_spouts::rmw_zenoh::{self, Qos};
use squall_spouts::rosbag2::messages;
use squall_topology::cluster::config::{
    LIVE_LINK_RISK, exposed_endpoint, exposure_refusal, exposure_warning,
};
use squall_topology::cluster::session::{SessionOptions, endpoints, open};

use super::tls::TlsArgs;
use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct RobotArgs {
    /// The log to play (CARMEN .clf or .clf.gz).
    #[arg(long, value_name = "FILE")]
    log: PathBuf,
    /// The topology's live link endpoint (repeatable).
    #[arg(long, value_name = "ENDPOINT", required = true)]
    connect: Vec<String>,
    /// `ros2` (a ROS 2 robot over rmw_zenoh: `/scan`, `/odom` in, `/pose`,
    /// `/map` back) or `squall` (squall's own messages). `cdr` is `ros2`.
    #[arg(long, default_value = "ros2", value_parser = ["ros2", "cdr", "squall"])]
    format: String,
    /// Playback speed: 1 is the log's own pace.
    #[arg(long, default_value_t = 1.0, value_parser = super::numbers::speed)]
    speed: f64,
    /// Play only the first N scans.
    #[arg(long, value_name = "N")]
    max_scans: Option<usize>,
    /// How long to wait for the last poses after the last scan, seconds, at
    /// most: the wait ends when the last scan's pose arrives.
    #[arg(long, default_value_t = 5.0, value_parser = super::numbers::wait_secs)]
    wait_secs: f64,
    /// How long to wait for the link to come up, seconds.
    #[arg(long, default_value_t = 20.0, value_parser = super::numbers::positive_wait_secs)]
    connect_secs: f64,
    #[command(flatten)]
    tls: TlsArgs,
    /// Allow a plain tcp/ endpoint beyond loopback, without mutual TLS: on
    /// a network you trust only (anyone on it can read the scans and send
    /// false poses). Warns at start.
    #[arg(long)]
    insecure: bool,
}

/// A stamp as a key that survives CDR's seconds + nanoseconds.
fn stamp_key(stamp: f64) -> i64 {
    (stamp * 1e6).round() as i64
}

/// Runs `squall robot`.
pub(super) fn robot(args: &RobotArgs) -> ExitCode {
    let connect = match endpoints(&args.connect) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let tls = match args.tls.spec(&connect) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    if let Some(exposed) = exposed_endpoint(&connect) {
        if !args.insecure {
            eprintln!("error: {}", exposure_refusal(exposed, LIVE_LINK_RISK, "pass --insecure"));
            return ExitCode::from(EXIT_INVALID);
        }
        for e in connect.iter().filter(|e| e.is_exposed()) {
            let warning = exposure_warning(e, LIVE_LINK_RISK);
            eprintln!("warning: {warning} (--insecure)");
        }
    }
    if !(args.speed.is_finite() && args.speed > 0.0) {
        eprintln!("error: --speed {}: expected a factor > 0", args.speed);
        return ExitCode::from(EXIT_INVALID);
    }
    let format = if args.format == "squall" { Format::Squall } else { Format::Ros2 };
    let mut scans = match read_front_scans(&args.log, ReadOptions::default()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    scans.truncate(args.max_scans.unwrap_or(usize::MAX));
    let runtime = match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot start the runtime: {e}");
            return ExitCode::from(EXIT_FAILED);
        }
    };
    match runtime.block_on(play(
        args,
        SessionOptions { connect, listen: Vec::new(), tls, allow: None },
        format,
        &scans,
    )) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_FAILED)
        }
    }
}

async fn play(
    args: &RobotArgs,
    options: SessionOptions,
    format: Format,
    scans: &[LaserReading],
) -> anyhow::Result<()> {
    let session = open(&options).await?;
    let zenoh_error = |e: zenoh::Error| anyhow::anyhow!("{e}");
    let boxed = |e: squall_topology::BoxError| anyhow::anyhow!("{e}");
    let fifo = || zenoh::handlers::FifoChannel::new(1024);
    // As a ROS 2 robot over rmw_zenoh: the node `squall_robot` with its
    // publishers and subscriptions; or squall's plain keys.
    let (_node, poses, maps, mut scan_publisher, mut odom_publisher) = match format {
        Format::Ros2 => {
            let node = RosNode::shared(&session, 0, "squall_robot").await.map_err(boxed)?;
            let poses =
                node.subscription(POSE_TOPIC, &rmw_zenoh::POSE_STAMPED, fifo()).await.map_err(boxed)?;
            let maps =
                node.subscription(MAP_TOPIC, &rmw_zenoh::OCCUPANCY_GRID, fifo()).await.map_err(boxed)?;
            let scan =
                node.publisher(SCAN_TOPIC, &rmw_zenoh::LASER_SCAN, Qos::DEFAULT).await.map_err(boxed)?;
            let odom = node.publisher(ODOM_TOPIC, &rmw_zenoh::ODOMETRY, Qos::DEFAULT).await.map_err(boxed)?;
            (Some(node), Subscription::Ros2(poses), Subscription::Ros2(maps), Sender::Ros2(scan), Some(odom))
        }
        Format::Squall => {
            let subscribe =
                |topic: &str| session.declare_subscriber(squall_key(topic).to_string()).with(fifo());
            let poses = subscribe(POSE_TOPIC).await.map_err(zenoh_error)?;
            let maps = subscribe(MAP_TOPIC).await.map_err(zenoh_error)?;
            let scan =
                session.declare_publisher(squall_key(SCAN_TOPIC).to_string()).await.map_err(zenoh_error)?;
            (None, Subscription::Squall(poses), Subscription::Squall(maps), Sender::Squall(scan), None)
        }
    };
    let (poses, maps) = (poses.handler(), maps.handler());
    // Drive only once the topology subscribes to the scans: what is
    // published before that reaches nobody.
    let deadline = Instant::now() + Duration::from_secs_f64(args.connect_secs);
    while !scan_publisher.matching().await? {
        anyhow::ensure!(
            Instant::now() < deadline,
            "no link to a topology taking scans at {:?} after {} s",
            args.connect,
            args.connect_secs
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut sent: HashMap<i64, Instant> = HashMap::new();
    let mut latencies = Vec::new();
    let mut malformed = 0u64;
    let mut take = |sample: zenoh::sample::Sample, sent: &HashMap<i64, Instant>, latencies: &mut Vec<f64>| {
        let bytes = sample.payload().to_bytes();
        let stamp = match format {
            Format::Ros2 => messages::read_pose_stamped(&bytes).map(|(h, _)| h.stamp).ok(),
            Format::Squall => postcard::from_bytes::<PoseStamped>(&bytes).map(|p| p.stamp).ok(),
        };
        let key = stamp.map(stamp_key);
        match key.and_then(|k| sent.get(&k)) {
            Some(at) => latencies.push(at.elapsed().as_secs_f64() * 1e3),
            None => malformed += 1,
        }
        key
    };
    let started = Instant::now();
    let first = scans.first().map_or(0.0, |s| s.stamp);
    for scan in scans {
        let due = started + Duration::from_secs_f64(((scan.stamp - first) / args.speed).max(0.0));
        loop {
            let wait = due.saturating_duration_since(Instant::now());
            if wait.is_zero() {
                break;
            }
            if let Ok(Ok(sample)) = tokio::time::timeout(wait, poses.recv_async()).await {
                let _ = take(sample, &sent, &mut latencies);
            }
        }
        sent.insert(stamp_key(scan.stamp), Instant::now());
        match (format, &mut odom_publisher) {
            (Format::Ros2, Some(odom)) => {
                let odometry = messages::odometry_cdr(scan.stamp, "odom", "base_link", &scan.odometry);
                odom.put(odometry).await.map_err(boxed)?;
                scan_publisher.put(messages::laser_scan_cdr(scan, "laser")).await?;
            }
            _ => scan_publisher.put(postcard::to_stdvec(scan)?).await?,
        }
    }
    // A live topology may drop readings while it is busy (and counts
    // them) but never the newest, and poses come in order: once the last
    // scan's pose is here, every pose that will come has.
    let last = scans.last().map(|s| stamp_key(s.stamp));
    let end = Instant::now() + Duration::from_secs_f64(args.wait_secs);
    while latencies.len() < scans.len() {
        let wait = end.saturating_duration_since(Instant::now());
        match tokio::time::timeout(wait, poses.recv_async()).await {
            Ok(Ok(sample)) => {
                if take(sample, &sent, &mut latencies) == last {
                    break;
                }
            }
            _ => break,
        }
    }
    let (mut map_count, mut map_bytes) = (0, 0);
    while let Ok(Some(map)) = maps.try_recv() {
        map_count += 1;
        map_bytes = map.payload().len();
    }
    let _ = session.close().await;
    let answered = latencies.len();
    latencies.sort_by(f64::total_cmp);
    let at =
        |q: f64| latencies.get(((answered as f64 - 1.0) * q).round() as usize).copied().unwrap_or(f64::NAN);
    outln!("scans sent: {}", scans.len());
    outln!("poses received: {answered}");
    outln!("readings without a pose: {}", scans.len() - answered.min(scans.len()));
    outln!("round trip ms: p50 {:.1}, p90 {:.1}, max {:.1}", at(0.5), at(0.9), at(1.0));
    outln!("maps received: {map_count} (the last {map_bytes} bytes)");
    if malformed > 0 {
        outln!("poses not matching a scan sent: {malformed}");
    }
    Ok(())
}

/// Where the robot's scans go.
enum Sender {
    Ros2(squall_spouts::live::node::RosPublisher),
    Squall(zenoh::pubsub::Publisher<'static>),
}

impl Sender {
    async fn matching(&self) -> anyhow::Result<bool> {
        match self {
            Sender::Ros2(p) => p.matching().await.map_err(|e| anyhow::anyhow!("{e}")),
            Sender::Squall(p) => {
                Ok(p.matching_status().await.map_err(|e| anyhow::anyhow!("{e}"))?.matching())
            }
        }
    }

    async fn put(&mut self, bytes: Vec<u8>) -> anyhow::Result<()> {
        match self {
            Sender::Ros2(p) => p.put(bytes).await.map_err(|e| anyhow::anyhow!("{e}")),
            Sender::Squall(p) => p.put(bytes).await.map_err(|e| anyhow::anyhow!("{e}")),
        }
    }
}

type Fifo = zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>;

/// What the robot hears back.
enum Subscription {
    Ros2(squall_spouts::live::node::RosSubscription<Fifo>),
    Squall(zenoh::pubsub::Subscriber<Fifo>),
}

impl Subscription {
    fn handler(&self) -> &Fifo {
        match self {
            Subscription::Ros2(s) => s.subscriber.handler(),
            Subscription::Squall(s) => s.handler(),
        }
    }
}
