//! Two nodes under one name in one namespace publish on the same keys with the same
//! attachment: every subscriber takes them for one node, and a lockstep simulator counts one
//! answer for two. Nothing else on the bus can tell them apart, so a node about to announce
//! itself asks first whether its token is already alive, and says so with the fix. A warning,
//! not a refusal (as ROS 2 does for duplicate node names): a node restarted while its old
//! process is still closing must not fail for it. The question reaches the nodes the session
//! has met when it announces: on one machine every node of the rendezvous (the default
//! config's), across machines every node behind the router; a peer met later through gossip
//! is not asked.

use std::time::Duration;

/// How long a node waits for the bus to answer whether its name is taken. Peers answer from
/// their token tables in a round trip; a peer that does not answer by then is left out.
pub(super) const NAMESAKE_WAIT: Duration = Duration::from_millis(500);

/// How many liveliness tokens on `key` are alive now (asked before this node declares its
/// own, so its own is never among them). An error of the query counts as none: the check
/// only warns.
pub(super) async fn namesakes(session: &zenoh::Session, key: &zenoh::key_expr::OwnedKeyExpr) -> usize {
    let Ok(replies) = session.liveliness().get(key.clone()).timeout(NAMESAKE_WAIT).await else { return 0 };
    let mut alive = 0;
    while let Ok(reply) = replies.recv_async().await {
        alive += usize::from(reply.result().is_ok());
    }
    alive
}

/// What the node says when its name is taken in its namespace.
pub(super) fn taken(node: &str, namespace: &str) -> String {
    let ns = if namespace.is_empty() { "the root namespace".to_string() } else { format!("namespace {namespace}") };
    format!(
        "another node named {node} is alive in {ns}: both publish on its keys under one name, so subscribers and a lockstep simulator take the two for one (fix: stop the other, or start this one with --name NAME or -n NAMESPACE)"
    )
}
