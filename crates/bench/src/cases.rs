//! The cases of the point-to-point suites (a. speed, b. frames, c. contention), each under a
//! typed id: the ratios find their rows by id, so renaming a row's label cannot drop a ratio.

use serde::Serialize;

use super::spec::{Background, CaseSpec, FrameReader, Payload, TcpBuffer, Transport};
use super::Suite;

/// ZENOH_RUNTIME value that gives Zenoh's own thread layout (a pool per role) instead of
/// slipstream's default handover layout (`slipstream_contract::process::ZENOH_RUNTIME_DEFAULT`).
pub(crate) const ZENOH_OWN_RUNTIME: &str = "()";

/// A frame size of section b.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrameSize {
    /// 640x480, the seed's camera.
    Vga,
    /// 1280x720.
    Hd,
}

impl FrameSize {
    pub const ALL: [FrameSize; 2] = [FrameSize::Vga, FrameSize::Hd];

    pub fn dims(self) -> (u32, u32) {
        match self {
            FrameSize::Vga => (640, 480),
            FrameSize::Hd => (1280, 720),
        }
    }
}

/// How a frame table's sender paces its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Phase {
    /// As fast as the sender can: frames/s, MB/s.
    Throughput,
    /// At 20 Hz: one-way latency.
    Latency,
}

/// One table of rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "table")]
pub enum Table {
    Speed,
    Frames { size: FrameSize, phase: Phase },
    Contention,
}

impl Table {
    /// The table's heading.
    pub fn label(self) -> String {
        match self {
            Table::Speed => "a. speed 100 Hz".into(),
            Table::Frames { size, phase } => {
                let (w, h) = size.dims();
                let phase = match phase {
                    Phase::Throughput => "throughput",
                    Phase::Latency => "latency @20 Hz",
                };
                format!("b. {w}x{h} RGB frames, {phase}")
            }
            Table::Contention => "c. bus speed 100 Hz under 640x480 frames".into(),
        }
    }
}

/// What a row measures within its table. The label is for people; code names the variant.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Path {
    /// The seed's speed link: Python, text in a UDP datagram.
    SeedPythonUdp,
    /// The seed's camera link: Python, pickled frames over TCP.
    SeedPythonTcpPickle,
    RawUdp,
    RawTcp,
    RawZenoh,
    RawZenohOwnRuntime,
    /// Raw Zenoh on its low-latency transport: the baseline of the bus's low-latency session.
    RawZenohLowlatency,
    RawZenohUnix,
    RawZenohTcp,
    RawZenohShm,
    Bus,
    BusOwnRuntime,
    /// The bus on two sessions (`--low-latency-session`): speed on the low-latency one.
    BusTwoSessions,
    BusTwoSessionsUnix,
    BusLowlatency,
    BusUnix,
    BusLowlatencyUnix,
    BusKernelBuffers,
    BusOneCore,
    /// The bus rows with another build's peers (`--with-build LABEL=PATH`).
    BusBuild(String),
    BusUnixBuild(String),
    BusShm,
    BusShmUnix,
    BusShmUnixCallback,
    BusShmUnixThread,
    BusShmUnixThreadWoken,
    BusTcp,
    BusShmOwnRuntime,
    BusTcpOwnRuntime,
    Unloaded,
    Frames30Qos,
    Frames30NoQos,
    SaturatingQos,
    SaturatingNoQos,
    SaturatingQosShm,
    SaturatingQosShmNice,
    SaturatingQosKernelBuffers,
    SaturatingQosOwnRuntime,
    SaturatingQosTwoSessions,
}

impl Path {
    pub fn label(&self) -> String {
        let fixed = match self {
            Path::BusBuild(b) => return format!("bus, {b}"),
            Path::BusUnixBuild(b) => return format!("bus, unix socket, {b}"),
            Path::SeedPythonUdp => "seed: Python UDP",
            Path::SeedPythonTcpPickle => "seed: Python pickle over TCP",
            Path::RawUdp => "raw UDP",
            Path::RawTcp => "raw TCP",
            Path::RawZenoh => "raw zenoh",
            Path::RawZenohOwnRuntime => "raw zenoh, zenoh's runtime",
            Path::RawZenohLowlatency => "raw zenoh, lowlatency transport",
            Path::RawZenohUnix => "raw zenoh, unix socket",
            Path::RawZenohTcp => "raw zenoh, TCP (shm off)",
            Path::RawZenohShm => "raw zenoh, implicit shm",
            Path::Bus => "bus",
            Path::BusTwoSessions => "bus, two sessions",
            Path::BusTwoSessionsUnix => "bus, two sessions, unix socket",
            Path::BusOwnRuntime => "bus, zenoh's runtime",
            Path::BusLowlatency => "bus, lowlatency transport",
            Path::BusUnix => "bus, unix socket",
            Path::BusLowlatencyUnix => "bus, lowlatency transport, unix socket",
            Path::BusKernelBuffers => "bus, kernel socket buffers",
            Path::BusOneCore => "bus, both peers on one core",
            Path::BusShm => "bus, shared memory",
            Path::BusShmUnix => "bus, shared memory, unix socket",
            Path::BusShmUnixCallback => "bus, shared memory, unix socket, callback reader",
            Path::BusShmUnixThread => "bus, shared memory, unix socket, reader thread",
            Path::BusShmUnixThreadWoken => "bus, shared memory, unix socket, reader thread woken (no polling)",
            Path::BusTcp => "bus, TCP (shm off)",
            Path::BusShmOwnRuntime => "bus, shared memory, zenoh's runtime",
            Path::BusTcpOwnRuntime => "bus, TCP (shm off), zenoh's runtime",
            Path::Unloaded => "unloaded",
            Path::Frames30Qos => "frames 30 Hz, QoS, TCP",
            Path::Frames30NoQos => "frames 30 Hz, QoS off, TCP",
            Path::SaturatingQos => "frames saturating, QoS, TCP",
            Path::SaturatingNoQos => "frames saturating, QoS off, TCP",
            Path::SaturatingQosShm => "frames saturating, QoS, shm",
            Path::SaturatingQosShmNice => "frames saturating, QoS, shm, frame thread at nice 10",
            Path::SaturatingQosKernelBuffers => "frames saturating, QoS, TCP, kernel socket buffers",
            Path::SaturatingQosOwnRuntime => "frames saturating, QoS, TCP, zenoh's runtime",
            Path::SaturatingQosTwoSessions => "frames saturating, QoS, TCP, two sessions",
        };
        fixed.into()
    }
}

/// A row's id: its table and its path there.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CaseId {
    #[serde(flatten)]
    pub table: Table,
    pub path: Path,
}

pub(crate) struct Case {
    pub id: CaseId,
    pub spec: CaseSpec,
}

/// Another build's binary, by label (`--with-build LABEL=PATH`).
pub(crate) struct OtherBuild {
    pub label: String,
    pub exe: String,
}

pub(crate) fn other_builds(args: &[String]) -> anyhow::Result<Vec<OtherBuild>> {
    args.iter()
        .map(|a| {
            let (label, exe) = a.split_once('=').ok_or_else(|| {
                anyhow::anyhow!("--with-build {a}: write LABEL=PATH, e.g. uring=/tmp/uring/release/slipstream")
            })?;
            anyhow::ensure!(
                std::path::Path::new(exe).is_file(),
                "--with-build {a}: no file at {exe} (build it, e.g. CARGO_TARGET_DIR=/tmp/uring cargo build --release --features uring)"
            );
            Ok(OtherBuild { label: label.to_string(), exe: exe.to_string() })
        })
        .collect()
}

pub(crate) fn speed_spec(transport: Transport, count: u64) -> CaseSpec {
    CaseSpec {
        transport,
        payload: Payload::Speed,
        count,
        rate_hz: Some(100.0),
        max_duration_s: count as f64 / 100.0 + 10.0,
        qos: true,
        shm: true,
        lowlatency: false,
        runtime: None,
        tcp_buffer: TcpBuffer::Default,
        unix_socket: false,
        background: None,
        via_router: false,
        namespace: None,
        control_echo: false,
        reader: FrameReader::Task,
        peer_exe: None,
        pin_cpu: None,
        subscribers: 1,
        two_sessions: false,
    }
}

/// Frames of `size` at `rate_hz` (a latency case: 60 frames) or as fast as the sender can
/// (throughput: up to 3 s), from one sender to one receiver.
pub(crate) fn frame_spec(
    transport: Transport,
    (width, height): (u32, u32),
    shm: bool,
    rate_hz: Option<f64>,
    quick: bool,
) -> CaseSpec {
    CaseSpec {
        payload: Payload::Frame { width, height },
        count: match (rate_hz, quick) {
            (Some(_), true) => 10,
            (Some(_), false) => 60,
            (None, true) => 200,
            (None, false) => 20_000,
        },
        rate_hz,
        max_duration_s: match (rate_hz, quick) {
            (Some(_), _) => 20.0,
            (None, true) => 1.0,
            (None, false) => 3.0,
        },
        shm,
        ..speed_spec(transport, 0)
    }
}

/// Every case of the suites asked for, in table order. `seed`: the seed's Python peers can
/// run here.
pub(crate) fn cases(suites: &[Suite], quick: bool, builds: &[OtherBuild], seed: bool) -> Vec<Case> {
    let mut out = Vec::new();
    if suites.contains(&Suite::Speed) {
        speed_cases(&mut out, if quick { 50 } else { 500 }, builds, seed);
    }
    if suites.contains(&Suite::Frames) {
        for size in FrameSize::ALL {
            for phase in [Phase::Throughput, Phase::Latency] {
                frame_cases(&mut out, size, phase, quick, seed);
            }
        }
    }
    if suites.contains(&Suite::Contention) {
        contention_cases(&mut out, if quick { 50 } else { 300 });
    }
    out
}

fn speed_cases(out: &mut Vec<Case>, n: u64, builds: &[OtherBuild], seed: bool) {
    let mut push = |path: Path, spec: CaseSpec| out.push(Case { id: CaseId { table: Table::Speed, path }, spec });
    let bus = || speed_spec(Transport::Bus, n);
    let own = || Some(ZENOH_OWN_RUNTIME.to_string());
    if seed {
        push(Path::SeedPythonUdp, speed_spec(Transport::SeedPythonUdp, n));
    }
    push(Path::RawUdp, speed_spec(Transport::Udp, n));
    push(Path::RawTcp, speed_spec(Transport::Tcp, n));
    push(Path::RawZenoh, speed_spec(Transport::Zenoh, n));
    push(Path::RawZenohLowlatency, CaseSpec { lowlatency: true, ..speed_spec(Transport::Zenoh, n) });
    // The bus as users get it (one session with priorities), then with speed on a low-latency
    // session of its own.
    push(Path::Bus, bus());
    push(Path::BusTwoSessions, CaseSpec { two_sessions: true, ..bus() });
    push(Path::RawZenohOwnRuntime, CaseSpec { runtime: own(), ..speed_spec(Transport::Zenoh, n) });
    push(Path::BusOwnRuntime, CaseSpec { runtime: own(), ..bus() });
    // The one session itself on the low-latency transport (no priorities).
    push(Path::BusLowlatency, CaseSpec { lowlatency: true, ..bus() });
    push(Path::RawZenohUnix, CaseSpec { unix_socket: true, ..speed_spec(Transport::Zenoh, n) });
    push(Path::BusUnix, CaseSpec { unix_socket: true, ..bus() });
    // Zenoh's low-latency transport (no priorities, so not for frames) over the one-host link.
    push(Path::BusLowlatencyUnix, CaseSpec { lowlatency: true, unix_socket: true, ..bus() });
    // Two sessions over the link `up` and `eval` give the loop's processes on one host.
    push(Path::BusTwoSessionsUnix, CaseSpec { two_sessions: true, unix_socket: true, ..bus() });
    // Issue 17's other leads for the speed path. (Batching off, `transport/link/tx/queue/
    // batching/enabled: false`, is not a row: Zenoh 1.10 then closes the transport before
    // the peers match, "Unable to push non droppable network message".)
    push(Path::BusKernelBuffers, CaseSpec { tcp_buffer: TcpBuffer::Kernel, ..bus() });
    push(Path::BusOneCore, CaseSpec { pin_cpu: Some(0), ..bus() });
    for b in builds {
        let other = |spec: CaseSpec| CaseSpec { peer_exe: Some(b.exe.clone()), ..spec };
        push(Path::BusBuild(b.label.clone()), other(bus()));
        push(Path::BusUnixBuild(b.label.clone()), other(CaseSpec { unix_socket: true, ..bus() }));
    }
}

fn frame_cases(out: &mut Vec<Case>, size: FrameSize, phase: Phase, quick: bool, seed: bool) {
    let table = Table::Frames { size, phase };
    let mut push = |path: Path, spec: CaseSpec| out.push(Case { id: CaseId { table, path }, spec });
    let rate = match phase {
        Phase::Throughput => None,
        Phase::Latency => Some(20.0),
    };
    let frame = |transport, shm| frame_spec(transport, size.dims(), shm, rate, quick);
    if seed {
        push(Path::SeedPythonTcpPickle, frame(Transport::SeedPythonTcpPickle, false));
    }
    push(Path::BusShm, frame(Transport::Bus, true));
    // The link `up` and `eval` give the loop's processes: the shared-memory descriptor crosses
    // a unix socket instead of TCP.
    push(Path::BusShmUnix, CaseSpec { unix_socket: true, ..frame(Transport::Bus, true) });
    if phase == Phase::Latency {
        // The same, read in Zenoh's receive callback: what the latest-only reader's hand-off
        // to the application's task adds.
        push(
            Path::BusShmUnixCallback,
            CaseSpec { unix_socket: true, reader: FrameReader::Callback, ..frame(Transport::Bus, true) },
        );
        // Read by a thread of its own, woken by the receive thread directly: the detector's
        // reader.
        push(
            Path::BusShmUnixThread,
            CaseSpec { unix_socket: true, reader: FrameReader::Thread, ..frame(Transport::Bus, true) },
        );
        // The same thread without polling: what the wake-up costs, in the same run.
        push(
            Path::BusShmUnixThreadWoken,
            CaseSpec { unix_socket: true, reader: FrameReader::ThreadWoken, ..frame(Transport::Bus, true) },
        );
    }
    push(Path::BusTcp, frame(Transport::Bus, false));
    push(Path::RawZenohTcp, frame(Transport::Zenoh, false));
    push(Path::RawZenohShm, frame(Transport::Zenoh, true));
    push(Path::RawTcp, frame(Transport::Tcp, false));
    if phase == Phase::Throughput {
        let own = |spec: CaseSpec| CaseSpec { runtime: Some(ZENOH_OWN_RUNTIME.into()), ..spec };
        push(Path::BusShmOwnRuntime, own(frame(Transport::Bus, true)));
        push(Path::BusTcpOwnRuntime, own(frame(Transport::Bus, false)));
    }
}

fn contention_cases(out: &mut Vec<Case>, n: u64) {
    let mut push = |path: Path, spec: CaseSpec| out.push(Case { id: CaseId { table: Table::Contention, path }, spec });
    let loaded = |rate: Option<f64>, qos: bool, shm: bool| CaseSpec {
        qos,
        shm,
        background: Some(Background { width: 640, height: 480, rate_hz: rate, nice: 0 }),
        ..speed_spec(Transport::Bus, n)
    };
    push(Path::Unloaded, speed_spec(Transport::Bus, n));
    push(Path::Frames30Qos, loaded(Some(30.0), true, false));
    push(Path::Frames30NoQos, loaded(Some(30.0), false, false));
    push(Path::SaturatingQos, loaded(None, true, false));
    push(Path::SaturatingNoQos, loaded(None, false, false));
    push(Path::SaturatingQosShm, loaded(None, true, true));
    let mut nice = loaded(None, true, true);
    nice.background = nice.background.map(|b| Background { nice: 10, ..b });
    push(Path::SaturatingQosShmNice, nice);
    push(Path::SaturatingQosKernelBuffers, CaseSpec { tcp_buffer: TcpBuffer::Kernel, ..loaded(None, true, false) });
    push(Path::SaturatingQosTwoSessions, CaseSpec { two_sessions: true, ..loaded(None, true, false) });
    push(
        Path::SaturatingQosOwnRuntime,
        CaseSpec { runtime: Some(ZENOH_OWN_RUNTIME.into()), ..loaded(None, true, false) },
    );
}
