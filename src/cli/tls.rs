//! The mutual-TLS flags that cluster commands share.

use std::path::PathBuf;

use squall_topology::cluster::config::{Endpoint, TlsSpec, mismatched_endpoint};

#[derive(Debug, clap::Args)]
pub(super) struct TlsArgs {
    /// Mutual TLS: the certificate authority (with --tls-cert and
    /// --tls-key; endpoints are then tls/).
    #[arg(long, value_name = "FILE", requires_all = ["tls_cert", "tls_key"])]
    tls_ca: Option<PathBuf>,
    /// This process's certificate, signed by the authority.
    #[arg(long, value_name = "FILE", requires_all = ["tls_ca", "tls_key"])]
    tls_cert: Option<PathBuf>,
    /// This process's private key.
    #[arg(long, value_name = "FILE", requires_all = ["tls_ca", "tls_cert"])]
    tls_key: Option<PathBuf>,
}

impl TlsArgs {
    /// The TLS material, checked against `endpoints` (all tls/ with it,
    /// all tcp/ without); the error says what is wrong.
    pub(super) fn spec<'a>(
        &self,
        endpoints: impl IntoIterator<Item = &'a Endpoint>,
    ) -> Result<Option<TlsSpec>, String> {
        let tls = match (&self.tls_ca, &self.tls_cert, &self.tls_key) {
            (Some(ca), Some(cert), Some(key)) => {
                Some(TlsSpec { root_ca: ca.clone(), certificate: cert.clone(), private_key: key.clone() })
            }
            _ => None,
        };
        if let Some(missing) = tls.as_ref().and_then(TlsSpec::missing_file) {
            return Err(format!("no such file: {}", missing.display()));
        }
        if let Some(e) = mismatched_endpoint(endpoints, tls.is_some()) {
            let why = if tls.is_some() {
                "with --tls-ca, endpoints are tls/"
            } else {
                "tls/ needs --tls-ca, --tls-cert and --tls-key"
            };
            return Err(format!("{e}: {why}"));
        }
        Ok(tls)
    }
}
