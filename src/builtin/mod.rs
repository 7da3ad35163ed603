//! Every component kind the `squall` binary knows.

pub mod probe;
pub mod sink;
pub mod wordcount;

use squall_topology::Registry;

/// A registry with all built-in kinds. Library users add their own kinds to
/// it (or start from [`Registry::new`]).
pub fn registry() -> Registry {
    let mut r = Registry::new();
    probe::register(&mut r);
    wordcount::register(&mut r);
    sink::register(&mut r);
    squall_spouts::register(&mut r);
    squall_bolts::register(&mut r);
    r
}
