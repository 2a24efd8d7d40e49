//! The simulator node's error: what stops a run (the bus, lockstep's start, the camera, the
//! settings), apart from the node and its ports, which both return it.

use slipstream_contract::bus::BusError;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("lockstep: {0}")]
    Lockstep(String),
    #[error("camera: {0}")]
    Camera(String),
    #[error("settings: {0}")]
    Settings(String),
}
