//! Configuration: the topic map (config/slipstream.json5) and the Zenoh connection
//! (config/zenoh.json5 plus the shared command-line flags).

mod closest;
mod connect;
mod error;
pub mod faults;
mod low_latency;
mod topic_map;
mod zenoh_error;

pub use closest::{closest, MAX_TYPO};
pub use connect::{ConnectArgs, ModeArg, DEFAULT_ZENOH_CONFIG, DEFAULT_ZENOH_CONFIG_PATH};
pub use error::{
    from_value, merge_json, parse_json5, parse_json5_value, parse_layered, read_config, ConfigError, Invalid,
};
pub use faults::{FaultArgs, FaultProfile, GilbertElliott, Jitter, JitterDist, Loss, Outage, TopicFaults};
pub use low_latency::{dial_own_main, low_latency_config, LowLatencyEndpoints};
pub use topic_map::{
    CameraEncoding, CameraSettings, EncodingSet, ResolvedTopic, TopicMap, DEFAULT_SLIPSTREAM_CONFIG_PATH,
};
