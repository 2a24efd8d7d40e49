//! The connection flags every binary shares, and the Zenoh config they produce.

use std::path::{Path, PathBuf};

use super::low_latency::LowLatencyEndpoints;
use super::{ConfigError, TopicMap};

/// Where binaries look for the Zenoh config when `-c` is not given.
pub const DEFAULT_ZENOH_CONFIG_PATH: &str = "config/zenoh.json5";

/// config/zenoh.json5 as shipped, built in so a binary run from any directory behaves the same.
pub const DEFAULT_ZENOH_CONFIG: &str = include_str!("../../../../config/zenoh.json5");

/// config/router.json5 as shipped: what `slipstream router` runs without -c.
pub(super) const DEFAULT_ROUTER_CONFIG: &str = include_str!("../../../../config/router.json5");

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    Peer,
    Client,
    Router,
}

/// `-m`: Zenoh's mode. A clock mode given there (`up -m lockstep`, for `--mode lockstep`) is
/// named as such.
fn zenoh_mode(value: &str) -> Result<ModeArg, String> {
    match value {
        "peer" => Ok(ModeArg::Peer),
        "client" => Ok(ModeArg::Client),
        "router" => Ok(ModeArg::Router),
        "realtime" | "fast" | "lockstep" => Err(format!(
            "`{value}` is a clock mode, and -m is Zenoh's mode (peer, client or router): the clock is `--mode {value}`"
        )),
        _ => Err(format!("`{value}` is no Zenoh mode: peer, client or router")),
    }
}

/// Connection and topic flags, flattened into every binary's command line.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ConnectArgs {
    /// Zenoh config file (JSON5) [default: ./config/zenoh.json5 if present, else the same
    /// settings built in: peer mode on loopback, multicast scouting off]
    #[arg(short = 'c', long = "config", value_name = "FILE", env = "SLIPSTREAM_ZENOH_CONFIG", global = true)]
    pub zenoh_config: Option<PathBuf>,

    /// Zenoh mode, overriding the config file: peer, client or router (the simulator's clock
    /// is `--mode`, without -m)
    #[arg(
        id = "zenoh_mode",
        short = 'm',
        long = "zenoh-mode",
        value_name = "MODE",
        value_parser = zenoh_mode,
        global = true
    )]
    pub mode: Option<ModeArg>,

    /// Endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable; replaces the config's list)
    #[arg(short = 'e', long = "connect", value_name = "ENDPOINT", global = true)]
    pub connect: Vec<String>,

    /// Endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable; replaces the config's list)
    #[arg(short = 'l', long = "listen", value_name = "ENDPOINT", global = true)]
    pub listen: Vec<String>,

    /// Turn multicast scouting off (it is already off in the default config)
    #[arg(long, global = true)]
    pub no_multicast_scouting: bool,

    /// Set any Zenoh config key, e.g. --cfg 'transport/shared_memory/enabled:false' (value is JSON5; repeatable)
    #[arg(long = "cfg", value_name = "KEY:VALUE", global = true)]
    pub cfg: Vec<String>,

    /// Topic config file (JSON5): namespace, key remapping, per-topic QoS
    /// [default: ./config/slipstream.json5 if present, else built-in defaults]
    #[arg(short = 't', long = "topics", value_name = "FILE", env = "SLIPSTREAM_CONFIG", global = true)]
    pub topics: Option<PathBuf>,

    /// Put every key under this namespace (several vehicles or simulators on one network)
    #[arg(short = 'n', long, env = "SLIPSTREAM_NAMESPACE", global = true)]
    pub namespace: Option<String>,

    /// Open a second Zenoh session (peer mode) for the small real-time topics (speed, state,
    /// control, clock, detections, status; `session` per topic in the topic config) on Zenoh's
    /// low-latency transport; opt-in, docs/deployment.md "Two sessions per node" says when it
    /// pays and what it costs
    #[arg(long, global = true)]
    pub low_latency_session: bool,

    /// Where the low-latency session listens (repeatable) [default: the --listen endpoints,
    /// unix sockets with `.ll` appended, TCP/UDP on a port the system picks]
    #[arg(long, value_name = "ENDPOINT", global = true)]
    pub low_latency_listen: Vec<String>,

    /// Whom the low-latency session dials (repeatable) [default: the --connect endpoints, unix
    /// sockets with `.ll` appended]
    #[arg(long, value_name = "ENDPOINT", global = true)]
    pub low_latency_connect: Vec<String>,
}

impl ConnectArgs {
    /// The Zenoh config: file (or built-in default), then mode, endpoints, scouting and --cfg.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, ConfigError> {
        self.config_over(DEFAULT_ZENOH_CONFIG_PATH, DEFAULT_ZENOH_CONFIG)
    }

    /// The router's config (`slipstream router`): -c FILE, else ./config/router.json5, else
    /// the same built in; then the flags, as for a node.
    pub fn router_config(&self) -> Result<zenoh::Config, ConfigError> {
        self.config_over("config/router.json5", DEFAULT_ROUTER_CONFIG)
    }

    fn config_over(&self, default_path: &str, built_in: &str) -> Result<zenoh::Config, ConfigError> {
        let (mut config, origin) = match &self.zenoh_config {
            Some(path) => (load_zenoh_file(path)?, ConfigError::file(path)),
            None if Path::new(default_path).is_file() => {
                let path = Path::new(default_path);
                (load_zenoh_file(path)?, ConfigError::file(path))
            }
            None => {
                let origin = format!("built-in {default_path}");
                let config = zenoh::Config::from_json5(built_in)
                    .map_err(|e| ConfigError::new(&origin, "", e.to_string(), "report this as a bug"))?;
                (config, origin)
            }
        };
        let set = |config: &mut zenoh::Config, key: &str, value: String, flag: &str| {
            config.insert_json5(key, &value).map_err(|e| {
                let message = super::zenoh_error::message(&e);
                if message.contains("unknown key") {
                    return ConfigError::new(
                        flag,
                        key,
                        "no such Zenoh config key",
                        "the keys are config/zenoh.json5's and those of Zenoh's DEFAULT_CONFIG.json5, written with `/`, e.g. --cfg 'scouting/multicast/enabled:false'",
                    );
                }
                ConfigError::new(
                    flag,
                    key,
                    format!("`{value}` rejected: {message}"),
                    format!("check the value given to {flag} (config from {origin})"),
                )
            })
        };
        if let Some(mode) = self.mode {
            let m = match mode {
                ModeArg::Peer => "peer",
                ModeArg::Client => "client",
                ModeArg::Router => "router",
            };
            set(&mut config, "mode", format!("\"{m}\""), "-m/--zenoh-mode")?;
        }
        if !self.connect.is_empty() {
            check_endpoints(&self.connect, "-e/--connect")?;
            set(&mut config, "connect/endpoints", json_list(&self.connect), "--connect")?;
        }
        if !self.listen.is_empty() {
            check_endpoints(&self.listen, "-l/--listen")?;
            set(&mut config, "listen/endpoints", json_list(&self.listen), "--listen")?;
        }
        if self.no_multicast_scouting {
            set(&mut config, "scouting/multicast/enabled", "false".into(), "--no-multicast-scouting")?;
        }
        for kv in &self.cfg {
            let Some((key, value)) = kv.split_once(':') else {
                return Err(ConfigError::new(
                    "--cfg",
                    kv,
                    "missing `:` between key and value",
                    "write --cfg 'KEY:VALUE', e.g. --cfg 'scouting/multicast/enabled:false'",
                ));
            };
            set(&mut config, key, value.to_string(), "--cfg")?;
        }
        Ok(config)
    }

    /// The low-latency session's config, derived from `main` (this node's main config) and the
    /// `--low-latency-*` flags; None without `--low-latency-session` or outside peer mode.
    pub fn low_latency_config(&self, main: &zenoh::Config) -> Result<Option<zenoh::Config>, ConfigError> {
        if !self.low_latency_session {
            if !self.low_latency_listen.is_empty() || !self.low_latency_connect.is_empty() {
                tracing::warn!(
                    "--low-latency-listen/--low-latency-connect without --low-latency-session: one session, the endpoints are not used"
                );
            }
            return Ok(None);
        }
        let given =
            LowLatencyEndpoints { listen: self.low_latency_listen.clone(), connect: self.low_latency_connect.clone() };
        super::low_latency::low_latency_config(main, &given)
    }

    /// The topic map: file (or default), then `--namespace`.
    pub fn topic_map(&self) -> Result<TopicMap, ConfigError> {
        let map = TopicMap::load_or_default(self.topics.as_deref())?;
        match &self.namespace {
            Some(ns) => map.with_namespace(ns),
            None => Ok(map),
        }
    }
}

fn load_zenoh_file(path: &Path) -> Result<zenoh::Config, ConfigError> {
    let origin = ConfigError::file(path);
    if !path.is_file() {
        return Err(ConfigError::new(
            &origin,
            "",
            "no such file",
            "give an existing file to -c/--config, or leave the flag out for the default",
        ));
    }
    zenoh::Config::from_file(path).map_err(|e| {
        // The text only to point at the key; Zenoh reads the file itself (JSON5 or YAML).
        let text = std::fs::read_to_string(path).unwrap_or_default();
        super::zenoh_error::file_error(&origin, &text, &e)
    })
}

/// Refuses an IP endpoint without its port (`tcp/127.0.0.1`), which Zenoh takes and then
/// never connects with: the flag, the endpoint and the fix.
fn check_endpoints(endpoints: &[String], flag: &str) -> Result<(), ConfigError> {
    const IP_LINKS: [&str; 6] = ["tcp", "udp", "tls", "quic", "ws", "wss"];
    for e in endpoints {
        let Some((proto, address)) = e.split_once('/') else { continue };
        if !IP_LINKS.contains(&proto) {
            continue;
        }
        let address = address.split('#').next().unwrap_or(address);
        // `host:port` or `[v6]:port`: the last `:` starts the port.
        let port = address.rsplit_once(':').map(|(_, port)| port);
        if !port.is_some_and(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_digit())) {
            return Err(ConfigError::new(
                flag,
                e,
                "no port",
                format!("give the port, e.g. {proto}/{address}:7447 (7447: Zenoh's and slipstream's default)"),
            ));
        }
    }
    Ok(())
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}
