//! `--set PATH=VALUE`: edits a topology before it is parsed.
//!
//! PATH starts with `topology` or a component's name and addresses any value
//! below it: `matcher.parallelism`, `matcher.params.particles`,
//! `matcher.inputs.0.queue`, `topology.seed`. The edit is made on the
//! document itself (format preserved), so errors still point at the user's
//! lines.

use std::fmt;
use std::str::FromStr;

use toml_edit::{DocumentMut, Item, TableLike, Value};

/// Keys a component table may hold (the file contract).
const COMPONENT_KEYS: &[&str] =
    &["name", "kind", "parallelism", "params", "inputs", "tick_secs", "restart", "ack", "peer_queue"];
const INPUT_KEYS: &[&str] = &["from", "stream", "grouping", "fields", "queue", "policy", "feedback", "batch"];
const TOPOLOGY_KEYS: &[&str] = &["name", "seed", "stall_secs", "memory_limit_mb", "execute_sample"];

/// Why an override could not be read or applied.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OverrideError {
    /// The argument has no `=`.
    #[error("--set {0}: expected PATH=VALUE, e.g. matcher.parallelism=4")]
    NoEquals(String),
    /// PATH is not `COMPONENT.KEY[.KEY...]` or `topology.KEY`.
    #[error("--set {0}: PATH must be COMPONENT.KEY[.KEY...] or topology.KEY")]
    BadPath(String),
    /// The topology text itself is not TOML, so nothing can be edited.
    #[error("not valid TOML: {0}")]
    NotToml(String),
    /// The override does not fit the file.
    #[error("--set {set}: {problem}")]
    Misfit {
        /// The override as given.
        set: String,
        /// What does not fit.
        problem: Misfit,
    },
}

/// How an override does not fit the topology file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Misfit {
    /// A key the file contract does not have at that place.
    #[error("unknown key \"{key}\" for {place} (expected one of {expected})")]
    UnknownKey {
        /// The key.
        key: String,
        /// Where it was looked for.
        place: String,
        /// The keys allowed there, comma-separated.
        expected: String,
    },
    /// `topology.KEY` with no `[topology]` table.
    #[error("the file has no [topology] table")]
    NoTopologyTable,
    /// No component of that name.
    #[error("no component named \"{name}\" (components: {components})")]
    NoComponent {
        /// The name asked for.
        name: String,
        /// The file's components, comma-separated.
        components: String,
    },
    /// Outside `params`, a path must exist to be set below.
    #[error("\"{0}\" is not set in the file, so nothing below it can be set")]
    NotSet(String),
    /// A path ends at a table of an array of tables.
    #[error("a whole table cannot be replaced; set its keys")]
    WholeTable,
    /// A path goes below an empty item.
    #[error("\"{0}\" is below an empty item")]
    BelowEmpty(String),
    /// A path goes below a plain value.
    #[error("\"{0}\" is below a value that is not a table or list")]
    BelowValue(String),
    /// A list index that is not a number.
    #[error("\"{0}\" must be an index into a list")]
    NotAnIndex(String),
    /// A list index past the end.
    #[error("index {index} is out of range (the list has {len} entries)")]
    OutOfRange {
        /// The index given.
        index: usize,
        /// The list's length.
        len: usize,
    },
}

/// One `PATH=VALUE` override.
#[derive(Debug, Clone)]
pub struct Override {
    path: Vec<String>,
    value: Value,
    text: String,
}

impl Override {
    /// The memory limit, bytes, the last `topology.memory_limit_mb=N` of
    /// `overrides` sets (for checks a command makes before it builds the
    /// topology); `None` if none sets a positive one.
    pub fn memory_limit(overrides: &[Override]) -> Option<u64> {
        overrides
            .iter()
            .rev()
            .find(|o| o.path == ["topology", "memory_limit_mb"])
            .and_then(|o| o.value.as_integer())
            .and_then(|mb| u64::try_from(mb).ok())
            .map(|mb| mb.saturating_mul(1 << 20))
    }
}

impl FromStr for Override {
    type Err = OverrideError;

    /// VALUE is a TOML value (`4`, `0.5`, `true`, `"x"`, `[1, 2]`); anything
    /// that does not parse as one is taken as a string (`log=data/a.clf`).
    fn from_str(s: &str) -> Result<Self, OverrideError> {
        let (path, raw) = s.split_once('=').ok_or_else(|| OverrideError::NoEquals(s.to_string()))?;
        let path: Vec<String> = path.trim().split('.').map(str::to_string).collect();
        if path.len() < 2 || path.iter().any(String::is_empty) {
            return Err(OverrideError::BadPath(s.to_string()));
        }
        let raw = raw.trim();
        let value = raw.parse::<Value>().unwrap_or_else(|_| Value::from(raw));
        Ok(Override { path, value, text: s.to_string() })
    }
}

impl fmt::Display for Override {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// Applies the overrides to the topology text and returns the new text.
pub(crate) fn apply(text: &str, overrides: &[Override]) -> Result<String, OverrideError> {
    let mut doc = DocumentMut::from_str(text).map_err(|e| OverrideError::NotToml(e.to_string()))?;
    for o in overrides {
        apply_one(&mut doc, o).map_err(|problem| OverrideError::Misfit { set: o.text.clone(), problem })?;
    }
    Ok(doc.to_string())
}

fn apply_one(doc: &mut DocumentMut, o: &Override) -> Result<(), Misfit> {
    let head = o.path[0].as_str();
    let rest = &o.path[1..];
    if head == "topology" {
        check_key(&rest[0], TOPOLOGY_KEYS, "[topology]")?;
        let table = doc.get_mut("topology").ok_or(Misfit::NoTopologyTable)?;
        return set_in_item(table, rest, o.value.clone(), false);
    }
    check_key(&rest[0], COMPONENT_KEYS, &format!("component \"{head}\""))?;
    let component = find_component(doc, head)?;
    set_in_table(component, rest, o.value.clone(), false)
}

fn check_key(key: &str, allowed: &[&str], place: &str) -> Result<(), Misfit> {
    if allowed.contains(&key) {
        Ok(())
    } else {
        Err(Misfit::UnknownKey {
            key: key.to_string(),
            place: place.to_string(),
            expected: allowed.join(", "),
        })
    }
}

fn find_component<'d>(doc: &'d mut DocumentMut, name: &str) -> Result<&'d mut toml_edit::Table, Misfit> {
    let mut names = Vec::new();
    let mut found = None;
    for section in ["spout", "bolt"] {
        if let Some(tables) = doc.get(section).and_then(Item::as_array_of_tables) {
            for (index, table) in tables.iter().enumerate() {
                if let Some(n) = table.get("name").and_then(Item::as_str) {
                    if n == name && found.is_none() {
                        found = Some((section, index));
                    }
                    names.push(n.to_string());
                }
            }
        }
    }
    let (section, index) =
        found.ok_or_else(|| Misfit::NoComponent { name: name.to_string(), components: names.join(", ") })?;
    let table = doc
        .get_mut(section)
        .and_then(Item::as_array_of_tables_mut)
        .and_then(|tables| tables.get_mut(index))
        .expect("located above");
    Ok(table)
}

/// Sets `path` below `table` to `value`. Inside `params` missing tables are
/// created (the component's own parser checks the keys); elsewhere the path
/// must already exist in the file or be a contract key.
fn set_in_table(
    table: &mut dyn TableLike,
    path: &[String],
    value: Value,
    in_params: bool,
) -> Result<(), Misfit> {
    let key = path[0].as_str();
    let in_params = in_params || key == "params";
    if path.len() == 1 {
        match table.get_mut(key) {
            Some(Item::Value(slot)) => *slot = value,
            _ => {
                table.insert(key, Item::Value(value));
            }
        }
        return Ok(());
    }
    if table.get(key).is_none() {
        if !in_params {
            return Err(Misfit::NotSet(key.to_string()));
        }
        table.insert(key, Item::Value(Value::InlineTable(Default::default())));
    }
    let child = table.get_mut(key).expect("present or inserted above");
    set_in_item(child, &path[1..], value, in_params)
}

fn set_in_item(item: &mut Item, path: &[String], value: Value, in_params: bool) -> Result<(), Misfit> {
    match item {
        Item::Value(v) => set_in_value(v, path, value, in_params),
        Item::Table(t) => set_in_table(t, path, value, in_params),
        Item::ArrayOfTables(tables) => {
            let index = parse_index(&path[0], tables.len())?;
            let table = tables.get_mut(index).expect("index checked");
            if path.len() == 1 {
                return Err(Misfit::WholeTable);
            }
            set_in_table(table, &path[1..], value, in_params)
        }
        Item::None => Err(Misfit::BelowEmpty(path[0].clone())),
    }
}

fn set_in_value(slot: &mut Value, path: &[String], value: Value, in_params: bool) -> Result<(), Misfit> {
    match slot {
        Value::Array(array) => {
            let index = parse_index(&path[0], array.len())?;
            let element = array.get_mut(index).expect("index checked");
            if path.len() == 1 {
                *element = value;
                return Ok(());
            }
            if !in_params && matches!(element, Value::InlineTable(_)) {
                check_key(&path[1], INPUT_KEYS, "an input")?;
            }
            set_in_value(element, &path[1..], value, in_params)
        }
        Value::InlineTable(table) => set_in_table(table, path, value, in_params),
        _ => Err(Misfit::BelowValue(path[0].clone())),
    }
}

fn parse_index(segment: &str, len: usize) -> Result<usize, Misfit> {
    let index: usize = segment.parse().map_err(|_| Misfit::NotAnIndex(segment.to_string()))?;
    if index < len { Ok(index) } else { Err(Misfit::OutOfRange { index, len }) }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"[topology]
name = "t"

[[spout]]
name = "src"
kind = "k"
params = { count = 10 }

[[bolt]]
name = "matcher"
kind = "k2"
inputs = [ { from = "src", queue = 4 } ]
"#;

    fn set(sets: &[&str]) -> Result<String, String> {
        let overrides: Vec<Override> = sets.iter().map(|s| s.parse().unwrap()).collect();
        apply(TEXT, &overrides).map_err(|e| e.to_string())
    }

    #[test]
    fn sets_nested_values_and_adds_params() {
        let out = set(&[
            "matcher.parallelism=4",
            "src.params.count=60",
            "src.params.log=data/aces.clf",
            "matcher.inputs.0.queue=8",
            "topology.seed=9",
        ])
        .unwrap();
        let doc: toml::Table = toml::from_str(&out).unwrap();
        let bolt = &doc["bolt"][0];
        assert_eq!(bolt["parallelism"].as_integer(), Some(4));
        assert_eq!(bolt["inputs"][0]["queue"].as_integer(), Some(8));
        assert_eq!(doc["spout"][0]["params"]["count"].as_integer(), Some(60));
        assert_eq!(doc["spout"][0]["params"]["log"].as_str(), Some("data/aces.clf"));
        assert_eq!(doc["topology"]["seed"].as_integer(), Some(9));
        // Replacing values keeps every line in its place, so errors still
        // point at the user's lines.
        let out = set(&["src.params.count=60", "matcher.inputs.0.queue=8"]).unwrap();
        assert_eq!(out.lines().count(), TEXT.lines().count());
        assert_eq!(out.lines().position(|l| l.starts_with("name = \"matcher\"")), Some(9));
    }

    #[test]
    fn unknown_paths_are_errors() {
        let e = set(&["nosuch.parallelism=2"]).unwrap_err();
        assert!(e.contains("no component named \"nosuch\" (components: src, matcher)"), "{e}");
        let e = set(&["matcher.paralelism=2"]).unwrap_err();
        assert!(e.contains("unknown key \"paralelism\""), "{e}");
        let e = set(&["matcher.inputs.3.queue=2"]).unwrap_err();
        assert!(e.contains("out of range"), "{e}");
        let e = set(&["matcher.inputs.0.qeue=2"]).unwrap_err();
        assert!(e.contains("unknown key \"qeue\" for an input"), "{e}");
        assert!("matcher".parse::<Override>().is_err());
    }
}
