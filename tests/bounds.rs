//! Every number a user gives is bounded (docs/guide/limits.md): each
//! numeric flag of every command, and each numeric key of every example
//! topology, given the values an adversary tries first (0, −1, NaN, ±inf,
//! 1e300 and the types' extremes), ends with exit 0 (a value within its
//! bound, run to its end), 1 (a run that failed, saying why) or 2 (refused
//! before anything ran, naming the flag or key), within a bounded time,
//! and never with a panic, an abort or a signal.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

mod common;

use common::{output_within, shared_data};

/// What an adversary tries first, as command-line text.
const VALUES: [&str; 10] = [
    "0",
    "-1",
    "NaN",
    "inf",
    "-inf",
    "1e300",
    "1.7976931348623157e308",
    "18446744073709551615",
    "-9223372036854775808",
    "4.9e-324",
];

/// The same as TOML values for `--set`.
const TOML_VALUES: [&str; 9] =
    ["0", "-1", "nan", "inf", "-inf", "1e300", "9223372036854775807", "-9223372036854775808", "5e-324"];

/// The longest one case may take: the valid ones run a few scans.
const LIMIT: Duration = Duration::from_secs(120);

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("squall-bounds-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// The first 60 scans' worth of ACES, a log small enough to run in
/// moments.
fn small_log(dir: &Path) -> String {
    std::fs::create_dir_all(dir).unwrap();
    let text = std::fs::read_to_string(shared_data("laser/aces.clf")).unwrap();
    let head: Vec<&str> = text.lines().take(300).collect();
    let path = dir.join("small.clf");
    std::fs::write(&path, head.join("\n") + "\n").unwrap();
    path.to_str().unwrap().to_string()
}

/// Runs `squall args` and checks how it ended; `name` is what an exit 2
/// must mention.
fn check(args: &[String], name: &str) {
    let shown = args.join(" ");
    let out = output_within(
        Command::new(env!("CARGO_BIN_EXE_squall")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")),
        LIMIT,
        || shown.clone(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "squall {shown} panicked:\n{stderr}");
    match out.status.code() {
        Some(0) => {}
        Some(1) => assert!(!stderr.trim().is_empty(), "squall {shown}: exit 1 saying nothing"),
        Some(2) => assert!(stderr.contains(name), "squall {shown}: exit 2 not naming {name}:\n{stderr}"),
        other => panic!("squall {shown}: ended with {other:?} ({:?}):\n{stderr}", out.status),
    }
}

/// Tries every value of [`VALUES`] for every flag of `flags` on `base`
/// (a flag also in `base` has its value there replaced).
fn sweep(base: &[&str], flags: &[&str]) {
    for flag in flags {
        for value in VALUES {
            let mut args: Vec<String> = Vec::new();
            let mut i = 0;
            while i < base.len() {
                if base[i] == *flag {
                    i += 2;
                    continue;
                }
                args.push(base[i].to_string());
                i += 1;
            }
            // `--flag=-1`: as `--flag -1`, clap would take `-inf` for a
            // flag of its own.
            args.push(format!("{flag}={value}"));
            check(&args, flag);
        }
    }
}

#[test]
fn every_numeric_flag_is_bounded() {
    let dir = out_dir("flags");
    let log = small_log(&dir);
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    let edsh = shared_data("linemaps/EDSH120_vector.txt");
    sweep(
        &["slam", "--log", &log, "--max-scans", "5", "--out", out, "--quiet"],
        &["--particles", "--matchers", "--max-scans", "--seed", "--cutoff"],
    );
    sweep(
        &["slam", "--log", &log, "--max-scans", "5", "--out", out, "--quiet", "--ui", "127.0.0.1:0"],
        &["--ui-linger", "--metrics-every"],
    );
    sweep(
        &["localize", "--map", &edsh, "--sim", "--duration", "2", "--out", out, "--quiet"],
        &["--duration", "--particles", "--matchers", "--kidnap-at", "--seed"],
    );
    sweep(
        &["sim", "--duration", "2", "--out", out],
        &["--duration", "--seed", "--beams", "--fov-deg", "--range-max", "--memory-limit-mb"],
    );
    sweep(
        &["speedup", "--log", &log, "--max-scans", "3", "--particles", "5", "--matchers", "1", "--out", out],
        &["--particles", "--matchers", "--max-scans", "--seed"],
    );
    sweep(
        &[
            "study",
            "--sim-worlds",
            "office",
            "--sim-duration",
            "3",
            "--seeds",
            "1",
            "--max-scans",
            "2",
            "--out",
            out,
        ],
        &["--sim-duration", "--particles", "--max-scans", "--jobs", "--seeds"],
    );
    if cfg!(feature = "cluster") {
        // Nothing listens on port 1: a value within its bound ends in a
        // failure to connect, soon.
        sweep(
            &["robot", "--log", &log, "--connect", "tcp/127.0.0.1:1", "--connect-secs", "1"],
            &["--speed", "--max-scans", "--wait-secs", "--connect-secs"],
        );
        // 192.0.2.1 (TEST-NET-1) is no address of this machine: a worker
        // whose limits are within their bounds cannot listen there.
        sweep(
            &["worker", "--listen", "tcp/192.0.2.1:1", "--insecure"],
            &["--max-tasks", "--max-queued", "--max-run-secs", "--max-memory-mb"],
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The numeric keys of a topology file: `topology.KEY`, `NAME.KEY` and
/// `NAME.params.KEY` (arrays and nested tables left out).
fn numeric_keys(file: &Path) -> Vec<String> {
    let doc: toml::Table = std::fs::read_to_string(file).unwrap().parse().unwrap();
    let numeric = |v: &toml::Value| matches!(v, toml::Value::Integer(_) | toml::Value::Float(_));
    let mut keys = Vec::new();
    if let Some(t) = doc.get("topology").and_then(|t| t.as_table()) {
        keys.extend(t.iter().filter(|(_, v)| numeric(v)).map(|(k, _)| format!("topology.{k}")));
    }
    for role in ["spout", "bolt"] {
        for c in doc.get(role).and_then(|v| v.as_array()).into_iter().flatten() {
            let name = c["name"].as_str().unwrap();
            let table = c.as_table().unwrap();
            keys.extend(table.iter().filter(|(_, v)| numeric(v)).map(|(k, _)| format!("{name}.{k}")));
            if let Some(p) = c.get("params").and_then(|p| p.as_table()) {
                keys.extend(p.iter().filter(|(_, v)| numeric(v)).map(|(k, _)| format!("{name}.params.{k}")));
            }
        }
    }
    keys
}

#[test]
fn every_numeric_topology_key_is_bounded() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/topologies");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&examples).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    let mut swept = 0;
    for file in files.iter().filter(|f| f.extension().is_some_and(|e| e == "toml")) {
        let rel = file.strip_prefix(env!("CARGO_MANIFEST_DIR")).unwrap().to_str().unwrap().to_string();
        // A topology of kinds this build leaves out (live_slam.toml
        // without `cluster`) is refused whatever its numbers.
        let plain = Command::new(env!("CARGO_BIN_EXE_squall"))
            .args(["validate", &rel])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        if !plain.status.success() {
            let stderr = String::from_utf8_lossy(&plain.stderr);
            assert!(stderr.contains("is not in this build"), "{rel} is invalid as shipped: {stderr}");
            continue;
        }
        // Keys every component has, whether or not the file sets them.
        let mut keys = numeric_keys(file);
        keys.extend(["topology.seed", "topology.stall_secs", "topology.memory_limit_mb"].map(String::from));
        for key in keys {
            let name = key.rsplit('.').next().unwrap().to_string();
            for value in TOML_VALUES {
                check(&["validate".into(), rel.clone(), "--set".into(), format!("{key}={value}")], &name);
                swept += 1;
            }
        }
    }
    assert!(swept > 300, "only {swept} cases: the examples lost their numbers?");
}

/// Runs `squall args` expecting a refusal before anything runs: exit 2
/// within seconds, the message naming the memory limit and `what`.
fn refused_for_memory(args: &[&str], what: &str) {
    let started = std::time::Instant::now();
    let out = output_within(
        Command::new(env!("CARGO_BIN_EXE_squall")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")),
        LIMIT,
        || args.join(" "),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "squall {}: {stderr}", args.join(" "));
    assert!(stderr.contains("past the memory limit") && stderr.contains(what), "{stderr}");
    assert!(started.elapsed() < Duration::from_secs(20), "refused only after {:?}", started.elapsed());
}

#[test]
fn what_would_not_fit_in_memory_is_refused_before_it_runs() {
    let dir = out_dir("memory");
    let log = small_log(&dir);
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    let edsh = shared_data("linemaps/EDSH120_vector.txt");
    // A hundred million particles: 300 GB of SLAM particles, 120 GB of
    // CGR's (both used to abort or swell until killed).
    refused_for_memory(
        &["slam", "--log", &log, "--particles", "100000000", "--out", out],
        "100000000 particles",
    );
    refused_for_memory(
        &["localize", "--map", &edsh, "--sim", "--particles", "100000000", "--out", out],
        "100000000 particles",
    );
    // A hundred million simulated seconds: a billion scans (they ran
    // forever, growing).
    refused_for_memory(&["sim", "--duration", "1e8", "--out", out], "--duration 100000000");
    refused_for_memory(
        &["localize", "--map", &edsh, "--sim", "--duration", "1e8", "--out", out],
        "--duration",
    );
    // A square map 10 km across: its observable scenes on 0.2 m cells
    // would take 65 GB (it aborted).
    let map = dir.join("square.txt");
    std::fs::write(&map, "0,0,10000,0\n10000,0,10000,10000\n10000,10000,0,10000\n0,10000,0,0\n").unwrap();
    refused_for_memory(
        &["localize", "--map", map.to_str().unwrap(), "--sim", "--out", out],
        "observable scenes on a 50000 × 50000 grid (cell = 0.2 m)",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_score_that_overflows_is_an_error_not_inf() {
    let dir = out_dir("eval");
    std::fs::create_dir_all(&dir).unwrap();
    let (trajectory, truth) = (dir.join("t.tum"), dir.join("g.tum"));
    std::fs::write(&trajectory, "1 0 0 0 0 0 0 1\n2 1e308 0 0 0 0 0 1\n3 -1e308 0 0 0 0 0 1\n").unwrap();
    std::fs::write(&truth, "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n3 2 0 0 0 0 0 1\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args([
            "eval",
            "--trajectory",
            trajectory.to_str().unwrap(),
            "--ground-truth",
            truth.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no finite score"), "{stderr}");
    assert!(!String::from_utf8_lossy(&out.stdout).contains("inf"), "no infinite score is printed");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The numeric keys of a settings struct, from its serialized defaults.
fn numeric_fields<T: serde::Serialize>(defaults: &T) -> Vec<String> {
    let table: toml::Table = toml::Table::try_from(defaults).unwrap();
    table
        .iter()
        .filter(|(_, v)| matches!(v, toml::Value::Integer(_) | toml::Value::Float(_)))
        .map(|(k, _)| k.clone())
        .collect()
}

#[test]
fn every_slam_and_cgr_setting_runs_or_is_refused() {
    // Validation checks these settings; this runs each, at the values an
    // adversary tries first, over a few readings, so what validation lets
    // through is seen to run without a panic.
    let dir = out_dir("settings");
    let log = small_log(&dir);
    let edsh = shared_data("linemaps/EDSH120_vector.txt");
    let slam = numeric_fields(&squall::bolts::slam::options::SlamOptions::default());
    let mut cgr = numeric_fields(&squall::bolts::cgr::measurement::CgrOptions::default());
    // The CGR model's own settings, beside the measurement's.
    cgr.extend(
        ["particles", "min_particles", "resample_threshold", "cell", "alpha_slow", "alpha_fast", "min_drop"]
            .into_iter()
            .chain(["lost_share", "srr", "srt", "str", "stt", "inside_opening"])
            .map(String::from),
    );
    assert!(slam.len() > 20 && cgr.len() > 20, "{slam:?} {cgr:?}");
    let values = ["0", "-1", "nan", "1e300", "9223372036854775807", "5e-324"];
    let mut cases: Vec<(Vec<String>, String)> = Vec::new();
    for (i, key) in slam.iter().enumerate() {
        for value in values {
            let out = dir.join(format!("slam-{i}"));
            let args =
                ["slam", "--log", &log, "--max-scans", "30", "--quiet", "--out", out.to_str().unwrap()];
            let mut args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
            args.extend(["--set".into(), format!("matcher.params.{key}={value}")]);
            cases.push((args, key.clone()));
        }
    }
    for (i, key) in cgr.iter().enumerate() {
        for value in values {
            let out = dir.join(format!("cgr-{i}"));
            let args = [
                "localize",
                "--map",
                &edsh,
                "--sim",
                "--duration",
                "2",
                "--quiet",
                "--out",
                out.to_str().unwrap(),
            ];
            let mut args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
            args.extend(["--set".into(), format!("matcher.params.{key}={value}")]);
            cases.push((args, key.clone()));
        }
    }
    // Two at a time: the machine's two cores.
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                while let Some((args, key)) =
                    cases.get(next.fetch_add(1, std::sync::atomic::Ordering::SeqCst))
                {
                    check(args, key);
                }
            });
        }
    });
    let _ = std::fs::remove_dir_all(&dir);
}
