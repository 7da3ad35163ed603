//! `squall study`: how robust is SLAM on these logs, or localization on
//! these buildings (`--maps`, see [`localization`])? Runs `squall slam`
//! for every (log, seed) as its own process, as many at once as `--jobs`,
//! measures each run's CPU time and peak memory, scores each trajectory
//! and the log's raw odometry on the log's relations, and writes
//! `study.csv`, `study.md` (also printed) and `study.svg`.
//!
//! Every input is checked before the first run starts (exit 2); a run
//! that fails is a row of the report, never the end of the study (exit 1
//! once everything is written).

mod localization;
mod report;
mod runner;
mod score;
mod svg;
mod worlds;

use std::ffi::OsString;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;
use std::sync::mpsc;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use squall_core::eval::relations::{Relation, read_relations};
use squall_core::trajectory::Trajectory;
use squall_topology::fsio::write_atomic;

use self::report::{Row, Status};
use self::runner::{Job, Measured};
use self::score::Accuracy;
use super::slam::SlamArgs;
use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct StudyArgs {
    /// The logs, comma-separated. Each is scored against its sibling
    /// relations file (`X.relations` for `X.clf`) when there is one.
    #[arg(long, value_name = "A.clf,B.clf", value_delimiter = ',', required_unless_present_any = ["sim_worlds", "maps"])]
    logs: Vec<PathBuf>,
    /// Study localization instead: line maps, comma-separated. Every
    /// (map, sensor, mode, seed) runs `squall localize --sim` with its
    /// defaults; the report gives success, errors and times per (map,
    /// sensor, mode).
    #[arg(long, value_name = "A.txt,B.txt", value_delimiter = ',', conflicts_with_all = ["logs", "sim_worlds", "particles", "cutoff", "max_scans"])]
    maps: Vec<PathBuf>,
    /// With `--maps`: the simulated sensors, comma-separated.
    #[arg(
        long,
        value_name = "laser,depth",
        value_delimiter = ',',
        default_value = "laser",
        requires = "maps"
    )]
    inputs: Vec<localization::Sensor>,
    /// With `--maps`: what each run is asked, comma-separated: `tracking`
    /// (from the true start), `global` (from anywhere), `kidnap` (tracked,
    /// then carried 5–20 m at `--kidnap-at`).
    #[arg(
        long,
        value_name = "tracking,global,kidnap",
        value_delimiter = ',',
        default_value = "tracking,global,kidnap",
        requires = "maps"
    )]
    modes: Vec<localization::Mode>,
    /// With `--maps`: simulated seconds per run.
    #[arg(long, value_name = "S", default_value_t = 20.0, requires = "maps", value_parser = crate::cli::numbers::sim_secs)]
    duration: f64,
    /// With `--maps`: when kidnap runs are carried, seconds.
    #[arg(long, value_name = "S", default_value_t = 8.0, requires = "maps", value_parser = crate::cli::numbers::sim_instant)]
    kidnap_at: f64,
    /// Simulated worlds to study as well, comma-separated: `office`,
    /// `campus` (a large open site, 80 m laser), `ring` (one long loop) or
    /// line-map files. Each
    /// becomes a log per `--odometry` quality (simulator seed 1,
    /// `--sim-duration` seconds) under `DIR/worlds`.
    #[arg(long, value_name = "office,campus,MAP.txt", value_delimiter = ',')]
    sim_worlds: Vec<String>,
    /// The simulated worlds' odometry qualities, comma-separated.
    #[arg(long, value_name = "good|poor|bad", value_delimiter = ',', default_value = "poor")]
    odometry: Vec<squall_spouts::sim::OdometryQuality>,
    /// Simulated seconds per world.
    #[arg(long, value_name = "S", default_value_t = 600.0, value_parser = crate::cli::numbers::sim_secs)]
    sim_duration: f64,
    /// Seeds: single seeds and inclusive ranges, comma-separated, e.g.
    /// `1-10`, `1,2,5` or `1-3,7`.
    #[arg(long, value_name = "LIST", value_parser = parse_seeds)]
    seeds: Seeds,
    /// Particles (as in `squall slam`).
    #[arg(long, value_parser = crate::cli::numbers::positive_count)]
    particles: Option<u64>,
    /// Pose evaluations per particle per reading: a number or `none`.
    #[arg(long, value_name = "N|none", value_parser = crate::cli::numbers::cutoff)]
    cutoff: Option<String>,
    /// Stop each run after this many scans (the odometry is then scored
    /// on the same first scans).
    #[arg(long, value_parser = crate::cli::numbers::positive_count)]
    max_scans: Option<u64>,
    /// Override any value of every run (as in `squall run`). Repeatable.
    #[arg(long = "set", value_name = "PATH=VALUE", value_parser = checked_override)]
    overrides: Vec<String>,
    /// Runs at once. The default is the number of cores.
    #[arg(long, value_parser = crate::cli::numbers::tasks)]
    jobs: Option<usize>,
    /// Output folder: study.csv, study.md, study.svg and runs/<log>-s<seed>.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// A validated seed list, in the order given, without repeats.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Seeds(Vec<u64>);

/// Parses `1-10`, `1,2,5` or a mix (`1-3,7`): ranges are inclusive and
/// ascending; a seed given twice runs once.
fn parse_seeds(s: &str) -> Result<Seeds, String> {
    let mut seeds = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for part in s.split(',').map(str::trim) {
        let number = |t: &str| crate::cli::numbers::seed(t).map_err(|e| format!("seed \"{t}\": {e}"));
        let (from, to) = match part.split_once('-') {
            Some((a, b)) => (number(a)?, number(b)?),
            None => (number(part)?, number(part)?),
        };
        if from > to {
            return Err(format!("the range {part} runs backwards (write {to}-{from})"));
        }
        if to - from >= 100_000 {
            return Err(format!("the range {part} has more than 100000 seeds"));
        }
        for seed in from..=to {
            if seen.insert(seed) {
                seeds.push(seed);
            }
        }
    }
    Ok(Seeds(seeds))
}

/// Keeps a `--set` as written (it is passed on to every run) once it
/// parses.
fn checked_override(s: &str) -> Result<String, squall_topology::OverrideError> {
    super::parse_override(s).map(|_| s.to_string())
}

/// One log of the study, checked.
#[derive(Debug)]
struct Log {
    path: PathBuf,
    /// The file name without `.clf` / `.clf.gz`: names its runs' folders.
    stem: String,
    /// Its sibling relations, when there are some.
    relations: Option<Vec<Relation>>,
    /// The true trajectory, for simulated worlds.
    ground_truth: Option<Trajectory>,
}

/// Runs `squall study`.
pub(super) fn study(args: &StudyArgs) -> ExitCode {
    let threads = args.jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if !args.maps.is_empty() {
        return localization::study(&localization::Plan {
            maps: args.maps.clone(),
            sensors: args.inputs.clone(),
            modes: args.modes.clone(),
            seeds: args.seeds.clone(),
            duration: args.duration,
            kidnap_at: args.kidnap_at,
            overrides: args.overrides.clone(),
            jobs: threads,
            out: args.out.clone(),
        });
    }
    let simulated = match worlds::plan(&args.sim_worlds, &args.odometry, args.sim_duration) {
        Ok(plan) => plan,
        Err(message) => {
            eprintln!("error: {message}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let mut logs = match validate(args, &simulated) {
        Ok(logs) => logs,
        Err(message) => {
            eprintln!("error: {message}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    for world in &simulated {
        let written = worlds::write(world, args.sim_duration, &args.out).and_then(|path| {
            let relations = read_relations(&relations_of(&path)).map_err(|e| e.to_string())?;
            let truth = path.with_file_name("ground_truth.tum");
            let truth = Trajectory::read_tum(&truth).map_err(|e| e.to_string())?;
            Ok(Log { path, stem: world.name.clone(), relations: Some(relations), ground_truth: Some(truth) })
        });
        match written {
            Ok(log) => logs.push(log),
            // Stopped while simulating: the runs are marked not started.
            Err(_) if super::signals::stopping() => break,
            Err(message) => {
                eprintln!("error: {message}");
                return ExitCode::from(EXIT_FAILED);
            }
        }
    }
    let jobs: Vec<Job> = logs
        .iter()
        .enumerate()
        .flat_map(|(l, log)| args.seeds.0.iter().map(move |&seed| (l, log, seed)))
        .map(|(l, log, seed)| Job {
            log: l,
            seed,
            dir: args.out.join("runs").join(format!("{}-s{seed}", log.stem)),
            args: slam_args(args, &log.path, seed),
        })
        .collect();
    let odometry: Vec<Option<Accuracy>> =
        logs.iter().map(|log| score::odometry(log, args.max_scans)).collect();
    let rows = run_all(&jobs, &logs, &odometry, threads);

    let summaries =
        report::summarize(&logs.iter().map(|l| l.path.clone()).collect::<Vec<_>>(), &rows, &odometry);
    let md = report::markdown(&command_line(), &summaries);
    out!("{md}");
    let written = write_atomic(&args.out.join("study.csv"), report::csv(&rows).as_bytes())
        .and_then(|()| write_atomic(&args.out.join("study.md"), md.as_bytes()))
        .and_then(|()| write_atomic(&args.out.join("study.svg"), svg::plot(&summaries, &rows).as_bytes()));
    if let Err(e) = written {
        eprintln!("error: cannot write to {}: {e}", args.out.display());
        return ExitCode::from(EXIT_FAILED);
    }
    let stopped = rows.iter().filter(|r| r.status == Status::Stopped).count();
    if stopped > 0 || super::signals::stopping() {
        eprintln!(
            "error: the study was stopped (Ctrl-C or SIGTERM): {stopped} of {} runs stopped early or not \
             started (study.csv marks them)",
            rows.len()
        );
        return ExitCode::from(EXIT_FAILED);
    }
    let failed = rows.iter().filter(|r| r.status == Status::Failed).count();
    if failed > 0 {
        eprintln!("error: {failed} of {} runs failed (see study.csv and runs/*/stderr.log)", rows.len());
        return ExitCode::from(EXIT_FAILED);
    }
    ExitCode::SUCCESS
}

/// Checks every input before anything runs: the logs exist and their
/// folder names differ, their relations parse, the SLAM topology with
/// these settings is valid, and the output folder is writable.
fn validate(args: &StudyArgs, simulated: &[worlds::World]) -> Result<Vec<Log>, String> {
    if args.seeds.0.is_empty() {
        return Err("--seeds gives no seed".into());
    }
    let mut logs: Vec<Log> = Vec::new();
    for path in &args.logs {
        if !path.is_file() {
            return Err(format!("{}: no such log file", path.display()));
        }
        let stem = stem(path);
        if let Some(other) = logs.iter().find(|l| l.stem == stem) {
            return Err(format!(
                "{} and {} would share the run folders runs/{stem}-s*: rename one",
                other.path.display(),
                path.display()
            ));
        }
        let sibling = relations_of(path);
        let relations = match sibling.is_file() {
            true => Some(read_relations(&sibling).map_err(|e| e.to_string())?),
            false => None,
        };
        logs.push(Log { path: path.clone(), stem, relations, ground_truth: None });
    }
    if let Some(w) = simulated.iter().find(|w| logs.iter().any(|l| l.stem == w.name)) {
        return Err(format!(
            "the simulated world {} and a log would share the run folders runs/{}-s*",
            w.name, w.name
        ));
    }
    // The settings are checked against every log, and against a CARMEN
    // log for the simulated worlds (which do not exist yet).
    let placeholder = simulated.first().map(|w| PathBuf::from(format!("{}.clf", w.name)));
    for path in logs.iter().map(|l| &l.path).chain(placeholder.as_ref()) {
        let overrides = args.overrides.iter().map(|s| s.parse()).collect::<Result<Vec<_>, _>>();
        let slam = SlamArgs {
            log: Some(path.clone()),
            particles: args.particles,
            cutoff: args.cutoff.clone(),
            matchers: 1,
            max_scans: args.max_scans,
            seed: args.seeds.0.first().copied(),
            topology: None,
            overrides: overrides.map_err(|e: squall_topology::OverrideError| e.to_string())?,
            out: args.out.clone(),
            quiet: true,
            cluster: None,
            watch: Default::default(),
        };
        // Prints the topology's problems itself.
        super::slam::topology(&slam).map_err(|_| "the SLAM settings are invalid (see above)".to_string())?;
    }
    writable(&args.out)?;
    Ok(logs)
}

/// Creates `dir` if needed and checks that a file can be written in it.
fn writable(dir: &Path) -> Result<(), String> {
    let probe = dir.join(format!(".study-probe-{}", std::process::id()));
    std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::write(&probe, b""))
        .and_then(|()| std::fs::remove_file(&probe))
        .map_err(|e| format!("{}: the output folder is not writable: {e}", dir.display()))
}

/// `aces` for `data/aces.clf` or `data/aces.clf.gz`.
fn stem(path: &Path) -> String {
    let name = path.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    [".clf.gz", ".clf", ".gz", ".mcap"]
        .iter()
        .find_map(|ext| name.strip_suffix(ext))
        .unwrap_or(&name)
        .to_string()
}

/// `X.relations` beside `X.clf`.
fn relations_of(log: &Path) -> PathBuf {
    log.with_file_name(format!("{}.relations", stem(log)))
}

/// The arguments of one run's `squall slam`.
fn slam_args(args: &StudyArgs, log: &Path, seed: u64) -> Vec<OsString> {
    let mut v: Vec<OsString> =
        vec!["slam".into(), "--log".into(), log.into(), "--seed".into(), seed.to_string().into()];
    let mut flag = |name: &str, value: String| {
        v.push(name.into());
        v.push(value.into());
    };
    if let Some(p) = args.particles {
        flag("--particles", p.to_string());
    }
    if let Some(c) = &args.cutoff {
        flag("--cutoff", c.clone());
    }
    if let Some(m) = args.max_scans {
        flag("--max-scans", m.to_string());
    }
    for s in &args.overrides {
        flag("--set", s.clone());
    }
    v
}

/// Runs every job on `threads` threads, each waiting on one child at a
/// time, while this thread turns each finished run into its row and the
/// line to print (`finish`, which may also set the bar's message) and
/// counts it on the progress bar; returns the rows in the jobs' order.
fn run_pool<R>(
    jobs: &[&Job],
    threads: usize,
    mut finish: impl FnMut(usize, Result<Measured, String>, &ProgressBar) -> (R, String),
) -> Vec<R> {
    let bar = progress_bar(jobs.len() as u64);
    let next = Mutex::new(0usize);
    let (done, finished) = mpsc::channel::<(usize, Result<Measured, String>)>();
    let mut rows: Vec<Option<R>> = (0..jobs.len()).map(|_| None).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads.min(jobs.len()) {
            let done = done.clone();
            let next = &next;
            scope.spawn(move || {
                loop {
                    let i = {
                        let mut n = next.lock().unwrap_or_else(|e| e.into_inner());
                        *n += 1;
                        *n - 1
                    };
                    let Some(job) = jobs.get(i) else { break };
                    if done.send((i, runner::run(job))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(done);
        for (i, outcome) in finished {
            let (row, line) = finish(i, outcome, &bar);
            if bar.is_hidden() {
                eprintln!("{line}");
            } else {
                bar.println(line);
            }
            bar.inc(1);
            rows[i] = Some(row);
        }
    });
    bar.finish_and_clear();
    rows.into_iter().map(|r| r.expect("every job reports once")).collect()
}

/// Runs every (log, seed) job; returns the rows in the jobs' order.
fn run_all(jobs: &[Job], logs: &[Log], odometry: &[Option<Accuracy>], threads: usize) -> Vec<Row> {
    let mut worst = f64::NAN;
    let refs: Vec<&Job> = jobs.iter().collect();
    run_pool(&refs, threads, |i, outcome, bar| {
        let job = &jobs[i];
        let log = &logs[job.log];
        let row = row_of(job, log, odometry[job.log], outcome);
        if let Some(e) = row.accuracy.map(|a| a.trans_m) {
            worst = worst.max(e);
        }
        let line = match (&row.status, row.accuracy) {
            (Status::Failed, _) => format!("{}: failed: {}", job.dir.display(), row.error),
            (Status::Stopped, _) => format!("{}: stopped: {}", job.dir.display(), row.error),
            (Status::Ok, Some(a)) => format!("{}: {:.4} m", job.dir.display(), a.trans_m),
            (Status::Ok, None) => format!("{}: ok (no relations)", job.dir.display()),
        };
        if worst.is_finite() {
            bar.set_message(format!("worst {worst:.4} m"));
        }
        (row, line)
    })
}

/// Counts finished runs on stderr when it is a terminal; hidden otherwise.
fn progress_bar(total: u64) -> ProgressBar {
    let target = match std::io::stderr().is_terminal() {
        true => ProgressDrawTarget::stderr_with_hz(10),
        false => ProgressDrawTarget::hidden(),
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} runs ({msg}, eta {eta})",
        )
        .expect("valid template"),
    );
    bar.set_message("no error yet");
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    bar
}

/// The row of a finished run: failed if it did not exit 0 or left no
/// trajectory; otherwise scored on the log's relations.
fn row_of(job: &Job, log: &Log, odometry: Option<Accuracy>, outcome: Result<Measured, String>) -> Row {
    let mut row = Row {
        log: log.path.display().to_string(),
        seed: job.seed,
        status: Status::Failed,
        error: String::new(),
        accuracy: None,
        ate_m: None,
        odometry,
        measured: None,
    };
    let measured = match outcome {
        Ok(m) => m,
        Err(e) => {
            if e == runner::NOT_STARTED {
                row.status = Status::Stopped;
            }
            row.error = e;
            return row;
        }
    };
    row.measured = Some(measured.clone());
    if measured.stopped {
        // Part of the log at most: never scored, never "ok".
        row.status = Status::Stopped;
        row.error = measured.failure.unwrap_or_else(|| "stopped early (Ctrl-C or SIGTERM)".into());
        return row;
    }
    if let Some(e) = measured.failure {
        row.error = e;
        return row;
    }
    match score::run(&job.dir.join("trajectory.tum"), log.relations.as_deref(), log.ground_truth.as_ref()) {
        Ok(scored) => {
            row.status = Status::Ok;
            row.accuracy = scored.accuracy;
            row.ate_m = scored.ate_m;
        }
        Err(e) => row.error = e,
    }
    row
}

/// This process's command line as `squall ...`, quoted where a shell
/// would need it.
fn command_line() -> String {
    std::iter::once("squall".to_string())
        .chain(std::env::args().skip(1))
        .map(|a| match a.is_empty() || a.contains(|c: char| c.is_whitespace() || "'\"$\\".contains(c)) {
            true => format!("'{}'", a.replace('\'', r"'\''")),
            false => a,
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_lists_take_ranges_single_seeds_and_mixes() {
        assert_eq!(parse_seeds("1-10").unwrap().0, (1..=10).collect::<Vec<_>>());
        assert_eq!(parse_seeds("1,2,5").unwrap().0, vec![1, 2, 5]);
        assert_eq!(parse_seeds("7, 1-3,2").unwrap().0, vec![7, 1, 2, 3]);
        assert_eq!(parse_seeds("4-4").unwrap().0, vec![4]);
    }

    #[test]
    fn seed_lists_that_run_backwards_or_are_not_numbers_are_refused() {
        assert!(parse_seeds("3-1").unwrap_err().contains("backwards"));
        for bad in ["", "a", "1-", "-1", "1,,2", "1.5", "1-2-3"] {
            assert!(parse_seeds(bad).is_err(), "{bad:?} was accepted");
        }
    }

    #[test]
    fn a_log_names_its_relations_and_run_folders_without_its_extension() {
        assert_eq!(stem(Path::new("d/aces.clf.gz")), "aces");
        assert_eq!(relations_of(Path::new("d/aces.clf")), Path::new("d/aces.relations"));
    }
}
