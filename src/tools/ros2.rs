//! `slipstream ros2`: the loop as ROS 2 sees it. A ROS 2 node (rmw_zenoh's keys and graph
//! tokens) that joins the bus with the usual connection flags and namespace and republishes
//! the loop's topics as standard ROS 2 messages until Ctrl-C or --duration; with --control, a
//! ROS 2 controller's Ackermann commands drive the ego. `up --ros2` runs the same bridge
//! inside `up`. docs/ros2.md has the mapping and the steps on the ROS side.

use std::time::Duration;

use anyhow::Result;
use serde::Serialize;

use crate::acc::VehicleClass;
use crate::bus::Bus;
use crate::config::{ConfigError, TopicMap};
use crate::ros2::graph::{endpoint_of, EndpointKind};
use crate::ros2::mapping::{Direction, Ros2Config, Route};
use crate::ros2::{schema, Distro, FaceStats, RosFace};
use slipstream_contract::node::ClockArg;

/// How often the status line is refreshed.
const STATUS_EVERY: Duration = Duration::from_secs(2);

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "On the ROS 2 side (rmw_zenoh, through the same router or on this machine):\n  \
    export RMW_IMPLEMENTATION=rmw_zenoh_cpp\n  ros2 topic list -t\n  ros2 topic echo /clock\n  \
    rviz2   (Image: /camera/front/image_raw; MarkerArray: /objects/markers; fixed frame: world)\n\n\
    Examples:\n  slipstream up --ros2                       (the loop and its ROS 2 face in one command)\n  \
    slipstream ros2                            (a loop already running)\n  \
    slipstream ros2 --list                     (the mapping: ROS names, types, QoS, keys)\n  \
    slipstream ros2 --control                  (a ROS 2 controller drives the ego; docs/ros2.md)")]
pub struct Ros2Args {
    /// The ROS domain [default: the config's ros2.domain_id, else $ROS_DOMAIN_ID, else 0]
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=232))]
    pub domain_id: Option<u32>,
    /// Key format: jazzy (and later: type hashes in keys) or humble (no type hashes)
    /// [default: the config's ros2.distro, else jazzy]
    #[arg(long, value_enum)]
    pub distro: Option<DistroArg>,
    /// Turn the command route on: ackermann_msgs/msg/AckermannDriveStamped from ROS 2 becomes
    /// vehicle/control (run the loop without slipstream-acc, or the two fight over the ego)
    #[arg(long)]
    pub control: bool,
    /// The ego's vehicle model, for turning commanded speeds into throttle and brake
    #[arg(long, value_enum, default_value = "car")]
    pub vehicle: VehicleClass,
    /// Print the mapping (route, ROS name, type, QoS, Zenoh key) and exit
    #[arg(long)]
    pub list: bool,
    /// With --list: every message type's DDS name, RIHS01 hash and ros2msg definition instead
    #[arg(long, requires = "list")]
    pub types: bool,
    /// JSON instead of text (the mapping, or the final counts)
    #[arg(long)]
    pub json: bool,
    /// Stop after this many seconds [default: until Ctrl-C]
    #[arg(long, value_parser = super::top::positive)]
    pub duration: Option<f64>,
    /// The name on the bus (liveliness token, vehicle/control's attachment): a loop runs the
    /// bridge of a ROS 2 controller as `acc` [env: SLIPSTREAM_NODE; default: ros2-<pid>]
    #[arg(long, env = "SLIPSTREAM_NODE", hide_env = true)]
    pub name: Option<String>,
    /// The simulator's clock, for --control: in lockstep each ROS command answers the step
    /// whose odometry stamp it carries, and the bridge joins the loop (its token) only once a
    /// ROS 2 node publishes the commands and subscribes to the odometry [env: SLIPSTREAM_CLOCK]
    #[arg(long, value_enum, env = "SLIPSTREAM_CLOCK", hide_env = true, default_value = "realtime")]
    pub clock: ClockArg,
    /// The ROS node's namespace, `/` or `/name` [default: the config's ros2.namespace, else the
    /// bus's namespace (-n) as `/name`]
    #[arg(long, value_name = "NS")]
    pub ros_namespace: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DistroArg {
    Humble,
    Jazzy,
}

/// The mapping in force: the topic config's `ros2` block with the flags laid over it.
pub fn config(topics: &TopicMap, args: &Ros2Args) -> Result<Ros2Config, ConfigError> {
    let mut c = Ros2Config::from_topic_map(topics)?;
    if let Some(d) = args.domain_id {
        c.domain_id = d;
    }
    if let Some(d) = args.distro {
        c.distro = match d {
            DistroArg::Humble => Distro::Humble,
            DistroArg::Jazzy => Distro::Jazzy,
        };
    }
    if args.control {
        c.routes.get_mut(&Route::Command).expect("every route has an entry").enabled = true;
    }
    if let Some(ns) = &args.ros_namespace {
        c.set_namespace(ns)
            .map_err(|p| ConfigError::new("--ros-namespace", "", p.to_string(), "use `/` or `/name`"))?;
    }
    Ok(c)
}

/// One row of `--list`.
#[derive(Debug, Serialize)]
pub struct MappingRow {
    pub route: &'static str,
    pub direction: &'static str,
    pub topic: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub qos: crate::ros2::graph::RosQos,
    pub enabled: bool,
    pub key: String,
}

/// The mapping as rows, each with its resolved name and data key.
pub fn mapping(c: &Ros2Config) -> Result<Vec<MappingRow>> {
    let node = c.node_id(String::new());
    c.routes
        .iter()
        .map(|(route, e)| {
            let topic = node.resolve(&e.name);
            Ok(MappingRow {
                route: route.id(),
                direction: if route.direction() == Direction::ToRos { "to ROS" } else { "from ROS" },
                key: node.data_key(&topic, &e.type_name).map_err(anyhow::Error::msg)?,
                topic,
                type_name: e.type_name.clone(),
                qos: e.qos,
                enabled: e.enabled,
            })
        })
        .collect()
}

/// One message type for `--list --types`.
#[derive(Debug, Serialize)]
pub struct TypeRow {
    #[serde(rename = "type")]
    pub type_name: &'static str,
    pub dds: String,
    pub hash: String,
    pub definition: String,
}

pub fn types() -> Result<Vec<TypeRow>> {
    schema::known_types()
        .into_iter()
        .map(|t| {
            Ok(TypeRow {
                type_name: t,
                dds: schema::dds_name(t)?,
                hash: schema::type_hash(t)?,
                definition: schema::ros2msg(t)?,
            })
        })
        .collect()
}

/// `--list`: the mapping or the types, printed.
pub fn list(topics: &TopicMap, args: &Ros2Args) -> Result<()> {
    if args.types {
        let rows = types()?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&rows)?);
        } else {
            for r in rows {
                println!("{:42} {}", r.type_name, r.hash);
            }
        }
        return Ok(());
    }
    let c = config(topics, args)?;
    let rows = mapping(&c)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!("ROS 2 node {} in namespace {} on domain {} ({:?} keys)", c.node, c.namespace, c.domain_id, c.distro);
    for r in rows {
        let on = if r.enabled { "on " } else { "off" };
        println!("{on} {:19} {:8} {:34} {:42} {}", r.route, r.direction, r.topic, r.type_name, r.qos);
    }
    Ok(())
}

/// One line of what the bridge has sent.
pub fn status_line(s: &FaceStats) -> String {
    let sent: u64 = s.routes.iter().map(|r| r.sent).sum();
    let dropped: u64 = s.routes.iter().map(|r| r.dropped).sum();
    let mb = s.routes.iter().map(|r| r.bytes).sum::<u64>() as f64 / 1e6;
    let mut line = format!("ROS 2: {sent} messages sent ({mb:.1} MB), {dropped} dropped for slow subscribers");
    if let Some(c) = &s.commands {
        line.push_str(&format!("; commands {} accepted, {} refused, {} applied", c.accepted, c.refused, c.applied));
    }
    line
}

/// Runs the bridge until Ctrl-C or --duration, with a status line on stderr; its token is
/// declared once it listens (in lockstep with --control, once a ROS 2 controller is there).
pub async fn run(bus: &Bus, args: &Ros2Args) -> Result<FaceStats> {
    let c = config(bus.topics(), args)?;
    let lockstep = args.control && args.clock == ClockArg::Lockstep;
    let face = RosFace::start(bus, &c, args.vehicle.params(), lockstep).await?;
    let n = face.node();
    eprintln!(
        "ROS 2 node {} in namespace {} on domain {} ({:?} keys): `ros2 topic list -t` with rmw_zenoh shows its topics",
        n.name, n.namespace, n.domain, n.distro
    );
    if lockstep {
        tokio::select! {
            found = ros_controller(bus, &c) => found?,
            signal = crate::cli::stop_requested() => {
                eprintln!("{signal} while waiting for the ROS 2 controller");
                return Ok(face.stop().await);
            }
        }
    }
    bus.announce().await?;
    super::until_stopped(args.duration, STATUS_EVERY, || status_line(&face.stats())).await;
    let stats = face.stop().await;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    } else {
        eprintln!("{}", status_line(&stats));
    }
    Ok(stats)
}

/// How often the ROS graph is asked for the controller's endpoints.
const GRAPH_POLL: Duration = Duration::from_millis(100);

/// Waits until the ROS graph has a publisher of the command route and a subscription to the
/// odometry: a lockstep simulator's first step must find the controller listening.
async fn ros_controller(bus: &Bus, c: &crate::ros2::Ros2Config) -> Result<()> {
    let node = c.node_id(String::new());
    let topic = |r: Route| node.resolve(&c.routes[&r].name);
    let (command, odometry) = (topic(Route::Command), topic(Route::Odometry));
    eprintln!(
        "lockstep: waiting for a ROS 2 controller on domain {}: a publisher of {command} and a subscription to {odometry} \
         (it answers each odometry with one command stamped with the odometry's header.stamp)",
        c.domain_id
    );
    let key = format!("@ros2_lv/{}/**", c.domain_id);
    loop {
        let replies =
            bus.session().liveliness().get(&key).await.map_err(|e| anyhow::anyhow!("ask the ROS graph: {e}"))?;
        let (mut publishes, mut listens) = (false, false);
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            match endpoint_of(sample.key_expr().as_str(), c.domain_id) {
                Some((EndpointKind::Publisher, t)) if t == command => publishes = true,
                Some((EndpointKind::Subscription, t)) if t == odometry => listens = true,
                _ => {}
            }
        }
        if publishes && listens {
            return Ok(());
        }
        tokio::time::sleep(GRAPH_POLL).await;
    }
}

/// `slipstream ros2`: the mapping with --list, else the bridge until Ctrl-C (or --duration).
pub fn command(args: &Ros2Args, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    if args.list {
        list(&connect.topic_map()?, args)?;
        return Ok(std::process::ExitCode::SUCCESS);
    }
    let name = args.name.clone().unwrap_or_else(|| crate::cli::own_name("ros2"));
    tokio::runtime::Runtime::new()?.block_on(async {
        let bus = Bus::open_node(connect, &crate::config::FaultArgs::default(), &name).await?;
        let out = run(&bus, args).await;
        bus.leave().await;
        out
    })?;
    Ok(std::process::ExitCode::SUCCESS)
}
