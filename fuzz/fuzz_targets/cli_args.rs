//! A command line, one argument a line, parsed and checked as `squall`
//! does before it runs anything: clap's parsing and every flag's bound
//! (`squall::cli::check_args`). Nothing runs.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &str| {
    let _ = squall::cli::check_args(input.lines());
});
