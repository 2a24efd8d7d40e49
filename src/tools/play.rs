//! `slipstream play FILE.mcap`: a recording back onto the bus, into this namespace (-n), at the
//! recorded pace, faster (--rate), or as fast as the subscribers take it (--max).

use std::path::PathBuf;

use anyhow::Result;

use crate::bus::Bus;
use crate::record::{play, Pace, PlayOptions, PlayReport};

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
}

/// Plays until the end (or forever with --loop); progress on stderr, the report at the end.
pub fn run(bus: &Bus, args: &PlayArgs) -> Result<PlayReport> {
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
        let report = play(bus, &args.file, &options, progress)?;
        shown.finish();
        eprintln!(
            "played {}: {} messages ({:.1} MB), {:.1} s recorded in {:.1} s{}{}",
            args.file.display(),
            report.messages,
            report.bytes as f64 / 1e6,
            report.recorded_s,
            report.wall_s,
            if report.skipped > 0 { format!(", {} skipped (--start/--keys)", report.skipped) } else { String::new() },
            if report.cut { "; the file is cut short: played up to the cut" } else { "" }
        );
        if !args.repeat {
            return Ok(report);
        }
    }
}

/// `slipstream play`: the player paces with blocking sleeps and puts, so it runs on a thread of
/// its own beside the session's runtime.
pub fn command(args: &PlayArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    crate::cli::on_bus(connect, "play", |bus| async move {
        let args = args.clone();
        tokio::task::spawn_blocking(move || run(&bus, &args)).await?
    })?;
    Ok(std::process::ExitCode::SUCCESS)
}
