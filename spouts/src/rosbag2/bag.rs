//! Reads a ROS 2 bag (MCAP or sqlite3 storage, CDR messages) into
//! readings.
//!
//! Scans come from a `sensor_msgs/msg/LaserScan` topic; the robot's pose at
//! each scan's stamp is interpolated from the `nav_msgs/msg/Odometry` topic,
//! as a robot's own TF would; the laser's mounting comes from `/tf_static`.
//! The bag is read into memory whole.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use squall_core::geometry::Pose2;
use squall_core::sensor::{LaserReading, Odometry};

use super::cdr::CdrError;
use super::messages::{self, Transform};
use super::record_check;

/// Scans farther than this (s) from the odometry stream's first or last
/// message get no pose: they are counted, not guessed (the odometry
/// track's bound).
pub use squall_core::odometry_track::MAX_EXTRAPOLATION;

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
    /// This process may not read the bag (a worker's `--data-dir`).
    #[error(transparent)]
    Confined(#[from] squall_topology::confine::ConfinementError),
    /// The bag or a file in it could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The bag folder holds no storage file.
    #[error("{0}: no .mcap or .db3 file in this bag folder (and no metadata.yaml naming one)")]
    Empty(PathBuf),
    /// A ROS 1 bag, which squall does not read.
    #[error(
        "{0}: a ROS 1 bag; squall reads ROS 2 bags (MCAP or sqlite3 storage). Convert it first: \
         `pip install rosbags && rosbags-convert --src {0} --dst BAG_FOLDER`"
    )]
    Ros1(PathBuf),
    /// A storage other than MCAP and sqlite3.
    #[error(
        "{path}: storage \"{storage}\" is not one squall reads (mcap, sqlite3). Convert it first: \
         `pip install rosbags && rosbags-convert --src {path} --dst BAG_FOLDER --dst-storage mcap`"
    )]
    UnknownStorage {
        /// The bag.
        path: PathBuf,
        /// What the bag's metadata or bytes say it is.
        storage: String,
    },
    /// An sqlite3 (`.db3`) storage file that SQLite cannot read as a
    /// rosbag2 database.
    #[error("{path}: not a readable rosbag2 sqlite3 database: {message}")]
    Sqlite {
        /// The file.
        path: PathBuf,
        /// What SQLite said.
        message: String,
    },
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

/// How a rosbag2 bag stores its messages (`storage_identifier` in its
/// `metadata.yaml`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// MCAP files (`.mcap`), rosbag2's default since Iron.
    Mcap,
    /// SQLite databases (`.db3`), Humble's default.
    Sqlite3,
}

/// What the first bytes of `file` say it is: a storage squall reads, or
/// the error for a ROS 1 bag or anything else.
fn sniff(file: &Path) -> Result<Storage, BagError> {
    use std::io::Read;
    let mut head = [0u8; 16];
    let mut f =
        std::fs::File::open(file).map_err(|source| BagError::Io { path: file.to_path_buf(), source })?;
    let n = f.read(&mut head).map_err(|source| BagError::Io { path: file.to_path_buf(), source })?;
    let head = &head[..n];
    if head.starts_with(b"\x89MCAP") {
        Ok(Storage::Mcap)
    } else if head.starts_with(b"SQLite format 3\0") {
        Ok(Storage::Sqlite3)
    } else if head.starts_with(b"#ROSBAG") {
        Err(BagError::Ros1(file.to_path_buf()))
    } else {
        Err(BagError::UnknownStorage {
            path: file.to_path_buf(),
            storage: "unrecognised (neither MCAP, SQLite nor a ROS 1 bag)".to_string(),
        })
    }
}

/// The `storage_identifier` and `relative_file_paths` of a rosbag2
/// `metadata.yaml` (the flat keys rosbag2 writes; no YAML features beyond
/// them are needed).
fn metadata(text: &str) -> (Option<String>, Vec<String>) {
    let mut storage = None;
    let mut files = Vec::new();
    let mut in_files = false;
    for line in text.lines() {
        let trimmed = line.trim();
        if let Some(value) = trimmed.strip_prefix("storage_identifier:") {
            storage = Some(value.trim().trim_matches(['\'', '"']).to_string());
            in_files = false;
        } else if trimmed == "relative_file_paths:" {
            in_files = true;
        } else if in_files && let Some(item) = trimmed.strip_prefix("- ") {
            files.push(item.trim().trim_matches(['\'', '"']).to_string());
        } else if in_files && !trimmed.is_empty() {
            in_files = false;
        }
    }
    (storage, files)
}

/// The storage and files of the bag at `path`: one file (its bytes say
/// which storage), or a bag folder (its `metadata.yaml` says; without one,
/// the `.mcap` or `.db3` files in it). ROS 1 bags and other storages are
/// errors that say how to convert them.
pub fn bag_files(path: &Path) -> Result<(Storage, Vec<PathBuf>), BagError> {
    // A confined process (a worker) reads the bag, and every file its
    // metadata or its folder names, only under its data folder.
    squall_topology::confine::check_read(path)?;
    let (storage, files) = find_bag_files(path)?;
    for file in &files {
        squall_topology::confine::check_read(file)?;
    }
    Ok((storage, files))
}

fn find_bag_files(path: &Path) -> Result<(Storage, Vec<PathBuf>), BagError> {
    let io = |source| BagError::Io { path: path.to_path_buf(), source };
    if path.is_file() {
        return Ok((sniff(path)?, vec![path.to_path_buf()]));
    }
    let listed = |extension: &str| -> Result<Vec<PathBuf>, BagError> {
        let mut files: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == extension))
            .collect();
        files.sort();
        Ok(files)
    };
    let yaml = path.join("metadata.yaml");
    if yaml.is_file() {
        squall_topology::confine::check_read(&yaml)?;
        let text =
            std::fs::read_to_string(&yaml).map_err(|source| BagError::Io { path: yaml.clone(), source })?;
        let (storage, files) = metadata(&text);
        let storage = match storage.as_deref() {
            Some("mcap") => Storage::Mcap,
            Some("sqlite3") => Storage::Sqlite3,
            Some(other) => {
                return Err(BagError::UnknownStorage { path: path.to_path_buf(), storage: other.into() });
            }
            None => {
                return Err(BagError::UnknownStorage {
                    path: yaml,
                    storage: "none given (no storage_identifier)".to_string(),
                });
            }
        };
        let files = if files.is_empty() {
            listed(if storage == Storage::Mcap { "mcap" } else { "db3" })?
        } else {
            files.iter().map(|f| path.join(f)).collect()
        };
        if files.is_empty() {
            return Err(BagError::Empty(path.to_path_buf()));
        }
        return Ok((storage, files));
    }
    for (storage, extension) in [(Storage::Mcap, "mcap"), (Storage::Sqlite3, "db3")] {
        let files = listed(extension)?;
        if !files.is_empty() {
            return Ok((storage, files));
        }
    }
    if let Some(ros1) = listed("bag")?.into_iter().next() {
        return Err(BagError::Ros1(ros1));
    }
    Err(BagError::Empty(path.to_path_buf()))
}

/// Checks, before a run, that the bag at `path` is one squall reads and
/// holds the scan and odometry topics asked for: the storage from
/// [`bag_files`], then the topics from the sqlite3 `topics` table or the
/// MCAP summary section (a file without one is read in full at the run).
pub fn check_bag(path: &Path, topics: &Topics) -> Result<Storage, BagError> {
    let (storage, files) = bag_files(path)?;
    let mut seen: Vec<(String, String)> = Vec::new();
    for file in &files {
        let declared = match storage {
            Storage::Sqlite3 => db3_topics(file)?,
            Storage::Mcap => match mcap_summary_topics(file)? {
                Some(declared) => declared,
                None => return Ok(storage),
            },
        };
        seen.extend(declared);
    }
    missing_topic(path, topics, &seen).map_or(Ok(storage), Err)
}

/// The error for the first of the scan and odometry topics that `seen`
/// (topic, type) lacks.
fn missing_topic(path: &Path, topics: &Topics, seen: &[(String, String)]) -> Option<BagError> {
    let has = |topic: &str| seen.iter().any(|(t, _)| t == topic);
    [("scan_topic", &topics.scan), ("odom_topic", &topics.odom)].into_iter().find(|(_, t)| !has(t)).map(
        |(param, topic)| {
            let present = seen.iter().map(|(t, ty)| format!("{t} ({ty})")).collect::<Vec<_>>().join(", ");
            let present = if present.is_empty() { "none".to_string() } else { present };
            BagError::MissingTopic { path: path.to_path_buf(), param, topic: topic.clone(), present }
        },
    )
}

/// Opens a `.db3` so that nothing is written beside it: read-only and
/// immutable (SQLite's `immutable=1`), so that SQLite neither takes a
/// lock nor makes the `-shm` and `-wal` files a database in WAL journal
/// mode (as rosbag2 records them) otherwise gets, which a bag in a
/// read-only folder cannot have and a user's bag should never grow.
/// Immutable mode does not read a write-ahead log: a bag whose recorder
/// died leaves its last messages in a non-empty `-wal` file, and reading
/// the database without them would lose them silently, so such a bag is
/// refused with what to do.
fn open_db3(file: &Path) -> Result<rusqlite::Connection, BagError> {
    use rusqlite::OpenFlags;
    let mut wal = file.as_os_str().to_owned();
    wal.push("-wal");
    if let Ok(m) = std::fs::metadata(&wal)
        && m.len() > 0
    {
        return Err(BagError::Sqlite {
            path: file.to_path_buf(),
            message: format!(
                "its write-ahead log {} holds {} bytes not yet in the database (the recording was \
                 not closed); in a writable copy of the bag folder, merge it with `sqlite3 FILE.db3 \
                 \"PRAGMA wal_checkpoint(TRUNCATE)\"` and read the copy",
                Path::new(&wal).display(),
                m.len()
            ),
        });
    }
    rusqlite::Connection::open_with_flags(
        immutable_uri(file),
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX | OpenFlags::SQLITE_OPEN_URI,
    )
    .map_err(|e| sqlite_error(file, e))
}

/// `file` as an SQLite URI that opens it read-only and immutable, every
/// byte outside the URI's unreserved set percent-encoded (a path may hold
/// `?`, `#` or `%`).
fn immutable_uri(file: &Path) -> String {
    use std::fmt::Write;
    let mut uri = String::from("file:");
    for &b in file.as_os_str().as_encoded_bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            uri.push(b as char);
        } else {
            let _ = write!(uri, "%{b:02X}");
        }
    }
    uri.push_str("?mode=ro&immutable=1");
    uri
}

fn sqlite_error(file: &Path, e: rusqlite::Error) -> BagError {
    BagError::Sqlite { path: file.to_path_buf(), message: e.to_string() }
}

/// The channels of a `.db3`'s `topics` table, by id.
fn db3_channels(db: &rusqlite::Connection, file: &Path) -> Result<HashMap<i64, Channel>, BagError> {
    let mut statement = db
        .prepare("SELECT id, name, type, serialization_format FROM topics")
        .map_err(|e| sqlite_error(file, e))?;
    let rows = statement
        .query_map([], |row| {
            Ok((
                row.get::<_, i64>(0)?,
                Channel { topic: row.get(1)?, schema: row.get(2)?, encoding: row.get(3)? },
            ))
        })
        .map_err(|e| sqlite_error(file, e))?;
    rows.collect::<Result<HashMap<_, _>, _>>().map_err(|e| sqlite_error(file, e))
}

/// The (topic, type) pairs a `.db3` declares in its `topics` table, as
/// an MCAP summary declares its channels: read without touching the
/// messages (a topic declared but empty is found when the bag is read).
fn db3_topics(file: &Path) -> Result<Vec<(String, String)>, BagError> {
    let mut channels: Vec<(i64, Channel)> = db3_channels(&open_db3(file)?, file)?.into_iter().collect();
    channels.sort_by_key(|(id, _)| *id);
    Ok(channels.into_iter().map(|(_, c)| (c.topic, c.schema)).collect())
}

/// The (topic, type) pairs of an MCAP file's summary section, read from
/// its footer without reading the messages; `None` when the file has no
/// summary (or its end is not a well-formed footer: the full read at the
/// run reports that).
fn mcap_summary_topics(file: &Path) -> Result<Option<Vec<(String, String)>>, BagError> {
    use std::io::{Read, Seek, SeekFrom};
    const MAGIC: &[u8] = b"\x89MCAP0\r\n";
    // Footer record: opcode, length, summary start, summary offset start, CRC.
    const FOOTER: u64 = 1 + 8 + 8 + 8 + 4;
    let io = |source| BagError::Io { path: file.to_path_buf(), source };
    let mut f = std::fs::File::open(file).map_err(io)?;
    let size = f.metadata().map_err(io)?.len();
    if size < FOOTER + 2 * MAGIC.len() as u64 {
        return Ok(None);
    }
    let mut tail = [0u8; (FOOTER as usize) + 8];
    f.seek(SeekFrom::Start(size - tail.len() as u64)).map_err(io)?;
    f.read_exact(&mut tail).map_err(io)?;
    if &tail[FOOTER as usize..] != MAGIC || tail[0] != 0x02 {
        return Ok(None);
    }
    let summary_start = u64::from_le_bytes(tail[9..17].try_into().expect("8 bytes"));
    let footer_at = size - tail.len() as u64;
    if summary_start == 0 || summary_start >= footer_at {
        return Ok(None);
    }
    let mut summary = vec![0u8; (footer_at - summary_start) as usize];
    f.seek(SeekFrom::Start(summary_start)).map_err(io)?;
    f.read_exact(&mut summary).map_err(io)?;
    let mut schemas: HashMap<u16, String> = HashMap::new();
    let mut out = Vec::new();
    let mut rest = summary.as_slice();
    while rest.len() >= 9 {
        let opcode = rest[0];
        let length = u64::from_le_bytes(rest[1..9].try_into().expect("8 bytes"));
        let Some(body) = usize::try_from(length).ok().and_then(|n| rest.get(9..9 + n)) else {
            return Ok(None);
        };
        rest = &rest[9 + body.len()..];
        if record_check::check(opcode, body).is_err() {
            return Ok(None);
        }
        match mcap::parse_record(opcode, body) {
            Ok(mcap::records::Record::Schema { header, .. }) => {
                schemas.insert(header.id, header.name);
            }
            Ok(mcap::records::Record::Channel(c)) => {
                out.push((c.topic, schemas.get(&c.schema_id).cloned().unwrap_or_default()));
            }
            Ok(_) => {}
            Err(_) => return Ok(None),
        }
    }
    Ok(Some(out))
}

const SCAN_TYPE: &str = "sensor_msgs/msg/LaserScan";
const ODOM_TYPE: &str = "nav_msgs/msg/Odometry";
const TF_TYPE: &str = "tf2_msgs/msg/TFMessage";

/// Reads the scans and odometry of the bag at `path` (a bag folder, or
/// one `.mcap` or `.db3` file).
pub fn read_bag(path: &Path, topics: &Topics) -> Result<BagReadings, BagError> {
    let mut collector = Collector::default();
    let (storage, files) = bag_files(path)?;
    for file in files {
        match storage {
            Storage::Mcap => {
                let bytes =
                    std::fs::read(&file).map_err(|source| BagError::Io { path: file.clone(), source })?;
                collector.read_mcap(&file, &bytes, topics)?;
            }
            Storage::Sqlite3 => collector.read_db3(&file, topics)?,
        }
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

    /// Gathers the messages of one sqlite3 storage file in the order
    /// rosbag2 plays them (by timestamp, then as recorded).
    fn read_db3(&mut self, file: &Path, topics: &Topics) -> Result<(), BagError> {
        let db = open_db3(file)?;
        let channels = db3_channels(&db, file)?;
        let mut statement = db
            .prepare("SELECT topic_id, data FROM messages ORDER BY timestamp, id")
            .map_err(|e| sqlite_error(file, e))?;
        let mut rows = statement.query([]).map_err(|e| sqlite_error(file, e))?;
        let mut index = 0;
        while let Some(row) = rows.next().map_err(|e| sqlite_error(file, e))? {
            let id: i64 = row.get(0).map_err(|e| sqlite_error(file, e))?;
            let data = row.get_ref(1).and_then(|v| Ok(v.as_blob()?)).map_err(|e| sqlite_error(file, e))?;
            let channel = channels.get(&id).ok_or_else(|| BagError::Sqlite {
                path: file.to_path_buf(),
                message: format!("message {index} on topic id {id}, which the topics table does not hold"),
            })?;
            self.message(file, index, channel, data, topics)?;
            index += 1;
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
        if let Some(missing) = missing_topic(path, topics, &seen) {
            return Err(missing);
        }
        if !seen.iter().any(|(t, _)| *t == topics.tf_static) {
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
/// heading between the two messages around it (the odometry track's).
pub use squall_core::odometry_track::pose_at as interpolate;

#[cfg(test)]
mod tests {
    use super::*;

    fn odom(stamp: f64, x: f64, theta: f64) -> Odometry {
        Odometry { stamp, pose: Pose2::new(x, 0.0, theta), linear_velocity: 0.0, angular_velocity: 0.0 }
    }

    #[test]
    fn metadata_names_the_storage_and_its_files() {
        let yaml = "rosbag2_bagfile_information:\n  files:\n  - path: a.db3\n  relative_file_paths:\n  - a.db3\n  - 'b.db3'\n  ros_distro: humble\n  storage_identifier: sqlite3\n";
        assert_eq!(
            metadata(yaml),
            (Some("sqlite3".to_string()), vec!["a.db3".to_string(), "b.db3".to_string()])
        );
        assert_eq!(metadata("version: 5\n"), (None, vec![]));
    }

    #[test]
    fn storage_is_told_from_the_files_and_what_squall_cannot_read_says_what_to_do() {
        let dir = tempfile::tempdir().unwrap();
        let file = |name: &str, bytes: &[u8]| {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).unwrap();
            path
        };
        let mcap = file("x.mcap", b"\x89MCAP0\r\n....");
        assert_eq!(bag_files(&mcap).unwrap(), (Storage::Mcap, vec![mcap.clone()]));
        // A .db3 named otherwise is still SQLite by its bytes.
        let db3 = file("x.data", b"SQLite format 3\0....");
        assert_eq!(bag_files(&db3).unwrap().0, Storage::Sqlite3);
        let ros1 = file("x.bag", b"#ROSBAG V2.0\n");
        let e = bag_files(&ros1).unwrap_err().to_string();
        assert!(e.contains("a ROS 1 bag") && e.contains("rosbags-convert --src"), "{e}");
        let other = file("x.txt", b"hello");
        assert!(matches!(bag_files(&other), Err(BagError::UnknownStorage { .. })));
        // A folder: metadata.yaml decides; without it, the files present.
        let folder = dir.path().join("bag");
        std::fs::create_dir(&folder).unwrap();
        assert!(matches!(bag_files(&folder), Err(BagError::Empty(_))));
        std::fs::write(folder.join("old.bag"), b"#ROSBAG V2.0\n").unwrap();
        assert!(matches!(bag_files(&folder), Err(BagError::Ros1(_))));
        std::fs::write(folder.join("b_0.db3"), b"SQLite format 3\0").unwrap();
        assert_eq!(bag_files(&folder).unwrap(), (Storage::Sqlite3, vec![folder.join("b_0.db3")]));
        std::fs::write(folder.join("metadata.yaml"), "  storage_identifier: rosbag_v2\n").unwrap();
        let e = bag_files(&folder).unwrap_err().to_string();
        assert!(e.contains("storage \"rosbag_v2\" is not one squall reads (mcap, sqlite3)"), "{e}");
        // SQLite, but not a rosbag2 database: named, not a panic.
        let not_a_bag = dir.path().join("plain.db3");
        rusqlite::Connection::open(&not_a_bag).unwrap().execute("CREATE TABLE t(x)", []).unwrap();
        let e = check_bag(&not_a_bag, &Topics::default()).unwrap_err().to_string();
        assert!(e.contains("not a readable rosbag2 sqlite3 database") && e.contains("topics"), "{e}");
    }

    #[test]
    fn a_db3_is_read_without_writing_beside_it_and_an_unmerged_log_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("odd name?#%.db3");
        let beside = || {
            let mut names: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().into_string().unwrap())
                .collect();
            names.sort();
            names
        };
        // rosbag2 records in WAL journal mode; while the recorder holds the
        // database, its last rows are only in the write-ahead log.
        let recorder = rusqlite::Connection::open(&file).unwrap();
        let mode: String = recorder.query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0)).unwrap();
        assert_eq!(mode, "wal");
        recorder.execute_batch("CREATE TABLE topics(id, name, type, serialization_format)").unwrap();
        recorder
            .execute("INSERT INTO topics VALUES (1, '/scan', 'sensor_msgs/msg/LaserScan', 'cdr')", [])
            .unwrap();
        let e = open_db3(&file).unwrap_err().to_string();
        assert!(e.contains("write-ahead log") && e.contains("not yet in the database"), "{e}");
        drop(recorder);
        // Closed: the log is merged and gone; reading leaves nothing beside.
        let before = beside();
        assert_eq!(before, vec!["odd name?#%.db3".to_string()]);
        let db = open_db3(&file).unwrap();
        assert_eq!(db3_channels(&db, &file).unwrap()[&1].topic, "/scan");
        drop(db);
        assert_eq!(beside(), before);
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
