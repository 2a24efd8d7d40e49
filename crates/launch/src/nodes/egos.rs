//! The controllers of a loop with several egos (a scenario's `egos`): per ego its
//! slipstream-acc, and with camera perception its slipstream-detect, each in the ego's
//! namespace under the run's (`car1` in the run's namespace `loop` is `loop/car1`), where
//! the simulator publishes that ego's topics. Every ego's nodes are ours, with the flags every
//! node of the run gets and what a loop file says of ours, or the loop file's node of the
//! user's own in that role, one process per ego with the ego's namespace in its environment
//! (docs/own-node.md): the same command drives every car, as our ACC does.

use slipstream_acc::VehicleClass;
use slipstream_contract::bus::NodesWatch;
use slipstream_contract::Bus;

use super::{LoopRun, ACC, ACC_NODE, DETECT, DETECT_NODE};
use crate::error::{Error, Result};
use crate::foreign::{ForeignNode, NodeRun};
use crate::ready::Watch;

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
    /// Watches `bus`'s namespace and each of `namespaces` under it.
    pub async fn watch(bus: &Bus, namespaces: &[String]) -> Result<AllNodes> {
        let mut watches = vec![(String::new(), bus.watch_nodes().await?)];
        for ns in namespaces {
            watches.push((ns.clone(), bus.scoped(ns)?.watch_nodes().await?));
        }
        Ok(AllNodes { watches })
    }

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
        let namespaces: Vec<String> = self.spec.egos.iter().map(|e| e.namespace.clone()).collect();
        AllNodes::watch(&self.bus, &namespaces).await
    }

    /// Starts every ego's controller (and detector with camera perception) in its namespace:
    /// ours, or the loop file's node of the user's own in that role, one per ego; returns
    /// what to wait for before the simulator starts.
    pub(super) async fn start_ego_controllers(&mut self) -> Result<Vec<Watch>> {
        self.refuse_for_egos()?;
        let (controller, detector) = (self.spec.own.controller.clone(), self.spec.own.detector.clone());
        let mut waits = Vec::new();
        for ego in self.spec.egos.clone() {
            let bus = self.bus.scoped(&ego.namespace)?;
            waits.push(self.ego_watch(&bus, &ego, ACC_NODE, controller.as_ref().map_or(ACC, |n| n.process())).await?);
            match &controller {
                Some(node) => self.spawn_foreign_in(&bus, &ego, node)?,
                None => {
                    let args = self.acc_args_of(ego.set_speed_mps, ego.time_gap_s, Some(ego.vehicle));
                    self.spawn_in(&bus, &ego, ACC, ACC_NODE, args)?
                }
            }
            if self.camera() {
                let role = detector.as_ref().map_or(DETECT, |n| n.process());
                waits.push(self.ego_watch(&bus, &ego, DETECT_NODE, role).await?);
                match &detector {
                    Some(node) => self.spawn_foreign_in(&bus, &ego, node)?,
                    None => self.spawn_in(&bus, &ego, DETECT, DETECT_NODE, vec!["--json".into()])?,
                }
            }
        }
        Ok(waits)
    }

    /// What one node per ego cannot be: a node in no role (one for all the cars, or one per car?
    /// started by hand, it says), and a ROS 2 controller (its bridge is one per run).
    fn refuse_for_egos(&self) -> Result<()> {
        let own = &self.spec.own;
        let other = own.others.first().map(|n| (n.process(), "a node in no role is one node for all of them"));
        let ros2 = own.controller.as_ref().filter(|n| n.ros2).map(|n| (n.process(), "its ROS 2 bridge is one per run"));
        match other.or(ros2) {
            Some((node, why)) => Err(Error::Refused(format!(
                "the scenario has {} controlled vehicles: {node}: {why} (fix: start it by hand in one ego's namespace, `-n <run namespace>/car1`, beside the run; or run a scenario with one ego)",
                self.spec.egos.len()
            ))),
            None => Ok(()),
        }
    }

    /// The watch for `node` (acc, detect) in `ego`'s namespace, ready as the loop file says of
    /// the process in that role (`role`: ours by binary, or the user's node by its process).
    async fn ego_watch(&self, bus: &Bus, ego: &EgoNodes, node: &str, role: &str) -> Result<Watch> {
        let process = ego.process(node);
        let qualified = format!("{}/{node}", ego.namespace);
        Watch::new(bus, &qualified, &process, &self.spec.own.run_of(role).ready).await
    }

    /// One of our node binaries as `ego`'s `node` (`car1-acc`), in `bus`'s namespace, with what
    /// a loop file says of it, as for the only ego's.
    fn spawn_in(&mut self, bus: &Bus, ego: &EgoNodes, bin: &str, node: &str, args: Vec<String>) -> Result<()> {
        let process = ego.process(node);
        let own = self.endpoints.extra(&process)?;
        let cmd = self.command_of(bin, args, in_namespace(self.flags(&own), bus.topics().namespace()))?;
        let run = self.role_run(bin, &ego.namespace);
        self.launch_as(&process, run, cmd, &format!("{process}.json"), &own)
    }

    /// The user's `node` for `ego`, in `bus`'s namespace, as `car1-controller`: its Zenoh
    /// config written under logs/car1/, the loop file's settings of its role (a log file it
    /// names goes under car1/ too). Started elsewhere: waited for in the ego's namespace.
    fn spawn_foreign_in(&mut self, bus: &Bus, ego: &EgoNodes, node: &ForeignNode) -> Result<()> {
        let ns = bus.topics().namespace().to_string();
        if node.elsewhere {
            super::announce_elsewhere(node, &ns);
            return Ok(());
        }
        let process = ego.process(node.process());
        let own = self.endpoints.extra(&process)?;
        let dir = self.logs.join(&ego.namespace);
        std::fs::create_dir_all(&dir).map_err(Error::file("create", &dir))?;
        let run = [self.spec.clock.name(), self.spec.perception.name()];
        let cmd = node.command(&in_namespace(self.flags(&own), &ns), &dir, run)?;
        let run = self.role_run(node.process(), &ego.namespace);
        self.launch_as(&process, run, cmd, &format!("{process}.out"), &own)
    }

    /// The loop file's settings of the process in a role (`role`: ours by binary, or the
    /// user's node by its process name) for one ego's: a log it names is kept apart per ego
    /// (`car1/<log>`, `ego` the ego's namespace); none named, `<process>.log`.
    fn role_run(&self, role: &str, ego: &str) -> NodeRun {
        let mut run = self.spec.own.run_of(role);
        run.log = run.log.map(|l| std::path::Path::new(ego).join(l));
        run
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
