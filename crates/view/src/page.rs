//! The view's page: the files of a page that needs nothing from the internet (HTML, script,
//! style compiled into the binary), its state as JSON and camera frames as JPEG.
//!
//! The page pulls: it asks for a snapshot, then for the frame the snapshot names, and asks
//! again when it has drawn them. A slow or far browser therefore asks less often and never
//! queues anything here; the frames it never asked for are counted as skipped (per page,
//! by the id it sends). A frame is encoded once per size however many pages ask for it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use serde::Serialize;

use super::board::{Board, Camera, Kept, Snapshot};
use super::http::{Body, Request, Response};
use super::timeline::{Position, Timeline};
use slipstream_observe::latency::{HopStats, LatencyWatch};
use slipstream_observe::watch::{TopView, Watcher};

const INDEX_HTML: &str = include_str!("page/index.html");
const APP_JS: &str = include_str!("page/app.js");
const STYLE_CSS: &str = include_str!("page/style.css");

/// JPEG quality of the page's frames: the boxes and the road read well, a 640x480 frame is
/// about 30 kB.
const JPEG_QUALITY: u8 = 80;
/// The narrowest frame a page may ask for.
const MIN_WIDTH: u32 = 16;
/// Pages remembered for counting skipped frames (the oldest forgotten beyond it).
const PAGES_REMEMBERED: usize = 64;
/// Bad requests are logged at most this often (each kind's first at once), with a count.
const LOG_EVERY: Duration = Duration::from_secs(10);

/// What the page's side of the view did, for the status line and the report.
#[derive(Default)]
pub(crate) struct Counters {
    pub states: AtomicU64,
    pub frames: AtomicU64,
    pub skipped: AtomicU64,
    pub bad: AtomicU64,
    pub websockets: AtomicU64,
    pub refused: AtomicU64,
    log: Mutex<Option<(Instant, u64)>>,
}

impl Counters {
    /// A request this server does not take: counted, logged (rate-limited).
    pub(crate) fn bad_request(&self, why: &str) {
        self.bad.fetch_add(1, Ordering::Relaxed);
        self.log_limited(why);
    }

    /// A connection over the limit, closed at once.
    pub(crate) fn refused(&self, why: &str) {
        self.refused.fetch_add(1, Ordering::Relaxed);
        self.log_limited(why);
    }

    pub(crate) fn websocket(&self) {
        self.websockets.fetch_add(1, Ordering::Relaxed);
    }

    fn log_limited(&self, why: &str) {
        let mut log = self.log.lock();
        let now = Instant::now();
        match *log {
            Some((last, n)) if now.duration_since(last) < LOG_EVERY => *log = Some((last, n + 1)),
            Some((_, n)) => {
                tracing::warn!("view: {why} (and {n} more refused since the last warning)");
                *log = Some((now, 0));
            }
            None => {
                tracing::warn!("view: {why} (refused; later ones are counted and logged every 10 s)");
                *log = Some((now, 0));
            }
        }
    }
}

/// A frame encoded for pages: which one and at what width.
struct Encoded {
    stamp: u64,
    width: u32,
    jpeg: Arc<Vec<u8>>,
}

/// The page's whole state, as `/state` answers.
#[derive(Serialize)]
struct State<'a> {
    #[serde(flatten)]
    board: Snapshot,
    top: TopView,
    hops: Vec<HopStats>,
    view: PageStats,
    version: &'a str,
    /// Where the recording is, when the view replays one.
    replay: Option<Position>,
}

/// What the view served so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PageStats {
    pub states: u64,
    pub frames: u64,
    /// Frames a page never asked for (it was slower than the camera), summed over pages.
    pub skipped: u64,
    pub bad_requests: u64,
    pub websockets: u64,
    pub refused: u64,
}

pub(crate) struct Page {
    board: Arc<Mutex<Board>>,
    watcher: Watcher,
    latency: LatencyWatch,
    pub counters: Counters,
    encoded: Mutex<[Option<Encoded>; 2]>,
    /// Per page: the last frame number it got, and when.
    pages: Mutex<HashMap<String, (u64, Instant)>>,
    timeline: Option<Arc<dyn Timeline>>,
}

impl Page {
    pub(crate) fn new(
        board: Arc<Mutex<Board>>,
        watcher: Watcher,
        latency: LatencyWatch,
        timeline: Option<Arc<dyn Timeline>>,
    ) -> Page {
        Page {
            board,
            watcher,
            latency,
            counters: Counters::default(),
            encoded: Mutex::new([None, None]),
            pages: Mutex::default(),
            timeline,
        }
    }

    pub(crate) fn stats(&self) -> PageStats {
        let c = &self.counters;
        PageStats {
            states: c.states.load(Ordering::Relaxed),
            frames: c.frames.load(Ordering::Relaxed),
            skipped: c.skipped.load(Ordering::Relaxed),
            bad_requests: c.bad.load(Ordering::Relaxed),
            websockets: c.websockets.load(Ordering::Relaxed),
            refused: c.refused.load(Ordering::Relaxed),
        }
    }

    /// The answer to a plain HTTP request.
    pub(crate) async fn answer(&self, req: &Request) -> Response {
        if req.method != "GET" && req.method != "HEAD" {
            self.counters.bad_request("a method other than GET or HEAD");
            return Response::text(405, "the view answers GET and HEAD only");
        }
        match req.path.as_str() {
            "/" | "/index.html" => asset("text/html; charset=utf-8", INDEX_HTML),
            "/app.js" => asset("text/javascript; charset=utf-8", APP_JS),
            "/style.css" => asset("text/css; charset=utf-8", STYLE_CSS),
            "/state" => self.state(req),
            "/frame" => self.frame(req).await,
            "/replay" if self.timeline.is_some() => self.replay(req),
            _ => {
                self.counters.bad_request("a request for a path the view does not have");
                Response::text(404, "no such page here: the view is at /")
            }
        }
    }

    fn state(&self, req: &Request) -> Response {
        self.counters.states.fetch_add(1, Ordering::Relaxed);
        let since = req.param("since").and_then(|s| s.parse::<f64>().ok()).filter(|s| s.is_finite());
        let state = State {
            board: self.board.lock().snapshot(since),
            top: self.watcher.view(),
            hops: self.latency.latency.lock().stats(true),
            view: self.stats(),
            version: env!("CARGO_PKG_VERSION"),
            replay: self.timeline.as_ref().map(|t| t.position()),
        };
        match serde_json::to_vec(&state) {
            Ok(json) => Response::new(200, "application/json", Body::Owned(Arc::new(json))),
            Err(e) => Response::text(503, &format!("the state does not serialise: {e}")),
        }
    }

    /// `/replay?play=1|0`, `/replay?seek=SECONDS` (simulated) and `/replay?rate=X`: the replay
    /// moved as asked; where it is.
    fn replay(&self, req: &Request) -> Response {
        let Some(timeline) = &self.timeline else { return Response::text(404, "no recording is replayed here") };
        if let Some(p) = req.param("play") {
            timeline.play(p == "1");
        }
        if let Some(t) = req.param("seek").and_then(|t| t.parse::<f64>().ok()).filter(|t| t.is_finite()) {
            timeline.seek(t);
        }
        if let Some(r) = req.param("rate").and_then(|r| r.parse::<f64>().ok()).filter(|r| r.is_finite() && *r > 0.0) {
            timeline.set_rate(r);
        }
        match serde_json::to_vec(&timeline.position()) {
            Ok(json) => Response::new(200, "application/json", Body::Owned(Arc::new(json))),
            Err(e) => Response::text(503, &format!("the position does not serialise: {e}")),
        }
    }

    /// `/frame?camera=front|narrow&stamp=NS&w=PX&page=ID`: the frame as JPEG, `w` pixels wide
    /// at most (never wider than the frame); the newest when `stamp` is not kept.
    async fn frame(&self, req: &Request) -> Response {
        let Some(camera) = Camera::parse(req.param("camera").unwrap_or("front")) else {
            self.counters.bad_request("a frame of a camera the view does not have");
            return Response::text(404, "cameras: front, narrow");
        };
        let stamp = req.param("stamp").and_then(|s| s.parse::<u64>().ok());
        let kept = {
            let board = self.board.lock();
            board.frame(camera, stamp).or_else(|| board.frame(camera, None))
        };
        let Some(kept) = kept else {
            return Response::text(404, "no frame from this camera yet");
        };
        let width =
            req.param("w").and_then(|w| w.parse::<u32>().ok()).unwrap_or(kept.width).clamp(MIN_WIDTH, kept.width);
        let jpeg = match self.encoded(camera, &kept, width).await {
            Ok(jpeg) => jpeg,
            Err(e) => return Response::text(503, &format!("the frame does not decode: {e}")),
        };
        self.counters.frames.fetch_add(1, Ordering::Relaxed);
        if let Some(page) = req.param("page") {
            self.count_skipped(page, kept.seq);
        }
        Response::new(200, "image/jpeg", Body::Owned(jpeg))
            .with_header("X-Frame-Stamp", kept.stamp.to_string())
            .with_header("X-Frame-Seq", kept.seq.to_string())
    }

    /// The frame's JPEG at `width`, encoded once (off the async threads) for every page.
    async fn encoded(&self, camera: Camera, kept: &Kept, width: u32) -> Result<Arc<Vec<u8>>, String> {
        if let Some(e) = &self.encoded.lock()[camera as usize] {
            if e.stamp == kept.stamp && e.width == width {
                return Ok(e.jpeg.clone());
            }
        }
        let k = kept.clone();
        let jpeg = tokio::task::spawn_blocking(move || jpeg_of(&k, width))
            .await
            .map_err(|e| format!("the encoder stopped: {e}"))??;
        let jpeg = Arc::new(jpeg);
        self.encoded.lock()[camera as usize] = Some(Encoded { stamp: kept.stamp, width, jpeg: jpeg.clone() });
        Ok(jpeg)
    }

    fn count_skipped(&self, page: &str, seq: u64) {
        let mut pages = self.pages.lock();
        if let Some((last, _)) = pages.get(page) {
            self.counters.skipped.fetch_add(seq.saturating_sub(*last + 1), Ordering::Relaxed);
        } else if pages.len() >= PAGES_REMEMBERED {
            if let Some(oldest) = pages.iter().min_by_key(|(_, (_, t))| *t).map(|(k, _)| k.clone()) {
                pages.remove(&oldest);
            }
        }
        // An id is the page's own random number: bounded in length like everything it sends.
        pages.insert(page.chars().take(32).collect(), (seq, Instant::now()));
    }
}

fn asset(content_type: &'static str, text: &'static str) -> Response {
    Response::new(200, content_type, Body::Static(text.as_bytes()))
}

/// The frame's pixels, scaled to `width` (aspect kept), as JPEG.
fn jpeg_of(kept: &Kept, width: u32) -> Result<Vec<u8>, String> {
    let frame = kept.sample.frame();
    let f = frame.msg;
    let rgb =
        slipstream_contract::msg::decode_pixels(f.data, f.width, f.height, f.encoding).map_err(|e| e.to_string())?;
    let img = image::RgbImage::from_raw(f.width, f.height, rgb.into_owned())
        .ok_or_else(|| format!("{}x{} does not match the pixels", f.width, f.height))?;
    let height = ((f.height as u64 * width as u64 + f.width as u64 / 2) / f.width as u64).max(1) as u32;
    let img = if width == f.width { img } else { image::imageops::thumbnail(&img, width, height) };
    let mut out = Vec::with_capacity(64 * 1024);
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode_image(&img)
        .map_err(|e| format!("JPEG encoding failed: {e}"))?;
    Ok(out)
}
