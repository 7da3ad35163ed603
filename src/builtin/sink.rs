//! `sink.count`: accepts any stream and counts tuples per source stream
//! (custom metrics `tuples.<component>.<stream>`). For trying out sources and
//! measuring what a topology delivers.

use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Registry, Tuple};

/// Registers `sink.count`.
pub fn register(r: &mut Registry) {
    r.register_bolt("sink.count", |p: &Params| match p.table().keys().next() {
        None => Ok(CountSink),
        Some(k) => Err(ParamError::new(format!("unknown parameter `{k}` (this kind takes none)"))),
    });
}

/// Counts what it receives.
#[derive(Debug)]
pub struct CountSink;

impl Bolt for CountSink {
    fn declare(&self, d: &mut Declarer) {
        d.any_input();
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let name = match (input.source_component(), input.stream()) {
            (Some(c), Some(s)) => format!("tuples.{c}.{s}"),
            _ => "tuples.peer".to_string(),
        };
        out.count(&name, 1);
        Ok(())
    }
}
