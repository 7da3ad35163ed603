//! `squall study --maps`: how robust is localization on these buildings?
//! Runs `squall localize --sim` for every (map, sensor, mode, seed) as its
//! own process, as many at once as `--jobs`, and reports per (map,
//! sensor, mode) how many runs succeeded, the median and worst of their
//! errors and of their times, and their CPU.
//!
//! The modes, each scored in the map frame against the simulator's truth
//! (`metrics.json`, `localization`):
//!
//! - `tracking`: from the true start; succeeds when every pose is within
//!   0.2 m and 5° of the truth.
//! - `global`: from anywhere (`--init global`); succeeds when it converges
//!   within [`GLOBAL_WITHIN_S`] and stays.
//! - `kidnap`: tracked from the true start, then carried 5–20 m at
//!   `--kidnap-at`; succeeds when found again within [`KIDNAP_WITHIN_S`]
//!   and kept.

use squall_core::depth_render::DepthCamera;
use squall_core::eval::lookalike::{self, Fan, Lookalike};
use squall_core::eval::map_frame::wrong_at;
use squall_core::linemap::LineMap;
use squall_core::trajectory::Trajectory;
use squall_spouts::sim::SimConfig;
use squall_topology::fsio::write_atomic;
use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use super::report::median;
use super::runner::{Job, Measured};
use super::{EXIT_FAILED, EXIT_INVALID, Seeds, command_line, run_pool, writable};

/// A global start succeeds when it converges within this many seconds.
pub(super) const GLOBAL_WITHIN_S: f64 = 10.0;
/// A kidnapped robot succeeds when found again within this many seconds.
pub(super) const KIDNAP_WITHIN_S: f64 = 5.0;

/// What a localization run is asked to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum Mode {
    /// From the true start.
    Tracking,
    /// From anywhere on the map.
    Global,
    /// From the true start, then carried elsewhere.
    Kidnap,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Tracking => "tracking",
            Mode::Global => "global",
            Mode::Kidnap => "kidnap",
        }
    }
}

/// The simulated sensor of a localization run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum Sensor {
    /// The 180° laser.
    Laser,
    /// The depth camera, plane filtered.
    Depth,
}

impl Sensor {
    fn name(self) -> &'static str {
        match self {
            Sensor::Laser => "laser",
            Sensor::Depth => "depth",
        }
    }
}

/// The localization study's settings, checked.
#[derive(Debug)]
pub(super) struct Plan {
    pub(super) maps: Vec<PathBuf>,
    pub(super) sensors: Vec<Sensor>,
    pub(super) modes: Vec<Mode>,
    pub(super) seeds: Seeds,
    /// Simulated seconds per run.
    pub(super) duration: f64,
    /// When kidnap runs are carried, seconds.
    pub(super) kidnap_at: f64,
    /// `--set` values passed on to every run.
    pub(super) overrides: Vec<String>,
    pub(super) jobs: usize,
    pub(super) out: PathBuf,
}

/// One (map, sensor, mode) of the study.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Cell {
    map: usize,
    sensor: Sensor,
    mode: Mode,
}

/// What one run's `metrics.json` says (`localization`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Scored {
    mean_m: f64,
    max_m: f64,
    within_share: f64,
    converged_after_s: Option<f64>,
    carry_m: Option<f64>,
    recovered_after_s: Option<f64>,
    /// The most the estimate's error exceeded raw odometry's, m.
    over_odometry_m: Option<f64>,
}

/// One run: its cell, seed, and what came of it.
#[derive(Debug, Clone)]
struct Row {
    cell: Cell,
    seed: u64,
    /// Why it failed to run; empty when it ran.
    error: String,
    scored: Option<Scored>,
    measured: Option<Measured>,
    /// For a missed global start or kidnapping: whether the place it
    /// settled in looked, to the sensor, like the robot's.
    lookalike: Option<Lookalike>,
}

impl Row {
    /// The time the mode is judged by: to convergence (global), to
    /// recovery (kidnap); `None` for tracking, or when it never came.
    fn time_s(&self) -> Option<f64> {
        let s = self.scored?;
        match self.cell.mode {
            Mode::Tracking => None,
            Mode::Global => s.converged_after_s,
            Mode::Kidnap => s.recovered_after_s,
        }
    }

    /// Whether the run did what its mode asks (see the module's doc).
    fn success(&self) -> bool {
        let Some(s) = self.scored else { return false };
        match self.cell.mode {
            Mode::Tracking => s.converged_after_s == Some(0.0),
            Mode::Global => s.converged_after_s.is_some_and(|t| t <= GLOBAL_WITHIN_S),
            Mode::Kidnap => s.recovered_after_s.is_some_and(|t| t <= KIDNAP_WITHIN_S),
        }
    }
}

/// Checks the maps (they exist and parse, their names differ) and the
/// times; the output folder is then made writable.
pub(super) fn check(plan: &Plan) -> Result<(), String> {
    if plan.seeds.0.is_empty() {
        return Err("--seeds gives no seed".into());
    }
    if !(plan.duration.is_finite() && plan.duration > 0.0) {
        return Err(format!("--duration must be > 0 seconds, got {}", plan.duration));
    }
    if plan.modes.contains(&Mode::Kidnap) && !(plan.kidnap_at >= 0.0 && plan.kidnap_at < plan.duration) {
        return Err(format!(
            "--kidnap-at must lie within the run (0 ≤ {} < --duration {})",
            plan.kidnap_at, plan.duration
        ));
    }
    for (i, map) in plan.maps.iter().enumerate() {
        squall_core::linemap::LineMap::load(map).map_err(|e| e.to_string())?;
        if let Some(other) = plan.maps[..i].iter().find(|m| name(m) == name(map)) {
            return Err(format!(
                "{} and {} would share the run folders runs/{}-*: rename one",
                other.display(),
                map.display(),
                name(map)
            ));
        }
    }
    writable(&plan.out)
}

/// `CVAP7` for `maps/CVAP7_vector.txt`: the file name without `.txt` and
/// without the shared maps' `_vector`.
fn name(map: &Path) -> String {
    let stem = map.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    stem.strip_suffix("_vector").unwrap_or(&stem).to_string()
}

/// The arguments of one run's `squall localize` (`--out` is the runner's).
fn localize_args(plan: &Plan, cell: Cell, seed: u64) -> Vec<OsString> {
    let mut v: Vec<OsString> = vec![
        "localize".into(),
        "--map".into(),
        plan.maps[cell.map].clone().into(),
        "--sim".into(),
        "--input".into(),
        cell.sensor.name().into(),
        "--duration".into(),
        plan.duration.to_string().into(),
        "--seed".into(),
        seed.to_string().into(),
        "--init".into(),
        if cell.mode == Mode::Global { "global" } else { "known" }.into(),
    ];
    if cell.mode == Mode::Kidnap {
        v.extend(["--kidnap-at".into(), plan.kidnap_at.to_string().into()]);
    }
    for s in &plan.overrides {
        v.extend(["--set".into(), s.into()]);
    }
    v
}

/// Runs the localization study: every run, then study.csv and study.md
/// (printed too). Exit 1 when a run failed to run (not when it failed to
/// localize: that is a result).
pub(super) fn study(plan: &Plan) -> ExitCode {
    if let Err(message) = check(plan) {
        eprintln!("error: {message}");
        return ExitCode::from(EXIT_INVALID);
    }
    let cells: Vec<Cell> = (0..plan.maps.len())
        .flat_map(|map| {
            plan.sensors
                .iter()
                .flat_map(move |&sensor| plan.modes.iter().map(move |&mode| Cell { map, sensor, mode }))
        })
        .collect();
    let jobs: Vec<(Cell, Job)> = cells
        .iter()
        .flat_map(|&cell| plan.seeds.0.iter().map(move |&seed| (cell, seed)))
        .map(|(cell, seed)| {
            let folder =
                format!("{}-{}-{}-s{seed}", name(&plan.maps[cell.map]), cell.sensor.name(), cell.mode.name());
            let job = Job {
                log: cell.map,
                seed,
                dir: plan.out.join("runs").join(folder),
                args: localize_args(plan, cell, seed),
            };
            (cell, job)
        })
        .collect();
    let rows = run_all(plan, &jobs);
    let md = markdown(plan, &cells, &rows);
    out!("{md}");
    let written = write_atomic(&plan.out.join("study.csv"), csv(plan, &rows).as_bytes())
        .and_then(|()| write_atomic(&plan.out.join("study.md"), md.as_bytes()));
    if let Err(e) = written {
        eprintln!("error: cannot write to {}: {e}", plan.out.display());
        return ExitCode::from(EXIT_FAILED);
    }
    let failed = rows.iter().filter(|r| !r.error.is_empty()).count();
    if crate::cli::signals::stopping() {
        eprintln!("error: the study was stopped (Ctrl-C or SIGTERM): study.csv marks the runs it cut short");
        return ExitCode::from(EXIT_FAILED);
    }
    if failed > 0 {
        eprintln!(
            "error: {failed} of {} runs failed to run (see study.csv and runs/*/stderr.log)",
            rows.len()
        );
        return ExitCode::from(EXIT_FAILED);
    }
    ExitCode::SUCCESS
}

/// Runs every job, `threads` at once; returns the rows in the jobs'
/// order.
fn run_all(plan: &Plan, jobs: &[(Cell, Job)]) -> Vec<Row> {
    let mut succeeded = 0;
    let refs: Vec<&Job> = jobs.iter().map(|(_, job)| job).collect();
    run_pool(&refs, plan.jobs, |i, outcome, bar| {
        let (cell, job) = &jobs[i];
        let mut row = row_of(*cell, job, outcome);
        match lookalike_of(plan, &row, &job.dir) {
            Ok(l) => row.lookalike = l,
            Err(e) => row.error = format!("the look-alike test: {e}"),
        }
        succeeded += usize::from(row.success());
        let line = match (&row.error, row.scored) {
            (e, _) if !e.is_empty() => format!("{}: failed: {e}", job.dir.display()),
            (_, Some(s)) => format!(
                "{}: {} (mean {:.3} m{}){}",
                job.dir.display(),
                if row.success() { "ok" } else { "missed" },
                s.mean_m,
                row.time_s().map_or(String::new(), |t| format!(", {t:.1} s")),
                if row.lookalike.is_some_and(|l| l.is_lookalike()) { ", a look-alike place" } else { "" },
            ),
            (_, None) => format!("{}: no score", job.dir.display()),
        };
        bar.set_message(format!("{succeeded} succeeded"));
        (row, line)
    })
}

/// The row of a finished run, scored from its `metrics.json`.
fn row_of(cell: Cell, job: &Job, outcome: Result<Measured, String>) -> Row {
    let mut row =
        Row { cell, seed: job.seed, error: String::new(), scored: None, measured: None, lookalike: None };
    match outcome {
        Err(e) => row.error = e,
        Ok(m) => {
            if m.stopped {
                // Part of the run at most: never scored, never a success.
                row.error = m.failure.clone().unwrap_or_else(|| "stopped early (Ctrl-C or SIGTERM)".into());
            } else if let Some(e) = &m.failure {
                row.error.clone_from(e);
            } else {
                match read_score(&job.dir.join("metrics.json")) {
                    Ok(s) => row.scored = Some(s),
                    Err(e) => row.error = e,
                }
            }
            row.measured = Some(m);
        }
    }
    row
}

/// The look-alike test of a missed global start or kidnapping
/// ([`lookalike`]): over the frames from the start (global) or the carry
/// (kidnap) to the time the estimate was wrong (the end of the time the
/// mode allows, or the last wrong pose after it for a run that did not
/// stay), did what the sensor would see from the truth and from the
/// estimate's place differ? `None` for runs it does not apply to.
fn lookalike_of(plan: &Plan, row: &Row, dir: &Path) -> Result<Option<Lookalike>, String> {
    let (from, within) = match row.cell.mode {
        _ if row.success() || row.scored.is_none() => return Ok(None),
        Mode::Tracking => return Ok(None),
        Mode::Global => (0.0, GLOBAL_WITHIN_S),
        Mode::Kidnap => (plan.kidnap_at, KIDNAP_WITHIN_S),
    };
    let read = |file: &str| Trajectory::read_tum(&dir.join(file)).map_err(|e| e.to_string());
    let (estimate, truth) = (read("trajectory.tum")?, read("ground_truth.tum")?);
    let Some(to) = wrong_at(&estimate, &truth, from + within) else { return Ok(None) };
    let map = LineMap::load(&plan.maps[row.cell.map]).map_err(|e| e.to_string())?;
    Ok(lookalike::compare(&map, &fan(row.cell.sensor), &estimate, &truth, from, to))
}

/// The simulated sensor's rays, as `squall localize --sim` sets it up.
fn fan(sensor: Sensor) -> Fan {
    match sensor {
        Sensor::Laser => {
            let c = SimConfig::default();
            Fan::even(c.fov, c.beams, crate::cli::localize::RANGE_MAX, c.range_noise, 0.0)
        }
        Sensor::Depth => {
            let camera = DepthCamera::d435_on_robot();
            let fov = 2.0 * (camera.width as f64 / 2.0 / camera.intrinsics.fx).atan();
            // A ray a degree.
            let rays = fov.to_degrees().round() as usize + 1;
            Fan::even(fov, rays, camera.noise.max_range, 0.0, camera.noise.sigma_per_z2)
        }
    }
}

/// The `localization` figures of a run's metrics.json.
fn read_score(path: &Path) -> Result<Scored, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let l = json.get("localization").ok_or_else(|| format!("{}: no localization score", path.display()))?;
    let number = |v: &serde_json::Value, key: &str| v.get(key).and_then(serde_json::Value::as_f64);
    let required =
        |key: &str| number(l, key).ok_or_else(|| format!("{}: no localization.{key}", path.display()));
    let kidnap = l.get("kidnap");
    Ok(Scored {
        mean_m: required("map_mean_m")?,
        max_m: required("map_max_m")?,
        within_share: required("map_within_share")?,
        converged_after_s: number(l, "converged_after_s"),
        carry_m: kidnap.and_then(|k| number(k, "carry_m")),
        recovered_after_s: kidnap.and_then(|k| number(k, "recovered_after_s")),
        over_odometry_m: number(l, "worst_over_odometry_m"),
    })
}

/// One line per run.
fn csv(plan: &Plan, rows: &[Row]) -> String {
    let mut out = String::from(
        "map,sensor,mode,seed,success,mean_m,max_m,within_share,converged_after_s,carry_m,recovered_after_s,over_odometry_m,lookalike,wrong_at_s,wrong_by_m,telling_frames,frames,cpu_s,peak_rss_mb,error\n",
    );
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for r in rows {
        let (s, l) = (r.scored, r.lookalike);
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},\"{}\"",
            name(&plan.maps[r.cell.map]),
            r.cell.sensor.name(),
            r.cell.mode.name(),
            r.seed,
            r.success(),
            opt(s.map(|s| s.mean_m)),
            opt(s.map(|s| s.max_m)),
            opt(s.map(|s| s.within_share)),
            opt(s.and_then(|s| s.converged_after_s)),
            opt(s.and_then(|s| s.carry_m)),
            opt(s.and_then(|s| s.recovered_after_s)),
            opt(s.and_then(|s| s.over_odometry_m)),
            l.map_or(String::new(), |l| l.is_lookalike().to_string()),
            opt(l.map(|l| l.at)),
            opt(l.map(|l| l.distance_m)),
            l.map_or(String::new(), |l| l.telling_frames.to_string()),
            l.map_or(String::new(), |l| l.frames.to_string()),
            opt(r.measured.as_ref().map(|m| m.cpu_secs)),
            opt(r.measured.as_ref().map(|m| m.peak_rss_mb)),
            r.error.replace('"', "'"),
        );
    }
    out
}

/// The summary: one table row per (map, sensor, mode).
fn markdown(plan: &Plan, cells: &[Cell], rows: &[Row]) -> String {
    let mut md = format!("# Localization study\n\n`{}`\n\n", command_line());
    let _ = writeln!(
        md,
        "Success: tracking, every pose within 0.2 m and 5°; global, converged within {GLOBAL_WITHIN_S} s and \
         stayed; kidnap (carried 5–20 m at {} s), found again within {KIDNAP_WITHIN_S} s and kept. Errors are \
         each run's mean position error in the map frame; times are to convergence (global) or recovery \
         (kidnap), over the runs that got there. Worse than odometry: the largest amount by which a run's \
         position error exceeded the raw odometry's (started at the true start) at any pose. A miss marked \
         look-alike settled in a place the sensor could not tell from the robot's: from the start or the \
         carry until the estimate was wrong, no frame's view of the map (its rays cast from the true path \
         and from the same path carried onto the estimate) differed beyond the sensor's noise.\n",
        plan.kidnap_at
    );
    md.push_str("| map | sensor | mode | success | mean error median / worst (m) | time median / worst (s) | worse than odometry by, median / worst (m) | CPU median / worst (s) | missed (seed: mean m) |\n");
    md.push_str("| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    let pair = |v: &[f64], digits: usize| match (median(v), v.iter().copied().reduce(f64::max)) {
        (Some(m), Some(w)) => format!("{m:.digits$} / {w:.digits$}"),
        _ => "–".to_string(),
    };
    for &cell in cells {
        let runs: Vec<&Row> = rows.iter().filter(|r| r.cell == cell).collect();
        let ok = runs.iter().filter(|r| r.success()).count();
        let errors: Vec<f64> = runs.iter().filter_map(|r| r.scored.map(|s| s.mean_m)).collect();
        let times: Vec<f64> = runs.iter().filter_map(|r| r.time_s()).collect();
        let cpu: Vec<f64> = runs.iter().filter_map(|r| r.measured.as_ref().map(|m| m.cpu_secs)).collect();
        let over: Vec<f64> = runs.iter().filter_map(|r| r.scored.and_then(|s| s.over_odometry_m)).collect();
        let missed: Vec<String> = runs
            .iter()
            .filter(|r| !r.success())
            .map(|r| match r.scored {
                Some(s) if r.lookalike.is_some_and(|l| l.is_lookalike()) => {
                    format!("{}: {:.2} (look-alike)", r.seed, s.mean_m)
                }
                Some(s) => format!("{}: {:.2}", r.seed, s.mean_m),
                None => format!("{}: failed", r.seed),
            })
            .collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} | {ok}/{} | {} | {} | {} | {} | {} |",
            name(&plan.maps[cell.map]),
            cell.sensor.name(),
            cell.mode.name(),
            runs.len(),
            pair(&errors, 3),
            if cell.mode == Mode::Tracking { "–".to_string() } else { pair(&times, 1) },
            if cell.mode == Mode::Kidnap { "–".to_string() } else { pair(&over, 3) },
            pair(&cpu, 1),
            if missed.is_empty() { "–".to_string() } else { missed.join(", ") },
        );
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(mode: Mode, scored: Scored) -> Row {
        let cell = Cell { map: 0, sensor: Sensor::Laser, mode };
        Row { cell, seed: 1, error: String::new(), scored: Some(scored), measured: None, lookalike: None }
    }

    #[test]
    fn each_mode_succeeds_by_its_own_measure() {
        let tracked = Scored { converged_after_s: Some(0.0), ..Scored::default() };
        assert!(row(Mode::Tracking, tracked).success());
        let late = Scored { converged_after_s: Some(0.1), ..Scored::default() };
        assert!(!row(Mode::Tracking, late).success(), "a tracking run off at any pose missed");
        assert!(row(Mode::Global, Scored { converged_after_s: Some(9.9), ..Scored::default() }).success());
        assert!(!row(Mode::Global, Scored { converged_after_s: Some(10.1), ..Scored::default() }).success());
        assert!(!row(Mode::Global, Scored::default()).success(), "never converged");
        let found =
            Scored { recovered_after_s: Some(4.0), converged_after_s: Some(12.0), ..Scored::default() };
        assert!(row(Mode::Kidnap, found).success());
        assert_eq!(row(Mode::Kidnap, found).time_s(), Some(4.0));
        assert!(!row(Mode::Kidnap, Scored { recovered_after_s: Some(6.0), ..Scored::default() }).success());
    }

    #[test]
    fn map_names_drop_the_shared_maps_suffix() {
        assert_eq!(name(Path::new("d/CVAP7_vector.txt")), "CVAP7");
        assert_eq!(name(Path::new("hall.txt")), "hall");
    }
}
