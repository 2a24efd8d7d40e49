//! `slipstream echo TOPIC`: the messages on one topic (or any key expression), decoded by their
//! kind byte and printed as JSON lines; camera frames summarized, and written as PNG files
//! with `--save DIR`.

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde_json::json;

use crate::bus::{Bus, TopicStats};
use crate::msg::{self, CameraFrameRef, MessageKind};
use crate::topics::Topic;

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  slipstream echo vehicle/speed --count 5\n  \
    slipstream echo camera/front --count 3 --save frames/\n  slipstream echo 'vehicle/**'")]
pub struct EchoArgs {
    /// A topic (vehicle/speed, camera/front, perception/objects, ...: `slipstream info` lists
    /// them with their keys after namespace and remapping) or any Zenoh key expression
    pub topic: String,
    /// Stop after this many messages
    #[arg(long)]
    pub count: Option<u64>,
    /// Print the payload as hex instead of decoding it (for payloads that do not decode)
    #[arg(long)]
    pub raw: bool,
    /// Write camera frames into this directory as PNG files (<key>-<seq>.png)
    #[arg(long, value_name = "DIR")]
    pub save: Option<PathBuf>,
    /// Stop after this many seconds [default: until Ctrl-C or --count]
    #[arg(long, value_parser = super::top::positive)]
    pub duration: Option<f64>,
}

/// Runs until --count, --duration or Ctrl-C. Returns how many messages it printed.
pub async fn run(bus: &Bus, args: &EchoArgs) -> Result<u64> {
    let (key, latched) = resolve(bus.topics(), &args.topic)?;
    if let Some(dir) = &args.save {
        std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    }
    // Samples (not copies: a sample holds its payload) go from Zenoh's thread to this loop.
    let (tx, mut rx) = tokio::sync::mpsc::channel::<zenoh::sample::Sample>(256);
    let dropped = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let d = dropped.clone();
    let _sub = bus
        .subscribe_samples(key.clone(), latched, move |s| {
            if tx.try_send(s).is_err() {
                d.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        })
        .await?;
    tracing::debug!(%key, "echo: waiting for messages");
    let bad = TopicStats::new(key.to_string());
    let deadline = args.duration.map(|d| Instant::now() + Duration::from_secs_f64(d));
    let mut printed = 0u64;
    let mut out = std::io::stdout().lock();
    let ctrl_c = crate::cli::stop_requested();
    tokio::pin!(ctrl_c);
    while args.count.is_none_or(|n| printed < n) {
        let left = deadline.map_or(Duration::from_secs(3600), |d| d.saturating_duration_since(Instant::now()));
        if left.is_zero() {
            break;
        }
        let sample = tokio::select! {
            _ = &mut ctrl_c => break,
            s = tokio::time::timeout(left, rx.recv()) => match s {
                Ok(Some(s)) => s,
                Ok(None) => break,
                Err(_) => continue,
            },
        };
        let line = match line(&sample, bus.topics(), args, &bad)? {
            Some(l) => l,
            None => continue,
        };
        writeln!(out, "{line}")?;
        out.flush()?;
        printed += 1;
    }
    if printed == 0 {
        let waited = args.duration.map_or(String::new(), |d| format!(" in {d} s"));
        eprintln!("echo: no message on {key}{waited} (`slipstream top` lists the keys that carry messages)");
    }
    let missed = dropped.load(std::sync::atomic::Ordering::Relaxed);
    if missed > 0 {
        tracing::warn!(missed, "messages arrived faster than they could be printed and were skipped");
    }
    Ok(printed)
}

/// The key to subscribe to for `given` and whether it is latched: a topic's key after
/// namespace and remapping, or any key expression. A name a letter or two off a topic's (or a
/// topic's last part alone) is refused with the topic it likely meant: waiting on a key
/// nothing publishes would look like a silent loop.
fn resolve(topics: &crate::TopicMap, given: &str) -> Result<(zenoh::key_expr::OwnedKeyExpr, bool)> {
    if let Some(t) = Topic::from_name(given) {
        return Ok((topics.key(t), topics.qos(t).latched));
    }
    if let Some(t) = Topic::nearest(given) {
        anyhow::bail!(
            "`{given}` is not a topic: did you mean {}? (topics: {}; a key expression nothing publishes yet can be given with a wildcard, e.g. `{given}/**`)",
            t.name(),
            Topic::ALL.map(|t| t.name()).join(", ")
        );
    }
    let key = zenoh::key_expr::OwnedKeyExpr::autocanonize(given.to_string()).map_err(|e| {
        anyhow::anyhow!(
            "`{given}` is neither a topic nor a key expression ({}); topics: {}",
            crate::bus::zenoh_message(&e),
            Topic::ALL.map(|t| t.name()).join(", ")
        )
    })?;
    Ok((key, false))
}

/// The JSON line for one sample; None (counted and logged) when it does not decode. A sample
/// that is not the loop's ([`crate::bus::is_foreign`], e.g. a bridged ROS 2 message under
/// `echo '**'`) is shown by its key, encoding and size, not counted as malformed.
fn line(
    sample: &zenoh::sample::Sample,
    topics: &crate::TopicMap,
    args: &EchoArgs,
    bad: &TopicStats,
) -> Result<Option<String>> {
    let key = sample.key_expr().as_str();
    let from = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
    let payload = sample.payload().to_bytes();
    let received_ns = msg::wall_clock_ns();
    if args.raw {
        let v = json!({ "key": key, "from": from, "bytes": payload.len(), "hex": msg::hex_lines(&payload).replace('\n', " ") });
        return Ok(Some(v.to_string()));
    }
    if crate::bus::is_foreign(sample, topics) {
        let v = json!({ "key": key, "from": from, "encoding": sample.encoding().to_string(), "bytes": payload.len() });
        return Ok(Some(v.to_string()));
    }
    let (kind, header, body) = match msg::decode_json(&payload) {
        Ok(d) => d,
        Err(e) => {
            bad.on_decode_error(&format_args!("{key}: {e} (--raw prints the bytes)"));
            return Ok(None);
        }
    };
    let mut v = json!({
        "key": key,
        "from": from,
        "kind": kind.name(),
        "header": header,
        "latency_us": (received_ns as i64 - header.stamp_pub_ns as i64) as f64 / 1e3,
        "msg": body,
    });
    if kind == MessageKind::CameraFrame {
        if let Some(dir) = &args.save {
            let frame = msg::decode::<CameraFrameRef>(&payload)?.msg;
            // Raw frames are encoded from the payload in place; JPEG is decoded once.
            let rgb = frame.to_rgb8()?;
            let path = dir.join(format!("{}-{:06}.png", key.replace('/', "_"), header.seq));
            image::save_buffer_with_format(
                &path,
                &rgb,
                frame.width,
                frame.height,
                image::ExtendedColorType::Rgb8,
                image::ImageFormat::Png,
            )
            .with_context(|| format!("write {}", path.display()))?;
            v["saved"] = json!(path);
        }
    }
    Ok(Some(v.to_string()))
}

/// `slipstream echo`: fails when --count messages did not come.
pub fn command(args: &EchoArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    // A typo is refused before joining the bus.
    resolve(&connect.topic_map()?, &args.topic)?;
    let printed =
        crate::cli::on_bus(connect, &crate::cli::own_name("echo"), |bus| async move { run(&bus, args).await })?;
    match args.count {
        Some(n) if printed < n => anyhow::bail!("{printed} of {n} messages seen on {}", args.topic),
        _ => Ok(std::process::ExitCode::SUCCESS),
    }
}
