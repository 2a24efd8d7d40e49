//! Recording the bus into MCAP files (`slipstream record`, `up --record`).
//!
//! A recording keeps every payload byte for byte, on one MCAP channel per key, message type
//! and publisher: the channel's topic is the Zenoh key, its schema is named after the message
//! type (`slipstream.Speed`, ...) and holds the type's layout (schema encoding
//! `slipstream-layout`, [`slipstream_contract::msg::layout`]), its message encoding names the wire version
//! (`slipstream/v5`), its metadata names the publishing node. Log time is when the recorder
//! received the message, publish time the header's publish stamp, the MCAP sequence its seq;
//! the header's simulation time stays inside the payload.
//!
//! The recorder never blocks a publisher: Zenoh's callback copies the payload into a bounded
//! queue ([`QUEUE_BYTES`]) and a writer thread of its own writes the file. Nothing is lost
//! silently: per channel it counts messages, bytes, sequence gaps (lost before the recorder:
//! a publisher's drop-when-congested QoS, the network) and messages it had to drop itself (a
//! full queue); they are printed at the end and stored in the file's `slipstream.recording`
//! metadata record.
//!
//! Every [`FLUSH_EVERY`] the writer closes its chunk, so a file cut by a crash is readable up
//! to that point with any MCAP reader that reads a stream without its summary (docs/recording.md).

pub mod error;
pub(crate) mod play;
pub(crate) mod recorder;
pub(crate) mod replay;

pub use error::{Error, Result};
pub use play::{
    each_message, each_message_until, is_viewable_copy, output_for, play, play_until, recorded_publishers, Output,
    Pace, PlayOptions, PlayReport,
};
pub use recorder::{ChannelSummary, Recording, RecordingSummary};
pub use replay::{private_bus, Replay};

use std::time::Duration;

/// Payload bytes waiting for the writer at most; past this the recorder drops and counts.
pub(crate) const QUEUE_BYTES: usize = 512 << 20;
/// How often the writer ends its chunk, so a crash loses at most this much.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// The MCAP message encoding of every channel: slipstream's wire format, this version.
pub(crate) fn message_encoding() -> String {
    format!("slipstream/v{}", slipstream_contract::msg::WIRE_VERSION)
}
/// The schema name of a message type's channels.
pub(crate) fn schema_name(kind: Option<slipstream_contract::msg::MessageKind>) -> String {
    match kind {
        Some(k) => format!("slipstream.{}", k.name()),
        None => "slipstream.Invalid".to_string(),
    }
}
/// The name of the metadata record with the recording's summary.
pub(crate) const METADATA_NAME: &str = "slipstream.recording";
