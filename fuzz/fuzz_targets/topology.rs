//! A topology file and `--set` overrides, checked as `squall validate`
//! checks them: the input's lines after a line `%%` are overrides.
#![no_main]

use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;
use squall::topology::{Override, Registry, Topology};

/// Every built-in kind, built once rather than per input.
static KINDS: LazyLock<Registry> = LazyLock::new(squall::builtin::registry);

fuzz_target!(|input: &str| {
    let (text, sets) = input.split_once("\n%%\n").unwrap_or((input, ""));
    let overrides: Vec<Override> = sets.lines().filter_map(|line| line.parse().ok()).collect();
    let _ = Topology::from_text("fuzz.toml", text, &overrides, &KINDS);
});
