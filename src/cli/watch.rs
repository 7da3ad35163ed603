//! Watching a run while it goes, for `run`, `slam` and `localize`: the
//! live page and Prometheus endpoint (`--ui`), the Foxglove view, live
//! (`--foxglove`) and recorded (`--record`), `metrics.json` written
//! periodically (`--metrics-every`), and a run log at INFO saying what
//! each component is doing.

use std::net::{SocketAddr, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::bolts::view::{self, Recording};
use crate::ui::UiServer;
use squall_topology::live::{LiveSample, Sampler};
use squall_topology::{CustomMetric, LiveRun, RunReport, StopRequest};

/// How often the run log speaks.
const LOG_PERIOD: Duration = Duration::from_secs(5);
/// How often the Foxglove view gets every component's metrics.
const METRICS_PERIOD: Duration = Duration::from_secs(1);

/// The flags that watch a run.
#[derive(Debug, Clone, Default, clap::Args)]
pub(super) struct WatchArgs {
    /// Serve a live page of the run (the topology, and per component and
    /// task: rates, execute latency, queues, drops, busy time, errors) and
    /// its Prometheus metrics at /metrics, on HOST:PORT (e.g.
    /// 127.0.0.1:8080; port 0 picks a free one, printed at start).
    #[arg(long, value_name = "HOST:PORT", value_parser = parse_addr)]
    pub(super) ui: Option<SocketAddr>,
    /// Keep the live page and the Foxglove view up this many seconds
    /// after the run ends (Ctrl-C ends the wait).
    #[arg(long, value_name = "SECS", default_value_t = 0.0, value_parser = super::numbers::wait_secs)]
    pub(super) ui_linger: f64,
    /// Serve a live view for Foxglove (its WebSocket protocol) on
    /// HOST:PORT, e.g. 127.0.0.1:8765 (port 0 picks a free one): the map,
    /// scans, poses, particles and transforms of `slam` and `localize`,
    /// whatever a topology's `sink.foxglove` publishes, and every
    /// component's metrics each second.
    #[arg(long, value_name = "HOST:PORT", value_parser = parse_host_port)]
    pub(super) foxglove: Option<(String, u16)>,
    /// Record the same channels into an MCAP file that Foxglove opens
    /// (written atomically when the run ends).
    #[arg(long, value_name = "FILE.mcap")]
    pub(super) record: Option<PathBuf>,
    /// Also write metrics.json every SECS while the run goes (atomically,
    /// with "status": "running"); needs an output folder.
    #[arg(long, value_name = "SECS", value_parser = super::numbers::period_secs)]
    pub(super) metrics_every: Option<f64>,
    /// Serve --ui and --foxglove beyond loopback, without authentication
    /// (anyone who reaches them sees the run: its topology, counters,
    /// poses and maps): on a network you trust only. Warns at start and
    /// in metrics.json.
    #[arg(long)]
    pub(super) insecure: bool,
}

impl WatchArgs {
    /// Whether a Foxglove view is wanted (live or recorded): the built-in
    /// topologies then add their `sink.foxglove`.
    pub(super) fn viewed(&self) -> bool {
        self.foxglove.is_some() || self.record.is_some()
    }
}

/// A `sink.foxglove` bolt named `view` subscribed to `inputs`
/// (component, stream), with `params` (TOML inline-table entries), to
/// append to a built-in topology.
pub(super) fn view_bolt(inputs: &[(&str, &str)], params: &str) -> String {
    let inputs: Vec<String> = inputs
        .iter()
        .map(|(from, stream)| format!("  {{ from = \"{from}\", stream = \"{stream}\" }},"))
        .collect();
    format!(
        "\n[[bolt]]\nname = \"view\"\nkind = \"sink.foxglove\"\nparams = {{ {params} }}\ninputs = [\n{}\n]\n",
        inputs.join("\n")
    )
}

/// Checks before the run that `path` can be recorded into: its folder
/// exists and is writable, and it is not a folder.
fn check_recordable(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err(format!("--record {}: is a folder; give a file name, e.g. run.mcap", path.display()));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    squall_topology::fsio::check_writable_dir(dir)
        .map_err(|e| format!("--record {}: cannot write there: {e}", path.display()))
}

/// Whether `host` (an address or a name) is loopback: reachable from this
/// machine only. Other names may resolve to addresses others reach.
fn is_loopback_host(host: &str) -> bool {
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// The refusal of a view served beyond loopback without `--insecure`.
fn exposed_view(flag: &str, at: &str) -> String {
    format!(
        "{flag} {at}: beyond loopback, with no authentication: anyone who can reach it sees the run (its \
         topology, counters, poses and maps). Serve it on 127.0.0.1 and reach it through an SSH tunnel \
         (ssh -L), or, on a network you trust, pass --insecure"
    )
}

fn parse_addr(s: &str) -> Result<SocketAddr, String> {
    let mut addrs =
        s.to_socket_addrs().map_err(|e| format!("expected HOST:PORT, e.g. 127.0.0.1:8080 ({e})"))?;
    addrs.next().ok_or_else(|| format!("{s} names no address"))
}

fn parse_host_port(s: &str) -> Result<(String, u16), String> {
    let expected = || "expected HOST:PORT, e.g. 127.0.0.1:8765".to_string();
    let (host, port) = s.rsplit_once(':').ok_or_else(expected)?;
    let port = port.parse::<u16>().map_err(|_| expected())?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(expected());
    }
    Ok((host.to_string(), port))
}

/// What watches one run; [`finish`](Self::finish) it when the run has
/// ended.
pub(super) struct Watch {
    live: Option<Arc<LiveRun>>,
    ui: Option<UiServer>,
    foxglove: Option<foxglove::WebSocketServerHandle>,
    /// What the run's metrics should warn of (views served beyond
    /// loopback with `--insecure`).
    warnings: Vec<String>,
    recording: Option<Recording>,
    linger: Duration,
    stop: Option<mpsc::Sender<()>>,
    threads: Vec<JoinHandle<()>>,
}

impl Watch {
    /// Starts what `args` ask for; an address that cannot be served, or
    /// `--metrics-every` without an output folder, is an error (exit 2).
    pub(super) fn start(args: &WatchArgs, out: Option<&Path>) -> Result<Watch, String> {
        let logging = tracing::enabled!(tracing::Level::INFO);
        let viewed = args.viewed();
        let wanted = args.ui.is_some() || args.metrics_every.is_some() || logging || viewed;
        if args.ui_linger > 0.0 && args.ui.is_none() && args.foxglove.is_none() {
            return Err("--ui-linger keeps --ui or --foxglove up: give one of them".into());
        }
        if let Some(path) = &args.record {
            check_recordable(path)?;
        }
        let mut exposed = Vec::new();
        if let Some(addr) = args.ui.filter(|a| !a.ip().is_loopback()) {
            exposed.push(("--ui", addr.to_string()));
        }
        if let Some((host, port)) = args.foxglove.as_ref().filter(|(h, _)| !is_loopback_host(h)) {
            exposed.push(("--foxglove", format!("{host}:{port}")));
        }
        if let Some((flag, at)) = exposed.first()
            && !args.insecure
        {
            return Err(exposed_view(flag, at));
        }
        let warnings: Vec<String> = exposed
            .iter()
            .map(|(flag, at)| {
                format!("insecure: {flag} {at} serves the run beyond loopback without authentication")
            })
            .collect();
        for w in &warnings {
            eprintln!("warning: {w} (--insecure)");
        }
        let mut watch = Watch {
            warnings,
            live: wanted.then(LiveRun::new),
            ui: None,
            foxglove: None,
            recording: None,
            linger: Duration::from_secs_f64(args.ui_linger),
            stop: None,
            threads: Vec::new(),
        };
        let Some(live) = watch.live.clone() else { return Ok(watch) };
        if let Some(addr) = args.ui {
            let server = UiServer::start(addr, live.clone()).map_err(|e| format!("--ui {addr}: {e}"))?;
            eprintln!("live page: http://{}/ (Prometheus metrics at /metrics)", server.addr());
            watch.ui = Some(server);
        }
        if let Some((host, port)) = &args.foxglove {
            let server = view::serve(host, *port).map_err(|e| format!("--foxglove {host}:{port}: {e}"))?;
            eprintln!(
                "Foxglove live view: ws://{host}:{} (in Foxglove: Open connection, Foxglove WebSocket)",
                server.port()
            );
            watch.foxglove = Some(server);
        }
        if let Some(path) = &args.record {
            watch.recording = Some(Recording::start(path).map_err(|e| format!("--record {e}"))?);
        }
        let (stop, stopped) = mpsc::channel::<()>();
        let mut every: Vec<Periodic> = Vec::new();
        if let Some(secs) = args.metrics_every {
            let Some(dir) = out else {
                return Err("--metrics-every needs an output folder (--out) to write metrics.json in".into());
            };
            let dir = dir.to_path_buf();
            every.push(Periodic {
                period: Duration::from_secs_f64(secs),
                at_end: false,
                action: Box::new(move |s| write_running(&dir, &s.snapshot.report)),
            });
        }
        if viewed {
            every.push(Periodic {
                period: METRICS_PERIOD,
                at_end: true,
                action: Box::new(view::publish_metrics),
            });
        }
        if logging {
            every.push(Periodic {
                period: LOG_PERIOD,
                at_end: true,
                action: Box::new(|s| tracing::info!("{}", log_line(s))),
            });
        }
        if !every.is_empty() {
            watch.threads.push(std::thread::spawn(move || periodically(&live, &stopped, every)));
        }
        watch.stop = Some(stop);
        Ok(watch)
    }

    /// The run to hand to the runtime, when anything watches it.
    pub(super) fn live(&self) -> Option<Arc<LiveRun>> {
        self.live.clone()
    }

    /// What the run's metrics should warn of about how it was watched.
    pub(super) fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Stops the periodic writers (before the final metrics.json is
    /// written, which they must not overwrite) and finishes the
    /// recording; a recording that cannot be finished is the error.
    pub(super) fn run_ended(&mut self) -> Result<(), String> {
        self.stop.take();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        match self.recording.take() {
            Some(r) => r.finish().map_err(|e| format!("--record {e}")),
            None => Ok(()),
        }
    }

    /// Keeps the live page up for `--ui-linger` (or until Ctrl-C), then
    /// stops it.
    pub(super) fn finish(mut self, stop: &StopRequest) {
        if let Err(e) = self.run_ended() {
            eprintln!("error: {e}");
        }
        if self.ui.is_none() && self.foxglove.is_none() {
            return;
        }
        if !self.linger.is_zero() && !stop.is_made() {
            eprintln!("the live views stay up for {:.0} s (Ctrl-C ends them)", self.linger.as_secs_f64());
            let until = Instant::now() + self.linger;
            while Instant::now() < until && !stop.is_made() {
                std::thread::sleep(
                    Duration::from_millis(50).min(until.saturating_duration_since(Instant::now())),
                );
            }
        }
        if let Some(ui) = self.ui.take() {
            ui.stop();
        }
        if let Some(f) = self.foxglove.take() {
            let viewers = f.client_count();
            if !closed_within(f.stop(), VIEWER_CLOSE) {
                eprintln!(
                    "warning: Foxglove view: {viewers} viewer{} connected, and the close did not reach every \
                     one within {} s (a viewer that stopped reading): dropped",
                    if viewers == 1 { "" } else { "s" },
                    VIEWER_CLOSE.as_secs()
                );
            }
        }
    }
}

/// How long the Foxglove view's close may wait for its viewers to take
/// it: a viewer reading its socket takes it in milliseconds; one that
/// stopped reading never does, and is dropped rather than awaited.
const VIEWER_CLOSE: Duration = Duration::from_secs(2);

/// Waits up to `limit` for the Foxglove server's graceful shutdown;
/// past it the handle is dropped, which aborts the tasks of the viewers
/// still being closed. Whether every viewer was closed in time.
fn closed_within(handle: foxglove::websocket::ShutdownHandle, limit: Duration) -> bool {
    let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_time().build() else {
        // Without a timer, abort at once rather than risk waiting forever.
        drop(handle);
        return false;
    };
    // The timer is made inside the runtime, which it needs.
    rt.block_on(async move { tokio::time::timeout(limit, handle.wait()).await.is_ok() })
}

/// Something done with a sample of the run every `period`.
struct Periodic {
    period: Duration,
    /// Done once more when the run has ended.
    at_end: bool,
    action: Box<dyn FnMut(&LiveSample) + Send>,
}

/// Runs each action on a sample of `live` every period until `stopped`
/// says so.
fn periodically(live: &Arc<LiveRun>, stopped: &mpsc::Receiver<()>, mut every: Vec<Periodic>) {
    // A sampler per action: its rates are over the action's own period.
    let mut samplers: Vec<Sampler> = every.iter().map(|_| Sampler::new(live.clone())).collect();
    for s in &mut samplers {
        s.sample();
    }
    let start = Instant::now();
    let mut due: Vec<Instant> = every.iter().map(|p| start + p.period).collect();
    loop {
        let next = due.iter().min().copied().unwrap_or(start);
        let ended = !matches!(
            stopped.recv_timeout(next.saturating_duration_since(Instant::now())),
            Err(RecvTimeoutError::Timeout)
        );
        let now = Instant::now();
        for ((p, due), sampler) in every.iter_mut().zip(&mut due).zip(&mut samplers) {
            if (ended && p.at_end) || (!ended && now >= *due) {
                if let Some(sample) = sampler.sample() {
                    (p.action)(&sample);
                }
                *due = now + p.period;
            }
        }
        if ended {
            return;
        }
    }
}

/// Writes a running run's metrics.json; an error is logged (the final
/// write reports its own).
fn write_running(dir: &Path, report: &RunReport) {
    if let Err(e) = super::run::write_metrics(dir, report, None, &super::run::Status::Running) {
        tracing::warn!("cannot write {}: {e}", PathBuf::from(dir).join("metrics.json").display());
    }
}

/// A component's own number as a person reads it: sizes (names ending in
/// `bytes`) in kB, MB or GB.
fn own(name: &str, v: u64) -> String {
    if !name.ends_with("bytes") || v < 10_000 {
        return v.to_string();
    }
    let (value, unit) = if v < 1_000_000 {
        (v as f64 / 1e3, "kB")
    } else if v < 1_000_000_000 {
        (v as f64 / 1e6, "MB")
    } else {
        (v as f64 / 1e9, "GB")
    };
    format!("{value:.1} {unit}")
}

/// `12 s: src 10/s out; matcher ×2 10/s in, busy 83%; resampler 10/s in,
/// busy 4%, resamplings 9`: per component its rate, how busy its tasks
/// are, and the counters and gauges it keeps itself.
fn log_line(s: &LiveSample) -> String {
    let mut parts = Vec::new();
    for (i, c) in s.snapshot.report.components.iter().enumerate() {
        let rates = s.rates.get(i).map(Vec::as_slice).unwrap_or(&[]);
        let n = rates.len().max(1) as f64;
        let tasks = if c.tasks > 1 { format!(" ×{}", c.tasks) } else { String::new() };
        let mut part = if c.role == squall_topology::spec::Role::Spout {
            format!("{}{tasks} {:.0}/s out", c.name, rates.iter().map(|r| r.out_per_s).sum::<f64>())
        } else {
            format!(
                "{}{tasks} {:.0}/s in, busy {:.0}%",
                c.name,
                rates.iter().map(|r| r.in_per_s).sum::<f64>(),
                rates.iter().map(|r| r.busy_pct).sum::<f64>() / n
            )
        };
        if c.dropped > 0 {
            part.push_str(&format!(", {} dropped", c.dropped));
        }
        for (k, v) in &c.custom {
            match v {
                CustomMetric::Counter(v) | CustomMetric::Gauge(v) => {
                    part.push_str(&format!(", {k} {}", own(k, *v)))
                }
                CustomMetric::Measured(m) => part.push_str(&format!(", {k} {m:.1}")),
                CustomMetric::Values { .. } => {}
            }
        }
        parts.push(part);
    }
    if s.snapshot.ended {
        format!("ended after {:.1} s: {}", s.snapshot.report.wall_secs, parts.join("; "))
    } else {
        format!("{:.0} s: {}", s.snapshot.elapsed_secs, parts.join("; "))
    }
}

#[cfg(test)]
mod tests {
    use super::own;

    #[test]
    fn sizes_read_in_units_and_other_numbers_as_they_are() {
        assert_eq!(own("map_bytes", 2_670_284), "2.7 MB");
        assert_eq!(own("map_bytes", 9_999), "9999");
        assert_eq!(own("map_bytes", 45_000), "45.0 kB");
        assert_eq!(own("map_bytes", 12_300_000_000), "12.3 GB");
        assert_eq!(own("resamplings", 2_670_284), "2670284");
    }
}
