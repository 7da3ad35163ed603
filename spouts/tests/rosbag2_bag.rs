//! The ROS 2 bag reader on `../shared/data/rosbag2/aces`, checked against
//! the same log in CARMEN form.

mod common;
use common::shared;

use squall_core::eval::relations::{self, read_relations};
use squall_core::trajectory::Trajectory;
use squall_spouts::carmen::{ReadOptions, read_front_scans};
use squall_spouts::rosbag2::{BagError, Topics, read_bag, read_mcap_bytes};

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
    let log = read_front_scans(&shared("laser/aces.clf"), ReadOptions::default()).unwrap();
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

/// Deterministic mutation fuzz of the CDR decoders with real messages:
/// flipped bytes, cut messages, corrupt lengths. Ok or Err, never a panic.
#[test]
fn the_cdr_decoders_never_panic() {
    use squall_spouts::rosbag2::messages::{laser_scan, odometry, tf_message};
    let bytes = std::fs::read(shared("rosbag2/aces/aces.mcap")).unwrap();
    let mut samples: Vec<(String, Vec<u8>)> = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap().take(600) {
        let m = m.unwrap();
        samples.push((m.channel.topic.clone(), m.data.into_owned()));
    }
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut rand = move |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n.max(1) as u64) as usize
    };
    let (mut ok, mut err) = (0, 0);
    for round in 0..30_000 {
        let (topic, original) = &samples[round % samples.len()];
        let mut data = original.clone();
        match rand(3) {
            0 => data.truncate(rand(data.len() + 1)),
            1 => {
                for _ in 0..1 + rand(4) {
                    let i = rand(data.len());
                    data[i] = rand(256) as u8;
                }
            }
            _ => {
                let i = rand(data.len().saturating_sub(4)) & !3;
                data[i..i + 4].copy_from_slice(&[0xff, 0xff, 0xff, 0x7f]);
            }
        }
        let decoded = match topic.as_str() {
            "/scan" => laser_scan(&data).map(|_| ()),
            "/odom" => odometry(&data).map(|_| ()),
            _ => tf_message(&data).map(|_| ()),
        };
        if decoded.is_ok() { ok += 1 } else { err += 1 }
    }
    assert!(ok > 1000 && err > 1000, "the fuzz should hit both outcomes: ok {ok}, err {err}");
}

/// A bag whose third scan is cut short: an error naming the message, or
/// with `skip_bad` the other scans and a count.
#[test]
fn skip_bad_skips_and_counts_undecodable_messages() {
    let bytes = std::fs::read(shared("rosbag2/aces/aces.mcap")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = mcap::Writer::new(file).unwrap();
        let meta = std::collections::BTreeMap::new();
        let mut channels = std::collections::HashMap::new();
        let mut scans = 0;
        for m in mcap::MessageStream::new(&bytes).unwrap().take(40) {
            let m = m.unwrap();
            let topic = m.channel.topic.clone();
            let id = *channels.entry(topic.clone()).or_insert_with(|| {
                let schema = m.channel.schema.as_ref().unwrap();
                let s = w.add_schema(&schema.name, &schema.encoding, &schema.data).unwrap();
                w.add_channel(s, &topic, "cdr", &meta).unwrap()
            });
            let mut data = m.data.into_owned();
            if topic == "/scan" {
                scans += 1;
                if scans == 3 {
                    data.truncate(data.len() / 2);
                }
            }
            let header = mcap::records::MessageHeader {
                channel_id: id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
            };
            w.write_to_known_channel(&header, &data).unwrap();
        }
        w.finish().unwrap();
    }
    let e = read_bag(&path, &Topics::default()).unwrap_err().to_string();
    assert!(e.contains("bad.mcap: message 9 on /scan: ranges: 180 elements do not fit"), "{e}");
    let ok = read_bag(&path, &Topics { skip_bad: true, ..Topics::default() }).unwrap();
    assert_eq!(ok.skipped, 1);
    assert!(ok.scans.len() >= 10, "{}", ok.scans.len());
}

/// A bag whose attachment's name claims 4 GB: the `mcap` crate alone
/// would allocate and zero that much before finding the record too short
/// (found by `fuzz/`'s `mcap_bag` target); squall refuses the record,
/// naming it, without the allocation.
#[test]
fn a_length_past_its_record_is_refused_before_it_is_allocated() {
    let mut w = mcap::Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
    let attachment = mcap::Attachment {
        log_time: 1,
        create_time: 1,
        name: "calibration".into(),
        media_type: "text/plain".into(),
        data: std::borrow::Cow::Borrowed(b"fx 615"),
    };
    w.attach(&attachment).unwrap();
    w.finish().unwrap();
    let mut bytes = w.into_inner().into_inner();
    let name = bytes.windows(15).position(|b| b == b"\x0b\0\0\0calibration").unwrap();
    bytes[name..name + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let path = std::path::Path::new("evil.mcap");
    let error = read_mcap_bytes(path, &bytes, &Topics::default()).unwrap_err().to_string();
    assert!(
        error.contains(
            "evil.mcap: malformed MCAP after message 0: record 0x09, field 3: claims 4294967295 bytes"
        ),
        "{error}"
    );
}
