//! Reads a CARMEN log, plain or gzip, record by record.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;

use squall_core::sensor::LaserReading;

use super::parse::{Laser, LineParser, Record, RecordError};

/// A problem reading a log, with file and line.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// This process may not read the file (a worker's `--data-dir`).
    #[error(transparent)]
    Confined(#[from] squall_topology::confine::ConfinementError),
    /// The file could not be opened.
    #[error("{path}: cannot open: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// A record is malformed.
    #[error("{path}:{line}: {source}")]
    Bad {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What was expected.
        source: RecordError,
    },
    /// The bytes could not be read (a truncated or corrupt gzip stream, a
    /// line that is not UTF-8, an I/O error).
    #[error("{path}:{line}: cannot read: {source} (truncated or corrupt file?)")]
    Read {
        /// The file.
        path: PathBuf,
        /// 1-based line being read.
        line: usize,
        /// Why.
        source: io::Error,
    },
}

/// How to read a log.
#[derive(Debug, Clone, Copy)]
pub struct ReadOptions {
    /// Range limit (metres) for lasers whose log has no `robot_*_laser_max`.
    /// The default is 80 m.
    pub default_range_max: f64,
    /// Skip malformed records (counted) instead of failing. The default is
    /// false: a bad record is an error.
    pub skip_bad: bool,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions { default_range_max: 80.0, skip_bad: false }
    }
}

/// The log's bytes, plain or gunzipped (gzip is recognised by its magic
/// bytes, not the name).
fn open_input(path: &Path) -> Result<Box<dyn BufRead + Send>, LogError> {
    squall_topology::confine::check_read(path)?;
    let open_err = |source| LogError::Open { path: path.to_path_buf(), source };
    let mut file = BufReader::with_capacity(1 << 16, File::open(path).map_err(open_err)?);
    let gzip = file.fill_buf().map_err(open_err)?.starts_with(&[0x1f, 0x8b]);
    Ok(if gzip {
        Box::new(BufReader::with_capacity(1 << 16, MultiGzDecoder::new(file)))
    } else {
        Box::new(file)
    })
}

/// How many front-laser records (`FLASER`, `ROBOTLASER1`) the log holds,
/// by their keyword alone: one pass that parses nothing, for a progress
/// display's total. Malformed records are counted too (the reader decides
/// about them).
pub fn count_front_scans(path: &Path) -> Result<u64, LogError> {
    let mut input = open_input(path)?;
    let mut line = Vec::with_capacity(4096);
    let (mut count, mut number) = (0, 0);
    loop {
        line.clear();
        number += 1;
        match input.read_until(b'\n', &mut line) {
            Ok(0) => return Ok(count),
            Ok(_) => {}
            Err(source) => return Err(LogError::Read { path: path.to_path_buf(), line: number, source }),
        }
        let keyword = line.split(|b| b.is_ascii_whitespace()).find(|field| !field.is_empty());
        if matches!(keyword, Some(b"FLASER" | b"ROBOTLASER1")) {
            count += 1;
        }
    }
}

/// Yields the records of one log.
pub struct LogReader {
    path: PathBuf,
    input: Box<dyn BufRead + Send>,
    parser: LineParser,
    options: ReadOptions,
    line: usize,
    buf: String,
    skipped: u64,
    other: BTreeMap<String, u64>,
}

impl std::fmt::Debug for LogReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogReader").field("path", &self.path).field("line", &self.line).finish()
    }
}

impl LogReader {
    /// Opens `path`; gzip is recognised by its magic bytes, not the name.
    pub fn open(path: &Path, options: ReadOptions) -> Result<Self, LogError> {
        Ok(LogReader {
            path: path.to_path_buf(),
            input: open_input(path)?,
            parser: LineParser::new(options.default_range_max),
            options,
            line: 0,
            buf: String::with_capacity(4096),
            skipped: 0,
            other: BTreeMap::new(),
        })
    }

    /// The next scan, odometry or parameter record; `None` at the end.
    /// Message types this reader does not use are counted, not returned.
    pub fn next_record(&mut self) -> Option<Result<Record, LogError>> {
        loop {
            self.buf.clear();
            self.line += 1;
            match self.input.read_line(&mut self.buf) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(source) => {
                    return Some(Err(LogError::Read { path: self.path.clone(), line: self.line, source }));
                }
            }
            let text = self.buf.strip_suffix('\n').unwrap_or(&self.buf);
            match self.parser.parse(text) {
                Ok(None) => {}
                Ok(Some(Record::Other(kind))) => *self.other.entry(kind).or_default() += 1,
                Ok(Some(record)) => return Some(Ok(record)),
                Err(_) if self.options.skip_bad => self.skipped += 1,
                Err(source) => {
                    return Some(Err(LogError::Bad { path: self.path.clone(), line: self.line, source }));
                }
            }
        }
    }

    /// Malformed records skipped so far (with `skip_bad`).
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Records of other message types seen so far, by type.
    pub fn other_records(&self) -> &BTreeMap<String, u64> {
        &self.other
    }

    /// The 1-based line last read (0 before the first).
    pub fn line(&self) -> usize {
        self.line
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Iterator for LogReader {
    type Item = Result<Record, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_record()
    }
}

/// Reads a whole log into memory.
pub fn read_log(path: &Path, options: ReadOptions) -> Result<Vec<Record>, LogError> {
    LogReader::open(path, options)?.collect()
}

/// Reads a log's front-laser scans (each with the odometry at its stamp),
/// in order: what SLAM and the robot player consume.
pub fn read_front_scans(path: &Path, options: ReadOptions) -> Result<Vec<LaserReading>, LogError> {
    LogReader::open(path, options)?
        .filter_map(|r| match r {
            Ok(Record::Scan(Laser::Front, s)) => Some(Ok(s)),
            Ok(_) => None,
            Err(e) => Some(Err(e)),
        })
        .collect()
}
