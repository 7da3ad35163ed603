//! Graphviz rendering of a topology.

use std::fmt::Write;

use crate::plan::Topology;
use crate::spec::Role;

/// The topology as a Graphviz DOT digraph: spouts as ellipses, bolts as
/// boxes (kind and parallelism shown), edges labelled with stream, type and
/// grouping; feedback edges dashed.
pub fn to_dot(topology: &Topology) -> String {
    let mut dot = String::new();
    let q = |s: &str| s.replace('\\', "\\\\").replace('"', "\\\"");
    let _ = writeln!(dot, "digraph \"{}\" {{", q(topology.name()));
    let _ = writeln!(dot, "  rankdir=LR;");
    let _ = writeln!(dot, "  node [fontname=\"Helvetica\"];");
    let _ = writeln!(dot, "  edge [fontname=\"Helvetica\", fontsize=10];");
    for c in &topology.components {
        let shape = if c.spec.role == Role::Spout { "ellipse" } else { "box" };
        let _ = writeln!(
            dot,
            "  \"{}\" [shape={shape}, label=\"{}\\n{} ×{}\"];",
            q(&c.spec.name),
            q(&c.spec.name),
            q(&c.spec.kind),
            c.spec.parallelism
        );
    }
    for c in &topology.components {
        for input in &c.spec.inputs {
            let ty = topology
                .declared(&input.from)
                .and_then(|d| d.stream(&input.stream))
                .map_or_else(|| "?".to_string(), |s| short_type(s.message.name()));
            let style = if input.feedback { ", style=dashed" } else { "" };
            let _ = writeln!(
                dot,
                "  \"{}\" -> \"{}\" [label=\"{}: {}\\n{}\"{style}];",
                q(&input.from),
                q(&c.spec.name),
                q(&input.stream),
                q(&ty),
                q(&input.grouping.to_string())
            );
        }
        if let Some(peer) = c.declared.peer_type() {
            let _ = writeln!(
                dot,
                "  \"{}\" -> \"{}\" [label=\"peer: {}\", style=dotted];",
                q(&c.spec.name),
                q(&c.spec.name),
                q(&short_type(peer.name()))
            );
        }
    }
    dot.push_str("}\n");
    dot
}

/// `a::b::Type<c::D, e::F>` → `Type<D, F>`: every path in a type name
/// shortened to its last segment, generic arguments included.
fn short_type(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut segment_start = 0;
    for (i, c) in name.char_indices() {
        if c.is_alphanumeric() || c == '_' || c == ':' {
            continue;
        }
        out.push_str(last_segment(&name[segment_start..i]));
        out.push(c);
        segment_start = i + c.len_utf8();
    }
    out.push_str(last_segment(&name[segment_start..]));
    out
}

/// `a::b::Type` → `Type`.
fn last_segment(path: &str) -> &str {
    path.rfind("::").map_or(path, |i| &path[i + 2..])
}

#[cfg(test)]
mod tests {
    use super::short_type;

    #[test]
    fn type_names_lose_their_paths_generics_included() {
        assert_eq!(short_type("u64"), "u64");
        assert_eq!(short_type("squall_core::sensor::LaserReading"), "LaserReading");
        assert_eq!(
            short_type(
                "squall_bolts::slam::Transfer<squall_bolts::slam::model::SlamParticle, alloc::vec::Vec<u8>>"
            ),
            "Transfer<SlamParticle, Vec<u8>>"
        );
        assert_eq!(short_type("(alloc::string::String, [f64; 3], &str)"), "(String, [f64; 3], &str)");
    }
}
