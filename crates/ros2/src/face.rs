//! The loop's ROS 2 face: a ROS node on the bus's session with a publisher per route (the
//! [`Bridge`] feeding a [`RosOutlet`]) and, when the command route is on, a ROS controller's
//! commands into vehicle/control. What `slipstream ros2` and `up --ros2` run.

use std::sync::Arc;

use crate::error::Result;
use serde::Serialize;

use super::bridge::{Bridge, RouteStats};
use super::command::CommandStats;
use super::graph::NodeId;
use super::inbound::CommandPath;
use super::mapping::{Ros2Config, Route};
use super::node::RosNode;
use super::outlet::RosOutlet;
use slipstream_contract::bus::Bus;
use slipstream_model::vehicle::VehicleParams;

/// What the face did so far.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FaceStats {
    pub routes: Vec<RouteStats>,
    /// With the command route on.
    pub commands: Option<CommandStats>,
}

/// A running ROS 2 face; [`RosFace::stop`] ends it.
pub struct RosFace {
    node: Arc<RosNode>,
    bridge: Bridge,
    commands: Option<CommandPath>,
}

impl RosFace {
    /// Declares the ROS node and its endpoints on `bus`'s session and starts republishing.
    /// `vehicle` is the ego's model, for turning ROS commands into throttle and brake; with
    /// `lockstep` a command answers the state its stamp names ([`super::lockstep`]).
    pub async fn start(bus: &Bus, config: &Ros2Config, vehicle: VehicleParams, lockstep: bool) -> Result<RosFace> {
        let node = Arc::new(RosNode::declare(bus.session(), config).await?);
        let outlet = Arc::new(RosOutlet::declare(&node, config).await?);
        let bridge = Bridge::start(bus, outlet).await?;
        let commands = match config.routes.get(&Route::Command).filter(|e| e.enabled) {
            Some(entry) => Some(CommandPath::start(bus, &node, entry, vehicle, lockstep).await?),
            None => None,
        };
        Ok(RosFace { node, bridge, commands })
    }

    /// The node's place in the ROS graph (namespace, name, domain, key format).
    pub fn node(&self) -> &NodeId {
        &self.node.id
    }

    pub fn stats(&self) -> FaceStats {
        FaceStats { routes: self.bridge.stats(), commands: self.commands.as_ref().map(CommandPath::stats) }
    }

    /// Stops the commands and the bridge (sending what is queued); the node's tokens go with it.
    pub async fn stop(mut self) -> FaceStats {
        let commands = self.commands.take().map(|c| c.stats());
        FaceStats { routes: self.bridge.stop().await, commands }
    }
}
