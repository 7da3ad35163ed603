//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

#[cfg(feature = "cluster")]
pub(crate) mod certs;
pub(crate) mod cluster;

/// A file of the shared data set (`../shared/data` beside the repository),
/// as a path string; fails the test, saying so, if it is missing.
pub(crate) fn shared_data(rel: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    assert!(
        path.exists(),
        "missing {}: this test reads the shared data set (../shared/data beside the repository)",
        path.display()
    );
    path.to_string_lossy().into_owned()
}

/// A loopback TCP port nothing listens on, never the same twice in this
/// test process: tests run in parallel, and the operating system may hand
/// a port it just freed to the next test before the first test's server
/// has bound it, which would put two tests' servers on one port.
pub(crate) fn free_port() -> u16 {
    static GIVEN: std::sync::Mutex<Vec<u16>> = std::sync::Mutex::new(Vec::new());
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        if !given.contains(&port) {
            given.push(port);
            return port;
        }
    }
}

/// Waits for `child` (spawned with piped stdout and stderr) to end, for at
/// most `limit`. A run that outlives it is killed and the test fails with
/// what it printed and `context()` (the workers' logs, say): a hung run
/// must fail the suite in minutes, not hold it until CI's limit.
pub(crate) fn finish_within(
    mut child: std::process::Child,
    limit: std::time::Duration,
    context: impl FnOnce() -> String,
) -> std::process::Output {
    use std::io::Read;
    fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<Vec<u8>> {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_end(&mut bytes);
            }
            bytes
        })
    }
    let (stdout, stderr) = (drain(child.stdout.take()), drain(child.stderr.take()));
    let deadline = std::time::Instant::now() + limit;
    let status = loop {
        if let Some(status) = child.try_wait().expect("the child can be waited on") {
            break Some(status);
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (stdout, stderr) = (stdout.join().unwrap(), stderr.join().unwrap());
    match status {
        Some(status) => std::process::Output { status, stdout, stderr },
        None => panic!(
            "still running after {limit:?}, killed; it printed:\n{}\n{}\n{}",
            String::from_utf8_lossy(&stdout),
            String::from_utf8_lossy(&stderr),
            context()
        ),
    }
}

/// Runs `command` to its end with stdout and stderr captured, at most
/// `limit` (see [`finish_within`]).
pub(crate) fn output_within(
    command: &mut std::process::Command,
    limit: std::time::Duration,
    context: impl FnOnce() -> String,
) -> std::process::Output {
    use std::process::Stdio;
    let child = command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the command starts");
    finish_within(child, limit, context)
}

/// Polls `ready` every 20 ms until it holds; fails the test with `what`
/// and `context()` (what the process printed so far) if it does not within
/// `limit`.
pub(crate) fn wait_for(
    what: &str,
    limit: std::time::Duration,
    mut ready: impl FnMut() -> bool,
    context: impl Fn() -> String,
) {
    let deadline = std::time::Instant::now() + limit;
    while !ready() {
        assert!(std::time::Instant::now() < deadline, "waited {limit:?} for {what}; so far:\n{}", context());
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The filter that makes `squall` log its progress (`N tuples from
/// spouts`, once a second, when stderr is not a terminal) and otherwise
/// what it logs by default.
pub(crate) const LOG_PROGRESS: &str =
    "warn,zenoh::net::runtime::orchestrator=error,squall::cli::progress=info";

/// The highest count of tuples from spouts that a run logged with
/// [`LOG_PROGRESS`] in `stderr`.
pub(crate) fn logged_progress(stderr: &str) -> Option<u64> {
    stderr
        .lines()
        .filter_map(|l| l.split_once(" tuples from spouts"))
        .filter_map(|(before, _)| before.rsplit(' ').next()?.parse().ok())
        .max()
}

/// The relation error (m) of the trajectory file `trajectory` against
/// `relations`, as `squall eval --json` reports it.
pub(crate) fn relation_error(trajectory: &std::path::Path, relations: &std::path::Path) -> f64 {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["eval", "--trajectory"])
        .arg(trajectory)
        .arg("--relations")
        .arg(relations)
        .arg("--json")
        .output()
        .expect("squall eval runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    report["trans_mean"].as_f64().unwrap_or_else(|| panic!("{report}"))
}

/// Whether process `pid` has installed a handler for signal `number`
/// (its bit in the caught-signals mask of Linux's /proc/PID/status).
pub(crate) fn catches(pid: u32, number: u32) -> bool {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (number - 1)) != 0)
}
