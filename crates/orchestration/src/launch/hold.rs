//! A loop's hold on a namespace on this machine: a lock file per namespace, held for the run.
//!
//! Liveliness tokens show a loop to another only once the two sessions are linked, and in
//! peer mode a session learns the rest of the mesh through gossip, after it opened: two `up`
//! started a moment apart could each find a namespace free. The lock cannot race: the first to
//! take `<namespace>.lock` holds it until its process ends (the kernel drops the lock even on
//! SIGKILL). Loops meet only within one network namespace (loopback), so the lock directory
//! is per network namespace and per user: loops in another network namespace (a test host, a
//! container) never block each other.

use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::PathBuf;

use crate::error::{Error, Result};

/// A held namespace: the lock goes with this value (or with the process).
#[derive(Debug)]
pub(crate) struct Hold {
    _file: std::fs::File,
}

/// What an attempt at a namespace's hold got.
#[derive(Debug)]
pub(crate) enum Attempt {
    /// The hold, this process's until it is dropped.
    Held(Hold),
    /// Another process holds it: what that process wrote (its pid and command line).
    TakenBy(String),
}

/// Takes the hold of `namespace` ("" for the default one), or says who has it.
pub(crate) fn take(namespace: &str) -> Result<Attempt> {
    let dir = lock_dir();
    std::fs::create_dir_all(&dir).map_err(Error::file("create", &dir))?;
    let path = dir.join(file_name(namespace));
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
    Ok(Attempt::Held(Hold { _file: file }))
}

/// `<temp>/slipstream-<uid>/net-<network namespace inode>`.
fn lock_dir() -> PathBuf {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let net = std::fs::metadata("/proc/self/ns/net").map_or_else(|_| "unknown".to_string(), |m| m.ino().to_string());
    std::env::temp_dir().join(format!("slipstream-{uid}")).join(format!("net-{net}")).join("namespaces")
}

/// The lock file of a namespace: `_default.lock`, `car1.lock`, `lab%rig2.lock`.
fn file_name(namespace: &str) -> String {
    match namespace {
        "" => "_default.lock".to_string(),
        ns => format!("{}.lock", ns.replace('/', "%")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_namespace_is_held_once_and_free_again_when_its_hold_goes() {
        let ns = format!("hold-test-{}", std::process::id());
        let Attempt::Held(first) = take(&ns).unwrap() else { panic!("free at first") };
        let Attempt::TakenBy(holder) = take(&ns).unwrap() else { panic!("held by the first") };
        assert!(holder.starts_with(&format!("pid {}: ", std::process::id())), "{holder}");
        drop(first);
        assert!(matches!(take(&ns).unwrap(), Attempt::Held(_)), "free once the hold is dropped");
        assert_eq!(file_name("lab/rig2"), "lab%rig2.lock");
        assert_eq!(file_name(""), "_default.lock");
    }
}
