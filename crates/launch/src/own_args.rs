//! The flags that put nodes of the user's own in the loop: `--loop FILE`, and its one-line
//! shortcuts `--controller CMD` and `--detector CMD`, on every command that runs the loop. One
//! place merges them into the loop's [`OwnNodes`], so a role cannot be given twice.

use std::path::{Path, PathBuf};

use super::foreign::{ForeignNode, NodeRun, OwnNodes, Role};
use crate::error::{Error, Result};

/// `--loop`, `--controller` and `--detector`: nodes of your own in the place of ours.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct OwnNodeArgs {
    /// A loop file (JSON5): which node runs in each role (ours, or any command), with its
    /// arguments, environment, working directory, readiness, restart policy and log
    /// (config/loop.json5 documents every key; docs/own-node.md)
    #[arg(long = "loop", value_name = "FILE")]
    pub loop_file: Option<PathBuf>,

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
    /// The nodes the flags and the loop file name, checked: each command split and its
    /// program found. A role given both in the file and by a flag is refused.
    pub fn nodes(&self) -> Result<OwnNodes> {
        let mut own = match &self.loop_file {
            Some(path) => super::loop_file::read(path)?,
            None => OwnNodes::default(),
        };
        let here = Path::new(".");
        for (flag, cmd, role) in
            [("--controller", &self.controller, Role::Controller), ("--detector", &self.detector, Role::Detector)]
        {
            let Some(cmd) = cmd else { continue };
            if let Some(file) = own.loop_file.as_ref().filter(|_| own.has(role)) {
                return Err(Error::flag(
                    flag,
                    format!(
                        "gives the {} a second time: {} names one (fix: drop {flag}, or its role from the file)",
                        role.process(),
                        file.path.display()
                    ),
                ));
            }
            let command = ForeignNode::split(cmd).map_err(|problem| Error::flag(flag, problem))?;
            let node = ForeignNode::new(role, None, command, NodeRun::default(), here)
                .map_err(|problem| Error::flag(flag, problem))?;
            match role {
                Role::Controller => own.controller = Some(node),
                _ => own.detector = Some(node),
            }
        }
        Ok(own)
    }

    /// [`OwnNodeArgs::nodes`] for a tool that runs each loop on a network of its own (`eval`):
    /// a node started elsewhere could not be waiting there, so the file is refused by its key.
    pub fn nodes_started_here(&self) -> Result<OwnNodes> {
        let own = self.nodes()?;
        if let (Some(sim), Some(file)) = (&own.simulator, &own.loop_file) {
            let key = if sim.elsewhere { "simulator.elsewhere" } else { "simulator.command" };
            return Err(slipstream_contract::config::ConfigError::new(
                file.path.display().to_string(),
                key,
                "a simulator of your own runs in `slipstream up` only: eval judges on slipstream's scenarios, which run in slipstream-sim",
                "drop `simulator` from the file for eval (or give it `builtin: true`)",
            )
            .into());
        }
        if let (Some(node), Some(file)) = (own.elsewhere(), &own.loop_file) {
            let key = match node.role {
                Role::Other => format!("others ({}).elsewhere", node.process()),
                role => format!("{}.elsewhere", role.process()),
            };
            return Err(slipstream_contract::config::ConfigError::new(
                file.path.display().to_string(),
                &key,
                "a node started elsewhere joins `slipstream up` only: eval runs each loop in a namespace and on ports of its own",
                "give the node's `command` in the loop file, so that eval starts it in every run",
            )
            .into());
        }
        Ok(own)
    }
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
        let args =
            OwnNodeArgs { controller: Some(format!("sh '{}' --gain 0.4", script.display())), ..OwnNodeArgs::default() };
        let nodes = args.nodes().unwrap();
        let c = nodes.controller.unwrap();
        assert_eq!(c.command[1], script.display().to_string());
        assert_eq!(c.command[2..], ["--gain", "0.4"]);
        assert_eq!(c.node(), "acc");
        // The program found on PATH, the script by its content, and the sources beside it.
        assert_eq!(c.files.len(), 3);
        assert!(c.files[0].path.ends_with("sh"));
        assert_eq!(c.files[1].sha256, "caf026f25d7140209f98072605307a438914b9ce6f3c14b23d15d9667241de52");
        assert!(c.files[2].path.ends_with("**/*.py"), "{:?}", c.files[2].path);
        assert!(nodes.detector.is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_command_that_cannot_run_is_refused_naming_the_flag() {
        let refused = |c: &str| {
            let args = OwnNodeArgs { detector: Some(c.into()), ..OwnNodeArgs::default() };
            args.nodes().unwrap_err().to_string()
        };
        assert!(refused("python3 'my acc.py").contains("--detector"), "{}", refused("python3 'my acc.py"));
        assert!(refused("").contains("no command line"));
        assert!(refused("no-such-program-here --x").contains("neither a file nor a program on PATH"));
    }

    #[test]
    fn a_flag_cannot_give_a_role_the_loop_file_gives() {
        let dir = dir_with("twice", &[("loop.json5", "{ controller: { builtin: true } }")]);
        let args = OwnNodeArgs {
            loop_file: Some(dir.join("loop.json5")),
            controller: Some("sh".into()),
            ..Default::default()
        };
        let e = args.nodes().unwrap_err().to_string();
        assert!(e.contains("--controller") && e.contains("second time") && e.contains("fix: "), "{e}");
        let args = OwnNodeArgs { controller: None, detector: Some("sh".into()), ..args };
        let own = args.nodes().unwrap();
        assert!(own.detector.is_some() && own.builtin.controller.is_some(), "other roles mix");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A directory of the test's own with `files` (name, text) in it.
    fn dir_with(test: &str, files: &[(&str, &str)]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("slipstream-own-args-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        dir
    }
}
