//! The live view: a page for any browser and a Foxglove WebSocket server, on one port
//! ([`super::front`]), fed from the bus.
//!
//! The bus side only keeps the latest message of each kind (Zenoh's receive thread stores a
//! handle, nothing is decoded twice or encoded there); a task of its own turns the latest into
//! Foxglove messages at most `rate_hz` times a second, and only for what a viewer subscribed
//! to. Each viewer's queue holds [`BACKLOG`] messages; beyond it the server drops the oldest,
//! so a slow viewer skips ahead instead of slowing anyone. The loop never waits for a viewer.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::error::{Error, Result};
use foxglove::schemas::{CameraCalibration, CompressedImage, FrameTransforms, ImageAnnotations, RawImage, SceneUpdate};
use foxglove::{Channel, Context, Encode, PartialMetadata, RawChannel, WebSocketServerHandle};
use parking_lot::Mutex;
use serde::Serialize;

use super::birdseye::birdseye;
use super::board::{Board, Camera};
use super::page::{Page, PageStats};
use super::scene::{self, Image, SceneContext};
use slipstream_contract::bus::{Bus, CallbackSubscriber, FrameSample, Received};
use slipstream_contract::msg::{
    AccStatus, CameraInfo, Detections, GroundTruthObjects, RoadSpec, SimEvent, SimEventKind, VehicleState,
};
use slipstream_contract::topics;
use slipstream_observe::latency::LatencyWatch;
use slipstream_observe::watch::Watcher;
use slipstream_sim::Scenario;

/// Where the server listens unless told otherwise: loopback only (docs/viewing.md shows the
/// SSH tunnel for a viewer on another PC).
pub const DEFAULT_HOST: &str = "127.0.0.1";
pub const DEFAULT_PORT: u16 = 8765;
/// Updates per second at most: the camera's default rate.
pub const DEFAULT_RATE_HZ: f64 = 20.0;
/// Messages queued per viewer before the server drops the oldest (about 0.3 s of updates).
pub(crate) const BACKLOG: usize = 32;

/// The viewer's topics (Foxglove's names, fixed whatever the bus's namespace and remapping:
/// the layout in config/foxglove-layout.json refers to them).
pub(crate) const TOPIC_CAMERA: &str = "/camera/front";
pub(crate) const TOPIC_ANNOTATIONS: &str = "/camera/front/annotations";
pub(crate) const TOPIC_CALIBRATION: &str = "/camera/front/calibration";
pub(crate) const TOPIC_VEHICLES: &str = "/scene/vehicles";
pub(crate) const TOPIC_ROAD: &str = "/scene/road";
pub(crate) const TOPIC_TF: &str = "/tf";
pub(crate) const TOPIC_ACC: &str = "/acc";

/// What the server serves and where.
#[derive(Clone)]
pub struct ViewOptions {
    pub host: String,
    pub port: u16,
    pub rate_hz: f64,
    /// The road and ego to draw; without a scenario the view takes the one the simulator
    /// announces (a built-in one) and draws no road for others.
    pub context: SceneContext,
    /// A recording replayed onto the view's bus, which the page moves through.
    pub timeline: Option<Arc<dyn super::Timeline>>,
}

impl ViewOptions {
    pub fn new(host: &str, port: u16) -> ViewOptions {
        ViewOptions {
            host: host.into(),
            port,
            rate_hz: DEFAULT_RATE_HZ,
            context: SceneContext::default(),
            timeline: None,
        }
    }

    /// The road and ego of `scenario`.
    pub fn with_scenario(mut self, scenario: &Scenario) -> ViewOptions {
        self.context = SceneContext::of(Some(scenario));
        self
    }
}

/// What the view sent so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ViewStats {
    pub viewers: usize,
    pub images: u64,
    pub annotations: u64,
    pub scenes: u64,
    pub series: u64,
    /// What the page's side served.
    pub page: PageStats,
}

/// The latest of everything the view draws; `fresh_*` says whether it changed since the
/// last update sent.
#[derive(Default)]
struct Latest {
    frame: Option<FrameSample>,
    camera_info: Option<CameraInfo>,
    detections: Option<Detections>,
    fresh_detections: bool,
    truth: Option<GroundTruthObjects>,
    state: Option<(u64, u64, VehicleState)>,
    fresh_state: bool,
    status: Option<AccStatus>,
    scenario: Option<String>,
    /// The road the simulator publishes (sim/road, latched: a view started beside a running
    /// loop gets it too).
    road: Option<RoadSpec>,
}

#[derive(Default)]
struct Counters {
    images: AtomicU64,
    annotations: AtomicU64,
    scenes: AtomicU64,
    series: AtomicU64,
}

/// The viewer's channels, in a context of their own (nothing else in the process logs there).
struct Channels {
    ctx: Arc<Context>,
    raw: Option<Channel<RawImage>>,
    compressed: Option<Channel<CompressedImage>>,
    annotations: Channel<ImageAnnotations>,
    calibration: Channel<CameraCalibration>,
    vehicles: Channel<SceneUpdate>,
    road: Channel<SceneUpdate>,
    tf: Channel<FrameTransforms>,
    acc: Arc<RawChannel>,
}

impl Channels {
    fn new(ctx: &Arc<Context>) -> Result<Channels> {
        let acc = ctx
            .channel_builder(TOPIC_ACC)
            .message_encoding("json")
            .schema(scene::acc_series_schema())
            .build_raw()
            .map_err(|source| Error::Foxglove { what: format!("declare the view's channel {TOPIC_ACC}"), source })?;
        Ok(Channels {
            ctx: ctx.clone(),
            raw: None,
            compressed: None,
            annotations: ctx.channel_builder(TOPIC_ANNOTATIONS).build(),
            calibration: ctx.channel_builder(TOPIC_CALIBRATION).build(),
            vehicles: ctx.channel_builder(TOPIC_VEHICLES).build(),
            road: ctx.channel_builder(TOPIC_ROAD).build(),
            tf: ctx.channel_builder(TOPIC_TF).build(),
            acc,
        })
    }

    /// Logs `msg` stamped with `stamp_ns` when a viewer subscribed to `ch`; whether it did.
    fn log<T: Encode>(ch: &Channel<T>, msg: &T, stamp_ns: u64) -> bool {
        let wanted = ch.has_sinks();
        if wanted {
            ch.log_with_meta(msg, PartialMetadata { log_time: Some(stamp_ns) });
        }
        wanted
    }

    /// The camera channel is made with the first frame: its schema follows the frames'
    /// encoding (raw pixels or a compressed image).
    fn image(&mut self, sample: FrameSample) -> bool {
        let stamp = sample.header().stamp_pub_ns;
        let ctx = &self.ctx;
        match scene::image(sample) {
            None => false,
            Some(Image::Raw(img)) => {
                Self::log(self.raw.get_or_insert_with(|| ctx.channel_builder(TOPIC_CAMERA).build()), &img, stamp)
            }
            Some(Image::Compressed(img)) => {
                Self::log(self.compressed.get_or_insert_with(|| ctx.channel_builder(TOPIC_CAMERA).build()), &img, stamp)
            }
        }
    }
}

/// The state of the update task between ticks.
struct Painter {
    channels: Channels,
    context: SceneContext,
    counters: Arc<Counters>,
    board: Arc<Mutex<Board>>,
}

impl Painter {
    /// One update: whatever changed since the last, to the channels viewers subscribed to.
    fn tick(&mut self, latest: &Mutex<Latest>) {
        let (frame, info, detections, truth, state, status, scenario, road) = {
            let mut l = latest.lock();
            let detections = std::mem::take(&mut l.fresh_detections).then(|| l.detections.clone()).flatten();
            let state = std::mem::take(&mut l.fresh_state).then_some(l.state.clone()).flatten();
            let frame = l.frame.take();
            let info = frame.as_ref().and(l.camera_info.clone());
            (frame, info, detections, l.truth.clone(), state, l.status.clone(), l.scenario.take(), l.road.take())
        };
        if let Some(road) = road {
            self.context.published(road);
        }
        if let Some(name) = scenario {
            self.context.announced(&name);
        }
        let frame_stamp = frame.as_ref().map(|f| f.header().stamp_pub_ns);
        if let Some(f) = frame {
            count(&self.counters.images, self.channels.image(f));
        }
        if let (Some(stamp), Some(info)) = (frame_stamp, info) {
            Channels::log(&self.channels.calibration, &scene::calibration(stamp, &info), stamp);
        }
        if let Some(stamp) = detections.as_ref().map(|d| d.frame_stamp_pub_ns).or(frame_stamp) {
            let lead = status.as_ref().and_then(|s| s.lead.map(|l| l.id));
            let a = scene::annotations(stamp, detections.as_ref(), truth.as_ref(), lead);
            count(&self.counters.annotations, Channels::log(&self.channels.annotations, &a, stamp));
        }
        if let Some((stamp, stamp_sim, ego)) = state {
            self.scene(stamp, stamp_sim, &ego, truth.as_ref(), status.as_ref());
        }
    }

    /// The vehicles, road and series of a new state: to the Foxglove channels that have a
    /// viewer, and always to the page's board (a page opened later gets the last minute).
    fn scene(
        &mut self,
        stamp: u64,
        stamp_sim: u64,
        ego: &VehicleState,
        truth: Option<&GroundTruthObjects>,
        status: Option<&AccStatus>,
    ) {
        let c = &self.channels;
        let params = self.context.ego();
        let vehicles = scene::vehicles(stamp, ego, &params, truth);
        count(&self.counters.scenes, Channels::log(&c.vehicles, &vehicles, stamp));
        Channels::log(&c.tf, &scene::ego_frame(stamp, ego), stamp);
        let road = self.context.road_around(ego);
        if let Some(lines) = road.as_deref().filter(|_| c.road.has_sinks()) {
            Channels::log(&c.road, &scene::road_update(stamp, lines), stamp);
        }
        let series = scene::acc_series(ego, stamp_sim, &params, status, truth);
        if c.acc.has_sinks() {
            if let Ok(json) = serde_json::to_vec(&series) {
                c.acc.log_with_meta(&json, PartialMetadata { log_time: Some(stamp) });
                self.counters.series.fetch_add(1, Ordering::Relaxed);
            }
        }
        let view = birdseye(ego, &params, truth, road.as_deref());
        let mut board = self.board.lock();
        board.on_series(series);
        board.on_scene(view);
    }
}

fn count(counter: &AtomicU64, sent: bool) {
    if sent {
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// A running live view; [`LiveView::stop`] ends it (dropping it stops the updates too).
pub struct LiveView {
    server: Option<WebSocketServerHandle>,
    task: tokio::task::JoinHandle<()>,
    front: tokio::task::JoinHandle<()>,
    port: u16,
    page: Arc<Page>,
    counters: Arc<Counters>,
    _subs: Vec<CallbackSubscriber>,
}

impl LiveView {
    /// Subscribes to the loop on `bus`, takes the view's port and starts the page and the
    /// Foxglove server behind it. Fails with the address when the port is taken.
    pub async fn start(bus: &Bus, opts: ViewOptions) -> Result<LiveView> {
        if !(opts.rate_hz.is_finite() && opts.rate_hz > 0.0) {
            return Err(Error::flag("the view's rate", "must be a number of updates per second > 0"));
        }
        let listener = tokio::net::TcpListener::bind((opts.host.as_str(), opts.port)).await.map_err(|source| {
            Error::System {
                what: format!(
                    "cannot serve the live view on {}:{} (another `slipstream view` or `up --view`? pick another with --view-port)",
                    opts.host, opts.port
                ),
                source,
            }
        })?;
        let port = listener.local_addr().map(|a| a.port()).unwrap_or(opts.port);
        let latest: Arc<Mutex<Latest>> = Arc::default();
        let board: Arc<Mutex<Board>> = Arc::default();
        let subs = subscribe(bus, &latest, &board).await?;
        let ctx = Context::new();
        let channels = Channels::new(&ctx)?;
        // The Foxglove server on loopback at a port of its own: viewers reach it through the
        // view's port (front.rs).
        let server = ctx
            .websocket_server()
            .name(format!("slipstream {}", env!("CARGO_PKG_VERSION")))
            .bind("127.0.0.1", 0)
            .message_backlog_size(BACKLOG)
            .start()
            .await
            .map_err(|source| Error::Foxglove {
                what: "cannot start the Foxglove server on loopback".into(),
                source,
            })?;
        let watcher = Watcher::start(bus, &bus.topics().every_key()).await?;
        let latency = LatencyWatch::start_live(bus, false).await?;
        let page = Arc::new(Page::new(board.clone(), watcher, latency, opts.timeline.clone()));
        let front = super::front::serve(listener, server.port(), page.clone());
        let counters = Arc::new(Counters::default());
        let mut painter = Painter { channels, context: opts.context.clone(), counters: counters.clone(), board };
        let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
        let task = tokio::spawn(async move {
            let mut every = tokio::time::interval(period);
            every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            loop {
                every.tick().await;
                painter.tick(&latest);
            }
        });
        Ok(LiveView { server: Some(server), task, front, port, page, counters, _subs: subs })
    }

    /// The port the view listens on (the one asked for, or the one chosen for port 0).
    pub fn port(&self) -> u16 {
        self.port
    }

    pub fn stats(&self) -> ViewStats {
        let c = &self.counters;
        ViewStats {
            viewers: self.server.as_ref().map_or(0, |s| s.client_count()),
            images: c.images.load(Ordering::Relaxed),
            annotations: c.annotations.load(Ordering::Relaxed),
            scenes: c.scenes.load(Ordering::Relaxed),
            series: c.series.load(Ordering::Relaxed),
            page: self.page.stats(),
        }
    }

    /// Stops the updates, the page and the server, closing the viewers' connections.
    pub async fn stop(mut self) -> ViewStats {
        let stats = self.stats();
        self.task.abort();
        self.front.abort();
        if let Some(server) = self.server.take() {
            server.stop().wait().await;
        }
        stats
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.task.abort();
        self.front.abort();
        if let Some(server) = self.server.take() {
            server.stop().detach_all();
        }
    }
}

/// The subscriptions that keep `latest` and the page's board current: short handlers on
/// Zenoh's receive thread.
async fn subscribe(
    bus: &Bus,
    latest: &Arc<Mutex<Latest>>,
    board: &Arc<Mutex<Board>>,
) -> Result<Vec<CallbackSubscriber>> {
    let (l, b) = (latest.clone(), board.clone());
    let frames = bus
        .subscribe_frames_with(topics::CAMERA_FRONT, move |f| {
            b.lock().on_frame(Camera::Front, f.clone());
            l.lock().frame = Some(f);
        })
        .await?;
    let b = board.clone();
    let narrow =
        bus.subscribe_frames_with(topics::CAMERA_NARROW, move |f| b.lock().on_frame(Camera::Narrow, f)).await?;
    let l = latest.clone();
    let info = bus
        .subscribe_with(topics::CAMERA_FRONT_INFO, move |i: Received<CameraInfo>| l.lock().camera_info = Some(i.msg))
        .await?;
    let (l, b) = (latest.clone(), board.clone());
    let detections = bus
        .subscribe_with(topics::PERCEPTION_OBJECTS, move |d: Received<Detections>| {
            b.lock().on_detections(&d.msg);
            let mut l = l.lock();
            l.detections = Some(d.msg);
            l.fresh_detections = true;
        })
        .await?;
    let (l, b) = (latest.clone(), board.clone());
    let truth = bus
        .subscribe_with(topics::OBJECTS, move |o: Received<GroundTruthObjects>| {
            b.lock().on_truth(&o.msg);
            l.lock().truth = Some(o.msg);
        })
        .await?;
    let mut subs = vec![frames, narrow, info, detections, truth];
    subs.extend(subscribe_state(bus, latest, board).await?);
    Ok(subs)
}

/// The ego's state, the ACC's status and the simulator's events.
async fn subscribe_state(
    bus: &Bus,
    latest: &Arc<Mutex<Latest>>,
    board: &Arc<Mutex<Board>>,
) -> Result<Vec<CallbackSubscriber>> {
    let l = latest.clone();
    let state = bus
        .subscribe_with(topics::VEHICLE_STATE, move |s: Received<VehicleState>| {
            let mut l = l.lock();
            l.state = Some((s.header.stamp_pub_ns, s.header.stamp_sim_ns, s.msg));
            l.fresh_state = true;
        })
        .await?;
    let (l, b) = (latest.clone(), board.clone());
    let status = bus
        .subscribe_with(topics::ACC_STATUS, move |s: Received<AccStatus>| {
            b.lock().on_lead(s.msg.lead.as_ref().map(|l| l.id));
            l.lock().status = Some(s.msg);
        })
        .await?;
    let (l, b) = (latest.clone(), board.clone());
    let events = bus
        .subscribe_with(topics::SIM_EVENTS, move |e: Received<SimEvent>| match e.msg.kind {
            SimEventKind::ScenarioStart { name, .. } => {
                b.lock().on_run(None);
                l.lock().scenario = Some(name);
            }
            SimEventKind::ScenarioEnd { reason, .. } => b.lock().on_run(Some(reason)),
            _ => {}
        })
        .await?;
    let l = latest.clone();
    let road = bus.subscribe_with(topics::SIM_ROAD, move |r: Received<RoadSpec>| l.lock().road = Some(r.msg)).await?;
    Ok(vec![state, status, events, road])
}
