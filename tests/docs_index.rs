//! The docs index (`docs/README.md`) is whole: every page under `docs/`
//! is linked from it, every other file there (tables, images, scripts)
//! from it or from a page it links, and every file it links exists.

use std::collections::BTreeSet;
use std::path::{Component, Path, PathBuf};

/// Every file under `dir`, relative to `base`.
fn files_under(dir: &Path, base: &Path, into: &mut BTreeSet<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files_under(&path, base, into);
        } else {
            into.insert(path.strip_prefix(base).unwrap().to_path_buf());
        }
    }
}

/// `path` with `.` and `..` taken out (a `..` past its start kept).
fn normal(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

/// The local targets of the Markdown links in `page` (relative to
/// `docs`), as paths relative to `docs`: `[text](target)`, anchors and
/// web addresses left out.
fn links(docs: &Path, page: &Path) -> Vec<PathBuf> {
    let text = std::fs::read_to_string(docs.join(page)).unwrap();
    let dir = page.parent().unwrap_or(Path::new(""));
    let mut found = Vec::new();
    let mut rest = text.as_str();
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
            found.push(normal(&dir.join(target)));
        }
    }
    found
}

#[test]
fn every_file_under_docs_is_linked_from_the_index() {
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs");
    let index = Path::new("README.md");
    let mut files = BTreeSet::new();
    files_under(&docs, &docs, &mut files);
    let from_index: BTreeSet<PathBuf> = links(&docs, index).into_iter().collect();
    let dead: Vec<_> = from_index.iter().filter(|p| !p.starts_with("..") && !docs.join(p).exists()).collect();
    assert!(dead.is_empty(), "docs/README.md links files that do not exist: {dead:?}");
    let pages: Vec<&PathBuf> = files.iter().filter(|p| p.extension().is_some_and(|e| e == "md")).collect();
    let unlisted: Vec<_> =
        pages.iter().filter(|p| p.as_path() != index && !from_index.contains(**p)).collect();
    assert!(unlisted.is_empty(), "pages under docs/ that docs/README.md does not link: {unlisted:?}");
    // Tables, images and scripts: from the index or a page it links.
    let mut reached = from_index.clone();
    for page in &from_index {
        if page.extension().is_some_and(|e| e == "md") && docs.join(page).exists() {
            reached.extend(links(&docs, page));
        }
    }
    let orphans: Vec<_> = files.iter().filter(|p| p.as_path() != index && !reached.contains(*p)).collect();
    assert!(
        orphans.is_empty(),
        "files under docs/ that neither docs/README.md nor a page it links links to: {orphans:?}"
    );
}
