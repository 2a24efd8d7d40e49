//! What one benchmark case runs, and what its two processes report.

use serde::{Deserialize, Serialize};

/// The path a message takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum Transport {
    /// slipstream's typed bus (encode, header, QoS from the topic map, decode).
    Bus,
    /// Zenoh put/subscribe of the same bytes, no typed layer.
    Zenoh,
    /// One UDP datagram per message (the seed design's speed port).
    Udp,
    /// Length-prefixed messages on one TCP connection (the seed design's image port).
    Tcp,
    /// The seed design itself: a Python script (standard library) sending the speed as text,
    /// one UDP datagram per message (crates/bench/src/seed.py).
    SeedPythonUdp,
    /// The seed design's camera link: the same script pickling each frame and sending it over
    /// one TCP connection behind a 4-byte length.
    SeedPythonTcpPickle,
}

impl Transport {
    /// The seed's own peers: the Python script, not `slipstream bench-peer`.
    pub(crate) fn is_seed(self) -> bool {
        matches!(self, Transport::SeedPythonUdp | Transport::SeedPythonTcpPickle)
    }
}

/// What flows in the measured stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Payload {
    Speed,
    Frame { width: u32, height: u32 },
}

/// Frames sent alongside the speed stream to load the link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Background {
    pub width: u32,
    pub height: u32,
    /// None: as fast as the publisher can.
    pub rate_hz: Option<f64>,
    /// The frame-publishing thread's nice value (0: as every other thread): what lowering
    /// a frame source's priority does for the real-time path on a busy machine.
    #[serde(default)]
    pub nice: i32,
}

/// TCP socket buffer sizes (so_sndbuf, so_rcvbuf) of Zenoh's links.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum TcpBuffer {
    /// As config/zenoh.json5 sets them.
    Default,
    /// The kernel's defaults.
    Kernel,
    Bytes(u32),
}

/// The reader of a latency case's frames: the hand-off from Zenoh's receive thread to the
/// application is what the rows tell apart.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) enum FrameReader {
    /// A latest-only `FrameSubscriber` awaited by a task of the async runtime.
    #[default]
    Task,
    /// The same subscriber read by a thread of its own (`recv_blocking`), as the detector does:
    /// awake and polling around each frame of the periodic stream (`camera.poll_before_frame`).
    Thread,
    /// The same thread, always woken by the receive thread (`camera.poll_before_frame: false`).
    ThreadWoken,
    /// Zenoh's receive callback itself: no hand-off.
    Callback,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CaseSpec {
    pub transport: Transport,
    pub payload: Payload,
    /// Messages in the measured stream.
    pub count: u64,
    /// None: as fast as possible.
    pub rate_hz: Option<f64>,
    /// The sender stops after this long even if `count` is not reached.
    pub max_duration_s: f64,
    /// false: every topic at Zenoh's defaults (priority data, not express).
    pub qos: bool,
    /// Shared memory on both sides (config and frame publisher).
    pub shm: bool,
    /// Zenoh's low-latency transport (no priorities, no fragmentation).
    pub lowlatency: bool,
    /// ZENOH_RUNTIME for both processes, None: slipstream's default.
    pub runtime: Option<String>,
    /// TCP send and receive buffer sizes of Zenoh's links.
    pub tcp_buffer: TcpBuffer,
    /// Zenoh over a unix socket (`unixsock-stream`) instead of TCP on loopback (one host).
    #[serde(default)]
    pub unix_socket: bool,
    pub background: Option<Background>,
    /// Both sides are Zenoh clients of a router (`slipstream router` on loopback, given to
    /// both as the endpoint): every message crosses the router.
    #[serde(default)]
    pub via_router: bool,
    /// Every key under this namespace (one vehicle among several on one router).
    #[serde(default)]
    pub namespace: Option<String>,
    /// The receiver answers each speed message with a vehicle/control command, as a
    /// controller would; the sender receives the commands and reports their latency.
    #[serde(default)]
    pub control_echo: bool,
    /// Who reads frames sent at a fixed rate at the receiver (throughput cases always count
    /// them in Zenoh's receive callback).
    #[serde(default)]
    pub reader: FrameReader,
    /// Run both peers from this slipstream binary instead of the running one (another build,
    /// e.g. with Zenoh's io_uring receive path: `bench --with-build`).
    #[serde(default)]
    pub peer_exe: Option<String>,
    /// Both peers' processes pinned to this CPU (every thread: the hand-offs stay on one core).
    #[serde(default)]
    pub pin_cpu: Option<usize>,
    /// Receivers of the measured stream: the sender waits for all of them before it starts.
    #[serde(default = "one")]
    pub subscribers: usize,
    /// The bus on two sessions (`--low-latency-session`: the small real-time topics on a
    /// low-latency session of their own) instead of the default one.
    #[serde(default)]
    pub two_sessions: bool,
}

fn one() -> usize {
    1
}

/// The receiver's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct RecvReport {
    pub received: u64,
    /// Sequence numbers never seen (sender's count minus received, from the gaps).
    pub highest_seq: Option<u64>,
    pub bytes: u64,
    /// One-way latency of every measured message, ns.
    pub latencies_ns: Vec<i64>,
    /// From the first measured message's publication (its stamp) to the last one's arrival,
    /// wall clock, s: the time the received messages took to be published and delivered, so
    /// a rate over it never exceeds the publisher's.
    pub span_s: f64,
    pub background_received: u64,
    /// Frames delivered in shared memory.
    pub shared_memory: u64,
    /// Frames that arrived but that the latest-only reader skipped (a newer one came before
    /// it read them): counted in `received`'s shortfall, not lost in transport.
    #[serde(default)]
    pub skipped: u64,
    /// Frames read by a task or a thread: each one's hand-off from Zenoh's receive callback to
    /// the reader, ns (in the order of `latencies_ns`).
    #[serde(default)]
    pub handoff_ns: Vec<i64>,
}

/// The sender's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct SendReport {
    pub sent: u64,
    /// From start (session open included) to the last message, s.
    pub elapsed_s: f64,
    /// From the first measured message's publish stamp to the last one's, s (the bus sender
    /// only; else 0).
    #[serde(default)]
    pub span_s: f64,
    pub background_sent: u64,
    /// With `control_echo`: the receiver's commands that came back.
    #[serde(default)]
    pub control_received: u64,
    /// ... and their one-way latency (command published -> received here), ns.
    #[serde(default)]
    pub control_latencies_ns: Vec<i64>,
}
