//! `slam.backend`: the pose-graph back end as a bolt downstream of the
//! resampler. It keeps the scans that become nodes as they pass, takes the
//! best lineage's trajectory when the resampler writes it at the end, and
//! emits that trajectory with its loops closed (see the module above). The
//! matcher's maps pass through as they come; where a loop was closed, the
//! map rebuilt along the corrected poses follows them as the final one.

use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Tuple};

use squall_core::geometry::Pose2;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::{LaserReading, PoseStamped};

use super::{BackendOptions, NodePicker, close_loops};
use crate::slam::grid::TiledGrid;
use crate::slam::integrate::integrate_scan;

/// The back end's bolt: takes `LaserReading`s (the source's scans),
/// `PoseStamped` (the resampler's trajectory) and `OccupancyGrid` (the
/// matcher's maps); emits `PoseStamped` on `trajectory` at the end and
/// `OccupancyGrid` on `map` as the maps pass and at the end.
#[derive(Debug)]
pub struct Backend {
    options: BackendOptions,
    /// The readings kept as nodes.
    picker: NodePicker,
    trajectory: Vec<(f64, Pose2)>,
    /// Cell size of the matcher's maps, once one has passed.
    resolution: Option<f64>,
}

impl Backend {
    /// Builds it from its `params` (the fields of [`BackendOptions`]).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let options: BackendOptions = p.parse()?;
        options.check().map_err(ParamError::new)?;
        if p.parallelism() != 1 {
            return Err(ParamError::new("slam.backend sees the whole lineage: use parallelism 1"));
        }
        Ok(Backend { options, picker: NodePicker::new(options), trajectory: Vec::new(), resolution: None })
    }

    /// The map along `poses` (every scan's), from the readings kept, at
    /// the matcher's map's resolution.
    fn rebuilt_map(&self, poses: &[(f64, Pose2)], resolution: f64) -> Result<OccupancyGrid, BoxError> {
        let mut grid = TiledGrid::new(resolution, (0.0, 0.0))?;
        let mut k = 0;
        for reading in self.picker.readings() {
            while k < poses.len() && poses[k].0 < reading.stamp {
                k += 1;
            }
            if let Some(&(stamp, pose)) = poses.get(k)
                && stamp == reading.stamp
            {
                integrate_scan(&mut grid, &pose, reading, self.options.map_range);
            }
        }
        Ok(grid.to_occupancy())
    }
}

impl Bolt for Backend {
    fn declare(&self, d: &mut Declarer) {
        d.input::<LaserReading>()
            .input::<PoseStamped>()
            .input::<OccupancyGrid>()
            .output::<PoseStamped>("trajectory")
            .output::<OccupancyGrid>("map");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(p) = input.get::<PoseStamped>() {
            self.trajectory.push((p.stamp, p.pose));
        } else if let Some(scan) = input.get::<LaserReading>() {
            self.picker.offer(scan);
        } else {
            // Maps pass through as they come (a viewer sees the map grow);
            // the last one's cell size is the rebuilt map's.
            let map = input
                .into_arc::<OccupancyGrid>()
                .map_err(|_| "slam.backend takes LaserReading, PoseStamped and OccupancyGrid")?;
            self.resolution = Some(map.resolution);
            out.emit_shared("map", map).await?;
        }
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let started = std::time::Instant::now();
        let nodes = self.picker.nodes();
        let (poses, report) = close_loops(&self.trajectory, &nodes, &self.options);
        out.record("close_loops_ms", started.elapsed().as_millis() as u64);
        out.count("nodes", report.nodes as u64);
        out.count("searches", report.searches as u64);
        out.count("loops", report.loops as u64);
        out.count("optimizations", report.optimizations as u64);
        out.count("full_optimizations", report.full_optimizations as u64);
        out.record("largest_move_mm", (report.largest_move * 1000.0) as u64);
        // With a loop closed, the matcher's last map no longer fits the
        // poses: the map rebuilt along them follows it as the final one.
        if let Some(resolution) = self.resolution
            && report.loops > 0
        {
            let started = std::time::Instant::now();
            let rebuilt = self.rebuilt_map(&poses, resolution)?;
            out.record("map_rebuild_ms", started.elapsed().as_millis() as u64);
            out.emit("map", rebuilt).await?;
        }
        self.picker = NodePicker::new(self.options);
        for (stamp, pose) in poses {
            out.emit("trajectory", PoseStamped { stamp, pose }).await?;
        }
        Ok(())
    }
}
