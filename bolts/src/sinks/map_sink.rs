//! `sink.map`: keeps the newest map and writes `DIR/<stem>.pgm`,
//! `.yaml` and `.png` at the end; poses it receives are drawn on the PNG.

use std::path::PathBuf;

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use squall_core::geometry::Pose2;
use squall_core::map_files::{write_pgm_yaml, write_png};
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::PoseStamped;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct P {
    /// File stem inside the run's output directory. The default is `map`.
    #[serde(default = "default_stem")]
    stem: String,
}

fn default_stem() -> String {
    "map".to_string()
}

/// Writes the last map received, with the path of the poses received.
#[derive(Debug)]
pub struct MapSink {
    stem: String,
    out: Option<PathBuf>,
    map: Option<std::sync::Arc<OccupancyGrid>>,
    path: Vec<Pose2>,
}

impl MapSink {
    /// Builds the sink from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let P { stem } = p.parse()?;
        if stem.is_empty() || stem.contains('/') {
            return Err(ParamError::new(format!("stem must be a plain file name, got \"{stem}\"")));
        }
        if p.parallelism() != 1 {
            return Err(ParamError::new("sink.map writes one map: use parallelism 1"));
        }
        Ok(MapSink { stem, out: None, map: None, path: Vec::new() })
    }
}

impl Bolt for MapSink {
    fn declare(&self, d: &mut Declarer) {
        d.input::<OccupancyGrid>().input::<PoseStamped>();
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.out = ctx.out_dir().map(|d| d.to_path_buf());
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(p) = input.get::<PoseStamped>() {
            self.path.push(p.pose);
            return Ok(());
        }
        let map =
            input.into_arc::<OccupancyGrid>().map_err(|_| "sink.map takes OccupancyGrid or PoseStamped")?;
        self.map = Some(map);
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let (Some(dir), Some(map)) = (&self.out, &self.map) else {
            out.count("maps_written", 0);
            return Ok(());
        };
        write_pgm_yaml(map, dir, &self.stem)?;
        write_png(map, &self.path, &dir.join(format!("{}.png", self.stem)))?;
        out.count("maps_written", 1);
        Ok(())
    }
}
