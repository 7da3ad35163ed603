//! Registering your own component kinds and running a TOML topology with
//! them, next to the built-in kinds.
//!
//!     cargo run --example custom_kind
//!
//! A `ticks` spout emits readings of a few sensors; a `threshold` bolt of our
//! own keeps readings above a limit (its parameter); the built-in-style
//! `alarm` bolt, keyed by sensor with a fields grouping, counts alarms.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use squall::topology::{
    Bolt, BoxError, Declarer, Emitter, Params, RunOptions, Spout, SpoutStatus, Topology, TopologySpec, Tuple,
    run,
};

/// One sensor reading.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Reading {
    sensor: String,
    value: f64,
}

/// Emits `count` readings cycling over eight sensors.
struct Readings {
    count: u64,
    next: u64,
}

impl Spout for Readings {
    fn declare(&self, d: &mut Declarer) {
        d.output::<Reading>("readings");
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.next == self.count {
            return Ok(SpoutStatus::Done);
        }
        let sensor = format!("s{}", self.next % 8);
        let value = (self.next % 10) as f64;
        out.emit("readings", Reading { sensor, value }).await?;
        self.next += 1;
        Ok(SpoutStatus::Continue)
    }
}

/// Passes on readings above `limit`.
struct Threshold {
    limit: f64,
}

impl Bolt for Threshold {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Reading>().output::<Reading>("alarms");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let r = input.get::<Reading>().ok_or("expected a Reading")?;
        if r.value > self.limit {
            out.emit("alarms", r.clone()).await?;
        }
        Ok(())
    }
}

/// Counts alarms per sensor and prints them at the end.
#[derive(Default)]
struct Alarms {
    per_sensor: BTreeMap<String, u64>,
    task: usize,
}

impl Bolt for Alarms {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Reading>();
    }

    async fn prepare(&mut self, ctx: &squall::topology::TaskContext) -> Result<(), BoxError> {
        self.task = ctx.task_index();
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        let r = input.get::<Reading>().ok_or("expected a Reading")?;
        *self.per_sensor.entry(r.sensor.clone()).or_default() += 1;
        Ok(())
    }

    async fn finish(&mut self, _out: &mut Emitter) -> Result<(), BoxError> {
        for (sensor, n) in &self.per_sensor {
            println!("alarm task {}: sensor {sensor}: {n} alarms", self.task);
        }
        Ok(())
    }
}

const TOPOLOGY: &str = r#"
[topology]
name = "alarms"

[[spout]]
name = "sensors"
kind = "example.readings"
params = { count = 1000 }

[[bolt]]
name = "threshold"
kind = "example.threshold"
parallelism = 2
params = { limit = 7.5 }
inputs = [ { from = "sensors", stream = "readings" } ]

[[bolt]]
name = "alarm"
kind = "example.alarms"
parallelism = 2
inputs = [ { from = "threshold", stream = "alarms", grouping = "fields", fields = ["sensor"] } ]
"#;

fn main() -> anyhow::Result<()> {
    // Start from the built-in kinds and add ours.
    let mut registry = squall::builtin::registry();
    registry.register_spout("example.readings", |p: &Params| {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct P {
            count: u64,
        }
        let P { count } = p.parse()?;
        Ok(Readings { count, next: 0 })
    });
    registry.register_bolt("example.threshold", |p: &Params| {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct P {
            limit: f64,
        }
        let P { limit } = p.parse()?;
        Ok(Threshold { limit })
    });
    registry.register_bolt("example.alarms", |_: &Params| Ok(Alarms::default()));

    let spec = TopologySpec::parse("alarms.toml", TOPOLOGY)?;
    let topology = Topology::validate(spec, &registry)?;
    let report = run(&topology, &RunOptions::default())?;
    print!("{report}");
    Ok(())
}
