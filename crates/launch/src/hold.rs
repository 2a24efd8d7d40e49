//! A loop's hold on a namespace on this machine: a lock file per namespace, held for the run.
//!
//! Liveliness tokens show a loop to another only once the two sessions are linked, and in
//! peer mode a session learns the rest of the mesh through gossip, after it opened: two `up`
//! started a moment apart could each find a namespace free. The lock cannot race: the first to
//! take `<namespace>.lock` holds it until its process ends (the kernel drops the lock even on
//! SIGKILL). Loops meet only within one network namespace (loopback), so the lock directory
//! is per network namespace and per user: loops in another network namespace (a test host, a
//! container) never block each other. Nor do loops that cannot meet in one network namespace:
//! the lock is per meeting point too (the endpoints the config dials and listens on, besides
//! ports the kernel picks), so a loop on a rendezvous of its own (`-l`/`-e` elsewhere, a test)
//! takes the default namespace beside a loop on the machine's rendezvous.

use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::PathBuf;

use crate::error::{Error, Result};

/// A held namespace: the lock goes with this value (or with the process).
#[derive(Debug)]
pub(crate) struct Hold {
    _file: Option<std::fs::File>,
}

/// What an attempt at a namespace's hold got.
#[derive(Debug)]
pub(crate) enum Attempt {
    /// The hold, this process's until it is dropped.
    Held(Hold),
    /// Another process holds it: what that process wrote (its pid and command line).
    TakenBy(String),
}

/// Where sessions with `config` meet others: the endpoints it dials and listens on, sorted,
/// leaving out `own` (a listener of the run's own) and ports the kernel picks (`:0`).
pub(crate) fn meeting_point(config: &zenoh::Config, own: &str) -> Vec<String> {
    let list = |key: &str| -> Vec<String> {
        config.get_json(key).ok().and_then(|v| serde_json::from_str::<Vec<String>>(&v).ok()).unwrap_or_default()
    };
    let mut all: Vec<String> = list("connect/endpoints").into_iter().chain(list("listen/endpoints")).collect();
    all.retain(|e| e != own && !e.ends_with(":0"));
    // Peers that scout by multicast meet without an endpoint.
    if config.get_json("scouting/multicast/enabled").is_ok_and(|v| v.trim() == "true") {
        let group = config.get_json("scouting/multicast/address").unwrap_or_default();
        all.push(format!("multicast {}", group.trim_matches('"')));
    }
    all.sort();
    all.dedup();
    all
}

/// Takes the hold of `namespace` ("" for the default one) at `meeting` ([`meeting_point`]),
/// or says who has it.
pub(crate) fn take(namespace: &str, meeting: &[String]) -> Result<Attempt> {
    // Dialling nothing, listening on kernel-picked ports only, scouting by no multicast: no
    // other loop can meet this one, and it needs no hold.
    if meeting.is_empty() {
        return Ok(Attempt::Held(Hold { _file: None }));
    }
    let dir = lock_dir();
    std::fs::create_dir_all(&dir).map_err(Error::file("create", &dir))?;
    let path = dir.join(file_name(namespace, meeting));
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(Error::file("open", &path))?;
    // SAFETY: flock on a descriptor this function owns; no memory is shared.
    if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        return Ok(Attempt::TakenBy(holder.trim().to_string()));
    }
    let me = format!("pid {}: {}", std::process::id(), std::env::args().collect::<Vec<_>>().join(" "));
    let written = file.set_len(0).and_then(|()| file.rewind()).and_then(|_| file.write_all(me.as_bytes()));
    written.map_err(Error::file("write", &path))?;
    Ok(Attempt::Held(Hold { _file: Some(file) }))
}

/// `<temp>/slipstream-<uid>/net-<network namespace inode>`.
fn lock_dir() -> PathBuf {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let net = std::fs::metadata("/proc/self/ns/net").map_or_else(|_| "unknown".to_string(), |m| m.ino().to_string());
    std::env::temp_dir().join(format!("slipstream-{uid}")).join(format!("net-{net}")).join("namespaces")
}

/// The lock file of a namespace at a meeting point: `_default@<hash>.lock`, `car1@<hash>.lock`,
/// `lab%rig2@<hash>.lock` (the hash names the endpoints; a file name holds no `/`).
fn file_name(namespace: &str, meeting: &[String]) -> String {
    use sha2::Digest;
    let at: String =
        sha2::Sha256::digest(meeting.join(" ").as_bytes()).iter().take(6).map(|b| format!("{b:02x}")).collect();
    match namespace {
        "" => format!("_default@{at}.lock"),
        ns => format!("{}@{at}.lock", ns.replace('/', "%")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_namespace_is_held_once_and_free_again_when_its_hold_goes() {
        let ns = format!("hold-test-{}", std::process::id());
        let here = ["tcp/127.0.0.1:7447".to_string()];
        let Attempt::Held(first) = take(&ns, &here).unwrap() else { panic!("free at first") };
        let elsewhere = ["tcp/127.0.0.1:17447".to_string()];
        let Attempt::Held(_beside) = take(&ns, &elsewhere).unwrap() else { panic!("another meeting point is free") };
        let Attempt::TakenBy(holder) = take(&ns, &here).unwrap() else { panic!("held by the first") };
        assert!(holder.starts_with(&format!("pid {}: ", std::process::id())), "{holder}");
        drop(first);
        assert!(matches!(take(&ns, &here).unwrap(), Attempt::Held(_)), "free once the hold is dropped");
        assert!(file_name("lab/rig2", &here).starts_with("lab%rig2@"), "{}", file_name("lab/rig2", &here));
        assert!(file_name("", &here).starts_with("_default@") && file_name("", &here).ends_with(".lock"));
        assert!(
            matches!(take(&ns, &[]).unwrap(), Attempt::Held(_)) && matches!(take(&ns, &[]).unwrap(), Attempt::Held(_))
        );
    }

    #[test]
    fn the_meeting_point_is_what_others_can_dial_not_what_the_kernel_picks() {
        let mut c = zenoh::Config::from_json5(slipstream_contract::config::DEFAULT_ZENOH_CONFIG).unwrap();
        assert_eq!(meeting_point(&c, "tcp/127.0.0.1:12001"), ["tcp/127.0.0.1:7447"]);
        c.insert_json5("connect/endpoints", "[]").unwrap();
        c.insert_json5("listen/endpoints", r#"["tcp/127.0.0.1:0", "tcp/127.0.0.1:12001"]"#).unwrap();
        assert!(meeting_point(&c, "tcp/127.0.0.1:12001").is_empty(), "a loop of its own meets nobody");
        c.insert_json5("scouting/multicast/enabled", "true").unwrap();
        assert_eq!(meeting_point(&c, "tcp/127.0.0.1:12001").len(), 1, "multicast scouting meets others");
    }
}
