//! Test helpers, in one place: loopback sessions with scouting off, timeouts on every await,
//! the binaries without the user's settings, free ports, scratch directories, and child
//! processes killed when a test ends.

use std::time::Duration;

use slipstream::{Bus, TopicMap};

/// Every await in a test gets this long before the test fails instead of hanging CI.
pub(crate) const TIMEOUT: Duration = Duration::from_secs(20);

#[macro_export]
macro_rules! within {
    ($fut:expr) => {
        tokio::time::timeout($crate::common::TIMEOUT, $fut).await.expect("timed out")
    };
}

/// Tests that run whole loops, realtime simulators or the node binaries take this: one at a
/// time, or on two cores they starve each other (and the realtime pacing some of them need).
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

pub(crate) fn serial() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn base_config() -> zenoh::Config {
    let mut c = zenoh::Config::default();
    for (k, v) in [("mode", "\"peer\""), ("scouting/multicast/enabled", "false"), ("scouting/gossip/enabled", "true")] {
        c.insert_json5(k, v).unwrap();
    }
    c
}

/// A session listening on an OS-chosen loopback port.
pub(crate) async fn listening_session() -> (zenoh::Session, String) {
    let mut c = base_config();
    c.insert_json5("listen/endpoints", r#"["tcp/127.0.0.1:0"]"#).unwrap();
    let s = zenoh::open(c).await.unwrap();
    let ep = s.info().locators().await.first().expect("a locator").to_string();
    (s, ep)
}

/// A session that connects to `endpoint`.
pub(crate) async fn connected_session(endpoint: &str) -> zenoh::Session {
    let mut c = base_config();
    c.insert_json5("listen/endpoints", "[]").unwrap();
    c.insert_json5("connect/endpoints", &format!(r#"["{endpoint}"]"#)).unwrap();
    zenoh::open(c).await.unwrap()
}

/// Two buses on two sessions joined over tcp/127.0.0.1.
pub(crate) async fn bus_pair(a: TopicMap, b: TopicMap) -> (Bus, Bus) {
    let (s1, ep) = listening_session().await;
    let s2 = connected_session(&ep).await;
    (Bus::from_session(s1, a, "node-a").await.unwrap(), Bus::from_session(s2, b, "node-b").await.unwrap())
}

pub(crate) fn map(json5: &str) -> TopicMap {
    TopicMap::from_json5(json5, "test config").unwrap()
}

/// Runs a command with a deadline; kills it and fails the test if it overruns.
pub(crate) fn run_with_limit(mut cmd: std::process::Command, limit: Duration) -> std::process::Output {
    let child = cmd.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
    wait_with_limit(child, limit, &format!("{cmd:?}"))
}

/// Waits for a started child's output with a deadline; kills it and fails the test if it
/// overruns.
pub(crate) fn wait_with_limit(child: std::process::Child, limit: Duration, what: &str) -> std::process::Output {
    let id = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(limit) {
        Ok(out) => out.unwrap(),
        Err(_) => {
            let _ = std::process::Command::new("kill").arg("-9").arg(id.to_string()).status();
            panic!("{what} ran longer than {limit:?}");
        }
    }
}

/// Every .rs file under `dir`, recursively.
pub(crate) fn rust_files(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The default Zenoh config (config/zenoh.json5) without its rendezvous: it dials nothing and
/// listens on a port the kernel picks, so a test's processes meet only whom the test connects
/// them to (`-e`, `-l`, or `up`'s own links to its nodes), never a loop a developer left
/// running on the machine's rendezvous port. Written once per test process.
pub(crate) fn hermetic_zenoh_config() -> &'static std::path::Path {
    static PATH: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let default = slipstream::config::DEFAULT_ZENOH_CONFIG;
        let (dial, listen) =
            (r#"endpoints: ["tcp/127.0.0.1:7447"],"#, r#"endpoints: ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:0"],"#);
        assert!(
            default.contains(dial) && default.contains(listen),
            "config/zenoh.json5's rendezvous moved: update this"
        );
        let own = default.replace(listen, r#"endpoints: ["tcp/127.0.0.1:0"],"#).replace(dial, "endpoints: [],");
        let path = std::env::temp_dir().join(format!("slipstream-it-{}-zenoh.json5", std::process::id()));
        std::fs::write(&path, own).unwrap();
        path
    })
}

/// A binary of this build (`slipstream`, `slipstream-sim`, `slipstream-detect`,
/// `slipstream-acc`), with none of the caller's settings (no RUST_LOG, no SLIPSTREAM_*) and
/// the [`hermetic_zenoh_config`] in their place, which `-c` overrides.
pub(crate) fn bin(name: &str) -> std::process::Command {
    let path = match name {
        "slipstream" => env!("CARGO_BIN_EXE_slipstream"),
        "slipstream-sim" => env!("CARGO_BIN_EXE_slipstream-sim"),
        "slipstream-detect" => env!("CARGO_BIN_EXE_slipstream-detect"),
        "slipstream-acc" => env!("CARGO_BIN_EXE_slipstream-acc"),
        other => panic!("no binary {other}"),
    };
    let mut c = std::process::Command::new(path);
    c.env_remove("RUST_LOG");
    for (var, _) in std::env::vars_os() {
        if var.to_string_lossy().starts_with("SLIPSTREAM_") {
            c.env_remove(var);
        }
    }
    c.env("SLIPSTREAM_ZENOH_CONFIG", hermetic_zenoh_config());
    c
}

/// A loopback port free at the time of asking, never given to another test of this process.
/// Taken from below the kernel's ephemeral range (32768 and up by default), where no port-0
/// listener and no outgoing connection of a process started meanwhile can take it before the
/// test's own process binds it (a test's node would then dial another test's loop). The Python
/// tests take theirs from 20000 up (tests/python/conftest.py).
pub(crate) fn free_port() -> u16 {
    use std::sync::atomic::{AtomicU16, Ordering};
    const FIRST: u16 = 12_000;
    const COUNT: u16 = 8_000;
    static NEXT: AtomicU16 = AtomicU16::new(0);
    for _ in 0..COUNT {
        let port = FIRST + NEXT.fetch_add(1, Ordering::Relaxed) % COUNT;
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
    panic!("no free loopback port in {FIRST}..{}", FIRST + COUNT)
}

#[test]
fn the_ports_given_are_distinct_and_below_the_ephemeral_range() {
    let ports: std::collections::BTreeSet<u16> = (0..50).map(|_| free_port()).collect();
    assert_eq!(ports.len(), 50);
    assert!(ports.iter().all(|p| (12_000..32_768).contains(p)), "{ports:?}");
}

/// The Zenoh endpoint of a loopback port.
pub(crate) fn ep(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// An empty scratch directory of this test process's own, named `name`.
pub(crate) fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("slipstream-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A child process killed and reaped when the test ends, passed or failed.
pub(crate) struct Killed(pub std::process::Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}
