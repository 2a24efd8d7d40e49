//! Foxglove-viewable copies of the loop's messages, one recorded message at a time: what
//! `record --viewable` (and `up --record --viewable`) writes next to the byte-for-byte
//! channels, so that Foxglove's own panels show a recording: the camera with its boxes, the 3D
//! scene, the ACC's series. The same drawings as the live view ([`super::scene`]), for every
//! message instead of the latest.

use foxglove::{Encode, Schema};

use super::scene::{self, Image, SceneContext};
use slipstream_contract::msg::{
    self, AccStatus, CameraFrameRef, CameraInfo, Detections, GroundTruthObjects, MessageKind, SimEvent, SimEventKind,
    VehicleState,
};
use slipstream_contract::topics::Topic;
use slipstream_sim::Scenario;

/// The copies' topics: the live view's (docs/viewing.md), so one layout shows both.
use super::live::{
    TOPIC_ACC, TOPIC_ANNOTATIONS, TOPIC_CALIBRATION, TOPIC_CAMERA, TOPIC_ROAD, TOPIC_TF, TOPIC_VEHICLES,
};

/// The road is drawn again after this much simulated time (it follows the ego).
const ROAD_EVERY_NS: u64 = 1_000_000_000;

/// One viewable message: its topic, schema and encoding (the channel it goes on), its bytes
/// and its log time (the original's publish stamp).
#[derive(Debug, Clone)]
pub struct ViewableCopy {
    pub topic: &'static str,
    pub schema: Schema,
    pub message_encoding: String,
    pub data: Vec<u8>,
    pub log_time: u64,
}

fn copy<T: Encode>(topic: &'static str, msg: &T, log_time: u64) -> Option<ViewableCopy> {
    let mut data = Vec::with_capacity(msg.encoded_len().unwrap_or(256));
    msg.encode(&mut data).ok()?;
    Some(ViewableCopy { topic, schema: T::get_schema()?, message_encoding: T::get_message_encoding(), data, log_time })
}

/// What the copies remember between messages: boxes need the latest ground truth and the
/// ACC's lead, the scene the road.
#[derive(Default)]
pub struct Copies {
    info: Option<CameraInfo>,
    truth: Option<GroundTruthObjects>,
    status: Option<AccStatus>,
    context: SceneContext,
    road_drawn_ns: Option<u64>,
    /// Which topic a key is (the recording's namespace and remapping); without it every key
    /// is taken by its payload's kind.
    topics: Option<slipstream_contract::config::TopicMap>,
}

impl Copies {
    /// With the road and ego of a known scenario; otherwise they come from the scenario the
    /// simulator announces (a built-in one).
    pub fn new(scenario: Option<&Scenario>) -> Copies {
        Copies { context: SceneContext::of(scenario), ..Copies::default() }
    }

    /// Keys are told apart by `topics` (the bus's namespace and remapping): the narrow camera
    /// has no view, and its frames and calibration must not pass for the front camera's.
    pub fn with_topics(self, topics: slipstream_contract::config::TopicMap) -> Copies {
        Copies { topics: Some(topics), ..self }
    }

    /// Whether the sample on `key` has no view: the narrow camera's.
    fn unviewed(&self, key: &str) -> bool {
        let Some(topics) = &self.topics else { return false };
        let topic = zenoh::key_expr::keyexpr::new(key).ok().and_then(|k| topics.topic_of(k));
        matches!(topic, Some(Topic::CameraNarrow | Topic::CameraNarrowInfo))
    }

    /// The viewable copies of one payload received on `key` (none for what has no view, or a
    /// malformed payload).
    pub fn of(&mut self, key: &str, payload: &[u8]) -> Vec<ViewableCopy> {
        if self.unviewed(key) {
            return Vec::new();
        }
        let Ok(kind) = msg::peek_kind(payload) else { return Vec::new() };
        match kind {
            MessageKind::CameraFrame => self.frame(payload),
            MessageKind::Detections => self.detections(payload),
            MessageKind::VehicleState => self.state(payload),
            MessageKind::CameraInfo => {
                self.info = msg::decode::<CameraInfo>(payload).ok().map(|i| i.msg);
                Vec::new()
            }
            MessageKind::GroundTruthObjects => {
                self.truth = msg::decode::<GroundTruthObjects>(payload).ok().map(|t| t.msg);
                Vec::new()
            }
            MessageKind::AccStatus => {
                self.status = msg::decode::<AccStatus>(payload).ok().map(|s| s.msg);
                Vec::new()
            }
            MessageKind::SimEvent => {
                self.event(payload);
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// Takes what `payload` tells (ground truth, status, ...) without making its copies
    /// (the recorder is behind); returns how many copies it would have made.
    pub fn skip(&mut self, key: &str, payload: &[u8]) -> u64 {
        if self.unviewed(key) {
            return 0;
        }
        match msg::peek_kind(payload) {
            Ok(MessageKind::CameraFrame) => 1 + u64::from(self.info.is_some()),
            Ok(MessageKind::Detections) => 1,
            Ok(MessageKind::VehicleState) => 3,
            Ok(_) => self.of(key, payload).len() as u64,
            Err(_) => 0,
        }
    }

    fn frame(&mut self, payload: &[u8]) -> Vec<ViewableCopy> {
        let Ok(f) = msg::decode::<CameraFrameRef>(payload) else { return Vec::new() };
        let stamp = f.header.stamp_pub_ns;
        // One copy of the pixels, into the protobuf message.
        let pixels = foxglove::bytes::Bytes::copy_from_slice(f.msg.data);
        let Some(image) = scene::frame_image(stamp, f.msg.width, f.msg.height, f.msg.encoding, pixels) else {
            return Vec::new();
        };
        let mut out: Vec<ViewableCopy> = match &image {
            Image::Raw(i) => copy(TOPIC_CAMERA, i, stamp),
            Image::Compressed(i) => copy(TOPIC_CAMERA, i, stamp),
        }
        .into_iter()
        .collect();
        if let Some(info) = &self.info {
            out.extend(copy(TOPIC_CALIBRATION, &scene::calibration(stamp, info), stamp));
        }
        out
    }

    fn detections(&mut self, payload: &[u8]) -> Vec<ViewableCopy> {
        let Ok(d) = msg::decode::<Detections>(payload) else { return Vec::new() };
        let lead = self.status.as_ref().and_then(|s| s.lead.map(|l| l.id));
        let stamp = d.msg.frame_stamp_pub_ns;
        let a = scene::annotations(stamp, Some(&d.msg), self.truth.as_ref(), lead);
        copy(TOPIC_ANNOTATIONS, &a, d.header.stamp_pub_ns).into_iter().collect()
    }

    fn state(&mut self, payload: &[u8]) -> Vec<ViewableCopy> {
        let Ok(s) = msg::decode::<VehicleState>(payload) else { return Vec::new() };
        let (stamp, ego) = (s.header.stamp_pub_ns, &s.msg);
        let params = self.context.ego();
        let truth = self.truth.as_ref();
        let mut out = Vec::new();
        out.extend(copy(TOPIC_VEHICLES, &scene::vehicles(stamp, ego, &params, truth), stamp));
        out.extend(copy(TOPIC_TF, &scene::ego_frame(stamp, ego), stamp));
        let due = self.road_drawn_ns.is_none_or(|t| s.header.stamp_sim_ns >= t + ROAD_EVERY_NS);
        if let Some(lines) = due.then(|| self.context.road_around(ego)).flatten() {
            self.road_drawn_ns = Some(s.header.stamp_sim_ns);
            out.extend(copy(TOPIC_ROAD, &scene::road_update(stamp, &lines), stamp));
        }
        let series = scene::acc_series(ego, s.header.stamp_sim_ns, &params, self.status.as_ref(), truth);
        if let Ok(data) = serde_json::to_vec(&series) {
            out.push(ViewableCopy {
                topic: TOPIC_ACC,
                schema: scene::acc_series_schema(),
                message_encoding: "json".into(),
                data,
                log_time: stamp,
            });
        }
        out
    }

    fn event(&mut self, payload: &[u8]) {
        if let Ok(e) = msg::decode::<SimEvent>(payload) {
            if let SimEventKind::ScenarioStart { name, .. } = e.msg.kind {
                self.context.announced(&name);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::{CameraFrame, Header, ImageEncoding, Message};

    fn payload<M: Message>(stamp_sim_ns: u64, m: &M) -> Vec<u8> {
        msg::encode(&Header { seq: 1, stamp_sim_ns, stamp_pub_ns: 5_000_000_000 + stamp_sim_ns }, m)
    }

    #[test]
    fn each_kind_gets_its_copies_on_the_live_views_topics() {
        let mut c = Copies::new(Some(&Scenario::find("cut-in").unwrap()));
        let topics = |v: Vec<ViewableCopy>| v.iter().map(|c| c.topic).collect::<Vec<_>>();
        let frame = CameraFrame { width: 4, height: 2, encoding: ImageEncoding::Rgb8, data: (0..24).collect() };
        // No calibration before camera/front/info.
        assert_eq!(topics(c.of("camera/front", &payload(0, &frame))), [TOPIC_CAMERA]);
        assert!(c.of("camera/front/info", &payload(0, &slipstream_contract::msg::example_info())).is_empty());
        let copies = c.of("camera/front", &payload(50, &frame));
        assert_eq!(copies.iter().map(|c| c.topic).collect::<Vec<_>>(), [TOPIC_CAMERA, TOPIC_CALIBRATION]);
        assert_eq!(copies[0].schema.name, "foxglove.RawImage");
        assert_eq!((copies[0].message_encoding.as_str(), copies[0].log_time), ("protobuf", 5_000_000_050));
        assert!(copies[0].data.windows(24).any(|w| w == (0..24).collect::<Vec<u8>>()), "the pixels, whole");
        assert_eq!(topics(c.of("perception/objects", &payload(60, &msg::example_detections()))), [TOPIC_ANNOTATIONS]);
        // The road with the first state and again a simulated second later, not in between.
        let state = slipstream_contract::msg::example_state();
        assert_eq!(
            topics(c.of("vehicle/state", &payload(0, &state))),
            [TOPIC_VEHICLES, TOPIC_TF, TOPIC_ROAD, TOPIC_ACC]
        );
        assert_eq!(topics(c.of("vehicle/state", &payload(10_000_000, &state))), [TOPIC_VEHICLES, TOPIC_TF, TOPIC_ACC]);
        assert_eq!(
            topics(c.of("vehicle/state", &payload(1_000_000_000, &state))),
            [TOPIC_VEHICLES, TOPIC_TF, TOPIC_ROAD, TOPIC_ACC]
        );
        let acc = c.of("vehicle/state", &payload(1_010_000_000, &state)).pop().unwrap();
        assert_eq!((acc.message_encoding.as_str(), acc.schema.encoding.as_str()), ("json", "jsonschema"));
        assert_eq!(serde_json::from_slice::<serde_json::Value>(&acc.data).unwrap()["t_s"], 1.01);
        // Skipped while the recorder is behind: counted, and what it tells is still taken.
        assert_eq!(c.skip("camera/front", &payload(1_020_000_000, &frame)), 2);
        assert_eq!(c.skip("acc/status", &payload(0, &slipstream_contract::msg::example_status())), 0);
        // Nothing to draw, or not a payload at all.
        assert!(c.of("vehicle/speed", &payload(0, &msg::Speed { speed_mps: 1.0 })).is_empty());
        assert!(c.of("vehicle/speed", &[1, 2, 3]).is_empty());
    }

    /// The narrow camera's frames and calibration are not the front camera's: no copies, and
    /// the front calibration stays.
    #[test]
    fn the_narrow_camera_gets_no_copies_and_leaves_the_front_calibration() {
        let mut c = Copies::new(None).with_topics(slipstream_contract::config::TopicMap::default());
        let frame = CameraFrame { width: 4, height: 2, encoding: ImageEncoding::Rgb8, data: (0..24).collect() };
        c.of("camera/front/info", &payload(0, &slipstream_contract::msg::example_info()));
        let narrow = slipstream_contract::msg::CameraInfo { width: 2, ..slipstream_contract::msg::example_info() };
        assert!(c.of("camera/narrow/info", &payload(0, &narrow)).is_empty());
        assert!(c.of("camera/narrow", &payload(50, &frame)).is_empty());
        assert_eq!(c.skip("camera/narrow", &payload(50, &frame)), 0);
        assert_eq!(c.info.as_ref().map(|i| i.width), Some(640));
        assert_eq!(c.of("camera/front", &payload(50, &frame)).len(), 2);
    }

    #[test]
    fn without_a_scenario_the_announced_one_gives_the_road() {
        let mut c = Copies::new(None);
        let state = slipstream_contract::msg::example_state();
        assert!(!c.of("vehicle/state", &payload(0, &state)).iter().any(|c| c.topic == TOPIC_ROAD));
        let start = SimEvent { kind: SimEventKind::ScenarioStart { name: "cut-in".into(), seed: 1 } };
        c.of("sim/events", &payload(0, &start));
        assert!(c.of("vehicle/state", &payload(0, &state)).iter().any(|c| c.topic == TOPIC_ROAD));
    }
}
