//! What every process on the bus does the same way, ours or a user's own node: Zenoh's thread
//! layout, chosen before Zenoh starts, and the signals that ask it to stop.

/// Zenoh's thread layout for slipstream processes: rx, acceptor, app and net work all hand
/// over to the tx pool instead of each having its own. Fewer thread wake-ups per message: on
/// the 2-core machines of docs/performance.md Zenoh's own layout takes the 100 Hz speed
/// message's median one-way latency from 161 to 259 us (`bench speed`, 2026-11-29).
///
/// The pool has four workers, not Zenoh's one. Zenoh sends what may not be dropped (a query's
/// reply, a new node's declarations told to the others) from the receive task that caused it,
/// and when the queue towards a peer that stopped reading is full, that send blocks its worker
/// until the transmit task drains the queue. With one worker the blocked thread was the only one
/// that could run the transmit task or poll the sockets: the process's Zenoh stood still, and
/// after 5 s Zenoh closed the link ("Unable to push non droppable network message"). A node slow
/// to read while another joined did that to the simulator (tests/python/test_slow_reader.py).
/// Each blocked send holds one worker; the spare ones drain the queue once the reader reads.
/// Zenoh's own layout (a pool per role) has no such stall but doubles the speed message's
/// latency (docs/performance.md).
pub const ZENOH_RUNTIME_DEFAULT: &str =
    "(rx: (handover: tx), acc: (handover: tx), app: (handover: tx), net: (handover: tx), tx: (worker_threads: 4))";

/// Sets ZENOH_RUNTIME to [`ZENOH_RUNTIME_DEFAULT`] unless the user set it (`ZENOH_RUNTIME='()'`
/// restores Zenoh's own layout). Call early in `main`, before any thread or Zenoh starts:
/// Zenoh reads the variable once, when its first runtime starts.
pub fn apply_zenoh_runtime_default() {
    if std::env::var_os("ZENOH_RUNTIME").is_none() {
        // Single-threaded at this point of main: no other thread reads the environment.
        std::env::set_var("ZENOH_RUNTIME", ZENOH_RUNTIME_DEFAULT);
    }
}

/// A router's runtime: Zenoh's own layout. A router forwards what it receives, and with
/// [`ZENOH_RUNTIME_DEFAULT`]'s handover layout it never forwarded a message of several batches
/// (a raw camera frame); so when a router inherits that layout from a slipstream process that
/// started it (`bench fleet`, a script run beside `up`), the layout is taken back. Any other
/// ZENOH_RUNTIME the user set stays. Call early in `main`, before any thread or Zenoh starts.
pub fn apply_router_runtime() {
    if std::env::var("ZENOH_RUNTIME").is_ok_and(|v| v == ZENOH_RUNTIME_DEFAULT) {
        // Single-threaded at this point of main: no other thread reads the environment.
        std::env::remove_var("ZENOH_RUNTIME");
    }
}

/// Resolves when the process is asked to stop: Ctrl-C (SIGINT), SIGTERM (a supervisor, `kill`,
/// systemd, docker stop) or SIGHUP (its terminal closed). Every long-running command stops on
/// any of them the same way, nodes stopped and reports written. Returns the signal's name.
pub async fn stop_requested() -> &'static str {
    use tokio::signal::unix::{signal, SignalKind};
    let (term, hup) = (signal(SignalKind::terminate()), signal(SignalKind::hangup()));
    let (Ok(mut term), Ok(mut hup)) = (term, hup) else {
        // No signal handling here (not expected on Linux): Ctrl-C alone.
        let _ = tokio::signal::ctrl_c().await;
        return "Ctrl-C";
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => "Ctrl-C",
        _ = term.recv() => "SIGTERM",
        _ = hup.recv() => "SIGHUP",
    }
}
