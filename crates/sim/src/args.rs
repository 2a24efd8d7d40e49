//! slipstream-sim's own command-line flags (the connection flags are shared: ConnectArgs).

use std::path::PathBuf;

use super::scenario::{Scenario, BUILT_IN, SEVERAL_EGOS};
use super::settings::{Mode, OnTimeout, SimSettings};
use slipstream_contract::config::{ConfigError, ConnectArgs, FaultArgs};

#[derive(Debug, Clone, clap::Args)]
pub struct SimArgs {
    /// Scenario: a built-in name (see --list-scenarios) or a path to a .json5 file (the same
    /// default as `slipstream up`)
    #[arg(short = 's', long, default_value = "cut-in")]
    pub scenario: String,
    /// List the built-in scenarios and exit
    #[arg(long)]
    pub list_scenarios: bool,
    /// Seed for every random choice (default: the scenario's own)
    #[arg(long)]
    pub seed: Option<u64>,
    /// Settings file (rates, camera, clock mode, lockstep, control policy); only the keys it
    /// changes are needed [default: config/sim.json5 when present, else built-in]
    #[arg(long, value_name = "FILE", env = "SLIPSTREAM_SIM_CONFIG")]
    pub settings: Option<PathBuf>,
    /// How the clock runs (settings key `mode`, as `up --mode`): realtime (paced to the wall
    /// clock), fast (as fast as it can), lockstep (each step waits for the controllers'
    /// answers; deterministic)
    #[arg(long, alias = "clock", value_parser = ["realtime", "fast", "lockstep"])]
    pub mode: Option<String>,
    /// Nodes lockstep waits for (comma-separated), e.g. acc
    #[arg(long, value_delimiter = ',')]
    pub wait_for: Option<Vec<String>>,
    /// Lockstep: after a step's timeout, continue (with the control policy) or stop the run
    /// (settings key `lockstep.on_timeout`)
    #[arg(long, value_parser = ["continue", "stop"])]
    pub on_timeout: Option<String>,
    /// Physics steps per simulated second
    #[arg(long)]
    pub physics_hz: Option<u32>,
    /// Camera frames (and ground truth) per simulated second
    #[arg(long)]
    pub camera_hz: Option<f64>,
    /// Camera resolution, WIDTHxHEIGHT
    #[arg(long, value_name = "WxH")]
    pub camera_size: Option<String>,
    /// End the scenario after this many simulated seconds instead of its own duration
    #[arg(long)]
    pub duration: Option<f64>,
    /// This node's name on the bus (liveliness token nodes/<name>)
    #[arg(long, default_value = "sim")]
    pub name: String,
    /// Render the camera at --at seconds into this PNG (ground-truth boxes in yellow) and exit,
    /// without joining the bus: to see what a scenario looks like
    #[arg(long, value_name = "FILE.png")]
    pub preview: Option<PathBuf>,
    /// Simulated time of the --preview frame, seconds (the ego cruises until then)
    #[arg(long, default_value_t = 0.0, requires = "preview")]
    pub at: f64,
    /// Print the run's report as JSON at the end
    #[arg(long)]
    pub json: bool,
}

impl SimArgs {
    /// The settings file (or defaults) with the flags applied and checked.
    pub fn settings(&self) -> Result<SimSettings, ConfigError> {
        let mut s = SimSettings::load_or_default(self.settings.as_deref())?;
        if let Some(mode) = &self.mode {
            s.mode = match mode.as_str() {
                "fast" => Mode::Fast,
                "lockstep" => Mode::Lockstep,
                _ => Mode::Realtime,
            };
        }
        if let Some(w) = &self.wait_for {
            s.lockstep.wait_for = w.clone();
        }
        if let Some(t) = &self.on_timeout {
            s.lockstep.on_timeout = if t == "stop" { OnTimeout::Stop } else { OnTimeout::Continue };
        }
        if let Some(hz) = self.physics_hz {
            s.physics_hz = hz;
        }
        if let Some(hz) = self.camera_hz {
            s.rates_hz.camera = hz;
        }
        if let Some(size) = &self.camera_size {
            let parsed = size.split_once(['x', 'X']).and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
            let Some((w, h)) = parsed else {
                return Err(ConfigError::new(
                    "--camera-size",
                    "",
                    format!("`{size}` is not WIDTHxHEIGHT"),
                    "write e.g. 640x480",
                ));
            };
            s.camera.width = w;
            s.camera.height = h;
        }
        s.check().map_err(|i| i.at("command line"))?;
        Ok(s)
    }

    /// The scenario, with --duration applied.
    pub fn scenario(&self) -> Result<Scenario, ConfigError> {
        let mut s = Scenario::find(&self.scenario)?;
        if let Some(d) = self.duration {
            if d.is_nan() || d <= 0.0 {
                return Err(ConfigError::new("--duration", "", format!("{d} s"), "give seconds > 0"));
            }
            s.duration_s = d;
        }
        Ok(s)
    }

    /// The built-in scenarios, one a line, with their descriptions (the platoons last, with
    /// their namespaces).
    pub fn scenario_list() -> String {
        let line = |(name, _): &(&str, &str)| {
            let s = Scenario::find(name).ok();
            let description = s.as_ref().map(|s| s.description.clone()).unwrap_or_default();
            let egos = s.filter(|s| s.egos().len() > 1).map(|s| {
                let ns: Vec<&str> = s.egos().iter().filter_map(|e| e.namespace.as_deref()).collect();
                format!(" [{} egos: {}]", ns.len(), ns.join(", "))
            });
            format!("{name:32} {description}{}\n", egos.unwrap_or_default())
        };
        BUILT_IN.iter().chain(SEVERAL_EGOS).map(line).collect()
    }
}

/// slipstream-sim: a deterministic driving simulator on the bus.
///
/// Publishes vehicle/speed, vehicle/state, camera/front (+ camera/front/info), objects
/// (ground truth), sim/clock and sim/events; the ego obeys vehicle/control. Runs one
/// scenario (scenarios/*.json5, or a file of your own: docs/simulator.md) and exits when it
/// ends. Examples:
///
///   slipstream-sim --scenario cut-in
///
///   slipstream-sim --scenario my.json5 --mode fast --seed 7
///
///   slipstream-sim --mode lockstep --wait-for acc    (steps wait for the acc node)
///
///   slipstream-sim --scenario busy-traffic --preview frame.png --at 5
#[derive(clap::Parser, Debug)]
#[command(name = "slipstream-sim", version, verbatim_doc_comment)]
pub struct SimCli {
    #[command(flatten)]
    pub connect: ConnectArgs,
    #[command(flatten)]
    pub faults: FaultArgs,
    #[command(flatten)]
    pub sim: SimArgs,
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::*;

    #[derive(clap::Parser)]
    struct WithConnect {
        #[command(flatten)]
        connect: slipstream_contract::config::ConnectArgs,
        #[command(flatten)]
        sim: SimArgs,
    }

    #[test]
    fn flags_do_not_clash_with_the_shared_connection_flags() {
        WithConnect::command().debug_assert();
    }
}
