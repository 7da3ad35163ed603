//! Ctrl-C and SIGTERM (how service managers and containers stop a
//! process), honoured at every stage of a command that runs something:
//! the first makes the process's stop request
//! ([`squall_topology::runtime::process_stop`]), which a run stops on
//! (its sources end, what they sent is finished within
//! [`STOP_DRAIN`](squall_topology::runtime::STOP_DRAIN), metrics.json
//! says "stopped") and which setup work polls (replaying a simulated
//! route, building observable scenes); the second exits at once, 130.

use std::sync::Mutex;

use squall_topology::runtime::{STOP_DRAIN, process_stop};

/// The child processes this one runs (`squall study`'s runs): the first
/// signal is passed on to them as SIGTERM, so each stops as a run stopped
/// on its own does; the second kills them before this process exits, so
/// no child outlives it.
static CHILDREN: Mutex<Vec<libc::pid_t>> = Mutex::new(Vec::new());

/// Sends `signal` to every child in [`CHILDREN`].
fn signal_children(signal: libc::c_int) {
    let children = CHILDREN.lock().unwrap_or_else(|e| e.into_inner());
    for &pid in children.iter() {
        // SAFETY: `kill` has no memory effects; `pid` is a child this
        // process started and has not reaped (it is released before).
        unsafe {
            libc::kill(pid, signal);
        }
    }
}

/// Counts `pid`, a child just started, among those a signal reaches; if
/// the stop was requested already, it is sent SIGTERM at once.
pub(super) fn adopt(pid: libc::pid_t) {
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner()).push(pid);
    if stopping() {
        // SAFETY: as in `signal_children`.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
    }
}

/// Forgets `pid`, before it is reaped (its id may then be reused).
pub(super) fn release(pid: libc::pid_t) {
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner()).retain(|&p| p != pid);
}

/// Watches for the signals from now on, on a thread of its own.
pub(super) fn install() {
    let spawned = std::thread::Builder::new().name("signals".into()).spawn(move || {
        let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_all().build() else { return };
        rt.block_on(async {
            let Some(name) = next_signal().await else { return };
            eprintln!(
                "\nstopping on {name}: the sources stop and what they sent is finished, within {} s \
                 (Ctrl-C again to abort)",
                STOP_DRAIN.as_secs()
            );
            process_stop().request();
            signal_children(libc::SIGTERM);
            if let Some(name) = next_signal().await {
                eprintln!("aborted on {name}");
                signal_children(libc::SIGKILL);
                std::process::exit(130);
            }
        });
    });
    if let Err(e) = spawned {
        tracing::warn!("cannot watch for Ctrl-C: {e}");
    }
}

/// Whether a signal has asked the process to stop.
pub(super) fn stopping() -> bool {
    process_stop().is_made()
}

/// The next Ctrl-C or SIGTERM, by name; `None` when neither can be
/// watched.
async fn next_signal() -> Option<&'static str> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => tokio::select! {
                r = tokio::signal::ctrl_c() => r.ok().map(|()| "Ctrl-C"),
                _ = term.recv() => Some("SIGTERM"),
            },
            Err(_) => tokio::signal::ctrl_c().await.ok().map(|()| "Ctrl-C"),
        }
    }
    #[cfg(not(unix))]
    {
        tokio::signal::ctrl_c().await.ok().map(|()| "Ctrl-C")
    }
}
