//! Zenoh's thread pools at the end of a process.
//!
//! Zenoh runs its work on thread pools kept in statics that nothing stops: they run on while
//! the process exits. Its shared-memory bookkeeping lives in statics that are finalized at
//! exit; a pool thread that touches it after that panics ("AccessError" from `static_init`).
//! Seen in `bench --quick`: a frame too big for the bus's pool went out from the heap, Zenoh
//! began making the link's implicit shared-memory pool on one of its blocking threads, and
//! the process exited before that thread was done.
//!
//! [`ZenohThreads`], held first in `main` and so dropped last, stops the pools once the
//! process's own work is done: it waits (up to a second per pool, Zenoh's choice) for their
//! tasks, then the exit handlers find no Zenoh thread running.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Buses alive in this process (see [`OpenBus`]).
static OPEN_BUSES: AtomicUsize = AtomicUsize::new(0);

/// Counts a bus as alive from its opening to its drop.
#[derive(Debug)]
pub(super) struct OpenBus(());

impl OpenBus {
    pub(super) fn new() -> Self {
        OPEN_BUSES.fetch_add(1, Ordering::SeqCst);
        OpenBus(())
    }
}

impl Drop for OpenBus {
    fn drop(&mut self) {
        OPEN_BUSES.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Stops Zenoh's thread pools when dropped. Declare it first in `main`, before the tokio
/// runtime, so that it is dropped after the runtime and every session: Zenoh may not be used
/// after it.
#[derive(Debug)]
#[must_use = "the pools stop when this is dropped: bind it (`let _zenoh = ...`) for all of main"]
pub struct ZenohThreads(());

impl ZenohThreads {
    pub fn stop_at_end_of_main() -> Self {
        ZenohThreads(())
    }
}

impl Drop for ZenohThreads {
    fn drop(&mut self) {
        // A bus still alive here (leaked, or held by a thread of our own) may still call into
        // the pools: leave them running then, as Zenoh would.
        let open = OPEN_BUSES.load(Ordering::SeqCst);
        if open > 0 {
            tracing::debug!(open, "a bus is still open at the end of main: Zenoh's threads left running");
            return;
        }
        drop(zenoh_runtime::ZRuntimePoolGuard);
    }
}
