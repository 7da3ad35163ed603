//! Ctrl-C and SIGTERM at every stage: during a command's setup (before
//! its run starts), during a drain that cannot finish in time, and to a
//! study and its children. Each ends within a bound, says what it did in
//! metrics.json or study.csv, and leaves no process behind.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{LOG_PROGRESS, catches, finish_within, logged_progress, shared_data, wait_for};

const SIGINT: i32 = 2;
const SIGTERM: i32 = 15;

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("squall-signals-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `squall args`, its stderr into `stderr`, with `env` set.
fn spawn(args: &[&str], stderr: &Path, env: &[(&str, &Path)]) -> Child {
    let mut command = Command::new(env!("CARGO_BIN_EXE_squall"));
    command
        .args(args)
        .env("SQUALL_LOG", LOG_PROGRESS)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(stderr).unwrap());
    for (k, v) in env {
        command.env(k, v);
    }
    command.spawn().unwrap()
}

fn send(pid: i32, signal: i32) {
    // SAFETY: `kill` has no memory effects; `pid` is a child of this test
    // (or, negative, its process group), not yet reaped.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0, "kill({pid}, {signal})");
}

fn metrics(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics.json was written");
    serde_json::from_str(&text).unwrap()
}

#[test]
fn a_signal_during_localizes_setup_stops_it_and_metrics_say_so() {
    for (signal, name) in [(SIGINT, "Ctrl-C"), (SIGTERM, "SIGTERM")] {
        let dir = out_dir(&format!("setup-{signal}"));
        // A temporary folder of its own: the scenes of GHC7 are not
        // cached there, so setup builds them (seconds) after replaying
        // the simulated route.
        let tmp = dir.join("tmp");
        std::fs::create_dir_all(&tmp).unwrap();
        let stderr_file = dir.join("stderr");
        let out = dir.join("out");
        let child = spawn(
            &[
                "localize",
                "--map",
                &shared_data("linemaps/GHC7_vector.txt"),
                "--sim",
                "--duration",
                "600",
                "--out",
                out.to_str().unwrap(),
                "--quiet",
            ],
            &stderr_file,
            &[("TMPDIR", &tmp)],
        );
        let stderr = || std::fs::read_to_string(&stderr_file).unwrap_or_default();
        let limit = Duration::from_secs(60);
        wait_for("the signal handler", limit, || catches(child.id(), signal as u32), stderr);
        send(child.id() as i32, signal);
        let started = Instant::now();
        let ended = finish_within(child, limit, stderr);
        let stderr = stderr();
        assert!(ended.status.success(), "{name}: {:?}\n{stderr}", ended.status);
        assert!(stderr.contains(&format!("stopping on {name}")), "{stderr}");
        assert!(stderr.contains("before the run started"), "{stderr}");
        assert!(started.elapsed() < Duration::from_secs(20), "took {:?}", started.elapsed());
        let m = metrics(&out);
        assert_eq!((m["status"].as_str(), m["stage"].as_str()), (Some("stopped"), Some("setup")), "{m}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_stopped_run_that_cannot_drain_in_time_is_abandoned_within_the_bound() {
    let dir = out_dir("drain");
    let stderr_file = dir.join("stderr");
    let out = dir.join("out");
    // Three hundred thousand particles: on this project's machine two
    // simulated seconds took 110 s at a hundred thousand and 441 s at
    // four hundred thousand, so the readings queued when the stop comes
    // take minutes, and even a machine ten times faster cannot drain them
    // within the bound. The test's time is the bound's, not the work's.
    let child = spawn(
        &[
            "localize",
            "--map",
            &shared_data("linemaps/EDSH120_vector.txt"),
            "--sim",
            "--duration",
            "30",
            "--particles",
            "300000",
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        &stderr_file,
        &[],
    );
    let stderr = || std::fs::read_to_string(&stderr_file).unwrap_or_default();
    let limit = Duration::from_secs(120);
    wait_for("the run to start", limit, || logged_progress(&stderr()).is_some_and(|n| n > 0), stderr);
    send(child.id() as i32, SIGTERM);
    let started = Instant::now();
    let ended = finish_within(child, limit, stderr);
    let took = started.elapsed();
    let stderr = stderr();
    // The drain's bound (10 s), the abort's grace (5 s), and slack.
    assert!(took < Duration::from_secs(30), "took {took:?}:\n{stderr}");
    assert!(ended.status.success(), "{:?}\n{stderr}", ended.status);
    assert!(stderr.contains("not drained within 10 s"), "{stderr}");
    let m = metrics(&out);
    assert_eq!(m["status"], "stopped", "{m}");
    let warnings = m["warnings"].to_string();
    assert!(warnings.contains("not drained within 10 s"), "{warnings}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The processes still running whose command line mentions `needle`.
fn running_with(needle: &str) -> Vec<(u32, String)> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else { continue };
        let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        // A zombie (state Z) has ended; its parent has yet to reap it.
        let zombie = stat.rsplit_once(')').is_some_and(|(_, rest)| rest.trim_start().starts_with('Z'));
        if cmdline.contains(needle) && !zombie {
            found.push((pid, cmdline));
        }
    }
    found
}

#[test]
fn a_signalled_study_stops_its_children_waits_for_them_and_says_so() {
    // SIGTERM and SIGINT to the study alone, and Ctrl-C at a terminal:
    // SIGINT to its whole process group.
    for (signal, group) in [(SIGTERM, false), (SIGINT, false), (SIGINT, true)] {
        let dir = out_dir(&format!("study-{signal}-{group}"));
        let stderr_file = dir.join("stderr");
        let out = dir.join("out");
        let mut command = Command::new(env!("CARGO_BIN_EXE_squall"));
        command
            .args(["study", "--sim-worlds", "office", "--seeds", "1-4", "--jobs", "2", "--out"])
            .arg(&out)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&stderr_file).unwrap());
        std::os::unix::process::CommandExt::process_group(&mut command, 0);
        let child = command.spawn().unwrap();
        let pid = child.id() as i32;
        let stderr = || std::fs::read_to_string(&stderr_file).unwrap_or_default();
        let limit = Duration::from_secs(120);
        let needle = out.to_str().unwrap().to_string();
        // Two runs going: each is a `squall slam ... --out OUT/runs/...`.
        wait_for("two runs", limit, || running_with(&format!("{needle}/runs/")).len() >= 2, stderr);
        send(if group { -pid } else { pid }, signal);
        let ended = finish_within(child, limit, stderr);
        let stderr = stderr();
        assert!(!ended.status.success(), "the study exits non-zero when stopped: {stderr}");
        assert_eq!(ended.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains("the study was stopped"), "{stderr}");
        let left = running_with(&needle);
        assert!(left.is_empty(), "processes outlived the study: {left:?}");
        let csv = std::fs::read_to_string(out.join("study.csv")).expect("study.csv was written");
        let rows: Vec<&str> = csv.lines().skip(1).collect();
        assert_eq!(rows.len(), 4, "{csv}");
        assert!(rows.iter().all(|r| r.split(',').nth(2) == Some("stopped")), "{csv}");
        let md = std::fs::read_to_string(out.join("study.md")).expect("study.md was written");
        assert!(md.contains("**stopped**"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
