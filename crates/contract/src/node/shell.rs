//! The shell around every node's body: what each `main` of slipstream-sim, slipstream-detect,
//! slipstream-acc and a user's own node would otherwise repeat, in one place so that they
//! start, stop and leave the bus the same way.

use std::future::Future;
use std::pin::Pin;

use crate::bus::{Bus, BusError};
use crate::config::{ConnectArgs, FaultArgs};
use crate::process;

/// Resolves when the process is asked to stop (Ctrl-C, SIGTERM, SIGHUP).
pub type Shutdown = Pin<Box<dyn Future<Output = ()> + Send>>;

/// Runs `body` as the node `name`: Zenoh's thread layout of every slipstream node applied
/// (unless ZENOH_RUNTIME is set), a multi-threaded tokio runtime, the bus opened from the
/// connection flags with `faults` injected on what the node receives, `body` given the bus
/// and a future that resolves on a stop signal, then the bus left (its token withdrawn, its
/// sessions closed) whether `body` succeeded or not. Call it from `main`, before any thread
/// starts; clap's parsing starts none.
pub fn serve<T, E>(
    connect: &ConnectArgs,
    faults: &FaultArgs,
    name: &str,
    body: impl AsyncFnOnce(&Bus, Shutdown) -> Result<T, E>,
) -> Result<T, E>
where
    E: From<BusError> + From<std::io::Error>,
{
    process::apply_zenoh_runtime_default();
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async {
        let bus = Bus::open_node(connect, faults, name).await?;
        let shutdown = Box::pin(async {
            let signal = process::stop_requested().await;
            tracing::info!("{signal}: stopping");
        });
        let done = body(&bus, shutdown).await;
        bus.leave().await;
        done
    })
}
