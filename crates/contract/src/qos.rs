//! Per-topic quality of service: what the config names, and its mapping onto Zenoh.

use serde::{Deserialize, Serialize};

/// Zenoh priority classes, most urgent first. Each class has its own queue in a QoS-enabled
/// transport, so a real-time message never waits behind a camera frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Priority {
    RealTime,
    InteractiveHigh,
    InteractiveLow,
    DataHigh,
    Data,
    DataLow,
    Background,
}

impl From<Priority> for zenoh::qos::Priority {
    fn from(p: Priority) -> Self {
        use zenoh::qos::Priority as Z;
        match p {
            Priority::RealTime => Z::RealTime,
            Priority::InteractiveHigh => Z::InteractiveHigh,
            Priority::InteractiveLow => Z::InteractiveLow,
            Priority::DataHigh => Z::DataHigh,
            Priority::Data => Z::Data,
            Priority::DataLow => Z::DataLow,
            Priority::Background => Z::Background,
        }
    }
}

/// What a publisher does when the transport's queue for its priority is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Congestion {
    /// Drop the message: right for data that the next message makes obsolete (frames).
    Drop,
    /// Wait for room: right for messages that must not be lost (events, calibration).
    Block,
}

impl From<Congestion> for zenoh::qos::CongestionControl {
    fn from(c: Congestion) -> Self {
        match c {
            Congestion::Drop => zenoh::qos::CongestionControl::Drop,
            Congestion::Block => zenoh::qos::CongestionControl::Block,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reliability {
    Reliable,
    BestEffort,
}

impl From<Reliability> for zenoh::qos::Reliability {
    fn from(r: Reliability) -> Self {
        match r {
            Reliability::Reliable => zenoh::qos::Reliability::Reliable,
            Reliability::BestEffort => zenoh::qos::Reliability::BestEffort,
        }
    }
}

/// Which of a node's two Zenoh sessions carries a topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SessionKind {
    /// The session with priorities: a queue per priority class and a transmit task that
    /// batches and fragments; frames, calibration, events, ground truth.
    Main,
    /// The low-latency session (Zenoh's low-latency transport): the publishing thread writes
    /// the socket itself, no transmit task, no priorities, no fragmentation (a message must
    /// fit one 64 KiB batch); small real-time topics. A node without one (the default: no
    /// `--low-latency-session`; a client of a router; a plain Zenoh session) sends them on its
    /// main session.
    LowLatency,
}

/// How a subscriber hands messages to its reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Delivery {
    /// Keep only the newest message: a slow reader never stalls Zenoh and never works on a
    /// stale frame. Overwritten messages are counted as skipped.
    Latest,
    /// Keep up to N messages; when full the oldest is dropped and counted as skipped.
    Queue(usize),
}

impl Delivery {
    pub fn capacity(self) -> usize {
        match self {
            Delivery::Latest => 1,
            Delivery::Queue(n) => n.max(1),
        }
    }
}

/// The QoS of one topic, after defaults and config (serialized with the config's key names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TopicQos {
    pub priority: Priority,
    /// Send at once instead of waiting to fill a batch.
    pub express: bool,
    pub congestion_control: Congestion,
    pub reliability: Reliability,
    /// Publishers drop messages that come sooner than 1/rate after the last one sent.
    pub max_rate_hz: Option<f64>,
    pub delivery: Delivery,
    /// The publisher keeps its last message (zenoh-ext advanced publisher with a cache of one)
    /// and a subscriber that starts later receives it first: calibration, configuration.
    pub latched: bool,
    /// The session that publishes and subscribes the topic.
    pub session: SessionKind,
}

impl Default for TopicQos {
    fn default() -> Self {
        TopicQos {
            priority: Priority::Data,
            express: false,
            congestion_control: Congestion::Drop,
            reliability: Reliability::Reliable,
            max_rate_hz: None,
            delivery: Delivery::Queue(16),
            latched: false,
            session: SessionKind::Main,
        }
    }
}
