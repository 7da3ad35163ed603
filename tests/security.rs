//! Secure by default: no process listens on or connects to a plain `tcp/`
//! endpoint beyond loopback unless told that the network is trusted
//! (`--insecure`, `insecure = true`), and then it says so at start and in
//! the run's metrics. Refusals come before anything listens or runs.
//!
//! Only loopback and a private network namespace are used: the tests that
//! need an address beyond loopback make one on the loopback device of a
//! namespace of their own (`unshare -rn`), which nothing outside reaches.
#![cfg(feature = "cluster")]

mod common;

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use common::{free_port, output_within};

/// How long a command may take before the test fails as hung.
const HUNG: Duration = Duration::from_secs(120);

fn squall(args: &[&str]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_squall"));
    command.current_dir(env!("CARGO_MANIFEST_DIR")).args(args);
    output_within(&mut command, HUNG, String::new)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Asserts that `out` is a refusal before the run (exit 2) of `endpoint`
/// that says how to set up mutual TLS and which opt-in exists.
fn assert_refused(out: &Output, endpoint: &str, opt_in: &str) {
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("{endpoint}: plain tcp/ beyond loopback, with no authentication")),
        "{stderr}"
    );
    assert!(stderr.contains("Use mutual TLS") && stderr.contains("docs/guide/security.md"), "{stderr}");
    assert!(stderr.contains(opt_in), "{stderr}");
}

#[test]
fn a_worker_refuses_to_listen_beyond_loopback_without_tls() {
    let port = free_port();
    for host in ["0.0.0.0", "192.0.2.7", "[::]"] {
        let endpoint = format!("tcp/{host}:{port}");
        let out = squall(&["worker", "--listen", &endpoint]);
        assert_refused(&out, &endpoint, "pass --insecure");
        assert!(!text(&out.stderr).contains("listening on"), "{}", text(&out.stderr));
    }
    // Nor does it connect to a plain peer beyond loopback.
    let out =
        squall(&["worker", "--listen", &format!("tcp/127.0.0.1:{port}"), "--connect", "tcp/192.0.2.7:7447"]);
    assert_refused(&out, "tcp/192.0.2.7:7447", "pass --insecure");
}

#[test]
fn a_coordinator_refuses_a_plain_worker_beyond_loopback_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lab.toml");
    let text_of = |insecure: &str| {
        format!(
            "[cluster]\nname = \"lab\"\n{insecure}\n[[worker]]\nname = \"big\"\nendpoint = \"tcp/192.0.2.7:7601\"\n"
        )
    };
    std::fs::write(&file, text_of("")).unwrap();
    let run = |file: &Path| {
        squall(&["run", "examples/topologies/probe.toml", "--quiet", "--cluster", file.to_str().unwrap()])
    };
    let out = run(&file);
    assert_refused(&out, "tcp/192.0.2.7:7601", "set `insecure = true` under [cluster]");
    assert!(text(&out.stderr).contains("lab.toml:4: worker \"big\""), "{}", text(&out.stderr));
}

#[test]
fn a_live_link_refuses_a_plain_endpoint_beyond_loopback_and_a_robot_too() {
    let endpoint = format!("tcp/0.0.0.0:{}", free_port());
    let out = squall(&[
        "run",
        "examples/topologies/live_slam.toml",
        "--set",
        &format!("source.params.listen=[\"{endpoint}\"]"),
    ]);
    assert_refused(&out, &endpoint, "set `insecure = true`");
    assert!(text(&out.stderr).contains("spout \"source\""), "{}", text(&out.stderr));
    let log = common::shared_data("laser/aces.clf");
    let out = squall(&["robot", "--log", &log, "--connect", "tcp/192.0.2.7:7447"]);
    assert_refused(&out, "tcp/192.0.2.7:7447", "pass --insecure");
}

/// Runs `script` with `sh` in a network namespace of its own whose
/// loopback device also carries 10.9.9.9, an address beyond loopback that
/// only this namespace has. Fails the test if such a namespace cannot be
/// made here.
fn in_private_network(script: &str) -> Output {
    let setup = "ip link set lo up && ip addr add 10.9.9.9/32 dev lo";
    let mut command = Command::new("unshare");
    command
        .args(["-rn", "sh", "-c", &format!("{setup} && {script}")])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("SQUALL", env!("CARGO_BIN_EXE_squall"));
    output_within(&mut command, HUNG, String::new)
}

#[test]
fn with_insecure_a_robot_and_its_live_link_talk_beyond_loopback_and_warn_at_start_and_in_the_metrics() {
    let out_dir = tempfile::tempdir().unwrap();
    let endpoint = "tcp/10.9.9.9:7447";
    let log = common::shared_data("laser/aces.clf");
    let script = format!(
        "\"$SQUALL\" run examples/topologies/live_slam.toml --quiet --out {out} \
           --set 'source.params.listen=[\"{endpoint}\"]' --set source.params.insecure=true \
           --set 'publish.params.listen=[\"{endpoint}\"]' --set publish.params.insecure=true \
           --set source.params.idle_secs=2.0 2> {out}/run.err & \
         \"$SQUALL\" robot --log {log} --connect {endpoint} --insecure --max-scans 20 --speed 5 --wait-secs 2; \
         robot=$?; wait $!; echo \"run=$? robot=$robot\"",
        out = out_dir.path().display(),
    );
    let done = in_private_network(&script);
    let (stdout, stderr) = (text(&done.stdout), text(&done.stderr));
    assert!(stdout.contains("run=0 robot=0"), "{stdout}\n{stderr}");
    let run_log = std::fs::read_to_string(out_dir.path().join("run.err")).unwrap();
    // The robot warned at start, and so did the run, once per component.
    assert!(stderr.contains(&format!("warning: insecure: {endpoint} is plain tcp/")), "{stderr}");
    for component in ["spout \"source\"", "bolt \"publish\""] {
        assert!(run_log.contains(&format!("{component}: insecure: {endpoint}")), "{run_log}");
    }
    let metrics = metrics_in(out_dir.path());
    let warnings: Vec<&str> =
        metrics["warnings"].as_array().unwrap().iter().filter_map(|w| w.as_str()).collect();
    let insecure: Vec<&&str> = warnings.iter().filter(|w| w.contains("insecure:")).collect();
    assert_eq!(insecure.len(), 2, "{warnings:?}");
    assert!(stdout.contains("poses received:"), "the robot got poses back: {stdout}");
}

#[test]
fn with_insecure_a_worker_and_its_coordinator_talk_beyond_loopback_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = dir.path().join("lab.toml");
    let file = "[cluster]\nname = \"lab\"\ninsecure = true\n\n[[worker]]\nname = \"big\"\n\
                endpoint = \"tcp/10.9.9.9:7601\"\n\n[placement]\nrelay = [\"big\"]\n";
    std::fs::write(&cluster, file).unwrap();
    // A worker outlives the runs it hosts: it is killed once the run is
    // over.
    let script = format!(
        "\"$SQUALL\" worker --listen tcp/10.9.9.9:7601 --insecure 2> {log} & \
         for i in $(seq 600); do grep -q 'listening on' {log} && break; sleep 0.1; done; \
         \"$SQUALL\" run examples/topologies/probe.toml --quiet --set source.params.count=2000 \
           --cluster {cluster} --out {out}; run=$?; kill $!; wait $!; cat {log} >&2; echo \"run=$run\"",
        log = dir.path().join("worker.err").display(),
        cluster = cluster.display(),
        out = dir.path().display(),
    );
    let done = in_private_network(&script);
    let (stdout, stderr) = (text(&done.stdout), text(&done.stderr));
    assert!(stdout.contains("run=0"), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("squall worker: WARNING: insecure: tcp/10.9.9.9:7601 is plain tcp/ beyond loopback"),
        "{stderr}"
    );
    assert!(stderr.contains("listening on tcp/10.9.9.9:7601"), "{stderr}");
    // The coordinator warned at start and in the run's metrics.
    assert!(stderr.contains("worker \"big\": insecure: tcp/10.9.9.9:7601"), "{stderr}");
    let metrics = metrics_in(dir.path());
    let warnings = metrics["warnings"].to_string();
    assert!(warnings.contains("worker \\\"big\\\": insecure: tcp/10.9.9.9:7601"), "{warnings}");
    let relay = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == "relay").unwrap();
    assert_eq!(relay["received"], 2000, "the relay on the worker got every probe");
}

/// A topology whose carmen source reads `log` into a counting sink, and a
/// cluster file placing the source on the one worker at `endpoint`.
fn carmen_on_worker(dir: &Path, log: &Path, endpoint: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let topology = dir.join("read.toml");
    let text = format!(
        "[topology]\nname = \"read\"\n\n[[spout]]\nname = \"source\"\nkind = \"carmen\"\n\
         params = {{ log = {:?} }}\n\n[[bolt]]\nname = \"count\"\nkind = \"sink.count\"\n\
         inputs = [ {{ from = \"source\", stream = \"scan\" }} ]\n",
        log.display().to_string()
    );
    std::fs::write(&topology, text).unwrap();
    let cluster = dir.join("lab.toml");
    let file = format!(
        "[cluster]\nname = \"lab\"\n\n[[worker]]\nname = \"w1\"\nendpoint = \"{endpoint}\"\n\n\
         [placement]\nsource = [\"w1\"]\n"
    );
    std::fs::write(&cluster, file).unwrap();
    (topology, cluster)
}

/// `squall worker` on a free loopback port with `args`, its stderr in
/// `log`; killed on drop.
struct Worker(std::process::Child, String);

impl Worker {
    fn start(args: &[&str], log: &Path) -> Worker {
        Worker::start_at(&format!("tcp/127.0.0.1:{}", free_port()), args, log)
    }

    /// `squall worker` on `endpoint`.
    fn start_at(endpoint: &str, args: &[&str], log: &Path) -> Worker {
        let child = Command::new(env!("CARGO_BIN_EXE_squall"))
            .args(["worker", "--listen", endpoint])
            .args(args)
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(log).unwrap())
            .spawn()
            .unwrap();
        Worker(child, endpoint.to_string())
    }
}

/// The metrics.json a run wrote into `dir`.
fn metrics_in(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap()
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn a_plan_reading_outside_the_data_dir_is_refused_and_nothing_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    // The file the plan names: a FIFO outside --data-dir. Opening it for
    // writing blocks until somebody opens it for reading, so the writer
    // below returns only if the worker ever opens it.
    let fifo = dir.path().join("system-file");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let (opened, was_opened) = std::sync::mpsc::channel();
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let _file = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
            let _ = opened.send(());
        })
    };
    let worker = Worker::start(&["--data-dir", data.to_str().unwrap()], &dir.path().join("w1.log"));
    let (topology, cluster) = carmen_on_worker(dir.path(), &fifo, &worker.1);
    let out = squall(&["run", topology.to_str().unwrap(), "--quiet", "--cluster", cluster.to_str().unwrap()]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("worker \"w1\" refused the run"), "{stderr}");
    assert!(stderr.contains(&format!("{}: outside this worker's --data-dir", fifo.display())), "{stderr}");
    assert!(stderr.contains("spout \"source\""), "the refusal names the component: {stderr}");
    // The worker never opened the file: the writer is still waiting.
    assert!(was_opened.try_recv().is_err(), "the worker opened the file outside its --data-dir");
    // Opening it here lets the writer go (a writer is waiting, so this
    // open does not block).
    let _reader = std::fs::File::open(&fifo).unwrap();
    writer.join().unwrap();
    assert!(was_opened.try_recv().is_ok());
    // The worker is still up and says why it refused.
    let log = std::fs::read_to_string(dir.path().join("w1.log")).unwrap();
    assert!(log.contains("outside this worker's --data-dir"), "{log}");
    drop(worker);
}

#[test]
fn a_plan_reading_under_the_data_dir_runs_on_the_worker() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    // The first 400 lines of the ACES log, under --data-dir.
    let aces = std::fs::read_to_string(common::shared_data("laser/aces.clf")).unwrap();
    let log = data.join("aces-head.clf");
    std::fs::write(&log, aces.lines().take(400).collect::<Vec<_>>().join("\n") + "\n").unwrap();
    let worker = Worker::start(&["--data-dir", data.to_str().unwrap()], &dir.path().join("w1.log"));
    let (topology, cluster) = carmen_on_worker(dir.path(), &log, &worker.1);
    let out_dir = dir.path().join("out");
    let out = squall(&[
        "run",
        topology.to_str().unwrap(),
        "--quiet",
        "--cluster",
        cluster.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let metrics = metrics_in(&out_dir);
    let count = metrics["components"].as_array().unwrap().iter().find(|c| c["name"] == "count").unwrap();
    assert!(count["received"].as_u64().unwrap() > 0, "{count}");
    drop(worker);
}

/// A cluster file with the one worker at `endpoint`, placing the probe's
/// relay tasks as `relay` says.
fn probe_cluster(dir: &Path, endpoint: &str, relay: &str) -> std::path::PathBuf {
    let cluster = dir.join("probe-lab.toml");
    let file = format!(
        "[cluster]\nname = \"lab\"\n\n[[worker]]\nname = \"w1\"\nendpoint = \"{endpoint}\"\n\n\
         [placement]\nrelay = {relay}\n"
    );
    std::fs::write(&cluster, file).unwrap();
    cluster
}

/// `squall run` on the probe topology with `sets` on `cluster`.
fn probe_run(cluster: &Path, sets: &[&str]) -> Output {
    let mut args =
        vec!["run", "examples/topologies/probe.toml", "--quiet", "--cluster", cluster.to_str().unwrap()];
    for set in sets {
        args.extend(["--set", set]);
    }
    squall(&args)
}

#[test]
fn a_worker_refuses_plans_past_its_task_and_queue_limits() {
    let dir = tempfile::tempdir().unwrap();
    let worker = Worker::start(&["--max-tasks", "1", "--max-queued", "4096"], &dir.path().join("w1.log"));
    let two = probe_cluster(dir.path(), &worker.1, "[\"w1\", \"w1\"]");
    let out = probe_run(&two, &["relay.parallelism=2"]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains(
            "refused the run: the plan places 2 tasks on this worker, past its limit of 1 (--max-tasks)"
        ),
        "{stderr}"
    );
    // One task, but its queue holds more than the worker allows.
    let one = probe_cluster(dir.path(), &worker.1, "[\"w1\"]");
    let out = probe_run(&one, &["relay.inputs.0.queue=8192"]);
    let stderr = text(&out.stderr);
    assert!(stderr.contains("up to 8192 tuples, past its limit of 4096 (--max-queued)"), "{stderr}");
    // Within both, the worker runs it.
    let out = probe_run(&one, &["source.params.count=5000"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    drop(worker);
}

#[test]
fn a_run_past_a_worker_s_time_or_memory_limit_fails_naming_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    // 3000 probes at 1 kHz take 3 s; the worker allows 1.
    let worker = Worker::start(&["--max-run-secs", "1"], &dir.path().join("w1.log"));
    let cluster = probe_cluster(dir.path(), &worker.1, "[\"w1\"]");
    let out = probe_run(&cluster, &["source.params.count=3000", "source.params.rate_hz=1000"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("worker limit: the run went past this worker's time limit of 1 s (--max-run-secs)"),
        "{stderr}"
    );
    drop(worker);
    // Any worker holds more than 1 MiB.
    let worker = Worker::start(&["--max-memory-mb", "1"], &dir.path().join("w2.log"));
    let cluster = probe_cluster(dir.path(), &worker.1, "[\"w1\"]");
    let out = probe_run(&cluster, &["source.params.count=3000", "source.params.rate_hz=1000"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("past its limit of 1 MiB (--max-memory-mb)"), "{stderr}");
    drop(worker);
}

#[test]
fn a_worker_hosts_an_unauthenticated_link_beyond_loopback_only_with_its_own_insecure() {
    // The plan allows it (`insecure = true`), the worker does not: the
    // plan is refused before anything listens.
    let dir = tempfile::tempdir().unwrap();
    let worker = Worker::start(&[], &dir.path().join("w1.log"));
    let cluster = dir.path().join("lab.toml");
    let file = format!(
        "[cluster]\nname = \"lab\"\n\n[[worker]]\nname = \"w1\"\nendpoint = \"{}\"\n\n\
         [placement]\nsource = [\"w1\"]\n",
        worker.1
    );
    std::fs::write(&cluster, file).unwrap();
    let endpoint = format!("tcp/0.0.0.0:{}", free_port());
    let out = squall(&[
        "run",
        "examples/topologies/live_slam.toml",
        "--quiet",
        "--set",
        &format!("source.params.listen=[\"{endpoint}\"]"),
        "--set",
        "source.params.insecure=true",
        "--cluster",
        cluster.to_str().unwrap(),
    ]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "worker \"w1\" refused the run: spout \"source\": insecure: {endpoint} is plain tcp/ beyond loopback"
        )),
        "{stderr}"
    );
    assert!(stderr.contains("hosts unauthenticated links only if started with --insecure"), "{stderr}");
    drop(worker);
}

#[test]
fn with_insecure_a_live_page_beyond_loopback_is_served_and_warned_of_in_the_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let script = format!(
        "\"$SQUALL\" run examples/topologies/wordcount.toml --quiet --ui 10.9.9.9:0 --insecure --out {}",
        dir.path().display()
    );
    let done = in_private_network(&script);
    let stderr = text(&done.stderr);
    assert!(done.status.success(), "{stderr}");
    assert!(stderr.contains("warning: insecure: --ui 10.9.9.9:0 serves the run beyond loopback"), "{stderr}");
    let metrics = metrics_in(dir.path());
    assert!(metrics["warnings"].to_string().contains("insecure: --ui 10.9.9.9:0"), "{}", metrics["warnings"]);
}

#[test]
fn a_signed_control_is_taken_once_for_its_key_from_an_allowed_coordinator_of_the_authority() {
    use squall::topology::cluster::identity::{IdentityError, Signer, Verifier};
    use squall::topology::cluster::wire::{Control, Frame};
    let dir = tempfile::tempdir().unwrap();
    common::certs::authority(dir.path(), "ca", &["coordinator", "intruder"]);
    common::certs::authority(dir.path(), "rogue_ca", &["rogue"]);
    let tls = |ca: &str, name: &str| common::certs::tls(dir.path(), ca, name);
    let signer = |ca: &str, name: &str| Signer::load(&tls(ca, name)).unwrap();
    let (coordinator, intruder, rogue) =
        (signer("ca", "coordinator"), signer("ca", "intruder"), signer("rogue_ca", "rogue"));
    assert_eq!(coordinator.name(), "coordinator");
    let allowed = ["coordinator".to_string()].into_iter().collect();
    let verifier = Verifier::load(&dir.path().join("ca.pem"), Some(allowed)).unwrap();
    let signed = |s: &Signer, to: &str| Frame::Signed(Box::new(s.sign(to, "session-1", Control::Stop)));
    let refusal = |frame: Frame, to: &str| verifier.accept_or_refusal(frame, to).unwrap_err().0.clone();

    let frame = signed(&coordinator, "squall/control/w1");
    assert_eq!(
        verifier.accept(frame.clone(), "squall/control/w1"),
        Some(("coordinator".into(), Control::Stop))
    );
    // Taken once: the same frame again is a replay.
    assert!(matches!(refusal(frame, "squall/control/w1"), IdentityError::Stale { .. }));
    // Signed for another worker's key.
    let elsewhere = refusal(signed(&coordinator, "squall/control/w2"), "squall/control/w1");
    assert!(elsewhere.to_string().contains("a frame for \"squall/control/w2\""), "{elsewhere}");
    // From the authority, but not on the allowlist.
    let not_allowed = refusal(signed(&intruder, "squall/control/w1"), "squall/control/w1");
    assert_eq!(not_allowed, IdentityError::NotAllowed { name: "intruder".into() });
    assert!(
        not_allowed.to_string().contains("\"intruder\" is not on this worker's --allow-coordinator list")
    );
    // From another authority.
    assert!(matches!(
        refusal(signed(&rogue, "squall/control/w1"), "squall/control/w1"),
        IdentityError::Untrusted(_)
    ));
    // Unsigned.
    assert_eq!(refusal(Frame::Control(Control::Stop), "squall/control/w1"), IdentityError::Unsigned);
    // Altered after signing.
    let Frame::Signed(mut altered) = signed(&coordinator, "squall/control/w1") else { unreachable!() };
    let last = altered.body.len() - 1;
    altered.body[last] ^= 1;
    assert!(matches!(
        refusal(Frame::Signed(altered), "squall/control/w1"),
        IdentityError::BadSignature { .. }
    ));
    assert_eq!(verifier.refused(), 6, "every refusal is counted");
    // A key that is not the certificate's is refused when it is loaded.
    let mismatched = squall::topology::cluster::config::TlsSpec {
        private_key: dir.path().join("intruder.key"),
        ..tls("ca", "coordinator")
    };
    let e = Signer::load(&mismatched).unwrap_err();
    assert!(e.to_string().contains("is not the key of the certificate"), "{e}");
}

#[test]
fn a_worker_takes_plans_only_from_the_coordinators_it_allows_and_names_the_others() {
    let dir = tempfile::tempdir().unwrap();
    common::certs::authority(dir.path(), "ca", &["worker", "coordinator", "intruder"]);
    let file = |name: &str| dir.path().join(name).display().to_string();
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let log = dir.path().join("w1.log");
    let (ca, cert, key) = (file("ca.pem"), file("worker.pem"), file("worker.key"));
    let args =
        ["--allow-coordinator", "coordinator", "--tls-ca", &ca, "--tls-cert", &cert, "--tls-key", &key];
    let mut worker = Worker::start_at(&endpoint, &args, &log);
    let cluster = |name: &str| {
        let path = dir.path().join(format!("{name}.toml"));
        let text = format!(
            "[cluster]\nname = \"lab\"\n\n[[worker]]\nname = \"w1\"\nendpoint = \"{endpoint}\"\n\n\
             [tls]\nroot_ca = \"ca.pem\"\ncertificate = \"{name}.pem\"\nprivate_key = \"{name}.key\"\n"
        );
        std::fs::write(&path, text).unwrap();
        path
    };
    // Every worker gets the plan (and accepts or refuses it), whatever it
    // hosts; here it hosts no task, so a worker-token flap under load
    // (decision 0033), which this test is not about, cannot fail the run.
    let allowed = probe_run(&cluster("coordinator"), &["source.params.count=2000"]);
    let worker_log = || std::fs::read_to_string(&log).unwrap_or_default();
    assert!(allowed.status.success(), "{}\n--- worker ---\n{}", text(&allowed.stderr), worker_log());
    let intruder = probe_run(&cluster("intruder"), &["source.params.count=2000"]);
    let stderr = text(&intruder.stderr);
    assert!(!intruder.status.success(), "{stderr}");
    assert!(
        stderr.contains("worker \"w1\" refused the run: coordinator \"intruder\" is not on this worker's --allow-coordinator list"),
        "{stderr}"
    );
    // Interrupted, the worker says what it refused.
    let stopped = Command::new("kill").args(["-INT", &worker.0.id().to_string()]).status().unwrap();
    assert!(stopped.success());
    worker.0.wait().unwrap();
    let log = std::fs::read_to_string(&log).unwrap();
    assert!(
        log.contains("coordinator \"intruder\" is not on this worker's --allow-coordinator list"),
        "{log}"
    );
    assert!(log.contains("hosting run") && log.contains("of coordinator \"coordinator\""), "{log}");
    assert!(log.contains("refused 1 control frames"), "{log}");
}

#[test]
fn an_allowlist_without_tls_is_refused_before_the_worker_listens() {
    let out = squall(&[
        "worker",
        "--listen",
        &format!("tcp/127.0.0.1:{}", free_port()),
        "--allow-coordinator",
        "lab",
    ]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--allow-coordinator needs mutual TLS"), "{stderr}");
    assert!(!stderr.contains("listening on"), "{stderr}");
}
