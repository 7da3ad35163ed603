//! The ROS 2 bag reader on `../shared/data/rosbag2/aces`, checked against
//! the same log in CARMEN form.

use std::path::{Path, PathBuf};

use squall_bolts::eval::relations::{self, read_relations};
use squall_bolts::eval::trajectory::Trajectory;
use squall_spouts::carmen::{Laser, ReadOptions, Record, read_log};
use squall_spouts::rosbag2::{BagError, Topics, read_bag};

fn shared(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data").join(rel);
    assert!(
        path.exists(),
        "missing {}: these tests read the shared data set (../shared/data beside the repository)",
        path.display()
    );
    path
}

/// The bag holds the same scans as the log. Their odometry poses are
/// interpolated at the scan stamps, as on a robot; `aces.clf` instead pairs
/// scan i with odometry message i, which lags the scan by up to 0.36 s, so
/// the poses differ while the robot moves (median 1.6 cm). Scored against
/// the ground-truth relations both are equally good in translation, and the
/// interpolated one is better in rotation.
#[test]
fn the_aces_bag_matches_the_aces_log() {
    let bag = read_bag(&shared("rosbag2/aces"), &Topics::default()).unwrap();
    assert_eq!(bag.scans.len(), 7374);
    assert_eq!(bag.scans_without_odometry, 0);
    assert_eq!(bag.odometry.len(), 7375);
    let log: Vec<_> = read_log(&shared("laser/aces.clf"), ReadOptions::default())
        .unwrap()
        .into_iter()
        .filter_map(|r| match r {
            Record::Scan(Laser::Front, s) => Some(s),
            _ => None,
        })
        .collect();
    let (mut bag_odometry, mut log_odometry) = (Trajectory::default(), Trajectory::default());
    for (b, c) in bag.scans.iter().zip(&log) {
        assert!((b.stamp - c.stamp).abs() < 1e-5, "stamps {} vs {}", b.stamp, c.stamp);
        assert_eq!(b.ranges, c.ranges);
        assert!((b.angle_increment - c.angle_increment).abs() < 1e-6);
        // The interpolated pose lies between the odometry messages around it.
        let k = bag.odometry.partition_point(|o| o.stamp <= b.stamp);
        let (before, after) = (&bag.odometry[k - 1].pose, &bag.odometry[k.min(bag.odometry.len() - 1)].pose);
        assert!(b.odometry.distance(before) + b.odometry.distance(after) <= before.distance(after) + 1e-9);
        bag_odometry.push(b.stamp, b.odometry);
        log_odometry.push(c.stamp, c.odometry);
    }
    let relations = read_relations(&shared("laser/aces.relations")).unwrap();
    let from_bag = relations::score(&bag_odometry, &relations);
    let from_log = relations::score(&log_odometry, &relations);
    assert_eq!(from_bag.matched, 1279);
    assert!((from_bag.trans_mean - from_log.trans_mean).abs() < 0.002, "{from_bag:?} vs {from_log:?}");
    assert!(from_bag.rot_mean_deg <= from_log.rot_mean_deg, "{from_bag:?} vs {from_log:?}");
}

#[test]
fn a_truncated_bag_is_an_error() {
    let bytes = std::fs::read(shared("rosbag2/aces/aces.mcap")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    match read_bag(&cut, &Topics::default()) {
        Err(e @ (BagError::Container { .. } | BagError::Message { .. })) => {
            assert!(e.to_string().starts_with(&cut.display().to_string()), "{e}")
        }
        other => panic!("a truncated bag must be an error, got {:?}", other.map(|b| b.scans.len())),
    }
}

#[test]
fn a_wrong_topic_type_is_an_error() {
    let topics = Topics { scan: "/odom".into(), ..Topics::default() };
    let e = read_bag(&shared("rosbag2/aces"), &topics).unwrap_err().to_string();
    assert!(
        e.contains("on /odom: carries nav_msgs/msg/Odometry (cdr), expected sensor_msgs/msg/LaserScan"),
        "{e}"
    );
}
