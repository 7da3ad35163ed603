//! The live robot link end to end: `squall run` on the live SLAM topology
//! and `squall robot` playing ACES scans to it over zenoh on loopback,
//! in ROS 2 CDR and in squall's own format. Poses come back for the
//! scans, the map comes back while the robot drives, the round trip is
//! reported, and the run writes its map.
#![cfg(feature = "cluster")]

mod common;

use std::path::Path;
use std::process::{Command, Stdio};

use common::{finish_within, free_port, output_within};

/// How long a run or a robot may take before the test fails as hung.
const HUNG: std::time::Duration = std::time::Duration::from_secs(120);

/// Runs `command` to its end (at most [`HUNG`]), capturing what it prints.
fn output(command: &mut Command) -> std::process::Output {
    output_within(command, HUNG, String::new)
}

fn aces() -> std::path::PathBuf {
    let log = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/laser/aces.clf");
    assert!(log.exists(), "missing {}: this test plays the shared data's ACES log", log.display());
    log
}

/// `squall run` on the live SLAM topology, both link components on
/// `listen`, with more `--set`s, writing to `out`.
fn start_live(listen: &str, sets: &[String], out: &Path) -> std::process::Child {
    let topology = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/topologies/live_slam.toml");
    let mut run = Command::new(env!("CARGO_BIN_EXE_squall"));
    run.arg("run").arg(&topology);
    let links = [format!("source.params.listen={listen}"), format!("publish.params.listen={listen}")];
    for set in links.iter().chain(sets) {
        run.args(["--set", set]);
    }
    run.args(["--quiet", "--out"])
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("squall run starts")
}

/// Runs the topology and the robot; returns the robot's report and the
/// run's metrics.
fn round_trip(format: &str, scans: usize) -> (String, serde_json::Value) {
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let listen = format!("[\"{endpoint}\"]");
    let out = tempfile::tempdir().unwrap();
    let sets = [
        format!("source.params.format=\"{format}\""),
        format!("publish.params.format=\"{format}\""),
        "source.params.idle_secs=3.0".to_string(),
        "matcher.params.map_interval=2".to_string(),
    ];
    let run = start_live(&listen, &sets, out.path());
    let robot = output(
        Command::new(env!("CARGO_BIN_EXE_squall"))
            .args(["robot", "--log"])
            .arg(aces())
            .args(["--connect", &endpoint, "--format", format, "--speed", "5", "--wait-secs", "60"])
            .args(["--max-scans", &scans.to_string()]),
    );
    let ran = finish_within(run, HUNG, String::new);
    let report = String::from_utf8_lossy(&robot.stdout).to_string();
    assert!(robot.status.success(), "robot: {report}{}", String::from_utf8_lossy(&robot.stderr));
    assert!(ran.status.success(), "run: {}", String::from_utf8_lossy(&ran.stderr));
    assert!(out.path().join("map.pgm").exists() && out.path().join("trajectory.tum").exists());
    (report, metrics_in(out.path()))
}

fn number(report: &str, label: &str) -> usize {
    let line =
        report.lines().find(|l| l.starts_with(label)).unwrap_or_else(|| panic!("no {label:?} in {report}"));
    line[label.len()..].trim().parse().unwrap_or_else(|_| panic!("{line}"))
}

fn custom(metrics: &serde_json::Value, component: &str, name: &str) -> u64 {
    let c = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == component).unwrap();
    c["custom"][name].as_u64().unwrap_or(0)
}

#[test]
fn a_robot_gets_a_pose_back_for_its_scans_in_cdr_and_in_squalls_format() {
    for format in ["ros2", "squall"] {
        let scans = 150;
        let (report, metrics) = round_trip(format, scans);
        assert_eq!(number(&report, "scans sent:"), scans, "{report}");
        let poses = number(&report, "poses received:");
        let without = number(&report, "readings without a pose:");
        // Everything the source took got a pose, but for what the live
        // dispatcher dropped (counted) while the matchers were busy.
        let received = custom(&metrics, "source", "scans_received") as usize;
        let dropped = custom(&metrics, "dispatcher", "dropped_readings") as usize;
        assert_eq!(received, scans, "{format}: {report}");
        assert_eq!(poses + dropped, scans, "{format}: {report} (dropped {dropped})");
        assert_eq!(without, dropped, "{format}: {report}");
        // How many the dispatcher drops depends on the machine's load;
        // the first scan finds the matchers idle.
        assert!(poses >= 1, "{format}: {report}");
        // Every pose sent arrived, and none went unheard: the robot listened.
        assert_eq!(custom(&metrics, "publish", "poses_sent") as usize, poses, "{format}: {report}");
        assert_eq!(custom(&metrics, "publish", "poses_unheard"), 0, "{format}: {report}");
        assert!(report.contains("round trip ms: p50"), "{report}");
        // The best particle's map came back while the robot was driving.
        let maps = report.lines().find_map(|l| l.strip_prefix("maps received: ")).unwrap();
        let count: usize = maps.split_whitespace().next().unwrap().parse().unwrap();
        assert!(count >= 1, "{format}: {report}");
        assert!(custom(&metrics, "publish", "maps_sent") as usize >= count, "{format}");
        eprintln!("{format}: {}", report.replace('\n', "; "));
    }
}

/// Runs the live topology and the independent ROS 2 client (written from
/// rmw_zenoh's design with the eclipse-zenoh package, messages by
/// `rosbags`, GIDs by `xxhash`; `./test.sh` installs all three, pinned)
/// with `args`; returns the client's report and the run's metrics.
fn python_round_trip(args: &[&str]) -> (serde_json::Value, serde_json::Value) {
    let check = Command::new("python3").args(["-c", "import zenoh, rosbags, xxhash"]).output();
    assert!(
        check.as_ref().is_ok_and(|o| o.status.success()),
        "this test needs python3 with eclipse-zenoh, rosbags and xxhash (./test.sh installs them: tests/clients/requirements.txt)"
    );
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let listen = format!("[\"{endpoint}\"]");
    let out = tempfile::tempdir().unwrap();
    // A map at every correction (at most every 2 s): some go out while
    // nobody listens on /map, for the late subscriber to find cached.
    // The run outlasts the client's wait for its last pose and its late
    // subscription to /map by its idle time.
    let sets = ["source.params.idle_secs=10.0".to_string(), "matcher.params.map_interval=1".to_string()];
    let run = start_live(&listen, &sets, out.path());
    let client = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/ros2_robot.py");
    let robot = output(Command::new("python3").arg(client).args(["--connect", &endpoint]).args(args));
    let ran = finish_within(run, HUNG, String::new);
    let stdout = String::from_utf8_lossy(&robot.stdout);
    assert!(robot.status.success(), "client: {stdout}{}", String::from_utf8_lossy(&robot.stderr));
    assert!(ran.status.success(), "run: {}", String::from_utf8_lossy(&ran.stderr));
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let metrics = metrics_in(out.path());
    (report, metrics)
}

/// The client's last pose: the robot drove 2.95 m along the corridor.
fn assert_drove_the_corridor(report: &serde_json::Value) {
    let last = report["last_pose"].as_array().unwrap();
    let (x, y) = (last[1].as_f64().unwrap(), last[2].as_f64().unwrap());
    assert!((x - 2.95).abs() < 0.1 && y.abs() < 0.05, "{report}");
}

#[test]
#[cfg_attr(
    not(feature = "client-tests"),
    ignore = "needs the Python ROS 2 client (feature client-tests; ./test.sh runs it)"
)]
fn a_ros_2_client_finds_squall_in_the_graph_and_gets_poses_transforms_and_the_map() {
    let (report, metrics) = python_round_trip(&["--scans", "60"]);
    // squall's node, publishers and subscriptions, as the client read them
    // from the liveliness tokens, with the type hashes rosbags computes.
    let entities: Vec<&str> =
        report["squall_entities"].as_array().unwrap().iter().map(|e| e.as_str().unwrap()).collect();
    let hash = |ty: &str| report["expected_hashes"][ty].as_str().unwrap().to_string();
    let expected = [
        "NN".to_string(),
        format!(
            "MS /scan sensor_msgs::msg::dds_::LaserScan_ {} ::,10:,:,:,,",
            hash("sensor_msgs/msg/LaserScan")
        ),
        format!("MS /odom nav_msgs::msg::dds_::Odometry_ {} ::,10:,:,:,,", hash("nav_msgs/msg/Odometry")),
        format!("MS /tf tf2_msgs::msg::dds_::TFMessage_ {} ::,10:,:,:,,", hash("tf2_msgs/msg/TFMessage")),
        format!(
            "MP /pose geometry_msgs::msg::dds_::PoseStamped_ {} ::,10:,:,:,,",
            hash("geometry_msgs/msg/PoseStamped")
        ),
        format!(
            "MP /map nav_msgs::msg::dds_::OccupancyGrid_ {} :1:,1:,:,:,,",
            hash("nav_msgs/msg/OccupancyGrid")
        ),
        format!("MP /tf tf2_msgs::msg::dds_::TFMessage_ {} ::,100:,:,:,,", hash("tf2_msgs/msg/TFMessage")),
    ];
    for e in &expected {
        assert!(entities.iter().filter(|x| *x == e).count() >= 1, "no {e:?} in {entities:?}");
    }
    // Every sample carried rmw_zenoh's attachment, in sequence, with the
    // GID of its publisher's token; squall took the client's as such.
    assert_eq!(report["attachment_errors"], serde_json::json!([]), "{report}");
    assert_eq!(custom(&metrics, "source", "without_attachment"), 0, "{metrics}");
    assert_eq!(custom(&metrics, "source", "malformed"), 0, "{metrics}");
    // A pose for every scan the live dispatcher kept, in the map frame.
    let poses = report["poses_received"].as_u64().unwrap();
    let dropped = custom(&metrics, "dispatcher", "dropped_readings");
    assert_eq!(custom(&metrics, "source", "scans_received"), 60, "{report}");
    assert_eq!(poses + dropped, 60, "{report}");
    assert!(poses >= 1, "{report}");
    assert_eq!(report["pose_frames"], serde_json::json!(["map"]), "{report}");
    assert_drove_the_corridor(&report);
    // map -> odom at the pose rate: composed with the robot's odometry at
    // the same stamp, it is the pose.
    let matched = report["transforms_matched"].as_u64().unwrap();
    assert_eq!(matched, custom(&metrics, "publish", "transforms_sent"), "{report}");
    assert!(report["tf_max_error"].as_f64().unwrap() < 1e-6, "{report}");
    assert_eq!(
        custom(&metrics, "publish", "transforms_sent")
            + custom(&metrics, "publish", "transforms_without_odometry"),
        custom(&metrics, "publish", "poses_sent"),
        "{metrics}"
    );
    // The map, to a subscriber that joined after it was sent
    // (transient-local), whole and in the map frame.
    let map = &report["late_map"];
    assert_eq!(map["frame"], "map", "{report}");
    assert_eq!(
        map["sent_before_joining"], true,
        "the first map the late subscriber got was not the cached one: {report}"
    );
    let cells = map["width"].as_u64().unwrap() * map["height"].as_u64().unwrap();
    assert!(cells > 0 && map["cells"].as_u64() == Some(cells), "{report}");
    assert!(
        map["occupied"].as_u64().unwrap() > 0 && map["known"].as_u64() > map["occupied"].as_u64(),
        "{report}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "client-tests"),
    ignore = "needs the Python ROS 2 client (feature client-tests; ./test.sh runs it)"
)]
fn the_robots_own_odom_to_base_link_on_tf_is_its_odometry() {
    let (report, metrics) = python_round_trip(&["--scans", "60", "--odometry", "tf"]);
    assert_eq!(custom(&metrics, "source", "odometry_from_tf"), 1, "{metrics}");
    assert_eq!(custom(&metrics, "source", "scans_without_odometry"), 0, "{metrics}");
    let poses = report["poses_received"].as_u64().unwrap();
    assert_eq!(poses + custom(&metrics, "dispatcher", "dropped_readings"), 60, "{report}");
    assert!(poses >= 1, "{report}");
    assert_drove_the_corridor(&report);
    assert!(report["tf_max_error"].as_f64().unwrap() < 1e-6, "{report}");
}

#[test]
#[cfg_attr(
    not(feature = "client-tests"),
    ignore = "needs the Python ROS 2 client (feature client-tests; ./test.sh runs it)"
)]
fn poses_no_robot_listens_for_are_counted_as_unheard_not_sent() {
    let (report, metrics) = python_round_trip(&["--scans", "40", "--ignore-poses"]);
    assert_eq!(report["poses_received"].as_u64(), Some(0), "{report}");
    let dropped = custom(&metrics, "dispatcher", "dropped_readings");
    assert_eq!(custom(&metrics, "source", "scans_received"), 40, "{report}");
    // A pose for every reading taken, none of them claimed as sent; nor
    // the corrections, although squall itself listens on /tf.
    assert_eq!(custom(&metrics, "publish", "poses_unheard") + dropped, 40, "{metrics}");
    assert_eq!(custom(&metrics, "publish", "poses_sent"), 0, "{metrics}");
    assert_eq!(custom(&metrics, "publish", "transforms_sent"), 0, "{metrics}");
}

/// The `tls` inline table of the topology's side of the link, with
/// `squall`'s certificate from the authority `ca` made in `certs`.
fn link_tls(certs: &Path) -> String {
    let file = |name: &str| certs.join(name).display().to_string();
    format!(
        "{{ root_ca = {:?}, certificate = {:?}, private_key = {:?} }}",
        file("ca.pem"),
        file("squall.pem"),
        file("squall.key")
    )
}

/// `squall robot` over TLS to `endpoint` as `name` (its certificate in
/// `certs`), trusting the authority `ca`, playing `scans` scans.
fn robot_over_tls(
    certs: &Path,
    endpoint: &str,
    (name, ca): (&str, &str),
    scans: &str,
    connect_secs: &str,
) -> std::process::Output {
    let file = |name: String| certs.join(name).display().to_string();
    output(
        Command::new(env!("CARGO_BIN_EXE_squall"))
            .args(["robot", "--log"])
            .arg(aces())
            .args(["--connect", endpoint, "--max-scans", scans, "--speed", "5", "--wait-secs", "60"])
            .args(["--connect-secs", connect_secs, "--tls-ca", &file(format!("{ca}.pem"))])
            .args(["--tls-cert", &file(format!("{name}.pem")), "--tls-key", &file(format!("{name}.key"))]),
    )
}

/// The metrics.json a run wrote into `dir`.
fn metrics_in(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap()
}

#[test]
fn over_tls_the_link_takes_a_member_and_keeps_a_rogue_out() {
    let certs = tempfile::tempdir().unwrap();
    common::certs::authority(certs.path(), "ca", &["squall", "robot"]);
    common::certs::authority(certs.path(), "rogue_ca", &["rogue"]);
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let listen = format!("[\"{endpoint}\"]");
    let tls = link_tls(certs.path());
    let out = tempfile::tempdir().unwrap();
    let sets = [
        format!("source.params.tls={tls}"),
        format!("publish.params.tls={tls}"),
        "source.params.idle_secs=2.0".to_string(),
    ];
    let run = start_live(&listen, &sets, out.path());
    let robot = |name: &str, ca: &str, scans: &str, connect_secs: &str| {
        robot_over_tls(certs.path(), &endpoint, (name, ca), scans, connect_secs)
    };
    // A rogue that trusts the cluster's authority but holds another's
    // certificate gets no link. The topology outwaits it: its idle timer
    // starts at the first scan.
    let rogue = robot("rogue", "ca", "20", "3");
    assert_eq!(rogue.status.code(), Some(1), "{}", String::from_utf8_lossy(&rogue.stdout));
    assert!(
        String::from_utf8_lossy(&rogue.stderr).contains("no link"),
        "{}",
        String::from_utf8_lossy(&rogue.stderr)
    );
    let member = robot("robot", "ca", "60", "20");
    let report = String::from_utf8_lossy(&member.stdout).to_string();
    assert!(member.status.success(), "{report}{}", String::from_utf8_lossy(&member.stderr));
    let ran = finish_within(run, HUNG, String::new);
    assert!(ran.status.success(), "run: {}", String::from_utf8_lossy(&ran.stderr));
    let metrics = metrics_in(out.path());
    // Only the member's scans reached the topology, and it got poses back.
    assert_eq!(custom(&metrics, "source", "scans_received"), 60, "{report}");
    assert_every_scan_answered_or_dropped(&report, &metrics, 60);
}

#[test]
fn with_an_allowlist_the_link_takes_only_the_robots_it_names_and_counts_the_others() {
    let certs = tempfile::tempdir().unwrap();
    common::certs::authority(certs.path(), "ca", &["squall", "robot", "intruder"]);
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let listen = format!("[\"{endpoint}\"]");
    let tls = link_tls(certs.path());
    let out = tempfile::tempdir().unwrap();
    let sets = [
        format!("source.params.tls={tls}"),
        format!("publish.params.tls={tls}"),
        "source.params.allow_robots=[\"robot\"]".to_string(),
        "publish.params.allow_robots=[\"robot\"]".to_string(),
        "source.params.idle_secs=2.0".to_string(),
    ];
    let run = start_live(&listen, &sets, out.path());
    let robot = |name: &str, scans: &str, connect_secs: &str| {
        robot_over_tls(certs.path(), &endpoint, (name, "ca"), scans, connect_secs)
    };
    // An intruder with a certificate from the same authority links, but
    // nothing it sends is taken and no topology answers it.
    let intruder = robot("intruder", "20", "3");
    assert_eq!(intruder.status.code(), Some(1), "{}", String::from_utf8_lossy(&intruder.stderr));
    let member = robot("robot", "40", "20");
    let report = String::from_utf8_lossy(&member.stdout).to_string();
    assert!(member.status.success(), "{report}{}", String::from_utf8_lossy(&member.stderr));
    let ran = finish_within(run, HUNG, String::new);
    let run_log = String::from_utf8_lossy(&ran.stderr).to_string();
    assert!(ran.status.success(), "run: {run_log}");
    assert!(run_log.contains("refused peer \"intruder\""), "{run_log}");
    let metrics = metrics_in(out.path());
    assert_eq!(custom(&metrics, "source", "scans_received"), 40, "{report}");
    assert!(custom(&metrics, "source", "robots_refused") >= 1, "{}", metrics["components"]);
    assert_every_scan_answered_or_dropped(&report, &metrics, 40);
}

/// What holds whatever the machine's pace: each of the robot's `scans`
/// got a pose back or was dropped by the live dispatcher while the
/// matchers were busy (counted), every pose sent arrived, and the first
/// scan, which finds the matchers idle, was answered. How many are
/// dropped depends on the machine's load, so no share is asserted.
fn assert_every_scan_answered_or_dropped(report: &str, metrics: &serde_json::Value, scans: usize) {
    assert_eq!(number(report, "scans sent:"), scans, "{report}");
    let poses = number(report, "poses received:");
    let dropped = custom(metrics, "dispatcher", "dropped_readings") as usize;
    assert_eq!(poses + dropped, scans, "{report} (dropped {dropped})");
    assert_eq!(number(report, "readings without a pose:"), dropped, "{report}");
    assert_eq!(custom(metrics, "publish", "poses_sent") as usize, poses, "{report}");
    assert!(poses >= 1, "{report}");
}
