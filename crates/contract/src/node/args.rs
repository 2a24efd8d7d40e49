//! The flags of a node of the user's own: its name, the run's clock and perception, the
//! connection. Each also reads the environment `slipstream up --controller CMD` hands a node
//! (docs/own-node.md, "In the loop"), so the same binary runs by hand and in the loop.

use crate::config::ConnectArgs;

/// The simulator's clock, as the node must know it before the first message: in lockstep an
/// answer waits for its step's inputs, outside it never long.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ClockArg {
    #[default]
    Realtime,
    Fast,
    Lockstep,
}

/// Which objects a controller reads: the detector's (perception/objects) or the simulator's
/// ground truth (objects).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum PerceptionArg {
    #[default]
    Camera,
    GroundTruth,
}

/// Flatten into a node's own clap parser (`#[command(flatten)] node: NodeArgs`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct NodeArgs {
    /// The node's name: its liveliness token nodes/NAME and the attachment of each sample
    /// (`up` and `eval` give a controller `acc`, a detector `detect`) [default: the node's own]
    #[arg(long, env = "SLIPSTREAM_NODE")]
    pub name: Option<String>,
    /// The simulator's clock
    #[arg(long, value_enum, env = "SLIPSTREAM_CLOCK", default_value_t = ClockArg::Realtime)]
    pub clock: ClockArg,
    /// Objects from the detector or the simulator's ground truth
    #[arg(long, value_enum, env = "SLIPSTREAM_PERCEPTION", default_value_t = PerceptionArg::Camera)]
    pub perception: PerceptionArg,
    #[command(flatten)]
    pub connect: ConnectArgs,
}

impl NodeArgs {
    /// The name given, else `default`.
    pub fn name_or<'a>(&'a self, default: &'a str) -> &'a str {
        self.name.as_deref().unwrap_or(default)
    }

    pub fn lockstep(&self) -> bool {
        self.clock == ClockArg::Lockstep
    }

    pub fn ground_truth(&self) -> bool {
        self.perception == PerceptionArg::GroundTruth
    }
}
