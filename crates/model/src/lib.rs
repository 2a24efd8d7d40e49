//! The model every part of the loop shares and no part owns: the vehicle (its dimensions,
//! limits and the powertrain both the simulator and the controllers reason with) and the road's
//! geometry (lanes, curves, road coordinates). The simulator, the detector and the ACC each
//! stand on it and on the contract, never on one another.

pub mod road;
pub mod vehicle;
