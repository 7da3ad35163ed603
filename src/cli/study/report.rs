//! The study's tables: one CSV row per run (`study.csv`) and a Markdown
//! summary per log (`study.md`, also printed).

use std::fmt::Write as _;
use std::path::PathBuf;

use super::runner::Measured;
use super::score::Accuracy;

/// Whether a run finished (whatever its accuracy).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Status {
    /// It exited 0 and left a trajectory.
    Ok,
    /// It exited otherwise, or left no usable trajectory.
    Failed,
    /// The study was stopped (Ctrl-C or SIGTERM) while it ran or before
    /// it started: it covers part of its log, or none, and is not scored.
    Stopped,
}

/// One (log, seed).
#[derive(Debug, Clone)]
pub(super) struct Row {
    /// The log as given on the command line.
    pub(super) log: String,
    pub(super) seed: u64,
    pub(super) status: Status,
    /// Why it failed; empty when it did not.
    pub(super) error: String,
    /// `None` when the run failed, or the log has no (matching) relations.
    pub(super) accuracy: Option<Accuracy>,
    /// Absolute trajectory error against the ground truth, m (simulated
    /// worlds).
    pub(super) ate_m: Option<f64>,
    /// The log's raw odometry, scored the same way.
    pub(super) odometry: Option<Accuracy>,
    /// `None` when the run could not start.
    pub(super) measured: Option<Measured>,
}

impl Row {
    /// Whether SLAM did worse than the raw odometry (translational mean
    /// error); `None` when either is not scored.
    pub(super) fn worse_than_odometry(&self) -> Option<bool> {
        Some(self.accuracy?.trans_m > self.odometry?.trans_m)
    }
}

/// The figures of one log over its seeds.
#[derive(Debug, Clone)]
pub(super) struct Summary {
    /// The log as given on the command line.
    pub(super) log: String,
    /// Runs of this log (one per seed), failed ones included.
    pub(super) runs: usize,
    pub(super) failures: usize,
    /// Runs stopped early or never started (the study was stopped).
    pub(super) stopped: usize,
    /// Translational errors of the scored runs, ascending.
    pub(super) errors_m: Vec<f64>,
    pub(super) median_span_0_10_m: Option<f64>,
    pub(super) odometry: Option<Accuracy>,
    pub(super) worse_than_odometry: usize,
    pub(super) median_cpu_secs: Option<f64>,
    pub(super) max_cpu_secs: Option<f64>,
    pub(super) max_peak_rss_mb: Option<f64>,
}

impl Summary {
    /// The median translational error of the scored runs, m.
    pub(super) fn median_m(&self) -> Option<f64> {
        median(&self.errors_m)
    }

    /// The largest translational error of the scored runs, m.
    pub(super) fn worst_m(&self) -> Option<f64> {
        self.errors_m.last().copied()
    }
}

/// The median of `values` (sorted here), `None` when empty.
pub(super) fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some((v[n / 2 - 1] + v[n / 2]) / 2.0),
    }
}

fn max(values: impl Iterator<Item = f64>) -> Option<f64> {
    values.fold(None, |m, v| Some(m.map_or(v, |m: f64| m.max(v))))
}

/// One summary per log, in the order of `logs`.
pub(super) fn summarize(logs: &[PathBuf], rows: &[Row], odometry: &[Option<Accuracy>]) -> Vec<Summary> {
    logs.iter()
        .zip(odometry)
        .map(|(path, &odometry)| {
            let log = path.display().to_string();
            let mine: Vec<&Row> = rows.iter().filter(|r| r.log == log).collect();
            let mut errors_m: Vec<f64> = mine.iter().filter_map(|r| r.accuracy.map(|a| a.trans_m)).collect();
            errors_m.sort_by(f64::total_cmp);
            let spans: Vec<f64> = mine.iter().filter_map(|r| r.accuracy?.span_0_10_m).collect();
            let cpu: Vec<f64> = mine.iter().filter_map(|r| r.measured.as_ref().map(|m| m.cpu_secs)).collect();
            Summary {
                log,
                runs: mine.len(),
                failures: mine.iter().filter(|r| r.status == Status::Failed).count(),
                stopped: mine.iter().filter(|r| r.status == Status::Stopped).count(),
                errors_m,
                median_span_0_10_m: median(&spans),
                odometry,
                worse_than_odometry: mine.iter().filter(|r| r.worse_than_odometry() == Some(true)).count(),
                median_cpu_secs: median(&cpu),
                max_cpu_secs: max(cpu.iter().copied()),
                max_peak_rss_mb: max(mine.iter().filter_map(|r| r.measured.as_ref().map(|m| m.peak_rss_mb))),
            }
        })
        .collect()
}

/// A CSV field, quoted when it holds a comma, a quote or a line break
/// (RFC 4180: quotes inside are doubled).
pub(super) fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

fn number(v: Option<f64>, decimals: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.decimals$}"))
}

/// `study.csv`: one row per run, in the order the runs were listed.
pub(super) fn csv(rows: &[Row]) -> String {
    let mut t = String::from(
        "log,seed,status,error,trans_error_m,rot_error_deg,span_0_10_m,odometry_trans_error_m,\
         odometry_span_0_10_m,worse_than_odometry,cpu_secs,peak_rss_mb,wall_secs,ate_m\n",
    );
    for r in rows {
        let m = r.measured.as_ref();
        let fields = [
            csv_field(&r.log),
            r.seed.to_string(),
            match r.status {
                Status::Ok => "ok".into(),
                Status::Failed => "failed".into(),
                Status::Stopped => "stopped".into(),
            },
            csv_field(&r.error),
            number(r.accuracy.map(|a| a.trans_m), 6),
            number(r.accuracy.map(|a| a.rot_deg), 4),
            number(r.accuracy.and_then(|a| a.span_0_10_m), 6),
            number(r.odometry.map(|a| a.trans_m), 6),
            number(r.odometry.and_then(|a| a.span_0_10_m), 6),
            r.worse_than_odometry().map_or(String::new(), |b| b.to_string()),
            number(m.map(|m| m.cpu_secs), 3),
            number(m.map(|m| m.peak_rss_mb), 1),
            number(m.map(|m| m.wall_secs), 3),
            number(r.ate_m, 6),
        ];
        let _ = writeln!(t, "{}", fields.join(","));
    }
    t
}

/// `study.md`: what ran, with which squall and when, then one line per
/// log. Empty cells are figures that could not be measured.
pub(super) fn markdown(command: &str, summaries: &[Summary]) -> String {
    let mut t = String::from("# squall study\n\n");
    let _ = writeln!(t, "- command: `{command}`");
    let _ = writeln!(t, "- squall {}", env!("CARGO_PKG_VERSION"));
    let _ = writeln!(t, "- date: {} (UTC)", today_utc());
    let stopped: usize = summaries.iter().map(|s| s.stopped).sum();
    if stopped > 0 {
        let runs: usize = summaries.iter().map(|s| s.runs).sum();
        let _ = writeln!(
            t,
            "- **stopped** (Ctrl-C or SIGTERM): {stopped} of {runs} runs were stopped early or never \
             started, and are not scored; study.csv marks them"
        );
    }
    t.push('\n');
    t.push_str(
        "Translational errors in metres (relation metric); \"0–10 s\" is the error of the relations \
         spanning under 10 s; \"worse\" counts runs whose error exceeds the raw odometry's.\n\n",
    );
    t.push_str(
        "| log | runs | failed | median m | worst m | odometry m | median 0–10 s m | odometry 0–10 s m \
         | worse | median CPU s | max CPU s | max RSS MB |\n",
    );
    t.push_str("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|\n");
    for s in summaries {
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            s.log.replace('|', "\\|"),
            s.runs,
            s.failures,
            number(s.median_m(), 4),
            number(s.worst_m(), 4),
            number(s.odometry.map(|o| o.trans_m), 4),
            number(s.median_span_0_10_m, 4),
            number(s.odometry.and_then(|o| o.span_0_10_m), 4),
            s.worse_than_odometry,
            number(s.median_cpu_secs, 2),
            number(s.max_cpu_secs, 2),
            number(s.max_peak_rss_mb, 0),
        );
    }
    t
}

/// Today's date, `YYYY-MM-DD`, from the system clock.
fn today_utc() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (Howard
/// Hinnant's `civil_from_days`).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_with_commas_quotes_or_line_breaks_are_quoted() {
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(csv_field("a.clf:1: 3 fields, found 2"), "\"a.clf:1: 3 fields, found 2\"");
        assert_eq!(csv_field("found \"x\""), "\"found \"\"x\"\"\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
        assert_eq!(csv_field(""), "");
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn day_counts_become_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(20_000), (2024, 10, 4));
    }
}
