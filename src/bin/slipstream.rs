//! `slipstream`: the tools. Parses the command line and hands each command to its tool's
//! `command()` in the library (src/tools/, crates/bench/src/command.rs).

use std::process::ExitCode;

use anyhow::Result;
use clap::{CommandFactory, Parser, Subcommand};
use slipstream::config::ConnectArgs;

/// slipstream: a driving simulator, perception and cruise control glued by Zenoh.
///
/// Every command reads config/zenoh.json5 (or -c FILE) and config/slipstream.json5 (or
/// -t FILE) from the working directory when present, else built-in defaults: peer mode on
/// this machine, no router needed.
#[derive(Parser)]
#[command(name = "slipstream", version, propagate_version = true)]
struct Cli {
    #[command(flatten)]
    connect: ConnectArgs,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the whole loop on this machine (simulator, detector, cruise control) and report on it
    ///
    /// slipstream-sim, slipstream-detect and slipstream-acc as separate processes, with a live
    /// view (scenario time, ego speed, gap, ACC mode, real-time factor, loop latency per hop),
    /// then a summary, report.json and plots. A second loop started beside a running one
    /// moves to a namespace of its own (loop-2, ...), named in its first line.
    ///
    /// Exits with 1 on a collision or when a node dies. Ctrl-C stops every node and still
    /// writes the report. The nodes' logs go to the report directory. Examples:
    ///
    ///   slipstream up
    ///   slipstream up --scenario cut-in --mode lockstep --report reports/cut-in
    ///   slipstream up --perception ground-truth --duration 20
    ///   slipstream up --record --view           (keep run.mcap; watch it live in Foxglove)
    ///   slipstream up --from reports/RUN/run.mcap  (today's detector and ACC on a recorded run)
    #[command(verbatim_doc_comment)]
    Up(slipstream::tools::up::UpArgs),
    /// Live view of every key: rate, bandwidth, latency p50/p99, losses, malformed payloads,
    /// age of the last message; the nodes alive and the simulator's real-time factor
    ///
    /// A table on a terminal; one JSON object per refresh with --json or when stdout is not a
    /// terminal. Like `ros2 topic hz/bw/delay` and `dora top` on one screen.
    Top(slipstream::tools::top::TopArgs),
    /// Print the messages of a topic as JSON lines (decoded by their type)
    Echo(slipstream::tools::echo::EchoArgs),
    /// Record every key of the namespace (or the topics and key expressions given) into an
    /// MCAP file, payloads byte for byte, until Ctrl-C or --duration
    ///
    /// The file opens in Foxglove and any MCAP reader (docs/recording.md). The summary counts
    /// per key the messages, the ones lost before the recorder (sequence gaps) and the ones it
    /// dropped; it exits with 1 when anything was lost.
    Record(slipstream::tools::record::RecordArgs),
    /// Play a recording back onto the bus: every payload on its key, in this namespace (-n),
    /// with the recorded timing (--rate for faster), or as fast as the subscribers take it
    /// without dropping anything (--max)
    Play(slipstream::tools::play::PlayArgs),
    /// Serve a live view of the running loop: a page for any browser and the Foxglove
    /// WebSocket, on one port (camera with boxes, bird's-eye scene, plots, topics, latency)
    ///
    /// http://localhost:8765 (loopback) until Ctrl-C, the Foxglove WebSocket on the same port;
    /// `up --view` runs the same view inside `up`. Viewers never slow the loop: a page pulls
    /// the latest when it is ready, a Foxglove viewer gets the latest at most --rate a second.
    View(slipstream::tools::view::ViewArgs),
    /// Show the loop to ROS 2: a ROS 2 node on rmw_zenoh's keys (camera, camera info,
    /// odometry, /tf, boxes, /clock, ACC status), found by `ros2 topic list` with no bridge to
    /// install; --control lets a ROS 2 controller drive the ego
    ///
    /// Runs until Ctrl-C or --duration; `up --ros2` runs the same inside `up`. The mapping
    /// (names, types, QoS) is the `ros2` block of config/slipstream.json5 (docs/ros2.md).
    Ros2(slipstream::tools::ros2::Ros2Args),
    /// Check a component against its contract: `conform sim` checks a running simulator
    /// (slipstream-sim, the Python reference simulator, the CARLA or CoppeliaSim adapter)
    /// against docs/simulator-contract.md; exits with 1 when a rule fails
    #[command(subcommand)]
    Conform(slipstream::tools::conform::ConformCommand),
    /// Convert a recording: `--to ros2` writes the ROS 2 messages of the `ros2` mapping into a
    /// ros2-profile MCAP file that `ros2 bag play`, Foxglove and ROS tools read (docs/ros2.md)
    Convert(slipstream::tools::convert::ConvertArgs),
    /// Run a Zenoh router for nodes on several PCs (for users who have no zenohd)
    ///
    /// With config/router.json5 (or -c FILE); the nodes run in client mode. Runs until Ctrl-C.
    /// Examples:
    ///
    ///   slipstream router                                  (listens on tcp/0.0.0.0:7447)
    ///   slipstream-sim -m client -e tcp/ROUTER-PC:7447     (on another PC)
    #[command(verbatim_doc_comment)]
    Router,
    /// Run a publisher and a subscriber as two processes and show what flows (the bus alone,
    /// without the simulator)
    Demo(slipstream::tools::demo::DemoArgs),
    /// Measure the bus against raw Zenoh, UDP and TCP (two processes on loopback; use --release)
    ///
    /// Every case runs a sender and a receiver as child processes on loopback ports of their
    /// own, with the built-in config/zenoh.json5: connection flags do not apply. About 14
    /// minutes for all suites; --quick checks every path in about a minute.
    Bench(slipstream::bench::BenchArgs),
    /// Feed every message decoder and config parser mutated valid inputs (seeded) and count
    /// what is accepted, rejected, or panics; exits with 1 on any panic
    Fuzz(slipstream::tools::fuzz::FuzzArgs),
    /// Run the loop for a long while and check that no process grows (memory, threads, files)
    ///
    /// The loop (lockstep, camera, by default 30 minutes) on loopback ports and a namespace of
    /// its own, with every process's resident memory, threads and open files sampled: after
    /// the warm-up nothing may grow (aim: RSS drift < 5 %) and every control step must be
    /// answered. Writes soak.json, soak.csv and soak.png. Example:
    ///
    ///   slipstream soak --minutes 30 --report reports/soak
    #[command(verbatim_doc_comment)]
    Soak(slipstream::tools::soak::SoakArgs),
    /// Show the key of every topic after namespace and remapping, its QoS, and the Zenoh
    /// mode and endpoints in use
    Info {
        /// Print JSON instead of a table
        #[arg(long)]
        json: bool,
    },
    /// Score a node against the simulator's ground truth
    #[command(subcommand)]
    Eval(slipstream::tools::eval::EvalCommand),
    /// Print a shell's completion script for `slipstream` (bash, zsh, fish, elvish, powershell)
    ///
    /// Example:
    ///
    ///   mkdir -p ~/.local/share/bash-completion/completions
    ///   slipstream completions bash > ~/.local/share/bash-completion/completions/slipstream
    #[command(verbatim_doc_comment)]
    Completions {
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Write the man pages of `slipstream`, of each of its commands and of the node binaries
    /// into DIR (slipstream.1, slipstream-up.1, slipstream-eval-acc.1, slipstream-sim.1, ...;
    /// `man -l DIR/slipstream-up.1`)
    Man {
        #[arg(value_name = "DIR")]
        dir: std::path::PathBuf,
    },
    /// Print the example payload of every message type (hex, as in docs/wire-format.md)
    #[command(hide = true)]
    WireExamples,
    /// Decode payloads given as hex, one per line on stdin, and print one JSON verdict per
    /// line (`{"kind": ...}` or `{"error": ...}`): the Rust decoder as an oracle for other
    /// implementations of docs/wire-format.md (tests/python/test_wire.py)
    #[command(hide = true)]
    WireCheck,
    /// The observer of `bench fleet` on the client PC's host (run by the bench)
    #[command(hide = true)]
    BenchFleetWatch(slipstream::bench::fleet_watch::FleetWatchArgs),
    /// One side of a benchmark case (started by `slipstream bench`)
    #[command(hide = true)]
    BenchPeer(slipstream::bench::command::PeerArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A router forwards what it receives: its receive path must not share the tx pool, or a
    // message of several batches (a raw camera frame) waits for the threads busy receiving it
    // and is never forwarded. Zenoh's own thread layout there; the handover layout elsewhere.
    let daemon = matches!(cli.command, Command::Router);
    if daemon {
        slipstream::cli::apply_router_runtime();
    } else {
        slipstream::cli::apply_zenoh_runtime_default();
    }
    slipstream::cli::init_tracing(if daemon {
        slipstream::cli::LogLevel::Node
    } else {
        slipstream::cli::LogLevel::Tool
    });
    slipstream::cli::exit_code(run(cli))
}

fn run(cli: Cli) -> Result<ExitCode> {
    use slipstream::bench;
    use slipstream::tools::*;
    let connect = &cli.connect;
    match &cli.command {
        Command::Up(args) => up::command(args, connect),
        Command::Top(args) => top::command(args, connect),
        Command::Echo(args) => echo::command(args, connect),
        Command::Record(args) => record::command(args, connect),
        Command::Play(args) => play::command(args, connect),
        Command::View(args) => view::command(args, connect),
        Command::Ros2(args) => ros2::command(args, connect),
        Command::Conform(command) => conform::command(command, connect),
        Command::Convert(args) => convert::command(args, connect),
        Command::Router => router::command(connect),
        Command::Demo(args) => demo::command(args, connect),
        Command::Bench(args) => bench::command::command(args),
        Command::Fuzz(args) => fuzz::command(args),
        Command::Soak(args) => soak::command(args, connect),
        Command::Info { json } => info::command(*json, connect),
        Command::Eval(command) => eval::command(command, connect),
        Command::Completions { shell } => manual::completions(Cli::command(), *shell),
        Command::Man { dir } => manual::man_pages(Cli::command(), dir),
        Command::WireExamples => wire::examples(),
        Command::WireCheck => wire::check(),
        Command::BenchFleetWatch(args) => bench::command::fleet_watch(connect, args),
        Command::BenchPeer(args) => bench::command::peer(args),
    }
}
