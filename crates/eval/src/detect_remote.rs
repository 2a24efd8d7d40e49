//! A detector of the user's own scored like slipstream-detect (`eval detect --detector CMD`):
//! the same worlds, the same frames and the same tally, but the frames go to its process over
//! the bus (camera/front, with camera/front/info latched) and its perception/objects come
//! back. Each frame waits for the detections of exactly that frame (`frame_seq`), as a
//! controller does in lockstep, so the score does not depend on the machine's speed; a frame
//! left unanswered for [`ANSWER_TIMEOUT`] is scored as one without detections and counted.
//!
//! One process per scenario (a tracker's state does not cross scenarios, as ours is built
//! afresh for each), on loopback ports and a namespace of its own, its logs in a directory of
//! the suite's.

use std::path::Path;
use std::time::{Duration, Instant};

use super::frame_detector::FrameDetector;
use crate::error::{Error, Result};
use slipstream_contract::bus::{FramePublisher, Publisher, Received, Subscriber};
use slipstream_contract::config::DEFAULT_ZENOH_CONFIG;
use slipstream_contract::msg::{CameraInfo, Detection, Detections};
use slipstream_contract::{topics, Bus, TopicMap};
use slipstream_launch::supervise::{State, Supervised};
use slipstream_launch::{free_ports, last_words, ForeignNode, NODE_POLL};
use slipstream_sim::Cameras;

/// How long a frame waits for its detections.
pub(crate) const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

/// The detector's process and the suite's end of the bus.
pub(crate) struct Yours {
    rt: tokio::runtime::Runtime,
    bus: Option<Bus>,
    /// Latched: kept for as long as the detector may join.
    _info: Publisher<CameraInfo>,
    frames: FramePublisher,
    answers: Subscriber<Detections>,
    node: Supervised,
    unanswered: u64,
}

impl Yours {
    /// Starts `node` for a scenario drawn by `cameras` (logs in `logs`) and waits until it is
    /// ready (its token), with the camera's info latched for it.
    pub(crate) fn start(node: &ForeignNode, cameras: &Cameras, logs: &Path) -> Result<Yours> {
        std::fs::create_dir_all(logs).map_err(Error::file("create the log directory", logs))?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .map_err(|source| Error::System { what: "start a runtime".into(), source })?;
        let [ours, its] = free_ports::<2>()?.map(|p| format!("tcp/127.0.0.1:{p}"));
        static RUNS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let run = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let namespace = format!("eval-detect-{}-{run}", std::process::id());
        let isolated = slipstream_launch::ISOLATED_CFG;
        let (bus, info, frames, answers) = rt.block_on(async {
            let mut config =
                zenoh::Config::from_json5(DEFAULT_ZENOH_CONFIG).map_err(Error::zenoh("the built-in Zenoh config"))?;
            config.insert_json5("listen/endpoints", &format!("[\"{ours}\"]")).map_err(Error::zenoh("listen"))?;
            config.insert_json5("connect/endpoints", "[]").map_err(Error::zenoh("connect to nothing"))?;
            for (key, value) in isolated {
                config.insert_json5(key, value).map_err(Error::zenoh(format!("zenoh config key {key}")))?;
            }
            let session = zenoh::open(config).await.map_err(Error::zenoh("join the bus"))?;
            let map = TopicMap::load_or_default(None)?.with_namespace(&namespace)?;
            let bus = Bus::from_session(session, map, "eval-detect").await?;
            let info = bus.publisher(topics::CAMERA_FRONT_INFO).await?;
            info.put(0, cameras.front.info())?;
            let frames = bus.frame_publisher(topics::CAMERA_FRONT).await?;
            let answers = bus.subscriber(topics::PERCEPTION_OBJECTS).await?;
            Ok::<_, Error>((bus, info, frames, answers))
        })?;
        let mut flags = vec!["-n".to_string(), namespace, "-l".into(), its, "-e".into(), ours];
        for (key, value) in isolated {
            flags.extend(["--cfg".into(), format!("{key}:{value}")]);
        }
        let cmd = node.command(&flags, logs, ["lockstep", "camera"])?;
        let (log, out) =
            (slipstream_launch::log_of(logs, node.process()), logs.join(format!("{}.out", node.process())));
        let node_process = Supervised::start(node.process(), cmd, node.run.clone(), log, out)?;
        let mut yours = Yours { rt, bus: Some(bus), _info: info, frames, answers, node: node_process, unanswered: 0 };
        yours.await_ready(node)?;
        Ok(yours)
    }

    /// Waits for the detector's token; names it with its last words when it exits first.
    fn await_ready(&mut self, node: &ForeignNode) -> Result<()> {
        let timeout = Duration::from_secs_f64(node.run.ready.timeout_s);
        let Some(bus) = &self.bus else { return Ok(()) };
        let seen = self.rt.block_on(bus.watch_nodes())?;
        let started = Instant::now();
        while !seen.names().iter().any(|n| n == node.node()) {
            self.alive("at start")?;
            if started.elapsed() > timeout {
                let problem = format!("declared no liveliness token nodes/{} within {timeout:?}", node.node());
                return Err(Error::node(node.process(), format!("{problem} (its log: {})", self.node.log.display())));
            }
            std::thread::sleep(NODE_POLL);
        }
        Ok(())
    }

    /// An error naming the detector and its last words once it has ended.
    fn alive(&mut self, when: &str) -> Result<()> {
        match self.node.poll() {
            State::Ended(status) => {
                let said = last_words(&self.node.log).map_or(String::new(), |w| format!(": {w}"));
                let problem = format!("exited {when} ({status}){said}\n(its log: {})", self.node.log.display());
                Err(Error::node(self.node.name(), problem))
            }
            _ => Ok(()),
        }
    }
}

impl FrameDetector for Yours {
    fn frame(&mut self, cameras: &Cameras, t_ns: u64) -> Result<Vec<Detection>> {
        let info = cameras.front.info();
        let Some(sent) = self.frames.put_rgb(t_ns, info.width, info.height, &cameras.front.rgb)? else {
            return Ok(Vec::new());
        };
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.answers.recv_blocking(left.min(Duration::from_millis(100))) {
                Some(Received { msg, .. }) if msg.frame_seq == sent.header.seq => return Ok(msg.detections),
                Some(_) => continue,
                None if left.is_zero() => {
                    self.unanswered += 1;
                    return Ok(Vec::new());
                }
                None => self.alive(&format!("at frame {}", sent.header.seq))?,
            }
        }
    }

    fn unanswered(&self) -> u64 {
        self.unanswered
    }
}

impl Drop for Yours {
    fn drop(&mut self) {
        self.node.stop(slipstream_launch::STOP_GRACE);
        if let Some(bus) = self.bus.take() {
            self.rt.block_on(bus.leave());
        }
    }
}
