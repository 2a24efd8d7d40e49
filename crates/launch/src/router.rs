//! A `slipstream router` of a run's own on loopback, for the tools that put a router between
//! their processes (`eval platoon --router`, the bench's router cases). It listens on a port the
//! kernel picks (`tcp/127.0.0.1:0`, so no other process can take it first) and is known by the
//! endpoint it prints once it listens, so a client dialled after [`LocalRouter::start`]
//! returns finds it there.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use super::child::{sibling_binary, Child};
use crate::error::{Error, Result};

/// How long the router may take to listen.
const START_TIMEOUT: Duration = Duration::from_secs(20);

/// A router started here, stopped (SIGINT, then killed) when dropped.
pub struct LocalRouter {
    child: Child,
    endpoint: String,
}

impl LocalRouter {
    /// Starts `slipstream router` on loopback with multicast scouting off, `extra` flags after
    /// those (`--cfg KEY:VALUE`), `env` set and its log to `stderr`; waits until it listens.
    /// It runs with Zenoh's runtime layout of its own (ZENOH_RUNTIME removed), as users run it.
    pub fn start(extra: &[&str], env: &[(&str, String)], stderr: Stdio) -> Result<LocalRouter> {
        let mut cmd = Command::new(sibling_binary("slipstream")?);
        cmd.args(["router", "-l", "tcp/127.0.0.1:0", "--no-multicast-scouting"]).args(extra);
        cmd.env_remove("ZENOH_RUNTIME").envs(env.iter().map(|(k, v)| (k, v)));
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(stderr);
        let mut child = Child::spawn("slipstream router", &mut cmd)?;
        let stdout = child.take_stdout().ok_or_else(|| Error::node("slipstream router", "no stdout"))?;
        let (tx, rx) = std::sync::mpsc::channel();
        // Reads to the end, so the router never blocks on a full pipe; the line that says where it
        // listens is handed over.
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(std::io::Result::ok) {
                if let Some(endpoint) = listening_endpoint(&line) {
                    let _ = tx.send(endpoint);
                }
            }
        });
        match rx.recv_timeout(START_TIMEOUT) {
            Ok(endpoint) => {
                tracing::info!(%endpoint, "router up");
                Ok(LocalRouter { child, endpoint })
            }
            Err(_) => {
                let how = child
                    .exited()
                    .map_or(format!("did not listen within {START_TIMEOUT:?}"), |s| format!("ended ({s})"));
                Err(Error::node("slipstream router", format!("{how} before printing where it listens")))
            }
        }
    }

    /// Where clients connect: `tcp/127.0.0.1:PORT`.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The router's process id (for its CPU and memory in /proc).
    pub fn pid(&self) -> u32 {
        self.child.pid()
    }
}

/// The line `slipstream router` prints once it listens: its id and every locator. Written and
/// read here, so the tools that start a router and the router agree on it.
pub fn listening_line(zid: &str, locators: &[String]) -> String {
    format!("router {zid} listening on {}", locators.join(", "))
}

/// The TCP endpoint in a [`listening_line`].
fn listening_endpoint(line: &str) -> Option<String> {
    let (_, endpoints) = line.strip_prefix("router ")?.split_once("listening on ")?;
    endpoints.split(", ").find(|e| e.starts_with("tcp/")).map(str::to_string)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_endpoint_is_read_from_the_routers_line_and_only_from_it() {
        let line = listening_line("1f2e", &["udp/127.0.0.1:7000".into(), "tcp/127.0.0.1:41234".into()]);
        assert_eq!(listening_endpoint(&line).as_deref(), Some("tcp/127.0.0.1:41234"));
        assert_eq!(listening_endpoint("router 1f2e listening on udp/127.0.0.1:7000"), None);
        assert_eq!(listening_endpoint("INFO listening on tcp/127.0.0.1:1"), None);
    }
}
