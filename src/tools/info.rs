//! `slipstream info`: the key map after namespace and remapping, QoS per topic, and the Zenoh
//! mode and endpoints the connection flags produce.

use serde::Serialize;

use crate::config::{ConfigError, ConnectArgs};
use crate::qos::{Delivery, TopicQos};
use crate::topics::Topic;

#[derive(Debug, Serialize)]
pub struct TopicInfo {
    pub topic: &'static str,
    pub key: String,
    pub message: &'static str,
    pub encoding: String,
    #[serde(flatten)]
    pub qos: TopicQos,
}

#[derive(Debug, Serialize)]
pub struct Info {
    pub topic_config: String,
    pub namespace: String,
    pub topics: Vec<TopicInfo>,
    pub zenoh_mode: String,
    pub zenoh_listen: serde_json::Value,
    pub zenoh_connect: serde_json::Value,
    pub multicast_scouting: serde_json::Value,
    pub shared_memory: serde_json::Value,
}

/// Gathers the info without opening a session.
pub fn gather(args: &ConnectArgs) -> Result<Info, ConfigError> {
    let map = args.topic_map()?;
    let z = args.zenoh_config()?;
    let get =
        |k: &str| z.get_json(k).ok().and_then(|s| serde_json::from_str(&s).ok()).unwrap_or(serde_json::Value::Null);
    let topics = Topic::ALL
        .into_iter()
        .map(|t| TopicInfo {
            topic: t.name(),
            key: map.key(t).to_string(),
            message: t.kind().name(),
            encoding: format!("application/octet-stream;{}", t.kind().encoding_schema()),
            qos: map.qos(t),
        })
        .collect();
    Ok(Info {
        topic_config: map.origin.clone(),
        namespace: map.namespace().to_string(),
        topics,
        zenoh_mode: get("mode").as_str().unwrap_or("peer").to_string(),
        zenoh_listen: get("listen/endpoints"),
        zenoh_connect: get("connect/endpoints"),
        multicast_scouting: get("scouting/multicast/enabled"),
        shared_memory: get("transport/shared_memory/enabled"),
    })
}

/// Human-readable rendering.
pub fn render(info: &Info) -> String {
    let mut s = format!(
        "topic config: {}\nnamespace:    {}\nzenoh:        mode {}, listen {}, connect {}, multicast scouting {}, shared memory {}\n\n",
        info.topic_config,
        if info.namespace.is_empty() { "(none)" } else { &info.namespace },
        info.zenoh_mode,
        info.zenoh_listen,
        info.zenoh_connect,
        info.multicast_scouting,
        info.shared_memory,
    );
    s.push_str(&format!(
        "{:<20} {:<28} {:<19} {:<17} {:<7} {:<6} {:<11} {}\n",
        "TOPIC", "KEY", "MESSAGE", "PRIORITY", "EXPRESS", "CC", "RELIABILITY", "DELIVERY"
    ));
    for t in &info.topics {
        let q = &t.qos;
        let delivery = match q.delivery {
            Delivery::Latest => "latest".to_string(),
            Delivery::Queue(n) => format!("queue {n}"),
        };
        let mut rate = q.max_rate_hz.map(|r| format!(", max {r} Hz")).unwrap_or_default();
        if q.latched {
            rate.push_str(", latched");
        }
        s.push_str(&format!(
            "{:<20} {:<28} {:<19} {:<17} {:<7} {:<6} {:<11} {}{}\n",
            t.topic,
            t.key,
            t.message,
            format!("{:?}", q.priority),
            q.express,
            format!("{:?}", q.congestion_control).to_lowercase(),
            format!("{:?}", q.reliability).to_lowercase(),
            delivery,
            rate
        ));
    }
    s
}

/// `slipstream info`: the table, or JSON with `json`.
pub fn command(json: bool, connect: &ConnectArgs) -> anyhow::Result<std::process::ExitCode> {
    let info = gather(connect)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        print!("{}", render(&info));
    }
    Ok(std::process::ExitCode::SUCCESS)
}
