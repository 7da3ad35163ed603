//! `squall worker`: a process that hosts tasks for a cluster's coordinator.
//! It listens on an explicit endpoint, announces itself with a liveliness
//! token, hosts the runs coordinators ship to it one after another, and
//! stops when told, or when a coordinator whose run it hosts is gone.

use std::collections::BTreeSet;
use std::process::ExitCode;
use std::sync::Arc;

use squall_topology::RunOptions;
use squall_topology::cluster::config::TlsSpec;
use squall_topology::cluster::config::{
    Endpoint, WORKER_RISK, exposed_endpoint, exposure_refusal, exposure_warning,
};
use squall_topology::cluster::identity::Verifier;
use squall_topology::cluster::run::{HostPolicy, WorkerLimits, host_run};
use squall_topology::cluster::session::{
    SessionOptions, Shipped, StopReason, WorkerPresence, reply_key, worker_key,
};
use squall_topology::confine::{self, Confinement};

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
    /// Where tasks placed here write their outputs: the only folder a
    /// plan may write under (none without it).
    #[arg(long, value_name = "DIR")]
    out: Option<std::path::PathBuf>,
    /// The only folder a plan's components may read under (logs, bags,
    /// maps); without it, plans read no files.
    #[arg(long, value_name = "DIR")]
    data_dir: Option<std::path::PathBuf>,
    /// Most tasks one run may place here; a plan with more is refused.
    #[arg(long, value_name = "N", default_value_t = WorkerLimits::default().max_tasks)]
    max_tasks: usize,
    /// Most tuples that may wait in this worker's input queues (the
    /// bounds of the queues of the tasks it hosts, summed); a plan with
    /// more is refused.
    #[arg(long, value_name = "N", default_value_t = WorkerLimits::default().max_queued)]
    max_queued: usize,
    /// Longest one run may go on here, seconds; past it the run fails.
    /// Unbounded by default (a live robot streams for hours).
    #[arg(long, value_name = "S", value_parser = super::numbers::positive_wait_secs)]
    max_run_secs: Option<f64>,
    /// With mutual TLS: take plans only from the coordinator whose
    /// certificate has this common name (repeatable; with none of these
    /// and no --allow-coordinators, any certificate from the authority).
    #[arg(long, value_name = "NAME")]
    allow_coordinator: Vec<String>,
    /// With mutual TLS: the coordinators' names allowed, one per line
    /// (`#` starts a comment), added to --allow-coordinator.
    #[arg(long, value_name = "FILE")]
    allow_coordinators: Option<std::path::PathBuf>,
    /// Most resident memory of this worker, MiB; past it the run fails.
    /// The default is 90% of the machine's memory.
    #[arg(long, value_name = "MIB")]
    max_memory_mb: Option<u64>,
    #[command(flatten)]
    tls: TlsArgs,
    /// Allow plain tcp/ endpoints beyond loopback, without mutual TLS: on
    /// a network you trust only (anyone who reaches the port can make the
    /// worker run plans). Warns at start. Also lets plans place here live
    /// links that are plain beyond loopback (`insecure = true`).
    #[arg(long)]
    insecure: bool,
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
    let endpoints = || std::iter::once(&listen).chain(&connect);
    if let Some(exposed) = exposed_endpoint(endpoints()) {
        if !args.insecure {
            eprintln!("squall worker: {}", exposure_refusal(exposed, WORKER_RISK, "pass --insecure"));
            return ExitCode::from(EXIT_INVALID);
        }
        for e in endpoints().filter(|e| e.is_exposed()) {
            let warning = exposure_warning(e, WORKER_RISK);
            eprintln!("squall worker: WARNING: {warning} (--insecure)");
        }
    }
    let limits = match worker_limits(args) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("squall worker: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    if let Some(out) = &args.out
        && let Err(e) = std::fs::create_dir_all(out)
    {
        eprintln!("squall worker: --out {}: {e}", out.display());
        return ExitCode::from(EXIT_INVALID);
    }
    // From here on this process reads and writes only where it was told.
    let policy = Confinement::new(args.data_dir.as_deref(), args.out.as_deref()).and_then(confine::confine);
    if let Err(e) = policy {
        eprintln!("squall worker: {e}");
        return ExitCode::from(EXIT_INVALID);
    }
    let folder = |dir: &Option<std::path::PathBuf>, none: &str| {
        dir.as_ref().map_or(none.to_string(), |d| format!("under {}", d.display()))
    };
    eprintln!(
        "squall worker: plans read {} and write {}",
        folder(&args.data_dir, "no files (no --data-dir)"),
        folder(&args.out, "no files (no --out)")
    );
    let verifier = match coordinator_check(args, tls.as_ref()) {
        Ok(v) => v.map(Arc::new),
        Err(e) => {
            eprintln!("squall worker: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let options = SessionOptions { listen: vec![listen.clone()], connect, tls, allow: None };
    let runtime = match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("squall worker: cannot start the runtime: {e}");
            return ExitCode::from(EXIT_FAILED);
        }
    };
    runtime.block_on(async {
        let mut presence = match WorkerPresence::start(&options, verifier.clone()).await {
            Ok(p) => p,
            Err(e) => {
                eprintln!("squall worker: cannot listen on {listen}: {e}");
                return ExitCode::from(EXIT_FAILED);
            }
        };
        eprintln!("squall worker {} listening on {listen}", worker_key(&listen));
        loop {
            let plan = tokio::select! {
                reason = presence.stopped() => {
                    report_stop(reason);
                    break;
                }
                _ = tokio::signal::ctrl_c() => {
                    eprintln!("squall worker: interrupted");
                    break;
                }
                shipped = presence.next_run() => match shipped {
                    Some(shipped) => shipped,
                    None => break,
                },
            };
            let Shipped { plan, coordinator } = plan;
            match &coordinator {
                Some(name) => eprintln!("squall worker: hosting run {} of coordinator {name:?} ({})", plan.run, plan.coordinator),
                None => eprintln!("squall worker: hosting run {}", plan.run),
            }
            let session = presence.session().clone();
            let reply = reply_key(presence.endpoint());
            let release = presence.releaser();
            let options = RunOptions { out_dir: args.out.clone(), ..RunOptions::default() };
            let limits = limits.clone();
            let verifier = verifier.clone();
            let hosting = tokio::task::spawn_blocking(move || {
                let registry = crate::builtin::registry();
                let authority = verifier.as_deref().zip(coordinator.as_deref());
                let policy = HostPolicy { limits: &limits, authority };
                host_run(&session, &plan, &registry, &reply, &options, policy, &release)
            });
            tokio::select! {
                hosted = hosting => match hosted {
                    Ok(Ok(h)) => eprintln!(
                        "squall worker: ran {} tasks of \"{}\"{}",
                        h.tasks,
                        h.topology,
                        if h.aborted { " (aborted)" } else { "" }
                    ),
                    Ok(Err(e)) => eprintln!("squall worker: the run ended: {e}"),
                    Err(e) => eprintln!("squall worker: the run's thread failed: {e}"),
                },
                reason = presence.stopped() => {
                    // Tasks may still be running: leave now rather than
                    // outlive the run.
                    report_stop(reason);
                    std::process::exit(i32::from(EXIT_FAILED));
                }
                _ = tokio::signal::ctrl_c() => {
                    eprintln!("squall worker: interrupted during a run");
                    std::process::exit(130);
                }
            }
        }
        let (too_large, malformed) = presence.rejections();
        if too_large + malformed > 0 {
            eprintln!("squall worker: refused {too_large} oversized and {malformed} malformed frames");
        }
        if let Some(v) = presence.verifier().filter(|v| v.refused() > 0) {
            eprintln!(
                "squall worker: refused {} control frames (unsigned, not from the authority, or from a coordinator not allowed)",
                v.refused()
            );
        }
        let _ = presence.session().close().await;
        ExitCode::SUCCESS
    })
}

/// The worker's limits from its flags; an error says which flag is wrong.
fn worker_limits(args: &WorkerArgs) -> Result<WorkerLimits, String> {
    let max_run = match args.max_run_secs {
        None => None,
        Some(s) => {
            Some(squall_topology::bounds::wait_secs("--max-run-secs", s, false).map_err(|e| e.to_string())?)
        }
    };
    let max_memory = match args.max_memory_mb {
        None => WorkerLimits::default().max_memory,
        Some(mb) => Some(
            squall_topology::bounds::count(
                "--max-memory-mb",
                mb,
                1,
                u64::MAX >> 20,
                "MiB, counted in bytes in 64 bits",
            )
            .map_err(|e| e.to_string())?
                << 20,
        ),
    };
    if args.max_tasks == 0 {
        return Err("--max-tasks 0: expected at least 1".into());
    }
    Ok(WorkerLimits {
        max_tasks: args.max_tasks,
        max_queued: args.max_queued,
        max_run,
        max_memory,
        insecure: args.insecure,
    })
}

/// The check of coordinators' signatures: with mutual TLS, against the
/// authority, allowing the names given (any, without names); without
/// TLS, none (and names are an error: coordinators are known by their
/// certificates).
fn coordinator_check(args: &WorkerArgs, tls: Option<&TlsSpec>) -> Result<Option<Verifier>, String> {
    let mut names: BTreeSet<String> = args.allow_coordinator.iter().cloned().collect();
    if let Some(file) = &args.allow_coordinators {
        let text = std::fs::read_to_string(file)
            .map_err(|e| format!("--allow-coordinators {}: {e}", file.display()))?;
        names.extend(
            text.lines()
                .map(|l| l.split('#').next().unwrap_or("").trim())
                .filter(|l| !l.is_empty())
                .map(str::to_string),
        );
    }
    let listed = !names.is_empty() || args.allow_coordinators.is_some();
    match tls {
        None if listed => Err("--allow-coordinator needs mutual TLS (--tls-ca, --tls-cert, --tls-key): \
                               coordinators are known by their certificate's common name"
            .into()),
        None => Ok(None),
        Some(tls) => {
            Verifier::load(&tls.root_ca, listed.then_some(names)).map(Some).map_err(|e| e.to_string())
        }
    }
}

fn report_stop(reason: StopReason) {
    match reason {
        StopReason::Told => eprintln!("squall worker: stopped by the coordinator"),
        StopReason::CoordinatorLost => eprintln!("squall worker: the coordinator is gone; stopping"),
    }
}
