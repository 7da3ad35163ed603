//! Writers of results: map images, trajectories. Library functions, and the
//! `sink.trajectory` and `sink.map` bolts that call them at the end of a run.
//! Every file is written atomically.

mod hypotheses_sink;
mod map_sink;
mod trajectory_sink;

use std::path::Path;

pub use hypotheses_sink::HypothesesSink;
pub use map_sink::MapSink;
use squall_topology::Registry;
use squall_topology::fsio::write_atomic;
pub use trajectory_sink::TrajectorySink;

use squall_core::trajectory::Trajectory;

/// Writes `trajectory` to `path` in TUM format (atomically), declaring
/// the poses' `frame` in its first line if given.
pub fn write_tum(trajectory: &Trajectory, frame: Option<&str>, path: &Path) -> std::io::Result<()> {
    let text = match frame {
        Some(frame) => trajectory.to_tum_in_frame(frame),
        None => trajectory.to_tum(),
    };
    write_atomic(path, text.as_bytes())
}

/// Registers `sink.trajectory`, `sink.map` and `sink.hypotheses`.
pub fn register(r: &mut Registry) {
    r.register_bolt("sink.hypotheses", HypothesesSink::from_params);
    r.register_bolt("sink.trajectory", TrajectorySink::from_params);
    r.register_bolt("sink.map", MapSink::from_params);
}
