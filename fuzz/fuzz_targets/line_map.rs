//! A building line map, as `squall localize --map` and `squall sim --world`
//! take it: parsed, then the simulator's roadmap and the interior the
//! localizer's proposals are drawn from.
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::core::interior::{DEFAULT_OPENING, Interior};
use squall::core::linemap::LineMap;
use squall::spouts::sim::{ROADMAP_MARGIN, ROADMAP_SPACING, roadmap::roadmap};

fuzz_target!(|text: &str| {
    let Ok(map) = LineMap::parse("fuzz.txt", text) else { return };
    let _ = Interior::of(&map, DEFAULT_OPENING);
    let _ = roadmap(map, ROADMAP_SPACING, ROADMAP_MARGIN);
});
