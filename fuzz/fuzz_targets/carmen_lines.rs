//! CARMEN log lines: every line of the input through one parser, as the
//! reader feeds a log (PARAM lines change how later scans parse).
#![no_main]

use libfuzzer_sys::fuzz_target;
use squall::spouts::carmen::LineParser;

fuzz_target!(|text: &str| {
    let mut parser = LineParser::new(80.0);
    for line in text.lines() {
        let _ = parser.parse(line);
    }
});
