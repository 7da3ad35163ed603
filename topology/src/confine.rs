//! Confinement: where a process that runs other people's plans (a
//! worker) may read and write files.
//!
//! A plan names component kinds and their parameters, file paths among
//! them. A worker started with `--data-dir` and `--out` reads only under
//! the first and writes only under the second: a path outside them
//! (absolute, climbing out with `..`, or through a symlink that leads
//! out) is refused before it is opened. The policy is the process's
//! own, set once at start ([`confine`]); components that touch files
//! check against it ([`check_read`], [`check_write`]) right before they
//! do, and the worker checks every path its components declared
//! ([`crate::Declarer::reads`], [`crate::Declarer::writes`]) before any
//! task starts. A process that never calls [`confine`] (a run on one
//! machine, the coordinator) is not confined: its user named the paths.

use std::path::{Component, Path, PathBuf};
use std::sync::OnceLock;

/// A path a confined process may not touch, or a policy that cannot be
/// set up.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfinementError {
    /// The path is outside the folder the process may read.
    #[error("{path}: outside this worker's --data-dir {root}: a worker reads only under it")]
    ReadOutside {
        /// The path as named.
        path: String,
        /// The folder it may read.
        root: String,
    },
    /// The process may read no files at all.
    #[error("{path}: this worker reads no files: start it with --data-dir DIR to let plans read under DIR")]
    NoReads {
        /// The path as named.
        path: String,
    },
    /// The path is outside the folder the process may write.
    #[error("{path}: outside this worker's --out {root}: a worker writes only under it")]
    WriteOutside {
        /// The path as named.
        path: String,
        /// The folder it may write.
        root: String,
    },
    /// The process may write no files at all.
    #[error("{path}: this worker writes no files: start it with --out DIR to let plans write under DIR")]
    NoWrites {
        /// The path as named.
        path: String,
    },
    /// A folder of the policy cannot be resolved.
    #[error("{dir}: {message}")]
    Folder {
        /// The folder.
        dir: String,
        /// What went wrong.
        message: String,
    },
    /// The policy was already set.
    #[error("this process is already confined")]
    AlreadySet,
}

/// The folders a confined process may read and write, resolved
/// (absolute, symlinks followed); `None` is none at all.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Confinement {
    read: Option<PathBuf>,
    write: Option<PathBuf>,
}

impl Confinement {
    /// Reading only under `data_dir`, writing only under `out_dir` (each
    /// must exist; `None` allows nothing).
    pub fn new(data_dir: Option<&Path>, out_dir: Option<&Path>) -> Result<Self, ConfinementError> {
        let resolve = |dir: Option<&Path>| {
            dir.map(|d| {
                let resolved = d.canonicalize().map_err(|e| ConfinementError::Folder {
                    dir: d.display().to_string(),
                    message: e.to_string(),
                })?;
                if resolved.is_dir() {
                    Ok(resolved)
                } else {
                    Err(ConfinementError::Folder {
                        dir: d.display().to_string(),
                        message: "not a folder".into(),
                    })
                }
            })
            .transpose()
        };
        Ok(Confinement { read: resolve(data_dir)?, write: resolve(out_dir)? })
    }

    /// Whether `path` may be read.
    pub fn check_read(&self, path: &Path) -> Result<(), ConfinementError> {
        within(
            &self.read,
            path,
            |path| ConfinementError::NoReads { path },
            |path, root| ConfinementError::ReadOutside { path, root },
        )
    }

    /// Whether `path` (a file or a folder, existing or to be made) may
    /// be written.
    pub fn check_write(&self, path: &Path) -> Result<(), ConfinementError> {
        within(
            &self.write,
            path,
            |path| ConfinementError::NoWrites { path },
            |path, root| ConfinementError::WriteOutside { path, root },
        )
    }
}

/// Whether `path` lies under `root`: else the error `none` (no root) or
/// `outside` makes of the path (and the root) as named.
fn within(
    root: &Option<PathBuf>,
    path: &Path,
    none: fn(String) -> ConfinementError,
    outside: fn(String, String) -> ConfinementError,
) -> Result<(), ConfinementError> {
    let named = path.display().to_string();
    match root {
        None => Err(none(named)),
        Some(root) if inside(path, root) => Ok(()),
        Some(root) => Err(outside(named, root.display().to_string())),
    }
}

/// Whether `path` (relative to the working folder) lies under `root` (a
/// resolved folder): its lexical form, `..` taken away, and the real
/// place of its longest existing part (symlinks followed), with the
/// rest, which must not climb.
fn inside(path: &Path, root: &Path) -> bool {
    let Ok(cwd) = std::env::current_dir() else { return false };
    let Some(lexical) = normalize(&cwd.join(path)) else { return false };
    // The real place: the longest prefix that exists, resolved, and what
    // follows it (which cannot hold a symlink: it does not exist yet).
    let mut existing = lexical.as_path();
    let mut rest = Vec::new();
    let real = loop {
        match existing.canonicalize() {
            Ok(resolved) => break resolved,
            Err(_) => match (existing.parent(), existing.file_name()) {
                (Some(parent), Some(name)) => {
                    rest.push(name.to_owned());
                    existing = parent;
                }
                _ => return false,
            },
        }
    };
    let real = rest.iter().rev().fold(real, |p, name| p.join(name));
    lexical.starts_with(root) && real.starts_with(root)
}

/// `path` (absolute) with `.` and `..` taken away; `None` if it climbs
/// above the root.
fn normalize(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => out.push(c.as_os_str()),
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::Normal(name) => out.push(name),
        }
    }
    Some(out)
}

static POLICY: OnceLock<Confinement> = OnceLock::new();

/// Confines this process for the rest of its life (a worker, at start).
pub fn confine(policy: Confinement) -> Result<(), ConfinementError> {
    POLICY.set(policy).map_err(|_| ConfinementError::AlreadySet)
}

/// This process's confinement, if it is confined.
pub fn policy() -> Option<&'static Confinement> {
    POLICY.get()
}

/// Whether this process may read `path` (always, unconfined).
pub fn check_read(path: &Path) -> Result<(), ConfinementError> {
    policy().map_or(Ok(()), |p| p.check_read(path))
}

/// Whether this process may write `path` (always, unconfined).
pub fn check_write(path: &Path) -> Result<(), ConfinementError> {
    policy().map_or(Ok(()), |p| p.check_write(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `data/` with a file, `out/`, a file outside both, and symlinks in
    /// `data/` to the outside file and to a file of its own.
    fn tree() -> (tempfile::TempDir, Confinement) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path();
        for d in ["data/logs", "out"] {
            std::fs::create_dir_all(p.join(d)).unwrap();
        }
        std::fs::write(p.join("data/logs/a.clf"), "x").unwrap();
        std::fs::write(p.join("secret"), "x").unwrap();
        std::os::unix::fs::symlink(p.join("secret"), p.join("data/escape")).unwrap();
        std::os::unix::fs::symlink(p.join("data/logs/a.clf"), p.join("data/alias.clf")).unwrap();
        std::os::unix::fs::symlink(p, p.join("data/up")).unwrap();
        let c = Confinement::new(Some(&p.join("data")), Some(&p.join("out"))).unwrap();
        (dir, c)
    }

    #[test]
    fn reads_stay_under_the_data_dir_whatever_the_path_says() {
        let (dir, c) = tree();
        let p = dir.path();
        assert_eq!(c.check_read(&p.join("data/logs/a.clf")), Ok(()));
        assert_eq!(c.check_read(&p.join("data/logs/../logs/a.clf")), Ok(()));
        assert_eq!(c.check_read(&p.join("data/alias.clf")), Ok(()), "a symlink that stays inside");
        assert_eq!(
            c.check_read(&p.join("data/logs/missing.clf")),
            Ok(()),
            "inside; its read says it is missing"
        );
        for outside in [
            p.join("secret"),
            p.join("data/../secret"),
            p.join("data/logs/../../secret"),
            p.join("data/escape"),
            p.join("data/up/secret"),
            PathBuf::from("/etc/passwd"),
            PathBuf::from("/../../etc/passwd"),
        ] {
            let refused = c.check_read(&outside).unwrap_err();
            assert!(matches!(refused, ConfinementError::ReadOutside { .. }), "{outside:?}: {refused}");
            assert!(refused.to_string().contains("outside this worker's --data-dir"), "{refused}");
        }
    }

    #[test]
    fn writes_stay_under_the_out_dir_and_nothing_goes_without_a_folder() {
        let (dir, c) = tree();
        let p = dir.path();
        assert_eq!(c.check_write(&p.join("out/scenes/cache.bin")), Ok(()), "a folder still to be made");
        assert!(c.check_write(&p.join("data/logs/a.clf")).is_err(), "the data dir is not for writing");
        assert!(c.check_write(&p.join("out/../secret")).is_err());
        assert!(c.check_write(Path::new("/tmp/squall-scenes")).is_err());
        let none = Confinement::new(None, None).unwrap();
        let e = none.check_read(&p.join("data/logs/a.clf")).unwrap_err();
        assert!(e.to_string().contains("start it with --data-dir DIR"), "{e}");
        let e = none.check_write(&p.join("out/x")).unwrap_err();
        assert!(e.to_string().contains("start it with --out DIR"), "{e}");
        let missing = Confinement::new(Some(&p.join("nowhere")), None).unwrap_err();
        assert!(matches!(missing, ConfinementError::Folder { .. }), "{missing}");
    }
}
