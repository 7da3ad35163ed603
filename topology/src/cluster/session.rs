//! zenoh sessions for the processes of a cluster: explicit endpoints, no
//! multicast scouting, mutual TLS when the cluster file configures it;
//! and a worker's presence (a liveliness token the coordinator watches)
//! and control channel.

use std::sync::Arc;
use std::time::Duration;

use zenoh::Session;
use zenoh::Wait;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

use crate::cluster::HostError;
use crate::cluster::config::{Endpoint, EndpointError, TlsSpec};
use crate::cluster::identity::{Signer, Verifier};
use crate::cluster::wire::{Control, DEFAULT_MAX_FRAME, Frame, Rejections, RunPlan};

/// Errors opening or using a cluster session.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// zenoh refused the configuration or could not open the session.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A worker did not answer in time.
    #[error("worker at {endpoint} did not answer within {secs} s")]
    NoAnswer {
        /// The worker's endpoint.
        endpoint: String,
        /// How long we waited.
        secs: f64,
    },
}

fn zenoh_error(e: impl std::fmt::Display) -> SessionError {
    SessionError::Zenoh(e.to_string())
}

/// Where a session listens and what it connects to.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SessionOptions {
    /// Endpoints to listen on (a worker's own).
    pub listen: Vec<Endpoint>,
    /// Endpoints to connect to (the workers, for a coordinator).
    pub connect: Vec<Endpoint>,
    /// Mutual TLS material.
    pub tls: Option<TlsSpec>,
    /// With mutual TLS: the only certificate common names that may talk
    /// to this session (everything from others is dropped by zenoh's
    /// access control); `None`: any certificate from the authority.
    pub allow: Option<Vec<String>>,
}

/// Opens a session: peer mode, only the given endpoints, no multicast
/// scouting.
pub async fn open(options: &SessionOptions) -> Result<Session, SessionError> {
    let mut config = zenoh::Config::default();
    let list = |endpoints: &[Endpoint]| {
        let quoted: Vec<String> = endpoints.iter().map(|e| format!("{:?}", e.to_string())).collect();
        format!("[{}]", quoted.join(","))
    };
    let mut set = |key: &str, value: String| config.insert_json5(key, &value).map_err(zenoh_error);
    set("mode", "\"peer\"".into())?;
    set("listen/endpoints", list(&options.listen))?;
    set("connect/endpoints", list(&options.connect))?;
    // No multicast discovery: peers are the endpoints given. Gossip only
    // runs over links already made (and zenoh warns without it).
    set("scouting/multicast/enabled", "false".into())?;
    // A message larger than a frame may be is dropped by the transport
    // before it is reassembled (zenoh's default allows 1 GiB).
    set("transport/link/rx/max_message_size", DEFAULT_MAX_FRAME.to_string())?;
    if let Some(tls) = &options.tls {
        let path = |p: &std::path::Path| format!("{:?}", p.display().to_string());
        set("transport/link/tls/root_ca_certificate", path(&tls.root_ca))?;
        set("transport/link/tls/listen_certificate", path(&tls.certificate))?;
        set("transport/link/tls/listen_private_key", path(&tls.private_key))?;
        set("transport/link/tls/connect_certificate", path(&tls.certificate))?;
        set("transport/link/tls/connect_private_key", path(&tls.private_key))?;
        set("transport/link/tls/enable_mtls", "true".into())?;
        if let Some(allowed) = &options.allow {
            // Deny by default; allow every message both ways to and from
            // the names allowed. A peer whose certificate is not on the
            // list keeps its link but gets nothing through.
            let names: Vec<String> = allowed.iter().map(|n| format!("{n:?}")).collect();
            let acl = format!(
                r#"{{ enabled: true, default_permission: "deny",
                    rules: [{{ id: "all", permission: "allow", flows: ["ingress", "egress"],
                              messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable",
                                         "reply", "liveliness_token", "declare_liveliness_subscriber",
                                         "liveliness_query"],
                              key_exprs: ["**"] }}],
                    subjects: [{{ id: "allowed", cert_common_names: [{}] }}],
                    policies: [{{ rules: ["all"], subjects: ["allowed"] }}] }}"#,
                names.join(", ")
            );
            set("access_control", acl)?;
        }
    }
    zenoh::open(config).await.map_err(zenoh_error)
}

/// The session of this process for `options`, opened on first use: the
/// components of one process that name the same endpoints (a live link's
/// ingest spout and publisher bolt) share one session, so a robot that
/// connects to it reaches both.
pub async fn shared(options: &SessionOptions) -> Result<Session, SessionError> {
    shared_with_refusals(options).await.map(|(session, _)| session)
}

/// Peers refused so far by a session's allowlist.
pub type RefusedPeers = Arc<std::sync::atomic::AtomicU64>;

/// [`shared`], and, for a session with an allowlist, the count of peers
/// it refused ([`watch_refused_peers`]).
pub async fn shared_with_refusals(
    options: &SessionOptions,
) -> Result<(Session, Option<RefusedPeers>), SessionError> {
    type Opened = (SessionOptions, Session, Option<RefusedPeers>);
    static SESSIONS: tokio::sync::Mutex<Vec<Opened>> = tokio::sync::Mutex::const_new(Vec::new());
    let mut sessions = SESSIONS.lock().await;
    sessions.retain(|(_, s, _)| !s.is_closed());
    if let Some((_, session, refused)) = sessions.iter().find(|(o, _, _)| o == options) {
        return Ok((session.clone(), refused.clone()));
    }
    let session = open(options).await?;
    let refused = match &options.allow {
        Some(allowed) => Some(watch_refused_peers(&session, allowed.clone()).await?),
        None => None,
    };
    sessions.push((options.clone(), session.clone(), refused.clone()));
    Ok((session, refused))
}

/// Logs, by the name on its certificate, and counts every peer that
/// links to `session` with a name not in `allowed`: the session's access
/// control lets nothing it sends through, and sends it nothing.
pub async fn watch_refused_peers(
    session: &Session,
    allowed: Vec<String>,
) -> Result<RefusedPeers, SessionError> {
    let refused = RefusedPeers::default();
    let events = session.info().link_events_listener().history(true).await.map_err(zenoh_error)?;
    let counter = refused.clone();
    tokio::spawn(async move {
        while let Ok(event) = events.recv_async().await {
            if event.kind() != SampleKind::Put {
                continue;
            }
            let link = event.link();
            let name = link.auth_identifier().unwrap_or("(no certificate name)");
            if !allowed.iter().any(|a| a == name) {
                counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                tracing::warn!(
                    "refused peer {name:?} ({}, from {}): not on the allowlist; nothing it sends is taken",
                    link.zid(),
                    link.dst()
                );
            }
        }
    });
    Ok(refused)
}

/// Parses endpoint strings (component parameters, command-line flags).
pub fn endpoints(texts: &[String]) -> Result<Vec<Endpoint>, EndpointError> {
    texts.iter().map(|t| Endpoint::parse(t)).collect()
}

/// The key part naming a worker: its listen endpoint, made key-safe.
pub fn worker_key(endpoint: &Endpoint) -> String {
    endpoint.to_string().replace(['/', ':'], "_")
}

/// Where workers' liveliness tokens live.
const WORKERS: &str = "squall/worker/";
/// Where coordinators' liveliness tokens live.
const COORDINATORS: &str = "squall/coordinator/";

/// The key of a worker's liveliness token.
pub fn presence_key(endpoint: &Endpoint) -> String {
    format!("{WORKERS}{}", worker_key(endpoint))
}

/// The key a worker takes control frames on.
pub fn control_key(endpoint: &Endpoint) -> String {
    format!("squall/control/{}", worker_key(endpoint))
}

/// The key a worker answers on.
pub fn reply_key(endpoint: &Endpoint) -> String {
    format!("squall/reply/{}", worker_key(endpoint))
}

/// Why a worker stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// A coordinator sent `Stop`.
    Told,
    /// The coordinator of a run it hosts is gone before the run was over
    /// (killed, or its link lost): a worker does not outlive its run.
    CoordinatorLost,
}

/// A worker process's presence in the cluster: its session, its
/// liveliness token, a task answering control frames and one watching
/// the coordinators. Dropping it withdraws the token.
#[derive(Debug)]
pub struct WorkerPresence {
    session: Session,
    rejections: Arc<Rejections>,
    stop: tokio::sync::watch::Receiver<Option<StopReason>>,
    runs: tokio::sync::mpsc::UnboundedReceiver<Shipped>,
    endpoint: Endpoint,
    hosting: Hosting,
    verifier: Option<Arc<Verifier>>,
}

/// A plan a coordinator shipped, and who signed it (with mutual TLS).
#[derive(Debug)]
pub struct Shipped {
    /// The plan.
    pub plan: Box<RunPlan>,
    /// The common name of the coordinator's certificate, when the worker
    /// checks signatures: only it may drive the run.
    pub coordinator: Option<String>,
}

/// The coordinators whose runs the worker hosts: if one goes, the worker
/// stops. Others' comings and goings are none of its business.
type Hosting = Arc<std::sync::Mutex<std::collections::HashSet<String>>>;

impl WorkerPresence {
    /// Opens the worker's session on `options.listen[0]` and announces it.
    /// With a `verifier` (mutual TLS), plans and stop are taken only from
    /// coordinators it accepts; pings are answered for anyone.
    pub async fn start(
        options: &SessionOptions,
        verifier: Option<Arc<Verifier>>,
    ) -> Result<Self, SessionError> {
        let endpoint = options
            .listen
            .first()
            .cloned()
            .ok_or_else(|| SessionError::Zenoh("a worker needs a listen endpoint".into()))?;
        let session = open(options).await?;
        let token = session.liveliness().declare_token(presence_key(&endpoint)).await.map_err(zenoh_error)?;
        let control = session.declare_subscriber(control_key(&endpoint)).await.map_err(zenoh_error)?;
        let rejections = Arc::new(Rejections::default());
        let (stopped, stop) = tokio::sync::watch::channel(None);
        let stopped = Arc::new(stopped);
        let hosting: Hosting = Arc::default();
        watch_coordinators(&session, stopped.clone(), hosting.clone()).await?;
        let hosted = hosting.clone();
        let (answer, counts, name) = (session.clone(), rejections.clone(), worker_key(&endpoint));
        let (plans, runs) = tokio::sync::mpsc::unbounded_channel();
        let me = endpoint.clone();
        let my_key = control_key(&endpoint);
        let checker = verifier.clone();
        tokio::spawn(async move {
            let _token = token;
            while let Ok(sample) = control.recv_async().await {
                let bytes = sample.payload().to_bytes();
                let decoded = Frame::decode(&bytes, DEFAULT_MAX_FRAME);
                // With a verifier, only what an accepted coordinator
                // signed is followed (a ping is answered for anyone).
                let mut signed_by = None;
                let decoded = match (decoded, &verifier) {
                    (Ok(ping @ Frame::Control(Control::Ping { .. })), _) => Ok(ping),
                    (Ok(frame), Some(verifier)) => match verifier.accept_or_refusal(frame, &my_key) {
                        Ok((coordinator, control)) => {
                            if let Control::Start(plan) = &control {
                                tracing::info!(
                                    "worker {name}: a plan from coordinator {coordinator:?}: {}",
                                    plan.run
                                );
                            }
                            signed_by = Some(coordinator);
                            Ok(Frame::Control(control))
                        }
                        Err(refused) => {
                            let (refusal, said) = *refused;
                            // An authentic plan from a coordinator not
                            // allowed is told no (others get no answer).
                            if let Some(Control::Start(plan)) = said {
                                let no = Control::Refused { run: plan.run, reason: refusal.to_string() };
                                let _ =
                                    put_waiting(&answer, reply_key(&endpoint), Frame::Control(no).encode())
                                        .await;
                            }
                            continue;
                        }
                    },
                    (other, _) => other,
                };
                match decoded {
                    Ok(Frame::Control(Control::Ping { nonce })) => {
                        let pong = Frame::Control(Control::Pong { nonce, worker: name.clone() });
                        if let Err(e) = put_waiting(&answer, reply_key(&endpoint), pong.encode()).await {
                            tracing::warn!("worker {name}: cannot answer a ping: {e}");
                        }
                    }
                    Ok(Frame::Control(Control::Stop)) => {
                        let _ = stopped.send(Some(StopReason::Told));
                    }
                    Ok(Frame::Control(Control::Start(plan))) => {
                        hosted.lock().unwrap_or_else(|e| e.into_inner()).insert(plan.coordinator.clone());
                        let _ = plans.send(Shipped { plan, coordinator: signed_by });
                    }
                    Ok(other) => tracing::warn!("worker {name}: unexpected on the control key: {other:?}"),
                    Err(e) => {
                        tracing::warn!("worker {name}: refused a control frame: {e}");
                        counts.count(&e);
                    }
                }
            }
        });
        Ok(WorkerPresence { session, rejections, stop, runs, endpoint: me, hosting, verifier: checker })
    }

    /// A function that lets the worker outlive a coordinator whose run is
    /// over (for [`crate::cluster::run::host_run`]).
    pub fn releaser(&self) -> impl Fn(&str) + Send + 'static {
        let hosting = self.hosting.clone();
        move |coordinator: &str| {
            hosting.lock().unwrap_or_else(|e| e.into_inner()).remove(coordinator);
        }
    }

    /// The next run a coordinator asks this worker to host.
    pub async fn next_run(&mut self) -> Option<Shipped> {
        self.runs.recv().await
    }

    /// The check of coordinators' signatures, with mutual TLS.
    pub fn verifier(&self) -> Option<&Arc<Verifier>> {
        self.verifier.as_ref()
    }

    /// The endpoint the worker listens on.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// The worker's session.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// Frames refused so far: (too large, malformed).
    pub fn rejections(&self) -> (u64, u64) {
        self.rejections.totals()
    }

    /// Waits until a coordinator sends `Stop` or the coordinators are gone.
    pub fn stopped(&self) -> impl std::future::Future<Output = StopReason> + Send + 'static {
        let mut stop = self.stop.clone();
        async move {
            match stop.wait_for(Option::is_some).await {
                Ok(reason) => reason.unwrap_or(StopReason::Told),
                Err(_) => StopReason::Told,
            }
        }
    }
}

/// Announces a coordinator: workers hosting its run stop if it goes
/// before the run is over. Keep the token for the run.
pub async fn announce_coordinator(session: &Session) -> Result<LivelinessToken, SessionError> {
    let key = format!("{COORDINATORS}{}", coordinator_id(session));
    session.liveliness().declare_token(key).await.map_err(zenoh_error)
}

/// How a coordinator names itself to workers.
pub fn coordinator_id(session: &Session) -> String {
    session.zid().to_string()
}

/// Follows the coordinators' tokens; when the coordinator of a run the
/// worker hosts goes, tells the worker to stop.
async fn watch_coordinators(
    session: &Session,
    stopped: Arc<tokio::sync::watch::Sender<Option<StopReason>>>,
    hosting: Hosting,
) -> Result<(), SessionError> {
    let mut tokens = watch_tokens(session, COORDINATORS).await?;
    let session = session.clone();
    tokio::spawn(async move {
        while let Some((key, up)) = tokens.recv().await {
            let hosts_its_run = {
                let hosting = hosting.clone();
                let key = key.clone();
                move || hosting.lock().unwrap_or_else(|e| e.into_inner()).contains(&key)
            };
            if up || !hosts_its_run() {
                continue;
            }
            // A token can go and come back as links between peers are
            // made and dropped (two coordinators, one leaving as the next
            // links): the coordinator is gone only if its token is still
            // missing a moment later.
            let (session, stopped) = (session.clone(), stopped.clone());
            tokio::spawn(async move {
                tokio::time::sleep(TOKEN_GRACE).await;
                if hosts_its_run() && !token_present(&session, &format!("{COORDINATORS}{key}")).await {
                    tracing::warn!("worker: the coordinator {key} is gone; stopping");
                    let _ = stopped.send(Some(StopReason::CoordinatorLost));
                }
            });
        }
    });
    Ok(())
}

/// How long a coordinator's liveliness token may be missing before a
/// worker counts it gone: a token can go and come back as links between
/// peers are made and dropped (one coordinator leaving as the next links).
const TOKEN_GRACE: Duration = Duration::from_secs(1);

/// Whether a liveliness token `key` is declared now (asked of the peers).
async fn token_present(session: &Session, key: &str) -> bool {
    let Ok(replies) = session.liveliness().get(key).await else { return false };
    matches!(tokio::time::timeout(Duration::from_secs(1), replies.recv_async()).await, Ok(Ok(_)))
}

/// Sends a control frame on `key`, waiting for room on the link rather
/// than dropping it. A put's default is to drop when the link's queue is
/// full, which it is while tuples stream, and a lost `Finished`, `Totals`
/// or `Go` would leave a run waiting forever.
pub(crate) fn send_control(session: &Session, key: &str, control: Control) -> Result<(), HostError> {
    send_frame(session, key, Frame::Control(control))
}

fn send_frame(session: &Session, key: &str, frame: Frame) -> Result<(), HostError> {
    put_waiting(session, key.to_string(), frame.encode()).wait().map_err(|e| HostError::Zenoh(e.to_string()))
}

/// Sends `control` on `key` as a coordinator: signed with `signer` (the
/// key of its TLS certificate) when the cluster has TLS, so that a
/// worker can tell who sent it ([`crate::cluster::identity`]); waiting
/// for room, as [`send_control`].
pub(crate) fn send_as_coordinator(
    session: &Session,
    key: &str,
    control: Control,
    signer: Option<&Signer>,
) -> Result<(), HostError> {
    let frame = match signer {
        Some(signer) => Frame::Signed(Box::new(signer.sign(key, &coordinator_id(session), control))),
        None => Frame::Control(control),
    };
    send_frame(session, key, frame)
}

/// A put of `bytes` on `key` that waits for room on the link instead of
/// being dropped (a put's default): for the frames a run cannot lose.
fn put_waiting(
    session: &Session,
    key: String,
    bytes: Vec<u8>,
) -> impl zenoh::Resolve<zenoh::Result<()>> + '_ {
    session.put(key, bytes).congestion_control(CongestionControl::Block)
}

/// Asks the worker at `endpoint` whether it is there; its name on success.
pub async fn ping(session: &Session, endpoint: &Endpoint, timeout: Duration) -> Result<String, SessionError> {
    let replies = session.declare_subscriber(reply_key(endpoint)).await.map_err(zenoh_error)?;
    let nonce = rand_nonce();
    let ping = Frame::Control(Control::Ping { nonce }).encode();
    let deadline = tokio::time::Instant::now() + timeout;
    // The first puts may go out before the link is up: repeat until answered.
    loop {
        put_waiting(session, control_key(endpoint), ping.clone()).await.map_err(zenoh_error)?;
        let wait = (deadline - tokio::time::Instant::now()).min(Duration::from_millis(200));
        if let Ok(Ok(sample)) = tokio::time::timeout(wait, replies.recv_async()).await
            && let Ok(Frame::Control(Control::Pong { nonce: n, worker })) =
                Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME)
            && n == nonce
        {
            return Ok(worker);
        }
        if tokio::time::Instant::now() >= deadline {
            return Err(SessionError::NoAnswer {
                endpoint: endpoint.to_string(),
                secs: timeout.as_secs_f64(),
            });
        }
    }
}

/// Tells the worker at `endpoint` to stop.
pub async fn stop(session: &Session, endpoint: &Endpoint) -> Result<(), SessionError> {
    put_waiting(session, control_key(endpoint), Frame::Control(Control::Stop).encode())
        .await
        .map_err(zenoh_error)
}

/// Watches workers' liveliness: yields (worker key, alive) as tokens come
/// and go, starting with those already present.
pub async fn watch_workers(
    session: &Session,
) -> Result<tokio::sync::mpsc::UnboundedReceiver<(String, bool)>, SessionError> {
    watch_tokens(session, WORKERS).await
}

/// Follows the liveliness tokens under `prefix`: yields (the key after
/// the prefix, alive) as they come and go, starting with those present.
async fn watch_tokens(
    session: &Session,
    prefix: &'static str,
) -> Result<tokio::sync::mpsc::UnboundedReceiver<(String, bool)>, SessionError> {
    let subscriber = session
        .liveliness()
        .declare_subscriber(format!("{prefix}*"))
        .history(true)
        .await
        .map_err(zenoh_error)?;
    let (send, receive) = tokio::sync::mpsc::unbounded_channel();
    tokio::spawn(async move {
        while let Ok(sample) = subscriber.recv_async().await {
            let key = sample.key_expr().as_str().trim_start_matches(prefix).to_string();
            if send.send((key, sample.kind() == SampleKind::Put)).is_err() {
                break;
            }
        }
    });
    Ok(receive)
}

/// A nonce that differs between calls and processes.
pub(crate) fn rand_nonce() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos(),
    );
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::config::Protocol;

    fn free_endpoint() -> Endpoint {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        Endpoint { protocol: Protocol::Tcp, host: "127.0.0.1".into(), port }
    }

    /// A worker on a free loopback port and a coordinator session connected
    /// to it.
    async fn worker_and_coordinator() -> (Endpoint, WorkerPresence, Session) {
        let endpoint = free_endpoint();
        let worker_options = SessionOptions { listen: vec![endpoint.clone()], ..SessionOptions::default() };
        let worker = WorkerPresence::start(&worker_options, None).await.unwrap();
        let coordinator =
            open(&SessionOptions { connect: vec![endpoint.clone()], ..SessionOptions::default() })
                .await
                .unwrap();
        (endpoint, worker, coordinator)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_coordinator_sees_a_worker_come_answer_and_go() {
        let (endpoint, worker, coordinator) = worker_and_coordinator().await;
        let mut presence = watch_workers(&coordinator).await.unwrap();
        let name = ping(&coordinator, &endpoint, Duration::from_secs(10)).await.unwrap();
        assert_eq!(name, worker_key(&endpoint));
        let seen = tokio::time::timeout(Duration::from_secs(10), presence.recv()).await.unwrap();
        assert_eq!(seen, Some((worker_key(&endpoint), true)));
        // Garbage on the control key is refused and counted, not fatal.
        coordinator.put(control_key(&endpoint), b"not a frame".to_vec()).await.unwrap();
        let name_again = ping(&coordinator, &endpoint, Duration::from_secs(10)).await.unwrap();
        assert_eq!(name_again, name);
        assert_eq!(worker.rejections(), (0, 1));
        stop(&coordinator, &endpoint).await.unwrap();
        let reason = tokio::time::timeout(Duration::from_secs(10), worker.stopped()).await.unwrap();
        assert_eq!(reason, StopReason::Told);
        worker.session().close().await.unwrap();
        drop(worker);
        let gone = tokio::time::timeout(Duration::from_secs(10), presence.recv()).await.unwrap();
        assert_eq!(gone, Some((worker_key(&endpoint), false)));
        // Nobody listens there any more.
        let silent = ping(&coordinator, &endpoint, Duration::from_millis(600)).await;
        assert!(matches!(silent, Err(SessionError::NoAnswer { .. })), "{silent:?}");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_worker_stops_when_its_coordinator_is_gone() {
        let (endpoint, worker, coordinator) = worker_and_coordinator().await;
        let token = announce_coordinator(&coordinator).await.unwrap();
        ping(&coordinator, &endpoint, Duration::from_secs(10)).await.unwrap();
        // The worker hosts one of its runs.
        let plan = RunPlan {
            run: "squall/test/run/1".into(),
            file: "t.toml".into(),
            topology: String::new(),
            hosts: Vec::new(),
            host: 1,
            host_count: 2,
            coordinator: coordinator_id(&coordinator),
        };
        coordinator
            .put(control_key(&endpoint), Frame::Control(Control::Start(Box::new(plan))).encode())
            .await
            .unwrap();
        let mut worker = worker;
        let shipped =
            tokio::time::timeout(Duration::from_secs(10), worker.next_run()).await.unwrap().unwrap();
        assert_eq!(shipped.plan.coordinator, coordinator_id(&coordinator));
        // Once the worker's side sees the coordinator's token, it dies.
        let seen = async {
            loop {
                let replies = worker.session().liveliness().get(format!("{COORDINATORS}*")).await.unwrap();
                if replies.recv_async().await.is_ok() {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        };
        tokio::time::timeout(Duration::from_secs(10), seen).await.unwrap();
        drop(token);
        coordinator.close().await.unwrap();
        let reason = tokio::time::timeout(Duration::from_secs(10), worker.stopped()).await.unwrap();
        assert_eq!(reason, StopReason::CoordinatorLost);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_worker_outlives_coordinators_whose_runs_it_does_not_host() {
        let (endpoint, worker, coordinator) = worker_and_coordinator().await;
        let token = announce_coordinator(&coordinator).await.unwrap();
        ping(&coordinator, &endpoint, Duration::from_secs(10)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
        drop(token);
        coordinator.close().await.unwrap();
        let stopped = tokio::time::timeout(Duration::from_secs(1), worker.stopped()).await;
        assert!(stopped.is_err(), "a coordinator that shipped no run stopped the worker");
    }
}
