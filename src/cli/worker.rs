//! `squall worker`: a process that hosts tasks for a cluster's coordinator.
//! It listens on an explicit endpoint, announces itself with a liveliness
//! token, and answers the coordinator until told to stop (or killed).

use std::path::PathBuf;
use std::process::ExitCode;

use squall_topology::cluster::config::{Endpoint, Protocol, TlsSpec};
use squall_topology::cluster::session::{SessionOptions, StopReason, WorkerPresence, worker_key};

use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct WorkerArgs {
    /// Where to listen: tcp/HOST:PORT (or tls/HOST:PORT).
    #[arg(long, value_name = "ENDPOINT")]
    listen: String,
    /// Other processes to connect to (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Mutual TLS: the cluster's certificate authority (with --tls-cert
    /// and --tls-key; endpoints are then tls/).
    #[arg(long, value_name = "FILE", requires_all = ["tls_cert", "tls_key"])]
    tls_ca: Option<PathBuf>,
    /// This worker's certificate, signed by the authority.
    #[arg(long, value_name = "FILE", requires_all = ["tls_ca", "tls_key"])]
    tls_cert: Option<PathBuf>,
    /// This worker's private key.
    #[arg(long, value_name = "FILE", requires_all = ["tls_ca", "tls_cert"])]
    tls_key: Option<PathBuf>,
}

/// Runs `squall worker`.
pub(super) fn worker(args: &WorkerArgs) -> ExitCode {
    let parse = |text: &str| Endpoint::parse(text).map_err(|e| eprintln!("squall worker: {e}"));
    let Ok(listen) = parse(&args.listen) else { return ExitCode::from(EXIT_INVALID) };
    let Ok(connect) = args.connect.iter().map(|c| parse(c)).collect::<Result<Vec<_>, _>>() else {
        return ExitCode::from(EXIT_INVALID);
    };
    let tls = match (&args.tls_ca, &args.tls_cert, &args.tls_key) {
        (Some(ca), Some(cert), Some(key)) => {
            for file in [ca, cert, key] {
                if !file.is_file() {
                    eprintln!("squall worker: no such file: {}", file.display());
                    return ExitCode::from(EXIT_INVALID);
                }
            }
            Some(TlsSpec { root_ca: ca.clone(), certificate: cert.clone(), private_key: key.clone() })
        }
        _ => None,
    };
    let wanted = if tls.is_some() { Protocol::Tls } else { Protocol::Tcp };
    if let Some(e) = std::iter::once(&listen).chain(&connect).find(|e| e.protocol != wanted) {
        let why = if tls.is_some() {
            "with --tls-ca, endpoints are tls/"
        } else {
            "tls/ needs --tls-ca, --tls-cert and --tls-key"
        };
        eprintln!("squall worker: {e}: {why}");
        return ExitCode::from(EXIT_INVALID);
    }
    let options = SessionOptions { listen: vec![listen.clone()], connect, tls };
    let runtime = match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("squall worker: cannot start the runtime: {e}");
            return ExitCode::from(EXIT_FAILED);
        }
    };
    runtime.block_on(async {
        let mut presence = match WorkerPresence::start(&options).await {
            Ok(p) => p,
            Err(e) => {
                eprintln!("squall worker: cannot listen on {listen}: {e}");
                return ExitCode::from(EXIT_FAILED);
            }
        };
        eprintln!("squall worker {} listening on {listen}", worker_key(&listen));
        tokio::select! {
            reason = presence.stopped() => match reason {
                StopReason::Told => eprintln!("squall worker: stopped by the coordinator"),
                StopReason::CoordinatorLost => eprintln!("squall worker: the coordinator is gone; stopping"),
            },
            _ = tokio::signal::ctrl_c() => eprintln!("squall worker: interrupted"),
        }
        let (too_large, malformed) = presence.rejections();
        if too_large + malformed > 0 {
            eprintln!("squall worker: refused {too_large} oversized and {malformed} malformed frames");
        }
        let _ = presence.session().close().await;
        ExitCode::SUCCESS
    })
}
