//! What can go wrong in squall-spouts: reading a log, a bag or a map, the
//! simulator's settings and floors, writing a simulated run. One type, so
//! that a caller combining several sources can use `?` throughout. The
//! errors that others wrap with the place they happened (a record with its
//! file and line, a message with its bag, a roadmap with its world) are
//! their own types and convert into it.

use squall_core::geometry::Real;
use squall_core::textfile::TextFileError;

use crate::carmen::{LogError, RecordError};
use crate::rosbag2::{BagError, CdrError};
use crate::sim::roadmap::RoadmapError;

/// An error of squall-spouts. Its text says what was expected and, for
/// files, where.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A CARMEN log could not be read or holds a malformed record.
    #[error(transparent)]
    Log(#[from] LogError),
    /// A CARMEN line is malformed (without the file and line; see
    /// [`Error::Log`]).
    #[error(transparent)]
    Record(#[from] RecordError),
    /// A ROS 2 bag could not be read or holds a malformed message.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// A CDR message does not decode (without the bag; see [`Error::Bag`]).
    #[error(transparent)]
    Cdr(#[from] CdrError),
    /// This process may not read the file (a worker's `--data-dir`).
    #[error(transparent)]
    Confined(#[from] squall_topology::confine::ConfinementError),
    /// A line-map file could not be read or holds a malformed line.
    #[error(transparent)]
    LineMap(#[from] TextFileError),
    /// A world's map has no roadmap for the robot to drive.
    #[error("{world}: {source}")]
    Roadmap {
        /// The world: the line-map file.
        world: String,
        /// Why there is no roadmap.
        source: RoadmapError,
    },
    /// A signal stopped the process (Ctrl-C or SIGTERM) while a run was
    /// simulated into files.
    #[error("stopped (Ctrl-C or SIGTERM) while the run was simulated")]
    Stopped,
    /// The simulated time is not a positive number of seconds, or is
    /// past [`MAX_SIM_SECS`](squall_topology::bounds::MAX_SIM_SECS).
    #[error(
        "duration_secs must be > 0 s and at most {} s (stamps keep a microsecond's resolution), got {}",
        squall_topology::bounds::MAX_SIM_SECS,
        squall_topology::spec::readable_number(*.0)
    )]
    Duration(Real),
    /// Fewer than 2 laser beams (a scan needs a first and a last), or more
    /// than [`MAX_BEAMS`](squall_topology::bounds::MAX_BEAMS).
    #[error("beams must be in 2..={max}, got {0}", max = squall_topology::bounds::MAX_BEAMS)]
    Beams(usize),
    /// The field of view (radians) is not in (0, 2π].
    #[error("field of view must be in (0°, 360°], got {}°", .0.to_degrees())]
    FieldOfView(Real),
    /// The laser's range or noise is out of range.
    #[error("range_max must be > 0, range_noise ≥ 0 and dropout in [0, 1]")]
    Laser {
        /// Range, metres: must be > 0.
        range_max: Real,
        /// Standard deviation of range noise, metres: must be ≥ 0.
        range_noise: Real,
        /// Probability of no return: must be in [0, 1].
        dropout: Real,
    },
    /// A simulated sensor or wheel fault's setting is out of range.
    #[error("{0}")]
    Faults(String),
    /// A kidnapping outside the run or with an impossible carry.
    #[error(
        "a kidnapping needs 0 ≤ at_secs < the duration and 0 ≤ min_m ≤ max_m, got at_secs {at_secs}, min_m {min_m}, max_m {max_m}"
    )]
    Kidnap {
        /// When, seconds.
        at_secs: Real,
        /// The shortest carry, metres.
        min_m: Real,
        /// The longest carry, metres.
        max_m: Real,
    },
    /// The scan rate or the robot's top speeds are not positive.
    #[error("scan rate, speed and turn rate must be > 0")]
    Motion {
        /// Scans per second.
        scan_hz: Real,
        /// Top speed, m/s.
        max_speed: Real,
        /// Top turn rate, rad/s.
        max_turn: Real,
    },
    /// A floor without nodes: nowhere for the robot or people to be.
    #[error("the floor has no nodes")]
    EmptyFloor,
    /// A floor's edge names a node the floor does not have.
    #[error("the floor's edge {a}–{b} names a node it does not have (it has {nodes})")]
    EdgeOutOfRange {
        /// One end.
        a: usize,
        /// The other end.
        b: usize,
        /// Nodes on the floor.
        nodes: usize,
    },
    /// The robot starts at the floor's first node, and no edge leaves it.
    #[error("the floor's first node has no edge: the robot has nowhere to drive")]
    Stranded,
    /// An odometry quality the simulator does not have.
    #[error("odometry must be good, poor or bad, got {0:?}")]
    OdometryQuality(String),
    /// `depth_sim` found no place for a box away from the roadmap: the map
    /// is too small for them.
    #[error("no place for box {} of {wanted} at least 1 m from the roadmap after {tries} tries", .placed + 1)]
    NoRoomForBoxes {
        /// Boxes placed.
        placed: usize,
        /// Boxes asked for.
        wanted: usize,
        /// Places tried for the next box.
        tries: u64,
    },
    /// More props (boxes, people) asked for than memory holds.
    #[error("no memory for {count} {what}")]
    TooMany {
        /// How many were asked for.
        count: usize,
        /// What they are.
        what: &'static str,
    },
    /// A file of a simulated run could not be written. The text is the
    /// system's alone: callers say which folder they were writing into.
    #[error("{source}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A map image of a simulated run could not be made or written.
    #[error(transparent)]
    Core(#[from] squall_core::Error),
}

/// A result whose error is squall-spouts' [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
