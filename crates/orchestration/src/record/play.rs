//! Playing a recording back onto the bus: every payload byte for byte on its key (moved into
//! this bus's namespace), with its publisher's name as the attachment, at the recorded pace
//! (or faster, or as fast as the subscribers take it).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use serde::Serialize;
use zenoh::key_expr::OwnedKeyExpr;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use slipstream_contract::bus::Bus;

/// How fast to play.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// The recorded timing, this many times faster (1.0: as recorded).
    Rate(f64),
    /// As fast as the subscribers take it: congestion control "block" on every key, so nothing
    /// is dropped (fast replay with "drop" loses messages).
    Max,
}

/// What to play.
#[derive(Debug, Clone)]
pub struct PlayOptions {
    pub pace: Pace,
    /// Skip the first this many seconds of the recording.
    pub start_s: f64,
    /// Only keys (relative to the recording's namespace) matching one of these; empty: all.
    pub keys: Vec<OwnedKeyExpr>,
}

/// What a playback did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct PlayReport {
    pub messages: u64,
    pub bytes: u64,
    /// Recorded time covered, seconds.
    pub recorded_s: f64,
    pub wall_s: f64,
    /// Messages skipped by --start or --keys.
    pub skipped: u64,
    /// The file ended in a partial record (cut by a crash): played up to it.
    pub cut: bool,
}

/// A key of the recording on this bus, with its publisher.
pub(crate) struct Output {
    publisher: zenoh::pubsub::Publisher<'static>,
    attachment: Option<String>,
}

impl Output {
    /// Publishes a recorded payload as it was, with its publisher's name.
    pub(crate) fn put(&self, payload: Vec<u8>) -> Result<()> {
        let mut put = self.publisher.put(payload);
        if let Some(a) = &self.attachment {
            put = put.attachment(a.clone());
        }
        put.wait().map_err(Error::zenoh(format!("publish on {}", self.publisher.key_expr())))
    }
}

/// Calls `f` with every message of the recording at `path`, in file order: the one reader of
/// recordings (`play`, re-simulation, the view's replay). A file cut by a crash is read up to
/// the cut and `true` returned; a file that is no MCAP at all is an error.
pub fn each_message(path: &Path, mut f: impl FnMut(mcap::Message<'static>) -> Result<()>) -> Result<bool> {
    each_message_until(path, |m| f(m).map(|()| ControlFlow::Continue(())))
}

/// [`each_message`] that `f` may stop early (`ControlFlow::Break`): the rest is not read.
pub fn each_message_until(
    path: &Path,
    mut f: impl FnMut(mcap::Message<'static>) -> Result<ControlFlow<()>>,
) -> Result<bool> {
    let file = File::open(path).map_err(Error::file("open", path))?;
    let mut seen = false;
    for message in mcap::io::MessageReader::new(BufReader::new(file)) {
        match message {
            Ok(m) => {
                seen = true;
                if f(m)?.is_break() {
                    return Ok(false);
                }
            }
            Err(e) if seen => {
                tracing::warn!("{}: {e}; read up to there", path.display());
                return Ok(true);
            }
            Err(e) => {
                let problem = format!("is no readable MCAP file: {e}");
                return Err(Error::Recording { path: path.to_path_buf(), problem });
            }
        }
    }
    Ok(false)
}

/// Plays `path` onto `bus`; `progress` is called about once a second with the report so far.
pub fn play(
    bus: &Bus,
    path: &Path,
    options: &PlayOptions,
    mut progress: impl FnMut(&PlayReport),
) -> Result<PlayReport> {
    let mut outputs: HashMap<u16, Option<Output>> = HashMap::new();
    let mut report = PlayReport::default();
    let started = Instant::now();
    let mut last_progress = Instant::now();
    let mut first: Option<u64> = None;
    report.cut = each_message(path, |message| {
        let t0 = *first.get_or_insert(message.log_time);
        let offset_s = message.log_time.saturating_sub(t0) as f64 / 1e9;
        let output = match outputs.get(&message.channel.id) {
            Some(o) => o,
            None => {
                let o = output_for(bus, &message.channel, &options.keys, options.pace == Pace::Max)?;
                outputs.entry(message.channel.id).or_insert(o)
            }
        };
        let Some(output) = output.as_ref().filter(|_| offset_s >= options.start_s) else {
            report.skipped += 1;
            return Ok(());
        };
        if let Pace::Rate(rate) = options.pace {
            let due = started + Duration::from_secs_f64((offset_s - options.start_s).max(0.0) / rate);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let len = message.data.len() as u64;
        output.put(message.data.into_owned())?;
        report.messages += 1;
        report.bytes += len;
        report.recorded_s = offset_s;
        if last_progress.elapsed() >= Duration::from_secs(1) {
            report.wall_s = started.elapsed().as_secs_f64();
            progress(&report);
            last_progress = Instant::now();
        }
        Ok(())
    })?;
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The publisher of a recorded channel on this bus, or None when `keys` (relative to the
/// recording's namespace; empty: all) leave it out. `block`: congestion control "block" on
/// every key, so that nothing is dropped.
pub(crate) fn output_for(
    bus: &Bus,
    channel: &mcap::Channel<'static>,
    keys: &[OwnedKeyExpr],
    block: bool,
) -> Result<Option<Output>> {
    let recorded_ns = channel.metadata.get("namespace").map(String::as_str).unwrap_or("");
    let relative = match recorded_ns {
        "" => channel.topic.as_str(),
        ns => channel.topic.strip_prefix(ns).and_then(|k| k.strip_prefix('/')).unwrap_or(&channel.topic),
    };
    let relative_key = OwnedKeyExpr::autocanonize(relative.to_string())
        .map_err(Error::zenoh(format!("recorded key `{}`", channel.topic)))?;
    if !keys.is_empty() && !keys.iter().any(|k| k.intersects(&relative_key)) {
        return Ok(None);
    }
    let topics = bus.topics();
    let key = match topics.namespace() {
        "" => relative_key.clone(),
        ns => {
            OwnedKeyExpr::autocanonize(format!("{ns}/{relative}")).map_err(Error::zenoh(format!("{ns}/{relative}")))?
        }
    };
    // The topic's QoS where the key is one of slipstream's; "block" at --max so nothing drops.
    let qos = topics.topic_of(&key).map(|t| topics.qos(t));
    let mut builder = bus.session().declare_publisher(key.clone());
    if let Some(q) = &qos {
        builder =
            builder.priority(q.priority.into()).express(q.express).congestion_control(q.congestion_control.into());
    }
    if block {
        builder = builder.congestion_control(CongestionControl::Block);
    }
    if let Some(encoding) = channel.metadata.get("zenoh_encoding") {
        builder = builder.encoding(zenoh::bytes::Encoding::from(encoding.as_str()));
    }
    let publisher = builder.wait().map_err(Error::zenoh(format!("declare a publisher on {key}")))?;
    Ok(Some(Output { publisher, attachment: channel.metadata.get("publisher").cloned() }))
}
