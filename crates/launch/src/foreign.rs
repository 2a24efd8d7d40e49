//! Nodes of the user's own in the loop: a detector or a controller started from any command (a
//! Python script, a binary, a `ros2 run`), in the place of slipstream-detect or slipstream-acc,
//! run, waited for and judged like ours.
//!
//! A foreign node cannot take our nodes' flags, so it gets its connection through the
//! environment, which the Python client and our own nodes read the same way:
//! `SLIPSTREAM_ZENOH_CONFIG` (a Zenoh config written for it: where it listens, whom it dials),
//! `SLIPSTREAM_NAMESPACE`, `SLIPSTREAM_CONFIG` (the topic file, when there is one) and
//! `SLIPSTREAM_NODE`, the name its liveliness token and attachment carry, with the run's
//! `SLIPSTREAM_CLOCK` (realtime, fast, lockstep: as sim/clock will say, known before the first
//! step) and `SLIPSTREAM_PERCEPTION` (camera or ground-truth: which objects the run judges the
//! controller on; the simulator publishes ground truth in both). The node's name is the
//! role's (`acc`, `detect`): the simulator's lockstep, the controller's watch on its detector
//! and the tools then need no change. What a node needs to drive a scenario (set speed, time
//! gap, vehicle, road, camera) comes over the bus (docs/node-contract.md).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};
use slipstream_contract::config::{ConnectArgs, FaultProfile};
use slipstream_contract::topics::Topic;

/// The environment variable that names the node to itself.
pub(crate) const NODE_ENV: &str = "SLIPSTREAM_NODE";
/// Where rmw_zenoh (and zenoh-ros2-sdk) read a ROS 2 node's Zenoh session config.
pub(crate) const RMW_ZENOH_CONFIG_ENV: &str = "ZENOH_SESSION_CONFIG_URI";
/// slipstream's binaries: a loop file's command naming one runs the one beside this slipstream.
const OUR_BINARIES: [&str; 4] = ["slipstream", "slipstream-sim", "slipstream-acc", "slipstream-detect"];

/// The loop's nodes of the user's own; None: ours. With a loop file, also what it says of
/// ours (arguments, restart) and the file itself by content.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct OwnNodes {
    /// A simulator of the user's own (`up` only): started from its command, or elsewhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator: Option<ForeignNode>,
    pub controller: Option<ForeignNode>,
    pub detector: Option<ForeignNode>,
    /// Nodes in no role of ours (a logger, a monitor, a second controller), started first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub others: Vec<ForeignNode>,
    /// Our own nodes as the loop file runs them; empty: as always.
    #[serde(default, skip_serializing_if = "Builtins::is_empty")]
    pub builtin: Builtins,
    /// The loop file the nodes came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_file: Option<HashedFile>,
}

impl OwnNodes {
    /// Whether a node of the user's own or a built-in one from the loop file takes `role`.
    pub(crate) fn has(&self, role: Role) -> bool {
        match role {
            Role::Controller => self.controller.is_some() || self.builtin.controller.is_some(),
            Role::Detector => self.detector.is_some() || self.builtin.detector.is_some(),
            Role::Simulator => self.simulator.is_some() || self.builtin.simulator.is_some(),
            Role::Other => false,
        }
    }

    /// The nodes under test for a person: the commands of the user's own (`ours` with none),
    /// and the loop file they came from.
    pub fn described(&self, ours: &str) -> String {
        let mut said: Vec<String> = self.foreign().map(|n| n.command_line()).collect();
        if said.is_empty() {
            said.push(ours.into());
        }
        match &self.loop_file {
            Some(f) => format!("{} (loop file {})", said.join(" + "), f.path.display()),
            None => said.join(" + "),
        }
    }

    /// The first node the user starts elsewhere, if any: a loop that makes its own network
    /// (eval's, conform's) cannot have one.
    pub fn elsewhere(&self) -> Option<&ForeignNode> {
        self.foreign().find(|n| n.elsewhere)
    }

    /// Every node of the user's own.
    pub fn foreign(&self) -> impl Iterator<Item = &ForeignNode> {
        self.others.iter().chain(&self.controller).chain(&self.detector).chain(&self.simulator)
    }

    /// The first fault of `profile` that would have to be injected into a node of the user's
    /// own: one on a topic the node reads, at it (its `at` names it, or names no node). Faults
    /// are injected by our nodes' bus as a message arrives; a process of someone else's has no
    /// such layer. None: every fault lands at one of our nodes (the simulator, slipstream-acc
    /// or slipstream-detect), whatever else the loop runs.
    pub fn fault_into_foreign(&self, profile: &FaultProfile) -> Option<(Topic, &ForeignNode)> {
        profile.topics.iter().find_map(|(topic, f)| {
            self.foreign().find(|n| n.role.reads(*topic) && f.applies_at(n.node())).map(|n| (*topic, n))
        })
    }

    /// How a node of the loop runs, by its process name (`controller`, `slipstream-acc`,
    /// `logger`): the loop file's settings, or the defaults.
    pub(crate) fn run_of(&self, process: &str) -> NodeRun {
        let ours = |b: &Option<BuiltinNode>| b.as_ref().map(|b| b.run.clone());
        let found = match process {
            "slipstream-acc" => ours(&self.builtin.controller),
            "slipstream-detect" => ours(&self.builtin.detector),
            "slipstream-sim" => ours(&self.builtin.simulator),
            name => self.foreign().find(|n| n.process() == name).map(|n| n.run.clone()),
        };
        found.unwrap_or_default()
    }
}

/// Our own nodes as a loop file runs them (`builtin: true`); None: as always.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Builtins {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator: Option<BuiltinNode>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detector: Option<BuiltinNode>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller: Option<BuiltinNode>,
}

impl Builtins {
    fn is_empty(&self) -> bool {
        self.simulator.is_none() && self.detector.is_none() && self.controller.is_none()
    }
}

/// One of our nodes in a loop file: arguments after the ones the loop gives it, and how it runs.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BuiltinNode {
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub args: Vec<String>,
    #[serde(default)]
    pub run: NodeRun,
}

/// How a node runs besides its command: what a loop file says of it (the flags say nothing:
/// the defaults).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeRun {
    /// Variables set for it (over the inherited environment).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub env: std::collections::BTreeMap<String, String>,
    /// Its working directory; None: the launcher's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cwd: Option<PathBuf>,
    #[serde(default)]
    pub ready: Ready,
    #[serde(default)]
    pub restart: Restart,
    /// Its stderr log (stdout beside it, `.out`); relative: in the run's log directory.
    /// None: `<process>.log` there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log: Option<PathBuf>,
    /// In lockstep, the simulator's steps also wait for this node's vehicle/control answers
    /// (a node in no role of ours; the controller's are always awaited).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub lockstep: bool,
}

/// When a node counts as ready: its liveliness token is seen, or, with `sample`, a first
/// sample arrives on that topic (a topic name of the loop's, or a key expression), within
/// `timeout_s`. The simulator starts once every node is ready.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ready {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample: Option<String>,
    #[serde(default = "Ready::default_timeout")]
    pub timeout_s: f64,
}

impl Ready {
    fn default_timeout() -> f64 {
        super::NODE_START_TIMEOUT.as_secs_f64()
    }
}

impl Default for Ready {
    fn default() -> Ready {
        Ready { sample: None, timeout_s: Ready::default_timeout() }
    }
}

/// What happens when a node ends before the run is over: `never` restarted (the run ends,
/// the node named), or `on-failure` (a non-zero exit or a signal) at most `limit` times,
/// `backoff_s` after it ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Restart {
    #[serde(default)]
    pub policy: RestartPolicy,
    #[serde(default = "Restart::default_limit")]
    pub limit: u32,
    #[serde(default = "Restart::default_backoff")]
    pub backoff_s: f64,
}

impl Restart {
    fn default_limit() -> u32 {
        3
    }
    fn default_backoff() -> f64 {
        1.0
    }
}

impl Default for Restart {
    fn default() -> Restart {
        Restart { policy: RestartPolicy::Never, limit: Restart::default_limit(), backoff_s: Restart::default_backoff() }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    #[default]
    Never,
    OnFailure,
}

/// Which of our nodes a foreign one stands in for; `Other`: none (a node of its own name).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Controller,
    Detector,
    Simulator,
    Other,
}

impl Role {
    /// The process's name in the loop's logs and reports.
    pub fn process(self) -> &'static str {
        match self {
            Role::Controller => "controller",
            Role::Detector => "detector",
            Role::Simulator => "simulator",
            Role::Other => "other",
        }
    }

    /// Whether a node in this role reads `topic` (docs/node-contract.md); a node in no role
    /// of ours may read anything.
    pub fn reads(self, topic: Topic) -> bool {
        match self {
            Role::Controller => matches!(
                topic,
                Topic::VehicleSpeed
                    | Topic::VehicleState
                    | Topic::PerceptionObjects
                    | Topic::Objects
                    | Topic::CameraFrontInfo
                    | Topic::SimRoad
                    | Topic::SimEgo
                    | Topic::AccCommand
                    | Topic::SimClock
            ),
            Role::Detector => matches!(
                topic,
                Topic::CameraFront | Topic::CameraFrontInfo | Topic::CameraNarrow | Topic::CameraNarrowInfo
            ),
            Role::Simulator => matches!(topic, Topic::VehicleControl),
            Role::Other => true,
        }
    }

    /// The name on the bus: our node's.
    pub fn node(self) -> &'static str {
        match self {
            Role::Controller => "acc",
            Role::Detector => "detect",
            Role::Simulator => "sim",
            Role::Other => "other",
        }
    }
}

/// A node started from the user's command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignNode {
    pub role: Role,
    /// A node in no role of ours: its name, on the bus and in the logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The command line, split.
    pub command: Vec<String>,
    /// What it runs, by content: the program and every argument that names a file.
    pub files: Vec<HashedFile>,
    /// How it runs (a loop file's settings; the defaults for a flag's command).
    #[serde(default, skip_serializing_if = "NodeRun::is_default")]
    pub run: NodeRun,
    /// Started by the user elsewhere (another PC, a container, a terminal): the loop starts
    /// and supervises nothing, it waits for the node to be ready as `run.ready` says. No
    /// command, no files.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub elsewhere: bool,
    /// A ROS 2 controller (a loop file's `ros2: true`): it speaks rmw_zenoh, and the loop runs
    /// `slipstream ros2 --control` beside it as the node `acc` the simulator waits for.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub ros2: bool,
}

/// A file a node runs, and the SHA-256 of its content: a report says which code it judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HashedFile {
    pub path: PathBuf,
    pub sha256: String,
}

impl NodeRun {
    fn is_default(&self) -> bool {
        *self == NodeRun::default()
    }
}

impl ForeignNode {
    /// A command line split as a shell would (no shell runs it); the problem otherwise.
    pub(crate) fn split(cmd: &str) -> std::result::Result<Vec<String>, String> {
        shlex::split(cmd)
            .filter(|v| !v.is_empty())
            .ok_or_else(|| format!("`{cmd}` is no command line (empty, or a quote left open)"))
    }

    /// The node running `command` (its program found, its files hashed; relative paths from
    /// `base`, the loop file's directory or the current one, or from its `cwd`); the problem
    /// otherwise.
    pub(crate) fn new(
        role: Role,
        name: Option<String>,
        command: Vec<String>,
        run: NodeRun,
        base: &Path,
    ) -> std::result::Result<ForeignNode, String> {
        let dir = run.cwd.clone().unwrap_or_else(|| base.to_path_buf());
        // From the current directory a path stays as the user typed it (the report shows it).
        let from = |p: &str| if dir == Path::new(".") { PathBuf::from(p) } else { dir.join(p) };
        let program = find_program(&command[0], &from)
            .ok_or_else(|| format!("`{}` is neither a file nor a program on PATH", command[0]))?;
        let read = |p: &Path| hashed(p).map_err(|e| format!("cannot read {}: {e}", p.display()));
        let mut files = vec![read(&program)?];
        for arg in &command[1..] {
            let path = from(arg);
            if path.is_file() {
                files.push(read(&path)?);
                match source_tree(&path) {
                    Some(Ok(Some(tree))) => files.push(tree),
                    Some(Ok(None)) => tracing::warn!(
                        "{}: more than {TREE_ENTRIES} files beside it; the report hashes the script alone, not the modules it may import",
                        path.display()
                    ),
                    Some(Err(e)) => tracing::warn!(
                        "{}: the sources beside it could not all be read ({e}); the report hashes the script alone",
                        path.display()
                    ),
                    None => {}
                }
            }
        }
        Ok(ForeignNode { role, name, command, files, run, elsewhere: false, ros2: false })
    }

    /// A node the user starts elsewhere, in `role` (`name`: in no role of ours).
    pub fn started_elsewhere(role: Role, name: Option<String>, run: NodeRun) -> ForeignNode {
        ForeignNode { role, name, command: Vec::new(), files: Vec::new(), run, elsewhere: true, ros2: false }
    }

    /// The name on the bus.
    pub fn node(&self) -> &str {
        self.name.as_deref().unwrap_or(self.role.node())
    }

    /// The process's name in the loop's logs and reports.
    pub fn process(&self) -> &str {
        self.name.as_deref().unwrap_or(self.role.process())
    }

    /// The command as a shell would take it back (a node started elsewhere: its name, said so).
    pub fn command_line(&self) -> String {
        if self.elsewhere {
            return format!("{} (started elsewhere)", self.node());
        }
        shlex::try_join(self.command.iter().map(String::as_str)).unwrap_or_else(|_| self.command.join(" "))
    }

    /// The process, its connection in the environment: `flags` are the ones our node would
    /// have got (they become a Zenoh config written into `logs`); `run` the clock's and the
    /// perception's names.
    pub fn command(&self, flags: &[String], logs: &Path, run: [&str; 2]) -> Result<std::process::Command> {
        #[derive(clap::Parser)]
        struct Flags {
            #[command(flatten)]
            connect: ConnectArgs,
            /// Not handed on: the faults land at our nodes only ([`OwnNodes::fault_into_foreign`]).
            #[command(flatten)]
            _faults: slipstream_contract::config::FaultArgs,
        }
        let parsed =
            <Flags as clap::Parser>::try_parse_from(std::iter::once("node").chain(flags.iter().map(String::as_str)))
                .map_err(|e| Error::Bug(format!("the loop's own node flags do not parse: {e}")))?;
        let config = parsed.connect.zenoh_config()?;
        // Absolute: the node may run in a directory of its own.
        let path = absolute(&logs.join(format!("{}.zenoh.json5", self.node())));
        std::fs::write(&path, config.to_string()).map_err(Error::file("write", &path))?;
        let program = match self.command[0].contains('/') || OUR_BINARIES.contains(&self.command[0].as_str()) {
            true => absolute(&self.files[0].path),
            false => PathBuf::from(&self.command[0]),
        };
        let mut cmd = std::process::Command::new(program);
        cmd.args(&self.command[1..]).env("SLIPSTREAM_ZENOH_CONFIG", &path).env(NODE_ENV, self.node());
        // rmw_zenoh's session config: a ROS 2 node joins the loop's network as our nodes do.
        cmd.env(RMW_ZENOH_CONFIG_ENV, &path);
        cmd.env("SLIPSTREAM_CLOCK", run[0]).env("SLIPSTREAM_PERCEPTION", run[1]);
        match &parsed.connect.namespace {
            Some(ns) => cmd.env("SLIPSTREAM_NAMESPACE", ns),
            None => cmd.env_remove("SLIPSTREAM_NAMESPACE"),
        };
        if let Some(t) = &parsed.connect.topics {
            cmd.env("SLIPSTREAM_CONFIG", absolute(t));
        }
        Ok(cmd)
    }
}

/// `path` from the root (as it is when that cannot be known).
pub(crate) fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

impl NodeRun {
    /// Sets the node's environment and working directory on its command.
    pub(crate) fn apply(&self, cmd: &mut std::process::Command) {
        cmd.envs(&self.env);
        if let Some(dir) = &self.cwd {
            cmd.current_dir(dir);
        }
    }
}

/// `name` as a path (`from` the node's directory) when it has a slash; one of slipstream's binaries is the one beside the
/// running slipstream (the build that runs the loop, installed or not); else the first match
/// on PATH.
fn find_program(name: &str, from: &dyn Fn(&str) -> PathBuf) -> Option<PathBuf> {
    if name.contains('/') {
        let direct = from(name);
        return direct.is_file().then_some(direct);
    }
    if OUR_BINARIES.contains(&name) {
        if let Ok(ours) = super::sibling_binary(name) {
            return Some(ours);
        }
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join(name)).find(|p| p.is_file())
}

/// Endings of the scripts whose neighbours a node may import: a script's hash alone would
/// miss a change to a module beside it.
const SCRIPT_ENDINGS: [&str; 8] = ["py", "js", "mjs", "ts", "rb", "lua", "jl", "m"];
/// A source tree of more entries than this is not hashed (a script at the root of a large
/// tree, a home directory): reading it would cost more than the run, and a walk cut short
/// would hash a different part each time. The script's own hash stands alone then, said so.
const TREE_ENTRIES: usize = 20_000;
/// Folders a source tree's hash passes over: caches, builds and environments, not sources.
const NOT_SOURCES: [&str; 5] = ["__pycache__", "target", "node_modules", "site-packages", "dist"];

/// For a script (`my_acc.py`), every file of its ending under its directory, hashed as one:
/// `<dir>/**/*.py` with the SHA-256 over each file's relative path and content, in path order
/// (hidden folders, caches and builds left out). What the script imports from beside it is
/// then part of what a report says it judged; what it imports from elsewhere (an installed
/// package) is not. None for a file that is no script.
fn source_tree(script: &Path) -> Option<std::io::Result<Option<HashedFile>>> {
    let ending = script.extension()?.to_str()?.to_ascii_lowercase();
    if !SCRIPT_ENDINGS.contains(&ending.as_str()) {
        return None;
    }
    let dir = script.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    Some(tree_hash(dir, &ending))
}

/// The hash of [`source_tree`]; none past [`TREE_ENTRIES`].
fn tree_hash(dir: &Path, ending: &str) -> std::io::Result<Option<HashedFile>> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    let mut entries = 0usize;
    while let Some(d) = pending.pop() {
        for entry in std::fs::read_dir(&d)? {
            entries += 1;
            if entries > TREE_ENTRIES {
                return Ok(None);
            }
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if name.starts_with('.') || NOT_SOURCES.contains(&name) {
                continue;
            }
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case(ending)) {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut digest = Sha256::new();
    for f in &files {
        digest.update(f.strip_prefix(dir).unwrap_or(f).to_string_lossy().as_bytes());
        digest.update([0]);
        digest.update(Sha256::digest(std::fs::read(f)?));
    }
    let sha256 = digest.finalize().iter().map(|b| format!("{b:02x}")).collect();
    Ok(Some(HashedFile { path: dir.join("**").join(format!("*.{ending}")), sha256 }))
}

pub(crate) fn hashed(path: &Path) -> std::io::Result<HashedFile> {
    let bytes = std::fs::read(path)?;
    let digest = Sha256::digest(&bytes);
    let sha256 = digest.iter().map(|b| format!("{b:02x}")).collect();
    Ok(HashedFile { path: path.to_path_buf(), sha256 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scripts_hash_covers_the_modules_beside_it_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("slipstream-source-tree-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for sub in ["helper", "__pycache__", ".venv"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        let write = |p: &str, text: &str| std::fs::write(dir.join(p), text).unwrap();
        write("acc.py", "import helper.law");
        write("helper/law.py", "GAIN = 0.5");
        write("notes.txt", "a");
        write("__pycache__/law.py", "cache");
        write(".venv/zenoh.py", "installed");
        let hash = || source_tree(&dir.join("acc.py")).expect("a script").unwrap().expect("a small tree");
        let before = hash();
        assert!(before.path.ends_with("**/*.py"), "{:?}", before.path);
        write("notes.txt", "b");
        write("__pycache__/law.py", "other cache");
        write(".venv/zenoh.py", "another version");
        assert_eq!(hash(), before, "data, caches and environments are not the node's sources");
        write("helper/law.py", "GAIN = 0.6");
        assert_ne!(hash().sha256, before.sha256, "a module beside the script is");
        assert!(source_tree(&dir.join("notes.txt")).is_none(), "a data file has no source tree");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
