//! Mutual TLS between cluster processes: a peer whose certificate does
//! not chain to the cluster's authority (or that has none) cannot join,
//! publish or read. Certificates are made for the test with `openssl`.
#![cfg(feature = "cluster")]

mod common;

use std::time::Duration;

use common::certs::{authority, tls};

use squall::topology::cluster::config::{Endpoint, Protocol, TlsSpec};
use squall::topology::cluster::session::{
    SessionError, SessionOptions, WorkerPresence, control_key, open, ping, reply_key, worker_key,
};
use squall::topology::cluster::wire::{Control, Frame};

fn free_endpoint() -> Endpoint {
    let port = common::free_port();
    Endpoint { protocol: Protocol::Tls, host: "127.0.0.1".into(), port }
}

#[test]
fn a_peer_without_the_clusters_certificate_cannot_join_publish_or_read() {
    let dir = tempfile::tempdir().unwrap();
    authority(dir.path(), "ca", &["worker", "coordinator"]);
    authority(dir.path(), "rogue_ca", &["rogue"]);
    let endpoint = free_endpoint();
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build().unwrap();
    runtime.block_on(async {
        let worker_options = SessionOptions {
            listen: vec![endpoint.clone()],
            connect: vec![],
            tls: Some(tls(dir.path(), "ca", "worker")),
            allow: None,
        };
        let worker = WorkerPresence::start(&worker_options, None).await.expect("the worker listens with TLS");
        let member = |name: &str, ca: &str| SessionOptions {
            listen: vec![],
            connect: vec![endpoint.clone()],
            tls: Some(tls(dir.path(), ca, name)),
            allow: None,
        };
        // A rogue peer that trusts the cluster's authority (its
        // certificate is public) but holds a certificate from another: the
        // worker must refuse it, and what it publishes does not arrive.
        let rogue_tls =
            TlsSpec { root_ca: dir.path().join("ca.pem"), ..tls(dir.path(), "rogue_ca", "rogue") };
        let rogue = open(&SessionOptions {
            listen: vec![],
            connect: vec![endpoint.clone()],
            tls: Some(rogue_tls),
            allow: None,
        })
        .await
        .unwrap();
        let refused = ping(&rogue, &endpoint, Duration::from_secs(2)).await;
        assert!(matches!(refused, Err(SessionError::NoAnswer { .. })), "{refused:?}");
        rogue.put(control_key(&endpoint), Frame::Control(Control::Stop).encode()).await.unwrap();
        let overheard = rogue.declare_subscriber(reply_key(&endpoint)).await.unwrap();
        // A member of the cluster is answered, and the worker is still
        // running: the rogue's Stop never reached it.
        let coordinator = open(&member("coordinator", "ca")).await.unwrap();
        let name =
            ping(&coordinator, &endpoint, Duration::from_secs(20)).await.expect("a member is answered");
        // The answer comes from the worker listening there, by its name.
        assert_eq!(name, worker_key(&endpoint));
        assert_eq!(name, format!("tls_127.0.0.1_{}", endpoint.port), "the worker's name is its endpoint");
        let stopped = tokio::time::timeout(Duration::from_millis(300), worker.stopped()).await;
        assert!(stopped.is_err(), "the worker stopped: {stopped:?}");
        // Nor did the rogue overhear the member's answer.
        let heard = tokio::time::timeout(Duration::from_millis(500), overheard.recv_async()).await;
        assert!(heard.is_err(), "the rogue read a reply");
        // A peer with no certificate at all gets nowhere either.
        let bare =
            open(&SessionOptions { listen: vec![], connect: vec![endpoint.clone()], tls: None, allow: None })
                .await;
        if let Ok(bare) = bare {
            let refused = ping(&bare, &endpoint, Duration::from_secs(2)).await;
            assert!(matches!(refused, Err(SessionError::NoAnswer { .. })), "{refused:?}");
        }
    });
}
