//! A LAN on this machine for benchmarks: network namespaces ("hosts") joined by a bridge that
//! lives in a namespace of its own, each host with one veth link whose egress can be capped
//! (`tc tbf`, like a switch port of that speed). Every address exists only inside these
//! namespaces, and dropping the [`Lan`] deletes them (with their links and the bridge). Needs
//! root and iproute2; [`Lan::create`] says so when either is missing.

use std::process::Command;

use anyhow::{bail, Context, Result};

/// Hosts by role on one or several subnets (`<prefix>.0/24`).
pub(crate) struct Lan {
    /// Role -> namespace name.
    ns: Vec<(String, String)>,
    /// `role@prefix` -> the host's address on that subnet.
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
    /// Creates the hosts on one subnet. `tag` makes the names unique to this run (a pid).
    pub(crate) fn create(tag: &str, roles: &[&str], subnet: &str) -> Result<Lan> {
        Lan::create_subnets(tag, &[(subnet, roles)])
    }

    /// Creates several subnets, each a bridge of its own: `(prefix, roles)`, role i of a subnet
    /// at `<prefix>.i+1`. A role on several subnets is one host with a leg (eth0, eth1, ...) on
    /// each (a router between subnets); [`Lan::addr_on`] gives its address on each.
    pub(crate) fn create_subnets(tag: &str, subnets: &[(&str, &[&str])]) -> Result<Lan> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            bail!("`bench fleet` builds network namespaces: run it as root (e.g. sudo)");
        }
        let mut lan = Lan { ns: Vec::new(), addr: Vec::new(), created: Vec::new() };
        let switch = format!("{tag}-sw");
        ip(&["netns", "add", &switch])?;
        lan.created.push(switch.clone());
        let mut legs: Vec<(String, usize)> = Vec::new();
        for (b, (prefix, roles)) in subnets.iter().enumerate() {
            let bridge = format!("br{b}");
            ip(&["-n", &switch, "link", "add", &bridge, "type", "bridge"])?;
            ip(&["-n", &switch, "link", "set", &bridge, "up"])?;
            for (i, role) in roles.iter().enumerate() {
                let ns = format!("{tag}-{role}");
                let leg = match legs.iter_mut().find(|(r, _)| r == role) {
                    Some((_, n)) => {
                        *n += 1;
                        *n
                    }
                    None => {
                        ip(&["netns", "add", &ns])?;
                        lan.created.push(ns.clone());
                        ip(&["-n", &ns, "link", "set", "lo", "up"])?;
                        lan.ns.push((role.to_string(), ns.clone()));
                        legs.push((role.to_string(), 0));
                        0
                    }
                };
                let (port, dev, address) = (format!("p{b}-{i}"), format!("eth{leg}"), format!("{prefix}.{}", i + 1));
                ip(&["-n", &switch, "link", "add", &port, "type", "veth", "peer", "name", &dev, "netns", &ns])?;
                ip(&["-n", &switch, "link", "set", &port, "master", &bridge, "up"])?;
                ip(&["-n", &ns, "addr", "add", &format!("{address}/24"), "dev", &dev])?;
                ip(&["-n", &ns, "link", "set", &dev, "up"])?;
                lan.addr.push((format!("{role}@{prefix}"), address));
            }
        }
        Ok(lan)
    }

    /// A host's address on the subnet `prefix`.
    pub(crate) fn addr_on(&self, role: &str, prefix: &str) -> &str {
        Self::get(&self.addr, &format!("{role}@{prefix}"))
    }

    fn get<'a>(list: &'a [(String, String)], role: &str) -> &'a str {
        list.iter().find(|(r, _)| r == role).map(|(_, v)| v.as_str()).expect("a role of this LAN")
    }

    /// Caps what a host sends at `mbit_s` on each of its legs (a token bucket on each link: a
    /// port of that speed).
    pub(crate) fn cap(&self, role: &str, mbit_s: u32) -> Result<()> {
        // The bucket holds at least 10 ms of the rate (and 64 KiB): tbf needs rate / HZ.
        let burst_kb = (mbit_s as u64 * 1000 / 8 / 100).max(64);
        let legs = self.addr.iter().filter(|(r, _)| r.starts_with(&format!("{role}@"))).count();
        for leg in 0..legs {
            let out = Command::new("ip")
                .args(["netns", "exec", Self::get(&self.ns, role), "tc", "qdisc", "replace", "dev"])
                .args([&format!("eth{leg}"), "root", "tbf", "rate", &format!("{mbit_s}mbit")])
                .args(["burst", &format!("{burst_kb}kb"), "latency", "50ms"])
                .output()
                .context("run `tc` (iproute2)")?;
            if !out.status.success() {
                bail!("capping {role} at {mbit_s} Mbit/s failed: {}", String::from_utf8_lossy(&out.stderr).trim());
            }
        }
        Ok(())
    }

    /// A command that runs `program` on a host (`ip netns exec` execs it: the child's pid is
    /// the program's own).
    pub(crate) fn command(&self, role: &str, program: &std::path::Path) -> Command {
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
