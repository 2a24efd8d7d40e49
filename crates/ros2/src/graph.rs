//! How an rmw_zenoh node looks on Zenoh (ros2/rmw_zenoh docs/design.md): the data key of a
//! topic, the liveliness tokens that put a node and its endpoints in the ROS graph
//! (`ros2 node list`, `ros2 topic list -t`, `ros2 topic info -v`), their QoS in the token, and
//! the attachment every sample carries.
//!
//! ```text
//! data key   <domain>/<topic without leading slash>/<dds type>/<type hash>
//! node       @ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>
//! endpoint   @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<MP|MS>/<enclave>/<namespace>/<node>
//!                /<topic>/<dds type>/<type hash>/<qos>
//! ```
//!
//! In tokens every `/` inside a name becomes `%`, and an empty namespace or enclave is `%`.

use serde::{Deserialize, Serialize};
use zenoh::bytes::ZBytes;

use super::schema::{dds_name, Distro};
use crate::message_error::Ros2Error;

/// Reliability, durability and history depth of one endpoint: what ROS 2 matches publishers
/// and subscriptions on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RosQos {
    pub reliability: Reliability,
    pub durability: Durability,
    /// Keep-last depth.
    pub depth: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reliability {
    Reliable,
    BestEffort,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Durability {
    Volatile,
    TransientLocal,
}

/// As ROS 2 tools name the settings (`ros2 topic info -v`): "best effort, volatile, keep last 5".
impl std::fmt::Display for RosQos {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let reliability = match self.reliability {
            Reliability::Reliable => "reliable",
            Reliability::BestEffort => "best effort",
        };
        let durability = match self.durability {
            Durability::Volatile => "volatile",
            Durability::TransientLocal => "transient local",
        };
        write!(f, "{reliability}, {durability}, keep last {}", self.depth)
    }
}

/// rmw_zenoh's default profile: a token leaves out what equals it.
const DEFAULT_DEPTH: u32 = 42;

impl RosQos {
    /// ROS's "sensor data" profile: best effort, keep the last 5.
    pub(crate) const SENSOR: RosQos =
        RosQos { reliability: Reliability::BestEffort, durability: Durability::Volatile, depth: 5 };
    /// ROS's default: reliable, volatile, keep the last 10.
    pub(crate) const DEFAULT: RosQos =
        RosQos { reliability: Reliability::Reliable, durability: Durability::Volatile, depth: 10 };
    /// Latched: a late subscriber gets the last message (rviz2's camera info, /tf_static).
    pub(crate) const LATCHED: RosQos =
        RosQos { reliability: Reliability::Reliable, durability: Durability::TransientLocal, depth: 1 };

    /// The QoS part of a token, as rmw_zenoh writes it: reliability (1 reliable, 2 best
    /// effort), durability (1 transient local, 2 volatile), history `<kind>,<depth>`, then
    /// deadline, lifespan and liveliness (always the defaults here); each left empty where it
    /// equals rmw_zenoh's default (reliable, volatile, keep last 42, infinite, automatic).
    pub(crate) fn token_part(&self) -> String {
        let reliability = match self.reliability {
            Reliability::Reliable => "",
            Reliability::BestEffort => "2",
        };
        let durability = match self.durability {
            Durability::Volatile => "",
            Durability::TransientLocal => "1",
        };
        let depth = if self.depth == DEFAULT_DEPTH { String::new() } else { self.depth.to_string() };
        format!("{reliability}:{durability}:,{depth}:,:,:,,")
    }
}

/// Where a node sits in the ROS graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeId {
    pub domain: u32,
    /// The Zenoh session's id, as Zenoh prints it.
    pub zid: String,
    pub node_id: u32,
    pub namespace: String,
    pub name: String,
    pub distro: Distro,
}

/// A publisher or a subscription of a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndpointKind {
    Publisher,
    Subscription,
}

impl NodeId {
    /// The node's liveliness token.
    pub(crate) fn node_token(&self) -> String {
        let id = self.node_id;
        format!(
            "@ros2_lv/{}/{}/{id}/{id}/NN/%/{}/{}",
            self.domain,
            self.zid,
            mangle_ns(&self.namespace),
            mangle(&self.name)
        )
    }

    /// A topic name resolved against the node's namespace: `/clock` stays, `camera/image`
    /// becomes `/<namespace>/camera/image`.
    pub fn resolve(&self, topic: &str) -> String {
        if topic.starts_with('/') {
            return topic.to_string();
        }
        let ns = self.namespace.trim_end_matches('/');
        format!("{ns}/{topic}")
    }

    /// The data key of `topic` (already resolved) with `type_name`.
    pub fn data_key(&self, topic: &str, type_name: &str) -> Result<String, Ros2Error> {
        let topic = topic.trim_matches('/');
        Ok(format!("{}/{topic}/{}/{}", self.domain, dds_name(type_name)?, self.distro.hash_of(type_name)?))
    }

    /// The liveliness token of endpoint `entity_id` on `topic` (resolved).
    pub(crate) fn endpoint_token(
        &self,
        entity_id: u32,
        kind: EndpointKind,
        topic: &str,
        type_name: &str,
        qos: &RosQos,
    ) -> Result<String, Ros2Error> {
        let kind = match kind {
            EndpointKind::Publisher => "MP",
            EndpointKind::Subscription => "MS",
        };
        Ok(format!(
            "@ros2_lv/{}/{}/{}/{entity_id}/{kind}/%/{}/{}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.node_id,
            mangle_ns(&self.namespace),
            mangle(&self.name),
            mangle(topic),
            dds_name(type_name)?,
            self.distro.hash_of(type_name)?,
            qos.token_part()
        ))
    }
}

/// The endpoint a liveliness token declares, read back: its kind and its topic (resolved,
/// `/` restored), on `domain`; None for a node's token, another domain or no rmw_zenoh token.
pub fn endpoint_of(token: &str, domain: u32) -> Option<(EndpointKind, String)> {
    let parts: Vec<&str> = token.split('/').collect();
    if parts.len() < 10 || parts[0] != "@ros2_lv" || parts[1] != domain.to_string() {
        return None;
    }
    let kind = match parts[5] {
        "MP" => EndpointKind::Publisher,
        "MS" => EndpointKind::Subscription,
        _ => return None,
    };
    Some((kind, parts[9].replace('%', "/")))
}

fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

fn mangle_ns(namespace: &str) -> String {
    match namespace {
        "" | "/" => "%".to_string(),
        ns => mangle(ns),
    }
}

/// A publisher's global id: 16 bytes from its token, the same for the same token.
pub(crate) fn gid(token: &str) -> [u8; 16] {
    use sha2::Digest as _;
    let digest = sha2::Sha256::digest(token.as_bytes());
    let mut out = [0u8; 16];
    out.copy_from_slice(&digest[..16]);
    out
}

/// The attachment of every rmw_zenoh sample: sequence number, source timestamp (Unix ns) and
/// the publisher's gid, in Zenoh's own serialization (as rmw_zenoh and hiroz write it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp_ns: i64,
    pub source_gid: [u8; 16],
}

impl Attachment {
    pub(crate) fn to_zbytes(self) -> ZBytes {
        let mut ser = zenoh_ext::ZSerializer::new();
        ser.serialize(self.sequence_number);
        ser.serialize(self.source_timestamp_ns);
        ser.serialize(self.source_gid);
        ser.finish()
    }

    pub(crate) fn from_zbytes(bytes: &ZBytes) -> Result<Attachment, Ros2Error> {
        let mut de = zenoh_ext::ZDeserializer::new(bytes);
        let bad = |e: zenoh_ext::ZDeserializeError| Ros2Error::Attachment(format!("{e:?}"));
        let sequence_number = de.deserialize::<i64>().map_err(bad)?;
        let source_timestamp_ns = de.deserialize::<i64>().map_err(bad)?;
        let source_gid = de.deserialize::<[u8; 16]>().map_err(bad)?;
        if !de.done() {
            return Err(Ros2Error::Attachment("bytes after the gid".into()));
        }
        Ok(Attachment { sequence_number, source_timestamp_ns, source_gid })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(distro: Distro) -> NodeId {
        NodeId {
            domain: 7,
            zid: "abc123".into(),
            node_id: 0,
            namespace: "/car1".into(),
            name: "slipstream".into(),
            distro,
        }
    }

    #[test]
    fn keys_follow_the_rmw_zenoh_layout() {
        let n = node(Distro::Jazzy);
        let topic = n.resolve("camera/front/image_raw");
        assert_eq!(topic, "/car1/camera/front/image_raw");
        let key = n.data_key(&topic, "sensor_msgs/msg/Image").unwrap();
        assert!(key.starts_with("7/car1/camera/front/image_raw/sensor_msgs::msg::dds_::Image_/RIHS01_"), "{key}");
        assert_eq!(n.resolve("/clock"), "/clock");
        let humble = node(Distro::Humble).data_key("/clock", "rosgraph_msgs/msg/Clock").unwrap();
        assert_eq!(humble, "7/clock/rosgraph_msgs::msg::dds_::Clock_/TypeHashNotSupported");
    }

    #[test]
    fn an_endpoint_token_reads_back_as_its_kind_and_topic() {
        let n = node(Distro::Jazzy);
        let qos = RosQos::DEFAULT;
        let token = n.endpoint_token(7, EndpointKind::Subscription, "/vehicle/odometry", "nav_msgs/msg/Odometry", &qos);
        let read = endpoint_of(&token.unwrap(), n.domain);
        assert_eq!(read, Some((EndpointKind::Subscription, "/vehicle/odometry".to_string())));
        assert_eq!(endpoint_of(&n.node_token(), n.domain), None, "a node's token is no endpoint");
        let other =
            n.endpoint_token(7, EndpointKind::Publisher, "/cmd", "ackermann_msgs/msg/AckermannDriveStamped", &qos);
        assert_eq!(endpoint_of(&other.unwrap(), n.domain + 1), None, "another domain");
        assert_eq!(endpoint_of("slipstream/nodes/acc", 0), None);
    }

    #[test]
    fn tokens_mangle_names_and_carry_the_qos() {
        let n = node(Distro::Humble);
        assert_eq!(n.node_token(), "@ros2_lv/7/abc123/0/0/NN/%/%car1/slipstream");
        let t = n
            .endpoint_token(
                3,
                EndpointKind::Publisher,
                "/car1/camera/info",
                "sensor_msgs/msg/CameraInfo",
                &RosQos::LATCHED,
            )
            .unwrap();
        assert_eq!(
            t,
            "@ros2_lv/7/abc123/0/3/MP/%/%car1/slipstream/%car1%camera%info/sensor_msgs::msg::dds_::CameraInfo_/TypeHashNotSupported/:1:,1:,:,:,,"
        );
        assert_eq!(RosQos::SENSOR.token_part(), "2::,5:,:,:,,");
        let root = NodeId { namespace: "/".into(), ..node(Distro::Jazzy) };
        assert!(root.node_token().ends_with("/NN/%/%/slipstream"));
        assert_eq!(root.resolve("odom"), "/odom");
    }

    #[test]
    fn attachment_round_trips_and_refuses_others() {
        let a = Attachment { sequence_number: 5, source_timestamp_ns: 1_700_000_000_000_000_000, source_gid: gid("x") };
        assert_eq!(Attachment::from_zbytes(&a.to_zbytes()).unwrap(), a);
        assert!(Attachment::from_zbytes(&ZBytes::from("acc")).is_err());
        assert_ne!(gid("a"), gid("b"));
    }
}
