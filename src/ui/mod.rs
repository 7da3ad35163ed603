//! The live page (`--ui HOST:PORT`): a Storm-UI-like view of a running
//! topology, served while the run goes and after it ends.
//!
//! - `/`: the page (HTML and JavaScript embedded in the binary; it fetches
//!   nothing from elsewhere): the topology graph and, per component and
//!   per task, rates in and out, execute latency, queue depth against its
//!   bound, drops, busy and backpressure, restarts and the last error,
//!   updated every second.
//! - `/api/run`: the same as JSON (a [`LiveSample`]).
//! - `/metrics`: the counters in the Prometheus text format.
//!
//! The server runs on a thread of its own with a one-thread runtime: it
//! takes no time from the tasks but what reading their published counters
//! costs, once a second and at each request.

pub mod prometheus;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::http::header;
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use squall_topology::LiveRun;
use squall_topology::live::{LiveSample, Sampler};
use tokio::sync::oneshot;

/// The page, embedded.
const PAGE: &str = include_str!("page.html");

/// How often the server samples the run for the page's rates.
const SAMPLE_PERIOD: Duration = Duration::from_secs(1);

#[derive(Clone)]
struct Served {
    run: Arc<LiveRun>,
    latest: Arc<Mutex<Option<LiveSample>>>,
}

/// A running server; it stops when dropped or [`stop`](Self::stop)ped.
#[derive(Debug)]
pub struct UiServer {
    addr: SocketAddr,
    shutdown: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl UiServer {
    /// Binds `addr` (port 0 picks a free one) and serves `run` there. A
    /// bind that fails is an error here, before anything runs.
    pub fn start(addr: SocketAddr, run: Arc<LiveRun>) -> std::io::Result<Self> {
        let listener = std::net::TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
        let (shutdown, stopped) = oneshot::channel::<()>();
        let served = Served { run, latest: Arc::default() };
        let thread = std::thread::Builder::new().name("ui".into()).spawn(move || {
            runtime.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => {
                        tracing::error!("the live page cannot listen: {e}");
                        return;
                    }
                };
                tokio::spawn(sample(served.clone()));
                let app = Router::new()
                    .route("/", get(page))
                    .route("/api/run", get(api_run))
                    .route("/metrics", get(metrics))
                    .with_state(served);
                let stopped = async {
                    let _ = stopped.await;
                };
                if let Err(e) = axum::serve(listener, app).with_graceful_shutdown(stopped).await {
                    tracing::error!("the live page stopped: {e}");
                }
            });
        })?;
        Ok(UiServer { addr, shutdown: Some(shutdown), thread: Some(thread) })
    }

    /// Where it listens.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving and waits for the server's thread.
    pub fn stop(mut self) {
        self.shut();
    }

    fn shut(&mut self) {
        if let Some(s) = self.shutdown.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for UiServer {
    fn drop(&mut self) {
        self.shut();
    }
}

/// Samples the run every [`SAMPLE_PERIOD`], for the rates the page shows.
async fn sample(served: Served) {
    let mut sampler = Sampler::new(served.run.clone());
    let mut every = tokio::time::interval(SAMPLE_PERIOD);
    loop {
        every.tick().await;
        if let Some(s) = sampler.sample() {
            *served.latest.lock().unwrap_or_else(|e| e.into_inner()) = Some(s);
        }
    }
}

async fn page() -> Html<&'static str> {
    Html(PAGE)
}

async fn api_run(State(served): State<Served>) -> impl IntoResponse {
    let latest = served.latest.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let body = match latest {
        Some(s) => serde_json::to_string(&s).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}")),
        None => "null".to_string(),
    };
    ([(header::CONTENT_TYPE, "application/json"), (header::CACHE_CONTROL, "no-store")], body)
}

async fn metrics(State(served): State<Served>) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, prometheus::CONTENT_TYPE)], prometheus::encode(&served.run))
}
