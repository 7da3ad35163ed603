//! Worker processes on loopback and the cluster file naming them.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// `squall worker` processes on free loopback ports, killed on drop, and
/// a cluster file listing them (with `placement`, a TOML table body, if
/// given).
pub(crate) struct Workers {
    pub(crate) children: Vec<Child>,
    pub(crate) endpoints: Vec<String>,
    dir: tempfile::TempDir,
}

impl Workers {
    /// Starts `n` workers.
    pub(crate) fn start(n: usize) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let mut children = Vec::new();
        let mut endpoints = Vec::new();
        for i in 0..n {
            let port = super::free_port();
            let endpoint = format!("tcp/127.0.0.1:{port}");
            let log = std::fs::File::create(dir.path().join(format!("w{}.log", i + 1))).unwrap();
            let child = Command::new(env!("CARGO_BIN_EXE_squall"))
                .args(["worker", "--listen", &endpoint])
                .stdout(Stdio::null())
                .stderr(log)
                .spawn()
                .expect("squall worker starts");
            children.push(child);
            endpoints.push(endpoint);
        }
        Workers { children, endpoints, dir }
    }

    /// Writes the cluster file; `placement` is the body of its
    /// `[placement]` table ("" for the defaults).
    pub(crate) fn cluster_file(&self, placement: &str) -> PathBuf {
        let mut text = String::from("[cluster]\nname = \"test\"\n");
        for (i, e) in self.endpoints.iter().enumerate() {
            text.push_str(&format!("\n[[worker]]\nname = \"w{}\"\nendpoint = \"{e}\"\n", i + 1));
        }
        if !placement.is_empty() {
            text.push_str(&format!("\n[placement]\n{placement}\n"));
        }
        let path = self.dir.path().join("cluster.toml");
        std::fs::write(&path, text).unwrap();
        path
    }

    /// What worker i (0-based) printed so far.
    pub(crate) fn log(&self, i: usize) -> String {
        std::fs::read_to_string(self.dir.path().join(format!("w{}.log", i + 1))).unwrap_or_default()
    }

    /// Every worker's log, each under its name: what a failed test shows.
    pub(crate) fn logs(&self) -> String {
        (0..self.children.len()).map(|i| format!("--- w{} ---\n{}", i + 1, self.log(i))).collect()
    }

    /// Waits up to 10 s for worker i's log to contain `needle`; the log.
    pub(crate) fn wait_for_log(&self, i: usize, needle: &str) -> String {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            let log = self.log(i);
            if log.contains(needle) || std::time::Instant::now() > deadline {
                return log;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    /// The folder of the cluster file and logs.
    pub(crate) fn dir(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
