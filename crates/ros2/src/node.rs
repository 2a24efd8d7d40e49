//! A ROS 2 node on a Zenoh session, as rmw_zenoh makes one: its liveliness token, and
//! publishers and subscriptions each with their token, their data key and (for publishers) the
//! attachment every sample carries. Transient-local publishers keep their last samples in a
//! Zenoh advanced publisher's cache, which is where rmw_zenoh's late subscribers ask.

use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, Ordering};
use std::sync::Arc;

use crate::error::{Error, Result};
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::Wait as _;

use super::graph::{gid, Attachment, Durability, EndpointKind, NodeId, Reliability, RosQos};
use super::mapping::Ros2Config;

/// A node and the ids it hands its endpoints.
pub(crate) struct RosNode {
    session: zenoh::Session,
    pub id: NodeId,
    next_entity: AtomicU32,
    _token: LivelinessToken,
}

impl RosNode {
    /// Declares the node on `session` (its `NN` token).
    pub(crate) async fn declare(session: &zenoh::Session, config: &Ros2Config) -> Result<RosNode> {
        let id = config.node_id(session.zid().to_string());
        let token = declare_token(session, &id.node_token()).await?;
        Ok(RosNode { session: session.clone(), id, next_entity: AtomicU32::new(1), _token: token })
    }

    pub(crate) fn session(&self) -> &zenoh::Session {
        &self.session
    }

    fn entity_id(&self) -> u32 {
        self.next_entity.fetch_add(1, Ordering::Relaxed)
    }

    /// An endpoint's resolved topic (relative names under the namespace), data key and token.
    fn endpoint(
        &self,
        kind: EndpointKind,
        topic: &str,
        type_name: &str,
        qos: &RosQos,
    ) -> Result<(String, String, String)> {
        let topic = self.id.resolve(topic);
        let key = self.id.data_key(&topic, type_name)?;
        let token = self.id.endpoint_token(self.entity_id(), kind, &topic, type_name, qos)?;
        Ok((topic, key, token))
    }

    /// A publisher of `type_name` on `topic` (relative names resolve under the namespace).
    pub(crate) async fn publisher(&self, topic: &str, type_name: &str, qos: RosQos) -> Result<RosPublisher> {
        let (topic, key, token_key) = self.endpoint(EndpointKind::Publisher, topic, type_name, &qos)?;
        let congestion = match qos.reliability {
            Reliability::Reliable => CongestionControl::Block,
            Reliability::BestEffort => CongestionControl::Drop,
        };
        let builder = self.session.declare_publisher(key.clone()).congestion_control(congestion);
        let inner = match qos.durability {
            Durability::Volatile => {
                Inner::Plain(builder.await.map_err(Error::zenoh(format!("declare a publisher on {key}")))?)
            }
            Durability::TransientLocal => {
                use zenoh_ext::AdvancedPublisherBuilderExt as _;
                let cache = zenoh_ext::CacheConfig::default().max_samples(qos.depth as usize);
                // Sequence numbers order the cache, so it works whatever the Zenoh config says
                // about timestamping.
                let cached = builder
                    .cache(cache)
                    .sample_miss_detection(zenoh_ext::MissDetectionConfig::default())
                    .publisher_detection()
                    .await
                    .map_err(Error::zenoh(format!("declare a cached publisher on {key}")))?;
                Inner::Cached(cached)
            }
        };
        let watched = match &inner {
            Inner::Plain(p) => Some(Watched::declare(p).await?),
            // A late subscriber reads the cache: it is filled whether anyone listens or not.
            Inner::Cached(_) => None,
        };
        let token = declare_token(&self.session, &token_key).await?;
        Ok(RosPublisher {
            inner,
            topic,
            key,
            type_name: type_name.to_string(),
            watched,
            gid: gid(&token_key),
            seq: AtomicI64::new(1),
            _token: token,
        })
    }

    /// The token and key of a subscription of `type_name` on `topic`; the caller subscribes
    /// to the key (with the handler it needs) and keeps the token as long.
    pub(crate) async fn subscription(
        &self,
        topic: &str,
        type_name: &str,
        qos: RosQos,
    ) -> Result<(String, LivelinessToken)> {
        let (_, key, token_key) = self.endpoint(EndpointKind::Subscription, topic, type_name, &qos)?;
        Ok((key, declare_token(&self.session, &token_key).await?))
    }
}

async fn declare_token(session: &zenoh::Session, key: &str) -> Result<LivelinessToken> {
    session
        .liveliness()
        .declare_token(key.to_string())
        .await
        .map_err(Error::zenoh(format!("declare the ROS 2 liveliness token {key}")))
}

enum Inner {
    Plain(zenoh::pubsub::Publisher<'static>),
    Cached(zenoh_ext::AdvancedPublisher<'static>),
}

/// One ROS 2 publisher: CDR payloads with rmw_zenoh's attachment.
pub(crate) struct RosPublisher {
    /// Whether a subscriber matches (None: always send). Declared before `inner` so that it
    /// drops first: a publisher's undeclaration also removes its matching listeners, and a
    /// listener dropped after that logs an error from Zenoh.
    watched: Option<Watched>,
    inner: Inner,
    /// The resolved ROS name (`/camera/front/image_raw`).
    pub topic: String,
    /// The Zenoh key it puts on.
    pub key: String,
    /// The ROS type (`sensor_msgs/msg/Image`).
    pub type_name: String,
    gid: [u8; 16],
    seq: AtomicI64,
    _token: LivelinessToken,
}

/// Whether a volatile publisher has a matching subscriber now, kept by Zenoh's matching
/// listener: with nobody listening, a route is not even converted (a frame's copy saved).
struct Watched {
    matching: Arc<AtomicBool>,
    _listener: zenoh::matching::MatchingListener<()>,
}

impl Watched {
    async fn declare(p: &zenoh::pubsub::Publisher<'static>) -> Result<Watched> {
        let now = p.matching_status().await.map_err(Error::zenoh("ask a publisher whether it matches"))?.matching();
        let matching = Arc::new(AtomicBool::new(now));
        let m = matching.clone();
        let listener = p
            .matching_listener()
            .callback(move |s: zenoh::matching::MatchingStatus| m.store(s.matching(), Ordering::Relaxed))
            .await
            .map_err(Error::zenoh("watch a publisher's matching"))?;
        Ok(Watched { matching, _listener: listener })
    }
}

impl RosPublisher {
    /// Whether a message sent now reaches anyone (or is kept for late subscribers).
    pub(crate) fn wanted(&self) -> bool {
        self.watched.as_ref().is_none_or(|w| w.matching.load(Ordering::Relaxed))
    }

    /// Sends one CDR payload (with its encapsulation header).
    pub(crate) fn put(&self, cdr: Vec<u8>) -> Result<()> {
        let attachment = Attachment {
            sequence_number: self.seq.fetch_add(1, Ordering::Relaxed),
            source_timestamp_ns: slipstream_contract::msg::wall_clock_ns() as i64,
            source_gid: self.gid,
        }
        .to_zbytes();
        let sent = match &self.inner {
            Inner::Plain(p) => p.put(cdr).attachment(attachment).wait(),
            Inner::Cached(p) => p.put(cdr).attachment(attachment).wait(),
        };
        sent.map_err(Error::zenoh(format!("put on {}", self.key)))
    }
}
