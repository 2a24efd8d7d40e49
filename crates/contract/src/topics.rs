//! Logical topics: the one place that knows their default keys, message types and QoS.
//!
//! A node never writes a key string. It names a typed topic ([`VEHICLE_SPEED`], ...) and the
//! [`crate::config::TopicMap`] turns it into the key in force after namespace and remapping.

use std::marker::PhantomData;

use crate::msg::{self, Message, MessageKind};
use crate::qos::{Delivery, Priority, SessionKind, TopicQos};

/// Every topic the system knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    VehicleSpeed,
    VehicleState,
    VehicleControl,
    CameraFront,
    CameraFrontInfo,
    Objects,
    PerceptionObjects,
    SimClock,
    SimEvents,
    AccStatus,
    AccCommand,
    SimRoad,
    CameraNarrow,
    CameraNarrowInfo,
    SimEgo,
}

impl Topic {
    pub const ALL: [Topic; 15] = [
        Topic::VehicleSpeed,
        Topic::VehicleState,
        Topic::VehicleControl,
        Topic::CameraFront,
        Topic::CameraFrontInfo,
        Topic::Objects,
        Topic::PerceptionObjects,
        Topic::SimClock,
        Topic::SimEvents,
        Topic::AccStatus,
        Topic::AccCommand,
        Topic::SimRoad,
        Topic::CameraNarrow,
        Topic::CameraNarrowInfo,
        Topic::SimEgo,
    ];

    /// The logical name, which is also the default key (before the namespace).
    pub fn name(self) -> &'static str {
        match self {
            Topic::VehicleSpeed => "vehicle/speed",
            Topic::VehicleState => "vehicle/state",
            Topic::VehicleControl => "vehicle/control",
            Topic::CameraFront => "camera/front",
            Topic::CameraFrontInfo => "camera/front/info",
            Topic::Objects => "objects",
            Topic::PerceptionObjects => "perception/objects",
            Topic::SimClock => "sim/clock",
            Topic::SimEvents => "sim/events",
            Topic::AccStatus => "acc/status",
            Topic::AccCommand => "acc/command",
            Topic::SimRoad => "sim/road",
            Topic::CameraNarrow => "camera/narrow",
            Topic::CameraNarrowInfo => "camera/narrow/info",
            Topic::SimEgo => "sim/ego",
        }
    }

    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The topic `name` most likely meant when it is none: a typo (at most two letters off,
    /// `vehicle/sped`) or a topic's last part alone (`speed`). For the suggestion in an error.
    pub fn nearest(name: &str) -> Option<Topic> {
        if Topic::from_name(name).is_some() {
            return None;
        }
        let by_suffix = Topic::ALL.into_iter().filter(|t| t.name().rsplit('/').next() == Some(name));
        let by_suffix: Vec<Topic> = by_suffix.collect();
        if let [one] = by_suffix[..] {
            return Some(one);
        }
        let typo = crate::config::closest(name, Topic::ALL.into_iter().map(Topic::name))?;
        Topic::from_name(typo)
    }

    /// The message type this topic carries.
    pub fn kind(self) -> MessageKind {
        match self {
            Topic::VehicleSpeed => MessageKind::Speed,
            Topic::VehicleState => MessageKind::VehicleState,
            Topic::VehicleControl => MessageKind::ControlCommand,
            Topic::CameraFront | Topic::CameraNarrow => MessageKind::CameraFrame,
            Topic::CameraFrontInfo | Topic::CameraNarrowInfo => MessageKind::CameraInfo,
            Topic::Objects => MessageKind::GroundTruthObjects,
            Topic::PerceptionObjects => MessageKind::Detections,
            Topic::SimClock => MessageKind::SimClock,
            Topic::SimEvents => MessageKind::SimEvent,
            Topic::AccStatus => MessageKind::AccStatus,
            Topic::AccCommand => MessageKind::AccCommand,
            Topic::SimRoad => MessageKind::RoadMap,
            Topic::SimEgo => MessageKind::EgoInfo,
        }
    }

    /// QoS when the config says nothing: control-loop signals at real-time priority and
    /// express (sent at once, never batched behind images), camera frames low priority and
    /// dropped under congestion, read latest-only; events and calibration never dropped and
    /// queued; calibration latched so a late subscriber still gets it.
    /// The loop's small real-time messages (speed, state, control, clock, detections, the
    /// ACC's status) ride the low-latency session; the rest the session with priorities.
    pub fn default_qos(self) -> TopicQos {
        let base = TopicQos::default();
        let low_latency = SessionKind::LowLatency;
        match self {
            Topic::VehicleSpeed | Topic::VehicleControl | Topic::SimClock => {
                TopicQos { priority: Priority::RealTime, express: true, session: low_latency, ..base }
            }
            Topic::VehicleState | Topic::PerceptionObjects => {
                TopicQos { priority: Priority::InteractiveHigh, express: true, session: low_latency, ..base }
            }
            Topic::CameraFront | Topic::CameraNarrow => TopicQos {
                priority: Priority::DataLow,
                congestion_control: crate::qos::Congestion::Drop,
                delivery: Delivery::Latest,
                ..base
            },
            Topic::CameraFrontInfo | Topic::CameraNarrowInfo | Topic::SimRoad | Topic::SimEgo => TopicQos {
                congestion_control: crate::qos::Congestion::Block,
                delivery: Delivery::Queue(64),
                latched: true,
                ..base
            },
            Topic::SimEvents | Topic::AccCommand => {
                TopicQos { congestion_control: crate::qos::Congestion::Block, delivery: Delivery::Queue(64), ..base }
            }
            // Ground truth is what a ground-truth controller waits for in lockstep: sent at
            // once, not batched.
            Topic::Objects => TopicQos { express: true, ..base },
            Topic::AccStatus => TopicQos { session: low_latency, ..base },
        }
    }
}

impl std::fmt::Display for Topic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A topic bound to its message type at compile time, so a publisher of `Speed` cannot be
/// declared on the camera topic.
pub struct TopicDef<M> {
    pub topic: Topic,
    _msg: PhantomData<fn() -> M>,
}

impl<M> Clone for TopicDef<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for TopicDef<M> {}

impl<M: Message> TopicDef<M> {
    const fn new(topic: Topic) -> Self {
        TopicDef { topic, _msg: PhantomData }
    }
}

pub const VEHICLE_SPEED: TopicDef<msg::Speed> = TopicDef::new(Topic::VehicleSpeed);
pub const VEHICLE_STATE: TopicDef<msg::VehicleState> = TopicDef::new(Topic::VehicleState);
pub const VEHICLE_CONTROL: TopicDef<msg::ControlCommand> = TopicDef::new(Topic::VehicleControl);
pub const CAMERA_FRONT: TopicDef<msg::CameraFrame> = TopicDef::new(Topic::CameraFront);
pub const CAMERA_FRONT_INFO: TopicDef<msg::CameraInfo> = TopicDef::new(Topic::CameraFrontInfo);
pub const CAMERA_NARROW: TopicDef<msg::CameraFrame> = TopicDef::new(Topic::CameraNarrow);
pub const CAMERA_NARROW_INFO: TopicDef<msg::CameraInfo> = TopicDef::new(Topic::CameraNarrowInfo);
pub const OBJECTS: TopicDef<msg::GroundTruthObjects> = TopicDef::new(Topic::Objects);
pub const PERCEPTION_OBJECTS: TopicDef<msg::Detections> = TopicDef::new(Topic::PerceptionObjects);
pub const SIM_CLOCK: TopicDef<msg::SimClock> = TopicDef::new(Topic::SimClock);
pub const SIM_EVENTS: TopicDef<msg::SimEvent> = TopicDef::new(Topic::SimEvents);
pub const ACC_STATUS: TopicDef<msg::AccStatus> = TopicDef::new(Topic::AccStatus);
pub const ACC_COMMAND: TopicDef<msg::AccCommand> = TopicDef::new(Topic::AccCommand);
pub const SIM_ROAD: TopicDef<msg::RoadSpec> = TopicDef::new(Topic::SimRoad);
pub const SIM_EGO: TopicDef<msg::EgoInfo> = TopicDef::new(Topic::SimEgo);

/// The key prefix (under the namespace) where nodes declare liveliness tokens:
/// `<namespace>/nodes/<node name>`.
pub const NODES_PREFIX: &str = "nodes";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_unique() {
        for t in Topic::ALL {
            assert_eq!(Topic::from_name(t.name()), Some(t));
        }
        let mut names: Vec<_> = Topic::ALL.iter().map(|t| t.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), Topic::ALL.len());
    }

    #[test]
    fn typed_constants_carry_the_right_kind() {
        assert_eq!(VEHICLE_SPEED.topic.kind(), <msg::Speed as Message>::KIND);
        assert_eq!(CAMERA_FRONT.topic.kind(), <msg::CameraFrame as Message>::KIND);
        assert_eq!(ACC_COMMAND.topic.kind(), <msg::AccCommand as Message>::KIND);
    }

    #[test]
    fn a_typo_or_a_last_part_suggests_the_topic_and_a_stranger_nothing() {
        assert_eq!(Topic::nearest("vehicle/sped"), Some(Topic::VehicleSpeed));
        assert_eq!(Topic::nearest("perception/object"), Some(Topic::PerceptionObjects));
        assert_eq!(Topic::nearest("clock"), Some(Topic::SimClock));
        assert_eq!(Topic::nearest("vehicle/speed"), None);
        assert_eq!(Topic::nearest("rt/chatter"), None);
    }
}
