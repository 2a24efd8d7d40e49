//! `slipstream record`: every key of the namespace (or the keys and topics given) into an MCAP
//! file until Ctrl-C or --duration, with progress; the summary at the end says what was lost.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Result;

use crate::bus::Bus;
use crate::record::{Recording, RecordingSummary};
use crate::topics::Topic;
use crate::view::Copies;

/// How often the progress line is refreshed.
const PROGRESS_EVERY: Duration = Duration::from_secs(1);

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  slipstream record -o run.mcap --duration 30\n  \
    slipstream record camera/front perception/objects\n  slipstream record 'vehicle/**' -o vehicle.mcap")]
pub struct RecordArgs {
    /// Topics (vehicle/speed, camera/front, ...) or key expressions under the namespace
    /// [default: every key of the namespace, and topics remapped outside it; in the default
    /// namespace, the root loop's topics and nodes, not the namespaces beneath it]
    #[arg(value_name = "KEY_EXPR")]
    pub keys: Vec<String>,
    /// Every key of every namespace (other loops, anyone's keys) instead
    #[arg(long, conflicts_with = "keys")]
    pub all_namespaces: bool,
    /// The MCAP file [default: recording-<UTC date>-<time>.mcap]
    #[arg(short = 'o', long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Stop after this many seconds [default: until Ctrl-C]
    #[arg(long, value_parser = super::top::positive)]
    pub duration: Option<f64>,
    /// Also write copies Foxglove's own panels show (camera image, boxes, 3D scene, the ACC's
    /// series) on the live view's topics, besides the byte-for-byte channels
    #[arg(long)]
    pub viewable: bool,
    /// With --viewable: the scenario whose road to draw (a built-in name or a .json5 file)
    /// [default: the one the simulator announces, if built in]
    #[arg(long, requires = "viewable")]
    pub scenario: Option<String>,
    /// What the file holds: slipstream (every payload byte for byte, for `play` and `up
    /// --from`) or ros2 (the ROS 2 messages of the `ros2` mapping in CDR, for `ros2 bag play`,
    /// Foxglove and ROS tools; docs/ros2.md)
    #[arg(long, value_enum, default_value = "slipstream", conflicts_with_all = ["keys", "viewable"])]
    pub profile: Profile,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Profile {
    Slipstream,
    Ros2,
}

/// What a ros2-profile recording wrote, per route.
#[derive(Debug, serde::Serialize)]
pub struct Ros2Summary {
    pub path: PathBuf,
    pub messages: u64,
    pub routes: Vec<crate::ros2::RouteStats>,
}

impl Ros2Summary {
    /// Anything dropped or not converted.
    pub fn lost_anything(&self) -> bool {
        self.routes.iter().any(|r| r.dropped > 0 || r.failed > 0)
    }

    pub fn render(&self) -> String {
        let mut s = format!("{}: {} ROS 2 messages\n", self.path.display(), self.messages);
        for r in &self.routes {
            s.push_str(&format!(
                "  {:32} {:7} messages {:9.1} MB  dropped {}  failed {}\n",
                r.topic,
                r.sent,
                r.bytes as f64 / 1e6,
                r.dropped,
                r.failed
            ));
        }
        s
    }
}

/// `slipstream record` in either profile: its own session, left at the end (a session that
/// does not close in time is only warned about: the file is whole by then); exit 1 when
/// anything was lost on the way to the file.
pub fn command(args: &RecordArgs, connect: &crate::config::ConnectArgs) -> Result<std::process::ExitCode> {
    let rt = tokio::runtime::Runtime::new()?;
    let clean = rt.block_on(async {
        let bus = Bus::open(connect.zenoh_config()?, connect.topic_map()?, &crate::cli::own_name("record")).await?;
        let clean = match args.profile {
            Profile::Ros2 => run_ros2(&bus, args).await.map(|s| !s.lost_anything()),
            Profile::Slipstream => run(&bus, args).await.map(|s| !s.lost_anything()),
        };
        bus.leave().await;
        clean
    })?;
    Ok(crate::cli::exit_when(clean))
}

/// `--profile ros2`: the `ros2` mapping's routes into a ros2-profile MCAP file until Ctrl-C or
/// --duration.
pub async fn run_ros2(bus: &Bus, args: &RecordArgs) -> Result<Ros2Summary> {
    let path = match &args.output {
        Some(p) => p.clone(),
        None => super::fresh_recording()?,
    };
    let config = crate::ros2::Ros2Config::from_topic_map(bus.topics())?;
    let bag = std::sync::Arc::new(crate::ros2::Bag::create(&path, &config)?);
    let bridge = crate::ros2::Bridge::start(bus, bag.clone()).await?;
    eprintln!("recording the ROS 2 mapping into {} (profile ros2)", path.display());
    let started = Instant::now();
    super::until_stopped(args.duration, PROGRESS_EVERY, || {
        let n: u64 = bridge.stats().iter().map(|r| r.sent).sum();
        format!("{:6.1} s  {n} messages", started.elapsed().as_secs_f64())
    })
    .await;
    let routes = bridge.stop().await;
    let messages = tokio::task::spawn_blocking(move || bag.finish()).await??;
    let summary = Ros2Summary { path, messages, routes };
    println!("{}", summary.render());
    Ok(summary)
}

/// The key expressions `args.keys` name: a topic's key after namespace and remapping, or a
/// key expression under the namespace (`/` first: as written).
pub fn selectors(bus: &Bus, keys: &[String]) -> Result<Vec<zenoh::key_expr::OwnedKeyExpr>> {
    let topics = bus.topics();
    if keys.is_empty() {
        return Ok(topics.every_key());
    }
    keys.iter()
        .map(|k| match Topic::from_name(k) {
            Some(t) => Ok(topics.key(t)),
            None => {
                let full = match k.strip_prefix('/') {
                    Some(absolute) => absolute.to_string(),
                    None if topics.namespace().is_empty() => k.clone(),
                    None => format!("{}/{k}", topics.namespace()),
                };
                zenoh::key_expr::OwnedKeyExpr::autocanonize(full).map_err(|e| {
                    anyhow::anyhow!(
                        "`{k}` is neither a topic nor a key expression ({e}); topics: {}",
                        Topic::ALL.map(|t| t.name()).join(", ")
                    )
                })
            }
        })
        .collect()
}

/// Records until Ctrl-C or --duration; prints progress to stderr and the summary to stdout.
pub async fn run(bus: &Bus, args: &RecordArgs) -> Result<RecordingSummary> {
    let path = match &args.output {
        Some(p) => p.clone(),
        None => super::fresh_recording()?,
    };
    let selectors = if args.all_namespaces { bus.topics().every_namespace_key() } else { selectors(bus, &args.keys)? };
    let viewable = match (args.viewable, &args.scenario) {
        (false, _) => None,
        (true, None) => Some(Copies::new(None)),
        (true, Some(name)) => Some(Copies::new(Some(&crate::sim::Scenario::find(name)?))),
    };
    let recording = Recording::start_with(bus, &selectors, &path, viewable).await?;
    eprintln!(
        "recording {} into {} ({})",
        selectors.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(" "),
        path.display(),
        args.duration.map_or("Ctrl-C stops".to_string(), |d| format!("for {d} s"))
    );
    let started = Instant::now();
    super::until_stopped(args.duration, PROGRESS_EVERY, || {
        let (n, bytes) = recording.progress();
        format!("{:6.1} s  {n} messages  {:.1} MB", started.elapsed().as_secs_f64(), bytes as f64 / 1e6)
    })
    .await;
    let summary = tokio::task::spawn_blocking(move || recording.finish()).await??;
    println!("{}", summary.render(crate::cli::colour(&std::io::stdout())));
    Ok(summary)
}
