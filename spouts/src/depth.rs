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
use squall_topology::bounds::MAX_SIM_SECS;
use squall_topology::spec::readable_number;
use squall_topology::{
    BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
};

use crate::sim::office::Floor;
use crate::sim::people::Crowd;
use crate::sim::{DEFAULT_WORLD, Kidnap, SimConfig, SimEvent, Simulation, Start, floor_for};
use crate::{Error, Result};

/// The fastest simulated frame rate: 1 kHz, ten times the fastest depth
/// camera sold (90 frames a second).
const MAX_FRAME_HZ: f64 = 1000.0;

/// The `depth_sim` spout's params; a param left out takes its value from
/// [`P::default`].
#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct P {
    /// `"office"` or a line-map file. The default is [`DEFAULT_WORLD`],
    /// `"office"`.
    world: String,
    /// Simulated seconds. The default is 60.
    duration_secs: f64,
    /// Frames per second. The default is 10.
    frame_hz: f64,
    /// Boxes scattered on the floor. The default is 20.
    boxes: usize,
    /// People walking about. The default is 5.
    people: usize,
    /// Seed; the default (`None`) is the topology's.
    seed: Option<u64>,
    /// Where the robot starts: `"first_node"` (the default) or `"drawn"`
    /// per seed ([`Start`]).
    start: Start,
    /// A kidnapping, e.g. `{ at_secs = 10 }` (carried 5–20 m, drawn per
    /// seed; [`Kidnap`]). The default is none.
    kidnap: Option<Kidnap>,
}

impl Default for P {
    fn default() -> Self {
        P {
            world: DEFAULT_WORLD.into(),
            duration_secs: 60.0,
            frame_hz: 10.0,
            boxes: 20,
            people: 5,
            seed: None,
            start: Start::default(),
            kidnap: None,
        }
    }
}

/// Places tried in a row for one box before `depth_sim` gives up: on a map
/// with room for boxes a place is found within a few tries.
const BOX_TRIES: u64 = 100_000;

/// `count` boxes at random places of `floor`'s map, each more than 1 m
/// from every node of its roadmap (so the robot's route stays clear); the
/// places are drawn from `seed`. An error when [`BOX_TRIES`] places in a
/// row are all too near the roadmap: the map has no room for them.
fn place_boxes(floor: &Floor, count: usize, seed: u64) -> Result<Vec<Clutter>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xb0e5);
    let (x0, y0, x1, y1) = floor.world.bounds();
    let mut boxes = Vec::new();
    boxes.try_reserve_exact(count).map_err(|_| Error::TooMany { count, what: "boxes" })?;
    let mut tries = 0;
    while boxes.len() < count {
        if tries == BOX_TRIES {
            return Err(Error::NoRoomForBoxes { placed: boxes.len(), wanted: count, tries });
        }
        tries += 1;
        let (x, y) = (x0 + rng.random::<f64>() * (x1 - x0), y0 + rng.random::<f64>() * (y1 - y0));
        if floor.nodes.iter().all(|n| (n.0 - x).hypot(n.1 - y) > 1.0) {
            boxes.push(Clutter { min: (x, y), max: (x + 0.4, y + 0.4), height: 0.6 });
            tries = 0;
        }
    }
    Ok(boxes)
}

/// Emits depth frames along a simulated route.
#[derive(Debug)]
pub struct DepthSimSpout {
    p: P,
    seed: u64,
    camera: DepthCamera,
    sim: Option<World>,
    /// Frames emitted, for the progress display.
    readings: ReadingCounter,
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
        let hz_ok = params.frame_hz > 0.0 && params.frame_hz <= MAX_FRAME_HZ;
        if !(params.duration_secs > 0.0 && params.duration_secs <= MAX_SIM_SECS && hz_ok) {
            return Err(ParamError::new(format!(
                "duration_secs must be in (0, {MAX_SIM_SECS}] (stamps keep a microsecond's resolution) \
                 and frame_hz in (0, {MAX_FRAME_HZ}], got {} and {}",
                readable_number(params.duration_secs),
                readable_number(params.frame_hz)
            )));
        }
        crate::sim::outputs_fit(p.budget(), params.duration_secs, params.frame_hz, "frames")
            .map_err(ParamError::new)?;
        let seed = params.seed.unwrap_or(p.seed());
        Ok(DepthSimSpout {
            p: params,
            seed,
            camera: DepthCamera::d435_on_robot(),
            sim: None,
            readings: ReadingCounter::default(),
        })
    }
}

impl Spout for DepthSimSpout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<DepthFrame>("frame").output::<PoseStamped>("truth");
        if let Some(file) = crate::sim::world_file(&self.p.world) {
            d.reads(file);
        }
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        let floor = floor_for(&self.p.world, self.seed)?;
        let map = floor.world.clone();
        let boxes = place_boxes(&floor, self.p.boxes, self.seed)?;
        let config = SimConfig {
            seed: self.seed,
            duration_secs: self.p.duration_secs,
            scan_hz: self.p.frame_hz,
            range_max: 8.0,
            beams: 2,
            start: self.p.start,
            kidnap: self.p.kidnap,
            ..SimConfig::default()
        };
        config.check()?;
        let frames = (self.p.duration_secs * self.p.frame_hz) as u64;
        ctx.expect_emits(2 * frames);
        self.readings = ctx.readings("frames", || Some(frames));
        let crowd = Crowd::new(&floor, self.p.people, self.seed)?;
        self.sim = Some(World {
            sim: Simulation::new(floor, config)?,
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
                    self.readings.add(1);
                    return Ok(SpoutStatus::Continue);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_left_out_take_the_documented_defaults() {
        let p: P = Params::new(toml::Table::new(), 7, 1).parse().unwrap();
        assert_eq!((p.world.as_str(), p.duration_secs, p.frame_hz), ("office", 60.0, 10.0));
        assert_eq!((p.boxes, p.people, p.seed), (20, 5, None));
        let unknown = Params::new(toml::from_str("box = 3").unwrap(), 7, 1).parse::<P>().unwrap_err();
        assert!(unknown.to_string().starts_with("unknown field `box`"), "{unknown}");
    }

    #[test]
    fn boxes_keep_off_the_roadmap_or_say_there_is_no_room() {
        let floor = crate::sim::office::office(3, 3, 2);
        let boxes = place_boxes(&floor, 20, 3).unwrap();
        assert_eq!(boxes.len(), 20);
        assert!(boxes.iter().all(|b| floor.nodes.iter().all(|n| (n.0 - b.min.0).hypot(n.1 - b.min.1) > 1.0)));
        // A 2.5 m room: every point lies within 1 m of its roadmap.
        let room = LineMap::parse("room", "0,0,2.5,0\n2.5,0,2.5,2.5\n2.5,2.5,0,2.5\n0,2.5,0,0\n").unwrap();
        let small = crate::sim::roadmap::roadmap(room, 0.5, 0.35).unwrap();
        let e = place_boxes(&small, 1, 3).unwrap_err();
        assert_eq!(e.to_string(), "no place for box 1 of 1 at least 1 m from the roadmap after 100000 tries");
        assert!(place_boxes(&small, 0, 3).unwrap().is_empty());
    }
}
