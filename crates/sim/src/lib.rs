//! slipstream-sim: a deterministic driving simulator.
//!
//! # Layout
//! - [`scenario`]: the scenario file format (scenarios/*.json5) and its checks.
//! - [`slipstream_model::road`]: the road's centre line, lanes and road coordinates (s, d), shared.
//! - [`dynamics`]: the forces on a vehicle's body (engine, brakes, drag, rolling resistance,
//!   tyres, steering) from the shared model in [`slipstream_model::vehicle`].
//! - [`physics`]: the one boundary to rapier3d (rigid bodies, contacts).
//! - [`driver`]: traffic drivers (speed profiles, following, lane changes).
//! - [`world`]: road + vehicles + drivers stepped at a fixed rate; no I/O.
//! - `render`: a camera, rendered in software ([`Renderer`]).
//! - `cameras`: the front and the narrow camera drawn in process (eval), seeded as the node.
//! - `ground_truth`: the objects message, from the world and the rendered frame.
//! - [`settings`]: rates, camera, clock mode and control policy (config/sim.json5).
//! - [`node`]: the simulator on the bus: clock modes, lockstep, the run's report.
//! - `port`: one controlled vehicle's topics, cameras and control input, in its namespace.
//! - `error`: the node's error, `SimError`.
//! - `control_in`: commands as they arrive, the timeout policy, lockstep's answers.
//! - [`args`]: slipstream-sim's command-line flags.
//! - `preview`: one frame to a PNG, off the bus, for scenario writers.
//!
//! docs/simulator.md describes the model, frames, scenario format and modes for users.

pub mod args;
mod cameras;
mod control_in;
mod driver;
mod dynamics;
mod error;
mod ground_truth;
mod node;
mod physics;
mod port;
mod preview;
mod render;
mod rng;
pub mod scenario;
pub mod settings;
pub mod world;

pub use cameras::{Cameras, DrawnCamera};
pub use error::SimError;
pub use ground_truth::ground_truth;
pub use node::{run, SimReport, SimTime};
pub use port::EgoRun;
pub use preview::preview;
pub use render::{FrameLook, ObjectVisibility, Renderer};
pub use rng::SimRng;
pub use scenario::Scenario;
pub use settings::SimSettings;
pub use world::World;
