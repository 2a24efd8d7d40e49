//! Where the bridge's ROS 2 messages go: the ROS graph (a node's publishers on rmw_zenoh's
//! keys, [`RosOutlet`]) or a `ros2`-profile MCAP file ([`super::bag::Bag`]). The bridge does
//! not know which.

use std::collections::BTreeMap;

use crate::error::Result;

use super::mapping::{Direction, Ros2Config, Route};
use super::node::{RosNode, RosPublisher};
use slipstream_contract::msg::Header;

/// A destination for converted messages.
pub trait Outlet: Send + Sync {
    /// Sends `cdr` (with its encapsulation header), the message of `route` made from a bus
    /// message with `header`.
    fn put(&self, route: Route, header: &Header, cdr: Vec<u8>) -> Result<()>;
    /// The routes it takes, with the ROS name and type each goes to.
    fn routes(&self) -> Vec<(Route, String, String)>;
    /// Whether a message of `route` would reach anyone now; when not, the bridge does not
    /// convert it.
    fn wanted(&self, _route: Route) -> bool {
        true
    }
}

/// The ROS graph: one publisher per route that is on.
pub(crate) struct RosOutlet {
    publishers: BTreeMap<Route, RosPublisher>,
}

impl RosOutlet {
    pub(crate) async fn declare(node: &RosNode, config: &Ros2Config) -> Result<RosOutlet> {
        let mut publishers = BTreeMap::new();
        for (route, entry) in config.enabled().filter(|(r, _)| r.direction() == Direction::ToRos) {
            let p = node.publisher(&entry.name, &entry.type_name, entry.qos).await?;
            tracing::info!(route = route.id(), topic = %p.topic, key = %p.key, "ROS 2 publisher");
            publishers.insert(route, p);
        }
        Ok(RosOutlet { publishers })
    }
}

impl Outlet for RosOutlet {
    fn put(&self, route: Route, _header: &Header, cdr: Vec<u8>) -> Result<()> {
        match self.publishers.get(&route) {
            Some(p) => p.put(cdr),
            None => Ok(()),
        }
    }

    fn routes(&self) -> Vec<(Route, String, String)> {
        self.publishers.iter().map(|(r, p)| (*r, p.topic.clone(), p.type_name.clone())).collect()
    }

    fn wanted(&self, route: Route) -> bool {
        self.publishers.get(&route).is_some_and(RosPublisher::wanted)
    }
}
