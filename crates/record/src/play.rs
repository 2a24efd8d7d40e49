//! Playing a recording back onto the bus: every payload byte for byte on its key (moved into
//! this bus's namespace), with its publisher's name marked as replayed as the attachment
//! (`sim@replay`, [`slipstream_contract::bus::replayed_name`]: no live node takes it for the
//! live loop), at the recorded pace (or faster, or as fast as the subscribers take it).
//!
//! What a recording holds besides the loop's payloads is not played: the Foxglove-viewable
//! copies of `--viewable` (channels marked `viewable_copy`, on keys such as `/scene/vehicles`
//! that are no Zenoh keys) are derived from the payloads and skipped, counted with the
//! skipped messages. A latched topic (camera info, the road) is played from a publisher that
//! keeps its last message for late subscribers, as the live simulator's does.

use std::collections::{BTreeSet, HashMap};
use std::fs::File;
use std::io::BufReader;
use std::ops::ControlFlow;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
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
    /// Viewers' copies (`--viewable`) the file holds beside the payloads: never played.
    pub viewer_copies: u64,
    /// The file ended in a partial record (cut by a crash): played up to it.
    pub cut: bool,
    /// Stopped before the end (a signal).
    pub interrupted: bool,
}

/// The Zenoh publisher of one recorded key: plain, or one that keeps the last message for late
/// subscribers (a latched topic).
enum Publisher {
    Plain(zenoh::pubsub::Publisher<'static>),
    Latched(zenoh_ext::AdvancedPublisher<'static>),
}

/// A key of the recording on this bus, with its publisher.
pub struct Output {
    publisher: Publisher,
    key: OwnedKeyExpr,
    /// The recorded publisher's name, marked as replayed.
    attachment: String,
}

impl Output {
    /// Publishes a recorded payload as it was, naming its recorded publisher as replayed.
    pub fn put(&self, payload: Vec<u8>) -> Result<()> {
        let attachment = self.attachment.clone();
        let sent = match &self.publisher {
            Publisher::Plain(p) => p.put(payload).attachment(attachment).wait(),
            Publisher::Latched(p) => p.put(payload).attachment(attachment).wait(),
        };
        sent.map_err(Error::zenoh(format!("publish on {}", self.key)))
    }
}

/// Whether a recorded channel holds a viewer's copy (`--viewable`), not a payload of the loop.
pub fn is_viewable_copy(channel: &mcap::Channel<'_>) -> bool {
    channel.metadata.get("viewable_copy").is_some_and(|v| v == "true")
}

/// Calls `f` with every message of the recording at `path`, in file order: the one reader of
/// recordings (`play`, re-simulation, the view's replay). A file cut by a crash is read up to
/// the cut and `true` returned; a file that is no MCAP at all is an error, and so is a ROS 2
/// profile file (`--profile ros2`, run.ros2.mcap), named as such: its messages are CDR, not
/// slipstream's payloads.
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
            Ok(m) if !seen && m.channel.message_encoding == "cdr" => {
                let problem = "is a ROS 2 profile recording (CDR messages on ROS topics: `ros2 bag play` plays it, Foxglove shows it); slipstream's tools take slipstream's own recordings (fix: use run.mcap beside it, which `up --record --ros2` writes too, or a file of `slipstream record`)".to_string();
                return Err(Error::Recording { path: path.to_path_buf(), problem });
            }
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

/// The recording's summary section (its channels, statistics), none when the file has none
/// (cut by a crash) or it does not read.
pub(crate) fn summary_of(path: &Path) -> Result<Option<mcap::Summary>> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader};
    use std::io::{Read, Seek};
    let mut file = File::open(path).map_err(Error::file("open", path))?;
    let mut reader = SummaryReader::new();
    while let Some(event) = reader.next_event() {
        let Ok(event) = event else { return Ok(None) };
        match event {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file.read(reader.insert(n)).map_err(Error::file("read", path))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                reader.notify_seeked(file.seek(to).map_err(Error::file("read", path))?);
            }
        }
    }
    Ok(reader.finish())
}

/// The nodes whose messages the recording holds (its channels' `publisher`): from the summary,
/// or, in a file cut by a crash, from every channel read up to the cut.
pub fn recorded_publishers(path: &Path) -> Result<BTreeSet<String>> {
    let of = |c: &mcap::Channel<'_>| c.metadata.get("publisher").filter(|_| !is_viewable_copy(c)).cloned();
    if let Some(summary) = summary_of(path)?.filter(|s| !s.channels.is_empty()) {
        return Ok(summary.channels.values().filter_map(|c| of(c)).collect());
    }
    let mut names = BTreeSet::new();
    each_message(path, |m| {
        names.extend(of(&m.channel));
        Ok(())
    })?;
    Ok(names)
}

/// Plays `path` onto `bus`; `progress` is called about once a second with the report so far.
pub fn play(bus: &Bus, path: &Path, options: &PlayOptions, progress: impl FnMut(&PlayReport)) -> Result<PlayReport> {
    play_until(bus, path, options, &AtomicBool::new(false), progress)
}

/// How often a wait for a message's recorded time looks whether the playback is to stop.
const STOP_POLL: Duration = Duration::from_millis(100);

/// [`play`] that ends early, between two messages, once `stop` is set (a signal):
/// `interrupted` in the report.
pub fn play_until(
    bus: &Bus,
    path: &Path,
    options: &PlayOptions,
    stop: &AtomicBool,
    mut progress: impl FnMut(&PlayReport),
) -> Result<PlayReport> {
    let mut outputs: HashMap<u16, Option<Output>> = HashMap::new();
    let mut report = PlayReport::default();
    let started = Instant::now();
    let mut last_progress = Instant::now();
    let mut first: Option<u64> = None;
    report.cut = each_message_until(path, |message| {
        let t0 = *first.get_or_insert(message.log_time);
        let offset_s = message.log_time.saturating_sub(t0) as f64 / 1e9;
        if is_viewable_copy(&message.channel) {
            report.viewer_copies += 1;
            return Ok(ControlFlow::Continue(()));
        }
        let output = match outputs.get(&message.channel.id) {
            Some(o) => o,
            None => {
                let o = output_for(bus, &message.channel, &options.keys, options.pace == Pace::Max)?;
                outputs.entry(message.channel.id).or_insert(o)
            }
        };
        let Some(output) = output.as_ref().filter(|_| offset_s >= options.start_s) else {
            report.skipped += 1;
            return Ok(ControlFlow::Continue(()));
        };
        if let Pace::Rate(rate) = options.pace {
            let due = started + Duration::from_secs_f64((offset_s - options.start_s).max(0.0) / rate);
            while !stop.load(Ordering::Relaxed) && Instant::now() < due {
                std::thread::sleep(STOP_POLL.min(due.saturating_duration_since(Instant::now())));
            }
        }
        if stop.load(Ordering::Relaxed) {
            report.interrupted = true;
            return Ok(ControlFlow::Break(()));
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
        Ok(ControlFlow::Continue(()))
    })?;
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The publisher of a recorded channel on this bus, or None when `keys` (relative to the
/// recording's namespace; empty: all) leave it out or the channel is a viewer's copy. `block`:
/// congestion control "block" on every key, so that nothing is dropped.
pub fn output_for(
    bus: &Bus,
    channel: &mcap::Channel<'static>,
    keys: &[OwnedKeyExpr],
    block: bool,
) -> Result<Option<Output>> {
    if is_viewable_copy(channel) {
        return Ok(None);
    }
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
    let declare = Error::zenoh(format!("declare a publisher on {key}"));
    let publisher = if qos.as_ref().is_some_and(|q| q.latched) {
        use zenoh_ext::AdvancedPublisherBuilderExt;
        let cache = zenoh_ext::CacheConfig::default().max_samples(1);
        let latched = builder
            .cache(cache)
            .sample_miss_detection(zenoh_ext::MissDetectionConfig::default())
            .publisher_detection()
            .wait()
            .map_err(declare)?;
        Publisher::Latched(latched)
    } else {
        Publisher::Plain(builder.wait().map_err(declare)?)
    };
    // A recording made before publishers named themselves: the replay still says it is one.
    let recorded = channel.metadata.get("publisher").map_or("unnamed", String::as_str);
    Ok(Some(Output { publisher, key, attachment: slipstream_contract::bus::replayed_name(recorded) }))
}
