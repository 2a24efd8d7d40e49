//! `slipstream router`: a Zenoh router for nodes on several PCs (client mode), for users who
//! have no zenohd. config/router.json5 (or -c FILE), then the connection flags; until Ctrl-C.

use anyhow::{anyhow, Result};

use crate::config::ConnectArgs;

/// Runs the router until Ctrl-C. The caller must not have applied slipstream's handover
/// runtime layout: a router's receive path forwards, and on the transmit pool it starves the
/// forwarding of messages of several batches (docs/architecture.md).
pub fn run(connect: &ConnectArgs) -> Result<()> {
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let mut config = connect.router_config()?;
        config.insert_json5("mode", "\"router\"").map_err(|e| anyhow!("router mode: {e}"))?;
        let session = zenoh::open(config).await.map_err(|e| anyhow!("start the router: {e}"))?;
        let locators: Vec<String> = session.info().locators().await.iter().map(|l| l.to_string()).collect();
        tracing::info!(zid = %session.zid(), ?locators, "router up (Ctrl-C to stop)");
        println!("{}", crate::launch::listening_line(&session.zid().to_string(), &locators));
        crate::cli::stop_requested().await;
        session.close().await.map_err(|e| anyhow!("close the router: {e}"))?;
        Ok(())
    })
}

/// `slipstream router`: until Ctrl-C.
pub fn command(connect: &ConnectArgs) -> Result<std::process::ExitCode> {
    run(connect).map(|()| std::process::ExitCode::SUCCESS)
}
