//! How a platoon run's processes reach each other: directly on loopback (each node dials the
//! observer, Zenoh's peers then mesh), or every node a client of one Zenoh router with shared
//! memory off, so that every message of every car crosses the router as it does between PCs.
//! In lockstep the simulator waits for each car's command, so the string-stability figures do
//! not depend on the links; the wall time a run takes does, and the router path is where a
//! deployment's routers show up first (a queue, a filter, a router of another build).

use crate::error::{Error, Result};
use slipstream_contract::config::{ConnectArgs, ModeArg};
use slipstream_launch::LocalRouter;

/// Zenoh's setting that keeps large payloads off the router: with shared memory on, processes
/// on one machine would hand each other references and the router would carry only those.
const NO_SHARED_MEMORY: &str = "transport/shared_memory/enabled:false";

/// The links of every run of one measurement.
pub enum Links {
    /// Every node dials the observer on loopback.
    Direct,
    /// Every node (the observer too) a client of the router at `endpoint`; `started` is the
    /// router this measurement runs itself, stopped with it.
    Router { endpoint: String, started: Option<LocalRouter> },
}

impl Links {
    /// `--router`: absent, direct; given with no value (`""`), a `slipstream router` of our own
    /// on a free loopback port, its log in `log`; given an endpoint, a router already there.
    pub(crate) fn from_arg(router: Option<&str>, log: &std::path::Path) -> Result<Links> {
        match router {
            None => Ok(Links::Direct),
            Some("") => start_router(log),
            Some(endpoint) => Ok(Links::Router { endpoint: endpoint.to_string(), started: None }),
        }
    }

    /// The router's endpoint, when the nodes go through one.
    pub fn router(&self) -> Option<&str> {
        match self {
            Links::Direct => None,
            Links::Router { endpoint, .. } => Some(endpoint),
        }
    }

    /// The observer's connection in namespace `ns`: listening on `here` when direct.
    pub fn observer(&self, ns: &str, here: &str) -> ConnectArgs {
        let mut c = ConnectArgs { namespace: Some(ns.to_string()), no_multicast_scouting: true, ..Default::default() };
        match self.router() {
            None => c.listen = vec![here.to_string()],
            Some(r) => {
                c.mode = Some(ModeArg::Client);
                c.connect = vec![r.to_string()];
                c.cfg = vec![NO_SHARED_MEMORY.to_string()];
            }
        }
        c
    }

    /// A node's connection flags: dialling the observer at `here` when direct.
    pub(crate) fn node_args(&self, here: &str) -> Vec<String> {
        let args: Vec<&str> = match self.router() {
            None => vec!["-e", here, "-l", "tcp/127.0.0.1:0", "--no-multicast-scouting"],
            Some(r) => vec!["-m", "client", "-e", r, "--no-multicast-scouting", "--cfg", NO_SHARED_MEMORY],
        };
        args.into_iter().map(String::from).collect()
    }
}

/// Starts `slipstream router` on a free loopback port, its log in `log`, and waits until it
/// listens (a client opened before that would fail at once).
fn start_router(log: &std::path::Path) -> Result<Links> {
    let file = std::fs::File::create(log).map_err(Error::file("create", log))?;
    let router = LocalRouter::start(&["--cfg", NO_SHARED_MEMORY], &[], file.into())?;
    tracing::info!(endpoint = router.endpoint(), "every node of the runs goes through the router");
    Ok(Links::Router { endpoint: router.endpoint().to_string(), started: Some(router) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn through_a_router_every_node_is_its_client_with_shared_memory_off() {
        let links = Links::Router { endpoint: "tcp/10.0.0.1:7447".into(), started: None };
        let args = links.node_args("tcp/127.0.0.1:9");
        assert_eq!(args[..4], ["-m", "client", "-e", "tcp/10.0.0.1:7447"]);
        assert!(args.contains(&NO_SHARED_MEMORY.to_string()) && !args.iter().any(|a| a.contains(":9")));
        let o = links.observer("ns", "tcp/127.0.0.1:9");
        assert_eq!(
            (o.mode, o.connect.as_slice(), o.listen.is_empty()),
            (Some(ModeArg::Client), &["tcp/10.0.0.1:7447".to_string()][..], true)
        );
    }

    #[test]
    fn direct_nodes_dial_the_observer() {
        let links = Links::from_arg(None, std::path::Path::new("/nonexistent")).unwrap();
        assert_eq!(links.node_args("tcp/127.0.0.1:9")[..2], ["-e", "tcp/127.0.0.1:9"]);
        assert_eq!(links.observer("ns", "tcp/127.0.0.1:9").listen, ["tcp/127.0.0.1:9"]);
        let given = Links::from_arg(Some("tcp/1.2.3.4:7447"), std::path::Path::new("/nonexistent")).unwrap();
        assert_eq!(given.router(), Some("tcp/1.2.3.4:7447"));
    }
}
