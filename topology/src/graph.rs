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
                .map_or("?", |s| short_type(s.message.name()));
            let style = if input.feedback { ", style=dashed" } else { "" };
            let _ = writeln!(
                dot,
                "  \"{}\" -> \"{}\" [label=\"{}: {}\\n{}\"{style}];",
                q(&input.from),
                q(&c.spec.name),
                q(&input.stream),
                q(ty),
                q(&input.grouping.to_string())
            );
        }
        if let Some(peer) = c.declared.peer_type() {
            let _ = writeln!(
                dot,
                "  \"{}\" -> \"{}\" [label=\"peer: {}\", style=dotted];",
                q(&c.spec.name),
                q(&c.spec.name),
                q(short_type(peer.name()))
            );
        }
    }
    dot.push_str("}\n");
    dot
}

/// `a::b::Type<c::D>` → `Type<D>`.
fn short_type(name: &'static str) -> &'static str {
    let generic = name.find('<').unwrap_or(name.len());
    match name[..generic].rfind("::") {
        Some(i) => &name[i + 2..],
        None => name,
    }
}
