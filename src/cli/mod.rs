//! The `squall` command line: argument parsing and the subcommands. The
//! binary is a one-line `main` calling [`main`]; the library holds it so
//! that the fuzz targets and tests reach the argument checks.

/// `print!` to stdout that does not panic when the reader has gone
/// (`squall graph big.toml | head -1`): the process ends quietly, with the
/// status a shell gives a command killed by SIGPIPE (128 + 13).
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*), false)
    };
}

/// `println!` to stdout, ending quietly when the reader has gone (see
/// `out!`).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*), true)
    };
}

mod eval;
mod localize;
mod numbers;
mod progress;
#[cfg(feature = "cluster")]
mod robot;
mod run;
mod signals;
mod sim;
mod slam;
mod speedup;
mod study;
#[cfg(feature = "cluster")]
mod tls;
mod watch;
#[cfg(feature = "cluster")]
mod worker;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use squall_topology::spec::SpecErrors;
use squall_topology::{Override, Topology};

/// Exit code for an invalid topology or usage error.
const EXIT_INVALID: u8 = 2;
/// Exit code for a run that failed.
const EXIT_FAILED: u8 = 1;

#[derive(Debug, Parser)]
#[command(
    name = "squall",
    version,
    about = "Storm-like stream topologies for cloud robotics",
    after_help = "Examples:\n  \
        squall run examples/topologies/wordcount.toml --out out/wc\n  \
        squall run examples/topologies/probe.toml --set source.params.count=100000 --set relay.parallelism=2\n  \
        squall validate examples/topologies/wordcount.toml\n  \
        squall graph examples/topologies/wordcount.toml | dot -Tsvg > wc.svg\n  \
        squall eval --trajectory out/trajectory.tum --relations aces.relations\n  \
        squall sim --world office --duration 600 --seed 1 --out out/sim\n  \
        squall slam --log ../shared/data/laser/aces.clf --out out/aces\n  \
        squall study --logs ../shared/data/laser/aces.clf --seeds 1-10 --out out/study\n  \
        squall kinds\n\n\
        Exit codes: 0 success, 1 the run failed, 2 invalid topology or arguments."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Options shared by the commands that read a topology.
#[derive(Debug, clap::Args)]
struct TopologyArgs {
    /// The topology file (TOML).
    file: PathBuf,
    /// Override any value before validation: COMPONENT.KEY[.KEY...]=VALUE or
    /// topology.KEY=VALUE, e.g. matcher.parallelism=4 or
    /// matcher.params.particles=60. Repeatable.
    #[arg(long = "set", value_name = "PATH=VALUE", value_parser = parse_override)]
    overrides: Vec<Override>,
}

fn parse_override(s: &str) -> Result<Override, squall_topology::OverrideError> {
    s.parse()
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a topology in this process; print a per-component summary.
    Run {
        #[command(flatten)]
        topology: TopologyArgs,
        /// Write metrics.json (and the components' outputs) here.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Do not print the summary table.
        #[arg(long)]
        quiet: bool,
        /// Run on the workers of this cluster file (cluster mode).
        #[arg(long, value_name = "CLUSTER.toml")]
        cluster: Option<PathBuf>,
        #[command(flatten)]
        watch: watch::WatchArgs,
    },
    /// Check a topology without running it.
    Validate {
        #[command(flatten)]
        topology: TopologyArgs,
    },
    /// Print a topology as a Graphviz DOT graph.
    Graph {
        #[command(flatten)]
        topology: TopologyArgs,
    },
    /// Score a trajectory: the relation metric and/or errors against ground
    /// truth.
    Eval(eval::EvalArgs),
    /// RBPF SLAM on a log, a bag or the simulated office; writes map.pgm,
    /// map.yaml, map.png, trajectory.tum and metrics.json.
    Slam(slam::SlamArgs),
    /// Localize on a line map with CGR (a simulated laser or depth
    /// camera); writes trajectory.tum, hypotheses.jsonl, ground_truth.tum
    /// and metrics.json.
    Localize(localize::LocalizeArgs),
    /// Run SLAM for every (particles, matcher tasks) pair; print the
    /// speedup table, write speedup.csv and speedup.svg.
    Speedup(speedup::SpeedupArgs),
    /// Run SLAM on every (log, seed) as its own process; print the spread
    /// of the error against the raw odometry's, with CPU time and memory;
    /// write study.csv, study.md and study.svg.
    Study(study::StudyArgs),
    /// Simulate a robot exploring a world; write a CARMEN log, ground truth
    /// and relations.
    Sim(sim::SimArgs),
    /// List the component kinds this binary knows.
    Kinds,
    /// Host tasks for a cluster's coordinator (cluster mode).
    #[cfg(feature = "cluster")]
    Worker(worker::WorkerArgs),
    /// Play a log as a robot over the live link; report the round trip.
    #[cfg(feature = "cluster")]
    Robot(robot::RobotArgs),
}

/// The `squall` command: parses arguments, runs the command, maps errors
/// to exit codes.
pub fn main() -> ExitCode {
    init_logging();
    // A write past a file-size limit (`ulimit -f`, a quota) then fails
    // with an error naming the file, instead of the signal killing the
    // process with nothing reported.
    // SAFETY: setting a signal's disposition to "ignore" before any
    // thread starts; no handler runs.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    let cli = match parse_args() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(EXIT_INVALID) } else { ExitCode::SUCCESS };
        }
    };
    if matches!(
        cli.command,
        Command::Run { .. }
            | Command::Slam(_)
            | Command::Localize(_)
            | Command::Speedup(_)
            | Command::Study(_)
    ) {
        signals::install();
    }
    match cli.command {
        Command::Run { topology, out, quiet, cluster, watch } => match load(&topology) {
            Ok(t) => run::run(&t, out, quiet, cluster.as_deref(), &watch),
            Err(_) if signals::stopping() => run::stopped_before_start(out.as_deref()),
            Err(code) => {
                // An unusable --out is reported with the topology's errors.
                if let Some(dir) = &out {
                    let _ = writable_out(dir);
                }
                code
            }
        },
        Command::Validate { topology } => match load(&topology) {
            Ok(t) => {
                let unreadable = t.unreadable_inputs();
                if !unreadable.is_empty() {
                    for error in unreadable {
                        eprintln!("{error}");
                    }
                    eprintln!("error: the topology is valid, but files it reads cannot be read or used here");
                    return ExitCode::from(EXIT_INVALID);
                }
                let tasks: usize = t.spec().components.iter().map(|c| c.parallelism).sum();
                outln!(
                    "{}: topology \"{}\" is valid ({} components, {tasks} tasks)",
                    topology.file.display(),
                    t.name(),
                    t.spec().components.len()
                );
                ExitCode::SUCCESS
            }
            Err(code) => code,
        },
        Command::Graph { topology } => match load(&topology) {
            Ok(t) => {
                out!("{}", squall_topology::graph::to_dot(&t));
                ExitCode::SUCCESS
            }
            Err(code) => code,
        },
        Command::Eval(args) => eval::eval(&args),
        Command::Sim(args) => sim::sim(&args),
        Command::Slam(args) => slam::slam(&args),
        Command::Speedup(args) => speedup::speedup(&args),
        Command::Study(args) => study::study(&args),
        Command::Localize(args) => localize::localize(&args),
        #[cfg(feature = "cluster")]
        Command::Worker(args) => worker::worker(&args),
        #[cfg(feature = "cluster")]
        Command::Robot(args) => robot::robot(&args),
        Command::Kinds => {
            let registry = crate::builtin::registry();
            outln!("spouts:");
            for k in registry.spout_kinds() {
                outln!("  {k}");
            }
            outln!("bolts:");
            for k in registry.bolt_kinds() {
                outln!("  {k}");
            }
            ExitCode::SUCCESS
        }
    }
}

/// Parses and validates a topology; on failure prints every error and
/// returns the exit code.
fn load(args: &TopologyArgs) -> Result<Topology, ExitCode> {
    report_invalid(Topology::load(&args.file, &args.overrides, &crate::builtin::registry()))
}

/// A topology, or every error found in it printed and the exit code.
fn report_invalid(validated: Result<Topology, SpecErrors>) -> Result<Topology, ExitCode> {
    validated.map_err(|errors: SpecErrors| {
        eprintln!("{errors}");
        eprintln!(
            "error: invalid topology ({} problem{})",
            errors.0.len(),
            if errors.0.len() == 1 { "" } else { "s" }
        );
        ExitCode::from(EXIT_INVALID)
    })
}

/// Parses and checks a command line (`args` after the program's name)
/// as `squall` does before it runs anything: every flag's value against
/// its bound. `Err` is clap's message, as `squall` would print it. For the
/// fuzz target of the command line.
pub fn check_args<I, T>(args: I) -> Result<(), String>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let args = std::iter::once(std::ffi::OsString::from("squall")).chain(args.into_iter().map(Into::into));
    let matches = negatives(Cli::command()).try_get_matches_from(args).map_err(|e| e.to_string())?;
    Cli::from_arg_matches(&matches).map(drop).map_err(|e| e.to_string())
}

/// Every option that takes a value takes negative numbers (see
/// [`parse_args`]).
fn negatives(command: clap::Command) -> clap::Command {
    command
        .mut_args(|a| if a.get_action().takes_values() { a.allow_negative_numbers(true) } else { a })
        .mut_subcommands(negatives)
}

/// Parses the command line. Every option that takes a value takes
/// negative numbers, so that `--particles -1` is refused as a value of
/// `--particles` (not a count) rather than read as an unknown flag `-1`.
/// (Flags take no value: clap's checks, which run in debug builds, refuse
/// the setting on them.)
fn parse_args() -> Result<Cli, clap::Error> {
    let matches = negatives(Cli::command()).try_get_matches()?;
    Cli::from_arg_matches(&matches)
}

/// A path the command passes to a component through the topology, whose
/// values are UTF-8 text: the path as text, or an error naming `flag` if
/// it is not valid UTF-8 (rather than a mangled name that then cannot be
/// read).
fn topology_path<'a>(flag: &str, path: &'a std::path::Path) -> Result<&'a str, String> {
    path.to_str().ok_or_else(|| {
        format!(
            "{flag} {}: the path is not valid UTF-8, and components take paths from the topology, \
             which is UTF-8 text: rename it, or link it under a UTF-8 name",
            path.display()
        )
    })
}

/// Checks before a run that `--out DIR` can be written (created if
/// missing); the error is printed and is exit code 2.
fn writable_out(dir: &std::path::Path) -> Result<(), ExitCode> {
    squall_topology::fsio::check_writable_dir(dir).map_err(|e| {
        eprintln!("error: --out {}: cannot write there: {e}", dir.display());
        ExitCode::from(EXIT_INVALID)
    })
}

/// Writes to stdout for `out!` and `outln!`. A closed pipe ends the
/// process at once with status 141; any other error is reported and ends
/// it with status 1: output the user asked for could not be written.
pub(crate) fn write_stdout(args: std::fmt::Arguments<'_>, newline: bool) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    let written =
        stdout.write_fmt(args).and_then(|()| if newline { stdout.write_all(b"\n") } else { Ok(()) });
    match written.and_then(|()| stdout.flush()) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(141),
        Err(e) => {
            eprintln!("error: cannot write to stdout: {e}");
            std::process::exit(i32::from(EXIT_FAILED));
        }
    }
}

fn init_logging() {
    // zenoh warns at every start that its scouting delay elapsed, although
    // squall connects to explicit endpoints and does not scout.
    let filter = tracing_subscriber::EnvFilter::try_from_env("SQUALL_LOG").unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new("warn,zenoh::net::runtime::orchestrator=error")
    });
    // Colours only for a person at a terminal, not into a log file or pipe.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(ansi)
        .with_writer(std::io::stderr)
        .try_init();
}
