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
use slipstream_contract::config::ConnectArgs;

/// The environment variable that names the node to itself.
pub const NODE_ENV: &str = "SLIPSTREAM_NODE";

/// `--controller` and `--detector`: nodes of your own in the place of ours.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct OwnNodeArgs {
    /// Your own controller in the place of slipstream-acc: a command line, split as a shell
    /// would (no shell runs it), e.g. "python3 my_acc.py --gain 0.4". It gets its connection
    /// in SLIPSTREAM_ZENOH_CONFIG, SLIPSTREAM_NAMESPACE and SLIPSTREAM_NODE (docs/own-node.md)
    #[arg(long, value_name = "CMD")]
    pub controller: Option<String>,

    /// Your own detector in the place of slipstream-detect (camera perception), as --controller
    #[arg(long, value_name = "CMD")]
    pub detector: Option<String>,
}

impl OwnNodeArgs {
    /// The nodes the flags name, checked: each command split and its program found.
    pub fn nodes(&self) -> Result<OwnNodes> {
        let node = |flag: &str, cmd: &Option<String>, role: Role| {
            cmd.as_deref().map(|c| ForeignNode::parse(flag, c, role)).transpose()
        };
        Ok(OwnNodes {
            controller: node("--controller", &self.controller, Role::Controller)?,
            detector: node("--detector", &self.detector, Role::Detector)?,
        })
    }
}

/// The loop's nodes of the user's own; None: ours.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct OwnNodes {
    pub controller: Option<ForeignNode>,
    pub detector: Option<ForeignNode>,
}

/// Which of our nodes a foreign one stands in for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    Controller,
    Detector,
}

impl Role {
    /// The process's name in the loop's logs and reports.
    pub fn process(self) -> &'static str {
        match self {
            Role::Controller => "controller",
            Role::Detector => "detector",
        }
    }

    /// The name on the bus: our node's.
    pub fn node(self) -> &'static str {
        match self {
            Role::Controller => "acc",
            Role::Detector => "detect",
        }
    }
}

/// A node started from the user's command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignNode {
    pub role: Role,
    /// The command line, split.
    pub command: Vec<String>,
    /// What it runs, by content: the program and every argument that names a file.
    pub files: Vec<HashedFile>,
}

/// A file a node runs, and the SHA-256 of its content: a report says which code it judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HashedFile {
    pub path: PathBuf,
    pub sha256: String,
}

impl ForeignNode {
    fn parse(flag: &str, cmd: &str, role: Role) -> Result<ForeignNode> {
        let command = shlex::split(cmd)
            .filter(|v| !v.is_empty())
            .ok_or_else(|| Error::flag(flag, format!("`{cmd}` is no command line (empty, or a quote left open)")))?;
        let program = find_program(&command[0])
            .ok_or_else(|| Error::flag(flag, format!("`{}` is neither a file nor a program on PATH", command[0])))?;
        let mut files = vec![hashed(&program).map_err(Error::file("read", &program))?];
        for arg in &command[1..] {
            let path = Path::new(arg);
            if path.is_file() {
                files.push(hashed(path).map_err(Error::file("read", path))?);
            }
        }
        Ok(ForeignNode { role, command, files })
    }

    /// The name on the bus.
    pub fn node(&self) -> &'static str {
        self.role.node()
    }

    /// The command as a shell would take it back.
    pub fn command_line(&self) -> String {
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
        }
        let parsed =
            <Flags as clap::Parser>::try_parse_from(std::iter::once("node").chain(flags.iter().map(String::as_str)))
                .map_err(|e| Error::Bug(format!("the loop's own node flags do not parse: {e}")))?;
        let config = parsed.connect.zenoh_config()?;
        let path = logs.join(format!("{}.zenoh.json5", self.node()));
        std::fs::write(&path, config.to_string()).map_err(Error::file("write", &path))?;
        let mut cmd = std::process::Command::new(&self.command[0]);
        cmd.args(&self.command[1..]).env("SLIPSTREAM_ZENOH_CONFIG", &path).env(NODE_ENV, self.node());
        cmd.env("SLIPSTREAM_CLOCK", run[0]).env("SLIPSTREAM_PERCEPTION", run[1]);
        match &parsed.connect.namespace {
            Some(ns) => cmd.env("SLIPSTREAM_NAMESPACE", ns),
            None => cmd.env_remove("SLIPSTREAM_NAMESPACE"),
        };
        if let Some(t) = &parsed.connect.topics {
            cmd.env("SLIPSTREAM_CONFIG", t);
        }
        Ok(cmd)
    }
}

/// `name` as a path when it is a file, else the first match on PATH.
fn find_program(name: &str) -> Option<PathBuf> {
    let direct = Path::new(name);
    if name.contains('/') {
        return direct.is_file().then(|| direct.to_path_buf());
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join(name)).find(|p| p.is_file())
}

fn hashed(path: &Path) -> std::io::Result<HashedFile> {
    let bytes = std::fs::read(path)?;
    let digest = Sha256::digest(&bytes);
    let sha256 = digest.iter().map(|b| format!("{b:02x}")).collect();
    Ok(HashedFile { path: path.to_path_buf(), sha256 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_line_is_split_as_a_shell_would_and_its_files_hashed() {
        let dir = std::env::temp_dir().join(format!("slipstream-foreign-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let script = dir.join("my acc.py");
        std::fs::write(&script, b"print('hi')\n").unwrap();
        let args = OwnNodeArgs { controller: Some(format!("sh '{}' --gain 0.4", script.display())), detector: None };
        let nodes = args.nodes().unwrap();
        let c = nodes.controller.unwrap();
        assert_eq!(c.command[1], script.display().to_string());
        assert_eq!(c.command[2..], ["--gain", "0.4"]);
        assert_eq!(c.node(), "acc");
        // The program found on PATH, and the script by its content.
        assert_eq!(c.files.len(), 2);
        assert!(c.files[0].path.ends_with("sh"));
        assert_eq!(c.files[1].sha256, "caf026f25d7140209f98072605307a438914b9ce6f3c14b23d15d9667241de52");
        assert!(nodes.detector.is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_command_that_cannot_run_is_refused_naming_the_flag() {
        let refused = |c: &str| {
            let args = OwnNodeArgs { controller: None, detector: Some(c.into()) };
            args.nodes().unwrap_err().to_string()
        };
        assert!(refused("python3 'my acc.py").contains("--detector"), "{}", refused("python3 'my acc.py"));
        assert!(refused("").contains("no command line"));
        assert!(refused("no-such-program-here --x").contains("neither a file nor a program on PATH"));
    }
}
