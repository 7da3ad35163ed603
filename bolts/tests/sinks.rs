//! The sink bolts in a running topology.

use squall_core::geometry::Pose2;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::PoseStamped;
use squall_core::trajectory::declared_frame;
use squall_topology::{
    BoxError, Declarer, Emitter, Params, Registry, RunOptions, Spout, SpoutStatus, Topology, TopologySpec,
};

/// Emits three maps (a wall growing) and a path of poses.
struct Mapper {
    step: usize,
}

impl Spout for Mapper {
    fn declare(&self, d: &mut Declarer) {
        d.output::<OccupancyGrid>("map").output::<PoseStamped>("pose");
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.step == 3 {
            return Ok(SpoutStatus::Done);
        }
        let mut grid = OccupancyGrid::unknown(20, 10, 0.1, (0.0, 0.0));
        for x in 0..=self.step * 5 {
            grid.set(x, 9, 100);
        }
        for y in 0..5 {
            for x in 0..20 {
                grid.set(x, y, 0);
            }
        }
        out.emit("map", grid).await?;
        let pose = Pose2::new(0.05 + 0.5 * self.step as f64, 0.25, 0.0);
        out.emit("pose", PoseStamped { stamp: self.step as f64, pose }).await?;
        self.step += 1;
        Ok(SpoutStatus::Continue)
    }
}

#[test]
fn map_and_trajectory_sinks_write_their_files() {
    let mut registry = Registry::new();
    squall_bolts::sinks::register(&mut registry);
    registry.register_spout("mapper", |_: &Params| Ok(Mapper { step: 0 }));
    let toml = r#"
[topology]
name = "sinks"

[[spout]]
name = "mapper"
kind = "mapper"

[[bolt]]
name = "map"
kind = "sink.map"
inputs = [ { from = "mapper", stream = "map" }, { from = "mapper", stream = "pose" } ]

[[bolt]]
name = "trajectory"
kind = "sink.trajectory"
params = { file = "poses.tum" }
inputs = [ { from = "mapper", stream = "pose" } ]
"#;
    let topology = Topology::validate(TopologySpec::parse("sinks.toml", toml).unwrap(), &registry).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let options = RunOptions { out_dir: Some(dir.path().to_path_buf()), ..RunOptions::default() };
    squall_topology::run(&topology, &options).unwrap();

    let pgm = std::fs::read(dir.path().join("map.pgm")).unwrap();
    let pixels = &pgm[pgm.len() - 200..];
    // The last map has the top wall over columns 0..=10.
    assert_eq!(pixels[..11], [0; 11]);
    assert_eq!(pixels[11], 205);
    assert!(std::fs::read_to_string(dir.path().join("map.yaml")).unwrap().contains("resolution: 0.1"));
    let png = std::fs::read(dir.path().join("map.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let poses = std::fs::read_to_string(dir.path().join("poses.tum")).unwrap();
    assert_eq!(poses.lines().filter(|l| !l.starts_with('#')).count(), 3);

    assert_eq!(declared_frame(&poses), None, "no frame unless one is given");

    // With a frame, the file declares it and the poses are the same.
    let framed = toml.replace("{ file = \"poses.tum\" }", "{ file = \"poses.tum\", frame = \"map\" }");
    let topology =
        Topology::validate(TopologySpec::parse("sinks.toml", &framed).unwrap(), &registry).unwrap();
    squall_topology::run(&topology, &options).unwrap();
    let in_map = std::fs::read_to_string(dir.path().join("poses.tum")).unwrap();
    assert_eq!(declared_frame(&in_map), Some("map"));
    assert_eq!(in_map.lines().filter(|l| !l.starts_with('#')).collect::<Vec<_>>(), poses_only(&poses));

    // Bad parameters are reported by the factory.
    for (param, message) in [
        ("{ file = \"a/b.tum\" }", "file must be a plain file name"),
        ("{ file = \"poses.tum\", frame = \"my map\" }", "frame must be one word"),
    ] {
        let bad = toml.replace("{ file = \"poses.tum\" }", param);
        let e = Topology::validate(TopologySpec::parse("sinks.toml", &bad).unwrap(), &registry).unwrap_err();
        assert!(e.to_string().contains(message), "{e}");
    }
}

/// The pose lines of a TUM text.
fn poses_only(text: &str) -> Vec<&str> {
    text.lines().filter(|l| !l.starts_with('#')).collect()
}
