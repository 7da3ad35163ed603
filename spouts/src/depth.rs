//! The `depth_sim` spout: the simulator's robot carrying a depth camera.
//! Along the simulated route (the laser simulator's, at its scan rate) it
//! renders a depth frame of the line map, with boxes scattered on the
//! floor as clutter and people walking the roadmap. Streams `frame` (`DepthFrame`) and `truth`
//! (`PoseStamped`).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;
use squall_core::camera::DepthFrame;
use squall_core::depth_render::{Clutter, DepthCamera, Props};
use squall_core::linemap::LineMap;
use squall_core::sensor::PoseStamped;
use squall_topology::{BoxError, Declarer, Emitter, ParamError, Params, Spout, SpoutStatus, TaskContext};

use crate::sim::people::Crowd;
use crate::sim::{SimConfig, SimEvent, Simulation, floor_for};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct P {
    /// `"office"` or a line-map file.
    #[serde(default = "default_world")]
    world: String,
    /// Simulated seconds. The default is 60.
    #[serde(default = "default_duration")]
    duration_secs: f64,
    /// Frames per second. The default is 10.
    #[serde(default = "default_rate")]
    frame_hz: f64,
    /// Boxes scattered on the floor. The default is 20.
    #[serde(default = "default_boxes")]
    boxes: usize,
    /// People walking about. The default is 5.
    #[serde(default = "default_people")]
    people: usize,
    /// Seed; the default is the topology's.
    seed: Option<u64>,
}

fn default_world() -> String {
    "office".into()
}
fn default_duration() -> f64 {
    60.0
}
fn default_rate() -> f64 {
    10.0
}
fn default_boxes() -> usize {
    20
}
fn default_people() -> usize {
    5
}

/// Emits depth frames along a simulated route.
#[derive(Debug)]
pub struct DepthSimSpout {
    p: P,
    seed: u64,
    camera: DepthCamera,
    sim: Option<World>,
}

/// The running simulation: the robot's, the map, the boxes, the people
/// and the camera's noise.
#[derive(Debug)]
struct World {
    sim: Simulation,
    map: LineMap,
    boxes: Vec<Clutter>,
    crowd: Crowd,
    /// The instant the crowd was last moved to.
    crowd_time: f64,
    noise: ChaCha8Rng,
}

impl DepthSimSpout {
    /// Builds the spout from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: P = p.parse()?;
        if !(params.duration_secs > 0.0 && params.frame_hz > 0.0) {
            return Err(ParamError::new("duration_secs and frame_hz must be > 0"));
        }
        let seed = params.seed.unwrap_or(p.seed());
        Ok(DepthSimSpout { p: params, seed, camera: DepthCamera::d435_on_robot(), sim: None })
    }
}

impl Spout for DepthSimSpout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<DepthFrame>("frame").output::<PoseStamped>("truth");
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        let floor = floor_for(&self.p.world, self.seed)?;
        let map = floor.world.clone();
        // Boxes at random places of the map, kept off the roadmap's nodes.
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0xb0e5);
        let (x0, y0, x1, y1) = map.bounds();
        let mut boxes = Vec::with_capacity(self.p.boxes);
        while boxes.len() < self.p.boxes {
            let (x, y) = (x0 + rng.random::<f64>() * (x1 - x0), y0 + rng.random::<f64>() * (y1 - y0));
            if floor.nodes.iter().all(|n| (n.0 - x).hypot(n.1 - y) > 1.0) {
                boxes.push(Clutter { min: (x, y), max: (x + 0.4, y + 0.4), height: 0.6 });
            }
        }
        let config = SimConfig {
            seed: self.seed,
            duration_secs: self.p.duration_secs,
            scan_hz: self.p.frame_hz,
            range_max: 8.0,
            beams: 2,
            ..SimConfig::default()
        };
        config.check()?;
        ctx.expect_emits(2 * (self.p.duration_secs * self.p.frame_hz) as u64);
        let crowd = Crowd::new(&floor, self.p.people, self.seed);
        self.sim = Some(World {
            sim: Simulation::new(floor, config),
            map,
            boxes,
            crowd,
            crowd_time: 0.0,
            noise: ChaCha8Rng::seed_from_u64(self.seed ^ 0xde97),
        });
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let world = self.sim.as_mut().ok_or("the depth simulation was not opened")?;
        loop {
            match world.sim.next() {
                None => return Ok(SpoutStatus::Done),
                Some(SimEvent::Odom(_)) => continue,
                Some(SimEvent::Scan(scan, truth)) => {
                    world.crowd.advance(world.sim.floor(), scan.stamp - world.crowd_time);
                    world.crowd_time = scan.stamp;
                    let people = world.crowd.people(world.sim.floor());
                    let props = Props { boxes: &world.boxes, people: &people };
                    let image = self.camera.render(&world.map, props, &truth, &mut world.noise);
                    out.emit("frame", DepthFrame { stamp: scan.stamp, odometry: scan.odometry, image })
                        .await?;
                    out.emit("truth", PoseStamped { stamp: scan.stamp, pose: truth }).await?;
                    return Ok(SpoutStatus::Continue);
                }
            }
        }
    }
}
