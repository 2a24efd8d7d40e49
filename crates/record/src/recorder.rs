//! The recorder: Zenoh callbacks -> a bounded queue -> a writer thread -> an MCAP file.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use crate::error::{Error, Result};
use parking_lot::Mutex;
use serde::Serialize;
use zenoh::key_expr::OwnedKeyExpr;

use super::{message_encoding, schema_name, FLUSH_EVERY, METADATA_NAME, QUEUE_BYTES};
use slipstream_contract::bus::{Bus, Declared};
use slipstream_contract::msg::{self, MessageKind, WIRE_VERSION};
use slipstream_view::{Copies, ViewableCopy};

/// Items the queue holds at most (besides the byte bound).
const QUEUE_ITEMS: usize = 1 << 16;

/// One sample on its way to the file.
struct Item {
    key: String,
    source: Option<String>,
    payload: Vec<u8>,
    received_ns: u64,
}

enum ToWriter {
    Item(Item),
    /// Every subscriber is gone: write the summary and close the file.
    Finish,
}

/// A channel: its key, the message type its payloads say (None: not a slipstream payload) and
/// the publisher (the node name in the samples' attachment): lockstep and replay need it.
type ChannelKey = (String, Option<MessageKind>, Option<String>);

/// What the callbacks and the writer share.
#[derive(Default)]
struct Shared {
    queued_bytes: AtomicUsize,
    /// Accepted into the queue (for progress).
    messages: AtomicU64,
    bytes: AtomicU64,
    dropped: Mutex<HashMap<ChannelKey, u64>>,
    /// Set when finishing: samples after it belong to no recording.
    closing: AtomicBool,
}

/// One channel of a recording.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ChannelSummary {
    pub topic: String,
    pub schema: String,
    pub messages: u64,
    pub bytes: u64,
    /// Sequence numbers never seen, per publisher: lost before the recorder (a publisher's
    /// drop-when-congested QoS, the network).
    pub lost_upstream: u64,
    /// Messages the recorder dropped itself (its queue was full).
    pub dropped_by_recorder: u64,
    /// The publishing node (the samples' attachment), if it names itself.
    pub publisher: Option<String>,
}

/// A finished recording.
#[derive(Debug, Clone, Serialize)]
pub struct RecordingSummary {
    pub path: PathBuf,
    pub duration_s: f64,
    pub file_bytes: u64,
    pub messages: u64,
    pub lost_upstream: u64,
    pub dropped_by_recorder: u64,
    pub channels: Vec<ChannelSummary>,
    /// Foxglove-viewable copies written besides (`--viewable`; not part of the counts above).
    pub viewable_copies: u64,
    /// Copies not made because the writer was behind (the payloads always come first).
    pub viewable_skipped: u64,
}

impl RecordingSummary {
    pub fn lost_anything(&self) -> bool {
        self.lost_upstream > 0 || self.dropped_by_recorder > 0
    }

    /// A table for people: one line per channel, then the verdict (red on a terminal when
    /// anything was lost).
    pub fn render(&self, color: bool) -> String {
        let mut s = format!(
            "recording {}: {} messages, {:.1} MB in {:.1} s\n  {:<34} {:<30} {:<10} {:>8} {:>10} {:>6} {:>8}\n",
            self.path.display(),
            self.messages,
            self.file_bytes as f64 / 1e6,
            self.duration_s,
            "key",
            "schema",
            "from",
            "messages",
            "MB",
            "lost",
            "dropped"
        );
        for c in &self.channels {
            s.push_str(&format!(
                "  {:<34} {:<30} {:<10} {:>8} {:>10.2} {:>6} {:>8}\n",
                c.topic,
                c.schema,
                c.publisher.as_deref().unwrap_or("-"),
                c.messages,
                c.bytes as f64 / 1e6,
                c.lost_upstream,
                c.dropped_by_recorder
            ));
        }
        if self.viewable_copies > 0 || self.viewable_skipped > 0 {
            s.push_str(&format!(
                "  and {} Foxglove-viewable copies (camera, boxes, scene, series)",
                self.viewable_copies
            ));
            if self.viewable_skipped > 0 {
                s.push_str(&format!("; {} not made while the writer was behind", self.viewable_skipped));
            }
            s.push('\n');
        }
        let verdict = if self.lost_anything() {
            format!(
                "LOST: {} messages never reached the recorder (sequence gaps), {} dropped by the recorder",
                self.lost_upstream, self.dropped_by_recorder
            )
        } else {
            "nothing lost: every sequence number of every publisher is in the file".to_string()
        };
        let verdict = console::style(verdict);
        let verdict = if color && self.lost_anything() { verdict.red().force_styling(true) } else { verdict };
        s.push_str(&format!("  {verdict}"));
        s
    }
}

/// A recording in progress; [`Recording::finish`] closes the file.
pub struct Recording {
    shared: Arc<Shared>,
    tx: SyncSender<ToWriter>,
    subs: Vec<Declared>,
    writer: Option<JoinHandle<Result<RecordingSummary>>>,
}

impl Recording {
    /// Starts recording `selectors` (key expressions) of `bus` into `path` (created, with its
    /// directory). The file's metadata names the namespace and the selectors.
    pub async fn start(bus: &Bus, selectors: &[OwnedKeyExpr], path: &Path) -> Result<Recording> {
        Recording::start_with(bus, selectors, path, None).await
    }

    /// [`Recording::start`], and with `viewable` Foxglove-viewable copies of the loop's
    /// messages on channels of their own (the live view's topics; docs/recording.md).
    pub async fn start_with(
        bus: &Bus,
        selectors: &[OwnedKeyExpr],
        path: &Path,
        viewable: Option<Copies>,
    ) -> Result<Recording> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(Error::file("create", dir))?;
        }
        let file = File::create(path).map_err(Error::file("create", path))?;
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .profile("slipstream")
            .library(format!("slipstream {}", env!("CARGO_PKG_VERSION")));
        let writer = options.create(BufWriter::new(file)).map_err(Error::mcap("start", path))?;
        let shared = Arc::new(Shared::default());
        let (tx, rx) = sync_channel(QUEUE_ITEMS);
        let mut about = BTreeMap::new();
        about.insert("namespace".to_string(), bus.topics().namespace().to_string());
        about.insert("selectors".to_string(), selectors.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(" "));
        about.insert("wire_version".to_string(), WIRE_VERSION.to_string());
        about.insert("started_unix_ns".to_string(), msg::wall_clock_ns().to_string());
        about.insert("viewable_copies".to_string(), viewable.is_some().to_string());
        let viewable = viewable.map(|c| c.with_topics(bus.topics().clone()));
        let thread = {
            let (shared, path) = (shared.clone(), path.to_path_buf());
            std::thread::Builder::new()
                .name("mcap-writer".into())
                .spawn(move || write_loop(rx, shared, Files { writer, path, viewable }, about))
                .map_err(|source| Error::System { what: "start the recorder's writer thread".into(), source })?
        };
        let mut subs = Vec::new();
        for sel in selectors {
            let (tx, shared) = (tx.clone(), shared.clone());
            subs.push(bus.subscribe_samples(sel.clone(), false, move |s| enqueue(&tx, &shared, &s)).await?);
        }
        // A latched topic (camera info, the road) was published when its node started, maybe
        // long before the recorder: ask its publishers for their cached message too. Its live
        // messages then come on both subscriptions; the writer keeps one of each.
        for key in latched_keys(bus.topics(), selectors) {
            let (tx, shared) = (tx.clone(), shared.clone());
            subs.push(bus.subscribe_samples(key, true, move |s| enqueue(&tx, &shared, &s)).await?);
        }
        Ok(Recording { shared, tx, subs, writer: Some(thread) })
    }

    /// Messages and payload bytes taken so far.
    pub fn progress(&self) -> (u64, u64) {
        (self.shared.messages.load(Ordering::Relaxed), self.shared.bytes.load(Ordering::Relaxed))
    }

    /// Stops taking samples, writes what is queued, the summary (metadata) and the file's
    /// index, and closes it.
    pub fn finish(mut self) -> Result<RecordingSummary> {
        self.shared.closing.store(true, Ordering::SeqCst);
        self.subs.clear();
        let _ = self.tx.send(ToWriter::Finish);
        let writer = self.writer.take().ok_or(Error::Panicked("the recorder's writer thread"))?;
        writer.join().map_err(|_| Error::Panicked("the recorder's writer thread"))?
    }
}

/// The keys of the latched topics that `selectors` cover.
fn latched_keys(topics: &slipstream_contract::TopicMap, selectors: &[OwnedKeyExpr]) -> Vec<OwnedKeyExpr> {
    slipstream_contract::topics::Topic::ALL
        .into_iter()
        .filter(|t| topics.qos(*t).latched)
        .map(|t| topics.key(t))
        .filter(|key| selectors.iter().any(|s| s.includes(key)))
        .collect()
}

/// Zenoh's callback: copy the payload (one copy: the sample's buffer, possibly shared memory
/// a publisher wants back, is not held) and queue it, or count it dropped. Never blocks.
fn enqueue(tx: &SyncSender<ToWriter>, shared: &Shared, sample: &zenoh::sample::Sample) {
    if shared.closing.load(Ordering::Relaxed) {
        return;
    }
    let payload = sample.payload().to_bytes().into_owned();
    let len = payload.len();
    let item = Item {
        key: sample.key_expr().as_str().to_string(),
        source: sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned()),
        received_ns: msg::wall_clock_ns(),
        payload,
    };
    // Reserve the bytes before sending: the writer may take the item (and give them back)
    // before this thread runs again.
    let queued = shared.queued_bytes.fetch_add(len, Ordering::Relaxed) + len;
    let rejected = if queued > QUEUE_BYTES {
        Some(item)
    } else {
        match tx.try_send(ToWriter::Item(item)) {
            Ok(()) => None,
            Err(TrySendError::Full(ToWriter::Item(i)) | TrySendError::Disconnected(ToWriter::Item(i))) => Some(i),
            Err(_) => None,
        }
    };
    match rejected {
        None => {
            shared.messages.fetch_add(1, Ordering::Relaxed);
            shared.bytes.fetch_add(len as u64, Ordering::Relaxed);
        }
        Some(item) => {
            shared.queued_bytes.fetch_sub(len, Ordering::Relaxed);
            // Only a dropped sample pays for naming its channel.
            let kind = kind_of(&item.payload);
            *shared.dropped.lock().entry((item.key, kind, item.source)).or_default() += 1;
        }
    }
}

/// The message type a payload says it holds (version and kind bytes).
fn kind_of(payload: &[u8]) -> Option<MessageKind> {
    match payload {
        [v, k, ..] if *v == WIRE_VERSION => MessageKind::from_u8(*k),
        _ => None,
    }
}

/// A channel being written.
struct Channel {
    id: u16,
    summary: ChannelSummary,
    /// The highest seq seen.
    last_seq: Option<u64>,
}

/// Queued payload bytes beyond which the writer makes no viewable copies (it is behind: the
/// byte-for-byte payloads come first).
const VIEWABLE_BACKLOG: usize = QUEUE_BYTES / 8;

/// Niceness of the writer thread: below the loop's processes, so that in a saturated loop
/// (fast mode) the simulator keeps the CPU and the writer catches up from the queue.
const WRITER_NICE: i32 = 10;

/// Lowers this thread's scheduling priority (Linux: nice is per thread); best effort.
fn lower_priority() {
    // SAFETY: setpriority reads no memory of ours; `who` 0 is the calling thread on Linux.
    let r = unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, WRITER_NICE) };
    if r != 0 {
        tracing::debug!("recorder: could not lower the writer's priority: {}", std::io::Error::last_os_error());
    }
}

/// The writer thread: items in, records out; at Finish the summary and the index.
/// What the writer thread writes into.
struct Files {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    viewable: Option<Copies>,
}

fn write_loop(
    rx: Receiver<ToWriter>,
    shared: Arc<Shared>,
    files: Files,
    mut about: BTreeMap<String, String>,
) -> Result<RecordingSummary> {
    let Files { mut writer, path, mut viewable } = files;
    let mut viewable_channels: HashMap<&'static str, u16> = HashMap::new();
    let (mut viewable_copies, mut viewable_skipped) = (0u64, 0u64);
    let started = Instant::now();
    lower_priority();
    let namespace = about.get("namespace").cloned().unwrap_or_default();
    let mut channels: HashMap<ChannelKey, Channel> = HashMap::new();
    let mut schemas: HashMap<Option<MessageKind>, u16> = HashMap::new();
    let mut last_flush = Instant::now();
    let fail = |e: mcap::McapError| Error::mcap("write", &path)(e);
    loop {
        let item = match rx.recv_timeout(FLUSH_EVERY) {
            Ok(ToWriter::Item(item)) => Some(item),
            Ok(ToWriter::Finish) | Err(RecvTimeoutError::Disconnected) => break,
            Err(RecvTimeoutError::Timeout) => None,
        };
        if let Some(item) = item {
            shared.queued_bytes.fetch_sub(item.payload.len(), Ordering::Relaxed);
            if let Some(copies) = viewable.as_mut() {
                // The payloads first: copies wait for a writer that keeps up.
                if shared.queued_bytes.load(Ordering::Relaxed) > VIEWABLE_BACKLOG {
                    viewable_skipped += copies.skip(&item.key, &item.payload);
                } else {
                    for c in copies.of(&item.key, &item.payload) {
                        write_copy(&mut writer, &mut viewable_channels, c, item.received_ns).map_err(fail)?;
                        viewable_copies += 1;
                    }
                }
            }
            write_item(&mut writer, &mut channels, &mut schemas, &namespace, item).map_err(fail)?;
        }
        if last_flush.elapsed() >= FLUSH_EVERY {
            writer.flush().map_err(fail)?;
            last_flush = Instant::now();
        }
    }
    // Drops are counted per channel, also on channels that never got a message through.
    for (key, n) in shared.dropped.lock().drain() {
        let channel = match channels.get_mut(&key) {
            Some(c) => c,
            None => {
                let id = add_channel(&mut writer, &mut schemas, &key, &namespace).map_err(fail)?;
                channels.entry(key.clone()).or_insert(Channel::new(id, &key))
            }
        };
        channel.summary.dropped_by_recorder += n;
    }
    let mut list: Vec<ChannelSummary> = channels.into_values().map(|c| c.summary).collect();
    list.sort_by(|a, b| (&a.topic, &a.schema, &a.publisher).cmp(&(&b.topic, &b.schema, &b.publisher)));
    let mut summary = RecordingSummary {
        path: path.clone(),
        duration_s: started.elapsed().as_secs_f64(),
        file_bytes: 0,
        messages: list.iter().map(|c| c.messages).sum(),
        lost_upstream: list.iter().map(|c| c.lost_upstream).sum(),
        dropped_by_recorder: list.iter().map(|c| c.dropped_by_recorder).sum(),
        channels: list,
        viewable_copies,
        viewable_skipped,
    };
    about.insert("ended_unix_ns".to_string(), msg::wall_clock_ns().to_string());
    about.insert("messages".to_string(), summary.messages.to_string());
    about.insert("lost_upstream".to_string(), summary.lost_upstream.to_string());
    about.insert("dropped_by_recorder".to_string(), summary.dropped_by_recorder.to_string());
    about.insert("viewable_copies_written".to_string(), summary.viewable_copies.to_string());
    about.insert("viewable_copies_skipped".to_string(), summary.viewable_skipped.to_string());
    about.insert(
        "channels".to_string(),
        serde_json::to_string(&summary.channels)
            .map_err(|e| Error::Bug(format!("the recording's channel table does not serialize: {e}")))?,
    );
    writer
        .write_metadata(&mcap::records::Metadata { name: METADATA_NAME.to_string(), metadata: about })
        .map_err(fail)?;
    writer.finish().map_err(fail)?;
    drop(writer);
    summary.file_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    Ok(summary)
}

impl Channel {
    fn new(id: u16, key: &ChannelKey) -> Channel {
        Channel {
            id,
            summary: ChannelSummary {
                topic: key.0.clone(),
                schema: schema_name(key.1),
                messages: 0,
                bytes: 0,
                lost_upstream: 0,
                dropped_by_recorder: 0,
                publisher: key.2.clone(),
            },
            last_seq: None,
        }
    }
}

/// The schema of the key's message type (added once) and a channel for the key.
fn add_channel(
    writer: &mut mcap::Writer<BufWriter<File>>,
    schemas: &mut HashMap<Option<MessageKind>, u16>,
    key: &ChannelKey,
    namespace: &str,
) -> mcap::McapResult<u16> {
    let schema = match (schemas.get(&key.1), key.1) {
        (Some(id), _) => *id,
        (None, Some(kind)) => {
            // The type's layout as data (crates/contract/src/msg/layout.rs): with docs/wire-format.md's rules a
            // reader decodes the channel without this crate.
            let data = serde_json::to_vec(&slipstream_contract::msg::layout::schema_data(kind)).unwrap_or_default();
            let id =
                writer.add_schema(&schema_name(key.1), slipstream_contract::msg::layout::SCHEMA_ENCODING, &data)?;
            schemas.insert(key.1, id);
            id
        }
        // Bytes that are no slipstream message have no layout: a channel without a schema
        // (schema id 0, as MCAP allows).
        (None, None) => 0,
    };
    let mut meta = BTreeMap::new();
    if let Some(kind) = key.1 {
        meta.insert("zenoh_encoding".to_string(), format!("application/octet-stream;{}", kind.encoding_schema()));
    }
    if let Some(publisher) = &key.2 {
        meta.insert("publisher".to_string(), publisher.clone());
    }
    meta.insert("namespace".to_string(), namespace.to_string());
    writer.add_channel(schema, &key.0, &message_encoding(), &meta)
}

/// A viewable copy on its topic's channel (made with its schema at the first copy), logged when
/// its original was received (`received_ns`), published when its original was.
fn write_copy(
    writer: &mut mcap::Writer<BufWriter<File>>,
    channels: &mut HashMap<&'static str, u16>,
    c: ViewableCopy,
    received_ns: u64,
) -> mcap::McapResult<()> {
    let id = match channels.get(c.topic) {
        Some(id) => *id,
        None => {
            let schema = writer.add_schema(&c.schema.name, &c.schema.encoding, &c.schema.data)?;
            let mut meta = BTreeMap::new();
            meta.insert("viewable_copy".to_string(), "true".to_string());
            let id = writer.add_channel(schema, c.topic, &c.message_encoding, &meta)?;
            channels.insert(c.topic, id);
            id
        }
    };
    let header =
        mcap::records::MessageHeader { channel_id: id, sequence: 0, log_time: received_ns, publish_time: c.log_time };
    writer.write_to_known_channel(&header, &c.data)
}

fn write_item(
    writer: &mut mcap::Writer<BufWriter<File>>,
    channels: &mut HashMap<ChannelKey, Channel>,
    schemas: &mut HashMap<Option<MessageKind>, u16>,
    namespace: &str,
    item: Item,
) -> mcap::McapResult<()> {
    let kind = kind_of(&item.payload);
    let key = (item.key, kind, item.source);
    if !channels.contains_key(&key) {
        let id = add_channel(writer, schemas, &key, namespace)?;
        channels.insert(key.clone(), Channel::new(id, &key));
    }
    let channel = channels.get_mut(&key).expect("just added");
    let header = kind.and_then(|k| msg::decode_header(&item.payload, k).ok()).map(|(h, _)| h);
    if header.is_some_and(|h| channel.last_seq == Some(h.seq)) {
        // The same sequence number again from the same publisher on the same key: one message
        // heard twice (a latched topic's live message also comes through its cache's
        // subscription), written once.
        return Ok(());
    }
    if let Some(h) = &header {
        let last = channel.last_seq.unwrap_or(h.seq);
        if h.seq > last + 1 {
            channel.summary.lost_upstream += h.seq - last - 1;
        }
        channel.last_seq = Some(last.max(h.seq));
    }
    channel.summary.messages += 1;
    channel.summary.bytes += item.payload.len() as u64;
    // MCAP's (and rosbag2's) meaning: logged when the recorder received it, published when the
    // publisher stamped it.
    let record = mcap::records::MessageHeader {
        channel_id: channel.id,
        sequence: header.map_or(0, |h| h.seq as u32),
        log_time: item.received_ns,
        publish_time: header.map_or(item.received_ns, |h| h.stamp_pub_ns),
    };
    writer.write_to_known_channel(&record, &item.payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(lost_upstream: u64) -> RecordingSummary {
        RecordingSummary {
            path: PathBuf::from("run.mcap"),
            duration_s: 1.0,
            file_bytes: 10,
            messages: 5,
            lost_upstream,
            dropped_by_recorder: 0,
            channels: Vec::new(),
            viewable_copies: 0,
            viewable_skipped: 0,
        }
    }

    #[test]
    fn the_verdict_is_red_only_when_something_was_lost_and_colour_is_wanted() {
        let red = "\u{1b}[31m";
        assert!(summary(2).render(true).contains(red));
        assert!(!summary(2).render(false).contains('\u{1b}'));
        assert!(!summary(0).render(true).contains('\u{1b}'));
        assert!(summary(2).render(false).contains("LOST: 2 messages"));
    }
}
