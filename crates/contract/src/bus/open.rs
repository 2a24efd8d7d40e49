//! Opening a Zenoh session, and saying what it waits for when that takes long.
//!
//! A client whose router is not there, or a peer told to connect to an endpoint nobody
//! listens on, keeps trying inside `zenoh::open` (the config's connect timeout and retry): a
//! tool that printed nothing meanwhile looks hung. After [`SLOW_OPEN`] the wait is named once,
//! with the mode and the endpoints, and the open goes on as the config says.
//!
//! A rendezvous endpoint (one the config both listens on and dials, as config/zenoh.json5
//! does with tcp/127.0.0.1:7447) held by a program that is no Zenoh node fails without a
//! word: the listen is tried once, the dial finds nothing that answers, and tools in other
//! terminals never find the loop. When, [`RENDEZVOUS_CHECK`] after opening, the session
//! holds no rendezvous it listens for and has met no peer, that is said once, with the fix.

use std::future::IntoFuture;
use std::sync::Arc;
use std::time::Duration;

use parking_lot::{Condvar, Mutex};

use super::{zerr, BusError};

/// How long a session may take to open before what it waits for is said.
pub const SLOW_OPEN: Duration = Duration::from_secs(2);

/// How long after opening a session looks whether its rendezvous is held by a stranger.
const RENDEZVOUS_CHECK: Duration = Duration::from_secs(1);

/// Opens a session with `config`; `what` names it in errors and in the slow-open warning. The
/// warning comes from a thread of its own: Zenoh's open may hold the task's thread while it
/// dials, so a timer beside it on the same runtime would not fire.
pub async fn open_session(config: zenoh::Config, what: &str) -> Result<zenoh::Session, BusError> {
    let waiting_for = format!("{what}: {}; still trying, as the config says (Ctrl-C stops)", waiting_for(&config));
    let rendezvous = rendezvous(&config);
    let opened = Arc::new((Mutex::new(false), Condvar::new()));
    let watch = opened.clone();
    let _ = std::thread::Builder::new().name("slow-open".into()).spawn(move || {
        let (done, changed) = &*watch;
        let mut done = done.lock();
        if !*done && changed.wait_for(&mut done, SLOW_OPEN).timed_out() && !*done {
            tracing::warn!("{waiting_for}");
        }
    });
    let session = zenoh::open(config).into_future().await;
    *opened.0.lock() = true;
    opened.1.notify_all();
    let session = session.map_err(zerr(what.to_string()))?;
    if !rendezvous.is_empty() {
        tokio::spawn(check_rendezvous(session.clone(), rendezvous));
    }
    Ok(session)
}

/// The endpoints `config` both listens on and dials: where peers on one machine meet.
fn rendezvous(config: &zenoh::Config) -> Vec<String> {
    let list = |key: &str| -> Vec<String> {
        config.get_json(key).ok().and_then(|v| serde_json::from_str::<Vec<String>>(&v).ok()).unwrap_or_default()
    };
    let listen = list("listen/endpoints");
    list("connect/endpoints").into_iter().filter(|e| listen.contains(e)).collect()
}

/// Says once when the rendezvous is neither this session's nor a Zenoh node's (see the module
/// doc).
async fn check_rendezvous(session: zenoh::Session, rendezvous: Vec<String>) {
    tokio::time::sleep(RENDEZVOUS_CHECK).await;
    if let Some(said) = held_by_a_stranger(&session, &rendezvous).await {
        tracing::warn!("{said}");
    }
}

/// What to say when `session` met nobody and holds none of `rendezvous` itself: one of them is
/// held by a program that is no Zenoh node. None while it has met a peer or a router.
async fn held_by_a_stranger(session: &zenoh::Session, rendezvous: &[String]) -> Option<String> {
    let info = session.info();
    if session.is_closed() || info.peers_zid().await.next().is_some() || info.routers_zid().await.next().is_some() {
        return None;
    }
    let own: Vec<String> = info.locators().await.iter().map(|l| l.to_string()).collect();
    let endpoint = rendezvous.iter().find(|r| !own.contains(r))?;
    Some(format!(
        "{endpoint}, where nodes on this machine meet, is held by a program that answers no Zenoh peer: tools started elsewhere (top, echo, another node) will not find this one (fix: stop that program, or run every command with -c FILE, a copy of config/zenoh.json5 with another rendezvous port in its connect and listen lists)"
    ))
}

/// What a session with `config` waits for while it opens, for a person.
fn waiting_for(config: &zenoh::Config) -> String {
    let get = |key: &str| config.get_json(key).ok().and_then(|v| serde_json::from_str::<serde_json::Value>(&v).ok());
    let mode = get("mode").and_then(|m| m.as_str().map(str::to_string)).unwrap_or_else(|| "peer".into());
    let endpoints: Vec<String> = get("connect/endpoints")
        .and_then(|v| v.as_array().cloned())
        .unwrap_or_default()
        .iter()
        .filter_map(|e| e.as_str().map(str::to_string))
        .collect();
    let at = if endpoints.is_empty() { "no endpoint".to_string() } else { endpoints.join(", ") };
    match mode.as_str() {
        "client" => format!(
            "no router answers at {at} yet (client mode: is `slipstream router` or zenohd running there, and reachable from here?)"
        ),
        _ => format!("no answer yet from {at} ({mode} mode)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wait_names_the_mode_and_the_endpoints() {
        let mut c = zenoh::Config::default();
        c.insert_json5("mode", "\"client\"").unwrap();
        c.insert_json5("connect/endpoints", r#"["tcp/127.0.0.1:17999"]"#).unwrap();
        let said = waiting_for(&c);
        assert!(
            said.contains("tcp/127.0.0.1:17999") && said.contains("client mode") && said.contains("router"),
            "{said}"
        );
        c.insert_json5("mode", "\"peer\"").unwrap();
        assert!(waiting_for(&c).contains("peer mode"));
    }

    /// A peer config whose rendezvous is `endpoint` (listened on and dialled), meeting nobody
    /// else: no scouting, as config/zenoh.json5 with its port replaced.
    fn rendezvous_config(endpoint: &str) -> zenoh::Config {
        let mut c = zenoh::Config::default();
        let list = format!(r#"["{endpoint}"]"#);
        for (k, v) in [
            ("mode", "\"peer\""),
            ("listen/endpoints", list.as_str()),
            ("listen/timeout_ms", "0"),
            ("listen/exit_on_failure", "false"),
            ("connect/endpoints", list.as_str()),
            ("connect/exit_on_failure", "false"),
            ("scouting/multicast/enabled", "false"),
        ] {
            c.insert_json5(k, v).unwrap();
        }
        c
    }

    #[tokio::test(flavor = "multi_thread")]
    async fn a_rendezvous_held_by_a_plain_listener_is_named_and_a_free_one_is_not() {
        let stranger = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let held = format!("tcp/{}", stranger.local_addr().unwrap());
        std::thread::spawn(move || {
            for conn in stranger.incoming() {
                drop(conn);
            }
        });
        let session = open_session(rendezvous_config(&held), "test").await.unwrap();
        let said = held_by_a_stranger(&session, std::slice::from_ref(&held)).await;
        assert!(said.as_deref().is_some_and(|s| s.contains(&held) && s.contains("fix:")), "{said:?}");
        session.close().await.unwrap();

        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let free = format!("tcp/127.0.0.1:{port}");
        let session = open_session(rendezvous_config(&free), "test").await.unwrap();
        let said = held_by_a_stranger(&session, std::slice::from_ref(&free)).await;
        assert!(said.is_none(), "the session holds its rendezvous itself: {said:?}");
        session.close().await.unwrap();
    }
}
