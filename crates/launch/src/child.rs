//! Child processes of the tools that start nodes (`slipstream up`, `slipstream eval acc`):
//! finding the node binaries, loopback ports for them, and stopping them the way Ctrl-C does.

use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// The binary `name` next to the running one (cargo puts them side by side).
pub fn sibling_binary(name: &str) -> Result<PathBuf> {
    let exe =
        std::env::current_exe().map_err(|source| Error::System { what: "find where this binary is".into(), source })?;
    let dir = exe.parent().unwrap_or(&exe);
    // Test binaries live one level further down (target/<profile>/deps).
    for d in [dir, dir.parent().unwrap_or(dir)] {
        let p = d.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(Error::NoBinary { name: name.to_string(), beside: exe })
}

/// `N` distinct free loopback TCP ports (bound together, released together; the children take
/// them right after). Released one at a time, the OS could hand out the same port twice.
pub fn free_ports<const N: usize>() -> Result<[u16; N]> {
    let port_error = |source| Error::System { what: "take a free loopback port".into(), source };
    let listeners: Vec<TcpListener> =
        (0..N).map(|_| TcpListener::bind("127.0.0.1:0")).collect::<Result<_, _>>().map_err(port_error)?;
    let mut ports = [0u16; N];
    for (p, l) in ports.iter_mut().zip(&listeners) {
        *p = l.local_addr().map_err(port_error)?.port();
    }
    Ok(ports)
}

/// Sends SIGINT (what Ctrl-C sends) to a process.
pub fn interrupt(pid: u32) {
    // SAFETY: kill(2) with a pid we started and a valid signal number has no memory effects.
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGINT);
    }
}

type SpawnRequest = (Command, std::sync::mpsc::Sender<std::io::Result<std::process::Child>>);

/// The thread that forks every child, started once and never ending before the process does.
fn spawner() -> &'static std::sync::Mutex<std::sync::mpsc::Sender<SpawnRequest>> {
    static SPAWNER: std::sync::OnceLock<std::sync::Mutex<std::sync::mpsc::Sender<SpawnRequest>>> =
        std::sync::OnceLock::new();
    SPAWNER.get_or_init(|| {
        let (tx, rx) = std::sync::mpsc::channel::<SpawnRequest>();
        let forker = move || {
            for (mut cmd, reply) in rx {
                let _ = reply.send(spawn_tied(&mut cmd));
            }
        };
        if let Err(e) = std::thread::Builder::new().name("spawner".into()).spawn(forker) {
            tracing::warn!("no spawner thread ({e}): children cannot be started");
        }
        std::sync::Mutex::new(tx)
    })
}

/// Forks `cmd` with the parent-death signal set (SIGTERM) in the child, and SIGINT and
/// SIGTERM at their default actions: a launcher started in the background (`cmd &`, nohup)
/// has SIGINT ignored, an ignored signal stays ignored across exec, and a node that cannot be
/// interrupted is killed at the end of its stop grace instead of closing (a Python node then
/// never closes its session; a shell cannot even trap it).
fn spawn_tied(cmd: &mut Command) -> std::io::Result<std::process::Child> {
    use std::os::unix::process::CommandExt as _;
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: between fork and exec only async-signal-safe calls (signal, prctl, getppid).
    unsafe {
        cmd.pre_exec(move || {
            for sig in [libc::SIGINT, libc::SIGTERM] {
                if libc::signal(sig, libc::SIG_DFL) == libc::SIG_ERR {
                    return Err(std::io::Error::last_os_error());
                }
            }
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The parent may have died before the signal was set up.
            if libc::getppid() != parent {
                return Err(std::io::Error::other("the launcher exited while starting this node"));
            }
            Ok(())
        });
    }
    cmd.spawn()
}

/// A node started as a child process; stopped (SIGINT, then killed) when dropped.
pub struct Child {
    pub name: String,
    child: std::process::Child,
    status: Option<ExitStatus>,
    /// SIGINT has been sent. It is sent once: a second one, by the convention of Ctrl-C pressed
    /// twice, cuts a node's own close short (a Python node then dies of the signal in its
    /// `finally`, its session left unclosed), so stopping after an interrupt only waits.
    interrupted: bool,
}

impl Child {
    /// Starts `cmd` so that it never outlives this process: should this process end without
    /// stopping it (killed with SIGKILL, a crash), the kernel sends the child SIGTERM, which
    /// every node takes as a request to stop (Linux's parent-death signal). The signal follows
    /// the *thread* that forked, so every child is forked by one thread that lives as long as
    /// the process ([`spawner`]): forked from a runtime's blocking thread, a node was stopped
    /// when that thread retired after 10 s idle.
    pub fn spawn(name: &str, cmd: &mut Command) -> Result<Child> {
        let cmd = std::mem::replace(cmd, Command::new(cmd.get_program()));
        let program = cmd.get_program().to_owned();
        let (tx, rx) = std::sync::mpsc::channel();
        let gone = || std::io::Error::other("the process spawner is gone");
        let sent = spawner().lock().map_err(|_| gone()).and_then(|s| s.send((cmd, tx)).map_err(|_| gone()));
        let child = sent
            .and_then(|()| rx.recv().map_err(|_| gone())?)
            .map_err(|source| Error::System { what: format!("start {name} ({program:?})"), source })?;
        Ok(Child { name: name.to_string(), child, status: None, interrupted: false })
    }
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The process's standard output, when it was piped and is not taken yet.
    pub fn take_stdout(&mut self) -> Option<std::process::ChildStdout> {
        self.child.stdout.take()
    }

    /// The exit status once the process has ended (reaped), else None.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        if self.status.is_none() {
            self.status = self.child.try_wait().ok().flatten();
        }
        self.status
    }

    /// Asks the process to stop (SIGINT) unless it has ended or has been asked already.
    pub fn interrupt(&mut self) {
        if self.exited().is_none() && !self.interrupted {
            self.interrupted = true;
            interrupt(self.pid());
        }
    }

    /// SIGINT (unless sent already), then up to `grace` for it to end, then SIGKILL. Returns
    /// the exit status.
    pub fn stop(&mut self, grace: Duration) -> Option<ExitStatus> {
        self.interrupt();
        if self.wait_for(grace).is_none() {
            tracing::warn!(node = %self.name, "did not stop on SIGINT within {grace:?}: killed");
            let _ = self.child.kill();
            self.status = self.child.wait().ok();
        }
        self.status
    }

    /// Waits up to `timeout` for the process to end.
    pub fn wait_for(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.exited() {
                return Some(s);
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(5));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A node slow to close after its SIGINT (a Python node closing its session) is waited
    /// for, not interrupted a second time: the shell counts the SIGINTs it got and exits with
    /// that count once its 0.4 s "close" is done.
    #[test]
    fn a_stop_after_an_interrupt_does_not_interrupt_again() {
        let script = "n=0; trap 'n=$((n+1))' INT; while [ $n -eq 0 ]; do sleep 0.02; done; sleep 0.4; exit $n";
        let mut child = Child::spawn("slow-close", Command::new("sh").args(["-c", script])).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        child.interrupt();
        std::thread::sleep(Duration::from_millis(100));
        let status = child.stop(Duration::from_secs(10)).expect("ended within the grace");
        assert_eq!(status.code(), Some(1), "SIGINTs received: {status:?}");
    }

    /// A launcher with SIGINT ignored (started with `&` or nohup) still starts nodes that a
    /// SIGINT stops: the shell traps it (a trap on a signal ignored at its start is refused).
    #[test]
    fn a_node_can_be_interrupted_when_its_launcher_ignores_sigint() {
        let script = "trap 'exit 7' INT; while :; do sleep 0.02; done";
        let mut cmd = Command::new("sh");
        cmd.args(["-c", script]);
        // The launcher's ignored SIGINT, as the child would inherit it, without touching this
        // test process's own handlers.
        // SAFETY: signal(2) is async-signal-safe; it runs between fork and exec, before ours.
        unsafe {
            use std::os::unix::process::CommandExt as _;
            cmd.pre_exec(|| {
                libc::signal(libc::SIGINT, libc::SIG_IGN);
                Ok(())
            });
        }
        let mut child = Child::spawn("ignoring-launcher", &mut cmd).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let status = child.stop(Duration::from_secs(10)).expect("ended within the grace");
        assert_eq!(status.code(), Some(7), "{status:?}");
    }
}
