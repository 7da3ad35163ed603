//! The cluster file (`CLUSTER.toml`): which worker processes exist and
//! where they listen, where each component's tasks go, and the TLS
//! material that lets peers in. Endpoints are explicit; nothing relies on
//! multicast discovery.
//!
//! ```toml
//! [cluster]
//! name = "lab"                        # key prefix: squall/lab/...
//!
//! [[worker]]
//! name = "w1"
//! endpoint = "tcp/127.0.0.1:7447"     # where `squall worker --listen` listens
//!
//! [placement]                         # optional (defaults below)
//! matcher = ["w1", "w2", "w1"]        # task i of `matcher` on the i-th worker
//! source = ["coordinator"]            # or in the coordinator's process
//!
//! [tls]                               # optional: mutual TLS, then endpoints are tls/
//! root_ca = "ca.pem"                  # paths relative to this file
//! certificate = "coordinator.pem"
//! private_key = "coordinator.key"
//! ```

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::cluster::PlacementError;
use crate::spec::{SpecError, SpecErrors};

/// The name placement uses for the coordinator's own process.
pub const COORDINATOR_NAME: &str = "coordinator";

/// Where a task runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Host {
    /// In the coordinator's process.
    Coordinator,
    /// On the worker of this index in the cluster file.
    Worker(usize),
}

impl Host {
    /// Its number in a run: 0 the coordinator, w + 1 worker w.
    pub fn number(self) -> u16 {
        match self {
            Host::Coordinator => 0,
            Host::Worker(w) => w as u16 + 1,
        }
    }
}

/// A zenoh locator that a worker listens on: `tcp/HOST:PORT` or
/// `tls/HOST:PORT`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    /// `tcp` or `tls`.
    pub protocol: Protocol,
    /// Host name or address (IPv6 in brackets).
    pub host: String,
    /// TCP port.
    pub port: u16,
}

/// The transports cluster mode speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    /// Plain TCP (trusted networks, loopback).
    Tcp,
    /// TLS over TCP, mutually authenticated.
    Tls,
}

impl Endpoint {
    /// Parses `tcp/HOST:PORT` or `tls/HOST:PORT`; the error says what was
    /// expected.
    pub fn parse(text: &str) -> Result<Self, EndpointError> {
        let expected = || EndpointError::Malformed(text.to_string());
        let (protocol, address) = match text.split_once('/') {
            Some(("tcp", address)) => (Protocol::Tcp, address),
            Some(("tls", address)) => (Protocol::Tls, address),
            _ => return Err(expected()),
        };
        let (host, port) = match address.strip_prefix('[') {
            // [IPv6]:PORT
            Some(rest) => rest.split_once("]:").map(|(h, p)| (&address[..h.len() + 2], p)),
            None => address.rsplit_once(':'),
        }
        .ok_or_else(expected)?;
        let port = port
            .parse::<u16>()
            .map_err(|_| EndpointError::Port { text: text.to_string(), port: port.to_string() })?;
        let bracketed = host.starts_with('[') && host.ends_with(']');
        if host.is_empty() || (host.contains(':') && !bracketed) || host.contains('/') {
            return Err(expected());
        }
        Ok(Endpoint { protocol, host: host.to_string(), port })
    }

    /// Whether the host is a loopback address (127.0.0.0/8, `[::1]`,
    /// `localhost`): reachable from this machine only. Any other name
    /// may resolve to an address others reach, so it is not.
    pub fn is_loopback(&self) -> bool {
        let host = self.host.trim_start_matches('[').trim_end_matches(']');
        host.eq_ignore_ascii_case("localhost")
            || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
    }

    /// Whether the endpoint is plain `tcp/` beyond loopback: whoever can
    /// reach it talks to this process, or reads and alters what it says,
    /// without proving who they are.
    pub fn is_exposed(&self) -> bool {
        self.protocol == Protocol::Tcp && !self.is_loopback()
    }
}

/// The first endpoint that is plain `tcp/` beyond loopback.
pub fn exposed_endpoint<'a>(endpoints: impl IntoIterator<Item = &'a Endpoint>) -> Option<&'a Endpoint> {
    endpoints.into_iter().find(|e| e.is_exposed())
}

/// Why `endpoint` (plain `tcp/` beyond loopback) is refused, what a peer
/// could do there (`risk`), and the two ways out: mutual TLS, or the
/// explicit opt-in `opt_in` (`--insecure`, `insecure = true`).
pub fn exposure_refusal(endpoint: &Endpoint, risk: &str, opt_in: &str) -> String {
    format!(
        "{endpoint}: plain tcp/ beyond loopback, with no authentication: anyone who can reach it could \
         {risk}. Use mutual TLS (tls/ endpoints and a certificate for each process, made as \
         docs/guide/security.md shows), or, on a network you trust, {opt_in}"
    )
}

/// The warning an insecure opt-in prints at start and leaves in the
/// run's metrics.
pub fn exposure_warning(endpoint: &Endpoint, risk: &str) -> String {
    format!(
        "insecure: {endpoint} is plain tcp/ beyond loopback, without authentication: anyone who can \
         reach it could {risk}"
    )
}

/// What a peer could do at a worker's port.
pub const WORKER_RISK: &str = "make this worker run plans: read the files it may read and send them on";
/// What a peer could do on a live link.
pub const LIVE_LINK_RISK: &str = "read the robot's scans and poses, or send it false ones";

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let protocol = match self.protocol {
            Protocol::Tcp => "tcp",
            Protocol::Tls => "tls",
        };
        write!(f, "{protocol}/{}:{}", self.host, self.port)
    }
}

/// An endpoint that is not `tcp/HOST:PORT` or `tls/HOST:PORT`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EndpointError {
    /// Not of the form PROTOCOL/HOST:PORT with a known protocol.
    #[error("expected tcp/HOST:PORT or tls/HOST:PORT, found {0:?}")]
    Malformed(String),
    /// The port is not a number 0–65535.
    #[error("expected tcp/HOST:PORT or tls/HOST:PORT, found {text:?}: port {port:?} is not 0–65535")]
    Port {
        /// The endpoint as given.
        text: String,
        /// Its port part.
        port: String,
    },
}

/// A worker process of the cluster.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WorkerSpec {
    /// Its name, unique in the cluster.
    pub name: String,
    /// Where it listens.
    pub endpoint: Endpoint,
    /// The line that declares it.
    pub line: usize,
}

/// Mutual TLS material, paths resolved against the cluster file's folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsSpec {
    /// The certificate authority every peer's certificate must chain to.
    pub root_ca: PathBuf,
    /// This process's certificate.
    pub certificate: PathBuf,
    /// Its private key.
    pub private_key: PathBuf,
}

impl TlsSpec {
    /// The first of its files that is not there.
    pub fn missing_file(&self) -> Option<&Path> {
        [&self.root_ca, &self.certificate, &self.private_key]
            .into_iter()
            .find(|f| !f.is_file())
            .map(PathBuf::as_path)
    }
}

impl Protocol {
    /// What endpoints speak with TLS configured (`tls/`) or without (`tcp/`).
    pub fn with_tls(tls: bool) -> Self {
        if tls { Protocol::Tls } else { Protocol::Tcp }
    }
}

/// The first of `endpoints` whose protocol does not go with TLS being
/// configured (`tls`) or not: a mixed set would fail only at connection
/// time, with a less helpful message.
pub fn mismatched_endpoint<'a>(
    endpoints: impl IntoIterator<Item = &'a Endpoint>,
    tls: bool,
) -> Option<&'a Endpoint> {
    endpoints.into_iter().find(|e| e.protocol != Protocol::with_tls(tls))
}

/// A checked cluster file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClusterSpec {
    /// The file, as named in errors.
    pub file: String,
    /// The cluster's name: the first part of every key it uses.
    pub name: String,
    /// The workers, in file order.
    pub workers: Vec<WorkerSpec>,
    /// Per component, the host of each task; see [`ClusterSpec::place`]
    /// for components not listed.
    pub placement: BTreeMap<String, Vec<Host>>,
    /// Mutual TLS, if configured.
    pub tls: Option<TlsSpec>,
    /// `insecure = true` under `[cluster]`: plain `tcp/` endpoints beyond
    /// loopback are allowed (a network the user trusts).
    pub insecure: bool,
}

impl ClusterSpec {
    /// The warnings of a run on this cluster: one per worker reached over
    /// plain `tcp/` beyond loopback (allowed by `insecure = true`).
    pub fn exposure_warnings(&self) -> Vec<String> {
        self.workers
            .iter()
            .filter(|w| w.endpoint.is_exposed())
            .map(|w| format!("worker {:?}: {}", w.name, exposure_warning(&w.endpoint, WORKER_RISK)))
            .collect()
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCluster {
    cluster: Spanned<RawHeader>,
    #[serde(default)]
    worker: Vec<Spanned<RawWorker>>,
    #[serde(default)]
    placement: BTreeMap<String, Spanned<Vec<Spanned<String>>>>,
    tls: Option<Spanned<RawTls>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHeader {
    name: Spanned<String>,
    #[serde(default)]
    insecure: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorker {
    name: Spanned<String>,
    endpoint: Spanned<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTls {
    root_ca: Spanned<String>,
    certificate: Spanned<String>,
    private_key: Spanned<String>,
}

/// 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// A name usable in a zenoh key: letters, digits, `-` and `_`.
fn is_key_safe(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// The checks of one cluster file, collecting every problem found.
struct Checker<'a> {
    file: &'a str,
    text: &'a str,
    errors: Vec<SpecError>,
}

impl Checker<'_> {
    fn error(&self, line: usize, message: String) -> SpecError {
        SpecError { file: self.file.into(), line, component: None, message }
    }

    /// Records a problem found at byte `offset` of the file.
    fn at(&mut self, offset: usize, message: String) {
        let error = self.error(line_of(self.text, offset), message);
        self.errors.push(error);
    }

    /// The cluster's name must be usable in a zenoh key.
    fn cluster_name(&mut self, name: &Spanned<String>) {
        if !is_key_safe(name.get_ref()) {
            let message = format!("cluster name {:?}: expected letters, digits, - or _", name.get_ref());
            self.at(name.span().start, message);
        }
    }

    /// The workers whose endpoints parse, and every declared name in file
    /// order: placement refers to these (a worker whose endpoint is wrong
    /// is still declared).
    fn workers(&mut self, raw: &[Spanned<RawWorker>]) -> (Vec<WorkerSpec>, Vec<String>) {
        let mut workers = Vec::new();
        let mut declared = Vec::new();
        let mut names = HashSet::new();
        for w in raw {
            let (span, w) = (w.span(), w.get_ref());
            let name = w.name.get_ref();
            declared.push(name.clone());
            if !is_key_safe(name) {
                self.at(
                    w.name.span().start,
                    format!("worker name {name:?}: expected letters, digits, - or _"),
                );
            } else if name == COORDINATOR_NAME {
                self.at(
                    w.name.span().start,
                    format!(
                        "worker name {name:?} is reserved: placement uses it for the coordinator's process"
                    ),
                );
            } else if !names.insert(name.clone()) {
                self.at(w.name.span().start, format!("worker {name:?} is declared twice"));
            }
            match Endpoint::parse(w.endpoint.get_ref()) {
                Ok(endpoint) => workers.push(WorkerSpec {
                    name: name.clone(),
                    endpoint,
                    line: line_of(self.text, span.start),
                }),
                Err(message) => self.at(w.endpoint.span().start, format!("worker {name:?}: {message}")),
            }
        }
        if raw.is_empty() {
            let error = self.error(0, "no [[worker]]: a cluster needs at least one worker".into());
            self.errors.push(error);
        }
        (workers, declared)
    }

    /// Each listed component's hosts, by the names `declared`.
    fn placement(
        &mut self,
        raw: &BTreeMap<String, Spanned<Vec<Spanned<String>>>>,
        declared: &[String],
    ) -> BTreeMap<String, Vec<Host>> {
        let mut placement = BTreeMap::new();
        for (component, tasks) in raw {
            let mut indices = Vec::new();
            for worker in tasks.get_ref() {
                if worker.get_ref() == COORDINATOR_NAME {
                    indices.push(Host::Coordinator);
                    continue;
                }
                match declared.iter().position(|w| w == worker.get_ref()) {
                    Some(i) => indices.push(Host::Worker(i)),
                    None => self.at(
                        worker.span().start,
                        format!("placement of {component:?}: no worker named {:?}", worker.get_ref()),
                    ),
                }
            }
            if tasks.get_ref().is_empty() {
                self.at(
                    tasks.span().start,
                    format!("placement of {component:?}: expected a worker per task"),
                );
            }
            placement.insert(component.clone(), indices);
        }
        placement
    }

    /// The TLS files, resolved against `folder`; each must exist.
    fn tls(&mut self, raw: &RawTls, folder: &Path) -> TlsSpec {
        let resolve = |p: &Spanned<String>| folder.join(p.get_ref());
        for p in [&raw.root_ca, &raw.certificate, &raw.private_key] {
            if !resolve(p).is_file() {
                self.at(p.span().start, format!("no such file: {}", resolve(p).display()));
            }
        }
        TlsSpec {
            root_ca: resolve(&raw.root_ca),
            certificate: resolve(&raw.certificate),
            private_key: resolve(&raw.private_key),
        }
    }

    /// With TLS every endpoint is `tls/`; without, every one is `tcp/`.
    fn endpoint_protocols(&mut self, workers: &[WorkerSpec], tls: bool, insecure: bool) {
        for w in workers {
            let why = if mismatched_endpoint([&w.endpoint], tls).is_some() {
                if tls {
                    "with [tls], endpoints are tls/".to_string()
                } else {
                    "tls/ needs a [tls] section".into()
                }
            } else if w.endpoint.is_exposed() && !insecure {
                exposure_refusal(&w.endpoint, WORKER_RISK, "set `insecure = true` under [cluster]")
            } else {
                continue;
            };
            let error = self.error(w.line, format!("worker {:?}: {why}", w.name));
            self.errors.push(error);
        }
    }
}

impl ClusterSpec {
    /// Reads and checks a cluster file.
    pub fn load(path: &Path) -> Result<Self, SpecErrors> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SpecError {
            file: file.as_str().into(),
            line: 0,
            component: None,
            message: format!("cannot read the cluster file: {e}"),
        })?;
        let folder = path.parent().unwrap_or(Path::new("."));
        Self::parse(&file, &text, folder)
    }

    /// Checks cluster-file text; `file` names it in errors and relative
    /// TLS paths are taken from `folder`. Reports every problem found.
    pub fn parse(file: &str, text: &str, folder: &Path) -> Result<Self, SpecErrors> {
        let mut check = Checker { file, text, errors: Vec::new() };
        let raw: RawCluster = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(0, |s| line_of(text, s.start));
            SpecErrors(vec![check.error(line, e.message().trim().to_string())])
        })?;
        let name = raw.cluster.get_ref().name.clone();
        let insecure = raw.cluster.get_ref().insecure;
        check.cluster_name(&name);
        let (workers, declared) = check.workers(&raw.worker);
        let placement = check.placement(&raw.placement, &declared);
        let tls = raw.tls.as_ref().map(|t| check.tls(t.get_ref(), folder));
        check.endpoint_protocols(&workers, tls.is_some(), insecure);
        if !check.errors.is_empty() {
            return Err(SpecErrors(check.errors));
        }
        Ok(ClusterSpec { file: file.to_string(), name: name.into_inner(), workers, placement, tls, insecure })
    }

    /// The host of each of `tasks` tasks of `component`: the explicit
    /// placement where the file gives one (its length must match); else a
    /// component of one task runs in the coordinator's process (sources,
    /// dispatchers, sinks: where the run's input and output files are) and
    /// a parallel one is spread evenly over the workers (task i on worker
    /// i mod n).
    pub fn place(&self, component: &str, tasks: usize) -> Result<Vec<Host>, PlacementError> {
        match self.placement.get(component) {
            Some(explicit) if explicit.len() == tasks => Ok(explicit.clone()),
            Some(explicit) => Err(PlacementError::Listed {
                file: self.file.clone(),
                component: component.to_string(),
                listed: explicit.len(),
                tasks,
            }),
            None if tasks == 1 => Ok(vec![Host::Coordinator]),
            None => Ok((0..tasks).map(|i| Host::Worker(i % self.workers.len())).collect()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = "[cluster]\nname = \"lab\"\n\n[[worker]]\nname = \"w1\"\nendpoint = \"tcp/127.0.0.1:7447\"\n\n[[worker]]\nname = \"w2\"\nendpoint = \"tcp/[::1]:7448\"\n\n[placement]\nmatcher = [\"w2\", \"w1\", \"w2\"]\n";

    fn parse(text: &str) -> Result<ClusterSpec, SpecErrors> {
        ClusterSpec::parse("c.toml", text, Path::new("."))
    }

    fn messages(text: &str) -> Vec<String> {
        parse(text).unwrap_err().0.iter().map(ToString::to_string).collect()
    }

    #[test]
    fn a_cluster_file_gives_workers_and_placement() {
        let c = parse(TWO).unwrap();
        assert_eq!(c.name, "lab");
        assert_eq!(c.workers.len(), 2);
        assert_eq!(
            c.workers[1].endpoint,
            Endpoint { protocol: Protocol::Tcp, host: "[::1]".into(), port: 7448 }
        );
        assert_eq!(c.workers[1].endpoint.to_string(), "tcp/[::1]:7448");
        let (w0, w1) = (Host::Worker(0), Host::Worker(1));
        assert_eq!(c.place("matcher", 3).unwrap(), vec![w1, w0, w1]);
        assert_eq!(c.place("resampler", 3).unwrap(), vec![w0, w1, w0]);
        assert_eq!(c.place("sink", 1).unwrap(), vec![Host::Coordinator]);
        assert!(c.place("matcher", 2).unwrap_err().to_string().contains("names 3 hosts, but it has 2 tasks"));
        let explicit = parse(&TWO.replace("[\"w2\", \"w1\", \"w2\"]", "[\"coordinator\", \"w1\"]")).unwrap();
        assert_eq!(explicit.place("matcher", 2).unwrap(), vec![Host::Coordinator, w0]);
        assert!(
            messages(&TWO.replace("\"w1\"\nendpoint", "\"coordinator\"\nendpoint"))[0].contains("reserved")
        );
    }

    #[test]
    fn endpoints_must_say_protocol_host_and_port() {
        for bad in [
            "127.0.0.1:7447",
            "udp/1.2.3.4:1",
            "tcp/host",
            "tcp/:80",
            "tcp/h:99999",
            "tcp/::1:80",
            "tcp/[::1]",
        ] {
            assert!(Endpoint::parse(bad).is_err(), "{bad} accepted");
        }
        assert_eq!(Endpoint::parse("tls/robot.lan:7447").unwrap().protocol, Protocol::Tls);
    }

    #[test]
    fn errors_name_file_line_and_what_was_expected() {
        let text = TWO.replace("tcp/[::1]:7448", "tcp/[::1]").replace("[\"w2\", \"w1\"", "[\"w9\", \"w1\"");
        let m = messages(&text);
        assert_eq!(m.len(), 2, "{m:?}");
        assert_eq!(
            m[0],
            "c.toml:10: worker \"w2\": expected tcp/HOST:PORT or tls/HOST:PORT, found \"tcp/[::1]\""
        );
        assert!(m[1].starts_with("c.toml:13: placement of \"matcher\": no worker named \"w9\""), "{m:?}");
        let twice = TWO.replace("w2", "w1");
        assert_eq!(messages(&twice), vec!["c.toml:9: worker \"w1\" is declared twice"]);
        let unknown = format!("{TWO}\n[extra]\n");
        assert!(messages(&unknown)[0].contains("unknown field `extra`"), "{:?}", messages(&unknown));
        assert!(messages("[cluster]\nname = \"lab\"\n")[0].contains("no [[worker]]"));
    }

    #[test]
    fn tls_needs_its_files_and_tls_endpoints() {
        let folder = std::env::temp_dir().join(format!("squall-cluster-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        for f in ["ca.pem", "me.pem", "me.key"] {
            std::fs::write(folder.join(f), "x").unwrap();
        }
        let tls = "\n[tls]\nroot_ca = \"ca.pem\"\ncertificate = \"me.pem\"\nprivate_key = \"me.key\"\n";
        let with_tls = format!("{}{tls}", TWO.replace("tcp/", "tls/"));
        let c = ClusterSpec::parse("c.toml", &with_tls, &folder).unwrap();
        assert_eq!(c.tls.unwrap().root_ca, folder.join("ca.pem"));
        let plain = format!("{TWO}{tls}");
        let m = ClusterSpec::parse("c.toml", &plain, &folder).unwrap_err().to_string();
        assert!(m.contains("c.toml:4: worker \"w1\": with [tls], endpoints are tls/"), "{m}");
        let missing = with_tls.replace("me.key", "gone.key");
        let m = ClusterSpec::parse("c.toml", &missing, &folder).unwrap_err().to_string();
        assert!(m.contains("no such file") && m.contains("gone.key"), "{m}");
        std::fs::remove_dir_all(&folder).unwrap();
    }

    #[test]
    fn loopback_is_told_apart_from_every_other_host() {
        for host in ["127.0.0.1", "127.8.9.10", "[::1]", "localhost", "LOCALHOST"] {
            let e = Endpoint::parse(&format!("tcp/{host}:7447")).unwrap();
            assert!(e.is_loopback() && !e.is_exposed(), "{host}");
        }
        for host in ["0.0.0.0", "192.168.1.10", "[::]", "[fe80::1]", "robot.lan", "localhost.evil.com"] {
            let e = Endpoint::parse(&format!("tcp/{host}:7447")).unwrap();
            assert!(!e.is_loopback() && e.is_exposed(), "{host}");
            let tls = Endpoint::parse(&format!("tls/{host}:7447")).unwrap();
            assert!(!tls.is_exposed(), "tls/{host} is authenticated");
        }
    }

    #[test]
    fn a_plain_worker_beyond_loopback_needs_insecure_and_is_then_warned_about() {
        let lan = TWO.replace("tcp/127.0.0.1:7447", "tcp/192.168.1.10:7447");
        let m = messages(&lan);
        assert_eq!(m.len(), 1, "{m:?}");
        assert!(
            m[0].starts_with("c.toml:4: worker \"w1\": tcp/192.168.1.10:7447: plain tcp/ beyond loopback"),
            "{m:?}"
        );
        assert!(
            m[0].contains("docs/guide/security.md") && m[0].contains("`insecure = true` under [cluster]"),
            "{m:?}"
        );
        let allowed = parse(&lan.replace("name = \"lab\"", "name = \"lab\"\ninsecure = true")).unwrap();
        assert!(allowed.insecure);
        let warnings = allowed.exposure_warnings();
        assert_eq!(warnings.len(), 1, "only w1 is beyond loopback: {warnings:?}");
        assert!(warnings[0].starts_with("worker \"w1\": insecure: tcp/192.168.1.10:7447"), "{warnings:?}");
        assert!(parse(TWO).unwrap().exposure_warnings().is_empty());
    }
}
