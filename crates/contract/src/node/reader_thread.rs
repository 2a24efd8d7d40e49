//! A node's reader on a thread of its own until the node is asked to stop: frames are read
//! and detected there, woken by Zenoh's receive thread directly (waking an async task costs a
//! trip through the runtime's scheduler on every frame, docs/performance.md's frame hop table),
//! and detection is CPU work that must not hold an async worker. slipstream-detect and the
//! detector SDK both read this way.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::bus::BusError;

/// How often a reader looks up from an empty inbox to see whether the node stops.
pub const STOP_POLL: Duration = Duration::from_millis(100);

/// Runs `read(stop)` on a blocking thread until `shutdown` completes (then `stop` is set and
/// its result awaited) or it ends by itself (only on an error). A panic in it is resumed here.
pub async fn until_stopped<T: Send + 'static>(
    read: impl FnOnce(&AtomicBool) -> Result<T, BusError> + Send + 'static,
    shutdown: impl Future,
) -> Result<T, BusError> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let mut thread = tokio::task::spawn_blocking(move || read(&flag));
    let joined = |done: Result<Result<T, BusError>, tokio::task::JoinError>| match done {
        Ok(done) => done,
        Err(e) => std::panic::resume_unwind(e.into_panic()),
    };
    tokio::select! {
        _ = shutdown => {}
        done = &mut thread => return joined(done),
    }
    stop.store(true, Ordering::Relaxed);
    joined(thread.await)
}
