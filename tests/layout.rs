//! The workspace's layout keeps its architecture: which crate may depend on
//! which, the generic particle filter naming no model, and no import cycles
//! between the modules of a crate. Read from the sources, so a change that
//! breaks a rule fails here with the offending file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The `squall-*` crates a manifest depends on, in any dependency table.
fn squall_dependencies(manifest: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(manifest).unwrap();
    let doc: toml::Table = text.parse().unwrap();
    ["dependencies", "dev-dependencies", "build-dependencies"]
        .iter()
        .filter_map(|t| doc.get(*t).and_then(|v| v.as_table()))
        .flat_map(|t| t.keys())
        .filter(|k| k.starts_with("squall-"))
        .cloned()
        .collect()
}

#[test]
fn each_crate_depends_only_on_the_layers_below_it() {
    let allowed: &[(&str, &[&str])] = &[
        ("topology", &[]),
        ("core", &["squall-topology"]),
        ("spouts", &["squall-core", "squall-topology"]),
        ("bolts", &["squall-core", "squall-topology"]),
    ];
    for (dir, may) in allowed {
        let found = squall_dependencies(&root().join(dir).join("Cargo.toml"));
        let may: BTreeSet<String> = may.iter().map(|s| s.to_string()).collect();
        let extra: Vec<_> = found.difference(&may).collect();
        assert!(extra.is_empty(), "{dir}/Cargo.toml depends on {extra:?}; it may depend on {may:?} only");
    }
}

/// Every `.rs` file under `src`, by module path (`lib.rs` and `mod.rs` name
/// their folder's module).
fn modules(src: &Path) -> BTreeMap<Vec<String>, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let rel = path.strip_prefix(src).unwrap().with_extension("");
                let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
                if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
                    parts.pop();
                }
                out.insert(parts, path);
            }
        }
    }
    out
}

/// The `crate::a::b…` paths a file names outside comments.
fn crate_paths(text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        for (i, _) in code.match_indices("crate::") {
            let after = &code[i + "crate::".len()..];
            let end = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                .unwrap_or(after.len());
            let path: Vec<String> =
                after[..end].split("::").take_while(|s| !s.is_empty()).map(str::to_string).collect();
            out.push(path);
        }
    }
    out
}

/// Edges between modules `depth` levels deep: (from, to, file that makes it).
fn module_edges(src: &Path, depth: usize) -> BTreeMap<(Vec<String>, Vec<String>), PathBuf> {
    let mods = modules(src);
    let mut edges = BTreeMap::new();
    for (module, file) in &mods {
        let text = std::fs::read_to_string(file).unwrap();
        for path in crate_paths(&text) {
            let target = (1..=path.len()).rev().map(|k| path[..k].to_vec()).find(|p| mods.contains_key(p));
            let Some(target) = target else { continue };
            if module.len() < depth || target.len() < depth {
                continue;
            }
            let (a, b) = (module[..depth].to_vec(), target[..depth].to_vec());
            if a != b {
                edges.entry((a, b)).or_insert_with(|| file.clone());
            }
        }
    }
    edges
}

/// A cycle among the edges, if any, as the files that close it.
fn find_cycle(edges: &BTreeMap<(Vec<String>, Vec<String>), PathBuf>) -> Option<Vec<String>> {
    let mut next: BTreeMap<&Vec<String>, Vec<&Vec<String>>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        next.entry(a).or_default().push(b);
    }
    for ((a, b), file) in edges {
        // Is `a` reachable from `b`?
        let mut seen = BTreeSet::new();
        let mut stack = vec![b];
        while let Some(x) = stack.pop() {
            if x == a {
                return Some(vec![format!("{} → {} ({})", a.join("::"), b.join("::"), file.display())]);
            }
            if seen.insert(x) {
                stack.extend(next.get(x).into_iter().flatten());
            }
        }
    }
    None
}

#[test]
fn modules_do_not_import_each_other_in_a_cycle() {
    // The engine's modules (squall-topology) are not held to this yet: its
    // component traits and its runtime name each other.
    for krate in ["core/src", "bolts/src", "spouts/src", "src"] {
        for depth in [1, 2] {
            let edges = module_edges(&root().join(krate), depth);
            if let Some(cycle) = find_cycle(&edges) {
                panic!("{krate}: modules import each other in a cycle, closed by {cycle:?}");
            }
        }
    }
}

#[test]
fn the_cycle_check_finds_a_cycle() {
    let mut edges = BTreeMap::new();
    let m = |s: &str| vec![s.to_string()];
    edges.insert((m("a"), m("b")), PathBuf::from("a.rs"));
    edges.insert((m("b"), m("c")), PathBuf::from("b.rs"));
    assert!(find_cycle(&edges).is_none());
    edges.insert((m("c"), m("a")), PathBuf::from("c.rs"));
    assert!(find_cycle(&edges).is_some());
    assert_eq!(
        crate_paths(
            "use crate::pf::kinds::{HostedModel, x}; // crate::slam\nlet a = crate::cgr::register(r);"
        ),
        vec![vec!["pf".to_string(), "kinds".into()], vec!["cgr".into(), "register".into()]]
    );
}

#[test]
fn the_generic_particle_filter_names_no_model() {
    let pf = root().join("bolts/src/pf");
    for file in modules(&pf).values() {
        let text = std::fs::read_to_string(file).unwrap();
        for path in crate_paths(&text) {
            let first = path.first().map(String::as_str);
            assert!(
                !matches!(first, Some("slam" | "cgr" | "parfil")),
                "{} names the model module crate::{}",
                file.display(),
                path.join("::")
            );
        }
    }
}
