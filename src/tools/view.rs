//! `slipstream view`: the live view of a loop already running (started by `up`, or nodes on
//! other PCs): a Foxglove WebSocket server until Ctrl-C or --duration. `up --view` runs the
//! same view inside `up`.

use std::time::Duration;

use anyhow::Result;

use crate::bus::Bus;
use crate::sim::Scenario;
use crate::view::{LiveView, ViewOptions, ViewStats};
use crate::view::{DEFAULT_HOST, DEFAULT_PORT, DEFAULT_RATE_HZ};

/// How often the status line is refreshed.
const STATUS_EVERY: Duration = Duration::from_secs(2);

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Then in the Foxglove app: Open connection > Foxglove WebSocket > ws://localhost:8765,\n\
    and import the layout config/foxglove-layout.json (docs/viewing.md).\n\n\
    Examples:\n  slipstream up --view                 (the loop and its view in one command)\n  \
    slipstream view                      (a loop that is already running)\n  \
    slipstream view --view-port 9000 --scenario scenarios/curve-follow.json5   (the road of a scenario file)")]
pub struct ViewArgs {
    /// Address to listen on. The default serves this machine only: from another PC, tunnel
    /// with `ssh -L 8765:localhost:8765 SIM-PC`
    #[arg(long = "view-host", alias = "host", default_value = DEFAULT_HOST)]
    pub host: String,
    /// Port to listen on (0: any free port, printed); the same flag as `up --view-port`
    #[arg(long = "view-port", alias = "port", default_value_t = DEFAULT_PORT)]
    pub port: u16,
    /// Updates per second sent to viewers at most; the loop's own rates are untouched
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
    format!(
        "live view on ws://{shown}:{port}: in Foxglove, Open connection > Foxglove WebSocket > that URL; \
         layout config/foxglove-layout.json (docs/viewing.md)"
    )
}

/// One line of what the view has sent.
pub fn status_line(s: &ViewStats) -> String {
    format!(
        "viewers {}  images {}  annotations {}  scene updates {}  series {}",
        s.viewers, s.images, s.annotations, s.scenes, s.series
    )
}

/// Serves until Ctrl-C or --duration, with a status line on stderr.
pub async fn run(bus: &Bus, args: &ViewArgs) -> Result<ViewStats> {
    let view = LiveView::start(bus, options(args)?).await?;
    eprintln!("{}", how_to_open(&args.host, view.port()));
    super::until_stopped(args.duration, STATUS_EVERY, || status_line(&view.stats())).await;
    let stats = view.stop().await;
    eprintln!("{}", status_line(&stats));
    Ok(stats)
}

/// `slipstream view`: serves until Ctrl-C (or its --duration).
pub fn command(args: &ViewArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    crate::cli::on_bus(connect, &crate::cli::own_name("view"), |bus| async move { run(&bus, args).await })?;
    Ok(std::process::ExitCode::SUCCESS)
}
