//! End-to-end tests of `squall study` on the start of the real ACES log and
//! on a log that `squall slam` cannot read.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

mod common;

/// Lines of aces.clf in the short log: about 600 scans, enough for dozens
/// of its relations to fall inside.
const SHORT_LINES: usize = 1200;

fn squall(dir: &Path, args: &[&str]) -> Output {
    common::output_within(
        Command::new(env!("CARGO_BIN_EXE_squall")).args(args).current_dir(dir),
        Duration::from_secs(120),
        String::new,
    )
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn shared_data(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    assert!(
        path.exists(),
        "missing {}: this test reads the shared data set (../shared/data beside the repository)",
        path.display()
    );
    path
}

/// A folder with `short.clf` (the start of aces.clf), `short.relations`
/// (all of ACES's: those outside the short log are not matched) and
/// `broken.clf` (a scan line cut off: it exists, but slam fails on it).
fn logs() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let aces = std::fs::read_to_string(shared_data("laser/aces.clf")).unwrap();
    let short: String = aces.lines().take(SHORT_LINES).flat_map(|l| [l, "\n"]).collect();
    std::fs::write(dir.path().join("short.clf"), short).unwrap();
    std::fs::copy(shared_data("laser/aces.relations"), dir.path().join("short.relations")).unwrap();
    std::fs::write(dir.path().join("broken.clf"), "FLASER 3 1.0 2.0\n").unwrap();
    dir
}

/// A tiny RFC 4180 reader: fields split on commas outside quotes, `""`
/// inside quotes is a quote.
fn csv_rows(text: &str) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for line in text.lines() {
        let (mut fields, mut field, mut quoted, mut chars) =
            (Vec::new(), String::new(), false, line.chars().peekable());
        while let Some(c) = chars.next() {
            match (c, quoted) {
                ('"', true) if chars.peek() == Some(&'"') => {
                    field.push('"');
                    chars.next();
                }
                ('"', _) => quoted = !quoted,
                (',', false) => fields.push(std::mem::take(&mut field)),
                _ => field.push(c),
            }
        }
        fields.push(field);
        rows.push(fields);
    }
    rows
}

#[test]
fn a_study_reports_every_run_and_a_failing_log_as_failed_rows_with_exit_1() {
    let dir = logs();
    let out = squall(
        dir.path(),
        &[
            "study",
            "--logs",
            "short.clf,broken.clf",
            "--seeds",
            "1-2",
            "--particles",
            "10",
            "--jobs",
            "2",
            "--out",
            "D",
        ],
    );
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "stdout:\n{stdout}\nstderr:\n{stderr}");

    let d = dir.path().join("D");
    let rows = csv_rows(&std::fs::read_to_string(d.join("study.csv")).unwrap());
    let header = &rows[0];
    let expected_header = "log,seed,status,error,trans_error_m,rot_error_deg,span_0_10_m,odometry_trans_error_m,\
                           odometry_span_0_10_m,worse_than_odometry,cpu_secs,peak_rss_mb,wall_secs,ate_m";
    assert_eq!(header.join(","), expected_header);
    assert_eq!(rows.len(), 5, "a header and 4 runs: {rows:?}");
    let col = |row: &[String], name: &str| row[header.iter().position(|h| h == name).unwrap()].clone();
    let num = |row: &[String], name: &str| {
        col(row, name).parse::<f64>().unwrap_or_else(|_| panic!("{name} of {row:?} is not a number"))
    };
    for row in &rows[1..] {
        assert_eq!(row.len(), header.len(), "{row:?}");
    }
    let short: Vec<&Vec<String>> = rows[1..].iter().filter(|r| r[0] == "short.clf").collect();
    let broken: Vec<&Vec<String>> = rows[1..].iter().filter(|r| r[0] == "broken.clf").collect();
    assert_eq!((short.len(), broken.len()), (2, 2));
    for (row, seed) in short.iter().zip(["1", "2"]) {
        assert_eq!(col(row, "seed"), seed);
        assert_eq!(col(row, "status"), "ok", "{row:?}");
        assert_eq!(col(row, "error"), "");
        for name in [
            "trans_error_m",
            "rot_error_deg",
            "span_0_10_m",
            "odometry_trans_error_m",
            "odometry_span_0_10_m",
        ] {
            let v = num(row, name);
            assert!(v.is_finite() && v >= 0.0, "{name} = {v}");
        }
        assert!(num(row, "trans_error_m") < 1.0, "SLAM on the start of ACES is metres off: {row:?}");
        let worse = num(row, "trans_error_m") > num(row, "odometry_trans_error_m");
        assert_eq!(col(row, "worse_than_odometry"), worse.to_string());
        assert!(num(row, "cpu_secs") > 0.0 && num(row, "peak_rss_mb") > 0.0 && num(row, "wall_secs") > 0.0);
        assert!(d.join(format!("runs/short-s{seed}/trajectory.tum")).is_file());
        assert!(d.join(format!("runs/short-s{seed}/stderr.log")).is_file());
    }
    assert_ne!(
        col(short[0], "trans_error_m"),
        col(short[1], "trans_error_m"),
        "two seeds gave the same error: was the seed passed on?"
    );
    for row in &broken {
        assert_eq!(col(row, "status"), "failed");
        let error = col(row, "error");
        assert!(error.contains("broken.clf:1: FLASER with 3 readings needs 13 fields"), "{error}");
        assert_eq!(col(row, "trans_error_m"), "");
        assert_eq!(col(row, "odometry_trans_error_m"), "", "broken.clf has no relations");
    }

    let md = std::fs::read_to_string(d.join("study.md")).unwrap();
    assert!(stdout.contains(&md), "stdout does not hold study.md:\n{stdout}");
    let table_line =
        |log: &str| md.lines().find(|l| l.starts_with(&format!("| {log} |"))).map(str::to_string);
    let short_line = table_line("short.clf").unwrap_or_else(|| panic!("no short.clf line in\n{md}"));
    assert!(short_line.starts_with("| short.clf | 2 | 0 |"), "{short_line}");
    let broken_line = table_line("broken.clf").unwrap_or_else(|| panic!("no broken.clf line in\n{md}"));
    assert!(broken_line.starts_with("| broken.clf | 2 | 2 |"), "{broken_line}");
    assert!(md.contains("--seeds 1-2"), "the command line is missing:\n{md}");

    let svg = std::fs::read_to_string(d.join("study.svg")).unwrap();
    assert_eq!(svg.matches("<circle class=\"run\"").count(), 2, "one dot per ok run:\n{svg}");
    assert_eq!(svg.matches("class=\"failed\"").count(), 2, "one cross per failed run");
    assert_eq!(svg.matches("class=\"odometry\"").count(), 1, "odometry of short.clf only");
}

#[test]
fn bad_input_exits_2_before_any_run() {
    let dir = logs();
    for (args, message) in [
        (&["--logs", "short.clf", "--seeds", "3-1"][..], "backwards"),
        (&["--logs", "short.clf,missing.clf", "--seeds", "1"][..], "missing.clf: no such log file"),
        (&["--logs", "short.clf", "--seeds", "1", "--set", "nonsense"][..], "expected PATH=VALUE"),
        (
            &["--logs", "short.clf", "--seeds", "1", "--set", "matcher.params.bogus=1"][..],
            "unknown field `bogus`",
        ),
        (
            &["--logs", "short.clf", "--seeds", "1", "--jobs", "0"][..],
            "invalid value '0' for '--jobs <JOBS>'",
        ),
    ] {
        let mut all = vec!["study"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--out", "D"]);
        let out = squall(dir.path(), &all);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(message), "{args:?}: {stderr}");
        assert!(!dir.path().join("D/runs").exists(), "{args:?} started runs");
    }
}

#[test]
fn an_output_folder_that_cannot_be_written_exits_2() {
    let dir = logs();
    std::fs::write(dir.path().join("file"), "").unwrap();
    let out = squall(dir.path(), &["study", "--logs", "short.clf", "--seeds", "1", "--out", "file/D"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("the output folder is not writable"), "{stderr}");
}

#[test]
fn a_study_whose_runs_all_finish_exits_0_and_a_log_without_relations_has_empty_accuracy() {
    let dir = logs();
    std::fs::copy(dir.path().join("short.clf"), dir.path().join("norel.clf")).unwrap();
    let out = squall(
        dir.path(),
        &["study", "--logs", "norel.clf", "--seeds", "5", "--particles", "10", "--out", "D"],
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let rows = csv_rows(&std::fs::read_to_string(dir.path().join("D/study.csv")).unwrap());
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[1][..5], ["norel.clf", "5", "ok", "", ""]);
    assert!(rows[1][10].parse::<f64>().unwrap() > 0.0, "cpu_secs of {:?}", rows[1]);
}

#[test]
fn simulated_worlds_are_studied_per_odometry_quality_with_their_relations() {
    let dir = tempfile::tempdir().unwrap();
    let out = squall(
        dir.path(),
        &[
            "study",
            "--sim-worlds",
            "office",
            "--odometry",
            "good,bad",
            "--sim-duration",
            "60",
            "--seeds",
            "1-2",
            "--particles",
            "10",
            "--out",
            "D",
        ],
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let worlds = dir.path().join("D/worlds");
    for name in ["office-good", "office-bad"] {
        for file in [format!("{name}.clf"), format!("{name}.relations"), "ground_truth.tum".to_string()] {
            assert!(worlds.join(name).join(&file).is_file(), "{name}/{file} missing");
        }
    }
    let rows = csv_rows(&std::fs::read_to_string(dir.path().join("D/study.csv")).unwrap());
    assert_eq!(rows.len(), 5, "a header and 2 worlds × 2 seeds: {rows:?}");
    let column = |name: &str| rows[0].iter().position(|c| c == name).unwrap();
    let (status, error, odometry) =
        (column("status"), column("trans_error_m"), column("odometry_trans_error_m"));
    let odometry_of = |log: &str| -> f64 {
        let row = rows.iter().find(|r| r[0].contains(log)).unwrap();
        row[odometry].parse().unwrap()
    };
    let (ate, rss, seed) = (column("ate_m"), column("peak_rss_mb"), column("seed"));
    for row in &rows[1..] {
        assert_eq!(row[status], "ok", "{row:?}");
        // Each run's memory is its own, as its metrics.json reports it, not
        // the study's (which generated the worlds) carried into the child.
        let name = Path::new(&row[0]).file_stem().unwrap().to_string_lossy().into_owned();
        let metrics = dir.path().join(format!("D/runs/{name}-s{}/metrics.json", row[seed]));
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
        let own = metrics["peak_rss_mb"].as_f64().expect("the run reports its peak memory");
        let reported: f64 = row[rss].parse().unwrap();
        assert!(own > 1.0 && (reported - own).abs() < 0.06, "{reported} against {own}: {row:?}");
        let e: f64 = row[error].parse().unwrap();
        assert!(e.is_finite() && e < 0.1, "{row:?}");
        // Against the world's ground truth: SLAM keeps to a few centimetres.
        let ate: f64 = row[ate].parse().unwrap();
        assert!(ate > 0.0 && ate < 0.3, "ATE {ate} m: {row:?}");
    }
    // The worlds differ only in their odometry, which scores accordingly.
    assert!(odometry_of("office-good") < odometry_of("office-bad"), "{rows:?}");

    // A world that does not exist stops the study before anything is written.
    let out = squall(dir.path(), &["study", "--sim-worlds", "nowhere.txt", "--seeds", "1", "--out", "E"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--sim-worlds nowhere.txt"), "{}", text(&out.stderr));
    assert!(!dir.path().join("E").exists());
}

#[test]
fn a_localization_study_scores_every_map_mode_and_seed_and_refuses_a_kidnap_after_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let map = shared_data("linemaps/CVAP7_vector.txt");
    let map = map.to_str().unwrap();
    let args = ["study", "--maps", map, "--seeds", "1", "--duration", "12", "--jobs", "2", "--out", "L"];
    let out = squall(dir.path(), &args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let md = text(&out.stdout);
    for mode in ["tracking", "global", "kidnap"] {
        assert!(md.contains(&format!("| CVAP7 | laser | {mode} | 1/1 |")), "{mode}:\n{md}");
    }
    let csv = std::fs::read_to_string(dir.path().join("L/study.csv")).unwrap();
    let rows = csv_rows(&csv);
    let column = |name: &str| rows[0].iter().position(|c| c == name).unwrap();
    assert_eq!(rows.len(), 4, "a header and one row per mode: {csv}");
    let (mode, success, carry, recovered, converged) = (
        column("mode"),
        column("success"),
        column("carry_m"),
        column("recovered_after_s"),
        column("converged_after_s"),
    );
    for row in &rows[1..] {
        assert_eq!(row[success], "true", "{row:?}");
        match row[mode].as_str() {
            "tracking" => assert_eq!(row[converged].parse::<f64>().unwrap(), 0.0, "{row:?}"),
            "global" => assert!(row[converged].parse::<f64>().unwrap() <= 10.0, "{row:?}"),
            "kidnap" => {
                // Carried as far as the study says, and found within 5 s.
                let c: f64 = row[carry].parse().unwrap();
                assert!((5.0..=20.0).contains(&c), "{row:?}");
                assert!(row[recovered].parse::<f64>().unwrap() <= 5.0, "{row:?}");
            }
            other => panic!("unexpected mode {other}"),
        }
        let run = dir.path().join(format!("L/runs/CVAP7-laser-{}-s1/metrics.json", row[mode]));
        assert!(run.is_file(), "{}", run.display());
    }

    for row in &rows[1..] {
        assert_eq!(row[column("lookalike")], "", "only a miss is tested for a look-alike: {row:?}");
    }

    // A kidnapping after the run's end, or a map that is not there, stops
    // the study before anything runs.
    let late = ["study", "--maps", map, "--seeds", "1", "--duration", "5", "--kidnap-at", "8", "--out", "M"];
    let out = squall(dir.path(), &late);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--kidnap-at must lie within the run"), "{}", text(&out.stderr));
    let out = squall(dir.path(), &["study", "--maps", "nowhere.txt", "--seeds", "1", "--out", "N"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("nowhere.txt"), "{}", text(&out.stderr));
    assert!(!dir.path().join("M").exists() && !dir.path().join("N").exists());
}

#[test]
fn a_kidnapping_into_one_of_a_row_of_identical_offices_is_a_lookalike_miss() {
    // CVAP6 seed 6: the laser robot is carried into an office whose
    // neighbours, 9 m apart along the corridor, are drawn the same to a few
    // centimetres; it turns in place there for the 5 s the study allows.
    let dir = tempfile::tempdir().unwrap();
    let map = shared_data("linemaps/CVAP6_vector.txt");
    let args = [
        "study",
        "--maps",
        map.to_str().unwrap(),
        "--modes",
        "kidnap",
        "--seeds",
        "6",
        "--duration",
        "20",
        "--out",
        "K",
    ];
    let out = squall(dir.path(), &args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let md = text(&out.stdout);
    assert!(md.contains("| CVAP6 | laser | kidnap | 0/1 |") && md.contains("6: 3.38 (look-alike)"), "{md}");
    let csv = std::fs::read_to_string(dir.path().join("K/study.csv")).unwrap();
    let rows = csv_rows(&csv);
    let column = |name: &str| rows[0].iter().position(|c| c == name).unwrap();
    let row = &rows[1];
    assert_eq!(row[column("lookalike")], "true", "{csv}");
    assert_eq!(row[column("telling_frames")], "0", "{csv}");
    // Wrong at the end of the 5 s after the carry at 8 s, by a whole office.
    assert_eq!(row[column("wrong_at_s")].parse::<f64>().unwrap(), 13.0, "{csv}");
    let by: f64 = row[column("wrong_by_m")].parse().unwrap();
    assert!(by > 5.0, "{csv}");
    assert_eq!(row[column("frames")], "50", "{csv}");
}
