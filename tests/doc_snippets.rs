//! The shell snippets of the user documentation run as written.
//!
//! `README.md` and every `docs/guide/*.md` mark the snippets a reader can
//! paste and run with the fence info string `sh runnable`; snippets that
//! need a robot, a second machine or cargo itself stay plain `sh`. This
//! test extracts the marked blocks (a line ending in `\` continues on the
//! next) and runs each with `bash -e`:
//!
//! 1. Each document gets a scratch folder laid out like the repository's
//!    neighbourhood: `scratch/repo` holds a symlink to every top-level entry
//!    of the repository (`examples`, `tests`, ...) but `out`, `target` and
//!    `.git`, and `scratch/shared` links to `../shared` beside the
//!    repository, so `../shared/data/...` resolves as it does in a
//!    checkout. A document's blocks run in order in `scratch/repo`, so a
//!    block may read what an earlier block of the same document wrote
//!    (`out/...`), and nothing is written into the repository.
//! 2. A command that starts with `cargo run --release --` or `squall` runs
//!    the binary under test (`CARGO_BIN_EXE_squall`) instead; a `cargo` on
//!    the `PATH` of the snippets fails, so the test never builds anything.
//! 3. A block that reads `../shared/data` is skipped, with a note, when
//!    that folder is absent. A block that needs cluster mode (`squall
//!    worker`, `squall robot`, `--cluster`) runs only in a build with the
//!    `cluster` feature, in its own test.
//! 4. Each block runs in its own process group: the processes it starts in
//!    the background (`squall worker ... &`) are killed when it ends, and
//!    the next block starts once they are gone.
//!
//! A failing block fails the test with its file and line, the command
//! that failed and what the block printed. As with any `bash -e` script, a
//! command inside an `&&` or `||` list does not stop the block when it
//! fails: a check belongs on a line of its own.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The README's main job, which must stay exactly this and runnable.
const MAIN_JOB: &str = "cargo run --release -- slam --out out/slam";
/// The README's test command, which `.ci/run` runs and nothing else: the
/// README must show it, and this test must not run it.
const TEST_COMMAND: &str = "./test.sh";
/// Fewer runnable blocks than this means the extraction is broken.
const MIN_BLOCKS: usize = 25;
/// A block still running after this is killed and fails the test.
const HUNG: Duration = Duration::from_secs(300);
/// The fence info string of a runnable block.
const RUNNABLE: &str = "sh runnable";
/// The first line of every generated script: the line of the failing
/// command goes to stderr, and background jobs end with the block.
const PRELUDE: &str = "trap 'echo \"doc-snippet: failed at script line $LINENO\" >&2' ERR; \
                       trap 'kill $(jobs -p) 2>/dev/null || true' EXIT";

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A fenced code block of a document.
#[derive(Debug)]
struct Block {
    /// The document, relative to the repository.
    file: String,
    /// 1-based line of the opening fence.
    line: usize,
    /// The fence's info string, trimmed.
    info: String,
    /// Logical lines (continuations joined), each with its first line.
    lines: Vec<(usize, String)>,
}

impl Block {
    fn runnable(&self) -> bool {
        self.info == RUNNABLE
    }

    fn text(&self) -> String {
        self.lines.iter().map(|(_, l)| l.as_str()).collect::<Vec<_>>().join("\n")
    }

    fn needs_data(&self) -> bool {
        self.text().contains("../shared/data")
    }

    /// Whether it uses what only a `cluster` build has.
    fn needs_cluster(&self) -> bool {
        self.lines.iter().any(|(_, l)| {
            let command = l.trim_start();
            command.starts_with("squall worker")
                || command.starts_with("squall robot")
                || l.contains("--cluster")
        })
    }

    fn at(&self) -> String {
        format!("{}:{}", self.file, self.line)
    }
}

/// The documents whose snippets are checked: the README and the guides.
fn documents() -> Vec<PathBuf> {
    let mut files = vec![repo().join("README.md")];
    let guide = repo().join("docs/guide");
    let mut guides: Vec<PathBuf> = std::fs::read_dir(&guide)
        .unwrap_or_else(|e| panic!("{}: {e}", guide.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    guides.sort();
    files.extend(guides);
    files
}

/// Every fenced block of `text`; `file` names it in messages.
fn blocks_of(file: &str, text: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    while let Some((line, l)) = lines.next() {
        let Some(info) = l.trim_start().strip_prefix("```") else { continue };
        let mut block =
            Block { file: file.to_string(), line, info: info.trim().to_string(), lines: Vec::new() };
        let mut pending: Option<(usize, String)> = None;
        for (n, l) in lines.by_ref() {
            if l.trim_start().starts_with("```") {
                break;
            }
            // A continuation line joins without its indentation.
            let (first, joined) = match pending.take() {
                Some((first, head)) => (first, head + l.trim_start()),
                None => (n, l.to_string()),
            };
            match joined.strip_suffix('\\') {
                Some(head) => pending = Some((first, format!("{} ", head.trim_end()))),
                None => block.lines.push((first, joined)),
            }
        }
        if let Some(rest) = pending {
            block.lines.push(rest);
        }
        blocks.push(block);
    }
    blocks
}

/// Every fenced block of every document.
fn all_blocks() -> Vec<Block> {
    documents()
        .iter()
        .flat_map(|path| {
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let name = path.strip_prefix(repo()).unwrap().display().to_string();
            blocks_of(&name, &text)
        })
        .collect()
}

/// `line` with a leading `cargo run --release --` or `squall` replaced
/// by the binary under test.
fn rewrite(line: &str) -> String {
    let body = line.trim_start();
    let indent = &line[..line.len() - body.len()];
    let binary = format!("'{}'", env!("CARGO_BIN_EXE_squall"));
    for prefix in ["cargo run --release -- ", "squall "] {
        if let Some(rest) = body.strip_prefix(prefix) {
            return format!("{indent}{binary} {rest}");
        }
    }
    line.to_string()
}

/// A document's scratch folder (see the module's documentation).
struct Scratch {
    root: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Self {
        let root = tempfile::tempdir().unwrap();
        let work = root.path().join("repo");
        std::fs::create_dir(&work).unwrap();
        for entry in std::fs::read_dir(repo()).unwrap() {
            let entry = entry.unwrap();
            let name = entry.file_name();
            if ["out", "target", ".git"].iter().any(|skip| name == *skip) {
                continue;
            }
            std::os::unix::fs::symlink(entry.path(), work.join(&name)).unwrap();
        }
        let shared = repo().join("../shared");
        if shared.is_dir() {
            std::os::unix::fs::symlink(shared.canonicalize().unwrap(), root.path().join("shared")).unwrap();
        }
        let bin = root.path().join("bin");
        std::fs::create_dir(&bin).unwrap();
        let cargo = bin.join("cargo");
        std::fs::write(&cargo, "#!/bin/sh\necho 'doc snippets must not call cargo' >&2\nexit 99\n").unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&cargo, std::fs::Permissions::from_mode(0o755)).unwrap();
        Scratch { root }
    }

    fn work(&self) -> PathBuf {
        self.root.path().join("repo")
    }

    /// Runs `block`; a failure is described in the error.
    fn run(&self, block: &Block, index: usize) -> Result<(), String> {
        let script = self.root.path().join(format!("block{index}.sh"));
        let body: Vec<String> = block.lines.iter().map(|(_, l)| rewrite(l)).collect();
        std::fs::write(&script, format!("{PRELUDE}\n{}\n", body.join("\n"))).unwrap();
        let (out_path, err_path) = (
            self.root.path().join(format!("block{index}.out")),
            self.root.path().join(format!("block{index}.err")),
        );
        let path = format!(
            "{}:{}",
            self.root.path().join("bin").display(),
            std::env::var("PATH").unwrap_or_default()
        );
        use std::os::unix::process::CommandExt;
        let mut child = Command::new("bash")
            .arg("-e")
            .arg(&script)
            .current_dir(self.work())
            .env("PATH", path)
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&out_path).unwrap())
            .stderr(std::fs::File::create(&err_path).unwrap())
            .process_group(0)
            .spawn()
            .expect("bash starts");
        let group = child.id();
        let deadline = Instant::now() + HUNG;
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break Some(status);
            }
            if Instant::now() > deadline {
                break None;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        end_group(group);
        let _ = child.wait();
        let stdout = std::fs::read_to_string(&out_path).unwrap_or_default();
        let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
        let failed = match status {
            Some(s) if s.success() => return Ok(()),
            Some(s) => format!("exited with {s}"),
            None => format!("still running after {HUNG:?}, killed"),
        };
        // The script's line k + 1 is the block's logical line k.
        let command = stderr
            .lines()
            .rev()
            .find_map(|l| l.strip_prefix("doc-snippet: failed at script line "))
            .and_then(|n| n.trim().parse::<usize>().ok())
            .and_then(|n| block.lines.get(n.wrapping_sub(2)))
            .map_or_else(
                || "(the block as a whole)".to_string(),
                |(line, text)| format!("{}:{line}: {}", block.file, text.trim()),
            );
        Err(format!(
            "{}: the block {failed}\n  command: {command}\n--- stderr ---\n{}\n--- stdout (end) ---\n{}",
            block.at(),
            stderr.trim_end(),
            tail(&stdout, 2000)
        ))
    }
}

/// The last `n` bytes of `text` (at a character boundary).
fn tail(text: &str, n: usize) -> &str {
    let mut start = text.len().saturating_sub(n);
    while !text.is_char_boundary(start) {
        start += 1;
    }
    &text[start..]
}

/// Kills every process left in the process group `group` and waits until
/// none is left (a worker's port must be free for the next block).
fn end_group(group: u32) {
    let target = format!("-{group}");
    let _ = Command::new("kill").args(["-KILL", "--", &target]).stderr(Stdio::null()).status();
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        let alive = Command::new("kill").args(["-0", "--", &target]).stderr(Stdio::null()).status();
        if !alive.is_ok_and(|s| s.success()) {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("the processes of group {group} outlived SIGKILL for 10 s");
}

/// Runs the runnable blocks that `select` picks, each document's in order
/// in its own scratch folder; fails with every failure found. Returns how
/// many ran.
fn run_blocks(select: impl Fn(&Block) -> bool) -> usize {
    let blocks: Vec<Block> = all_blocks().into_iter().filter(|b| b.runnable() && select(b)).collect();
    let has_data = repo().join("../shared/data").is_dir();
    let mut failures = Vec::new();
    let mut ran = 0;
    let mut scratch: Option<(String, Scratch)> = None;
    for (i, block) in blocks.iter().enumerate() {
        if block.needs_data() && !has_data {
            println!("skipped {}: it reads ../shared/data, which is absent", block.at());
            continue;
        }
        if scratch.as_ref().is_none_or(|(file, _)| *file != block.file) {
            scratch = Some((block.file.clone(), Scratch::new()));
        }
        let (_, folder) = scratch.as_ref().unwrap();
        let started = Instant::now();
        let result = folder.run(block, i);
        println!("{} ran in {:.1} s", block.at(), started.elapsed().as_secs_f64());
        ran += 1;
        if let Err(e) = result {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{} of {ran} blocks failed:\n\n{}", failures.len(), failures.join("\n\n"));
    ran
}

#[test]
fn the_readme_keeps_its_main_job_runnable_and_its_test_command() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let blocks = blocks_of("README.md", &readme);
    let runnable_line = |wanted: &str| {
        blocks.iter().filter(|b| b.runnable()).flat_map(|b| &b.lines).any(|(_, l)| l.trim() == wanted)
    };
    assert!(runnable_line(MAIN_JOB), "README.md has no `{RUNNABLE}` block with the line `{MAIN_JOB}`");
    assert!(
        readme.lines().any(|l| l.trim() == TEST_COMMAND),
        "README.md lacks the exact line `{TEST_COMMAND}` (what .ci/run runs)"
    );
    assert!(
        !runnable_line(TEST_COMMAND),
        "README.md marks `{TEST_COMMAND}` runnable: this test would run it"
    );
    let ci = std::fs::read_to_string(repo().join(".ci/run")).unwrap();
    let commands: Vec<&str> =
        ci.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
    assert_eq!(
        commands.last(),
        Some(&format!("exec {TEST_COMMAND}").as_str()),
        ".ci/run must end by running the README's test command: {commands:?}"
    );
    assert!(
        !ci.contains("cargo "),
        ".ci/run runs cargo itself: what it runs belongs in {TEST_COMMAND}, for a newcomer to run too"
    );
}

#[test]
fn enough_snippets_are_marked_runnable_and_none_calls_cargo_but_the_main_job() {
    let blocks: Vec<Block> = all_blocks().into_iter().filter(Block::runnable).collect();
    assert!(blocks.len() >= MIN_BLOCKS, "only {} `{RUNNABLE}` blocks found", blocks.len());
    for block in &blocks {
        for (line, text) in &block.lines {
            let rewritten = rewrite(text);
            assert!(
                !rewritten.trim_start().starts_with("cargo"),
                "{}:{line}: a runnable snippet may not call cargo (but `{MAIN_JOB}`): {text}",
                block.file
            );
        }
    }
    let files: std::collections::BTreeSet<&str> = blocks.iter().map(|b| b.file.as_str()).collect();
    for guide in documents() {
        let name = guide.strip_prefix(repo()).unwrap().display().to_string();
        println!("{name}: {} runnable blocks", blocks.iter().filter(|b| b.file == name).count());
    }
    assert!(files.contains("README.md"), "no runnable block in README.md");
}

#[test]
fn every_topology_shown_in_the_docs_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let topologies: Vec<Block> = all_blocks()
        .into_iter()
        .filter(|b| b.info == "toml" && b.lines.first().is_some_and(|(_, l)| l.trim() == "[topology]"))
        .collect();
    assert!(!topologies.is_empty(), "no topology (a toml block opening with [topology]) in the docs");
    for (i, block) in topologies.iter().enumerate() {
        let file = dir.path().join(format!("topology{i}.toml"));
        std::fs::write(&file, block.text()).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_squall"))
            .arg("validate")
            .arg(&file)
            .current_dir(repo())
            .output()
            .expect("the squall binary runs");
        assert!(
            out.status.success(),
            "{}: invalid topology:\n{}",
            block.at(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn every_runnable_snippet_runs() {
    let ran = run_blocks(|b| !b.needs_cluster());
    println!("{ran} blocks ran");
    assert!(ran > 0, "no runnable block ran");
}

#[cfg(feature = "cluster")]
#[test]
fn every_runnable_cluster_snippet_runs() {
    let ran = run_blocks(Block::needs_cluster);
    println!("{ran} cluster blocks ran");
}

#[cfg(not(feature = "cluster"))]
#[test]
fn cluster_snippets_need_the_cluster_feature() {
    let cluster = all_blocks().into_iter().filter(|b| b.runnable() && b.needs_cluster()).count();
    println!("{cluster} cluster blocks not run: build with --features cluster to run them");
}
