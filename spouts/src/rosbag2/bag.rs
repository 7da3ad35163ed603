//! Reads a ROS 2 bag (MCAP storage, CDR messages) into readings.
//!
//! Scans come from a `sensor_msgs/msg/LaserScan` topic; the robot's pose at
//! each scan's stamp is interpolated from the `nav_msgs/msg/Odometry` topic,
//! as a robot's own TF would; the laser's mounting comes from `/tf_static`.
//! The bag is read into memory whole.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use squall_core::geometry::{Pose2, normalize_angle};
use squall_core::sensor::{LaserReading, Odometry};

use super::cdr::CdrError;
use super::messages::{self, Transform};
use super::record_check;

/// Scans farther than this (s) from the odometry stream's first or last
/// message get no pose: they are counted, not guessed.
pub const MAX_EXTRAPOLATION: f64 = 0.2;

/// Which topics to read, and how strictly.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    /// Skip messages that do not decode (counted in
    /// [`BagReadings::skipped`]) instead of failing. A malformed container
    /// is always an error. The default is false.
    pub skip_bad: bool,
    /// LaserScan topic. The default is `/scan`.
    pub scan: String,
    /// Odometry topic. The default is `/odom`.
    pub odom: String,
    /// Static transforms. The default is `/tf_static`.
    pub tf_static: String,
}

impl Default for Topics {
    fn default() -> Self {
        Topics { skip_bad: false, scan: "/scan".into(), odom: "/odom".into(), tf_static: "/tf_static".into() }
    }
}

/// A problem reading a bag.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// The bag or a file in it could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The bag holds no MCAP file.
    #[error("{0}: no .mcap file in this bag folder")]
    Empty(PathBuf),
    /// No message on a topic the readings need (a misspelled topic name).
    #[error("{path}: no messages on {param} \"{topic}\"; the bag's topics: {present}")]
    MissingTopic {
        /// The bag.
        path: PathBuf,
        /// The setting that names the topic (`scan_topic`, `odom_topic`).
        param: &'static str,
        /// The topic asked for.
        topic: String,
        /// The topics the bag does hold, with their types.
        present: String,
    },
    /// The MCAP container is malformed or truncated.
    #[error("{path}: malformed MCAP after message {index}: {message}")]
    Container {
        /// The file.
        path: PathBuf,
        /// Messages read before the problem.
        index: usize,
        /// What the MCAP reader said.
        message: String,
    },
    /// A message on a topic read carries another type or encoding than
    /// the topic's.
    #[error("{path}: message {index} on {topic}: carries {schema} ({encoding}), expected {expected} (cdr)")]
    WrongType {
        /// The file.
        path: PathBuf,
        /// 0-based index of the message in the file.
        index: usize,
        /// Its topic.
        topic: String,
        /// The type it carries (its schema's name; empty without one).
        schema: String,
        /// Its message encoding.
        encoding: String,
        /// The type the topic is read as.
        expected: &'static str,
    },
    /// A message could not be decoded.
    #[error("{path}: message {index} on {topic}: {source}")]
    Message {
        /// The file.
        path: PathBuf,
        /// 0-based index of the message in the file.
        index: usize,
        /// Its topic.
        topic: String,
        /// What was expected.
        source: CdrError,
    },
}

/// What a bag yields.
#[derive(Debug, Clone, Default)]
pub struct BagReadings {
    /// Scans with interpolated odometry, in stamp order.
    pub scans: Vec<LaserReading>,
    /// The odometry stream, in stamp order.
    pub odometry: Vec<Odometry>,
    /// Scans outside the odometry stream's time span (not emitted).
    pub scans_without_odometry: u64,
    /// Messages that did not decode, skipped with `skip_bad`.
    pub skipped: u64,
}

fn mcap_files(path: &Path) -> Result<Vec<PathBuf>, BagError> {
    let io = |source| BagError::Io { path: path.to_path_buf(), source };
    if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(io)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(BagError::Empty(path.to_path_buf()));
    }
    Ok(files)
}

const SCAN_TYPE: &str = "sensor_msgs/msg/LaserScan";
const ODOM_TYPE: &str = "nav_msgs/msg/Odometry";
const TF_TYPE: &str = "tf2_msgs/msg/TFMessage";

/// Reads the scans and odometry of the bag at `path` (a bag folder or one
/// `.mcap` file).
pub fn read_bag(path: &Path, topics: &Topics) -> Result<BagReadings, BagError> {
    let mut collector = Collector::default();
    for file in mcap_files(path)? {
        let bytes = std::fs::read(&file).map_err(|source| BagError::Io { path: file.clone(), source })?;
        collector.read_mcap(&file, &bytes, topics)?;
    }
    collector.finish(path, topics)
}

/// Reads the scans and odometry of one MCAP file already in memory;
/// `name` is what errors call it. What [`read_bag`] does per file, for
/// callers (and fuzzers) holding the bytes.
pub fn read_mcap_bytes(name: &Path, bytes: &[u8], topics: &Topics) -> Result<BagReadings, BagError> {
    let mut collector = Collector::default();
    collector.read_mcap(name, bytes, topics)?;
    collector.finish(name, topics)
}

/// The largest MCAP record read (a message, or a chunk's compressed
/// bytes): far above a scan's or an image's, far below what a corrupt
/// length could make the reader buffer.
const MAX_RECORD_BYTES: usize = 256 << 20;

/// A channel of an MCAP file: its topic, message encoding and schema name
/// (empty without a schema).
struct Channel {
    topic: String,
    encoding: String,
    schema: String,
}

/// The messages of a bag's files gathered so far, before the scans are
/// given poses.
#[derive(Default)]
struct Collector {
    raw_scans: Vec<messages::LaserScan>,
    odometry: Vec<Odometry>,
    statics: Vec<Transform>,
    skipped: u64,
    /// Every topic met, with its type: what a missing topic's error lists.
    seen: Vec<(String, String)>,
}

impl Collector {
    /// Gathers the messages of one MCAP file, `file` naming it in errors.
    ///
    /// Records are read one at a time by the `mcap` crate's streaming
    /// reader (chunks decompressed as they are read), each checked by
    /// [`record_check`] before the crate parses it.
    fn read_mcap(&mut self, file: &Path, bytes: &[u8], topics: &Topics) -> Result<(), BagError> {
        let container =
            |index, message: String| BagError::Container { path: file.to_path_buf(), index, message };
        let options = LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES);
        let mut reader = LinearReader::new_with_options(options);
        let mut unread = bytes;
        let mut schemas: HashMap<u16, String> = HashMap::new();
        let mut channels: HashMap<u16, Channel> = HashMap::new();
        let mut index = 0;
        while let Some(event) = reader.next_event() {
            match event.map_err(|e| container(index, e.to_string()))? {
                LinearReadEvent::ReadRequest(wanted) => {
                    let n = wanted.min(unread.len());
                    reader.insert(n).copy_from_slice(&unread[..n]);
                    reader.notify_read(n);
                    unread = &unread[n..];
                }
                LinearReadEvent::Record { opcode, data } => {
                    record_check::check(opcode, data).map_err(|m| container(index, m))?;
                    match mcap::parse_record(opcode, data).map_err(|e| container(index, e.to_string()))? {
                        mcap::records::Record::Schema { header, .. } => {
                            schemas.insert(header.id, header.name);
                        }
                        mcap::records::Record::Channel(c) => {
                            let schema = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                            channels.insert(
                                c.id,
                                Channel { topic: c.topic, encoding: c.message_encoding, schema },
                            );
                        }
                        mcap::records::Record::Message { header, data } => {
                            let channel = channels.get(&header.channel_id).ok_or_else(|| {
                                container(
                                    index,
                                    format!("a message on channel {}, never declared", header.channel_id),
                                )
                            })?;
                            self.message(file, index, channel, &data, topics)?;
                            index += 1;
                        }
                        _ => {}
                    }
                }
            }
        }
        Ok(())
    }

    /// Takes message `index` of `file`, on `channel`, if its topic is one
    /// the readings need.
    fn message(
        &mut self,
        file: &Path,
        index: usize,
        channel: &Channel,
        data: &[u8],
        topics: &Topics,
    ) -> Result<(), BagError> {
        let Channel { topic, encoding, schema } = channel;
        if !self.seen.iter().any(|(t, _)| t == topic) {
            self.seen.push((topic.clone(), schema.clone()));
        }
        let expected = if *topic == topics.scan {
            SCAN_TYPE
        } else if *topic == topics.odom {
            ODOM_TYPE
        } else if *topic == topics.tf_static {
            TF_TYPE
        } else {
            return Ok(());
        };
        if schema != expected || encoding != "cdr" {
            return Err(BagError::WrongType {
                path: file.to_path_buf(),
                index,
                topic: topic.clone(),
                schema: schema.clone(),
                encoding: encoding.clone(),
                expected,
            });
        }
        let decoded = match expected {
            SCAN_TYPE => messages::laser_scan(data).map(|m| self.raw_scans.push(m)),
            ODOM_TYPE => messages::odometry(data).map(|o| self.odometry.push(o.into_odometry())),
            _ => messages::tf_message(data).map(|t| self.statics.extend(t)),
        };
        match decoded {
            Ok(()) => Ok(()),
            Err(_) if topics.skip_bad => {
                self.skipped += 1;
                Ok(())
            }
            Err(source) => {
                Err(BagError::Message { path: file.to_path_buf(), index, topic: topic.clone(), source })
            }
        }
    }

    /// The readings of the bag at `path`: every scan with its pose
    /// interpolated from odometry and its laser's mounting; an error if a
    /// topic the readings need never appeared.
    fn finish(self, path: &Path, topics: &Topics) -> Result<BagReadings, BagError> {
        let Collector { mut raw_scans, mut odometry, statics, skipped, seen } = self;
        let has = |topic: &str| seen.iter().any(|(t, _)| t == topic);
        for (param, topic) in [("scan_topic", &topics.scan), ("odom_topic", &topics.odom)] {
            if !has(topic) {
                let present = seen.iter().map(|(t, ty)| format!("{t} ({ty})")).collect::<Vec<_>>().join(", ");
                let present = if present.is_empty() { "none".to_string() } else { present };
                return Err(BagError::MissingTopic {
                    path: path.to_path_buf(),
                    param,
                    topic: topic.clone(),
                    present,
                });
            }
        }
        if !has(&topics.tf_static) {
            tracing::warn!(
                bag = %path.display(),
                "no messages on tf_static_topic \"{}\": the laser is taken to sit at the robot's origin",
                topics.tf_static
            );
        }
        odometry.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
        raw_scans.sort_by(|a, b| a.header.stamp.total_cmp(&b.header.stamp));
        let mut out = BagReadings { odometry, skipped, ..Default::default() };
        for scan in raw_scans {
            let Some(pose) = interpolate(&out.odometry, scan.header.stamp) else {
                out.scans_without_odometry += 1;
                continue;
            };
            let laser_offset = statics
                .iter()
                .find(|t| t.child_frame_id == scan.header.frame_id)
                .map_or(Pose2::IDENTITY, |t| t.pose);
            out.scans.push(scan.into_reading(pose, laser_offset));
        }
        Ok(out)
    }
}

/// The odometry pose at `t`, linear in position and along the shorter arc in
/// heading between the two messages around it.
pub fn interpolate(odometry: &[Odometry], t: f64) -> Option<Pose2> {
    let first = odometry.first()?;
    let last = odometry.last()?;
    if t <= first.stamp {
        return (first.stamp - t <= MAX_EXTRAPOLATION).then_some(first.pose);
    }
    if t >= last.stamp {
        return (t - last.stamp <= MAX_EXTRAPOLATION).then_some(last.pose);
    }
    let i = odometry.partition_point(|o| o.stamp <= t);
    let (a, b) = (&odometry[i - 1], &odometry[i]);
    let span = b.stamp - a.stamp;
    let f = if span > 0.0 { (t - a.stamp) / span } else { 0.0 };
    Some(Pose2::new(
        a.pose.x + f * (b.pose.x - a.pose.x),
        a.pose.y + f * (b.pose.y - a.pose.y),
        a.pose.theta + f * normalize_angle(b.pose.theta - a.pose.theta),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn odom(stamp: f64, x: f64, theta: f64) -> Odometry {
        Odometry { stamp, pose: Pose2::new(x, 0.0, theta), linear_velocity: 0.0, angular_velocity: 0.0 }
    }

    #[test]
    fn interpolates_position_and_heading_across_the_wrap() {
        let stream = [odom(1.0, 0.0, 3.0), odom(2.0, 1.0, -3.0)];
        let p = interpolate(&stream, 1.5).unwrap();
        assert!((p.x - 0.5).abs() < 1e-12);
        // From 3.0 to −3.0 the short way passes through π.
        assert!((p.theta.abs() - (3.0 + (2.0 * std::f64::consts::PI - 6.0) / 2.0)).abs() < 1e-9, "{p:?}");
        assert_eq!(interpolate(&stream, 0.9).unwrap().x, 0.0);
        assert!(interpolate(&stream, 0.5).is_none());
        assert!(interpolate(&stream, 2.5).is_none());
        assert!(interpolate(&[], 1.0).is_none());
    }
}
