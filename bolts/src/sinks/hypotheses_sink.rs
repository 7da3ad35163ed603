//! `sink.hypotheses`: collects the filter's hypotheses (the modes of the
//! particle set at each corrected reading) and writes them as JSON lines,
//! `DIR/hypotheses.jsonl`, at the end (atomically).

use std::fmt::Write as _;
use std::path::PathBuf;

use squall_topology::fsio::write_atomic;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use crate::pf::modes::Hypotheses;

/// Writes one JSON object per reading: `{"stamp": s, "modes": [{"pose":
/// {"x", "y", "theta"}, "weight", "particles"}, ...]}`.
#[derive(Debug, Default)]
pub struct HypothesesSink {
    out: Option<PathBuf>,
    lines: String,
    count: u64,
}

impl HypothesesSink {
    /// Builds the sink (no params).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        if !p.table().is_empty() {
            return Err(ParamError::new("sink.hypotheses takes no params"));
        }
        if p.parallelism() != 1 {
            return Err(ParamError::new("sink.hypotheses writes one file: use parallelism 1"));
        }
        Ok(HypothesesSink::default())
    }
}

impl Bolt for HypothesesSink {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Hypotheses>();
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.out = ctx.out_dir().map(|d| d.join("hypotheses.jsonl"));
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        let h = input.get::<Hypotheses>().ok_or("sink.hypotheses takes Hypotheses")?;
        let _ = writeln!(self.lines, "{}", serde_json::to_string(h)?);
        self.count += 1;
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        out.count("hypotheses", self.count);
        if let Some(path) = &self.out {
            write_atomic(path, self.lines.as_bytes()).map_err(|e| format!("{}: {e}", path.display()))?;
        }
        Ok(())
    }
}
