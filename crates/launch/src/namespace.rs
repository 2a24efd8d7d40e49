//! Which namespace a loop started with the user's flags runs in, so that two loops on one host
//! never mix.
//!
//! Every peer on a machine meets every other through the rendezvous port, so a second `up` in
//! the same namespace would join the first one's keys: its simulator would apply the other
//! loop's controls and both reports would merge each other's topics. Before anything starts,
//! the launcher lists the nodes alive on the bus (their liveliness tokens, in every namespace)
//! and compares them with the nodes this run brings. A name both have is a clash:
//! - in a namespace the user chose (`-n`, or the topic config's `namespace`), the run refuses,
//!   naming the nodes already there;
//! - in the default namespace, the run moves to the first free `loop-N` (N = 2, 3, ...) and
//!   says so, so that `slipstream top -n loop-N` finds it.
//!
//! A run whose simulator is someone else's (`up --sim external`) expects a `sim` there and
//! cannot move away from it: a clash on its other nodes refuses.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use super::hold::{Attempt, Hold};
use crate::error::{Error, Result};

use slipstream_contract::topics::NODES_PREFIX;
use slipstream_contract::TopicMap;

/// How long the launcher asks the bus for the nodes alive. The replies come from sessions
/// already connected (opening a session waits for its peers' declarations): milliseconds.
const ASK_TIMEOUT: Duration = Duration::from_secs(1);
/// The namespaces a second, third, ... loop moves to: `loop-2` to `loop-<MAX_LOOPS>`.
const MAX_LOOPS: u32 = 64;
/// How often, how many times at most, and for how many polls unchanged the launcher watches
/// its count of peers settle before asking for the nodes alive (about 0.2 s on one machine).
const SETTLE_POLL: Duration = Duration::from_millis(100);
const SETTLE_POLLS: u32 = 15;
const SETTLED_AFTER: u32 = 2;

/// The namespace the run got, and whether it moved there from the default one.
pub(crate) struct Claimed {
    pub map: TopicMap,
    /// Set when the default namespace held another loop: the namespace moved to.
    pub moved_to: Option<String>,
    /// Why the default namespace was taken, when the run moved ("its nodes acc, sim are
    /// alive", "`up` (pid 42: slipstream up) holds it").
    pub beside: String,
    /// The run's hold on its namespace on this machine (none for an isolated loop).
    pub hold: Option<Hold>,
}

/// Claims `map`'s namespace for a run that brings the nodes `ours`, or moves (see the module
/// doc); `meeting` is where the run's sessions meet others ([`super::hold::meeting_point`]). `expected_here`: a node not ours (the simulator with `--sim external`, a node of a
/// loop file started elsewhere) waits in the namespace, so the run cannot move.
pub(crate) async fn claim(
    session: &zenoh::Session,
    map: TopicMap,
    ours: &[&str],
    expected_here: bool,
    meeting: &[String],
) -> Result<Claimed> {
    settle(session).await;
    let alive = nodes_by_namespace(session).await?;
    let taken_by = |ns: &str| -> Result<Attempt> {
        let alive_here = alive.get(ns);
        let here: Vec<&str> =
            alive_here.map_or(Vec::new(), |n| n.iter().map(String::as_str).filter(|n| ours.contains(n)).collect());
        if !here.is_empty() {
            return Ok(Attempt::TakenBy(format!("its nodes {} are alive", here.join(", "))));
        }
        // A replay plays a recorded loop's topics there: a live loop beside it would read them.
        if let Some(player) = alive_here.and_then(|n| n.iter().find(|n| is_player(n))) {
            return Ok(Attempt::TakenBy(format!("a recording is playing there (`{player}`)")));
        }
        Ok(match super::hold::take(ns, meeting)? {
            Attempt::TakenBy(holder) => Attempt::TakenBy(format!("`up` ({holder}) holds it")),
            held => held,
        })
    };
    let why = match taken_by(map.namespace())? {
        Attempt::Held(hold) => return Ok(Claimed { map, moved_to: None, beside: String::new(), hold: Some(hold) }),
        Attempt::TakenBy(why) => why,
    };
    if !map.namespace().is_empty() || expected_here {
        let shown = if map.namespace().is_empty() {
            "the default namespace".to_string()
        } else {
            format!("namespace `{}`", map.namespace())
        };
        return Err(Error::Refused(format!(
            "a loop is already running in {shown} ({why}): this one would mix with it (fix: stop it, or give this run a namespace of its own with -n NAME; `slipstream top -n NAME` then watches it)"
        )));
    }
    for ns in (2..=MAX_LOOPS).map(|n| format!("loop-{n}")) {
        if let Attempt::Held(hold) = taken_by(&ns)? {
            return Ok(Claimed { map: map.with_namespace(&ns)?, moved_to: Some(ns), beside: why, hold: Some(hold) });
        }
    }
    Err(Error::Refused(format!(
        "loop-2 to loop-{MAX_LOOPS} all hold loops (fix: give this run a namespace of its own with -n NAME)"
    )))
}

/// The node name of `slipstream play` (`play-<pid>`), which a loop must not share a namespace
/// with.
pub const PLAYER: &str = "play";

fn is_player(node: &str) -> bool {
    node.strip_prefix(PLAYER).is_some_and(|rest| rest.starts_with('-'))
}

/// The nodes alive in `namespace` ("" for the default one), once gossip has linked this
/// session to the peers it learned of.
pub async fn nodes_alive_in(session: &zenoh::Session, namespace: &str) -> Result<BTreeSet<String>> {
    settle(session).await;
    Ok(nodes_by_namespace(session).await?.remove(namespace).unwrap_or_default())
}

/// Lets gossip link this session to the peers it learned of when it opened, so that the
/// question for the nodes alive reaches each of them (a peer answers for its own tokens only):
/// waits until the count of peers has not changed for [`SETTLED_AFTER`] polls, at most
/// [`SETTLE_POLLS`].
async fn settle(session: &zenoh::Session) {
    let mut last = usize::MAX;
    let mut unchanged = 0;
    for _ in 0..SETTLE_POLLS {
        let peers = session.info().peers_zid().await.count();
        unchanged = if peers == last { unchanged + 1 } else { 0 };
        if unchanged >= SETTLED_AFTER {
            return;
        }
        last = peers;
        tokio::time::sleep(SETTLE_POLL).await;
    }
}

/// Every node alive on the bus, by namespace ("" for the default one).
async fn nodes_by_namespace(session: &zenoh::Session) -> Result<BTreeMap<String, BTreeSet<String>>> {
    let selector = format!("**/{NODES_PREFIX}/*");
    let replies = session
        .liveliness()
        .get(&selector)
        .timeout(ASK_TIMEOUT)
        .await
        .map_err(Error::zenoh("ask the bus for the nodes alive"))?;
    let mut alive: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            if let Some((ns, name)) = split_node_key(sample.key_expr().as_str()) {
                alive.entry(ns.to_string()).or_default().insert(name.to_string());
            }
        }
    }
    Ok(alive)
}

/// `lab/rig2/nodes/sim` -> ("lab/rig2", "sim"); `nodes/sim` -> ("", "sim").
fn split_node_key(key: &str) -> Option<(&str, &str)> {
    let marker = format!("{NODES_PREFIX}/");
    let (ns, name) = match key.strip_prefix(&marker) {
        Some(name) => ("", name),
        None => {
            let at = key.rfind(&format!("/{marker}"))?;
            (&key[..at], &key[at + marker.len() + 1..])
        }
    };
    (!name.is_empty() && !name.contains('/')).then_some((ns, name))
}

#[cfg(test)]
mod tests {
    use super::{is_player, split_node_key};

    #[test]
    fn a_player_is_known_by_its_name() {
        assert!(is_player("play-4242"));
        assert!(!is_player("player") && !is_player("play") && !is_player("sim"));
    }

    #[test]
    fn a_token_key_splits_into_namespace_and_node() {
        assert_eq!(split_node_key("nodes/sim"), Some(("", "sim")));
        assert_eq!(split_node_key("lab/rig2/nodes/acc"), Some(("lab/rig2", "acc")));
        assert_eq!(split_node_key("loop-2/nodes/up"), Some(("loop-2", "up")));
        assert_eq!(split_node_key("nodes/acc/inputs"), None);
        assert_eq!(split_node_key("vehicle/speed"), None);
    }
}
