//! A topology file and `--set` overrides, checked as `squall validate`
//! checks them: the input's lines after a line `%%` are overrides.
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::topology::{Override, Topology, TopologySpec};

fuzz_target!(|input: &str| {
    let (text, sets) = input.split_once("\n%%\n").unwrap_or((input, ""));
    let overrides: Vec<Override> = sets.lines().filter_map(|line| line.parse().ok()).collect();
    if let Ok(spec) = TopologySpec::parse_with("fuzz.toml", text, &overrides) {
        let _ = Topology::validate(spec, &squall::builtin::registry());
    }
});
