//! The topology file as written, with source spans, before any checking.

use serde::Deserialize;
use toml::Spanned;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFile {
    pub(crate) topology: Spanned<RawTopology>,
    #[serde(default)]
    pub(crate) spout: Vec<Spanned<RawComponent>>,
    #[serde(default)]
    pub(crate) bolt: Vec<Spanned<RawComponent>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTopology {
    pub(crate) name: Spanned<String>,
    #[serde(default)]
    pub(crate) seed: Option<Spanned<i64>>,
    #[serde(default)]
    pub(crate) stall_secs: Option<Spanned<f64>>,
    #[serde(default)]
    pub(crate) memory_limit_mb: Option<Spanned<i64>>,
    #[serde(default)]
    pub(crate) execute_sample: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawComponent {
    pub(crate) name: Spanned<String>,
    pub(crate) kind: Spanned<String>,
    pub(crate) parallelism: Option<Spanned<i64>>,
    pub(crate) params: Option<Spanned<toml::Table>>,
    pub(crate) inputs: Option<Spanned<Vec<Spanned<RawInput>>>>,
    pub(crate) tick_secs: Option<Spanned<f64>>,
    pub(crate) restart: Option<Spanned<RawRestart>>,
    pub(crate) ack: Option<Spanned<RawAck>>,
    pub(crate) peer_queue: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInput {
    pub(crate) from: Spanned<String>,
    pub(crate) stream: Option<Spanned<String>>,
    pub(crate) grouping: Option<Spanned<String>>,
    pub(crate) fields: Option<Spanned<Vec<String>>>,
    pub(crate) queue: Option<Spanned<i64>>,
    pub(crate) policy: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) feedback: bool,
    pub(crate) batch: Option<Spanned<RawBatch>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBatch {
    pub(crate) max: Option<Spanned<i64>>,
    pub(crate) linger_us: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRestart {
    pub(crate) max_restarts: i64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAck {
    pub(crate) timeout_secs: Option<f64>,
    pub(crate) max_pending: Option<i64>,
    pub(crate) max_retries: Option<i64>,
}
