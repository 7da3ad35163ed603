//! squall-bolts' errors: settings out of range, parameter tables that do
//! not deserialize, filters asked for no tasks, inputs that do not fit a
//! filter, and particle states that do not cross between tasks.

use std::path::PathBuf;

/// Why a model, a filter or a bolt could not be built or fed.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A numeric setting outside its range.
    #[error("{name} must be {expected}, got {}", squall_topology::spec::readable_number(*.found))]
    OutOfRange {
        /// The setting.
        name: &'static str,
        /// The range it must be in, in words (`> 0`, `≥ 0`, `in [0, 90]`).
        expected: &'static str,
        /// The value given.
        found: f64,
    },
    /// A setting that is invalid for a reason its message says in full
    /// (a count of zero, settings that do not go together).
    #[error("{0}")]
    Setting(String),
    /// A component's parameter table does not deserialize.
    #[error("{0}")]
    Params(String),
    /// A filter split over no tasks.
    #[error("at least one shard")]
    NoShards,
    /// A grid cell size that is not a positive number of metres.
    #[error("grid resolution {0} is not a positive number of metres")]
    Resolution(f64),
    /// A wall threshold that is not an occupancy in 0..=1.
    #[error("wall threshold {0} is not an occupancy in 0..=1")]
    WallThreshold(f64),
    /// A particle's scan-match reports, not one per particle.
    #[error("{reports} reports for {particles} particles: expected one per particle")]
    ReportCount {
        /// Particles in the population.
        particles: usize,
        /// Reports given.
        reports: usize,
    },
    /// A task was told to take up a particle whose state it does not have.
    #[error("task {task}: no state for new slot {slot} (parent {parent})")]
    MissingState {
        /// The task.
        task: usize,
        /// The new slot.
        slot: usize,
        /// Its parent's slot.
        parent: usize,
    },
    /// What the settings ask for would not fit the run's memory limit.
    #[error(transparent)]
    OverBudget(#[from] squall_topology::bounds::OverBudget),
    /// A line-map file that does not read or parse.
    #[error(transparent)]
    MapFile(#[from] squall_core::textfile::TextFileError),
    /// This process may not touch the file (a worker's `--data-dir` and
    /// `--out`).
    #[error(transparent)]
    Confined(#[from] squall_topology::confine::ConfinementError),
    /// A map's inside could not be found (see `squall_core::interior`).
    #[error(transparent)]
    Core(#[from] squall_core::Error),
    /// The scene cache could not be read or written.
    #[error(transparent)]
    SceneCache(#[from] SceneCacheError),
    /// The process-wide scene grid cache was poisoned by a panic.
    #[error("the scene grid cache was poisoned")]
    CachePoisoned,
    /// A grid or tile that does not decode.
    #[error(transparent)]
    Grid(#[from] GridWireError),
}

/// Why a cached grid could not be used or written.
#[derive(Debug, thiserror::Error)]
pub enum SceneCacheError {
    /// The cache file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
}

/// Why a grid or tile read from another process was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridWireError {
    /// A tile with another number of cells.
    #[error("a tile holds {expected} cells, got {got}")]
    TileCells {
        /// Cells in a tile.
        expected: usize,
        /// Cells read.
        got: usize,
    },
    /// A cell that counts more than it can.
    #[error(
        "tile cell ({x}, {y}): {hits} hits in {visits} visits (a cell counts at most {max_visits} visits and no more hits than visits)"
    )]
    CellCounts {
        /// Column in the tile.
        x: usize,
        /// Row in the tile.
        y: usize,
        /// Its hits.
        hits: u32,
        /// Its visits.
        visits: u32,
        /// The most visits a cell counts.
        max_visits: u32,
    },
    /// A tile with another number of bit rows.
    #[error("a tile has {expected} bit rows, got {got}")]
    BitRows {
        /// Bit rows in a tile.
        expected: usize,
        /// Rows read.
        got: usize,
    },
    /// A cell size that is not a positive number of metres.
    #[error("grid resolution {0} is not a positive number of metres")]
    Resolution(f64),
    /// An origin that is not finite.
    #[error("grid origin {0:?} is not finite")]
    Origin((f64, f64)),
    /// A wall threshold that is not an occupancy.
    #[error("wall threshold {0} is not an occupancy in 0..=1")]
    WallThreshold(f64),
    /// An index whose size is not its width times its height.
    #[error("a grid index of {wide} × {high} tiles holds {entries} entries")]
    IndexSize {
        /// Tiles wide.
        wide: usize,
        /// Tiles high.
        high: usize,
        /// Entries in the index.
        entries: usize,
    },
    /// Tiles whose coordinates overflow.
    #[error("grid tiles from {0:?} reach beyond the coordinates")]
    Reach((i64, i64)),
    /// A hit cell whose mean hit point is not finite.
    #[error("tile {tile}, cell ({x}, {y}): mean hit point is not finite")]
    MeanHit {
        /// The tile's index entry.
        tile: usize,
        /// Column in the tile.
        x: usize,
        /// Row in the tile.
        y: usize,
    },
    /// Bit rows that disagree with the cells.
    #[error("tile {tile}, cell ({x}, {y}): wall and free bits disagree with the cell")]
    Bits {
        /// The tile's index entry.
        tile: usize,
        /// Column in the tile.
        x: usize,
        /// Row in the tile.
        y: usize,
    },
}

/// The result of squall-bolts' fallible steps.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `Ok` if `value` is finite and above zero.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::OutOfRange { name, expected: "> 0", found: value })
    }
}

/// `Ok` if `value` is finite and not below zero.
pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(Error::OutOfRange { name, expected: "≥ 0", found: value })
    }
}
