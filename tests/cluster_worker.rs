//! `squall worker` as a real process: a coordinator's session reaches it
//! over TCP on loopback, sees its liveliness token, and sees the token go
//! when the process is killed.
#![cfg(feature = "cluster")]

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use squall::topology::cluster::config::{Endpoint, Protocol};
use squall::topology::cluster::session::{SessionOptions, open, ping, watch_workers, worker_key};

fn free_endpoint() -> Endpoint {
    let port = common::free_port();
    Endpoint { protocol: Protocol::Tcp, host: "127.0.0.1".into(), port }
}

/// A `squall worker` process on a free loopback port, and a runtime for
/// the test's coordinator.
fn worker(stderr: Stdio) -> (Endpoint, std::process::Child, tokio::runtime::Runtime) {
    let endpoint = free_endpoint();
    let child = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["worker", "--listen", &endpoint.to_string()])
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .expect("squall worker starts");
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build().unwrap();
    (endpoint, child, runtime)
}

#[test]
fn a_killed_worker_is_seen_to_go() {
    let (endpoint, mut child, runtime) = worker(Stdio::null());
    let outcome = runtime.block_on(async {
        let options = SessionOptions { connect: vec![endpoint.clone()], ..SessionOptions::default() };
        let coordinator = open(&options).await.unwrap();
        let mut presence = watch_workers(&coordinator).await.unwrap();
        let name = ping(&coordinator, &endpoint, Duration::from_secs(20)).await.expect("the worker answers");
        assert_eq!(name, worker_key(&endpoint));
        let seen = tokio::time::timeout(Duration::from_secs(10), presence.recv()).await;
        assert_eq!(seen.unwrap(), Some((worker_key(&endpoint), true)));
        child.kill().unwrap();
        let started = std::time::Instant::now();
        let gone = tokio::time::timeout(Duration::from_secs(15), presence.recv()).await;
        (gone, started.elapsed())
    });
    let _ = child.wait();
    let (gone, after) = outcome;
    assert_eq!(gone.expect("the token goes within 15 s"), Some((worker_key(&endpoint), false)));
    eprintln!("worker's departure seen after {:.2} s", after.as_secs_f64());
}

#[test]
fn a_worker_with_a_bad_endpoint_says_what_was_expected() {
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["worker", "--listen", "127.0.0.1:7447"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("expected tcp/HOST:PORT or tls/HOST:PORT"), "{stderr}");
    let out = Command::new(env!("CARGO_BIN_EXE_squall"))
        .args(["worker", "--listen", "tls/127.0.0.1:7447"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("tls/ needs --tls-ca, --tls-cert and --tls-key"), "{stderr}");
}
