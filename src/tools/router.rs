//! `slipstream router`: a Zenoh router for nodes on several PCs (client mode), for users who
//! have no zenohd. config/router.json5 (or -c FILE, never SLIPSTREAM_ZENOH_CONFIG, the nodes'
//! config), then the connection flags; until Ctrl-C.

use anyhow::{anyhow, Result};

use crate::config::ConnectArgs;

/// Runs the router until Ctrl-C. The caller must not have applied slipstream's handover
/// runtime layout: a router's receive path forwards, and on the transmit pool it starves the
/// forwarding of messages of several batches (docs/architecture.md).
pub fn run(connect: &ConnectArgs) -> Result<()> {
    // SLIPSTREAM_ZENOH_CONFIG names the nodes' config (a peer's or a client's): the router's is
    // -c, or config/router.json5.
    let from_env = std::env::var_os("SLIPSTREAM_ZENOH_CONFIG").map(std::path::PathBuf::from);
    let connect = match &connect.zenoh_config {
        Some(file) if Some(file) == from_env.as_ref() => ConnectArgs { zenoh_config: None, ..connect.clone() },
        _ => connect.clone(),
    };
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let mut config = connect.router_config()?;
        config.insert_json5("mode", "\"router\"").map_err(|e| anyhow!("router mode: {e}"))?;
        let listen = config.get_json("listen/endpoints").unwrap_or_default();
        let session = zenoh::open(config).await.map_err(|e| refused(&e, &listen))?;
        let locators: Vec<String> = session.info().locators().await.iter().map(|l| l.to_string()).collect();
        tracing::info!(zid = %session.zid(), ?locators, "router up (Ctrl-C to stop)");
        println!("{}", crate::launch::listening_line(&session.zid().to_string(), &locators));
        crate::cli::stop_requested().await;
        session.close().await.map_err(|e| anyhow!("close the router: {e}"))?;
        Ok(())
    })
}

/// Why the router did not start, in our words: Zenoh's message without its source locations,
/// and for a port another program holds, which one to look for and the fix.
fn refused(e: &zenoh::Error, listen: &str) -> anyhow::Error {
    let message = crate::bus::zenoh_message(e);
    if message.contains("in use") {
        return anyhow!(
            "start the router: an endpoint of {listen} is taken: the address is already in use (fix: stop what holds it, `ss -ltnp` names it; or give this router another port, e.g. `slipstream router -l tcp/0.0.0.0:7448`, and its nodes `-e tcp/HOST:7448`)"
        );
    }
    anyhow!("start the router: {}", crate::bus::without_source_locations(&message))
}

/// `slipstream router`: until Ctrl-C.
pub fn command(connect: &ConnectArgs) -> Result<std::process::ExitCode> {
    run(connect).map(|()| std::process::ExitCode::SUCCESS)
}
