//! What every binary does before its work (Zenoh's runtime choice and logging) and after it
//! (its error, said for a person).

use tracing::field::{Field, Visit};
use tracing::{Event, Metadata};
use tracing_subscriber::layer::{Context, Filter, SubscriberExt};
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer};

mod repeats;

pub use slipstream_contract::process::{
    apply_router_runtime, apply_zenoh_runtime_default, stop_requested, ZENOH_RUNTIME_DEFAULT,
};

/// The exit of a binary's `main`: its code, or on an error the error and each cause under it
/// (see [`error_report`]) on stderr and exit code 1.
pub fn exit_code(result: anyhow::Result<std::process::ExitCode>) -> std::process::ExitCode {
    result.unwrap_or_else(|e| {
        eprint!("{}", error_report(&e));
        std::process::ExitCode::FAILURE
    })
}

/// The exit of a node binary's `main`: as [`exit_code`], and with `json` (the node's `--json`,
/// its report on stdout) a failure also goes to stdout as the report, a
/// [`crate::node::Failure`], so a launcher reads why the node ended from its report.
pub fn node_exit_code(result: anyhow::Result<()>, json: bool) -> std::process::ExitCode {
    if let (Err(e), true) = (&result, json) {
        let clean = |text: String| crate::bus::without_source_locations(&text);
        let failure = crate::node::Failure {
            error: clean(e.to_string()),
            causes: e.chain().skip(1).map(|c| clean(c.to_string())).collect(),
        };
        if let Ok(text) = serde_json::to_string_pretty(&failure) {
            println!("{text}");
        }
    }
    exit_code(result.map(|()| std::process::ExitCode::SUCCESS))
}

/// An error as a person reads it: `Error: ` and what failed, then a line per cause under it.
/// No stack trace: RUST_BACKTRACE=1, often set for panics, made every bad config key and every
/// missed aim print sixty lines of frames; RUST_LIB_BACKTRACE=1 adds the trace where it was
/// captured (anyhow's switch for errors, as against panics).
pub fn error_report(e: &anyhow::Error) -> String {
    let clean = |text: String| crate::bus::without_source_locations(&text);
    let mut out = format!("Error: {}\n", clean(e.to_string()));
    for cause in e.chain().skip(1) {
        out.push_str(&format!("  caused by: {}\n", clean(cause.to_string())));
    }
    if std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0") {
        out.push_str(&format!("\n{}\n", e.backtrace()));
    }
    out
}

/// Whether to colour what goes to `stream`: only on a terminal, and never when NO_COLOR is set
/// to anything but the empty string (no-color.org).
pub fn colour(stream: &impl std::io::IsTerminal) -> bool {
    stream.is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// What a process logs when RUST_LOG is not set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogLevel {
    /// A node or a daemon (the simulator, the detector, the ACC, a router): its lifecycle at
    /// INFO, into the log file `up` gives it or the terminal it runs in.
    Node,
    /// A tool a person runs at a terminal (`up`, `top`, `echo`, `record`, ...): warnings and
    /// errors only, so that its own output (a live view, JSON lines, a verdict) is all there is.
    Tool,
}

/// Logs to stderr, filtered by RUST_LOG (default by `level`; warnings for Zenoh and the
/// Foxglove server), without the messages Zenoh prints for the loopback rendezvous working as
/// designed (see config/zenoh.json5), and with a library's repeated warnings shown once per
/// period ([`repeats`]: a peer sending garbage cannot flood stderr).
pub fn init_tracing(level: LogLevel) {
    let base = match level {
        LogLevel::Node => "info",
        LogLevel::Tool => "warn",
    };
    let env = EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        EnvFilter::new(format!("{base},zenoh=warn,zenoh_ext=warn,foxglove=warn,{ACL_TARGET}=trace"))
    });
    let layer = tracing_subscriber::fmt::layer()
        // Above a live status (a progress bar), never inside it.
        .with_writer(|| LogLine(Vec::new()))
        // Colours on a terminal only: `slipstream up` writes the nodes' logs to files.
        .with_ansi(colour(&std::io::stderr()))
        .with_filter(repeats::Repeats::default())
        .with_filter(RendezvousNoise)
        .with_filter(AclRefusals::default())
        .with_filter(env);
    let _ = tracing_subscriber::registry().with(layer).try_init();
}

/// One log event's text, written to stderr whole when the event is done
/// ([`crate::tools::status::write_above`]).
struct LogLine(Vec<u8>);

impl std::io::Write for LogLine {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for LogLine {
    fn drop(&mut self) {
        if !self.0.is_empty() {
            let _ = crate::tools::status::write_above(&self.0);
        }
    }
}

/// Drops the Zenoh events that the rendezvous of config/zenoh.json5 causes on purpose: the
/// node holding the loopback rendezvous port is refused when it dials itself (every retry),
/// the other nodes find that port busy, and session open notes that the self-dial never
/// completed. Also Zenoh's note, on every unix-socket connection it opens, that the client
/// end has no path (it never has one; the link works): `up` and `eval` link their nodes so;
/// and its note that without gossip region gateways cannot de-duplicate (slipstream uses no
/// region gateways; `eval` turns gossip off). Everything else passes.
struct RendezvousNoise;

struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

/// Whether a Zenoh log message is rendezvous noise.
pub fn is_rendezvous_noise(message: &str) -> bool {
    message.contains("CONNECTION_TO_SELF")
        || message.contains("establish transport to itself")
        || message.contains("Scouting delay elapsed before start conditions are met")
        || (message.contains("Unable to open listener tcp/127.0.0.1:") && message.contains("Address already in use"))
        || (message.starts_with("Can not create a new UnixSocketStream link bound to") && message.ends_with('"'))
        || message.starts_with("Gossip is disabled: cannot de-duplicate data traversing region gateways")
}

impl<S> Filter<S> for RendezvousNoise {
    fn enabled(&self, _meta: &Metadata<'_>, _cx: &Context<'_, S>) -> bool {
        true
    }

    fn event_enabled(&self, event: &Event<'_>, _cx: &Context<'_, S>) -> bool {
        if !event.metadata().target().starts_with("zenoh") {
            return true;
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        !is_rendezvous_noise(&m.0)
    }
}

/// Where Zenoh's access control says what it decided (at trace level only).
const ACL_TARGET: &str = "zenoh::net::routing::interceptor::access_control";
/// A refusal of the same thing is logged at most once per this period.
const REFUSAL_LOG_EVERY: std::time::Duration = std::time::Duration::from_secs(5);

/// Lets through, of Zenoh's access-control decisions, only the refusals ("... is unauthorized
/// to put on car2/vehicle/control"), each at most once per [`REFUSAL_LOG_EVERY`]: a router
/// with access control says in its log who was refused what (docs/deployment.md), without a
/// line for every message it allows or every repeat of a flood.
#[derive(Default)]
struct AclRefusals {
    last: parking_lot::Mutex<std::collections::HashMap<String, std::time::Instant>>,
}

impl AclRefusals {
    fn admits(&self, message: &str, now: std::time::Instant) -> bool {
        if !message.contains("is unauthorized to") {
            return false;
        }
        // "Using cached result: X" repeats X's first decision: one key for both.
        let what = message.trim_start_matches("Using cached result: ").to_string();
        let mut last = self.last.lock();
        if last.len() > 1024 {
            last.clear();
        }
        match last.get(&what) {
            Some(t) if now.duration_since(*t) < REFUSAL_LOG_EVERY => false,
            _ => {
                last.insert(what, now);
                true
            }
        }
    }
}

impl<S> Filter<S> for AclRefusals {
    fn enabled(&self, _meta: &Metadata<'_>, _cx: &Context<'_, S>) -> bool {
        true
    }

    fn event_enabled(&self, event: &Event<'_>, _cx: &Context<'_, S>) -> bool {
        if event.metadata().target() != ACL_TARGET || *event.metadata().level() <= tracing::Level::INFO {
            return true;
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        self.admits(&m.0, std::time::Instant::now())
    }
}

/// Opens a bus as `node` on `connect`'s config, runs `f` with it and leaves it: the frame of
/// every tool that is one participant on the bus for its whole run. Leaving cannot fail the
/// tool ([`crate::Bus::leave`]); a tool prints its verdict inside `f`, so nothing on the way
/// out can delay or lose it.
pub fn on_bus<T, F, Fut>(connect: &crate::ConnectArgs, node: &str, f: F) -> anyhow::Result<T>
where
    F: FnOnce(std::sync::Arc<crate::Bus>) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<T>>,
{
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let bus = std::sync::Arc::new(crate::Bus::open(connect.zenoh_config()?, connect.topic_map()?, node).await?);
        let out = f(bus.clone()).await;
        match std::sync::Arc::try_unwrap(bus) {
            Ok(bus) => bus.leave().await,
            Err(_) => tracing::warn!(node, "the bus is still in use at the end; left to the process's exit"),
        }
        out
    })
}

/// A node name of this process's own (`top-4242`), so that several copies of a watching tool
/// can run at once.
pub fn own_name(tool: &str) -> String {
    format!("{tool}-{}", std::process::id())
}

/// Exit 0 when the command says all went well, 1 when it says otherwise (something lost, a
/// rule failed).
pub fn exit_when(clean: bool) -> std::process::ExitCode {
    if clean {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    }
}

/// A report on stdout, flushed: pretty JSON with `json`, else its markdown rendering.
pub fn print_report<R: serde::Serialize>(json: bool, report: &R, markdown: fn(&R) -> String) -> anyhow::Result<()> {
    use std::io::Write;
    let text = if json { serde_json::to_string_pretty(report)? } else { markdown(report) };
    let mut out = std::io::stdout().lock();
    writeln!(out, "{text}")?;
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{error_report, is_rendezvous_noise};

    #[test]
    fn only_access_control_refusals_pass_and_each_once_a_while() {
        let f = super::AclRefusals::default();
        let t0 = std::time::Instant::now();
        let refused = "zid on car1-acc is unauthorized to put on car2/vehicle/control";
        assert!(f.admits(refused, t0));
        assert!(!f.admits(&format!("Using cached result: {refused}"), t0 + std::time::Duration::from_secs(1)));
        assert!(f.admits(refused, t0 + super::REFUSAL_LOG_EVERY));
        assert!(!f.admits("zid on car1-acc is authorized to put on car1/vehicle/control", t0));
    }

    #[test]
    fn an_error_is_reported_with_each_cause_on_a_line_of_its_own() {
        let e = anyhow::anyhow!("no such file").context("read scenarios/x.json5").context("scenario `x`");
        assert_eq!(
            error_report(&e),
            "Error: scenario `x`\n  caused by: read scenarios/x.json5\n  caused by: no such file\n"
        );
    }

    #[test]
    fn only_the_expected_zenoh_notes_are_noise() {
        assert!(is_rendezvous_noise("Can not create a new UnixSocketStream link bound to \"/tmp/s/acc.sock\""));
        // A unix socket that cannot be reached is an error worth seeing.
        assert!(!is_rendezvous_noise(
            "Can not create a new UnixSocketStream link bound to \"/tmp/s/acc.sock\": No such file or directory (os error 2)"
        ));
        assert!(is_rendezvous_noise("Unable to open listener tcp/127.0.0.1:7447: Address already in use"));
        assert!(!is_rendezvous_noise("Unable to open listener tcp/10.0.0.1:7447: Address already in use"));
    }
}
