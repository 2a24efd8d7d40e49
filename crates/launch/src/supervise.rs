//! A node process of the loop under its restart policy (a loop file's `restart`): ended on a
//! failure, it is started again after the backoff, up to the limit, with the same command and
//! its log continued; the restarts are counted for the report. Only once it ends for good
//! does the loop hear of its end. Our simulator is never restarted: its end is the run's.

use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use super::child::Child;
use super::foreign::{NodeRun, RestartPolicy};
use super::DEFAULT_RUST_LOG;
use crate::error::{Error, Result};

/// A node process, its command kept to start it again.
pub struct Supervised {
    child: Child,
    command: Command,
    pub run: NodeRun,
    /// Its stderr; stdout goes to `out`.
    pub log: PathBuf,
    pub out: PathBuf,
    /// How often it was started again.
    pub restarts: u32,
    /// When the pending restart is due.
    due: Option<Instant>,
    /// Stopping: no more restarts.
    stopping: bool,
}

/// What a node is doing.
pub enum State {
    Running,
    /// Ended on a failure; started again once the backoff has passed.
    Restarting,
    /// Ended for good.
    Ended(ExitStatus),
}

impl Supervised {
    /// Starts `command` as `name` with its run's environment and directory: stderr to `log`,
    /// stdout to `out` (both created afresh), the default RUST_LOG unless the user set one,
    /// faults never inherited (a loop's come as a flag).
    pub fn start(name: &str, mut command: Command, run: NodeRun, log: PathBuf, out: PathBuf) -> Result<Supervised> {
        run.apply(&mut command);
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", DEFAULT_RUST_LOG);
        }
        command.env_remove("SLIPSTREAM_FAULTS");
        let child = spawn(name, &command, &log, &out, false)?;
        Ok(Supervised { child, command, run, log, out, restarts: 0, due: None, stopping: false })
    }

    pub fn name(&self) -> &str {
        &self.child.name
    }

    pub fn pid(&self) -> u32 {
        self.child.pid()
    }

    /// Its state now: a due restart is made here.
    pub fn poll(&mut self) -> State {
        if let Some(due) = self.due {
            if Instant::now() < due {
                return State::Restarting;
            }
            self.due = None;
            self.restarts += 1;
            let note = format!(
                "--- started again by the loop (restart {} of {}) ---\n",
                self.restarts, self.run.restart.limit
            );
            let _ = OpenOptions::new().append(true).open(&self.log).and_then(|mut f| {
                use std::io::Write as _;
                f.write_all(note.as_bytes())
            });
            match spawn(&self.child.name, &self.command, &self.log, &self.out, true) {
                Ok(child) => self.child = child,
                Err(e) => tracing::warn!(node = %self.child.name, "could not be started again: {e}"),
            }
        }
        let Some(status) = self.child.exited() else { return State::Running };
        let r = &self.run.restart;
        let again = r.policy == RestartPolicy::OnFailure && !status.success() && self.restarts < r.limit;
        if again && !self.stopping {
            tracing::warn!(node = %self.child.name, %status, "ended; starting it again in {} s", r.backoff_s);
            self.due = Some(Instant::now() + Duration::from_secs_f64(r.backoff_s));
            return State::Restarting;
        }
        State::Ended(status)
    }

    /// Its exit status once it has ended for good.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        match self.poll() {
            State::Ended(s) => Some(s),
            _ => None,
        }
    }

    /// Waits up to `timeout` for it to end by itself (no restart is waited for).
    pub fn wait_for(&mut self, timeout: Duration) -> Option<ExitStatus> {
        self.child.wait_for(timeout)
    }

    /// Asks it to stop (SIGINT); no restart follows.
    pub fn interrupt(&mut self) {
        self.stopping = true;
        self.due = None;
        self.child.interrupt();
    }

    /// SIGINT, then up to `grace`, then SIGKILL; no restart follows.
    pub fn stop(&mut self, grace: Duration) -> Option<ExitStatus> {
        self.stopping = true;
        self.due = None;
        self.child.stop(grace)
    }
}

/// One start of the command, its output to the node's files (appended to on a restart).
fn spawn(name: &str, command: &Command, log: &Path, out: &Path, append: bool) -> Result<Child> {
    let open = |path: &Path| {
        let mut o = OpenOptions::new();
        match append {
            true => o.append(true).create(true),
            false => o.write(true).create(true).truncate(true),
        };
        o.open(path).map_err(Error::file("create", path))
    };
    let mut cmd = again(command);
    cmd.stdin(Stdio::null()).stdout(open(out)?).stderr(open(log)?);
    Child::spawn(name, &mut cmd)
}

/// A command like `command`: program, arguments, environment, directory.
fn again(command: &Command) -> Command {
    let mut cmd = Command::new(command.get_program());
    cmd.args(command.get_args());
    for (k, v) in command.get_envs() {
        match v {
            Some(v) => cmd.env(k, v),
            None => cmd.env_remove(k),
        };
    }
    if let Some(dir) = command.get_current_dir() {
        cmd.current_dir(dir);
    }
    cmd
}
