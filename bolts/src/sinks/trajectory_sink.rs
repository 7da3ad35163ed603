//! `sink.trajectory`: collects poses and writes `DIR/<file>` (TUM) at the
//! end. It takes `PoseStamped` estimates, and `LaserReading`s (their
//! odometry poses: the raw-odometry trajectory of a log). With `frame`, the
//! file's first line declares the poses' frame (`# frame: map` for a
//! localizer's, whose poses are in the given map's frame), and `squall
//! eval` scores them in it.

use std::path::PathBuf;

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use squall_core::sensor::{LaserReading, PoseStamped};
use squall_core::trajectory::Trajectory;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct P {
    /// File name inside the run's output directory. The default is
    /// `trajectory.tum`.
    #[serde(default = "default_file")]
    file: String,
    /// The frame the poses are in, declared in the file (one word).
    #[serde(default)]
    frame: Option<String>,
}

fn default_file() -> String {
    "trajectory.tum".to_string()
}

/// Writes a TUM trajectory of what it receives.
#[derive(Debug)]
pub struct TrajectorySink {
    file: String,
    frame: Option<String>,
    out: Option<PathBuf>,
    trajectory: Trajectory,
}

impl TrajectorySink {
    /// Builds the sink from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let P { file, frame } = p.parse()?;
        if file.is_empty() || file.contains('/') {
            return Err(ParamError::new(format!("file must be a plain file name, got \"{file}\"")));
        }
        if let Some(f) = frame.as_deref().filter(|f| f.is_empty() || f.contains(char::is_whitespace)) {
            return Err(ParamError::new(format!("frame must be one word, such as \"map\", got \"{f}\"")));
        }
        if p.parallelism() != 1 {
            return Err(ParamError::new("sink.trajectory writes one file: use parallelism 1"));
        }
        Ok(TrajectorySink { file, frame, out: None, trajectory: Trajectory::default() })
    }
}

impl Bolt for TrajectorySink {
    fn declare(&self, d: &mut Declarer) {
        d.input::<PoseStamped>().input::<LaserReading>();
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.out = ctx.out_dir().map(|d| d.join(&self.file));
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        let (stamp, pose) = match (input.get::<PoseStamped>(), input.get::<LaserReading>()) {
            (Some(p), _) => (p.stamp, p.pose),
            (None, Some(s)) => (s.stamp, s.odometry),
            _ => return Err("sink.trajectory takes PoseStamped or LaserReading".into()),
        };
        if self.trajectory.stamps.last().is_some_and(|&last| stamp < last) {
            return Err(format!(
                "pose at {stamp} s arrived after one at {} s: out of order",
                self.trajectory.stamps[self.trajectory.len() - 1]
            )
            .into());
        }
        self.trajectory.push(stamp, pose);
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        out.count("poses", self.trajectory.len() as u64);
        if let Some(path) = &self.out {
            super::write_tum(&self.trajectory, self.frame.as_deref(), path)
                .map_err(|e| format!("{}: {e}", path.display()))?;
        }
        Ok(())
    }
}
