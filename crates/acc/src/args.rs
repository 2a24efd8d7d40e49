//! slipstream-acc's own command-line flags (the connection flags are shared: ConnectArgs).

use std::path::PathBuf;

use super::settings::{AccSettings, PerceptionSource, Vehicle, DEFAULT_ACC_CONFIG_PATH};
use slipstream_contract::config::{ConfigError, ConnectArgs, FaultArgs};
use slipstream_contract::msg::ObjectClass;
use slipstream_model::vehicle::VehicleParams;

/// The vehicle types the ACC can drive: the simulator's, by class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VehicleClass {
    Car,
    Van,
    Truck,
    Motorcycle,
}

impl VehicleClass {
    pub fn name(self) -> &'static str {
        match self {
            VehicleClass::Car => "car",
            VehicleClass::Van => "van",
            VehicleClass::Truck => "truck",
            VehicleClass::Motorcycle => "motorcycle",
        }
    }

    pub fn params(self) -> VehicleParams {
        VehicleParams::of_class(self.into())
    }
}

impl From<VehicleClass> for ObjectClass {
    fn from(c: VehicleClass) -> Self {
        match c {
            VehicleClass::Car => ObjectClass::Car,
            VehicleClass::Van => ObjectClass::Van,
            VehicleClass::Truck => ObjectClass::Truck,
            VehicleClass::Motorcycle => ObjectClass::Motorcycle,
        }
    }
}

impl From<ObjectClass> for VehicleClass {
    fn from(c: ObjectClass) -> Self {
        match c {
            ObjectClass::Van => VehicleClass::Van,
            ObjectClass::Truck => VehicleClass::Truck,
            ObjectClass::Motorcycle => VehicleClass::Motorcycle,
            ObjectClass::Car | ObjectClass::Unknown => VehicleClass::Car,
        }
    }
}

#[derive(Debug, Clone, clap::Args)]
pub struct AccArgs {
    /// Settings file (control law, limits, stale ages, vehicle model); only the keys it
    /// changes are needed [default: config/acc.json5 when present, else built-in]
    #[arg(long, value_name = "FILE", env = "SLIPSTREAM_ACC_CONFIG")]
    pub settings: Option<PathBuf>,
    /// Cruise speed with no vehicle ahead, m/s (settings key set_speed_mps) [default: the
    /// scenario's, from sim/ego, once the simulator publishes it; until then the settings']
    #[arg(long, value_name = "M/S")]
    pub set_speed: Option<f64>,
    /// Time gap to the lead, seconds, 0.8 to 3.0 (settings key time_gap_s) [default: the
    /// scenario's from sim/ego when it names one, else the settings']
    #[arg(long, value_name = "S")]
    pub time_gap: Option<f64>,
    /// Where the vehicles ahead come from: camera (perception/objects from slipstream-detect)
    /// or ground-truth (the simulator's objects, to judge control apart from perception)
    #[arg(long, value_enum)]
    pub perception: Option<PerceptionSource>,
    /// The vehicle it drives, one of the simulator's: its model for the low-level loop (mass,
    /// power, brakes, actuator lag) and where its front is, from which gaps are measured.
    /// Replaces the settings' vehicle section; `up` and `eval acc` pass the scenario's ego.
    #[arg(long, value_enum, value_name = "CLASS")]
    pub vehicle: Option<VehicleClass>,
    /// Answer each step only once the perception of that step's camera frame is in: a
    /// deterministic loop with `slipstream-sim --mode lockstep`
    #[arg(long)]
    pub lockstep: bool,
    /// Start disengaged (acc/command { enable: true } engages)
    #[arg(long)]
    pub disengaged: bool,
    /// This node's name on the bus; the simulator's lockstep.wait_for names it
    #[arg(long, default_value = "acc")]
    pub name: String,
}

impl AccArgs {
    /// The settings file (or defaults) with the flags applied and checked.
    pub fn settings(&self) -> Result<AccSettings, ConfigError> {
        let default_file = PathBuf::from(DEFAULT_ACC_CONFIG_PATH);
        let path = self.settings.clone().or_else(|| default_file.exists().then_some(default_file));
        let mut s = AccSettings::load_or_default(path.as_deref())?;
        if let Some(v) = self.set_speed {
            s.set_speed_mps = v;
            s.from_scenario.set_speed = false;
        }
        if let Some(h) = self.time_gap {
            s.time_gap_s = h;
            s.from_scenario.time_gap = false;
        }
        if let Some(p) = self.perception {
            s.perception = p;
        }
        if let Some(v) = self.vehicle {
            s.vehicle = Vehicle::of(&v.params());
        }
        s.lockstep |= self.lockstep;
        if self.disengaged {
            s.enabled = false;
        }
        s.check().map_err(|i| i.at("command line"))?;
        Ok(s)
    }
}

/// slipstream-acc: adaptive cruise control, closing the loop through the simulator.
///
/// Reads vehicle/speed, vehicle/state, the vehicles ahead (perception/objects, or the
/// simulator's ground truth with --perception ground-truth) and acc/command; publishes
/// vehicle/control for every speed message (naming the step it answers, for lockstep) and
/// acc/status (mode, set speed, target acceleration, lead, gap, desired gap, TTC, warnings).
/// Keeps a time gap to the lead in its lane, holds the set speed with nobody ahead, stops and
/// goes, warns and brakes hard when a collision threatens, and brakes smoothly when its inputs
/// go stale. Control law and results: docs/control.md. Examples:
///
///   slipstream-acc                                  (camera perception, config/acc.json5)
///
///   slipstream-acc --perception ground-truth --set-speed 30 --time-gap 2.0
///
///   slipstream-acc --lockstep     (with slipstream-sim --mode lockstep --wait-for acc)
#[derive(clap::Parser, Debug)]
#[command(name = "slipstream-acc", version, verbatim_doc_comment)]
pub struct AccCli {
    #[command(flatten)]
    pub connect: ConnectArgs,
    #[command(flatten)]
    pub faults: FaultArgs,
    #[command(flatten)]
    pub acc: AccArgs,
    /// At exit, print the run's statistics as JSON on stdout (commands, modes, and per input
    /// what arrived, was lost on the way, or was dropped or delayed by --faults)
    #[arg(long)]
    pub json: bool,
}
