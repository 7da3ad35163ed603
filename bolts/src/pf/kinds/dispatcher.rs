//! `pf.dispatcher`: numbers the readings and hands them to every matcher
//! task, one at a time: the next goes out when the resampler reports the
//! last one done.
//!
//! Offline (`mode = "offline"`, the default) it holds its input while a
//! reading is out, so the source waits and nothing is dropped. Live
//! (`mode = "live"`) it keeps taking readings, keeps only the newest while
//! the matchers are busy and counts every reading it drops
//! (`dropped_readings`), as a robot streaming faster than the cluster
//! keeps up would need.
//! Metrics: `processed_scan_us` (wall time of each correcting reading,
//! from hand-out to every matcher done), `reading_us` (of each reading).

use std::collections::VecDeque;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Instant;

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, Message, ParamError, Params, Tuple};

use crate::pf::kinds::messages::{Reading, Ready};

/// How readings wait while the matchers are busy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Hold the source back: every reading is processed.
    #[default]
    Offline,
    /// Keep only the newest reading; count the drops.
    Live,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DispatcherParams {
    #[allow(dead_code)]
    model: String,
    #[serde(default)]
    mode: Mode,
}

/// The dispatcher for readings of type `I`.
#[derive(Debug)]
pub struct Dispatcher<I> {
    mode: Mode,
    next_step: u64,
    /// The reading out, and when it left.
    out: Option<(u64, Instant)>,
    /// Readings taken while one was out (offline: at most the rest of a
    /// batch the engine had already handed over; live: at most one).
    waiting: VecDeque<Arc<I>>,
    _input: PhantomData<fn(I)>,
}

impl<I: Message> Dispatcher<I> {
    /// Builds it from `mode` (and the `model` the kind was chosen by).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: DispatcherParams = p.parse()?;
        if p.parallelism() != 1 {
            return Err(ParamError::new("pf.dispatcher runs as one task (it numbers the readings)"));
        }
        Ok(Dispatcher {
            mode: params.mode,
            next_step: 0,
            out: None,
            waiting: VecDeque::new(),
            _input: PhantomData,
        })
    }

    async fn hand_out(&mut self, input: Arc<I>, out: &mut Emitter) -> Result<(), BoxError> {
        let step = self.next_step;
        self.next_step += 1;
        out.emit("reading", Reading { step, input }).await?;
        self.out = Some((step, Instant::now()));
        if self.mode == Mode::Offline {
            out.hold_inputs(true);
        }
        Ok(())
    }
}

impl<I: Message> Bolt for Dispatcher<I> {
    fn declare(&self, d: &mut Declarer) {
        d.input::<I>().input::<Ready>().output::<Reading<I>>("reading");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(ready) = input.get::<Ready>() {
            let Some((step, since)) = self.out.take() else {
                return Err(format!("pf.dispatcher: ready for reading {} with none out", ready.step).into());
            };
            if step != ready.step {
                return Err(
                    format!("pf.dispatcher: ready for reading {} while {step} is out", ready.step).into()
                );
            }
            let us = since.elapsed().as_micros() as u64;
            out.record("reading_us", us);
            if ready.corrected {
                out.record("processed_scan_us", us);
            }
            match self.waiting.pop_front() {
                Some(next) => self.hand_out(next, out).await?,
                None => out.hold_inputs(false),
            }
            return Ok(());
        }
        let reading = input.into_arc::<I>().map_err(|_| "pf.dispatcher takes readings and Ready")?;
        if self.out.is_none() {
            return self.hand_out(reading, out).await;
        }
        if self.mode == Mode::Live && !self.waiting.is_empty() {
            self.waiting.clear();
            out.count("dropped_readings", 1);
        }
        self.waiting.push_back(reading);
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        // Present in the metrics even when nothing was dropped.
        out.count("dropped_readings", 0);
        Ok(())
    }
}
