//! slipstream-detect's command line (the connection and fault flags are shared), in the
//! library so that `slipstream man` writes its page with the others.

use slipstream_contract::config::{ConnectArgs, FaultArgs};

/// slipstream-detect: finds vehicles in camera/front frames and publishes perception/objects.
///
/// Reads camera/front (latest-only: never a stale frame; skipped frames are counted) and
/// camera/front/info; publishes one Detections message per frame with the frame's simulation
/// time, sequence number and publish time, so consumers can match it to speed and ground
/// truth. Method and scores: docs/perception.md.
#[derive(clap::Parser, Debug)]
#[command(name = "slipstream-detect", version)]
pub struct DetectCli {
    #[command(flatten)]
    pub connect: ConnectArgs,
    #[command(flatten)]
    pub faults: FaultArgs,
    /// This node's name on the bus
    #[arg(long, default_value = "detect")]
    pub name: String,
    /// Settings file (detector thresholds, tracker, camera fusion); only the keys it changes
    /// are needed [default: config/detect.json5 when present, else built-in]
    #[arg(long, value_name = "FILE", env = "SLIPSTREAM_DETECT_CONFIG")]
    pub settings: Option<std::path::PathBuf>,
    /// At exit, print the run's statistics as JSON on stdout (frames, detections, time spent
    /// detecting)
    #[arg(long)]
    pub json: bool,
}
