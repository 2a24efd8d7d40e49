//! `slipstream record`: every key of the namespace (or the keys and topics given) into an MCAP
//! file until Ctrl-C or --duration, with progress; the summary at the end says what was lost.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Result;

use crate::bus::Bus;
use crate::record::{Recording, RecordingSummary};
use crate::topics::Topic;
use crate::view::copies::Copies;

/// How often the progress line is refreshed.
const PROGRESS_EVERY: Duration = Duration::from_secs(1);

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  slipstream record -o run.mcap --duration 30\n  \
    slipstream record camera/front perception/objects\n  slipstream record 'vehicle/**' -o vehicle.mcap")]
pub struct RecordArgs {
    /// Topics (vehicle/speed, camera/front, ...) or key expressions under the namespace
    /// [default: every key of the namespace, and topics remapped outside it]
    #[arg(value_name = "KEY_EXPR")]
    pub keys: Vec<String>,
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
    let path = args.output.clone().unwrap_or_else(|| PathBuf::from(format!("recording-{}.mcap", super::utc_stamp())));
    let selectors = selectors(bus, &args.keys)?;
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
    println!("{}", summary.render(std::io::stdout().is_terminal()));
    Ok(summary)
}
