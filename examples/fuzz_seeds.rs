//! Writes the fuzz targets' seed corpus (`fuzz/`) from the real data in
//! `../shared/data` and the repository's example topologies, so each
//! fuzzer starts from inputs that parse and explores outward from them.
//! The data is not copied into the repository; the seeds are made where
//! they are needed (`fuzz/run` calls this).
//!
//! ```text
//! cargo run --release --example fuzz_seeds -- ../shared/data SEED_DIR
//! ```

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hdrhistogram::serialization::{Serializer, V2Serializer};
use squall::core::geometry::Pose2;
use squall::core::trajectory::Trajectory;
use squall::spouts::carmen::{ReadOptions, read_front_scans};
use squall::spouts::rosbag2::messages;
use squall::topology::cluster::wire::{Control, Frame, RunPlan, TaskEvent};

/// Messages kept per topic in the small bag.
const BAG_MESSAGES: usize = 12;
/// Lines in one excerpt of a text file.
const EXCERPT_LINES: usize = 40;
/// Lines in one excerpt of a CARMEN log (its lines are long).
const LOG_LINES: usize = 6;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data, out] = args.as_slice() else {
        bail!("usage: fuzz_seeds DATA_DIR SEED_DIR   (DATA_DIR is ../shared/data)");
    };
    let (data, out) = (Path::new(data), Path::new(out));
    let seeds = Seeds { out: out.to_path_buf() };
    carmen(&seeds, &data.join("laser"))?;
    bag(&seeds, &data.join("rosbag2/aces/aces.mcap"))?;
    line_maps(&seeds, &data.join("linemaps"))?;
    trajectories(&seeds, &data.join("laser"))?;
    topologies(&seeds, Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/topologies").as_path())?;
    frames(&seeds)?;
    command_lines(&seeds)?;
    println!("seeds written under {}", out.display());
    Ok(())
}

/// Command lines, one argument a line: each command with its numeric
/// flags, for the `cli_args` target.
fn command_lines(seeds: &Seeds) -> Result<()> {
    let lines = [
        "slam\n--log\na.clf\n--particles\n30\n--max-scans\n5\n--ui-linger\n1.5\n--metrics-every\n2\n--out\no",
        "localize\n--map\nm.txt\n--sim\n--duration\n20\n--kidnap-at\n8\n--seed\n3\n--out\no",
        "sim\n--duration\n600\n--beams\n180\n--fov-deg\n180\n--range-max\n30\n--out\no",
        "study\n--sim-worlds\noffice\n--sim-duration\n60\n--seeds\n1-10,12\n--jobs\n2\n--out\no",
        "speedup\n--particles\n20,60\n--matchers\n1,2\n--cutoff\nnone\n--out\no",
        "run\nt.toml\n--set\nmatcher.params.particles=60\n--out\no",
    ];
    for (i, line) in lines.iter().enumerate() {
        seeds.write("cli_args", &format!("command-{i}"), line.as_bytes())?;
    }
    Ok(())
}

/// Where each target's seeds go.
struct Seeds {
    out: PathBuf,
}

impl Seeds {
    fn write(&self, target: &str, name: &str, bytes: &[u8]) -> Result<()> {
        let dir = self.out.join(target);
        fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        fs::write(dir.join(name), bytes).with_context(|| format!("writing {target}/{name}"))
    }
}

/// `count` lines of `text` from line `from`, newline-terminated.
fn excerpt(text: &str, from: usize, count: usize) -> String {
    text.lines().skip(from).take(count).map(|l| format!("{l}\n")).collect()
}

fn files_ending(dir: &Path, suffix: &str) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(suffix))
        .collect();
    files.sort();
    Ok(files)
}

fn stem(path: &Path) -> String {
    path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// CARMEN logs: the head (PARAM lines and the first records), the middle,
/// and the PARAM lines alone, of each log.
fn carmen(seeds: &Seeds, dir: &Path) -> Result<()> {
    for log in files_ending(dir, ".clf")? {
        let text = fs::read_to_string(&log)?;
        let name = stem(&log);
        let middle = text.lines().count() / 2;
        seeds.write("carmen_lines", &format!("{name}-head"), excerpt(&text, 0, LOG_LINES).as_bytes())?;
        seeds.write(
            "carmen_lines",
            &format!("{name}-middle"),
            excerpt(&text, middle, LOG_LINES).as_bytes(),
        )?;
        let params: String =
            text.lines().filter(|l| l.starts_with("PARAM")).map(|l| format!("{l}\n")).collect();
        if !params.is_empty() {
            seeds.write("carmen_lines", &format!("{name}-params"), params.as_bytes())?;
        }
    }
    Ok(())
}

/// The ROS 2 bag: its first messages on each topic as CDR seeds (the
/// first byte picks the decoder, as in the target), and a small MCAP of
/// them, chunked and compressed as `rosbags` writes, and plain.
fn bag(seeds: &Seeds, path: &Path) -> Result<()> {
    let bytes = fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut kept: BTreeMap<String, usize> = BTreeMap::new();
    let mut small = Vec::new();
    for message in mcap::MessageStream::new(&bytes)? {
        let message = message?;
        let count = kept.entry(message.channel.topic.clone()).or_default();
        if *count >= BAG_MESSAGES {
            continue;
        }
        *count += 1;
        let kind = match message.channel.topic.as_str() {
            "/scan" => 0u8,
            "/odom" => 1,
            _ => 2,
        };
        if *count <= 2 {
            let mut seed = vec![kind];
            seed.extend_from_slice(&message.data);
            let topic = message.channel.topic.trim_start_matches('/').replace('/', "-");
            seeds.write("cdr_messages", &format!("{topic}-{count}"), &seed)?;
        }
        small.push(message);
    }
    let mut pose = vec![3u8];
    pose.extend(messages::pose_stamped(12.5, "map", &Pose2::new(1.0, -2.0, 0.3)));
    seeds.write("cdr_messages", "pose_stamped", &pose)?;
    for (name, compression) in [("chunked-zstd.mcap", Some(mcap::Compression::Zstd)), ("plain.mcap", None)] {
        let mut buffer = std::io::Cursor::new(Vec::new());
        let mut writer = mcap::WriteOptions::new().compression(compression).create(&mut buffer)?;
        for message in &small {
            writer.write(message)?;
        }
        writer.finish()?;
        drop(writer);
        seeds.write("mcap_bag", name, buffer.get_ref())?;
    }
    Ok(())
}

/// Building line maps: the smallest whole, the others' first walls.
fn line_maps(seeds: &Seeds, dir: &Path) -> Result<()> {
    for map in files_ending(dir, ".txt")? {
        let text = fs::read_to_string(&map)?;
        seeds.write("line_map", &stem(&map), excerpt(&text, 0, EXCERPT_LINES).as_bytes())?;
    }
    Ok(())
}

/// Relations files (first line `r`) and a TUM trajectory of a log's
/// odometry (first line `t`), as the target reads them.
fn trajectories(seeds: &Seeds, dir: &Path) -> Result<()> {
    for relations in files_ending(dir, ".relations")? {
        let text = fs::read_to_string(&relations)?;
        seeds.write(
            "trajectories",
            &stem(&relations),
            format!("r\n{}", excerpt(&text, 0, EXCERPT_LINES)).as_bytes(),
        )?;
    }
    let log = dir.join("aces.clf");
    let scans = read_front_scans(&log, ReadOptions::default())?;
    let mut odometry = Trajectory::default();
    for scan in scans.iter().take(EXCERPT_LINES) {
        odometry.push(scan.stamp, scan.odometry);
    }
    seeds.write("trajectories", "aces-odometry", format!("t\n{}", odometry.to_tum()).as_bytes())?;
    Ok(())
}

/// The example topologies, each also with an override section.
fn topologies(seeds: &Seeds, dir: &Path) -> Result<()> {
    for file in files_ending(dir, ".toml")? {
        let text = fs::read_to_string(&file)?;
        seeds.write("topology", &stem(&file), text.as_bytes())?;
    }
    let wordcount = fs::read_to_string(dir.join("wordcount.toml"))?;
    let with_sets = format!("{wordcount}\n%%\ncount.parallelism=3\ntopology.tick_secs=0.5\n");
    seeds.write("topology", "wordcount-sets", with_sets.as_bytes())?;
    Ok(())
}

/// One frame of each kind a run sends, and a latency histogram as a
/// worker reports it (first byte 0: a frame; 1: a histogram).
fn frames(seeds: &Seeds) -> Result<()> {
    let plan = RunPlan {
        run: "squall/run/1".into(),
        file: "slam.toml".into(),
        topology: "[spout.source]\nkind = \"probe.source\"\n".into(),
        hosts: vec![vec![0, 1], vec![1]],
        host: 1,
        host_count: 2,
        coordinator: "coordinator".into(),
    };
    let frames = [
        ("tuple", Frame::Tuple { sender: 1, edge: 2, from: 0, to: 1, payload: vec![7; 24] }),
        ("credit", Frame::Credit { edge: 2, from: 0, to: 1, n: 64 }),
        ("start", Frame::Control(Control::Start(Box::new(plan)))),
        (
            "event",
            Frame::Control(Control::Event { component: 1, task: 0, event: TaskEvent::Failed("boom".into()) }),
        ),
        ("stop", Frame::Control(Control::Stop)),
    ];
    for (name, frame) in frames {
        let mut seed = vec![0u8];
        seed.extend(frame.encode());
        seeds.write("cluster_frames", name, &seed)?;
    }
    let mut latency = hdrhistogram::Histogram::<u64>::new_with_bounds(1, 3_600_000_000_000, 3)?;
    for ns in [900, 1500, 40_000, 2_000_000] {
        latency.record(ns)?;
    }
    let mut seed = vec![1u8];
    V2Serializer::new().serialize(&latency, &mut seed).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    seeds.write("cluster_frames", "histogram", &seed)?;
    Ok(())
}
