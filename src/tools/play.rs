//! `slipstream play FILE.mcap`: a recording back onto the bus, into this namespace (-n), at the
//! recorded pace, faster (--rate), or as fast as the subscribers take it (--max).
//!
//! A replay says it is one (its samples name `sim@replay`, its node `play-<pid>`), so no live
//! node follows it; and it refuses to start in a namespace where a node it has recordings of
//! is alive (the live loop would read two simulators), unless `--into-live` says that is meant.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Result;

use crate::bus::Bus;
use crate::record::{play_until, Pace, PlayOptions, PlayReport};

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  slipstream play run.mcap\n  \
    slipstream play run.mcap --rate 2 -n replay\n  slipstream play run.mcap --max --keys camera/front")]
pub struct PlayArgs {
    /// The recording (slipstream record, up --record)
    pub file: PathBuf,
    /// Play this many times faster than recorded
    #[arg(long, default_value_t = 1.0, value_parser = super::top::positive, conflicts_with = "max")]
    pub rate: f64,
    /// As fast as the subscribers take it, flow-controlled: nothing is dropped
    #[arg(long)]
    pub max: bool,
    /// Play the file again and again until Ctrl-C
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Start this many seconds into the recording
    #[arg(long, default_value_t = 0.0)]
    pub start: f64,
    /// Only these topics or key expressions (as recorded, without the recording's namespace)
    #[arg(long, value_name = "KEY_EXPR", num_args = 1..)]
    pub keys: Vec<String>,
    /// Play even where a node the recording holds messages of is alive (a live loop): its
    /// nodes keep following their live publishers and count the replayed messages as strangers
    #[arg(long)]
    pub into_live: bool,
}

/// Plays until the end (or forever with --loop) or until `stop` is set (Ctrl-C, SIGTERM,
/// SIGHUP: between two messages); progress on stderr, the report at the end.
pub fn run(bus: &Bus, args: &PlayArgs, stop: &AtomicBool) -> Result<PlayReport> {
    anyhow::ensure!(args.start >= 0.0 && args.start.is_finite(), "--start must be seconds >= 0");
    let keys = args
        .keys
        .iter()
        .map(|k| {
            let key = crate::topics::Topic::from_name(k).map_or(k.clone(), |t| t.name().to_string());
            zenoh::key_expr::OwnedKeyExpr::autocanonize(key).map_err(|e| anyhow::anyhow!("--keys `{k}`: {e}"))
        })
        .collect::<Result<Vec<_>>>()?;
    let options =
        PlayOptions { pace: if args.max { Pace::Max } else { Pace::Rate(args.rate) }, start_s: args.start, keys };
    loop {
        let shown = super::status::Status::lines(false);
        let progress = |r: &PlayReport| {
            shown.show(&format!(
                "{:7.1} s recorded, {} messages, {:.1} MB",
                r.recorded_s,
                r.messages,
                r.bytes as f64 / 1e6
            ))
        };
        let report = play_until(bus, &args.file, &options, stop, progress)?;
        shown.finish();
        eprintln!(
            "played {}: {} messages ({:.1} MB), {:.1} s recorded in {:.1} s{}{}{}",
            args.file.display(),
            report.messages,
            report.bytes as f64 / 1e6,
            report.recorded_s,
            report.wall_s,
            if report.skipped > 0 { format!(", {} skipped (--start/--keys)", report.skipped) } else { String::new() },
            if report.viewer_copies > 0 {
                format!(", {} viewers' copies (--viewable) left out", report.viewer_copies)
            } else {
                String::new()
            },
            if report.cut { "; the file is cut short: played up to the cut" } else { "" }
        );
        if !args.repeat || report.interrupted {
            return Ok(report);
        }
    }
}

/// Refuses a namespace where a node the recording has messages of is alive (see the module
/// doc), naming the nodes and the fixes.
async fn refuse_a_live_loop(bus: &Bus, args: &PlayArgs) -> Result<()> {
    if args.into_live {
        return Ok(());
    }
    let recorded = crate::record::recorded_publishers(&args.file)?;
    let alive = crate::launch::nodes_alive_in(bus.session(), bus.topics().namespace()).await?;
    let live: Vec<&str> = alive.iter().filter(|n| recorded.contains(*n)).map(String::as_str).collect();
    let ns = bus.topics().namespace();
    anyhow::ensure!(
        live.is_empty(),
        "a live loop runs in {}: {} {} alive there, and {} holds their messages (fix: play into a namespace of its own, e.g. `-n replay`; or add --into-live: the live nodes keep following their own publishers and count the replayed messages as strangers)",
        if ns.is_empty() { "the default namespace".to_string() } else { format!("namespace `{ns}`") },
        live.join(", "),
        if live.len() == 1 { "is" } else { "are" },
        args.file.display(),
    );
    Ok(())
}

/// `slipstream play`: the player paces with blocking sleeps and puts, so it runs on a thread of
/// its own beside the session's runtime.
pub fn command(args: &PlayArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    let name = crate::cli::own_name(crate::launch::PLAYER);
    let report = crate::cli::on_bus(connect, &name, |bus| async move {
        refuse_a_live_loop(&bus, args).await?;
        bus.announce().await?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let signals = tokio::spawn(async move {
            crate::cli::stop_requested().await;
            flag.store(true, Ordering::Relaxed);
        });
        let args = args.clone();
        let played = tokio::task::spawn_blocking(move || run(&bus, &args, &stop)).await?;
        signals.abort();
        played
    })?;
    // Stopping --loop is how it ends; a single playback stopped early says so (as `up` does).
    Ok(std::process::ExitCode::from(if report.interrupted && !args.repeat { 130 } else { 0 }))
}
