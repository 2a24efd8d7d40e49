//! The loop file (`--loop FILE`, JSON5): which node takes each role of the loop (simulator,
//! detector, controller, others), ours or any command, and how each runs (arguments,
//! environment, working directory, readiness, restart policy, log). config/loop.json5
//! documents every key; the flags `--controller`/`--detector` are its one-line shortcuts.
//!
//! Read once into [`OwnNodes`], checked whole before anything starts: an unknown key, a role
//! given twice, a command that cannot run or a value out of range names the file, the key and
//! the fix. A node's relative paths (its program, its script, its `cwd`) are taken from the
//! loop file's directory, so a file runs the same from wherever it is launched; a command
//! runs there unless `cwd` says otherwise. Our own nodes keep the launcher's directory (the
//! loop's own flags name paths from it); their `args` that name files are taken from the
//! file's directory too.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::foreign::{absolute, hashed, BuiltinNode, ForeignNode, NodeRun, OwnNodes, Ready, Restart, Role, NODE_ENV};
use crate::error::Result;
use slipstream_contract::config::{from_value, parse_json5_value, read_config, ConfigError, Invalid};

/// What every error of a loop file adds.
const FIX: &str = "see config/loop.json5 for every key";

/// Variables the loop sets for a node itself (its connection and its run).
const RESERVED_ENV: [&str; 6] = [
    "SLIPSTREAM_ZENOH_CONFIG",
    NODE_ENV,
    "SLIPSTREAM_NAMESPACE",
    "SLIPSTREAM_CONFIG",
    "SLIPSTREAM_CLOCK",
    "SLIPSTREAM_PERCEPTION",
];

/// Names a node in no role of ours cannot take: the roles' and our nodes' names on the bus.
const RESERVED_NAMES: [&str; 7] = ["simulator", "detector", "controller", "sim", "detect", "acc", "observer"];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLoop {
    #[serde(default)]
    simulator: Option<RawNode>,
    #[serde(default)]
    detector: Option<RawNode>,
    #[serde(default)]
    controller: Option<RawNode>,
    #[serde(default)]
    others: Vec<RawNode>,
}

/// The top level's keys, to find one given twice (a JSON value keeps the last silently).
#[derive(Deserialize)]
#[allow(dead_code)]
struct Roles {
    simulator: Option<serde::de::IgnoredAny>,
    detector: Option<serde::de::IgnoredAny>,
    controller: Option<serde::de::IgnoredAny>,
    others: Option<serde::de::IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNode {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    builtin: bool,
    #[serde(default)]
    command: Option<CommandLine>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default)]
    env: BTreeMap<String, String>,
    #[serde(default)]
    cwd: Option<PathBuf>,
    #[serde(default)]
    ready: Ready,
    #[serde(default)]
    restart: Restart,
    #[serde(default)]
    log: Option<PathBuf>,
    #[serde(default)]
    lockstep: Option<bool>,
    #[serde(default)]
    elsewhere: bool,
    #[serde(default)]
    ros2: bool,
}

/// A command as one line (split as a shell would) or as its words.
#[derive(Deserialize)]
#[serde(untagged)]
enum CommandLine {
    Line(String),
    Words(Vec<String>),
}

/// Reads and checks a loop file.
pub fn read(path: &Path) -> Result<OwnNodes> {
    let (text, origin) = read_config(path)?;
    if let Err(e) = json5::from_str::<Roles>(&text) {
        let said = e.to_string();
        if let Some(field) = said.split("duplicate field `").nth(1).and_then(|r| r.split('`').next()) {
            let fix = format!("keep one `{field}` (a role is taken by one node; more nodes go in `others`)");
            return Err(ConfigError::new(&origin, field, "given twice", fix).into());
        }
    }
    let raw: RawLoop = from_value(parse_json5_value(&text, &origin)?, &origin, FIX)?;
    let base = absolute(path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")));
    let mut own = nodes(raw, &base).map_err(|e| e.at(&origin))?;
    own.loop_file = Some(hashed(path).map_err(|e| ConfigError::new(&origin, "", format!("cannot read: {e}"), ""))?);
    Ok(own)
}

/// The nodes of a parsed file, relative paths from `base`.
fn nodes(raw: RawLoop, base: &Path) -> std::result::Result<OwnNodes, Invalid> {
    let mut own = OwnNodes::default();
    if let Some(sim) = raw.simulator {
        if sim.restart != Restart::default() || sim.ready != Ready::default() {
            let fix = "drop them: the simulator's end is the run's end, and it starts once the others are ready \
                       (`up --sim-wait` bounds the wait for its first message)";
            return Invalid::err("simulator", "`restart` and `ready` are not the simulator's", fix);
        }
        match sim.builtin {
            true => own.builtin.simulator = Some(builtin("simulator", sim, base)?),
            false => own.simulator = Some(command("simulator", Role::Simulator, sim, base)?),
        }
    }
    for (role, raw) in [(Role::Detector, raw.detector), (Role::Controller, raw.controller)] {
        let Some(raw) = raw else { continue };
        let key = role.process();
        if raw.builtin {
            let node = Some(builtin(key, raw, base)?);
            match role {
                Role::Detector => own.builtin.detector = node,
                _ => own.builtin.controller = node,
            }
            continue;
        }
        let node = Some(command(key, role, raw, base)?);
        match role {
            Role::Detector => own.detector = node,
            _ => own.controller = node,
        }
    }
    for (i, raw) in raw.others.into_iter().enumerate() {
        let key = format!("others[{i}]");
        let node = command(&key, Role::Other, raw, base)?;
        if own.others.iter().any(|o| o.name == node.name) {
            return Invalid::err(format!("{key}.name"), "names a node twice", "give every node a name of its own");
        }
        own.others.push(node);
    }
    Ok(own)
}

/// One of our nodes (`builtin: true`): no command, no working directory of its own.
fn builtin(key: &str, raw: RawNode, base: &Path) -> std::result::Result<BuiltinNode, Invalid> {
    let refuse = |what: &str, problem: &str, fix: &str| Invalid::err(format!("{key}.{what}"), problem, fix);
    if raw.command.is_some() {
        return refuse("command", "a built-in node has no command", "drop `builtin: true` or `command`");
    }
    if raw.cwd.is_some() {
        return refuse(
            "cwd",
            "a built-in node runs in the launcher's directory (the loop's flags name paths from it)",
            "drop `cwd`; its `args` that name files are taken from the loop file's directory",
        );
    }
    let args = raw
        .args
        .iter()
        .map(|a| match base.join(a).is_file() {
            true => base.join(a).display().to_string(),
            false => a.clone(),
        })
        .collect();
    Ok(BuiltinNode { args, run: run(key, &raw, None)? })
}

/// A node started from a command, or by the user elsewhere.
fn command(key: &str, role: Role, raw: RawNode, base: &Path) -> std::result::Result<ForeignNode, Invalid> {
    let name = name(key, role, &raw)?;
    if raw.elsewhere {
        return elsewhere(key, role, name, &raw);
    }
    let mut words = match &raw.command {
        None if raw.builtin && role == Role::Other => {
            return Invalid::err(
                format!("{key}.builtin"),
                "a node in no role of ours cannot be built in",
                "give its `command`",
            )
        }
        None => {
            let fix = "give `command: \"python3 my_node.py\"` (any command), or `builtin: true` for ours";
            return Invalid::err(format!("{key}.command"), "missing: which node takes this role?", fix);
        }
        Some(_) if raw.builtin => {
            return Invalid::err(
                format!("{key}.builtin"),
                "a node with a command is not built in",
                "drop one of the two",
            )
        }
        Some(CommandLine::Line(line)) => {
            ForeignNode::split(line).map_err(|p| Invalid::new(format!("{key}.command"), p, FIX))?
        }
        Some(CommandLine::Words(w)) if w.is_empty() => return Invalid::err(format!("{key}.command"), "is empty", FIX),
        Some(CommandLine::Words(w)) => w.clone(),
    };
    words.extend(raw.args.iter().cloned());
    let cwd = raw.cwd.as_deref().map_or_else(|| base.to_path_buf(), |c| base.join(c));
    if !cwd.is_dir() {
        let fix = "give a directory, relative to the loop file's";
        return Invalid::err(format!("{key}.cwd"), format!("{} is no directory", cwd.display()), fix);
    }
    let run = run(key, &raw, Some(cwd))?;
    if run.lockstep && role != Role::Other {
        let problem = "lockstep always waits for the controller (and for the detector through it)";
        return Invalid::err(format!("{key}.lockstep"), problem, "drop it; it is for nodes in `others`");
    }
    let mut node =
        ForeignNode::new(role, name, words, run, base).map_err(|p| Invalid::new(format!("{key}.command"), p, FIX))?;
    if raw.ros2 && role != Role::Controller {
        let problem = "only a controller speaks ROS 2 to the loop (its commands through `slipstream ros2 --control`)";
        return Invalid::err(format!("{key}.ros2"), problem, "drop it, or give the node as the `controller`");
    }
    node.ros2 = raw.ros2;
    Ok(node)
}

/// A node the user starts elsewhere (`elsewhere: true`): nothing of how to start it applies.
fn elsewhere(key: &str, role: Role, name: Option<String>, raw: &RawNode) -> std::result::Result<ForeignNode, Invalid> {
    let given = [
        ("builtin", raw.builtin),
        ("command", raw.command.is_some()),
        ("args", !raw.args.is_empty()),
        ("env", !raw.env.is_empty()),
        ("cwd", raw.cwd.is_some()),
        ("log", raw.log.is_some()),
        ("restart", raw.restart != Restart::default()),
        ("ros2", raw.ros2),
    ];
    if let Some((what, _)) = given.iter().find(|(_, given)| *given) {
        let problem = "a node started elsewhere is not started, restarted or logged by the loop";
        let fix =
            "drop it (start the node yourself with the loop's namespace and its role's name), or drop `elsewhere`";
        return Invalid::err(format!("{key}.{what}"), problem, fix);
    }
    let run = run(key, raw, None)?;
    if run.lockstep && role != Role::Other {
        let problem = "lockstep always waits for the controller (and for the detector through it)";
        return Invalid::err(format!("{key}.lockstep"), problem, "drop it; it is for nodes in `others`");
    }
    Ok(ForeignNode::started_elsewhere(role, name, run))
}

/// A node's name: only, and always, for one in no role of ours.
fn name(key: &str, role: Role, raw: &RawNode) -> std::result::Result<Option<String>, Invalid> {
    match (&raw.name, role) {
        (None, Role::Other) => Invalid::err(format!("{key}.name"), "missing", "name it (on the bus and in the logs)"),
        (Some(_), Role::Controller | Role::Detector | Role::Simulator) => {
            Invalid::err(format!("{key}.name"), "a role's node has the role's name on the bus", "drop `name`")
        }
        (Some(n), _) if RESERVED_NAMES.contains(&n.as_str()) => Invalid::err(
            format!("{key}.name"),
            format!("`{n}` is a role of the loop or one of its nodes: a role is taken by one node"),
            format!("to put your node in that role, give it under `{}`; else name it otherwise", role_key(n)),
        ),
        (Some(n), _) if n.is_empty() || !n.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') => {
            Invalid::err(format!("{key}.name"), format!("`{n}` is no name"), "use letters, digits, - and _")
        }
        (name, _) => Ok(name.clone()),
    }
}

/// The role key a reserved name stands for.
fn role_key(name: &str) -> &'static str {
    match name {
        "detect" | "detector" => "detector",
        "acc" | "controller" => "controller",
        _ => "simulator",
    }
}

/// How a node runs, its values checked.
fn run(key: &str, raw: &RawNode, cwd: Option<PathBuf>) -> std::result::Result<NodeRun, Invalid> {
    if let Some(var) = raw.env.keys().find(|k| RESERVED_ENV.contains(&k.as_str())) {
        let fix = "drop it (docs/own-node.md says what the loop hands a node)";
        return Invalid::err(format!("{key}.env.{var}"), "the loop sets this one itself", fix);
    }
    let r = &raw.ready;
    if !(r.timeout_s > 0.0 && r.timeout_s <= 600.0) {
        return Invalid::err(format!("{key}.ready.timeout_s"), "out of range", "give seconds in (0, 600]");
    }
    if r.sample.as_deref().is_some_and(str::is_empty) {
        return Invalid::err(format!("{key}.ready.sample"), "is empty", "give a topic name or a key expression");
    }
    let s = &raw.restart;
    if s.limit > 100 {
        return Invalid::err(format!("{key}.restart.limit"), "out of range", "give at most 100 restarts");
    }
    if !(0.0..=60.0).contains(&s.backoff_s) {
        return Invalid::err(format!("{key}.restart.backoff_s"), "out of range", "give seconds in [0, 60]");
    }
    Ok(NodeRun {
        env: raw.env.clone(),
        cwd,
        ready: raw.ready.clone(),
        restart: raw.restart.clone(),
        log: raw.log.clone(),
        lockstep: raw.lockstep.unwrap_or(false),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::foreign::RestartPolicy;

    /// A directory of the test's own with `files` (name, text) in it.
    fn dir_with(test: &str, files: &[(&str, &str)]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("slipstream-loop-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        dir
    }

    fn refused(test: &str, text: &str) -> String {
        let dir = dir_with(test, &[("loop.json5", text), ("acc.py", "")]);
        let e = read(&dir.join("loop.json5")).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(e.contains("loop.json5: "), "names the file: {e}");
        e
    }

    #[test]
    fn a_loop_file_gives_each_role_its_node_with_paths_from_its_own_directory() {
        let text = r#"{
            controller: { command: "sh acc.py --gain 0.4", env: { GAIN: "1" },
                          restart: { policy: "on-failure", limit: 2 } },
            detector: { builtin: true, args: ["--settings", "detect.json5", "--verbose"] },
            others: [{ name: "monitor", command: ["sh", "mon.sh"], ready: { sample: "acc/status", timeout_s: 5 },
                       lockstep: true, log: "mon/err.log" }],
        }"#;
        let dir = dir_with("full", &[("loop.json5", text), ("acc.py", "x = 1\n"), ("detect.json5", "{}")]);
        std::fs::write(dir.join("mon.sh"), "").unwrap();
        let own = read(&dir.join("loop.json5")).unwrap();
        let c = own.controller.as_ref().unwrap();
        assert_eq!(c.command, ["sh", "acc.py", "--gain", "0.4"]);
        assert_eq!(c.files[1].path, dir.join("acc.py"), "the script is found from the file's directory");
        assert_eq!(c.run.cwd.as_deref(), Some(dir.as_path()), "a command runs in the file's directory");
        assert_eq!(c.run.env["GAIN"], "1");
        assert_eq!((c.run.restart.policy, c.run.restart.limit), (RestartPolicy::OnFailure, 2));
        assert_eq!(c.run.restart.backoff_s, 1.0, "unset keys take their defaults");
        let d = own.builtin.detector.as_ref().unwrap();
        let settings = dir.join("detect.json5").display().to_string();
        assert_eq!(d.args, ["--settings", settings.as_str(), "--verbose"]);
        assert!(own.detector.is_none() && own.builtin.controller.is_none());
        let m = &own.others[0];
        assert_eq!((m.node(), m.process(), m.run.lockstep), ("monitor", "monitor", true));
        assert_eq!(m.run.ready.sample.as_deref(), Some("acc/status"));
        assert_eq!(own.run_of("monitor").log.as_deref(), Some(Path::new("mon/err.log")));
        assert_eq!(own.run_of("slipstream-acc"), NodeRun::default(), "a role left out is ours, as always");
        assert_eq!(own.loop_file.as_ref().unwrap().path, dir.join("loop.json5"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Faults land where our nodes receive: into a node of the user's own only when it reads
    /// the topic and the entry's `at` names it (or no node).
    #[test]
    fn a_fault_is_refused_only_where_it_would_land_in_a_node_of_your_own() {
        use slipstream_contract::config::{FaultProfile, Loss, TopicFaults};
        use slipstream_contract::topics::Topic;
        let dir = dir_with("faults", &[("loop.json5", r#"{ controller: { command: "sh acc.py" } }"#), ("acc.py", "")]);
        let own = read(&dir.join("loop.json5")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let lost = |topic, at: &[&str]| {
            let f = TopicFaults {
                loss: Some(Loss::Independent(0.1)),
                at: at.iter().map(|s| s.to_string()).collect(),
                ..TopicFaults::default()
            };
            FaultProfile::single("t", 1, topic, f)
        };
        let landed = |p: &FaultProfile| own.fault_into_foreign(p).map(|(t, n)| (t, n.node().to_string()));
        assert_eq!(landed(&lost(Topic::Objects, &["acc"])), Some((Topic::Objects, "acc".into())));
        assert_eq!(
            landed(&lost(Topic::PerceptionObjects, &[])),
            Some((Topic::PerceptionObjects, "acc".into())),
            "no `at`: every node that reads it"
        );
        assert_eq!(
            landed(&lost(Topic::VehicleControl, &[])),
            None,
            "the simulator reads control, the controller does not"
        );
        assert_eq!(landed(&lost(Topic::Objects, &["sim", "detect"])), None, "an `at` naming only our nodes");
        assert_eq!(landed(&lost(Topic::CameraFront, &[])), None, "a controller reads no frames");
    }

    #[test]
    fn the_documented_loop_file_is_todays_loop() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/loop.json5");
        let own = read(&path).unwrap();
        assert!(own.controller.is_none() && own.detector.is_none() && own.others.is_empty());
        for node in [&own.builtin.simulator, &own.builtin.detector, &own.builtin.controller] {
            assert_eq!(node.as_ref().unwrap(), &BuiltinNode::default());
        }
    }

    #[test]
    fn a_simulator_of_your_own_is_a_command_or_started_elsewhere() {
        let dir = dir_with("own-sim", &[("loop.json5", "{ simulator: { command: 'sh my_sim.sh --mode lockstep' } }")]);
        std::fs::write(dir.join("my_sim.sh"), "exit 0\n").unwrap();
        let own = read(&dir.join("loop.json5")).unwrap();
        let sim = own.simulator.as_ref().unwrap();
        assert_eq!((sim.role, sim.node(), sim.process()), (Role::Simulator, "sim", "simulator"));
        assert!(sim.command[1].ends_with("my_sim.sh") && sim.files.len() == 2, "{sim:?}");
        assert!(own.has(Role::Simulator) && own.builtin.simulator.is_none());
        let dir = dir_with("far-sim", &[("loop.json5", "{ simulator: { elsewhere: true } }")]);
        let own = read(&dir.join("loop.json5")).unwrap();
        assert_eq!(own.elsewhere().map(|n| n.process()), Some("simulator"));
    }

    #[test]
    fn a_node_started_elsewhere_is_awaited_not_started() {
        let text = "{ controller: { elsewhere: true, ready: { timeout_s: 120 } },
                      others: [{ name: 'monitor', elsewhere: true, lockstep: true }] }";
        let dir = dir_with("elsewhere", &[("loop.json5", text)]);
        let own = read(&dir.join("loop.json5")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let acc = own.controller.as_ref().unwrap();
        assert!(acc.elsewhere && acc.command.is_empty() && acc.files.is_empty());
        assert_eq!((acc.run.ready.timeout_s, acc.command_line().as_str()), (120.0, "acc (started elsewhere)"));
        assert!(own.others[0].elsewhere && own.others[0].run.lockstep);
        assert_eq!(own.elsewhere().map(|n| n.node()), Some("monitor"));
    }

    #[test]
    fn a_bad_loop_file_names_the_key_and_the_fix() {
        let cases = [
            ("{ controller: { comand: 'sh' } }", "unknown field `comand`"),
            ("{ controller: { builtin: true }, controller: { command: 'sh' } }", "key `controller`: given twice"),
            ("{ controller: {} }", "key `controller.command`: missing"),
            ("{ controller: { builtin: true, command: 'sh' } }", "key `controller.command`: a built-in node"),
            ("{ controller: { command: 'no-such-program-here' } }", "neither a file nor a program on PATH"),
            ("{ controller: { command: 'sh', cwd: 'nowhere' } }", "key `controller.cwd`"),
            (
                "{ controller: { command: 'sh', env: { SLIPSTREAM_NODE: 'x' } } }",
                "key `controller.env.SLIPSTREAM_NODE`",
            ),
            ("{ controller: { command: 'sh', ready: { timeout_s: 0 } } }", "key `controller.ready.timeout_s`"),
            ("{ controller: { command: 'sh', restart: { backoff_s: 90 } } }", "key `controller.restart.backoff_s`"),
            ("{ controller: { command: 'sh', lockstep: true } }", "key `controller.lockstep`"),
            ("{ others: [{ name: 'acc', command: 'sh' }] }", "under `controller`"),
            ("{ others: [{ command: 'sh' }] }", "key `others[0].name`: missing"),
            ("{ others: [{ name: 'm', command: 'sh' }, { name: 'm', command: 'sh' }] }", "names a node twice"),
            ("{ simulator: { command: 'sh', restart: { policy: 'on-failure' } } }", "not the simulator's"),
            ("{ simulator: { command: 'sh', name: 'carla' } }", "key `simulator.name`"),
            ("{ simulator: { command: 'sh', lockstep: true } }", "key `simulator.lockstep`"),
            (
                "{ controller: { elsewhere: true, command: 'sh' } }",
                "key `controller.command`: a node started elsewhere",
            ),
            ("{ detector: { elsewhere: true, restart: { policy: 'on-failure' } } }", "key `detector.restart`"),
            ("{ others: [{ name: 'm', elsewhere: true, env: { A: '1' } }] }", "key `others[0].env`"),
        ];
        for (i, (text, said)) in cases.iter().enumerate() {
            let e = refused(&format!("bad{i}"), text);
            assert!(e.contains(said), "{text}: {e}");
            assert!(e.contains("fix: "), "{text}: {e}");
        }
    }
}
