//! Every shipped example topology runs as shipped: each file of
//! `examples/topologies/` is validated and run from the repository root
//! with nothing set, and completes. `live_slam.toml` waits for a robot:
//! in a build with the `cluster` feature `squall robot` plays it 30 ACES
//! scans on the file's own endpoint; without it, validating and running
//! it name the feature.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

mod common;

use common::{finish_within, output_within, shared_data};

/// How long one example may take before it fails as hung (the slowest
/// takes about 5 s).
const HUNG: Duration = Duration::from_secs(300);

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn squall() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_squall"));
    c.current_dir(repo());
    c
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// The shipped example topologies.
fn examples() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(repo().join("examples/topologies"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 9, "{files:?}");
    files
}

/// Checks that a run into `out` completed and wrote its metrics.
fn completed(file: &Path, run: &Output, out: &Path) {
    assert!(run.status.success(), "{}: {}", file.display(), text(run));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["status"], "completed", "{}: {metrics}", file.display());
}

#[test]
fn every_example_topology_validates_and_runs_as_shipped() {
    // The examples read the shared data set beside the repository.
    shared_data("laser/aces.clf");
    for file in examples() {
        let relative = file.strip_prefix(repo()).unwrap().to_str().unwrap().to_string();
        let live = relative.ends_with("live_slam.toml");
        let validated = output_within(squall().args(["validate", &relative]), HUNG, String::new);
        if live && !cfg!(feature = "cluster") {
            assert_eq!(validated.status.code(), Some(2), "{relative}: {}", text(&validated));
            assert!(text(&validated).contains("--features cluster"), "{relative}: {}", text(&validated));
            continue;
        }
        assert!(validated.status.success(), "{relative}: {}", text(&validated));
        assert!(text(&validated).contains("is valid"), "{relative}: {}", text(&validated));
        let out = tempfile::tempdir().unwrap();
        let mut run = squall();
        run.args(["run", &relative, "--quiet", "--out"]).arg(out.path());
        if live {
            let child = run.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
            let robot = output_within(
                squall()
                    .args(["robot", "--log", &shared_data("laser/aces.clf"), "--max-scans", "30"])
                    .args(["--connect", "tcp/127.0.0.1:7450", "--speed", "5", "--wait-secs", "60"]),
                HUNG,
                String::new,
            );
            assert!(robot.status.success(), "{relative}: robot: {}", text(&robot));
            let ran = finish_within(child, HUNG, String::new);
            completed(&file, &ran, out.path());
            assert!(out.path().join("map.pgm").exists(), "{relative}");
        } else {
            let ran = output_within(&mut run, HUNG, String::new);
            completed(&file, &ran, out.path());
        }
    }
}
