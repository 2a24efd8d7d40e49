//! `slipstream`: the tools. Parses the command line and calls the library.

use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{CommandFactory, Parser, Subcommand};
use slipstream::bench::{self, BenchArgs, CaseSpec};
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
    /// Run the whole loop on this machine: slipstream-sim, slipstream-detect and slipstream-acc
    /// as separate processes, with a live view (scenario time, ego speed, gap, ACC mode,
    /// real-time factor, loop latency per hop), then a summary, report.json and plots.
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
    /// Serve a live view of the running loop for Foxglove: the camera with detections and
    /// ground-truth boxes, a 3D scene of the road and vehicles, the ACC's speed, gap and mode
    ///
    /// A Foxglove WebSocket server on ws://localhost:8765 (loopback) until Ctrl-C; `up --view`
    /// runs the same view inside `up`. Viewers never slow the loop: each gets the latest
    /// updates, at most --rate a second.
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
    /// Run a Zenoh router (for nodes on several PCs, in client mode) with config/router.json5
    /// (or -c FILE): for users who have no zenohd. Runs until Ctrl-C.
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
    Bench(BenchArgs),
    /// Feed every message decoder and config parser mutated valid inputs (seeded) and count
    /// what is accepted, rejected, or panics; exits with 1 on any panic
    Fuzz(slipstream::tools::fuzz::FuzzArgs),
    /// The loop for a long while (lockstep, camera, by default 30 minutes) on loopback ports
    /// and a namespace of its own, with every process's resident memory, threads and open
    /// files sampled: after the warm-up nothing may grow (aim: RSS drift < 5 %) and every
    /// control step must be answered. Writes soak.json, soak.csv and soak.png. Example:
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
    Eval(EvalCommand),
    /// Print the completion script of a shell for `slipstream` (bash, zsh, fish, elvish,
    /// powershell). Example:
    ///
    ///   slipstream completions bash > ~/.local/share/bash-completion/completions/slipstream
    #[command(verbatim_doc_comment)]
    Completions {
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Write the man pages of `slipstream` and of each of its commands into DIR
    /// (slipstream.1, slipstream-up.1, ...; `man -l DIR/slipstream-up.1`)
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
    BenchPeer {
        #[arg(value_parser = ["send", "recv"])]
        role: String,
        #[arg(long)]
        spec: String,
        /// The receiver's endpoint(s) for a sender; the router's for a receiver through one
        #[arg(long)]
        endpoint: Vec<String>,
    },
}

#[derive(Subcommand)]
enum EvalCommand {
    /// Vehicle detection: runs scenarios in process (world, camera, detector and tracker; the
    /// ego keeps its start speed and slows for the vehicle ahead), matches detections to the ground truth of the same frame, and reports
    /// precision, recall and distance/lateral errors by range, and the lateral error 80-200 m
    /// ahead by range and the bend it is seen through (--family bend-neighbours scores the
    /// bends of `eval sweep`)
    Detect {
        /// Scenarios to run (names or files) [default: the standard set]
        #[arg(long = "scenario", value_name = "NAME")]
        scenarios: Vec<String>,
        /// Simulated seconds per scenario at most
        #[arg(long, default_value_t = 30.0)]
        seconds: f64,
        /// Print JSON instead of the table
        #[arg(long)]
        json: bool,
        /// Simulator settings to measure with (the cameras: resolution, field of view, mount);
        /// only the keys it changes are needed [default: config/sim.json5 when present, else
        /// built-in]
        #[arg(long, value_name = "FILE", env = "SLIPSTREAM_SIM_CONFIG")]
        settings: Option<std::path::PathBuf>,
        /// Put every frame through this encoding and back before the detector sees it, as a
        /// link copy would (raw, lz4, jpeg, png), and report its size and encode/decode time
        #[arg(long, value_name = "ENCODING")]
        frames: Option<String>,
        /// JPEG quality for --frames jpeg, 1..100
        #[arg(long, default_value_t = 85, value_parser = clap::value_parser!(u8).range(1..=100))]
        jpeg_quality: u8,
        /// Also score --count scenarios of this `eval sweep` family (the sweep's own, with
        /// --seed), e.g. bend-neighbours for the lateral error far ahead in bends
        #[arg(long, value_enum)]
        family: Option<slipstream::eval::sweep::families::Family>,
        /// How many scenarios of --family
        #[arg(long, default_value_t = 20)]
        count: usize,
        /// The sweep seed the --family scenarios come from
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Adaptive cruise control: runs slipstream-sim (lockstep, fast), slipstream-detect and
    /// slipstream-acc as separate processes over Zenoh through each scenario and reports
    /// collisions, minimum gap and TTC, time-gap and speed errors, and comfort (accel, decel,
    /// jerk outside emergencies) and what a driver feels (unwarranted emergencies, phantom
    /// braking, stopping for nothing, acceleration swings behind a steady lead) against the
    /// aims, with traffic collisions counted, and where the time went; exits with 1 when a
    /// scenario misses one. Runs one scenario per CPU core at once (-j). The nodes talk over
    /// unix sockets in a namespace of their own (the topic config, -t, is passed on;
    /// connection flags are not). Example:
    ///
    ///   slipstream eval acc --perception ground-truth --plots plots/
    #[command(verbatim_doc_comment)]
    Acc(slipstream::eval::acc::EvalAccArgs),
    /// The ACC's safety envelope under network faults: for each scenario a fault-free run,
    /// then perception delay, perception loss (independent, then bursty) and control-command
    /// loss in rising steps, injected where samples enter the ACC and the simulator
    /// (lockstep: the same seed gives the same run). Prints, per scenario and axis, the largest
    /// fault with no collision, no emergency braking the fault-free run does not need and
    /// comfort kept, and what failed first (docs/faults.md). Example:
    ///
    ///   slipstream eval faults --scenario cut-in --plot envelope.png
    #[command(verbatim_doc_comment)]
    Faults(slipstream::eval::faults::EvalFaultsArgs),
    /// Driving judged at scale: generates --count scenarios (default 1,000) from parameterised
    /// families (Euro NCAP car-to-car rear, cut-ins, cut-outs, braking leads, the edge of
    /// range, bends with vehicles in the next lanes, lane ends, dense traffic), each declaring
    /// what its physics warrants, runs each like `eval acc` and reports collisions,
    /// unwarranted emergencies and phantom braking per 1,000 km by family, comfort violations
    /// and the time-gap error, with the worst runs named (their files replay with `eval acc
    /// --scenario FILE`). Writes the scenarios, sweep.json and rates.png under --out; exits
    /// with 1 when a family misses the bar (no collision, no unwarranted emergency, at most
    /// one phantom-braking event per 1,000 km). Example:
    ///
    ///   slipstream eval sweep --count 40 --seed 7 --out /tmp/sweep
    #[command(verbatim_doc_comment)]
    Sweep(slipstream::eval::sweep::EvalSweepArgs),
}

/// Opens a bus as `node`, runs `f` with it, closes it.
fn on_bus<F, Fut>(connect: &ConnectArgs, node: &str, f: F) -> Result<()>
where
    F: FnOnce(slipstream::Bus) -> Fut,
    Fut: std::future::Future<Output = Result<slipstream::Bus>>,
{
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let bus = slipstream::Bus::open(connect.zenoh_config()?, connect.topic_map()?, node).await?;
        let bus = f(bus).await?;
        bus.close().await?;
        Ok(())
    })
}

/// Exit 0 when the command says all went well, 1 when it says something was lost.
fn code(clean: Result<bool>) -> Result<ExitCode> {
    Ok(if clean? { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A router forwards what it receives: its receive path must not share the tx pool, or a
    // message of several batches (a raw camera frame) waits for the threads busy receiving it
    // and is never forwarded. Zenoh's own thread layout there; the handover layout elsewhere.
    if !matches!(cli.command, Command::Router) {
        slipstream::cli::apply_zenoh_runtime_default();
    }
    slipstream::cli::init_tracing();
    slipstream::cli::exit_code(run(cli))
}

fn run(cli: Cli) -> Result<ExitCode> {
    let connect = &cli.connect;
    let done = |r: Result<()>| r.map(|()| ExitCode::SUCCESS);
    match cli.command {
        Command::Up(args) => match &args.from {
            Some(path) => Ok(ExitCode::from(slipstream::tools::up::run_from(path, &args, connect)?)),
            None => Ok(ExitCode::from(slipstream::tools::up::run(&args, connect)?.exit_code())),
        },
        Command::Top(args) => done(on_bus(connect, &format!("top-{}", std::process::id()), |bus| async move {
            slipstream::tools::top::run(&bus, &args).await?;
            Ok(bus)
        })),
        Command::Echo(args) => done(on_bus(connect, &format!("echo-{}", std::process::id()), |bus| async move {
            let printed = slipstream::tools::echo::run(&bus, &args).await?;
            if args.count.is_some_and(|n| printed < n) {
                anyhow::bail!("{printed} of {} messages seen on {}", args.count.unwrap_or(0), args.topic);
            }
            Ok(bus)
        })),
        Command::Record(args) if args.profile == slipstream::tools::record::Profile::Ros2 => {
            code(slipstream::tools::record::command_ros2(&args, connect))
        }
        Command::Convert(args) => {
            code(connect.topic_map().map_err(Into::into).and_then(|t| slipstream::tools::convert::command(&args, &t)))
        }
        Command::Record(args) => record(&args, connect),
        Command::Play(args) => done(on_bus(connect, "play", |bus| async move {
            // The player paces with blocking sleeps and puts: on a thread of its own.
            let bus = std::sync::Arc::new(bus);
            let b = bus.clone();
            tokio::task::spawn_blocking(move || slipstream::tools::play::run(&b, &args)).await??;
            std::sync::Arc::try_unwrap(bus).map_err(|_| anyhow::anyhow!("the player still holds the session"))
        })),
        Command::View(args) => done(on_bus(connect, &format!("view-{}", std::process::id()), |bus| async move {
            slipstream::tools::view::run(&bus, &args).await?;
            Ok(bus)
        })),
        Command::Ros2(args) if args.list => {
            done(connect.topic_map().map_err(Into::into).and_then(|t| slipstream::tools::ros2::list(&t, &args)))
        }
        Command::Ros2(args) => done(on_bus(connect, &format!("ros2-{}", std::process::id()), |bus| async move {
            slipstream::tools::ros2::run(&bus, &args).await?;
            Ok(bus)
        })),
        Command::Conform(slipstream::tools::conform::ConformCommand::Sim(args)) => conform_sim(connect, &args),
        Command::Fuzz(args) => done(slipstream::tools::fuzz::command(&args)),
        Command::Soak(args) => {
            use slipstream::tools::soak;
            let report = soak::run(&args, connect)?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!("{}", soak::summary(&report));
            }
            Ok(if report.pass { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        Command::Router => done(slipstream::tools::router::run(connect)),
        Command::Demo(args) => done(slipstream::tools::demo::run(connect, &args)),
        Command::Bench(args) => done(bench_command(&args)),
        Command::Info { json } => {
            let info = slipstream::tools::info::gather(connect)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                print!("{}", slipstream::tools::info::render(&info));
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Eval(e) => eval_command(e, connect),
        Command::Completions { shell } => {
            clap_complete::generate(shell, &mut Cli::command(), "slipstream", &mut std::io::stdout());
            Ok(ExitCode::SUCCESS)
        }
        Command::Man { dir } => done(write_man_pages(&dir)),
        Command::WireExamples => wire_examples(),
        Command::WireCheck => wire_check(),
        Command::BenchFleetWatch(args) => {
            let rt = tokio::runtime::Runtime::new()?;
            let seen = rt.block_on(slipstream::bench::fleet_watch::watch(connect, args))?;
            println!("{}", serde_json::to_string(&seen)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::BenchPeer { role, spec, endpoint } => {
            let spec: CaseSpec = serde_json::from_str(&spec).context("bench-peer: parse --spec")?;
            let rt = tokio::runtime::Runtime::new()?;
            done(rt.block_on(async move {
                match role.as_str() {
                    "send" => bench::run_sender(spec, endpoint).await,
                    _ => bench::run_receiver(spec, endpoint.into_iter().next()).await,
                }
            }))
        }
    }
}

/// `eval detect`, `eval acc`, `eval faults`: the report, and failure when an aim was missed
/// (acc).
fn eval_command(command: EvalCommand, connect: &ConnectArgs) -> Result<ExitCode> {
    match command {
        EvalCommand::Detect { scenarios, seconds, json, settings, frames, jpeg_quality, family, count, seed } => {
            use slipstream::eval::{detect, link_codec::LinkCodec};
            let scenarios = detect::scenarios(&scenarios, family, count, seed)?;
            let settings = slipstream::sim::SimSettings::load_or_default(settings.as_deref())?;
            let codec = match frames.as_deref() {
                None => None,
                Some(name) => {
                    let Some(e) = slipstream::config::CameraEncoding::ALL.into_iter().find(|e| e.name() == name) else {
                        anyhow::bail!("--frames {name}: not a frame encoding (use raw, lz4, jpeg or png)");
                    };
                    Some(LinkCodec::new(e, jpeg_quality))
                }
            };
            let report = detect::evaluate(scenarios, seconds, &settings, codec);
            print_report(json, &report, detect::markdown)?;
            Ok(ExitCode::SUCCESS)
        }
        EvalCommand::Acc(args) => {
            use slipstream::eval::acc;
            let report = acc::run(&args, connect)?;
            print_report(args.json, &report, acc::markdown)?;
            let failed = report.results.iter().filter(|r| !r.metrics.pass || r.lockstep_timeouts > 0).count();
            if failed > 0 {
                anyhow::bail!("{failed} of {} scenarios missed an aim", report.results.len());
            }
            Ok(ExitCode::SUCCESS)
        }
        EvalCommand::Sweep(args) => {
            use slipstream::eval::sweep;
            let report = sweep::run(&args, connect)?;
            let json = serde_json::to_string_pretty(&report)?;
            let file = args.out.join("sweep.json");
            std::fs::write(&file, &json).with_context(|| format!("write {}", file.display()))?;
            print_report(args.json, &report, sweep::markdown)?;
            eprintln!(
                "report: {}; plot: {}",
                file.display(),
                report.plot.as_ref().map_or("none".into(), |p| p.display().to_string())
            );
            if !report.pass {
                anyhow::bail!("the sweep missed the bar (table above)");
            }
            Ok(ExitCode::SUCCESS)
        }
        EvalCommand::Faults(args) => {
            use slipstream::eval::faults;
            let report = faults::run(&args, connect)?;
            print_report(args.json, &report, faults::markdown)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `wire-examples`: every message kind's example encoding, as JSON (for the wire doc's test).
fn wire_examples() -> Result<ExitCode> {
    let all: Vec<_> = slipstream::msg::examples()
        .into_iter()
        .map(|(kind, bytes)| serde_json::json!({ "kind": kind.name(), "hex": slipstream::msg::hex_lines(&bytes).replace('\n', " ") }))
        .collect();
    println!("{}", serde_json::to_string_pretty(&all)?);
    Ok(ExitCode::SUCCESS)
}

/// `wire-check`: decodes each hex line of stdin, printing its kind or why it is refused.
fn wire_check() -> Result<ExitCode> {
    use std::io::BufRead;
    for line in std::io::stdin().lock().lines() {
        let line = line?;
        let bytes: Result<Vec<u8>, _> =
            (0..line.len()).step_by(2).map(|i| u8::from_str_radix(line.get(i..i + 2).unwrap_or("zz"), 16)).collect();
        let verdict = match bytes.map(|b| slipstream::msg::decode_json(&b)) {
            Ok(Ok((kind, _, _))) => serde_json::json!({ "kind": kind.name() }),
            Ok(Err(e)) => serde_json::json!({ "error": e.to_string() }),
            Err(_) => serde_json::json!({ "error": format!("not hex: {line}") }),
        };
        println!("{verdict}");
    }
    Ok(ExitCode::SUCCESS)
}

/// `record` (slipstream's profile): fails when anything was lost on the way to the file.
fn record(args: &slipstream::tools::record::RecordArgs, connect: &ConnectArgs) -> Result<ExitCode> {
    let rt = tokio::runtime::Runtime::new()?;
    let summary = rt.block_on(async {
        let bus = slipstream::Bus::open(connect.zenoh_config()?, connect.topic_map()?, "record").await?;
        let summary = slipstream::tools::record::run(&bus, args).await;
        let closed = tokio::time::timeout(slipstream::launch::CLOSE_TIMEOUT, bus.close()).await;
        if !matches!(closed, Ok(Ok(()))) {
            tracing::warn!("the recorder's session did not close cleanly");
        }
        summary
    })?;
    Ok(if summary.lost_anything() { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}

/// `conform sim`: as the lockstep node it answers for, or as a watcher of its own name.
fn conform_sim(connect: &ConnectArgs, args: &slipstream::tools::conform::ConformSimArgs) -> Result<ExitCode> {
    use slipstream::tools::conform;
    let node = if args.lockstep { args.name.clone() } else { format!("conform-{}", std::process::id()) };
    let mut pass = false;
    on_bus(connect, &node, |bus| async {
        let report = conform::run_sim(&bus, args).await?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&report)?);
        } else {
            print!("{}", conform::render(&report));
        }
        pass = report.pass;
        Ok(bus)
    })?;
    Ok(if pass { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// slipstream.1 and a page per visible command (slipstream-up.1, ...) into `dir`.
fn write_man_pages(dir: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    let top = Cli::command();
    let pages = std::iter::once(top.clone()).chain(
        top.get_subcommands()
            .filter(|c| !c.is_hide_set())
            .map(|c| c.clone().name(format!("slipstream-{}", c.get_name())))
            .collect::<Vec<_>>(),
    );
    for page in pages {
        let path = dir.join(format!("{}.1", page.get_name()));
        let mut text = Vec::new();
        clap_mangen::Man::new(page).render(&mut text)?;
        std::fs::write(&path, text).with_context(|| format!("write {}", path.display()))?;
    }
    Ok(())
}

/// A report as JSON or as its markdown rendering.
fn print_report<R: serde::Serialize>(json: bool, report: &R, markdown: fn(&R) -> String) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(report)?);
    } else {
        println!("{}", markdown(report));
    }
    Ok(())
}

fn bench_command(args: &BenchArgs) -> Result<()> {
    let report = bench::run(args)?;
    let md = bench::markdown(&report);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{md}");
    }
    if let Some(path) = &args.markdown {
        std::fs::write(path, format!("Command: `{}`\n{md}", report.command))
            .with_context(|| format!("write {}", path.display()))?;
    }
    Ok(())
}
