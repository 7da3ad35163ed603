//! Certificates made for a test with the `openssl` command.

use std::path::Path;
use std::process::Command;

use squall::topology::cluster::config::TlsSpec;

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("this test needs the openssl command (Debian package openssl)");
    assert!(out.status.success(), "openssl {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// Makes a certificate authority named `ca` and, signed by it, certificates for
/// each of `names` (valid for 127.0.0.1 and localhost).
pub(crate) fn authority(dir: &Path, ca: &str, names: &[&str]) {
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

/// The TLS material of `name`, trusting the authority `ca`.
pub(crate) fn tls(dir: &Path, ca: &str, name: &str) -> TlsSpec {
    TlsSpec {
        root_ca: dir.join(format!("{ca}.pem")),
        certificate: dir.join(format!("{name}.pem")),
        private_key: dir.join(format!("{name}.key")),
    }
}
