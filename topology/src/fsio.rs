//! Atomic output files: a reader never sees a half-written file.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` through a temporary file in the same directory
/// and a rename, so `path` is either the old file or the whole new one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomic_with(path, |out| out.write_all(bytes))
}

/// Writes `path` the same way, streaming: `write` fills a buffered writer
/// into the temporary file, so a large output (a map image of tens of
/// millions of pixels) is never held whole in memory. Its error (or the
/// file system's, through `From<io::Error>`) leaves no file behind.
pub fn write_atomic_with<E: From<io::Error>>(
    path: &Path,
    write: impl FnOnce(&mut io::BufWriter<fs::File>) -> Result<(), E>,
) -> Result<(), E> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    fs::create_dir_all(dir)?;
    let tmp = temporary_beside(path, "tmp")?;
    let result = (|| {
        let mut out = io::BufWriter::new(fs::File::create(&tmp)?);
        write(&mut out)?;
        let file = out.into_inner().map_err(io::IntoInnerError::into_error)?;
        file.sync_all()?;
        fs::rename(&tmp, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// This process's temporary name for `path`, in its folder:
/// `.NAME.TAG<pid>`. Those of the same `NAME.TAG` that processes no
/// longer running left behind (killed between creating and renaming one)
/// are removed first, so that a killed run's leftovers never block, nor
/// litter, the next.
pub fn temporary_beside(path: &Path, tag: &str) -> io::Result<PathBuf> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "path has no file name"))?;
    let prefix = format!(".{}.{tag}", name.to_string_lossy());
    remove_stale(dir, &prefix);
    Ok(dir.join(format!("{prefix}{}", std::process::id())))
}

/// Removes the temporary files `prefix<pid>` in `dir` that a process no
/// longer running left behind (killed between creating and renaming
/// one). Where processes cannot be looked up (no `/proc`), nothing.
fn remove_stale(dir: &Path, prefix: &str) {
    let proc_fs = Path::new("/proc");
    if !proc_fs.join("self").exists() {
        return;
    }
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(pid) = file.to_str().and_then(|f| f.strip_prefix(prefix)) else { continue };
        let ours = pid == std::process::id().to_string();
        if pid.parse::<u32>().is_ok() && !ours && !proc_fs.join(pid).exists() {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Checks before a run that an input can be read: a file opens, a
/// folder lists.
pub fn check_readable(path: &Path) -> io::Result<()> {
    if path.is_dir() { fs::read_dir(path).map(drop) } else { fs::File::open(path).map(drop) }
}

/// Checks before a run that outputs can be written into `dir` (created
/// if missing): creates and removes a file there, so that a read-only or
/// missing place is found before hours of work, not after.
pub fn check_writable_dir(dir: &Path) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let probe = dir.join(format!(".squall-write-check.tmp{}", std::process::id()));
    fs::File::create(&probe)?;
    fs::remove_file(&probe)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("squall-fsio-{}", std::process::id()));
        let path = dir.join("out.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_temp_file_left_by_a_killed_process_is_removed_at_the_next_write() {
        let dir = std::env::temp_dir().join(format!("squall-fsio-stale-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        // No process has this pid (past any kernel's pid_max); pid 1 runs.
        let dead = dir.join(".map.pgm.tmp999999999");
        let live = dir.join(".map.pgm.tmp1");
        fs::write(&dead, b"half").unwrap();
        fs::write(&live, b"being written").unwrap();
        write_atomic(&dir.join("map.pgm"), b"map").unwrap();
        assert!(!dead.exists(), "the dead process's temp file is removed");
        assert!(live.exists(), "a running process's temp file is left alone");
        check_writable_dir(&dir).unwrap();
        let mut names: Vec<_> = fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        names.sort();
        assert_eq!(names, [".map.pgm.tmp1", "map.pgm"], "the write check leaves nothing");
        fs::remove_dir_all(&dir).unwrap();
        assert!(check_writable_dir(Path::new("/proc/self/squall-out")).is_err());
    }

    #[test]
    fn a_failed_stream_keeps_the_old_file_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("squall-fsio-stream-{}", std::process::id()));
        let path = dir.join("out.txt");
        write_atomic(&path, b"old").unwrap();
        let failed = write_atomic_with(&path, |out| {
            out.write_all(b"half of the new")?;
            Err(io::Error::other("the encoder failed"))
        });
        assert_eq!(failed.unwrap_err().to_string(), "the encoder failed");
        assert_eq!(fs::read(&path).unwrap(), b"old");
        write_atomic_with(&path, |out| out.write_all(b"new")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        let names: Vec<_> = fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        fs::remove_dir_all(&dir).unwrap();
    }
}
