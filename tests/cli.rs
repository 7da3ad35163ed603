//! End-to-end tests of the `squall` binary on the example and test
//! topologies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use squall::builtin::wordcount::SentenceGen;

mod common;

use common::{LOG_PROGRESS, catches, finish_within, logged_progress, relation_error, shared_data, wait_for};

fn squall(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the squall binary runs")
}

/// Starts `squall ARGS` logging its progress into the file `stderr`, for
/// a test that signals it while it runs.
fn spawn_logging_progress(args: &[&str], stderr: &Path) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(args)
        .env("SQUALL_LOG", LOG_PROGRESS)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(stderr).unwrap())
        .spawn()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("squall-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn every_invalid_topology_gets_its_own_message_and_exit_code_2() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/invalid");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 10, "the corpus has {} files", files.len());
    for file in files {
        let content = std::fs::read_to_string(&file).unwrap();
        // Every `# expect:` line at the top is one error the file must get.
        let expected: Vec<&str> = content.lines().map_while(|l| l.strip_prefix("# expect: ")).collect();
        assert!(!expected.is_empty(), "{} lacks an `# expect:` first line", file.display());
        let rel = format!("tests/invalid/{}", file.file_name().unwrap().to_string_lossy());
        for command in ["validate", "run"] {
            let out = squall(&[command, &rel]);
            let stderr = text(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{command} {rel}: {stderr}");
            for expected in &expected {
                assert!(
                    stderr.contains(&format!("tests/invalid/{expected}")),
                    "{command} {rel}\n expected: {expected}\n got: {stderr}"
                );
            }
        }
    }
}

#[test]
fn wordcount_counts_exactly_and_writes_metrics() {
    let dir = out_dir("wordcount");
    let out = squall(&[
        "run",
        "examples/topologies/wordcount.toml",
        "--set",
        "sentences.params.count=5000",
        "--set",
        "count.parallelism=4",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("component") && stdout.contains("p99 exec"), "{stdout}");

    let mut expected: BTreeMap<String, u64> = BTreeMap::new();
    for sentence in SentenceGen::new(42).take(5000) {
        for w in sentence.split_whitespace() {
            *expected.entry(w.to_string()).or_default() += 1;
        }
    }
    let tsv = std::fs::read_to_string(dir.join("wordcount.tsv")).unwrap();
    let got: BTreeMap<String, u64> = tsv
        .lines()
        .skip(1)
        .map(|l| {
            let (w, c) = l.split_once('\t').unwrap();
            (w.to_string(), c.parse().unwrap())
        })
        .collect();
    assert_eq!(got, expected);

    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let components = metrics["components"].as_array().unwrap();
    let count = components.iter().find(|c| c["name"] == "count").unwrap();
    assert_eq!(count["tasks"], 4);
    assert_eq!(count["per_task"].as_array().unwrap().len(), 4);
    let words: u64 = expected.values().sum();
    assert_eq!(count["received"], words);
    assert!(count["execute"]["p99_us"].as_f64().unwrap() > 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unknown_set_paths_are_rejected() {
    let out = squall(&["run", "examples/topologies/wordcount.toml", "--set", "matcher.parallelism=4"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr)
            .contains("no component named \"matcher\" (components: sentences, split, count, report)")
    );
    let out = squall(&["validate", "examples/topologies/wordcount.toml", "--set", "split.paralelism=4"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("unknown key \"paralelism\""), "{}", text(&out.stderr));
    let out = squall(&["validate", "examples/topologies/wordcount.toml", "--set", "split.parallelism"]);
    assert_eq!(out.status.code(), Some(2));
}

/// A component's (received, emitted, lost) in a run's metrics.json, lost
/// being dropped plus undelivered.
fn counts(metrics: &serde_json::Value, name: &str) -> (u64, u64, u64) {
    let c = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == name).unwrap();
    let count = |key: &str| c[key].as_u64().unwrap();
    (count("received"), count("emitted"), count("dropped") + count("undelivered"))
}

#[test]
fn a_panicking_bolt_fails_the_run_naming_it() {
    let dir = out_dir("panic");
    // Metrics are written for a failed run too, say so, and add up as
    // they stood when it failed: every tuple a component emitted was
    // received downstream or counted lost (three runs: which task
    // reported last used to vary).
    for run in 0..3 {
        let out = squall(&[
            "run",
            "examples/topologies/probe.toml",
            "--set",
            "source.params.count=1000",
            "--set",
            "relay.params.panic_at=100",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert_eq!(out.status.code(), Some(1));
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(
                "error: the run failed: bolt \"relay\" task 0 panicked: injected panic at message 100"
            ),
            "{stderr}"
        );
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
        assert_eq!(metrics["status"], "failed");
        assert_eq!(metrics["error"], "bolt \"relay\" task 0 panicked: injected panic at message 100");
        let (source, relay, sink) =
            (counts(&metrics, "source"), counts(&metrics, "relay"), counts(&metrics, "sink"));
        assert_eq!(source.1, 1000, "run {run}: {metrics}");
        assert_eq!(relay.0 + relay.2, source.1, "run {run}: relay (received, emitted, lost) {relay:?}");
        assert_eq!(relay.0, 100, "run {run}: the tuple that panicked was received");
        assert_eq!(sink.0 + sink.2, relay.1, "run {run}: sink (received, emitted, lost) {sink:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

// Fault injection: each fault ends the run with a failure that names
// it, exit code 1, metrics.json marked failed with the error, and no
// output file left half-written. (The panicking bolt is above.)

/// Runs the probe topology with `sets`, expecting a failed run; its
/// stderr and metrics.json.
fn failed_probe_run(name: &str, sets: &[&str]) -> (String, serde_json::Value) {
    let dir = out_dir(name);
    let mut args = vec!["run", "examples/topologies/probe.toml", "--out", dir.to_str().unwrap()];
    for set in sets {
        args.extend(["--set", set]);
    }
    let out = squall(&args);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let metrics = serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (stderr, metrics)
}

#[test]
fn a_bolt_that_hangs_is_named_by_the_stall_watchdog() {
    // The relay never returns from its 50th tuple; the watchdog gives it
    // one second.
    let (stderr, metrics) = failed_probe_run("hang", &["topology.stall_secs=1", "relay.params.hang_at=50"]);
    // The component, the limit and the cause are exact; how long the
    // watchdog saw it stuck is at least the limit (it looks a little
    // later on a loaded machine).
    let error = metrics["error"].as_str().unwrap();
    let stuck = error
        .strip_prefix("bolt \"relay\" task 0 stalled: no progress for ")
        .and_then(|rest| rest.split_once(" s inside one execute or tick"))
        .unwrap_or_else(|| panic!("{error}"));
    let secs: f64 = stuck.0.parse().unwrap_or_else(|_| panic!("{error}"));
    assert!(secs >= 1.0, "{error}");
    assert!(stuck.1.ends_with("the limit is [topology] stall_secs = 1"), "{error}");
    assert!(stderr.contains(&format!("error: the run failed: {error}")), "{stderr}");
    assert!(stderr.contains("ERROR") && stderr.contains("component=relay task=0"), "logged: {stderr}");
    assert_eq!(metrics["status"], "failed");
    // Its thread never returned: its counters are unknown, and say so.
    let relay = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == "relay").unwrap();
    assert_eq!(relay["per_task"][0]["lost"], true, "{relay}");
}

#[test]
fn a_restarted_bolt_waiting_for_input_is_not_a_stall() {
    // The relay panics on its 2nd tuple and is restarted; the source sends
    // one tuple every 2 s, so the new incarnation waits longer than the
    // watchdog's 1 s for the 3rd: idle, not stuck in a call. (No
    // backtrace: printing one takes long enough to look like a stall.)
    let dir = out_dir("restart-idle");
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["run", "examples/topologies/probe.toml", "--out", dir.to_str().unwrap()])
        .args(["--set", "source.params={ count = 3, rate_hz = 0.5 }", "--set", "relay.params.panic_at=2"])
        .args(["--set", "relay.restart={ max_restarts = 1 }", "--set", "topology.stall_secs=1"])
        .args(["--set", "topology.execute_sample=1"])
        .env("RUST_BACKTRACE", "0")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["status"], "completed");
    assert_eq!(metrics["components"][1]["restarts"], 1, "{metrics}");
    // Every tuple timed, as the file asked and metrics.json says.
    assert_eq!(metrics["execute_sample"], 1);
    let sink = &metrics["components"][2];
    assert_eq!(sink["execute"]["count"], sink["received"], "{sink}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bolt_that_keeps_allocating_hits_the_memory_limit() {
    // 1 MiB kept per tuple against a 200 MiB limit.
    let (stderr, metrics) =
        failed_probe_run("leak", &["topology.memory_limit_mb=200", "relay.params.leak_kib=1024"]);
    let error = "the process's resident memory reached";
    assert!(stderr.contains(&format!("error: the run failed: {error}")), "{stderr}");
    assert_eq!(metrics["status"], "failed");
    let message = metrics["error"].as_str().unwrap();
    assert!(message.starts_with(error) && message.contains("past the limit of 200 MiB"), "{message}");
    assert!(metrics["peak_rss_mb"].as_f64().unwrap() > 200.0, "{}", metrics["peak_rss_mb"]);
}

#[test]
fn a_source_that_errors_mid_stream_fails_the_run_with_consistent_counts() {
    let (stderr, metrics) = failed_probe_run("source-error", &["source.params.fail_at=5000"]);
    let error = "spout \"source\" task 0 failed: injected source error at message 5000";
    assert!(stderr.contains(&format!("error: the run failed: {error}")), "{stderr}");
    assert_eq!(metrics["status"], "failed");
    assert_eq!(metrics["error"], error);
    let (source, relay, sink) =
        (counts(&metrics, "source"), counts(&metrics, "relay"), counts(&metrics, "sink"));
    assert_eq!(source.1, 4999, "everything before the error was emitted");
    assert_eq!(relay.0 + relay.2, source.1, "relay (received, emitted, lost) {relay:?}");
    assert_eq!(sink.0 + sink.2, relay.1, "sink (received, emitted, lost) {sink:?}");
}

#[test]
fn a_full_disk_fails_the_run_naming_the_file_and_leaves_no_partial_output() {
    // A 64 KiB file-size limit (what a full disk or a quota looks like to
    // a writer): metrics.json fits, the map does not.
    let dir = out_dir("full-disk");
    let command = format!(
        "ulimit -f 64; exec {} slam --max-scans 60 --out {}",
        env!("CARGO_BIN_EXE_squall"),
        dir.display()
    );
    let out = Command::new("sh").args(["-c", &command]).output().unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let map = dir.join("map.pgm");
    let error = format!("bolt \"map\" task 0 failed: {}: cannot write: File too large", map.display());
    assert!(stderr.contains(&format!("error: the run failed: {error}")), "{stderr}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["status"], "failed");
    assert!(metrics["error"].as_str().unwrap().starts_with(&error), "{}", metrics["error"]);
    let mut left: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert!(left.iter().all(|f| !f.contains(".tmp") && f != "map.pgm"), "half-written files: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn paths_that_are_not_utf_8_are_used_as_given_or_refused_by_name() {
    use std::os::unix::ffi::OsStrExt;
    let dir = out_dir("non-utf8");
    let odd = dir.join(std::ffi::OsStr::from_bytes(b"caf\xe9"));
    std::fs::create_dir_all(&odd).unwrap();
    // --out is used as the bytes given.
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args([
            "run",
            "examples/topologies/probe.toml",
            "--set",
            "source.params.count=100",
            "--quiet",
            "--out",
        ])
        .arg(odd.join("run"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(odd.join("run/metrics.json").is_file());
    // A log reaches its spout through the topology (UTF-8 text): refused
    // by name before the run, not mangled into a file that cannot be read.
    let log = odd.join("aces.clf");
    std::fs::copy(shared_data("laser/aces.clf"), &log).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["slam", "--max-scans", "5", "--log"])
        .arg(&log)
        .arg("--out")
        .arg(odd.join("slam"))
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("aces.clf: the path is not valid UTF-8"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_into_a_closed_pipe_ends_quietly_without_a_panic() {
    // `squall graph … | head -0`: the reader is gone before the first
    // write (its end of the pipe closed before squall starts).
    let mut fds = [0; 2];
    // SAFETY: `pipe` fills both descriptors, each then owned by one File.
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    let (reader, writer) = unsafe {
        use std::os::fd::FromRawFd;
        (std::fs::File::from_raw_fd(fds[0]), std::fs::File::from_raw_fd(fds[1]))
    };
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["graph", "tests/topologies/feedback.toml"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(writer)
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(141), "{stderr}");
}

#[test]
fn negative_numbers_reach_their_own_checks() {
    let out = squall(&["sim", "--fov-deg", "-5", "--out", "/nonexistent-squall-out"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("invalid value '-5' for '--fov-deg <FOV_DEG>': expected degrees in [1, 360]"),
        "{stderr}"
    );
    let out = squall(&["slam", "--particles", "-1", "--out", "/nonexistent-squall-out"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("invalid value '-1' for '--particles"), "{stderr}");
}

#[test]
fn an_unwritable_out_is_refused_before_the_run() {
    // /proc takes no new files, whoever runs the test.
    for args in [
        &["run", "examples/topologies/probe.toml", "--out", "/proc/self/squall-out"][..],
        &["slam", "--out", "/proc/self/squall-out"],
        &["sim", "--out", "/proc/self/squall-out"],
    ] {
        let out = squall(args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("error: --out /proc/self/squall-out: cannot write there"), "{stderr}");
    }
}

#[test]
fn graph_labels_streams_groupings_and_dashes_feedback() {
    let out = squall(&["graph", "tests/topologies/feedback.toml"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let dot = text(&out.stdout);
    assert!(dot.starts_with("digraph \"feedback\" {"), "{dot}");
    assert!(dot.contains("\"source\" -> \"a\" [label=\"default: Probe\\nfields(key)\"];"), "{dot}");
    assert!(dot.contains("\"b\" -> \"a\" [label=\"default: Probe\\nshuffle\", style=dashed];"), "{dot}");
    assert!(dot.contains("\"a\" -> \"b\" [label=\"default: Probe\\nglobal\"];"), "{dot}");
    assert!(dot.contains("\"a\" [shape=box, label=\"a\\nprobe.relay ×2\"];"), "{dot}");
}

#[test]
fn validate_reports_a_valid_topology() {
    let out = squall(&["validate", "tests/topologies/feedback.toml"]);
    assert!(out.status.success());
    assert_eq!(
        text(&out.stdout).trim(),
        "tests/topologies/feedback.toml: topology \"feedback\" is valid (3 components, 4 tasks)"
    );
}

#[test]
fn help_shows_examples() {
    let out = squall(&["--help"]);
    assert!(out.status.success());
    let help = text(&out.stdout);
    for needle in ["run", "validate", "graph", "Examples:", "--set"] {
        assert!(help.contains(needle), "{needle} missing from:\n{help}");
    }
}

#[test]
fn ctrl_c_stops_the_spouts_and_drains_everything_in_flight() {
    let dir = out_dir("ctrl-c");
    let log = std::env::temp_dir().join(format!("squall-cli-{}-ctrl-c.stderr", std::process::id()));
    // A billion probes through a relay that takes 200 µs each: the source
    // is held back by full queues (1024 per edge) whenever Ctrl-C comes.
    let out_dir = dir.to_str().unwrap();
    let child = spawn_logging_progress(
        &[
            "run",
            "examples/topologies/probe.toml",
            "--set",
            "source.params.count=1000000000",
            "--set",
            "relay.params.delay_us=200",
            "--out",
            out_dir,
        ],
        &log,
    );
    let stderr = || std::fs::read_to_string(&log).unwrap_or_default();
    // Interrupt once the handler is in place and both queues have filled.
    let limit = Duration::from_secs(60);
    wait_for("the Ctrl-C handler", limit, || catches(child.id(), 2), stderr);
    wait_for("3000 probes sent", limit, || logged_progress(&stderr()).is_some_and(|n| n >= 3000), stderr);
    let sent_before = logged_progress(&stderr()).unwrap();
    let killed = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let out = finish_within(child, limit, stderr);
    let stderr = stderr();
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("stopping on Ctrl-C") && stderr.contains("stopped early"), "{stderr}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let component = |name: &str| counts(&metrics, name);
    let (_, emitted, _) = component("source");
    assert!(emitted >= sent_before, "{emitted} probes sent, but {sent_before} were logged before Ctrl-C");
    // Everything the source sent before it stopped went through, although
    // up to 2048 probes were queued when it stopped.
    assert_eq!(component("relay"), (emitted, emitted, 0), "relay: (executed, forwarded, lost)");
    assert_eq!(component("sink"), (emitted, 0, 0), "sink: (executed, emitted, lost)");
    let relay = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == "relay").unwrap();
    assert_eq!(relay["queue_depth_max"], 1024, "the relay's queue filled up");
    assert!(text(&out.stdout).starts_with("topology \"probe\""), "{}", text(&out.stdout));
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&log);
}

#[test]
fn sigterm_stops_a_replay_sleeping_until_its_next_record_and_the_run_finishes() {
    let dir = out_dir("sigterm");
    std::fs::create_dir_all(&dir).unwrap();
    // Replayed in real time, the second record is due in ten million
    // seconds (115 days): only the stop can end the wait.
    let log = dir.join("gap.clf");
    std::fs::write(&log, "ODOM 0 0 0 0 0 0 1.0 h 1.0\nODOM 1 0 0 0 0 0 10000001.0 h 10000001.0\n").unwrap();
    let stderr_file = dir.join("stderr");
    let child = spawn_logging_progress(
        &[
            "run",
            "examples/topologies/replay.toml",
            "--set",
            &format!("source.params.log={}", log.display()),
            "--set",
            "source.params.rate=1",
            "--out",
            dir.join("out").to_str().unwrap(),
        ],
        &stderr_file,
    );
    let stderr = || std::fs::read_to_string(&stderr_file).unwrap_or_default();
    let limit = Duration::from_secs(60);
    wait_for("the SIGTERM handler", limit, || catches(child.id(), 15), stderr);
    wait_for("the first record", limit, || logged_progress(&stderr()).is_some_and(|n| n >= 1), stderr);
    let killed = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let out = finish_within(child, limit, stderr);
    let stderr = stderr();
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("stopping on SIGTERM"), "{stderr}");
    assert!(!stderr.contains('\x1b'), "log lines into a file carry no colour codes: {stderr:?}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["status"], "stopped", "{metrics}");
    assert_eq!(metrics["components"][1]["custom"]["tuples.source.odom"], 1, "{metrics}");

    // A stamp whose wait cannot be timed at all fails the run naming its
    // line; it used to panic.
    std::fs::write(&log, "ODOM 0 0 0 0 0 0 1.0 h 1.0\nODOM 1 0 0 0 0 0 1e300 h 1e300\n").unwrap();
    let out = squall(&[
        "run",
        "examples/topologies/replay.toml",
        "--set",
        &format!("source.params.log={}", log.display()),
        "--set",
        "source.params.rate=1",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let expected = format!("{}:2: stamp 1e300 lies", log.display());
    assert!(text(&out.stderr).contains(&expected), "{}", text(&out.stderr));
    assert!(!text(&out.stderr).contains("panicked"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eval_scores_raw_odometry_of_the_real_logs_as_published() {
    for (log, expected) in [("aces", 0.549), ("intel", 7.39), ("mit-csail", 1.68)] {
        let clf = shared_data(&format!("laser/{log}.clf"));
        let relations = shared_data(&format!("laser/{log}.relations"));
        let out = squall(&["eval", "--trajectory", &clf, "--relations", &relations, "--json"]);
        assert!(out.status.success(), "{log}: {}", text(&out.stderr));
        let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
        assert_eq!(v["matched"], v["total"], "{log}: every relation has poses");
        let trans = v["trans_mean"].as_f64().unwrap();
        let digits = if expected < 1.0 { 1e-3 } else { 1e-2 };
        assert!((trans - expected).abs() < digits, "{log}: {trans} vs published {expected}");
        for key in ["trans_std", "rot_mean_deg", "rot_std_deg"] {
            assert!(v[key].as_f64().unwrap() > 0.0, "{log}: {key}");
        }
        // The breakdown by span covers every relation; odometry's error
        // grows with the span, so the long relations carry most of it.
        let spans = v["by_span"].as_array().unwrap();
        let counted: u64 = spans.iter().map(|s| s["matched"].as_u64().unwrap()).sum();
        let shares: f64 = spans.iter().map(|s| s["share"].as_f64().unwrap()).sum();
        assert_eq!(Some(counted), v["matched"].as_u64(), "{log}");
        assert!((shares - 1.0).abs() < 1e-9, "{log}: shares add up to {shares}");
        let means: Vec<f64> = spans.iter().map(|s| s["trans_mean"].as_f64().unwrap()).collect();
        assert!(means[0] < means[2], "{log}: {means:?}");
    }
}

#[test]
fn eval_round_trips_a_tum_trajectory_and_reports_bad_files() {
    let dir = out_dir("eval");
    std::fs::create_dir_all(&dir).unwrap();
    // The odometry of the CSAIL log as TUM scores the same as the log itself.
    let clf = shared_data("laser/mit-csail.clf");
    let records = squall::spouts::carmen::read_log(Path::new(&clf), Default::default()).unwrap();
    let mut t = squall::core::trajectory::Trajectory::default();
    for r in records {
        if let squall::spouts::carmen::Record::Scan(_, s) = r {
            t.push(s.stamp, s.odometry);
        }
    }
    let tum = dir.join("odom.tum");
    std::fs::write(&tum, t.to_tum()).unwrap();
    let relations = shared_data("laser/mit-csail.relations");
    let from_tum =
        squall(&["eval", "--trajectory", tum.to_str().unwrap(), "--relations", &relations, "--json"]);
    let from_clf = squall(&["eval", "--trajectory", &clf, "--relations", &relations, "--json"]);
    let a: serde_json::Value = serde_json::from_str(&text(&from_tum.stdout)).unwrap();
    let b: serde_json::Value = serde_json::from_str(&text(&from_clf.stdout)).unwrap();
    assert!((a["trans_mean"].as_f64().unwrap() - b["trans_mean"].as_f64().unwrap()).abs() < 1e-5);

    // Against itself as ground truth, everything is zero.
    let out = squall(&[
        "eval",
        "--trajectory",
        tum.to_str().unwrap(),
        "--ground-truth",
        tum.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert_eq!(v["pairs"], 1988);
    assert!(v["ate_rmse"].as_f64().unwrap() < 1e-6 && v["rpe_trans_rmse"].as_f64().unwrap() < 1e-6);
    assert_eq!(v["frame"], "aligned", "a file that declares no frame is aligned");

    // A localizer's trajectory declares the map frame and is scored as it
    // is: moved 5 m, it is 5 m off everywhere, although it aligns to zero.
    let mut shifted = squall::core::trajectory::Trajectory::default();
    for (stamp, p) in t.stamps.iter().zip(&t.poses) {
        shifted.push(*stamp, squall::core::geometry::Pose2::new(p.x + 3.0, p.y + 4.0, p.theta));
    }
    let in_map = dir.join("in_map.tum");
    std::fs::write(&in_map, shifted.to_tum_in_frame("map")).unwrap();
    let eval_in = |frame: &[&str]| {
        let mut all = vec!["eval", "--trajectory", in_map.to_str().unwrap(), "--ground-truth"];
        all.extend([tum.to_str().unwrap(), "--json"]);
        all.extend_from_slice(frame);
        let out = squall(&all);
        assert!(out.status.success(), "{}", text(&out.stderr));
        serde_json::from_str::<serde_json::Value>(&text(&out.stdout)).unwrap()
    };
    let v = eval_in(&[]);
    assert_eq!((&v["frame"], &v["pairs"]), (&"map".into(), &1988.into()), "{v}");
    assert!((v["map_mean_m"].as_f64().unwrap() - 5.0).abs() < 1e-5, "{v}");
    assert!((v["map_max_m"].as_f64().unwrap() - 5.0).abs() < 1e-5, "{v}");
    assert_eq!((v["map_within_share"].as_f64(), v["converged_after_s"].is_null()), (Some(0.0), true), "{v}");
    let v = eval_in(&["--frame", "aligned"]);
    assert!(v["ate_rmse"].as_f64().unwrap() < 1e-5 && v["map_mean_m"].is_null(), "{v}");
    let text_out =
        squall(&["eval", "--trajectory", in_map.to_str().unwrap(), "--ground-truth", tum.to_str().unwrap()]);
    assert!(text(&text_out.stdout).contains("in the map frame, no alignment (the trajectory declares"));
    // A frame eval does not know is an error before any scoring.
    std::fs::write(&in_map, shifted.to_tum_in_frame("odom")).unwrap();
    let out =
        squall(&["eval", "--trajectory", in_map.to_str().unwrap(), "--ground-truth", tum.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("declares frame \"odom\""), "{}", text(&out.stderr));

    let bad = dir.join("bad.tum");
    std::fs::write(&bad, "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n").unwrap();
    let out = squall(&["eval", "--trajectory", bad.to_str().unwrap(), "--relations", &relations]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("bad.tum:2: expected 8 fields"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn log_and_bag_sources_run_in_a_topology() {
    let dir = out_dir("replay");
    let log = shared_data("laser/aces.clf");
    let out = squall(&[
        "run",
        "examples/topologies/replay.toml",
        "--set",
        &format!("source.params.log={log}"),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let count = &m["components"][1]["custom"];
    assert_eq!(count["tuples.source.scan"], 7374);
    assert_eq!(count["tuples.source.odom"], 7375);

    let bag = shared_data("rosbag2/aces");
    let out = squall(&[
        "run",
        "examples/topologies/replay.toml",
        "--set",
        "source.kind=rosbag2",
        "--set",
        &format!("source.params={{ bag = \"{bag}\", max_scans = 500 }}"),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["components"][1]["custom"]["tuples.source.scan"], 500);

    // A missing log is invalid input, named before the run starts.
    let out =
        squall(&["run", "examples/topologies/replay.toml", "--set", "source.params.log=/nonexistent.clf"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("spout \"source\": cannot read /nonexistent.clf: No such file"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn slam_without_scans_fails_saying_why_instead_of_succeeding_empty() {
    let dir = out_dir("no-scans");
    std::fs::create_dir_all(&dir).unwrap();
    let odometry_only: String = std::fs::read_to_string(shared_data("laser/aces.clf"))
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("ODOM"))
        .take(50)
        .map(|l| format!("{l}\n"))
        .collect();
    for (name, content) in [("empty.clf", String::new()), ("odometry.clf", odometry_only)] {
        let log = dir.join(name);
        std::fs::write(&log, content).unwrap();
        let out =
            squall(&["slam", "--log", log.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains("no reading arrived, so nothing was estimated"), "{name}: {stderr}");
    }
    // A log that cannot be read is refused before the run.
    let out = squall(&["slam", "--log", "/nonexistent.clf", "--out", dir.join("out").to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--log /nonexistent.clf: cannot read: No such file"), "{stderr}");
    // A misspelled topic names itself and the topics the bag has.
    let bag = shared_data("rosbag2/aces");
    let out = squall(&[
        "slam",
        "--log",
        &bag,
        "--set",
        "source.params.scan_topic=\"/scna\"",
        "--out",
        dir.join("out").to_str().unwrap(),
    ]);
    let stderr = text(&out.stderr);
    // Found in the bag's summary before the run: invalid input.
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no messages on scan_topic \"/scna\"; the bag's topics: "), "{stderr}");
    assert!(stderr.contains("/scan (sensor_msgs/msg/LaserScan)"), "{stderr}");
    assert!(!stderr.contains("component"), "no run started, so no component table: {stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The names in `dir`, sorted.
fn names_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_bag_in_a_read_only_folder_is_read_by_a_user_who_is_not_root_and_nothing_is_written_beside_it() {
    use std::os::unix::fs::PermissionsExt;
    // The TurtleBot 4 bag: sqlite3 in WAL journal mode, as rosbag2 records.
    let original = PathBuf::from(shared_data("real/olin_mac/bag"));
    let root = tempfile::tempdir().unwrap();
    let mode = |path: &Path, mode: u32| {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap()
    };
    mode(root.path(), 0o755);
    let bag = root.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    for name in names_in(&original) {
        std::fs::copy(original.join(&name), bag.join(&name)).unwrap();
        mode(&bag.join(&name), 0o444);
    }
    mode(&bag, 0o555);
    let before = names_in(&bag);
    let out = root.path().join("out");
    std::fs::create_dir(&out).unwrap();
    mode(&out, 0o777);
    // As root the folder's modes bind nobody: the run then drops to the
    // unprivileged user (setpriv, from util-linux), with its own copy of
    // the binary where that user can reach it.
    // SAFETY: geteuid has no preconditions and cannot fail.
    let root_user = unsafe { libc::geteuid() } == 0;
    let mut command = if root_user {
        let binary = root.path().join("squall");
        std::fs::copy(env!("CARGO_BIN_EXE_squall"), &binary).unwrap();
        mode(&binary, 0o755);
        let mut c = Command::new("setpriv");
        c.args(["--reuid=65534", "--regid=65534", "--clear-groups"]).arg(binary);
        c
    } else {
        Command::new(env!("CARGO_BIN_EXE_squall"))
    };
    let run = command
        .arg("slam")
        .arg("--log")
        .arg(&bag)
        .args(["--max-scans", "40", "--particles", "10", "--quiet", "--out"])
        .arg(&out)
        .current_dir(root.path())
        .output()
        .expect("setpriv runs (util-linux)");
    assert!(run.status.success(), "{}", text(&run.stderr));
    let poses = std::fs::read_to_string(out.join("trajectory.tum")).unwrap();
    assert_eq!(poses.lines().filter(|l| !l.starts_with('#')).count(), 40, "{poses}");
    assert!(run.stdout.is_empty(), "--quiet prints no summary: {}", text(&run.stdout));
    assert_eq!(names_in(&bag), before, "nothing is written beside the bag (no -shm, no -wal)");
    mode(&bag, 0o755);
}

/// `aces` converted to rosbag2's sqlite3 storage by an independent tool,
/// the `rosbags` Python package (`./test.sh` installs it, pinned), into
/// `dir/aces-db3`.
fn aces_as_db3(dir: &Path) -> PathBuf {
    let check = Command::new("rosbags-convert").arg("--help").output();
    assert!(
        check.as_ref().is_ok_and(|o| o.status.success()),
        "this test needs rosbags-convert from the rosbags Python package (./test.sh installs it: tests/clients/requirements.txt)"
    );
    let db3 = dir.join("aces-db3");
    let _ = std::fs::remove_dir_all(&db3);
    let out = Command::new("rosbags-convert")
        .args(["--src", &shared_data("rosbag2/aces"), "--dst"])
        .arg(&db3)
        .args(["--dst-storage", "sqlite3"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    db3
}

#[test]
#[cfg_attr(
    not(feature = "client-tests"),
    ignore = "needs rosbags-convert (feature client-tests; ./test.sh runs it)"
)]
fn a_db3_bag_gives_byte_identical_slam_to_the_mcap_and_ros_1_bags_are_refused_before_the_run() {
    let dir = out_dir("db3");
    std::fs::create_dir_all(&dir).unwrap();
    let db3 = aces_as_db3(&dir);
    let yaml = std::fs::read_to_string(db3.join("metadata.yaml")).unwrap();
    assert!(yaml.contains("storage_identifier: sqlite3"), "{yaml}");
    let slam = |bag: &Path, out: &str| {
        let out_dir = dir.join(out);
        let run = squall(&[
            "slam",
            "--log",
            bag.to_str().unwrap(),
            "--max-scans",
            "400",
            "--particles",
            "10",
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        assert!(run.status.success(), "{out}: {}", text(&run.stderr));
        let read = |name: &str| std::fs::read(out_dir.join(name)).unwrap();
        (read("trajectory.tum"), read("map.pgm"))
    };
    let from_mcap = slam(Path::new(&shared_data("rosbag2/aces")), "mcap");
    let from_db3 = slam(&db3, "db3");
    assert!(from_mcap.0.len() > 1000);
    assert!(from_mcap == from_db3, "the sqlite3 bag's trajectory and map differ from the MCAP's");
    // The .db3 file itself, without its folder, reads the same.
    let file = std::fs::read_dir(&db3)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "db3"))
        .unwrap();
    assert!(slam(&file, "db3-file") == from_mcap);

    // A ROS 1 bag, a storage squall does not read, and a .db3 without the
    // topic asked for are refused before the run, saying what to do.
    let ros1 = dir.join("old.bag");
    std::fs::write(&ros1, b"#ROSBAG V2.0\nE\0\0\0").unwrap();
    let unknown = dir.join("unknown");
    std::fs::create_dir_all(&unknown).unwrap();
    std::fs::write(
        unknown.join("metadata.yaml"),
        yaml.replace("storage_identifier: sqlite3", "storage_identifier: rosbag_v2"),
    )
    .unwrap();
    let wheel_odom = ["--set", "source.params.odom_topic=\"/wheel_odom\""];
    for (bag, sets, says) in [
        (
            ros1.as_path(),
            &[][..],
            "a ROS 1 bag; squall reads ROS 2 bags (MCAP or sqlite3 storage). Convert it first: `pip install rosbags && rosbags-convert --src",
        ),
        (unknown.as_path(), &[][..], "storage \"rosbag_v2\" is not one squall reads (mcap, sqlite3)"),
        (db3.as_path(), &wheel_odom[..], "no messages on odom_topic \"/wheel_odom\"; the bag's topics: "),
    ] {
        let refused = dir.join("refused");
        let mut args = vec!["slam", "--log", bag.to_str().unwrap()];
        args.extend(sets);
        args.extend(["--out", refused.to_str().unwrap()]);
        let out = squall(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(says), "{stderr}");
        // --out is checked (made) with the inputs; nothing is written in it.
        let written = std::fs::read_dir(&refused).map_or(0, |d| d.count());
        assert_eq!(written, 0, "nothing is written for invalid input");
        if !sets.is_empty() {
            assert!(stderr.contains("/odom (nav_msgs/msg/Odometry)"), "{stderr}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_topology_writes_the_raw_odometry_trajectory_that_eval_scores() {
    let dir = out_dir("odometry");
    let out = squall(&["run", "examples/topologies/odometry.toml", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let tum = dir.join("trajectory.tum");
    let relations = shared_data("laser/aces.relations");
    let out = squall(&["eval", "--trajectory", tum.to_str().unwrap(), "--relations", &relations, "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert_eq!(v["matched"], 1279);
    assert!((v["trans_mean"].as_f64().unwrap() - 0.549).abs() < 1e-3, "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_writes_a_log_that_eval_and_topologies_read() {
    let dir = out_dir("sim");
    let out = squall(&["sim", "--duration", "120", "--seed", "4", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("1200 scans"), "{}", text(&out.stdout));
    for f in ["sim.clf", "ground_truth.tum", "sim.relations", "world.png"] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    let error = relation_error(&dir.join("ground_truth.tum"), &dir.join("sim.relations"));
    assert!(error < 1e-5, "the ground truth scores {error} m");

    let out = squall(&["sim", "--world", "nowhere.txt", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("nowhere.txt: cannot read"), "{}", text(&out.stderr));

    // A real building's line map.
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let out =
        squall(&["sim", "--world", &map, "--duration", "60", "--seed", "1", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("600 scans"), "{}", text(&out.stdout));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The source's own metrics in a run's metrics.json.
fn source_metrics(dir: &std::path::Path) -> serde_json::Value {
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    m["components"][0]["custom"].clone()
}

#[test]
fn slam_learns_a_simulated_scan_latency_from_the_log() {
    let dir = out_dir("sim-latency");
    let d = |p: &str| dir.join(p).to_str().unwrap().to_string();
    // Scans stamped 0.1 s after they were measured, odometry at 50 Hz;
    // and a log without latency.
    for (latency, hz, name) in [("0.1", "50", "late"), ("0", "0", "clean")] {
        let out = squall(&[
            "sim",
            "--duration",
            "400",
            "--seed",
            "3",
            "--scan-latency",
            latency,
            "--odom-hz",
            hz,
            "--out",
            &d(name),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let log = d(&format!("{name}/sim.clf"));
        let out = squall(&["slam", "--log", &log, "--quiet", "--out", &d(&format!("{name}/slam"))]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let m = source_metrics(&dir.join(name).join("slam"));
        let offset = m["clock_offset_ms"].as_f64().unwrap();
        let truth = -1e3 * latency.parse::<f64>().unwrap();
        assert!((offset - truth).abs() < 20.0, "{name}: estimated {offset} ms against {truth} ms: {m}");
        let posed = m["scans_posed_from_odometry_stream"].as_u64().or(m["scans_posed_as_logged"].as_u64());
        assert_eq!(posed, Some(4000), "{m}");
    }
    // With the latency learnt the map is better than with the stamps as
    // logged.
    let late = d("late/sim.clf");
    let out = squall(&[
        "slam",
        "--log",
        &late,
        "--quiet",
        "--set",
        "source.params.clock_offset=\"log\"",
        "--out",
        &d("late/as-logged"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(source_metrics(&dir.join("late/as-logged"))["scans_posed_as_logged"], 4000);
    let relations = dir.join("late/sim.relations");
    let learnt = relation_error(&dir.join("late/slam/trajectory.tum"), &relations);
    let as_logged = relation_error(&dir.join("late/as-logged/trajectory.tum"), &relations);
    assert!(learnt < as_logged, "learnt {learnt} m, as logged {as_logged} m");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Width × height of a PGM map, from its header.
fn pgm_size(path: &std::path::Path) -> (u64, u64) {
    let text = String::from_utf8_lossy(&std::fs::read(path).unwrap()).into_owned();
    let mut fields = text.lines().skip(1).filter(|l| !l.starts_with('#')).flat_map(str::split_whitespace);
    let mut next = || fields.next().unwrap().parse::<u64>().unwrap();
    (next(), next())
}

#[test]
fn slam_finds_a_simulated_no_return_code_below_the_declared_range() {
    let dir = out_dir("sim-no-return");
    let d = |p: &str| dir.join(p).to_str().unwrap().to_string();
    // No return written as 51.08 m ± 4 cm, the log declaring 80 m.
    let out = squall(&[
        "sim",
        "--duration",
        "200",
        "--seed",
        "4",
        "--no-return",
        "51.08",
        "--declared-range",
        "80",
        "--out",
        &d("log"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let log = d("log/sim.clf");
    let slam = |mode: &str| {
        let out_dir = d(&format!("slam-{mode}"));
        let set = format!("source.params.no_return=\"{mode}\"");
        let out = squall(&["slam", "--log", &log, "--quiet", "--set", &set, "--out", &out_dir]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        std::path::PathBuf::from(out_dir)
    };
    let found = slam("auto");
    let m = source_metrics(&found);
    assert_eq!(m["no_return_codes"], 1, "{m}");
    let (from, to) =
        (m["no_return_code_1_from_m"].as_f64().unwrap(), m["no_return_code_1_to_m"].as_f64().unwrap());
    assert!((51.0..=51.04).contains(&from) && (51.12..=51.2).contains(&to), "{m}");
    assert!(m["no_return_readings_marked"].as_u64().unwrap() > 0, "{m}");
    // Taken at its word, the log's code draws walls 51 m out and the map
    // grows to hold them; with the code found, it holds the office.
    let declared = slam("declared");
    assert!(source_metrics(&declared).get("no_return_codes").is_none());
    let (w_found, h_found) = pgm_size(&found.join("map.pgm"));
    let (w_declared, h_declared) = pgm_size(&declared.join("map.pgm"));
    assert!(
        w_found * h_found * 2 < w_declared * h_declared,
        "found {w_found}×{h_found}, declared {w_declared}×{h_declared}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_slip_guard_mends_simulated_wheel_slips() {
    let dir = out_dir("sim-slips");
    let d = |p: &str| dir.join(p).to_str().unwrap().to_string();
    let out = squall(&["sim", "--duration", "300", "--seed", "5", "--slip-every", "60", "--out", &d("log")]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let log = d("log/sim.clf");
    let error = |mend: &str| {
        let out_dir = d(&format!("mend-{mend}"));
        let set = format!("source.params.mend_slips={mend}");
        let out = squall(&["slam", "--log", &log, "--quiet", "--set", &set, "--out", &out_dir]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let m = source_metrics(std::path::Path::new(&out_dir));
        (relation_error(&dir.join(format!("mend-{mend}/trajectory.tum")), &dir.join("log/sim.relations")), m)
    };
    let ((mended, m), (kept, plain)) = (error("true"), error("false"));
    assert!(m["slipped_steps"].as_u64().unwrap() > 20, "{m}");
    assert!(plain.get("slipped_steps").is_none(), "off by default: {plain}");
    assert!(mended < 0.5 * kept, "mended {mended} m, kept {kept} m");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_odometry_quality_and_laser_flags_take_effect() {
    let dir = out_dir("sim-odometry");
    // Raw odometry's relation error for each quality, same seed and route.
    let error = |quality: &str| -> f64 {
        let out_dir = dir.join(quality);
        let out = squall(&[
            "sim",
            "--duration",
            "120",
            "--seed",
            "4",
            "--odometry",
            quality,
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let (clf, rel) = (out_dir.join("sim.clf"), out_dir.join("sim.relations"));
        let out = squall(&[
            "eval",
            "--trajectory",
            clf.to_str().unwrap(),
            "--relations",
            rel.to_str().unwrap(),
            "--json",
        ]);
        let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
        v["trans_mean"].as_f64().unwrap()
    };
    let (good, poor, bad) = (error("good"), error("poor"), error("bad"));
    assert!(good < poor && poor < bad, "odometry errors: good {good}, poor {poor}, bad {bad}");
    let out = squall(&["sim", "--odometry", "awful", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("good, poor or bad"), "{}", text(&out.stderr));
    // The laser's field of view and range reach the log.
    let narrow = dir.join("narrow");
    let out = squall(&[
        "sim",
        "--duration",
        "5",
        "--fov-deg",
        "90",
        "--range-max",
        "10",
        "--out",
        narrow.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let clf = std::fs::read_to_string(narrow.join("sim.clf")).unwrap();
    assert!(clf.contains("PARAM laser_front_laser_angle_min -0.785398163"), "{clf:.400}");
    assert!(clf.contains("PARAM robot_front_laser_max 10.00"), "{clf:.400}");
    // The campus has an 80 m laser and a faster robot unless told
    // otherwise; the range flag still wins.
    let campus = |dir: &std::path::Path, extra: &[&str]| -> String {
        let mut args = vec!["sim", "--world", "campus", "--duration", "5", "--out", dir.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = squall(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        std::fs::read_to_string(dir.join("sim.clf")).unwrap()
    };
    let clf = campus(&dir.join("campus"), &[]);
    assert!(clf.contains("PARAM robot_front_laser_max 80.00"), "{clf:.400}");
    let clf = campus(&dir.join("campus30"), &["--range-max", "30"]);
    assert!(clf.contains("PARAM robot_front_laser_max 30.00"), "{clf:.400}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_sim_spout_feeds_a_topology() {
    let dir = out_dir("simrun");
    let out = squall(&[
        "run",
        "examples/topologies/sim.toml",
        "--set",
        "source.params.duration_secs=60",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (odom, truth) = (dir.join("odometry.tum"), dir.join("truth.tum"));
    let out = squall(&[
        "eval",
        "--trajectory",
        odom.to_str().unwrap(),
        "--ground-truth",
        truth.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert_eq!(v["pairs"], 600);
    assert!(v["ate_rmse"].as_f64().unwrap() > 0.0, "odometry drifts from the truth: {v}");

    let out = squall(&["validate", "examples/topologies/sim.toml", "--set", "source.params.fov_deg=0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("field of view must be in (0°, 360°]"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn slam_on_an_aces_prefix_writes_maps_and_a_good_trajectory() {
    let dir = out_dir("slam-aces");
    let log = shared_data("laser/aces.clf");
    let out = squall(&["slam", "--log", &log, "--max-scans", "300", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for f in ["map.pgm", "map.yaml", "map.png", "trajectory.tum", "metrics.json"] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    let tum = dir.join("trajectory.tum");
    let relations = shared_data("laser/aces.relations");
    let out = squall(&["eval", "--trajectory", tum.to_str().unwrap(), "--relations", &relations, "--json"]);
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert!(v["matched"].as_u64().unwrap() > 10, "{v}");
    // Raw odometry scores 0.549 m on the whole log; SLAM on the prefix must
    // do far better.
    assert!(v["trans_mean"].as_f64().unwrap() < 0.15, "{v}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let matcher = m["components"].as_array().unwrap().iter().find(|c| c["name"] == "matcher").unwrap();
    assert!(matcher["custom"]["evaluations_per_particle"]["count"].as_u64().unwrap() > 0, "{matcher}");
    // What the best particle learned of the robot's odometry: a turn error
    // in thousandths, moved from the prior's 100 by the prefix's turns.
    let turn_error = matcher["custom"]["turn_error_permille"].as_u64().unwrap();
    assert!((10..500).contains(&turn_error) && turn_error != 100, "{matcher}");
    assert!(matcher["custom"]["matcher_heading_noise_mrad"].as_u64().is_some(), "{matcher}");
    // Map memory is sampled at the first update and every tenth after, and
    // tiles cloned are reported per reading: one value per update; the maps
    // grow (a resampling may shrink them: copies share tiles), so the final
    // size is at least about the largest sampled and of its order (the
    // readings after the last sample may still enter new ground), and the
    // clones add up to the total.
    let updates = matcher["custom"]["update_us"]["count"].as_u64().unwrap();
    let memory = &matcher["custom"]["map_bytes_per_reading"];
    assert_eq!(memory["count"].as_u64().unwrap(), updates.div_ceil(10), "{matcher}");
    let final_bytes = matcher["custom"]["map_bytes"].as_f64().unwrap();
    let largest = memory["max"].as_f64().unwrap();
    assert!(largest <= 1.03 * final_bytes && largest > 0.5 * final_bytes, "{matcher}");
    assert!(memory["p50"].as_f64().unwrap() < largest, "the maps grow: {matcher}");
    let resampler = m["components"].as_array().unwrap().iter().find(|c| c["name"] == "resampler").unwrap();
    let clones = &resampler["custom"]["tiles_cloned_per_reading"];
    assert_eq!(clones["count"].as_u64().unwrap(), updates, "{resampler}");
    let total = resampler["custom"]["tiles_cloned"].as_f64().unwrap();
    assert!(total > 0.0, "{resampler}");
    let summed = clones["mean"].as_f64().unwrap() * updates as f64;
    assert!((summed - total).abs() < 0.01 * total, "{resampler}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn slam_on_the_simulator_and_its_argument_checks() {
    let dir = out_dir("slam-sim");
    let out = squall(&[
        "slam",
        "--max-scans",
        "400",
        "--particles",
        "10",
        "--cutoff",
        "140",
        "--set",
        "matcher.params.map_interval=3",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let poses = std::fs::read_to_string(dir.join("trajectory.tum")).unwrap();
    assert_eq!(poses.lines().filter(|l| !l.starts_with('#')).count(), 400);
    // The map sink gets the 400 trajectory poses, a map every third
    // processed scan and the final map.
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let component =
        |name: &str| m["components"].as_array().unwrap().iter().find(|c| c["name"] == name).unwrap();
    let processed = component("resampler")["custom"]["processed_scans"].as_u64().unwrap();
    assert!(processed > 6, "{processed} processed scans");
    assert_eq!(component("map")["received"].as_u64().unwrap(), 400 + processed / 3 + 1);
    let out = squall(&["slam", "--matchers", "0", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr)
            .contains("invalid value '0' for '--matchers <MATCHERS>': expected a count in 1..=1024"),
        "{}",
        text(&out.stderr)
    );
    let out = squall(&["slam", "--cutoff", "fast", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("cutoff"), "{}", text(&out.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A copy of the first `scans` front scans of the ACES log (with the
/// odometry between them), every pose after the `jump_after`-th scan moved
/// `jump` metres along x: a log whose odometry jumps.
fn aces_with_a_jump(path: &std::path::Path, scans: usize, jump_after: usize, jump: f64) {
    let log = std::fs::read_to_string(shared_data("laser/aces.clf")).unwrap();
    let (mut seen, mut out) = (0, String::new());
    for line in log.lines() {
        let mut fields: Vec<String> = line.split_whitespace().map(str::to_string).collect();
        let moved = seen >= jump_after;
        match fields.first().map(String::as_str) {
            Some("FLASER") => {
                if seen == scans {
                    break;
                }
                seen += 1;
                // FLASER n r1..rn x y θ odom_x odom_y odom_θ …
                let n: usize = fields[1].parse().unwrap();
                if moved {
                    for k in [2 + n, 2 + n + 3] {
                        fields[k] = (fields[k].parse::<f64>().unwrap() + jump).to_string();
                    }
                }
            }
            Some("ODOM") if moved => fields[1] = (fields[1].parse::<f64>().unwrap() + jump).to_string(),
            _ => {}
        }
        out.push_str(&fields.join(" "));
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn a_map_that_would_outgrow_its_bound_is_an_error_not_an_abort() {
    let dir = out_dir("slam-bound");
    std::fs::create_dir_all(&dir).unwrap();
    // Odometry that jumps a billion metres after scan 100 used to grow
    // every particle's map until the allocation of 49 PB failed (abort).
    let log = dir.join("jump.clf");
    aces_with_a_jump(&log, 150, 100, 1e9);
    let out = squall(&["slam", "--log", log.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("would pass its bound of 2000 m a side (max_map_m)"), "{stderr}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["status"], "failed", "{metrics}");
    // A jump the bound holds (500 m) is mapped.
    aces_with_a_jump(&log, 150, 100, 500.0);
    let bounded =
        squall(&["slam", "--log", log.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
    assert!(bounded.status.success(), "{}", text(&bounded.stderr));
    // Cells so small that the bound's index alone would take terabytes
    // are refused before the run.
    let out = squall(&[
        "slam",
        "--log",
        log.to_str().unwrap(),
        "--set",
        "matcher.params.delta=1e-9",
        "--out",
        dir.join("out").to_str().unwrap(),
    ]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("raise delta or lower max_map_m"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_backend_closes_the_simulated_offices_loops_and_rebuilds_the_map() {
    // The main job's world and seed, with its ground-truth relations.
    let sim = out_dir("backend-sim");
    let out = squall(&["sim", "--seed", "42", "--out", sim.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let relations = sim.join("sim.relations");
    let on = out_dir("backend-on");
    let off = out_dir("backend-off");
    let out = squall(&["slam", "--out", on.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = squall(&["slam", "--set", "backend.params.enabled=false", "--out", off.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let component = |dir: &Path, name: &str| {
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
        m["components"].as_array().unwrap().iter().find(|c| c["name"] == name).unwrap().clone()
    };
    let backend = component(&on, "backend");
    assert!(backend["custom"]["loops"].as_u64().unwrap() > 10, "{backend}");
    assert_eq!(component(&off, "backend")["custom"]["searches"].as_u64(), Some(0));
    // The matcher's maps pass through either way; with loops closed, the
    // map rebuilt along the corrected poses comes last.
    let received = |dir: &Path| component(dir, "map")["received"].as_u64().unwrap();
    assert_eq!(received(&on), received(&off) + 1, "{backend}");
    let (with, without) = (
        relation_error(&on.join("trajectory.tum"), &relations),
        relation_error(&off.join("trajectory.tum"), &relations),
    );
    assert!(
        with < 0.9 * without,
        "the loops closed made the trajectory {with} m against {without} m without"
    );
    assert!(std::fs::read(on.join("map.pgm")).unwrap() != std::fs::read(off.join("map.pgm")).unwrap());
    for dir in [sim, on, off] {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// `squall slam` with K matcher tasks writes byte-identical `trajectory.tum`
/// and `map.pgm` to K = 1, for every K up to 8. Returns K = 1's trajectory.
fn assert_matchers_agree(name: &str, args: &[&str]) -> Vec<u8> {
    let run = |k: usize| {
        let dir = out_dir(&format!("{name}-k{k}"));
        let k_text = k.to_string();
        let mut all = vec!["slam", "--matchers", &k_text, "--out", dir.to_str().unwrap()];
        all.extend_from_slice(args);
        let out = squall(&all);
        assert!(out.status.success(), "K = {k}: {}", text(&out.stderr));
        let read = |f: &str| std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("K = {k}: {f}: {e}"));
        let files = (read("trajectory.tum"), read("map.pgm"), read("metrics.json"));
        let _ = std::fs::remove_dir_all(&dir);
        files
    };
    let (trajectory, map, _) = run(1);
    let mut moved = 0;
    for k in 2..=8 {
        let (t, m, metrics) = run(k);
        assert!(t == trajectory, "{name}: K = {k} trajectory.tum differs from K = 1");
        assert!(m == map, "{name}: K = {k} map.pgm differs from K = 1");
        let v: serde_json::Value = serde_json::from_slice(&metrics).unwrap();
        let resampler =
            v["components"].as_array().unwrap().iter().find(|c| c["name"] == "resampler").unwrap();
        moved += resampler["custom"]["particles_moved"]["mean"].as_f64().map_or(0.0, |m| m.ceil()) as u64;
    }
    assert!(moved > 0, "{name}: no particle ever moved between tasks: the exchange went untested");
    trajectory
}

#[test]
fn slam_on_the_simulator_is_the_same_for_every_matcher_count() {
    // 1200 scans: enough processed readings for the filter to resample
    // and move particles between tasks (600 did not, once the turns' error
    // spread the particles less unevenly; decision 0016).
    assert_matchers_agree("slam-k-sim", &["--max-scans", "1200", "--particles", "12"]);
}

#[test]
fn slam_on_an_aces_prefix_is_the_same_for_every_matcher_count() {
    let log = shared_data("laser/aces.clf");
    // Map snapshots every 3 readings, so that the old-map search runs (and
    // particles move with their snapshots) within the prefix. (In 500 scans
    // it ran but changed nothing once the turn error was learned without
    // the matcher's noise.)
    let args = ["--log", &log, "--max-scans", "700", "--set", "matcher.params.old_map_age=3"];
    let searched = assert_matchers_agree("slam-k-aces", &args);
    let dir = out_dir("slam-k-aces-no-old-map");
    let out = squall(&["slam", "--log", &log, "--max-scans", "700", "--out", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let plain = std::fs::read(dir.join("trajectory.tum")).unwrap();
    assert!(plain != searched, "the old-map search changed nothing: it went untested");
}

#[test]
fn live_dispatch_drops_readings_while_the_matchers_are_busy_and_counts_each() {
    let dir = out_dir("slam-live");
    let out = squall(&[
        "slam",
        "--max-scans",
        "500",
        "--particles",
        "40",
        "--set",
        "dispatcher.params.mode=\"live\"",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let dispatcher = m["components"].as_array().unwrap().iter().find(|c| c["name"] == "dispatcher").unwrap();
    let handed_out = dispatcher["emitted"].as_u64().unwrap();
    let dropped = dispatcher["custom"]["dropped_readings"].as_u64().unwrap();
    assert!(dropped > 0, "the source outran 40 particles, yet nothing was dropped: {dispatcher}");
    assert_eq!(handed_out + dropped, 500, "every scan was either handed out or counted as dropped");
    let poses = std::fs::read_to_string(dir.join("trajectory.tum")).unwrap();
    assert_eq!(poses.lines().filter(|l| !l.starts_with('#')).count() as u64, handed_out);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn speedup_runs_every_configuration_and_writes_a_table_csv_and_plot() {
    let dir = out_dir("speedup");
    let args = ["speedup", "--max-scans", "300", "--particles", "6,10", "--matchers", "1,2", "--out"];
    let out = squall(&[&args[..], &[dir.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let table = text(&out.stdout);
    assert!(table.contains("median ms") && table.contains("efficiency"), "{table}");
    let csv = std::fs::read_to_string(dir.join("speedup.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let number =
        |r: &Vec<&str>, i: usize| r[i].parse::<f64>().unwrap_or_else(|_| panic!("column {i}: {csv}"));
    for pair in rows.chunks(2) {
        let (one, two) = (&pair[0], &pair[1]);
        assert_eq!(
            (one[0], one[1], two[0], two[1]),
            (two[0], "1", one[0], "2"),
            "rows by particles, then K: {csv}"
        );
        assert!(number(one, 2) > 0.0 && number(two, 2) > 0.0, "median ms: {csv}");
        // Speedup T1/T2 and efficiency speedup/2, from the medians shown.
        let speedup = number(one, 2) / number(two, 2);
        assert!((number(two, 3) - speedup).abs() < 1e-3 * speedup.max(1.0), "speedup: {csv}");
        assert!((number(two, 4) - speedup / 2.0).abs() < 1e-3 * speedup.max(1.0), "efficiency: {csv}");
        assert_eq!(two[8], "true", "K = 2 must reproduce K = 1: {csv}");
    }
    let svg = std::fs::read_to_string(dir.join("speedup.svg")).unwrap();
    assert_eq!(svg.matches("<polyline").count(), 2, "one line per particle count");
    assert!(svg.contains("stroke-dasharray"), "the ideal line is dashed");
    assert!(dir.join("p10-k2/trajectory.tum").exists());
    let out = squall(&["speedup", "--matchers", "0", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("invalid value '0' for '--matchers <MATCHERS>'"),
        "{}",
        text(&out.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn parfil_runs_on_the_particle_filter_topology_and_finds_the_robot() {
    let mut last = Vec::new();
    for k in ["1", "2"] {
        let dir = out_dir(&format!("parfil-k{k}"));
        let out = squall(&[
            "run",
            "examples/topologies/parfil.toml",
            "--set",
            "source.params.iterations=500",
            "--set",
            &format!("matcher.parallelism={k}"),
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let (estimate, truth) = (tum_xy(&dir.join("trajectory.tum")), tum_xy(&dir.join("truth.tum")));
        assert_eq!((estimate.len(), truth.len()), (501, 501));
        // Distance in the wrap-around room of 100 m × 100 m.
        let wrapped = |a: f64, b: f64| {
            let d = (a - b).rem_euclid(100.0);
            d.min(100.0 - d)
        };
        // A uniform guess is 38 m off on average; over the last 100
        // iterations the best lineage must track the robot.
        let mut errors: Vec<f64> = estimate[400..]
            .iter()
            .zip(&truth[400..])
            .map(|(&(_, ex, ey), &(_, tx, ty))| wrapped(ex, tx).hypot(wrapped(ey, ty)))
            .collect();
        errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 3.0, "K = {k}: the best lineage is a median {median:.2} m from the robot");
        last.push(estimate);
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(last[0] == last[1], "K = 2 differs from K = 1");
}

#[test]
fn localize_tracks_a_simulated_robot_in_a_real_building_map() {
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let cache = out_dir("localize-scenes");
    let (one, two) = (out_dir("localize-k1"), out_dir("localize-k2"));
    localize(&map, &one, &cache, &["--duration", "30", "--matchers", "1"]);
    localize(&map, &two, &cache, &["--duration", "30", "--matchers", "2"]);
    let tum = one.join("trajectory.tum");
    // Scored in the map frame, as the trajectory declares: every pose
    // within 5 cm, and the same figures in metrics.json.
    let v = against_ground_truth(&one);
    assert_eq!(v["frame"], "map", "{v}");
    let mean = v["map_mean_m"].as_f64().unwrap_or_else(|| panic!("no map-frame error in {v}"));
    assert!(mean < 0.02 && v["map_max_m"].as_f64().unwrap() < 0.05, "{v}");
    assert_eq!((v["map_within_share"].as_f64(), v["converged_after_s"].as_f64()), (Some(1.0), Some(0.0)));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(one.join("metrics.json")).unwrap()).unwrap();
    for key in
        ["pairs", "map_mean_m", "map_max_m", "map_rot_max_deg", "map_within_share", "converged_after_s"]
    {
        assert_eq!(m["localization"][key], v[key], "{key}: {}", m["localization"]);
    }
    assert!(
        std::fs::read(&tum).unwrap() == std::fs::read(two.join("trajectory.tum")).unwrap(),
        "two matchers differ from one"
    );
    assert!(std::fs::read_dir(&cache).unwrap().count() == 1, "the scene grid was cached once");
    let bad =
        squall(&["localize", "--map", &map, "--sim", "--resampling", "best", "--out", one.to_str().unwrap()]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(text(&bad.stderr).contains("--resampling"), "{}", text(&bad.stderr));
    let bad =
        squall(&["localize", "--map", &map, "--sim", "--start", "somewhere", "--out", one.to_str().unwrap()]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(text(&bad.stderr).contains("--start must be drawn or first-node"), "{}", text(&bad.stderr));
    let bad = squall(&["localize", "--map", &map, "--out", one.to_str().unwrap()]);
    assert_eq!(bad.status.code(), Some(2));
    assert_eq!(
        text(&bad.stderr),
        "error: --sim is required: recorded depth and laser input come later\n",
        "localize without --sim refuses before running anything"
    );
    assert!(bad.stdout.is_empty(), "{}", text(&bad.stdout));
    for d in [one, two, cache] {
        let _ = std::fs::remove_dir_all(d);
    }
}

fn toml_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// Runs `squall localize --sim` on `map` into `dir` with `args`, the scene
/// cache in `cache`; it must succeed.
fn localize(map: &str, dir: &Path, cache: &Path, args: &[&str]) {
    let cache_dir = format!("matcher.params.cache_dir={}", toml_string(cache.to_str().unwrap()));
    let mut all =
        vec!["localize", "--map", map, "--sim", "--set", &cache_dir, "--out", dir.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = squall(&all);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

/// `squall eval --json` of `dir`'s trajectory against its ground truth (in
/// the frame the trajectory declares).
fn against_ground_truth(dir: &Path) -> serde_json::Value {
    let (tum, truth) = (dir.join("trajectory.tum"), dir.join("ground_truth.tum"));
    let out = squall(&[
        "eval",
        "--trajectory",
        tum.to_str().unwrap(),
        "--ground-truth",
        truth.to_str().unwrap(),
        "--json",
    ]);
    serde_json::from_str(&text(&out.stdout)).unwrap()
}

/// (stamp, x, y) of every pose of a TUM file.
fn tum_xy(path: &Path) -> Vec<(f64, f64, f64)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], v[1], v[2])
        })
        .collect()
}

#[test]
fn a_kidnapped_robot_is_found_again_and_the_carry_reported_is_the_one_simulated() {
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let (dir, cache) = (out_dir("localize-kidnap"), out_dir("localize-kidnap-scenes"));
    let args = ["--duration", "14", "--kidnap-at", "6", "--seed", "2"];
    localize(&map, &dir, &cache, &args);
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let l = &metrics["localization"];
    let (at, carry) = (l["kidnap"]["at_s"].as_f64().unwrap(), l["kidnap"]["carry_m"].as_f64().unwrap());
    assert!((5.0..=20.0).contains(&carry), "{l}");
    // The ground truth the run wrote jumps by the reported carry at the
    // reported instant: the replay before the run saw the run's robot.
    let truth = tum_xy(&dir.join("ground_truth.tum"));
    let i = truth.iter().position(|p| p.0 > at).unwrap();
    let jump = (truth[i].1 - truth[i - 1].1).hypot(truth[i].2 - truth[i - 1].2);
    assert!((jump - carry).abs() < 0.2, "truth jumps {jump} m, reported {carry} m");
    let recovered = l["kidnap"]["recovered_after_s"].as_f64().expect("found again");
    assert!(recovered <= 5.0, "found after {recovered} s");
    // Scored against dead reckoning too.
    let odometry = l["odometry"]["map_mean_m"].as_f64().unwrap();
    assert!(odometry > 0.0 && l["worst_over_odometry_m"].as_f64().is_some(), "{l}");
}

#[test]
fn global_localization_converges_within_ten_seconds() {
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let (dir, cache) = (out_dir("localize-global"), out_dir("localize-global-scenes"));
    // The defaults: 2000 particles where the first scan fits, fewer as
    // they gather.
    localize(&map, &dir, &cache, &["--duration", "15", "--init", "global"]);
    let (estimate, truth) = (tum_xy(&dir.join("trajectory.tum")), tum_xy(&dir.join("ground_truth.tum")));
    assert_eq!(estimate.len(), truth.len());
    let t0 = truth[0].0;
    // metrics.json scores it in the map frame: settled within 0.2 m and 5°
    // within ten seconds, and stayed.
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let converged = m["localization"]["converged_after_s"].as_f64();
    assert!(converged.is_some_and(|s| s > 0.0 && s <= 10.0), "{}", m["localization"]);
    // KLD-sampling: the set shrinks to what tracking needs once the robot
    // is found (one or two bins: at most n(2) = 67 particles).
    let resampler = m["components"].as_array().unwrap().iter().find(|c| c["name"] == "resampler").unwrap();
    let particles = &resampler["custom"]["particles"];
    assert!(
        particles["p50"].as_u64().unwrap() <= 67 && particles["max"].as_u64().unwrap() >= 50,
        "{particles}"
    );
    let first_error = (estimate[0].1 - truth[0].1).hypot(estimate[0].2 - truth[0].2);
    assert!(first_error > 1.0, "the uniform start is not already at the robot ({first_error:.2} m)");
    for (e, t) in estimate.iter().zip(&truth).filter(|(_, t)| t.0 - t0 >= 10.0) {
        let error = (e.1 - t.1).hypot(e.2 - t.2);
        assert!(error < 0.2, "{:.1} s after the start the estimate is {error:.2} m off", t.0 - t0);
    }
    // The hypotheses: several modes at first, then one heavy mode at the
    // robot.
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(dir.join("hypotheses.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), truth.len() - 1, "one line per corrected scan");
    // The estimate is the heaviest mode's weighted mean at every corrected
    // scan (`estimate = "mode"`), not one particle's pose.
    for line in &lines {
        let stamp = line["stamp"].as_f64().unwrap();
        let mode = &line["modes"][0]["pose"];
        let at = estimate.iter().find(|e| (e.0 - stamp).abs() < 1e-6).unwrap();
        let (x, y) = (mode["x"].as_f64().unwrap(), mode["y"].as_f64().unwrap());
        assert!((at.1 - x).abs() < 1e-5 && (at.2 - y).abs() < 1e-5, "{stamp}: {at:?} against {mode}");
    }
    assert!(lines[0]["modes"].as_array().unwrap().len() > 1, "{}", lines[0]);
    let last = &lines[lines.len() - 1]["modes"][0];
    let (x, y) = (last["pose"]["x"].as_f64().unwrap(), last["pose"]["y"].as_f64().unwrap());
    let t = truth[truth.len() - 1];
    assert!((x - t.1).hypot(y - t.2) < 0.2 && last["weight"].as_f64().unwrap() > 0.9, "{last}");
    // The set's size changes, over tasks too: two matchers write the same
    // bytes.
    let two = out_dir("localize-global-k2");
    localize(&map, &two, &cache, &["--duration", "15", "--init", "global", "--matchers", "2"]);
    for file in ["trajectory.tum", "hypotheses.jsonl"] {
        let (a, b) = (std::fs::read(dir.join(file)).unwrap(), std::fs::read(two.join(file)).unwrap());
        assert!(a == b, "{file} differs between 1 and 2 matcher tasks");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&two);
    let _ = std::fs::remove_dir_all(&cache);
}

#[test]
fn global_localization_never_reports_a_pose_outside_the_building() {
    use squall::core::interior::{DEFAULT_OPENING, Interior};
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let walls = squall::core::linemap::LineMap::load(Path::new(&map)).unwrap();
    let inside = Interior::of(&walls, DEFAULT_OPENING).unwrap();
    let (dir, cache) = (out_dir("localize-inside"), out_dir("localize-inside-scenes"));
    // Issue 24's report: started at the roadmap's first node, the sets of
    // seeds 3 and 6 used to leave the building through its outer wall,
    // ending tens of metres outside; kept inside, no estimate of theirs
    // is outside. (Since proposals take two surfaces, their sets stay in
    // even without the inside; the model's unit tests check that without
    // it proposals land outside.)
    let outside = |seed: &str, keep: &str| {
        let keep = format!("matcher.params.keep_inside={keep}");
        let global = ["--duration", "15", "--init", "global", "--start", "first-node"];
        let args = [&global[..], &["--seed", seed, "--set", &keep]].concat();
        localize(&map, &dir, &cache, &args);
        let estimates = tum_xy(&dir.join("trajectory.tum"));
        estimates.iter().filter(|p| !inside.contains(p.1, p.2)).count()
    };
    for seed in ["3", "6"] {
        assert_eq!(outside(seed, "true"), 0, "seed {seed}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&cache);
}

#[test]
fn localize_with_a_simulated_depth_camera_tracks_through_fspf() {
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let (dir, cache) = (out_dir("localize-depth"), out_dir("localize-depth-scenes"));
    localize(&map, &dir, &cache, &["--input", "depth", "--duration", "5"]);
    let v = against_ground_truth(&dir);
    assert_eq!(v["pairs"].as_u64(), Some(50), "{v}");
    assert!(v["map_mean_m"].as_f64().unwrap() < 0.05, "{v}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let points = m["components"].as_array().unwrap().iter().find(|c| c["name"] == "points").unwrap();
    assert!(points["custom"]["wall_points"]["p50"].as_u64().unwrap() > 300, "{points}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&cache);
}
