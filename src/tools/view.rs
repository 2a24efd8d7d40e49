//! `slipstream view`: the live view of a loop already running (started by `up`, or nodes on
//! other PCs): a page for any browser and the Foxglove WebSocket on one port, until Ctrl-C or
//! --duration. `up --view` runs the same view inside `up`. `slipstream view FILE.mcap` serves
//! a recording the same way, replayed on a bus of its own, with the page's time slider.

use std::time::Duration;

use anyhow::{Context, Result};

use crate::bus::Bus;
use crate::sim::Scenario;
use crate::view::{LiveView, ViewOptions, ViewStats};
use crate::view::{DEFAULT_HOST, DEFAULT_PORT, DEFAULT_RATE_HZ};

/// How often the status line is refreshed.
const STATUS_EVERY: Duration = Duration::from_secs(2);

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Then open http://localhost:8765 in a browser (nothing to install), or in the Foxglove app:\n\
    Open connection > Foxglove WebSocket > ws://localhost:8765 with the layout config/foxglove-layout.json\n\
    (docs/viewing.md).\n\n\
    Examples:\n  slipstream up --view                 (the loop and its view in one command)\n  \
    slipstream view                      (a loop that is already running)\n  \
    slipstream view reports/RUN/run.mcap  (a recording: the same page with a time slider)\n  \
    slipstream view --view-port 9000 --scenario scenarios/curve-follow.json5   (the road of a scenario file)")]
pub struct ViewArgs {
    /// A recording to show instead of the live bus: replayed at its pace on a bus of this
    /// process only, moved with the page's play, pause and time slider
    #[arg(value_name = "FILE.mcap")]
    pub recording: Option<std::path::PathBuf>,
    /// Address to listen on. The default serves this machine only; 0.0.0.0 serves the LAN
    /// (read-only, but anyone who reaches the port sees the camera), or tunnel with
    /// `ssh -L 8765:localhost:8765 SIM-PC`
    #[arg(long = "view-host", alias = "host", default_value = DEFAULT_HOST)]
    pub host: String,
    /// Port to listen on (0: any free port, printed); the same flag as `up --view-port`
    #[arg(long = "view-port", alias = "port", default_value_t = DEFAULT_PORT)]
    pub port: u16,
    /// Updates per second sent to Foxglove viewers and drawn for pages at most; the loop's own
    /// rates are untouched
    #[arg(long, default_value_t = DEFAULT_RATE_HZ, value_parser = rate)]
    pub rate: f64,
    /// The scenario whose road to draw (a built-in name or a .json5 file)
    /// [default: the one the simulator announces when it starts, if built in]
    #[arg(long)]
    pub scenario: Option<String>,
    /// Stop after this many seconds [default: until Ctrl-C]
    #[arg(long, value_parser = super::top::positive)]
    pub duration: Option<f64>,
}

fn rate(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 1000.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of updates per second in (0, 1000]")),
    }
}

/// The view's options from the command line.
pub fn options(args: &ViewArgs) -> Result<ViewOptions> {
    let mut opts = ViewOptions::new(&args.host, args.port);
    opts.rate_hz = args.rate;
    if let Some(name) = &args.scenario {
        opts = opts.with_scenario(&Scenario::find(name)?);
    }
    Ok(opts)
}

/// How to open the view, printed when it starts.
pub fn how_to_open(host: &str, port: u16) -> String {
    let shown = if host == "127.0.0.1" || host == "0.0.0.0" { "localhost" } else { host };
    let lan = if host == "0.0.0.0" { " (and on this PC's LAN addresses)" } else { "" };
    format!(
        "live view on http://{shown}:{port}{lan}: open it in a browser; in Foxglove, Open connection > \
         Foxglove WebSocket > ws://{shown}:{port}, layout config/foxglove-layout.json (docs/viewing.md)"
    )
}

/// One line of what the view has sent.
pub fn status_line(s: &ViewStats) -> String {
    let p = &s.page;
    format!(
        "page: states {}  frames {}  skipped {}  bad requests {}   Foxglove: viewers {}  images {}  annotations {}  \
         scene updates {}  series {}",
        p.states, p.frames, p.skipped, p.bad_requests, s.viewers, s.images, s.annotations, s.scenes, s.series
    )
}

/// Serves until Ctrl-C or --duration, with a status line on stderr.
pub async fn run(bus: &Bus, args: &ViewArgs) -> Result<ViewStats> {
    serve(bus, options(args)?, args).await
}

async fn serve(bus: &Bus, opts: ViewOptions, args: &ViewArgs) -> Result<ViewStats> {
    let view = LiveView::start(bus, opts).await?;
    eprintln!("{}", how_to_open(&args.host, view.port()));
    super::until_stopped(args.duration, STATUS_EVERY, || status_line(&view.stats())).await;
    let stats = view.stop().await;
    eprintln!("{}", status_line(&stats));
    Ok(stats)
}

/// A recording served on a bus of this process only, the page moving the replay.
async fn replay(path: &std::path::Path, args: &ViewArgs) -> Result<ViewStats> {
    let bus = std::sync::Arc::new(crate::record::private_bus(&crate::cli::own_name("view")).await?);
    let replay =
        crate::record::Replay::start(bus.clone(), path).with_context(|| format!("replay {}", path.display()))?;
    let mut opts = options(args)?;
    opts.timeline = Some(replay.clone());
    eprintln!("replaying {} (play, pause and move it on the page)", path.display());
    let stats = serve(&bus, opts, args).await;
    replay.stop();
    stats
}

/// `slipstream view`: serves until Ctrl-C (or its --duration).
pub fn command(args: &ViewArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    match &args.recording {
        Some(path) => {
            if !path.is_file() {
                anyhow::bail!("{}: no such recording (record one with `slipstream up --record`)", path.display());
            }
            tokio::runtime::Runtime::new()?.block_on(replay(path, args))?;
        }
        None => {
            crate::cli::on_bus(connect, &crate::cli::own_name("view"), |bus| async move { run(&bus, args).await })?;
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}
