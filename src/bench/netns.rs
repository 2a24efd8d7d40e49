//! A LAN on this machine for benchmarks: network namespaces ("hosts") joined by a bridge that
//! lives in a namespace of its own, each host with one veth link whose egress can be capped
//! (`tc tbf`, like a switch port of that speed). Every address exists only inside these
//! namespaces, and dropping the [`Lan`] deletes them (with their links and the bridge). Needs
//! root and iproute2; [`Lan::create`] says so when either is missing.

use std::process::Command;

use anyhow::{bail, Context, Result};

/// Hosts by role, on `<subnet>.0/24`, host i at `.i+1`.
pub struct Lan {
    /// Role -> namespace name.
    ns: Vec<(String, String)>,
    /// Role -> address.
    addr: Vec<(String, String)>,
    created: Vec<String>,
}

fn ip(args: &[&str]) -> Result<()> {
    let out = Command::new("ip").args(args).output().context("run `ip` (iproute2)")?;
    if !out.status.success() {
        bail!("`ip {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

impl Lan {
    /// Creates the hosts. `tag` makes the names unique to this run (a pid).
    pub fn create(tag: &str, roles: &[&str], subnet: &str) -> Result<Lan> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            bail!("`bench fleet` builds network namespaces: run it as root (e.g. sudo)");
        }
        let mut lan = Lan { ns: Vec::new(), addr: Vec::new(), created: Vec::new() };
        let switch = format!("{tag}-sw");
        ip(&["netns", "add", &switch])?;
        lan.created.push(switch.clone());
        ip(&["-n", &switch, "link", "add", "br0", "type", "bridge"])?;
        ip(&["-n", &switch, "link", "set", "br0", "up"])?;
        for (i, role) in roles.iter().enumerate() {
            let ns = format!("{tag}-{role}");
            let address = format!("{subnet}.{}", i + 1);
            ip(&["netns", "add", &ns])?;
            lan.created.push(ns.clone());
            let port = format!("p{i}");
            ip(&["-n", &switch, "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", &ns])?;
            ip(&["-n", &switch, "link", "set", &port, "master", "br0", "up"])?;
            ip(&["-n", &ns, "addr", "add", &format!("{address}/24"), "dev", "eth0"])?;
            ip(&["-n", &ns, "link", "set", "lo", "up"])?;
            ip(&["-n", &ns, "link", "set", "eth0", "up"])?;
            lan.ns.push((role.to_string(), ns));
            lan.addr.push((role.to_string(), address));
        }
        Ok(lan)
    }

    fn get<'a>(list: &'a [(String, String)], role: &str) -> &'a str {
        list.iter().find(|(r, _)| r == role).map(|(_, v)| v.as_str()).expect("a role of this LAN")
    }

    pub fn addr(&self, role: &str) -> &str {
        Self::get(&self.addr, role)
    }

    /// Caps what a host sends at `mbit_s` (a token bucket on its link: a port of that speed).
    pub fn cap(&self, role: &str, mbit_s: u32) -> Result<()> {
        // The bucket holds at least 10 ms of the rate (and 64 KiB): tbf needs rate / HZ.
        let burst_kb = (mbit_s as u64 * 1000 / 8 / 100).max(64);
        let out = Command::new("ip")
            .args(["netns", "exec", Self::get(&self.ns, role), "tc", "qdisc", "replace", "dev", "eth0", "root", "tbf"])
            .args(["rate", &format!("{mbit_s}mbit"), "burst", &format!("{burst_kb}kb"), "latency", "50ms"])
            .output()
            .context("run `tc` (iproute2)")?;
        if !out.status.success() {
            bail!("capping {role} at {mbit_s} Mbit/s failed: {}", String::from_utf8_lossy(&out.stderr).trim());
        }
        Ok(())
    }

    /// A command that runs `program` on a host (`ip netns exec` execs it: the child's pid is
    /// the program's own).
    pub fn command(&self, role: &str, program: &std::path::Path) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", Self::get(&self.ns, role)]).arg(program);
        c
    }
}

impl Drop for Lan {
    fn drop(&mut self) {
        for ns in self.created.drain(..).rev() {
            let _ = ip(&["netns", "del", &ns]);
        }
    }
}
