//! Trajectory files (TUM) and ground-truth relations, as `squall eval`
//! reads them, then scored against each other: the first line picks
//! which, the rest is the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::core::eval::{map_frame, relations};
use squall::core::trajectory::Trajectory;

fuzz_target!(|input: &str| {
    let (kind, text) = input.split_once('\n').unwrap_or(("", input));
    if kind.starts_with('r') {
        let _ = relations::parse_relations("fuzz.relations", text);
    } else if let Ok(trajectory) = Trajectory::parse_tum("fuzz.tum", text) {
        let _ = map_frame::score(&trajectory, &trajectory);
    }
});
