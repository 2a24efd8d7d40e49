//! The controllers of a loop with several egos (a scenario's `egos`): per ego its
//! slipstream-acc, and with camera perception its slipstream-detect, each in the ego's
//! namespace under the run's (`car1` in the run's namespace `loop` is `loop/car1`), where
//! the simulator publishes that ego's topics. Every ego's nodes are ours, with the flags every
//! node of the run gets; nodes of the user's own take one ego's place through their own
//! commands (docs/simulator.md), not through `up`'s roles, which name one node each.

use slipstream_acc::VehicleClass;
use slipstream_contract::bus::NodesWatch;
use slipstream_contract::Bus;

use super::{LoopRun, ACC, ACC_NODE, DETECT, DETECT_NODE};
use crate::error::{Error, Result};
use crate::launch::ready::Watch;

/// One ego's controller settings, from its scenario entry.
#[derive(Debug, Clone, PartialEq)]
pub struct EgoNodes {
    /// Its namespace under the run's (`car1`).
    pub namespace: String,
    pub set_speed_mps: f64,
    /// None: the ACC's own setting.
    pub time_gap_s: Option<f64>,
    pub vehicle: VehicleClass,
}

impl EgoNodes {
    /// Every ego's settings when a scenario lists several; empty for one ego (the loop's own
    /// fields drive it, in the run's namespace).
    pub fn of(scenario: &slipstream_sim::Scenario) -> Vec<EgoNodes> {
        let egos = scenario.egos();
        if egos.len() < 2 {
            return Vec::new();
        }
        egos.iter()
            .map(|e| EgoNodes {
                namespace: e.namespace.clone().unwrap_or_default(),
                set_speed_mps: e.controller_set_speed_mps(),
                time_gap_s: e.time_gap_s,
                vehicle: slipstream_contract::msg::ObjectClass::from(e.class).into(),
            })
            .collect()
    }

    /// Its process names: `car1-acc`, `car1-detect`.
    pub fn process(&self, node: &str) -> String {
        format!("{}-{node}", self.namespace)
    }
}

/// The liveliness of the run's nodes in its namespace and in every ego's, by qualified name
/// (`sim`, `car1/acc`).
pub struct AllNodes {
    watches: Vec<(String, NodesWatch)>,
}

impl AllNodes {
    pub fn names(&self) -> Vec<String> {
        let mut names = Vec::new();
        for (prefix, w) in &self.watches {
            names.extend(w.names().into_iter().map(|n| if prefix.is_empty() { n } else { format!("{prefix}/{n}") }));
        }
        names
    }
}

impl LoopRun {
    /// Watches the run's namespace and every ego's.
    pub async fn watch_all_nodes(&self) -> Result<AllNodes> {
        let mut watches = vec![(String::new(), self.bus.watch_nodes().await?)];
        for ego in &self.spec.egos {
            watches.push((ego.namespace.clone(), self.bus.scoped(&ego.namespace)?.watch_nodes().await?));
        }
        Ok(AllNodes { watches })
    }

    /// Starts every ego's ACC (and detector with camera perception) in its namespace;
    /// returns what to wait for before the simulator starts.
    pub(super) async fn start_ego_controllers(&mut self) -> Result<Vec<Watch>> {
        let own = &self.spec.own;
        if let Some(node) = own.controller.iter().chain(&own.detector).chain(&own.others).next() {
            return Err(Error::Refused(format!(
                "the scenario has {} controlled vehicles: a loop file's or --controller/--detector node ({}) would be one node for all of them (fix: start your node by hand in one ego's namespace, `-n <run namespace>/car1`, beside a simulator run as docs/simulator.md shows; or run a scenario with one ego)",
                self.spec.egos.len(),
                node.process()
            )));
        }
        let mut waits = Vec::new();
        for ego in self.spec.egos.clone() {
            let bus = self.bus.scoped(&ego.namespace)?;
            let acc = ego.process(ACC_NODE);
            waits.push(self.ego_watch(&bus, &ego, ACC_NODE).await?);
            let args = self.acc_args_of(ego.set_speed_mps, ego.time_gap_s, Some(ego.vehicle));
            self.spawn_in(&bus, ACC, &acc, args)?;
            if self.camera() {
                waits.push(self.ego_watch(&bus, &ego, DETECT_NODE).await?);
                self.spawn_in(&bus, DETECT, &ego.process(DETECT_NODE), vec!["--json".into()])?;
            }
        }
        Ok(waits)
    }

    async fn ego_watch(&self, bus: &Bus, ego: &EgoNodes, node: &str) -> Result<Watch> {
        let process = ego.process(node);
        let qualified = format!("{}/{node}", ego.namespace);
        Watch::new(bus, &qualified, &process, &self.spec.own.run_of(&process).ready).await
    }

    /// One of our node binaries as `process`, in `bus`'s namespace, with what a loop file adds
    /// for its role, as for the only ego's.
    fn spawn_in(&mut self, bus: &Bus, bin: &str, process: &str, args: Vec<String>) -> Result<()> {
        let own = self.endpoints.extra(process)?;
        let cmd = self.command_of(bin, args, in_namespace(self.flags(&own), bus.topics().namespace()))?;
        self.launch(process, cmd, &format!("{process}.json"), &own)
    }
}

/// `flags` with the namespace given as `-n ns` in place of any the run's flags hold.
fn in_namespace(flags: Vec<String>, ns: &str) -> Vec<String> {
    let mut out = Vec::with_capacity(flags.len() + 2);
    let mut it = flags.into_iter();
    while let Some(f) = it.next() {
        match f.as_str() {
            "-n" | "--namespace" => drop(it.next()),
            _ => out.push(f),
        }
    }
    out.extend(["-n".into(), ns.to_string()]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_egos_node_gets_its_namespace_in_place_of_the_runs() {
        let flags: Vec<String> = ["-c", "z.json5", "-n", "loop", "-e", "tcp/127.0.0.1:1"].map(String::from).into();
        assert_eq!(
            in_namespace(flags, "loop/car2"),
            ["-c", "z.json5", "-e", "tcp/127.0.0.1:1", "-n", "loop/car2"].map(String::from)
        );
        assert_eq!(in_namespace(Vec::new(), "car1"), ["-n", "car1"].map(String::from));
    }

    #[test]
    fn only_a_scenario_with_several_egos_lists_them() {
        let one = slipstream_sim::Scenario::find("cut-in").unwrap();
        assert!(EgoNodes::of(&one).is_empty());
        let eight = slipstream_sim::Scenario::find("platoon-8").unwrap();
        let egos = EgoNodes::of(&eight);
        assert_eq!(egos.len(), 8);
        assert_eq!(egos[1].namespace, "car2");
        assert_eq!(egos[1].process("acc"), "car2-acc");
    }
}
