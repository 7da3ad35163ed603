//! Who sent a control frame, and whether it may.
//!
//! Mutual TLS authenticates every link: a peer without a certificate from
//! the cluster's authority gets none. But every holder of such a
//! certificate is alike to zenoh, and squall does not see which link a
//! message came over. So a coordinator signs what it tells a worker (a
//! plan, the stages of a run, stop) with the private key of its TLS
//! certificate and sends the certificate along ([`Signer`]); a worker
//! checks that the certificate chains to its authority, that the
//! signature is good, that the frame is fresh and addressed to it, and
//! that the certificate's common name is on its allowlist ([`Verifier`]).
//! A refusal names the identity it saw.

use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::cluster::config::TlsSpec;
use crate::cluster::wire::{Algorithm, Control, Frame, Signed, SignedBody};
use ring::rand::SystemRandom;
use ring::signature::{self, EcdsaKeyPair, Ed25519KeyPair, RsaKeyPair};
use rustls_pki_types::{CertificateDer, PrivateKeyDer, SignatureVerificationAlgorithm, UnixTime};

/// How far a signed frame's clock may be from the worker's.
pub const FRESH_FOR: Duration = Duration::from_secs(120);

/// A problem loading keys or certificates, or a refused frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IdentityError {
    /// A key or certificate file could not be read or parsed.
    #[error("{file}: {message}")]
    File {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// The frame was not signed, and this worker accepts signed ones only.
    #[error("an unsigned control frame: this worker takes control only from coordinators with a certificate")]
    Unsigned,
    /// The certificate does not chain to this worker's authority.
    #[error("a certificate that does not chain to this worker's authority: {0}")]
    Untrusted(String),
    /// The signature does not match the frame and the certificate.
    #[error("coordinator {name:?}: a bad signature")]
    BadSignature {
        /// The certificate's common name.
        name: String,
    },
    /// The certificate's name is not on the allowlist.
    #[error("coordinator {name:?} is not on this worker's --allow-coordinator list")]
    NotAllowed {
        /// The certificate's common name.
        name: String,
    },
    /// The frame is old, from the future, replayed, or for another worker.
    #[error("coordinator {name:?}: {why}")]
    Stale {
        /// The certificate's common name.
        name: String,
        /// What is wrong with it.
        why: String,
    },
    /// The signed body does not decode.
    #[error("a signed frame whose body does not decode: {0}")]
    Malformed(String),
}

fn file_error(file: &Path, message: impl std::fmt::Display) -> IdentityError {
    IdentityError::File { file: file.display().to_string(), message: message.to_string() }
}

/// The verification of a signature `algorithm`.
fn verification(algorithm: Algorithm) -> &'static dyn SignatureVerificationAlgorithm {
    match algorithm {
        Algorithm::EcdsaP256Sha256 => webpki::ring::ECDSA_P256_SHA256,
        Algorithm::EcdsaP384Sha384 => webpki::ring::ECDSA_P384_SHA384,
        Algorithm::Ed25519 => webpki::ring::ED25519,
        Algorithm::RsaPkcs1Sha256 => webpki::ring::RSA_PKCS1_2048_8192_SHA256,
    }
}

enum SigningKey {
    Ecdsa(EcdsaKeyPair, Algorithm),
    Ed25519(Ed25519KeyPair),
    Rsa(RsaKeyPair),
}

/// A coordinator's signing identity: its TLS certificate and key.
pub struct Signer {
    key: SigningKey,
    certificates: Vec<Vec<u8>>,
    rng: SystemRandom,
    counter: AtomicU64,
    name: String,
}

impl std::fmt::Debug for Signer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Signer").field("name", &self.name).finish_non_exhaustive()
    }
}

fn now_ms() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64)
}

fn read_certificates(file: &Path) -> Result<Vec<CertificateDer<'static>>, IdentityError> {
    let text = std::fs::read(file).map_err(|e| file_error(file, e))?;
    let certificates: Vec<_> = rustls_pemfile::certs(&mut text.as_slice())
        .collect::<Result<_, _>>()
        .map_err(|e| file_error(file, format!("not PEM certificates: {e}")))?;
    if certificates.is_empty() {
        return Err(file_error(file, "holds no PEM certificate"));
    }
    Ok(certificates)
}

/// The common name of a DER certificate.
pub fn common_name(der: &[u8]) -> Option<String> {
    let (_, cert) = x509_parser::parse_x509_certificate(der).ok()?;
    let name = cert.subject().iter_common_name().next()?.as_str().ok()?.to_string();
    Some(name)
}

impl Signer {
    /// The identity in `tls`: its certificate (chain) and private key
    /// (PKCS#8 ECDSA P-256 or P-384, Ed25519, or RSA).
    pub fn load(tls: &TlsSpec) -> Result<Signer, IdentityError> {
        let certificates = read_certificates(&tls.certificate)?;
        let name = common_name(&certificates[0])
            .ok_or_else(|| file_error(&tls.certificate, "its certificate has no common name"))?;
        let text = std::fs::read(&tls.private_key).map_err(|e| file_error(&tls.private_key, e))?;
        let key = rustls_pemfile::private_key(&mut text.as_slice())
            .map_err(|e| file_error(&tls.private_key, format!("not a PEM private key: {e}")))?
            .ok_or_else(|| file_error(&tls.private_key, "holds no PEM private key"))?;
        let rng = SystemRandom::new();
        let unsupported =
            || file_error(&tls.private_key, "expected an ECDSA P-256/P-384, Ed25519 or RSA key");
        let key = match &key {
            PrivateKeyDer::Pkcs8(der) => {
                let der = der.secret_pkcs8_der();
                let ecdsa =
                    |alg, tag| EcdsaKeyPair::from_pkcs8(alg, der, &rng).map(|k| SigningKey::Ecdsa(k, tag));
                ecdsa(&signature::ECDSA_P256_SHA256_ASN1_SIGNING, Algorithm::EcdsaP256Sha256)
                    .or_else(|_| {
                        ecdsa(&signature::ECDSA_P384_SHA384_ASN1_SIGNING, Algorithm::EcdsaP384Sha384)
                    })
                    .or_else(|_| Ed25519KeyPair::from_pkcs8_maybe_unchecked(der).map(SigningKey::Ed25519))
                    .or_else(|_| RsaKeyPair::from_pkcs8(der).map(SigningKey::Rsa))
                    .map_err(|_| unsupported())?
            }
            PrivateKeyDer::Pkcs1(der) => {
                SigningKey::Rsa(RsaKeyPair::from_der(der.secret_pkcs1_der()).map_err(|_| unsupported())?)
            }
            _ => return Err(unsupported()),
        };
        let signer = Signer {
            key,
            certificates: certificates.iter().map(|c| c.to_vec()).collect(),
            rng,
            // Grows across this process's runs and stays above what an
            // earlier process with the same session name sent.
            counter: AtomicU64::new(now_ms() << 20),
            name,
        };
        // The key must be the certificate's: a mismatch would sign
        // frames no worker accepts.
        let probe = signer.sign_bytes(b"squall key check")?;
        let cert = webpki::EndEntityCert::try_from(&certificates[0])
            .map_err(|e| file_error(&tls.certificate, format!("not a usable certificate: {e:?}")))?;
        cert.verify_signature(verification(signer.algorithm()), b"squall key check", &probe)
            .map_err(|_| file_error(&tls.private_key, "is not the key of the certificate"))?;
        Ok(signer)
    }

    /// The certificate's common name: how workers know this coordinator.
    pub fn name(&self) -> &str {
        &self.name
    }

    fn algorithm(&self) -> Algorithm {
        match &self.key {
            SigningKey::Ecdsa(_, alg) => *alg,
            SigningKey::Ed25519(_) => Algorithm::Ed25519,
            SigningKey::Rsa(_) => Algorithm::RsaPkcs1Sha256,
        }
    }

    fn sign_bytes(&self, bytes: &[u8]) -> Result<Vec<u8>, IdentityError> {
        let failed = |_| IdentityError::Malformed("the key could not sign".into());
        Ok(match &self.key {
            SigningKey::Ecdsa(k, _) => k.sign(&self.rng, bytes).map_err(failed)?.as_ref().to_vec(),
            SigningKey::Ed25519(k) => k.sign(bytes).as_ref().to_vec(),
            SigningKey::Rsa(k) => {
                let mut signature = vec![0; k.public().modulus_len()];
                k.sign(&signature::RSA_PKCS1_SHA256, &self.rng, bytes, &mut signature).map_err(failed)?;
                signature
            }
        })
    }

    /// `control`, signed for key `to` by `coordinator` (its session).
    pub fn sign(&self, to: &str, coordinator: &str, control: Control) -> Signed {
        let body = SignedBody {
            to: to.to_string(),
            coordinator: coordinator.to_string(),
            counter: self.counter.fetch_add(1, Ordering::SeqCst),
            issued_ms: now_ms(),
            control,
        };
        let body = postcard::to_stdvec(&body).expect("a control serializes");
        // A key that signed at load signs again.
        let signature = self.sign_bytes(&body).expect("the key signs");
        Signed { certificates: self.certificates.clone(), algorithm: self.algorithm(), body, signature }
    }
}

/// Why a control frame was refused, and, when it was authentic but its
/// coordinator is not allowed, what it said (so the worker can say no).
pub type Refusal = (IdentityError, Option<Control>);

/// A worker's check of signed control frames.
pub struct Verifier {
    anchors: Vec<rustls_pki_types::TrustAnchor<'static>>,
    /// Common names allowed; `None`: any certificate from the authority.
    allowed: Option<BTreeSet<String>>,
    /// The last counter taken from each coordinator session, per key.
    last: Mutex<HashMap<String, u64>>,
    /// Control frames refused so far.
    refused: AtomicU64,
}

impl std::fmt::Debug for Verifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Verifier").field("allowed", &self.allowed).finish_non_exhaustive()
    }
}

impl Verifier {
    /// Checks against the authority `root_ca` (a PEM file), allowing the
    /// common names `allowed` (`None`: any).
    pub fn load(root_ca: &Path, allowed: Option<BTreeSet<String>>) -> Result<Verifier, IdentityError> {
        let anchors = read_certificates(root_ca)?
            .iter()
            .map(|c| {
                webpki::anchor_from_trusted_cert(c)
                    .map(|a| a.to_owned())
                    .map_err(|e| file_error(root_ca, format!("not a usable authority: {e:?}")))
            })
            .collect::<Result<_, _>>()?;
        Ok(Verifier { anchors, allowed, last: Mutex::new(HashMap::new()), refused: AtomicU64::new(0) })
    }

    /// The coordinator's name and what it says from a control frame on
    /// key `to`: a signed frame that passes [`check`](Self::check); an
    /// unsigned one is refused. Each refusal is logged, with the identity
    /// seen, and counted.
    pub fn accept(&self, frame: Frame, to: &str) -> Option<(String, Control)> {
        self.accept_or_refusal(frame, to).ok()
    }

    /// As [`accept`](Self::accept), with the refusal, and what an
    /// authentic frame from a coordinator not allowed said (so that the
    /// worker can tell it no).
    pub fn accept_or_refusal(&self, frame: Frame, to: &str) -> Result<(String, Control), Box<Refusal>> {
        let checked = match frame {
            Frame::Signed(signed) => self.check(&signed, to).map_err(|e| {
                let authentic = matches!(e, IdentityError::NotAllowed { .. });
                let said = authentic.then(|| postcard::from_bytes::<SignedBody>(&signed.body).ok()).flatten();
                Box::new((e, said.map(|b| b.control)))
            }),
            _ => Err(Box::new((IdentityError::Unsigned, None))),
        };
        checked.inspect_err(|refused| {
            let (e, _) = &**refused;
            self.refused.fetch_add(1, Ordering::Relaxed);
            tracing::warn!("refused a control frame on {to}: {e}");
        })
    }

    /// Logs and counts a refusal found outside [`accept`](Self::accept).
    pub fn count_refusal(&self, why: &str) {
        self.refused.fetch_add(1, Ordering::Relaxed);
        tracing::warn!("refused a control frame: {why}");
    }

    /// Control frames refused so far.
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    /// The coordinator's name and what it says, if `signed` is a fresh
    /// frame for key `to`, signed by an allowed coordinator of this
    /// worker's authority; else why not.
    pub fn check(&self, signed: &Signed, to: &str) -> Result<(String, Control), IdentityError> {
        let untrusted = |why: String| IdentityError::Untrusted(why);
        let (leaf, rest) =
            signed.certificates.split_first().ok_or_else(|| untrusted("no certificate".into()))?;
        let leaf_der = CertificateDer::from(leaf.as_slice());
        let intermediates: Vec<CertificateDer<'_>> =
            rest.iter().map(|c| CertificateDer::from(c.as_slice())).collect();
        let cert = webpki::EndEntityCert::try_from(&leaf_der).map_err(|e| untrusted(format!("{e:?}")))?;
        cert.verify_for_usage(
            webpki::ALL_VERIFICATION_ALGS,
            &self.anchors,
            &intermediates,
            UnixTime::now(),
            webpki::KeyUsage::client_auth(),
            None,
            None,
        )
        .map_err(|e| untrusted(format!("{e:?}")))?;
        let name = common_name(leaf).unwrap_or_else(|| "(no common name)".to_string());
        cert.verify_signature(verification(signed.algorithm), &signed.body, &signed.signature)
            .map_err(|_| IdentityError::BadSignature { name: name.clone() })?;
        if self.allowed.as_ref().is_some_and(|a| !a.contains(&name)) {
            return Err(IdentityError::NotAllowed { name });
        }
        let body: SignedBody =
            postcard::from_bytes(&signed.body).map_err(|e| IdentityError::Malformed(e.to_string()))?;
        let stale = |why: String| IdentityError::Stale { name: name.clone(), why };
        if body.to != to {
            return Err(stale(format!("a frame for {:?}, received on {to:?}", body.to)));
        }
        let skew = now_ms().abs_diff(body.issued_ms);
        if skew > FRESH_FOR.as_millis() as u64 {
            return Err(stale(format!("a frame signed {} s away from this worker's clock", skew / 1000)));
        }
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        // Frames on one key arrive in the order they were signed.
        let seen = last.entry(format!("{name}/{}/{to}", body.coordinator)).or_insert(0);
        if body.counter <= *seen {
            return Err(stale("a frame already taken (replayed)".into()));
        }
        *seen = body.counter;
        Ok((name, body.control))
    }
}
