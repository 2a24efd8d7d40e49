//! The Zenoh config of a node's low-latency session, derived from its main session's config so
//! that one config file and one set of flags set up both.
//!
//! The low-latency session runs Zenoh's low-latency transport: the publishing thread writes
//! the socket itself (no hand-off to a transmit task), one queue, no priorities, no
//! fragmentation. Two sessions that both run it talk over it; a session that does not (a
//! node's main session, a router, a plain Zenoh client in any language) talks to it over an
//! ordinary transport, because Zenoh agrees on the low-latency transport per link only when
//! both ends ask for it. So every subscriber still receives every topic.
//!
//! Where it listens and whom it dials, unless the flags say (`--low-latency-listen`,
//! `--low-latency-connect`):
//! - a unix socket `P`: `P.ll` (both sides derive the same path, so a loop on one host
//!   dials its peers' low-latency sessions directly);
//! - a TCP or UDP listener: the same address on a port the system picks (the fixed port
//!   belongs to the main session); other sessions find it through gossip or multicast
//!   scouting, as they find every peer;
//! - a TCP or UDP endpoint to dial: unchanged (whoever listens there introduces the rest);
//! - and its own node's main session (`Bus::open_sessions`), so that a peer given only the
//!   main session's address learns of the low-latency one there.
//!
//! Gossip stays as the main config sets it: it is how a third party (a Python client given
//! one address) finds the low-latency sessions, whose locators only they advertise.
//!
//! A client of a router gets no low-latency session: every message crosses the router, whose
//! transport has priorities, so a second session would only add a connection.

use super::ConfigError;

/// The suffix a unix socket's low-latency twin carries.
const UNIX_SUFFIX: &str = ".ll";

/// Endpoints the flags give the low-latency session instead of the derived ones.
#[derive(Debug, Clone, Default)]
pub struct LowLatencyEndpoints {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// The low-latency session's config, or None where a node gets none (client or router mode).
pub fn low_latency_config(
    main: &zenoh::Config,
    given: &LowLatencyEndpoints,
) -> Result<Option<zenoh::Config>, ConfigError> {
    let mode = main.get_json("mode").ok().and_then(|m| serde_json::from_str::<String>(&m).ok());
    if mode.as_deref().unwrap_or("peer") != "peer" {
        return Ok(None);
    }
    let mut config = main.clone();
    let listen = match given.listen.is_empty() {
        true => derive(&endpoints(main, "listen/endpoints"), true),
        false => given.listen.clone(),
    };
    let connect = match given.connect.is_empty() {
        true => derive(&endpoints(main, "connect/endpoints"), false),
        false => given.connect.clone(),
    };
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    for (key, value) in [
        ("transport/unicast/lowlatency", "true".to_string()),
        // The low-latency transport has no priority queues; Zenoh refuses it with QoS on.
        ("transport/unicast/qos/enabled", "false".to_string()),
        ("listen/endpoints", list(&listen)),
        ("connect/endpoints", list(&connect)),
        // Its links to sessions without the low-latency transport (an observer, a tool, a
        // router) have no priorities: one queue, the data priority's, 2 batches by default.
        // Every express message takes a batch, so two batches overflow whenever the transmit
        // task is a millisecond late, and at 100 Hz most of a simulator's states would drop on
        // those links; 16 batches ride out such a delay.
        ("transport/link/tx/queue/size/data", "16".to_string()),
        // Its messages are far below the shared-memory threshold: no pool of its own.
        ("transport/shared_memory/enabled", "false".to_string()),
        // A second session must not take the first one's id or start its plugins again.
        ("id", "null".to_string()),
        ("plugins", "{}".to_string()),
    ] {
        config.insert_json5(key, &value).map_err(|e| {
            ConfigError::new(
                "the low-latency session",
                key,
                format!("`{value}` rejected: {e}"),
                "give its endpoints with --low-latency-listen/--low-latency-connect, or run one session (leave out --low-latency-session)",
            )
        })?;
    }
    Ok(Some(config))
}

/// Adds the node's own main session (`own`: its listening locators) to what the low-latency
/// session `config` dials: a peer given only the main session's address learns of the
/// low-latency one there (gossip) and dials it. Not where gossip is off: there only the
/// endpoints given make the mesh.
pub fn dial_own_main(config: &mut zenoh::Config, own: &[String]) -> Result<(), ConfigError> {
    if !config.get_json("scouting/gossip/enabled").is_ok_and(|g| g == "true") {
        return Ok(());
    }
    let mut connect = endpoints(config, "connect/endpoints");
    connect.extend(own.iter().cloned());
    let list = serde_json::to_string(&connect).unwrap_or_else(|_| "[]".into());
    config.insert_json5("connect/endpoints", &list).map_err(|e| {
        ConfigError::new(
            "the low-latency session",
            "connect/endpoints",
            e.to_string(),
            "run one session (leave out --low-latency-session)",
        )
    })
}

fn endpoints(config: &zenoh::Config, key: &str) -> Vec<String> {
    let json = config.get_json(key).ok();
    // A mode-dependent list ({ peer: [...], router: [...] }) has no list for this purpose.
    json.and_then(|j| serde_json::from_str::<Vec<String>>(&j).ok()).unwrap_or_default()
}

/// The main session's endpoints mapped to the low-latency session's (see the module doc).
fn derive(main: &[String], listen: bool) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for e in main {
        let mapped = match e.split_once('/') {
            Some(("unixsock-stream", rest)) => {
                let (path, tail) = split_tail(rest);
                format!("unixsock-stream/{path}{UNIX_SUFFIX}{tail}")
            }
            Some((proto, rest)) if listen && (proto == "tcp" || proto == "udp") => {
                let (addr, tail) = split_tail(rest);
                match addr.rsplit_once(':') {
                    Some((host, _port)) => format!("{proto}/{host}:0{tail}"),
                    None => e.clone(),
                }
            }
            _ => e.clone(),
        };
        if !out.contains(&mapped) {
            out.push(mapped);
        }
    }
    out
}

/// An endpoint's address and what follows it (`?metadata`, `#config`).
fn split_tail(rest: &str) -> (&str, &str) {
    match rest.find(['?', '#']) {
        Some(i) => rest.split_at(i),
        None => (rest, ""),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(json: &str) -> zenoh::Config {
        zenoh::Config::from_json5(json).unwrap()
    }

    fn list(c: &zenoh::Config, key: &str) -> Vec<String> {
        endpoints(c, key)
    }

    #[test]
    fn a_peer_gets_twin_sockets_free_ports_and_the_same_rendezvous() {
        let main = config(
            r#"{ mode: "peer",
                 listen: { endpoints: ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:0", "unixsock-stream/tmp/run/acc.sock", "tcp/10.0.0.2:7447#iface=eth0"] },
                 connect: { endpoints: ["tcp/127.0.0.1:7447", "unixsock-stream/tmp/run/sim.sock"] } }"#,
        );
        let ll = low_latency_config(&main, &LowLatencyEndpoints::default()).unwrap().unwrap();
        assert_eq!(
            list(&ll, "listen/endpoints"),
            ["tcp/127.0.0.1:0", "unixsock-stream/tmp/run/acc.sock.ll", "tcp/10.0.0.2:0#iface=eth0"]
        );
        assert_eq!(list(&ll, "connect/endpoints"), ["tcp/127.0.0.1:7447", "unixsock-stream/tmp/run/sim.sock.ll"]);
        assert_eq!(ll.get_json("transport/unicast/lowlatency").unwrap(), "true");
        assert_eq!(ll.get_json("transport/unicast/qos/enabled").unwrap(), "false");
        assert_eq!(ll.get_json("id").unwrap(), "null");
        assert_eq!(ll.get_json("transport/link/tx/queue/size/data").unwrap(), "16");
        // The main config is left as it was.
        assert_eq!(main.get_json("transport/unicast/lowlatency").unwrap(), "false");
    }

    #[test]
    fn flags_replace_the_derived_endpoints_and_clients_get_no_second_session() {
        let main = config(r#"{ mode: "peer", id: "a1b2c3", listen: { endpoints: ["tcp/127.0.0.1:7447"] } }"#);
        let given = LowLatencyEndpoints { listen: vec!["tcp/127.0.0.1:9000".into()], connect: vec![] };
        let ll = low_latency_config(&main, &given).unwrap().unwrap();
        assert_eq!(list(&ll, "listen/endpoints"), ["tcp/127.0.0.1:9000"]);
        // A fixed id stays the main session's.
        assert_eq!(ll.get_json("id").unwrap(), "null");
        let client = config(r#"{ mode: "client", connect: { endpoints: ["tcp/10.0.0.1:7447"] } }"#);
        assert!(low_latency_config(&client, &LowLatencyEndpoints::default()).unwrap().is_none());
    }
}
