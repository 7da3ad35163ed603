//! What a person watches: squall's streams as Foxglove channels, live
//! over the Foxglove SDK's WebSocket server and recorded by its MCAP
//! writer.
//!
//! Channels belong to two process-wide contexts: [`context`], which a
//! [`Recording`] records, gets every message; [`live_context`], which
//! the server of [`serve`] serves, gets per topic at most what a screen
//! shows (30 a second), so that a log replayed a hundred times faster
//! than real time does not cost the robot's computer more to send than
//! to process. The `sink.foxglove` bolt ([`FoxgloveSink`]) publishes the
//! streams it subscribes to into both. A viewer subscribing to a live
//! channel gets its latest message at once (latched, as ROS 2 latches
//! `/map`), so that one who joins late, or after the run while the views
//! linger, sees the map, the robot and its scan. With neither attached, publishing
//! costs little more than the conversion: the SDK drops messages no sink
//! takes. A live client that cannot keep up loses its oldest messages in
//! the SDK's per-client queue, never holding up the topology.

pub mod convert;
mod latch;
mod sink;

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use foxglove::{Context, McapWriterHandle, WebSocketServer, WebSocketServerHandle};
use squall_topology::Registry;
use squall_topology::live::LiveSample;

pub use sink::{FoxgloveSink, Weights};

/// The context of what is recorded: every message.
pub fn context() -> &'static Arc<Context> {
    static CONTEXT: OnceLock<Arc<Context>> = OnceLock::new();
    CONTEXT.get_or_init(Context::new)
}

/// The context of what live viewers get: per topic at most what a screen
/// shows (see `sink.foxglove`).
pub fn live_context() -> &'static Arc<Context> {
    static CONTEXT: OnceLock<Arc<Context>> = OnceLock::new();
    CONTEXT.get_or_init(Context::new)
}

/// Registers `sink.foxglove`.
pub fn register(r: &mut Registry) {
    r.register_bolt("sink.foxglove", FoxgloveSink::from_params);
}

/// Serves the live view on `host:port` (port 0 picks a free one) for
/// Foxglove to connect to; it runs until [`WebSocketServerHandle::stop`].
/// Its sockets are served by one thread of its own (the SDK would start
/// a thread per core, which on a robot's small computer take turns with
/// the topology's tasks).
pub fn serve(host: &str, port: u16) -> Result<WebSocketServerHandle, String> {
    static RUNTIME: OnceLock<std::io::Result<tokio::runtime::Runtime>> = OnceLock::new();
    let runtime = RUNTIME.get_or_init(|| {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("foxglove")
            .enable_all()
            .build()
    });
    let runtime = runtime.as_ref().map_err(|e| format!("cannot start the view's thread: {e}"))?;
    let server = WebSocketServer::new()
        .name("squall")
        .bind(host, port)
        .context(live_context())
        .listener(Arc::new(latch::Replay))
        .tokio_runtime(runtime.handle())
        .start_blocking()
        .map_err(|e| e.to_string())?;
    latch::enable();
    Ok(server)
}

/// Records every channel into an MCAP file, written beside it under a
/// temporary name (`.NAME.partial<pid>`) and renamed into place when
/// finished: a run that dies leaves no half-written file under the name
/// asked for, and what a killed run left is removed by the next.
#[derive(Debug)]
pub struct Recording {
    writer: McapWriterHandle<std::io::BufWriter<std::fs::File>>,
    partial: PathBuf,
    path: PathBuf,
}

impl Recording {
    /// Starts recording into `path`.
    pub fn start(path: &Path) -> Result<Recording, String> {
        let partial = squall_topology::fsio::temporary_beside(path, "partial")
            .map_err(|e| format!("{}: {e}", path.display()))?;
        let writer = context()
            .mcap_writer()
            .create_new_buffered_file(&partial)
            .map_err(|e| format!("{}: {e}", partial.display()))?;
        Ok(Recording { writer, partial, path: path.to_path_buf() })
    }

    /// Finishes the file (summary, index) and moves it into place.
    pub fn finish(self) -> Result<(), String> {
        let Recording { writer, partial, path } = self;
        writer.close().map_err(|e| format!("{}: {e}", partial.display()))?;
        std::fs::rename(&partial, &path).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// One component's metrics over the last second, on `/squall/metrics`.
#[derive(Debug, Clone, foxglove::Encode)]
pub struct ComponentMetrics {
    /// The component.
    pub component: String,
    /// Its tasks.
    pub tasks: u32,
    /// Tuples executed so far.
    pub received: u64,
    /// Tuples emitted so far.
    pub emitted: u64,
    /// Tuples dropped at its inputs so far.
    pub dropped: u64,
    /// Tuples executed per second, over its tasks.
    pub in_per_s: f64,
    /// Tuples emitted per second, over its tasks.
    pub out_per_s: f64,
    /// Mean share of the last interval its tasks spent in its code, percent.
    pub busy_pct: f64,
    /// Tuples in its input queues now.
    pub queue_depth: u64,
    /// Its slowest task's 99th percentile execute latency, µs.
    pub execute_p99_us: f64,
    /// Seconds since the run started.
    pub elapsed_s: f64,
}

/// Publishes every component's metrics of `sample` on `/squall/metrics`,
/// recorded and live.
pub fn publish_metrics(sample: &LiveSample) {
    static CHANNELS: OnceLock<[foxglove::Channel<ComponentMetrics>; 2]> = OnceLock::new();
    let channels = CHANNELS
        .get_or_init(|| [context(), live_context()].map(|c| c.channel_builder("/squall/metrics").build()));
    let s = &sample.snapshot;
    for (i, c) in s.report.components.iter().enumerate() {
        let rates = sample.rates.get(i).map(Vec::as_slice).unwrap_or(&[]);
        let n = rates.len().max(1) as f64;
        let metrics = ComponentMetrics {
            component: c.name.clone(),
            tasks: c.tasks as u32,
            received: c.received,
            emitted: c.emitted,
            dropped: c.dropped,
            in_per_s: rates.iter().map(|r| r.in_per_s).sum(),
            out_per_s: rates.iter().map(|r| r.out_per_s).sum(),
            busy_pct: rates.iter().map(|r| r.busy_pct).sum::<f64>() / n,
            queue_depth: s.tasks.get(i).map_or(0, |t| t.iter().map(|t| t.queue_depth as u64).sum()),
            execute_p99_us: c.execute.p99_us,
            elapsed_s: s.elapsed_secs,
        };
        for channel in channels {
            channel.log(&metrics);
        }
    }
}
