//! Mutual TLS between cluster processes: a peer whose certificate does
//! not chain to the cluster's authority (or that has none) cannot join,
//! publish or read. Certificates are made for the test with `openssl`.
#![cfg(feature = "cluster")]

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use squall::topology::cluster::config::{Endpoint, Protocol, TlsSpec};
use squall::topology::cluster::session::{
    SessionError, SessionOptions, WorkerPresence, control_key, open, ping, reply_key,
};
use squall::topology::cluster::wire::{Control, Frame};

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("this test needs the openssl command (Debian package openssl)");
    assert!(out.status.success(), "openssl {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// A certificate authority named `ca` and, signed by it, certificates for
/// each of `names` (valid for 127.0.0.1 and localhost).
fn authority(dir: &Path, ca: &str, names: &[&str]) {
    let ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"];
    let (key, pem) = (format!("{ca}.key"), format!("{ca}.pem"));
    let mut args = vec!["req", "-x509"];
    args.extend(ec);
    args.extend(["-keyout", &key, "-out", &pem, "-days", "2", "-subj", "/CN=squall test CA"]);
    openssl(dir, &args);
    std::fs::write(dir.join("san.cnf"), "subjectAltName=IP:127.0.0.1,DNS:localhost\n").unwrap();
    for name in names {
        let (k, csr, cert) = (format!("{name}.key"), format!("{name}.csr"), format!("{name}.pem"));
        let subject = format!("/CN={name}");
        let mut args = vec!["req"];
        args.extend(ec);
        args.extend(["-keyout", &k, "-out", &csr, "-subj", &subject]);
        openssl(dir, &args);
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                &pem,
                "-CAkey",
                &key,
                "-CAcreateserial",
                "-out",
                &cert,
                "-days",
                "2",
            ]
            .into_iter()
            .chain(["-extfile", "san.cnf"])
            .collect::<Vec<_>>(),
        );
    }
}

fn tls(dir: &Path, ca: &str, name: &str) -> TlsSpec {
    TlsSpec {
        root_ca: dir.join(format!("{ca}.pem")),
        certificate: dir.join(format!("{name}.pem")),
        private_key: dir.join(format!("{name}.key")),
    }
}

fn free_endpoint() -> Endpoint {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
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
        };
        let mut worker = WorkerPresence::start(&worker_options).await.expect("the worker listens with TLS");
        let member = |name: &str, ca: &str| SessionOptions {
            listen: vec![],
            connect: vec![endpoint.clone()],
            tls: Some(tls(dir.path(), ca, name)),
        };
        // A rogue peer that trusts the cluster's authority (its
        // certificate is public) but holds a certificate from another: the
        // worker must refuse it, and what it publishes does not arrive.
        let rogue_tls =
            TlsSpec { root_ca: dir.path().join("ca.pem"), ..tls(dir.path(), "rogue_ca", "rogue") };
        let rogue =
            open(&SessionOptions { listen: vec![], connect: vec![endpoint.clone()], tls: Some(rogue_tls) })
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
        assert!(!name.is_empty());
        let stopped = tokio::time::timeout(Duration::from_millis(300), worker.stopped()).await;
        assert!(stopped.is_err(), "the worker stopped: {stopped:?}");
        // Nor did the rogue overhear the member's answer.
        let heard = tokio::time::timeout(Duration::from_millis(500), overheard.recv_async()).await;
        assert!(heard.is_err(), "the rogue read a reply");
        // A peer with no certificate at all gets nowhere either.
        let bare = open(&SessionOptions { listen: vec![], connect: vec![endpoint.clone()], tls: None }).await;
        if let Ok(bare) = bare {
            let refused = ping(&bare, &endpoint, Duration::from_secs(2)).await;
            assert!(matches!(refused, Err(SessionError::NoAnswer { .. })), "{refused:?}");
        }
    });
}
