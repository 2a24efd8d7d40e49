//! What every binary does before its work: logging and Zenoh's runtime tuning.

use tracing_subscriber::EnvFilter;

/// Logs to stderr, filtered by RUST_LOG (default: info for slipstream, warnings for Zenoh).
pub fn init_tracing() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info,zenoh=warn,zenoh_ext=warn"));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
}
