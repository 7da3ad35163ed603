//! `squall worker`: a process that hosts tasks for a cluster's coordinator.
//! It listens on an explicit endpoint, announces itself with a liveliness
//! token, and answers the coordinator until told to stop (or killed).

use std::process::ExitCode;

use squall_topology::cluster::config::Endpoint;
use squall_topology::cluster::session::{SessionOptions, StopReason, WorkerPresence, worker_key};

use super::tls::TlsArgs;
use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct WorkerArgs {
    /// Where to listen: tcp/HOST:PORT (or tls/HOST:PORT).
    #[arg(long, value_name = "ENDPOINT")]
    listen: String,
    /// Other processes to connect to (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    #[command(flatten)]
    tls: TlsArgs,
}

/// Runs `squall worker`.
pub(super) fn worker(args: &WorkerArgs) -> ExitCode {
    let parse = |text: &str| Endpoint::parse(text).map_err(|e| eprintln!("squall worker: {e}"));
    let Ok(listen) = parse(&args.listen) else { return ExitCode::from(EXIT_INVALID) };
    let Ok(connect) = args.connect.iter().map(|c| parse(c)).collect::<Result<Vec<_>, _>>() else {
        return ExitCode::from(EXIT_INVALID);
    };
    let tls = match args.tls.spec(std::iter::once(&listen).chain(&connect)) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("squall worker: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
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
