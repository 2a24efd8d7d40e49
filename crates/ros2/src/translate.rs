//! One place that turns a bus payload into a route's ROS 2 message in CDR: the live bridge,
//! `record --profile ros2` and `slipstream convert` all call [`Translator::encode`], so a
//! recording holds exactly what ROS 2 subscribers get.

use std::collections::BTreeMap;

use parking_lot::Mutex;
use serde::Serialize;

use super::convert::{self, Frames, RosImage};
use super::mapping::Route;
use super::messages::{to_cdr, TfMessage, TransformStamped};
use crate::message_error::Ros2Error;
use slipstream_contract::msg::{
    self, AccStatus, CameraFrameRef, CameraInfo, Detections, GroundTruthObjects, Header, SimClock, VehicleState,
};
use slipstream_contract::topics::Topic;

impl Route {
    /// The bus topics a route's messages come from (the command route's go to its one):
    /// /tf_static gathers both cameras' mounts.
    pub fn sources(self) -> &'static [Topic] {
        match self {
            Route::TfStatic => &[Topic::CameraFrontInfo, Topic::CameraNarrowInfo],
            Route::CameraFront => &[Topic::CameraFront],
            Route::CameraFrontInfo => &[Topic::CameraFrontInfo],
            Route::CameraNarrow => &[Topic::CameraNarrow],
            Route::CameraNarrowInfo => &[Topic::CameraNarrowInfo],
            Route::Odometry | Route::Tf => &[Topic::VehicleState],
            Route::Objects => &[Topic::Objects],
            Route::Detections => &[Topic::PerceptionObjects],
            Route::Clock => &[Topic::SimClock],
            Route::AccStatus => &[Topic::AccStatus],
            Route::Command => &[Topic::VehicleControl],
        }
    }
}

/// Payloads in, CDR out, for one vehicle's frames.
pub struct Translator {
    frames: Frames,
    /// Camera routes whose configured type is CompressedImage (the others carry Image).
    compressed: Vec<Route>,
    /// Each camera's mount transforms, all sent together on /tf_static (a latched topic keeps
    /// only the last message).
    mounts: Mutex<BTreeMap<&'static str, Vec<TransformStamped>>>,
}

fn cdr<T: Serialize>(header: Header, msg: &T, hint: usize) -> Result<Option<(Header, Vec<u8>)>, Ros2Error> {
    Ok(Some((header, to_cdr(msg, hint)?)))
}

fn decoded<'a, M: msg::Message + serde::Deserialize<'a>>(payload: &'a [u8]) -> Result<msg::Stamped<M>, Ros2Error> {
    Ok(msg::decode::<M>(payload)?)
}

impl Translator {
    /// For the vehicle in bus namespace `ns` (its frames are prefixed with it).
    pub fn new(ns: &str) -> Translator {
        Translator { frames: Frames::new(ns), compressed: Vec::new(), mounts: Mutex::default() }
    }

    /// The routes' configured types (route, type name): a camera route refuses frames whose
    /// encoding its type cannot carry.
    pub fn with_types<'a>(mut self, types: impl IntoIterator<Item = (Route, &'a str)>) -> Translator {
        self.compressed =
            types.into_iter().filter(|(_, t)| *t == "sensor_msgs/msg/CompressedImage").map(|(r, _)| r).collect();
        self
    }

    /// `route`'s message from `payload`, a message of `topic` (one of the route's sources),
    /// with the payload's header; None when the route sends nothing for it.
    pub fn encode(&self, route: Route, topic: Topic, payload: &[u8]) -> Result<Option<(Header, Vec<u8>)>, Ros2Error> {
        let f = &self.frames;
        match route {
            Route::CameraFront | Route::CameraNarrow => {
                let s = decoded::<CameraFrameRef>(payload)?;
                let optical = f.camera(camera_of(topic)).1;
                // LZ4 is no ROS format: such frames go out as raw Images.
                let pixels;
                let frame = match s.msg.encoding {
                    slipstream_contract::msg::ImageEncoding::Lz4 => {
                        pixels = s.msg.to_rgb8()?;
                        CameraFrameRef {
                            encoding: slipstream_contract::msg::ImageEncoding::Rgb8,
                            data: &pixels,
                            ..s.msg
                        }
                    }
                    _ => s.msg,
                };
                let hint = frame.data.len() + 128;
                match (convert::image(s.header.stamp_sim_ns, optical, &frame), self.compressed.contains(&route)) {
                    (RosImage::Raw(img), false) => cdr(s.header, &img, hint),
                    (RosImage::Compressed(img), true) => cdr(s.header, &img, hint),
                    (_, compressed) => Err(Ros2Error::FrameType {
                        topic: topic.to_string(),
                        encoding: s.msg.encoding,
                        route: route.id(),
                        configured: if compressed { "CompressedImage" } else { "Image" },
                        fix: if compressed { "sensor_msgs/msg/Image" } else { "sensor_msgs/msg/CompressedImage" },
                    }),
                }
            }
            Route::CameraFrontInfo | Route::CameraNarrowInfo => {
                let s = decoded::<CameraInfo>(payload)?;
                cdr(s.header, &convert::camera_info(s.header.stamp_sim_ns, f.camera(camera_of(topic)).1, &s.msg), 512)
            }
            Route::TfStatic => {
                let s = decoded::<CameraInfo>(payload)?;
                let all = {
                    let mut m = self.mounts.lock();
                    m.insert(camera_of(topic), convert::mount_transforms(f, camera_of(topic), &s.msg));
                    TfMessage { transforms: m.values().flatten().cloned().collect() }
                };
                cdr(s.header, &all, 512)
            }
            Route::Odometry => {
                let s = decoded::<VehicleState>(payload)?;
                cdr(s.header, &convert::odometry(s.header.stamp_sim_ns, f, &s.msg), 800)
            }
            Route::Tf => {
                let s = decoded::<VehicleState>(payload)?;
                cdr(
                    s.header,
                    &TfMessage { transforms: vec![convert::ego_transform(s.header.stamp_sim_ns, f, &s.msg)] },
                    128,
                )
            }
            _ => self.encode_signal(route, payload),
        }
    }

    fn encode_signal(&self, route: Route, payload: &[u8]) -> Result<Option<(Header, Vec<u8>)>, Ros2Error> {
        let f = &self.frames;
        match route {
            Route::Objects => {
                let s = decoded::<GroundTruthObjects>(payload)?;
                cdr(s.header, &convert::ground_truth_markers(s.header.stamp_sim_ns, f, &s.msg), 1024)
            }
            Route::Detections => {
                let s = decoded::<Detections>(payload)?;
                cdr(s.header, &convert::detection_markers(s.header.stamp_sim_ns, f, &s.msg), 1024)
            }
            Route::Clock => {
                let s = decoded::<SimClock>(payload)?;
                cdr(s.header, &convert::clock(s.header.stamp_sim_ns), 16)
            }
            Route::AccStatus => {
                let s = decoded::<AccStatus>(payload)?;
                cdr(s.header, &convert::acc_status(&s.msg), 256)
            }
            _ => Ok(None),
        }
    }
}

fn camera_of(topic: Topic) -> &'static str {
    match topic {
        Topic::CameraNarrow | Topic::CameraNarrowInfo => "narrow",
        _ => "front",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_route_reads_what_its_sources_say_and_refuses_other_payloads() {
        let t = Translator::new("");
        let state = msg::encode(&Header::default(), &msg::example_state());
        let (_, odo) = t.encode(Route::Odometry, Topic::VehicleState, &state).unwrap().unwrap();
        assert_eq!(&odo[..4], &super::super::messages::CDR_LE);
        let err = t.encode(Route::Clock, Topic::SimClock, &state).unwrap_err();
        let err = err.to_string();
        assert!(err.contains("SimClock"), "{err}");
    }

    #[test]
    fn frames_go_out_as_published_or_are_refused_with_the_fix() {
        let jpeg =
            msg::CameraFrameRef { width: 4, height: 2, encoding: msg::ImageEncoding::Jpeg, data: &[0xff, 0xd8, 1, 2] };
        let payload = msg::encode(&Header::default(), &jpeg);
        let plain = Translator::new("");
        let err = plain.encode(Route::CameraFront, Topic::CameraFront, &payload).unwrap_err().to_string();
        assert!(err.contains("ros2.topics.camera_front.type") && err.contains("CompressedImage"), "{err}");
        let typed = Translator::new("").with_types([(Route::CameraFront, "sensor_msgs/msg/CompressedImage")]);
        let (_, cdr) = typed.encode(Route::CameraFront, Topic::CameraFront, &payload).unwrap().unwrap();
        // header (stamp 8, frame id length 4 + 21 bytes "camera_front_optical\0"), then "jpeg".
        assert!(cdr.windows(5).any(|w| w == b"jpeg\0"));
        assert!(cdr.ends_with(&[0xff, 0xd8, 1, 2]));
    }

    #[test]
    fn tf_static_carries_every_camera_seen() {
        let t = Translator::new("car1");
        let info = msg::encode(&Header::default(), &msg::example_info());
        t.encode(Route::TfStatic, Topic::CameraFrontInfo, &info).unwrap();
        let (_, both) = t.encode(Route::TfStatic, Topic::CameraNarrowInfo, &info).unwrap().unwrap();
        let (_, one) =
            Translator::new("car1").encode(Route::TfStatic, Topic::CameraNarrowInfo, &info).unwrap().unwrap();
        assert!(both.len() > one.len() + 100, "{} vs {}", both.len(), one.len());
    }
}
