//! The two processes of a benchmark case: a receiver that reports latencies, a sender that
//! paces messages. Run as `slipstream bench-peer` by the orchestrator in [`super`].
//!
//! Raw transports (UDP, TCP, raw Zenoh) carry a 16-byte record: seq (u64 LE) then the publish
//! wall-clock time (u64 LE ns), followed by the frame bytes for frames. The bus carries its
//! own encoded messages.

use std::io::{BufRead, Read, Write};
use std::net::{TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use parking_lot::Mutex;
use zenoh::bytes::ZBytes;
use zenoh::Wait;

use super::spec::{Background, CaseSpec, FrameReader, Payload, RecvReport, SendReport, TcpBuffer, Transport};
use slipstream_contract::bus::Bus;
use slipstream_contract::config::TopicMap;
use slipstream_contract::msg::{wall_clock_ns, ControlCommand, ImageEncoding, Speed};
use slipstream_contract::topics;

const RAW_HEADER: usize = 16;
const SPEED_KEY: &str = "bench/speed";
const FRAME_KEY: &str = "bench/frame";

fn raw_record(seq: u64) -> [u8; RAW_HEADER] {
    let mut r = [0u8; RAW_HEADER];
    r[..8].copy_from_slice(&seq.to_le_bytes());
    r[8..].copy_from_slice(&wall_clock_ns().to_le_bytes());
    r
}

fn parse_record(b: &[u8]) -> Option<(u64, u64)> {
    let seq = u64::from_le_bytes(b.get(..8)?.try_into().ok()?);
    let stamp = u64::from_le_bytes(b.get(8..16)?.try_into().ok()?);
    Some((seq, stamp))
}

/// What the receiver collects, shared with Zenoh callbacks and reader threads.
#[derive(Default)]
struct Collector {
    latencies: Mutex<Vec<i64>>,
    received: AtomicU64,
    bytes: AtomicU64,
    highest: Mutex<Option<u64>>,
    /// The earliest publish stamp and the latest arrival of the measured messages (wall clock,
    /// ns): the span a receiver's throughput is taken over.
    first_pub_last_arrival: Mutex<Option<(u64, u64)>>,
    background: AtomicU64,
    shm: AtomicU64,
    skipped: AtomicU64,
    handoffs: Mutex<Vec<i64>>,
}

impl Collector {
    fn record(&self, seq: u64, stamp_pub_ns: u64, len: usize) {
        let now_ns = wall_clock_ns();
        self.latencies.lock().push(now_ns as i64 - stamp_pub_ns as i64);
        self.received.fetch_add(1, Ordering::Relaxed);
        self.bytes.fetch_add(len as u64, Ordering::Relaxed);
        let mut h = self.highest.lock();
        *h = Some(h.map_or(seq, |x| x.max(seq)));
        let mut span = self.first_pub_last_arrival.lock();
        *span = Some(span.map_or((stamp_pub_ns, now_ns), |(f, l)| (f.min(stamp_pub_ns), l.max(now_ns))));
    }

    fn report(&self) -> RecvReport {
        RecvReport {
            received: self.received.load(Ordering::Relaxed),
            highest_seq: *self.highest.lock(),
            bytes: self.bytes.load(Ordering::Relaxed),
            latencies_ns: self.latencies.lock().clone(),
            span_s: self.first_pub_last_arrival.lock().map_or(0.0, |(f, l)| l.saturating_sub(f) as f64 / 1e9),
            background_received: self.background.load(Ordering::Relaxed),
            shared_memory: self.shm.load(Ordering::Relaxed),
            skipped: self.skipped.load(Ordering::Relaxed),
            handoff_ns: self.handoffs.lock().clone(),
        }
    }
}

/// The Zenoh config of a bench peer: the shipped default (config/zenoh.json5, so the bench
/// measures what users run) with loopback endpoints of its own, no scouting, and the case's
/// shared memory, transport and socket-buffer choices.
/// The default config on exactly these loopback endpoints: no rendezvous, no gossip, and the
/// listener bound before the session opens returns.
pub(crate) fn loopback_config(listen: Option<&str>, connect: &[String]) -> Result<zenoh::Config> {
    let mut c = zenoh::Config::from_json5(slipstream_contract::config::DEFAULT_ZENOH_CONFIG)
        .map_err(|e| anyhow::anyhow!("default config: {e}"))?;
    let set = |c: &mut zenoh::Config, k: &str, v: &str| c.insert_json5(k, v).map_err(|e| anyhow::anyhow!("{k}: {e}"));
    set(&mut c, "scouting/gossip/enabled", "false")?;
    // The default binds listeners in the background (the rendezvous may be busy); a bench
    // receiver's own port must be bound when the session opens.
    set(&mut c, "listen/timeout_ms", "0")?;
    set(&mut c, "listen/exit_on_failure", "true")?;
    set(&mut c, "listen/endpoints", &serde_json::to_string(&listen.into_iter().collect::<Vec<_>>())?)?;
    set(&mut c, "connect/endpoints", &serde_json::to_string(connect)?)?;
    Ok(c)
}

/// A bench peer's config: listening on `listen` (a receiver in peer mode) or connecting to
/// `connect` (a sender; or, with `via_router`, either side as the router's client).
pub(crate) fn peer_config(spec: &CaseSpec, listen: Option<&str>, connect: &[String]) -> Result<zenoh::Config> {
    let mut c = loopback_config(listen, connect)?;
    let set = |c: &mut zenoh::Config, k: &str, v: &str| c.insert_json5(k, v).map_err(|e| anyhow::anyhow!("{k}: {e}"));
    if spec.via_router {
        set(&mut c, "mode", "\"client\"")?;
    }
    set(&mut c, "transport/shared_memory/enabled", if spec.shm { "true" } else { "false" })?;
    match spec.tcp_buffer {
        TcpBuffer::Default => {}
        TcpBuffer::Kernel => {
            set(&mut c, "transport/link/tcp/so_sndbuf", "null")?;
            set(&mut c, "transport/link/tcp/so_rcvbuf", "null")?;
        }
        TcpBuffer::Bytes(b) => {
            set(&mut c, "transport/link/tcp/so_sndbuf", &b.to_string())?;
            set(&mut c, "transport/link/tcp/so_rcvbuf", &b.to_string())?;
        }
    }
    if spec.lowlatency {
        set(&mut c, "transport/unicast/lowlatency", "true")?;
        set(&mut c, "transport/unicast/qos/enabled", "false")?;
    }
    Ok(c)
}

/// The topic map of a bench peer: the defaults, or every topic at Zenoh's defaults
/// (`qos: false`), and shared memory for frames as the case says.
pub(crate) fn peer_topics(spec: &CaseSpec) -> Result<TopicMap> {
    let flat = r#"{ priority: "data", express: false, congestion_control: "drop" }"#;
    let topics = if spec.qos {
        String::new()
    } else {
        format!(r#"topics: {{ "vehicle/speed": {flat}, "camera/front": {flat} }},"#)
    };
    let poll = spec.reader != FrameReader::ThreadWoken;
    let text = format!("{{ {topics} camera: {{ shared_memory: {}, poll_before_frame: {poll} }} }}", spec.shm);
    let map = TopicMap::from_json5(&text, "bench case")?;
    Ok(match &spec.namespace {
        Some(ns) => map.with_namespace(ns)?,
        None => map,
    })
}

/// What a receiver keeps alive until the report: sessions, subscribers, reader threads.
#[derive(Default)]
struct Receiving {
    keep: Vec<Box<dyn std::any::Any + Send>>,
    threads: Vec<std::thread::JoinHandle<()>>,
    /// Run when collecting ends, before the report.
    on_stop: Vec<Box<dyn FnOnce() + Send>>,
}

/// Receiver: prints `READY <endpoint>`, collects until stdin closes (or a hard limit), then
/// prints `RESULT <json>`. `router`: the router's endpoint when the case goes through one.
pub(crate) async fn run_receiver(spec: CaseSpec, router: Option<String>) -> Result<()> {
    if spec.via_router != router.is_some() {
        bail!("a case through a router needs the router's endpoint (--endpoint), and only such a case");
    }
    if spec.transport != Transport::Bus && spec.background.is_some() {
        bail!("background frames are measured through the bus only");
    }
    let col = Arc::new(Collector::default());
    let stop = Arc::new(AtomicBool::new(false));
    let mut receiving = Receiving::default();
    let endpoint = match spec.transport {
        Transport::Udp => receive_udp(&col, &stop, &mut receiving)?,
        Transport::Tcp => receive_tcp(&col, &stop, &mut receiving)?,
        Transport::Zenoh => receive_zenoh(&spec, router.as_deref(), &col, &mut receiving).await?,
        Transport::Bus => receive_bus(&spec, router.as_deref(), &col, &stop, &mut receiving).await?,
        Transport::SeedPythonUdp | Transport::SeedPythonTcpPickle => {
            anyhow::bail!("the seed's peers are the Python script, not bench-peer")
        }
    };
    println!("READY {endpoint}");
    std::io::stdout().flush()?;

    // Wait for the orchestrator to close stdin (or a hard limit so nothing hangs).
    let hard_limit = Duration::from_secs_f64(spec.max_duration_s + 60.0);
    let (tx, rx) = tokio::sync::oneshot::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = std::io::stdin().lock().read_line(&mut line);
        let _ = tx.send(());
    });
    let _ = tokio::time::timeout(hard_limit, rx).await;
    stop.store(true, Ordering::Relaxed);
    for t in receiving.threads {
        let _ = t.join();
    }
    for f in receiving.on_stop {
        f();
    }
    let report = col.report();
    drop(receiving.keep);
    println!("RESULT {}", serde_json::to_string(&report)?);
    std::io::stdout().flush()?;
    Ok(())
}

/// Raw UDP: one datagram per record, read by a thread of its own.
fn receive_udp(col: &Arc<Collector>, stop: &Arc<AtomicBool>, r: &mut Receiving) -> Result<String> {
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(Duration::from_millis(50)))?;
    let addr = sock.local_addr()?;
    let (col, stop) = (col.clone(), stop.clone());
    r.threads.push(std::thread::spawn(move || {
        let mut buf = [0u8; 2048];
        while !stop.load(Ordering::Relaxed) {
            if let Ok(n) = sock.recv(&mut buf) {
                if let Some((seq, stamp)) = parse_record(&buf[..n]) {
                    col.record(seq, stamp, n);
                }
            }
        }
    }));
    Ok(addr.to_string())
}

/// Raw TCP: length-prefixed records on one connection, read by a thread of its own.
fn receive_tcp(col: &Arc<Collector>, stop: &Arc<AtomicBool>, r: &mut Receiving) -> Result<String> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let addr = listener.local_addr()?;
    let (col, stop) = (col.clone(), stop.clone());
    r.threads.push(std::thread::spawn(move || {
        let Ok((stream, _)) = listener.accept() else { return };
        let _ = stream.set_nodelay(true);
        let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
        let mut stream = std::io::BufReader::with_capacity(1 << 16, stream);
        let mut len_buf = [0u8; 4];
        let mut body = Vec::new();
        // read_fully keeps partial progress across read timeouts (read_exact would lose a
        // half-read length prefix and desynchronise the stream).
        while !stop.load(Ordering::Relaxed) {
            if read_fully(&mut stream, &mut len_buf, &stop).is_err() {
                return;
            }
            let len = u32::from_le_bytes(len_buf) as usize;
            body.resize(len, 0);
            if read_fully(&mut stream, &mut body, &stop).is_err() {
                return;
            }
            if let Some((seq, stamp)) = parse_record(&body) {
                col.record(seq, stamp, len + 4);
            }
        }
    }));
    Ok(addr.to_string())
}

/// Raw Zenoh: a callback subscriber on the case's key.
async fn receive_zenoh(
    spec: &CaseSpec,
    router: Option<&str>,
    col: &Arc<Collector>,
    r: &mut Receiving,
) -> Result<String> {
    let session = zenoh::open(receiver_config(spec, router)?).await.map_err(anyhow::Error::msg)?;
    let key = if matches!(spec.payload, Payload::Speed) { SPEED_KEY } else { FRAME_KEY };
    let c = col.clone();
    let sub = session
        .declare_subscriber(key)
        .callback(move |s| {
            let p = s.payload();
            if p.as_shm().is_some() {
                c.shm.fetch_add(1, Ordering::Relaxed);
            }
            let bytes = p.to_bytes();
            if let Some((seq, stamp)) = parse_record(&bytes) {
                c.record(seq, stamp, bytes.len());
            }
        })
        .await
        .map_err(anyhow::Error::msg)?;
    let ep = receiver_endpoint(&session, router).await?;
    r.keep.push(Box::new(sub));
    r.keep.push(Box::new(session));
    Ok(ep)
}

/// A receiver listens on an endpoint of its own, or is the router's client.
fn receiver_config(spec: &CaseSpec, router: Option<&str>) -> Result<zenoh::Config> {
    match router {
        Some(r) => peer_config(spec, None, &[r.to_string()]),
        None => peer_config(spec, Some(&listen_endpoint(spec)), &[]),
    }
}

/// What the receiver's READY line gives the sender: where to connect (the router's clients
/// both connect to the router).
async fn receiver_endpoint(session: &zenoh::Session, router: Option<&str>) -> Result<String> {
    match router {
        Some(r) => Ok(r.to_string()),
        None => first_locator(session).await,
    }
}

/// The bus: speed by a callback subscriber; frames as [`read_frames`] says.
async fn receive_bus(
    spec: &CaseSpec,
    router: Option<&str>,
    col: &Arc<Collector>,
    stop: &Arc<AtomicBool>,
    r: &mut Receiving,
) -> Result<String> {
    let main = receiver_config(spec, router)?;
    let low_latency = low_latency_config(spec, &main, &[])?;
    // A name of its own: the sender counts the receivers alive before it starts.
    let node = format!("{RECEIVER_NODE}-{}", std::process::id());
    let bus = Arc::new(Bus::open_sessions(main, low_latency, peer_topics(spec)?, &node).await?);
    let mut ep = receiver_endpoint(bus.session(), router).await?;
    if let Some(ll) = bus.low_latency_session() {
        // The sender's low-latency session dials this one (READY's second endpoint).
        ep = format!("{ep} {LOW_LATENCY_TAG}{}", first_locator(ll).await?);
    }
    if matches!(spec.payload, Payload::Speed) {
        let answer = match spec.control_echo {
            true => Some(control_echo(&bus, stop, r).await?),
            false => None,
        };
        let c = col.clone();
        let sub = bus
            .subscribe_with(topics::VEHICLE_SPEED, move |r| {
                c.record(r.header.seq, r.header.stamp_pub_ns, 0);
                if let Some(tx) = &answer {
                    let _ = tx.send(r.header.stamp_sim_ns);
                }
            })
            .await?;
        r.keep.push(Box::new(sub));
    }
    let frames_measured = matches!(spec.payload, Payload::Frame { .. });
    if frames_measured || spec.background.is_some() {
        read_frames(&bus, spec, col, stop, r).await?;
    }
    r.keep.push(Box::new(bus));
    Ok(ep)
}

/// Frames at the receiver: counted in the receive callback (throughput, or a latency case that
/// asks for it: validated, zero-copy, touching the last byte, where raw zenoh counts them), or
/// taken from the application's latest-only `FrameSubscriber` by a task or a thread of its own
/// (latency, background load).
async fn read_frames(
    bus: &Bus,
    spec: &CaseSpec,
    col: &Arc<Collector>,
    stop: &Arc<AtomicBool>,
    r: &mut Receiving,
) -> Result<()> {
    let measured = matches!(spec.payload, Payload::Frame { .. });
    let reader = if measured && spec.rate_hz.is_none() { FrameReader::Callback } else { spec.reader };
    let handed_off = reader != FrameReader::Callback;
    let take = {
        let c = col.clone();
        move |s: &slipstream_contract::bus::FrameSample| {
            let f = s.frame();
            let _ = std::hint::black_box(f.msg.data.last());
            if s.is_shared_memory() {
                c.shm.fetch_add(1, Ordering::Relaxed);
            }
            if measured {
                c.record(f.header.seq, f.header.stamp_pub_ns, s.bytes().len());
                if handed_off {
                    c.handoffs.lock().push(wall_clock_ns() as i64 - s.arrived_ns() as i64);
                }
            } else {
                c.background.fetch_add(1, Ordering::Relaxed);
            }
        }
    };
    if reader == FrameReader::Callback {
        let sub = bus.subscribe_frames_with(slipstream_contract::topics::CAMERA_FRONT, move |s| take(&s)).await?;
        r.keep.push(Box::new(sub));
        return Ok(());
    }
    let sub = bus.frame_subscriber(slipstream_contract::topics::CAMERA_FRONT).await?;
    let (skipped, stats) = (col.clone(), sub.stats().clone());
    r.on_stop.push(Box::new(move || {
        skipped.skipped.store(stats.snapshot().skipped, Ordering::Relaxed);
    }));
    let stop = stop.clone();
    const POLL: Duration = Duration::from_millis(100);
    if matches!(reader, FrameReader::Thread | FrameReader::ThreadWoken) {
        r.threads.push(std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                if let Some(s) = sub.recv_blocking(POLL) {
                    take(&s);
                }
            }
        }));
    } else {
        tokio::spawn(async move {
            while !stop.load(Ordering::Relaxed) {
                if let Some(s) = sub.recv_timeout(POLL).await {
                    take(&s);
                }
            }
        });
    }
    Ok(())
}

/// Marks an endpoint of a receiver's low-latency session (in READY and a sender's
/// `--endpoint` list).
pub(crate) const LOW_LATENCY_TAG: &str = "ll=";

/// A bus peer's low-latency session, as a node derives it (unless the case runs one session
/// or goes through a router); a sender dials `connect`, the receiver's.
fn low_latency_config(spec: &CaseSpec, main: &zenoh::Config, connect: &[String]) -> Result<Option<zenoh::Config>> {
    if !spec.two_sessions {
        return Ok(None);
    }
    let given = slipstream_contract::config::LowLatencyEndpoints { listen: Vec::new(), connect: connect.to_vec() };
    Ok(slipstream_contract::config::low_latency_config(main, &given)?)
}

/// The receivers' node names start with this (then `-<pid>`).
const RECEIVER_NODE: &str = "bench-recv";

/// A controller's answer to each speed message: a vehicle/control command published by a
/// thread of its own (as a node's control loop would, not from Zenoh's callback), stamped
/// with the speed message's simulation time. Returns where the callback hands over.
async fn control_echo(bus: &Bus, stop: &Arc<AtomicBool>, r: &mut Receiving) -> Result<std::sync::mpsc::Sender<u64>> {
    let publisher = bus.publisher(topics::VEHICLE_CONTROL).await?;
    let (tx, rx) = std::sync::mpsc::channel::<u64>();
    let stop = stop.clone();
    r.threads.push(std::thread::spawn(move || {
        let command = ControlCommand { throttle: 0.2, ..ControlCommand::NEUTRAL };
        while !stop.load(Ordering::Relaxed) {
            if let Ok(stamp_sim_ns) = rx.recv_timeout(Duration::from_millis(50)) {
                let _ = publisher.put(stamp_sim_ns, &command);
            }
        }
    }));
    Ok(tx)
}

fn read_fully(stream: &mut impl Read, buf: &mut [u8], stop: &AtomicBool) -> std::io::Result<()> {
    let mut at = 0;
    while at < buf.len() {
        match stream.read(&mut buf[at..]) {
            Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => at += n,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                if stop.load(Ordering::Relaxed) {
                    return Err(e);
                }
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Where a Zenoh receiver listens: a free loopback TCP port, or a unix socket of this
/// process in the temp directory (removed first if a crashed run left it).
fn listen_endpoint(spec: &CaseSpec) -> String {
    if spec.unix_socket {
        let path = std::env::temp_dir().join(format!("slipstream-bench-{}.sock", std::process::id()));
        let _ = std::fs::remove_file(&path);
        format!("unixsock-stream/{}", path.display())
    } else {
        "tcp/127.0.0.1:0".to_string()
    }
}

async fn first_locator(session: &zenoh::Session) -> Result<String> {
    let locators = session.info().locators().await;
    locators.first().map(|l| l.to_string()).context("the receiver's session has no listening locator")
}

/// The first and the last publish stamp of what a sender sent (wall clock, ns): the span its
/// rate is taken over, the same clock and the same start as a receiver's
/// (`RecvReport::span_s`), so that no receiver's rate exceeds it.
#[derive(Default)]
struct Stamps(Mutex<Option<(u64, u64)>>);

impl Stamps {
    /// Notes a message's publish stamp (None: not sent); returns whether it was sent.
    fn note(&self, stamp_pub_ns: Option<u64>) -> bool {
        let Some(t) = stamp_pub_ns else { return false };
        let mut s = self.0.lock();
        *s = Some(s.map_or((t, t), |(first, _)| (first, t)));
        true
    }

    fn span_s(&self) -> f64 {
        self.0.lock().map_or(0.0, |(first, last)| last.saturating_sub(first) as f64 / 1e9)
    }
}

/// Paces a loop: the i-th iteration starts at start + i/rate (no drift), or at once.
struct Pacer {
    start: Instant,
    period: Option<Duration>,
}

impl Pacer {
    fn new(rate_hz: Option<f64>) -> Self {
        Pacer { start: Instant::now(), period: rate_hz.map(|r| Duration::from_secs_f64(1.0 / r)) }
    }
    fn wait(&self, i: u64) {
        if let Some(p) = self.period {
            let due = self.start + p * i as u32;
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
    }
}

impl Pacer {
    /// Calls `send(i)` for i in 0..count at the pace, until `deadline`; counts the sends that
    /// returned true (a frame dropped by a rate limit returns false).
    fn run(&self, count: u64, deadline: Instant, mut send: impl FnMut(u64) -> Result<bool>) -> Result<u64> {
        let mut sent = 0;
        for i in 0..count {
            if Instant::now() > deadline {
                break;
            }
            self.wait(i);
            sent += send(i)? as u64;
        }
        Ok(sent)
    }
}

/// After the last message: time for it to arrive before the session closes.
const DRAIN: Duration = Duration::from_millis(300);

/// Sender: connects to `endpoint`, sends the measured stream (and background frames), prints
/// `SENT <json>`.
pub(crate) async fn run_sender(spec: CaseSpec, endpoints: Vec<String>) -> Result<()> {
    let endpoint = endpoints.first().cloned().context("a sender needs an endpoint")?;
    // The sending time a case allows counts from its first message, once the receiver is
    // matched: a session that is slow to connect on a loaded machine does not eat it.
    let max = Duration::from_secs_f64(spec.max_duration_s);
    let started = Instant::now();
    let mut report = match spec.transport {
        Transport::Udp => {
            SendReport { sent: send_udp(&spec, &endpoint, Instant::now() + max)?, ..SendReport::default() }
        }
        Transport::Tcp => {
            SendReport { sent: send_tcp(&spec, &endpoint, Instant::now() + max)?, ..SendReport::default() }
        }
        Transport::Zenoh => SendReport { sent: send_zenoh(&spec, &endpoints, max).await?, ..SendReport::default() },
        Transport::Bus => send_bus(&spec, &endpoints, max).await?,
        Transport::SeedPythonUdp | Transport::SeedPythonTcpPickle => {
            anyhow::bail!("the seed's peers are the Python script, not bench-peer")
        }
    };
    report.elapsed_s = started.elapsed().as_secs_f64();
    println!("SENT {}", serde_json::to_string(&report)?);
    std::io::stdout().flush()?;
    Ok(())
}

fn frame_bytes(payload: &Payload) -> Vec<u8> {
    match payload {
        Payload::Speed => Vec::new(),
        Payload::Frame { width, height } => vec![7u8; (width * height * 3) as usize],
    }
}

fn send_udp(spec: &CaseSpec, endpoint: &str, deadline: Instant) -> Result<u64> {
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.connect(endpoint)?;
    Pacer::new(spec.rate_hz).run(spec.count, deadline, |i| Ok(sock.send(&raw_record(i)).map(|_| true)?))
}

fn send_tcp(spec: &CaseSpec, endpoint: &str, deadline: Instant) -> Result<u64> {
    let mut stream = TcpStream::connect(endpoint)?;
    stream.set_nodelay(true)?;
    let frame = frame_bytes(&spec.payload);
    let sent = Pacer::new(spec.rate_hz).run(spec.count, deadline, |i| {
        let len = (RAW_HEADER + frame.len()) as u32;
        let mut head = [0u8; 4 + RAW_HEADER];
        head[..4].copy_from_slice(&len.to_le_bytes());
        head[4..].copy_from_slice(&raw_record(i));
        stream.write_all(&head)?;
        if !frame.is_empty() {
            stream.write_all(&frame)?;
        }
        Ok(true)
    })?;
    stream.flush()?;
    Ok(sent)
}

async fn send_zenoh(spec: &CaseSpec, endpoints: &[String], max: Duration) -> Result<u64> {
    let session = zenoh::open(peer_config(spec, None, endpoints)?).await.map_err(anyhow::Error::msg)?;
    let (key, topic, frame) = match spec.payload {
        Payload::Speed => (SPEED_KEY, topics::Topic::VehicleSpeed, None),
        Payload::Frame { .. } => {
            (FRAME_KEY, topics::Topic::CameraFront, Some(ZBytes::from(frame_bytes(&spec.payload))))
        }
    };
    // The same QoS the bus gives the topic (or Zenoh's defaults with qos off): the comparison
    // isolates the typed layer.
    let qos = peer_topics(spec)?.qos(topic);
    let publisher = session
        .declare_publisher(key)
        .priority(qos.priority.into())
        .express(qos.express)
        .congestion_control(qos.congestion_control.into())
        .await
        .map_err(anyhow::Error::msg)?;
    wait_matching(&publisher).await?;
    let deadline = Instant::now() + max;
    let sent = Pacer::new(spec.rate_hz).run(spec.count, deadline, |i| {
        let payload = match &frame {
            None => ZBytes::from(raw_record(i).to_vec()),
            Some(f) => {
                // Record then the frame: two slices, the frame shared, not copied.
                let mut w = ZBytes::writer();
                w.write_all(&raw_record(i))?;
                w.append(f.clone());
                w.finish()
            }
        };
        publisher.put(payload).wait().map_err(anyhow::Error::msg)?;
        Ok(true)
    })?;
    tokio::time::sleep(DRAIN).await;
    session.close().await.map_err(anyhow::Error::msg)?;
    Ok(sent)
}

async fn send_bus(spec: &CaseSpec, endpoints: &[String], max: Duration) -> Result<SendReport> {
    // Background frames stop with the measured stream; this only bounds them if it hangs.
    let guard = Instant::now() + max + MATCH_WAIT;
    let (main_eps, ll_eps): (Vec<String>, Vec<String>) =
        endpoints.iter().cloned().partition(|e| !e.starts_with(LOW_LATENCY_TAG));
    let ll_eps: Vec<String> = ll_eps.iter().map(|e| e.trim_start_matches(LOW_LATENCY_TAG).to_string()).collect();
    let main = peer_config(spec, None, &main_eps)?;
    let low_latency = low_latency_config(spec, &main, &ll_eps)?;
    let bus = Bus::open_sessions(main, low_latency, peer_topics(spec)?, "bench-send").await?;
    wait_receivers(&bus, spec.subscribers).await?;
    let bus = Arc::new(bus);
    let control = Arc::new(Collector::default());
    let control_sub = match spec.control_echo {
        true => {
            let c = control.clone();
            Some(
                bus.subscribe_with(topics::VEHICLE_CONTROL, move |r| c.record(r.header.seq, r.header.stamp_pub_ns, 0))
                    .await?,
            )
        }
        false => None,
    };
    let done = Arc::new(AtomicBool::new(false));
    let background = spec.background.map(|bg| {
        let (bus, done) = (bus.clone(), done.clone());
        tokio::spawn(async move { send_background(bus, bg, done, guard).await })
    });
    let mut report = SendReport::default();
    match spec.payload {
        Payload::Speed => {
            let publisher = bus.publisher(topics::VEHICLE_SPEED).await?;
            if !publisher.wait_for_subscriber(MATCH_WAIT).await {
                bail!("no subscriber matched vehicle/speed within {MATCH_WAIT:?}");
            }
            let (pacer, deadline) = (Pacer::new(spec.rate_hz), Instant::now() + max);
            // Paced on a blocking thread: a sleeping pacer must not hold a runtime worker.
            let count = spec.count;
            let stamps = Arc::new(Stamps::default());
            let seen = stamps.clone();
            report.sent = tokio::task::spawn_blocking(move || {
                pacer.run(count, deadline, |i| {
                    let header = publisher.put(i * 10_000_000, &Speed { speed_mps: 20.0 });
                    Ok(seen.note(header.ok().flatten().map(|h| h.stamp_pub_ns)))
                })
            })
            .await??;
            report.span_s = stamps.span_s();
        }
        Payload::Frame { width, height } => {
            let publisher = bus.frame_publisher(slipstream_contract::topics::CAMERA_FRONT).await?;
            if !publisher.publisher().wait_for_subscriber(MATCH_WAIT).await {
                bail!("no subscriber matched camera/front within {MATCH_WAIT:?}");
            }
            let (pacer, deadline) = (Pacer::new(spec.rate_hz), Instant::now() + max);
            let len = (width * height * 3) as usize;
            let stamps = Stamps::default();
            report.sent = pacer.run(spec.count, deadline, |i| {
                // The renderer would write every pixel here; the bench writes one byte so
                // that only transport costs are compared.
                let sent = publisher
                    .put_with(i * 50_000_000, width, height, ImageEncoding::Rgb8, len, |px| px[len - 1] = i as u8)?;
                Ok(stamps.note(sent.map(|s| s.header.stamp_pub_ns)))
            })?;
            report.span_s = stamps.span_s();
        }
    }
    done.store(true, Ordering::Relaxed);
    if let Some(bg) = background {
        report.background_sent = bg.await??;
    }
    tokio::time::sleep(DRAIN).await;
    let answers = control.report();
    report.control_received = answers.received;
    report.control_latencies_ns = answers.latencies_ns;
    drop(control_sub);
    if let Ok(bus) = Arc::try_unwrap(bus) {
        bus.close().await?;
    }
    Ok(report)
}

async fn send_background(bus: Arc<Bus>, bg: Background, done: Arc<AtomicBool>, deadline: Instant) -> Result<u64> {
    let publisher = bus.frame_publisher(slipstream_contract::topics::CAMERA_FRONT).await?;
    let len = (bg.width * bg.height * 3) as usize;
    tokio::task::spawn_blocking(move || {
        if bg.nice != 0 {
            // SAFETY: setpriority on this thread's own id (Linux: a thread is a process id).
            let rc = unsafe { libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, bg.nice) };
            anyhow::ensure!(rc == 0, "setpriority {}: {}", bg.nice, std::io::Error::last_os_error());
        }
        let pacer = Pacer::new(bg.rate_hz);
        let mut sent = 0u64;
        let mut i = 0u64;
        while !done.load(Ordering::Relaxed) && Instant::now() < deadline {
            pacer.wait(i);
            match publisher
                .put_with(i * 33_000_000, bg.width, bg.height, ImageEncoding::Rgb8, len, |px| px[0] = i as u8)
            {
                Ok(Some(_)) => sent += 1,
                Ok(None) => {}
                Err(e) => return Err(anyhow::Error::from(e)),
            }
            i += 1;
        }
        Ok(sent)
    })
    .await?
}

/// How long a sender waits for its receiver to match.
const MATCH_WAIT: Duration = Duration::from_secs(10);

/// Waits until `n` receivers are alive (their liveliness tokens, seen directly or through a
/// router), then a moment more for their subscriptions (declared before each printed READY,
/// after its token) to reach this session on every path: a case with several receivers
/// starts when all of them listen.
async fn wait_receivers(bus: &Bus, n: usize) -> Result<()> {
    if n <= 1 {
        return Ok(());
    }
    let deadline = Instant::now() + MATCH_WAIT;
    loop {
        let alive = bus.nodes_alive().await?.iter().filter(|name| name.starts_with(RECEIVER_NODE)).count();
        if alive >= n {
            break;
        }
        if Instant::now() > deadline {
            bail!("{alive} of {n} receivers alive after {MATCH_WAIT:?}");
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    Ok(())
}

async fn wait_matching(publisher: &zenoh::pubsub::Publisher<'_>) -> Result<()> {
    let deadline = Instant::now() + MATCH_WAIT;
    while Instant::now() < deadline {
        if publisher.matching_status().await.map(|s| s.matching()).unwrap_or(false) {
            return Ok(());
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    bail!("no subscriber matched within 10 s")
}
