//! The default config/zenoh.json5: nodes started separately on one machine find each other
//! with no router and no address typed, form a direct mesh, and survive the node that holds
//! the rendezvous port leaving. The test uses a free port instead of 7447 so it cannot meet
//! anything else on the machine; everything stays on 127.0.0.1.

use std::time::Duration;

use crate::common::free_port;
use slipstream::msg::Speed;
use slipstream::topics::VEHICLE_SPEED;
use slipstream::{Bus, TopicMap};

fn default_config_on(port: u16) -> zenoh::Config {
    let text = slipstream::config::DEFAULT_ZENOH_CONFIG.replace("127.0.0.1:7447", &format!("127.0.0.1:{port}"));
    assert_ne!(text, slipstream::config::DEFAULT_ZENOH_CONFIG, "the default config names the rendezvous port");
    zenoh::Config::from_json5(&text).unwrap()
}

async fn node(port: u16, name: &str) -> Bus {
    within!(Bus::open(default_config_on(port), TopicMap::default(), name)).unwrap()
}

/// Publishes until `sub` receives (discovery takes a moment), returning the value seen.
async fn delivered(from: &Bus, to: &slipstream::bus::Subscriber<Speed>, value: f64) {
    let publisher = from.publisher(VEHICLE_SPEED).await.unwrap();
    within!(async {
        loop {
            publisher.put(0, &Speed { speed_mps: value }).unwrap();
            if let Some(r) = to.recv_timeout(Duration::from_millis(200)).await {
                if r.msg.speed_mps == value {
                    return;
                }
            }
        }
    });
}

#[tokio::test(flavor = "multi_thread")]
async fn separately_started_nodes_mesh_and_survive_the_rendezvous_leaving() {
    let port = free_port();
    let a = node(port, "a").await;
    let b = node(port, "b").await;
    let c = node(port, "c").await;
    let sub_b = b.subscriber(VEHICLE_SPEED).await.unwrap();
    delivered(&c, &sub_b, 1.0).await;

    // Gossip gave b and c a direct link (not only through a).
    let c_zid = c.session().zid();
    within!(async {
        while !b.session().info().peers_zid().await.any(|z| z == c_zid) {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });

    // The node holding the rendezvous port leaves: b and c keep talking.
    a.close().await.unwrap();
    delivered(&c, &sub_b, 2.0).await;

    // A node started later still finds them (b or c took the port over, or d binds it).
    let d = node(port, "d").await;
    delivered(&d, &sub_b, 3.0).await;
    let mut alive = Vec::new();
    within!(async {
        loop {
            alive = d.nodes_alive().await.unwrap();
            if alive.len() == 3 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    assert_eq!(alive, vec!["b", "c", "d"]);
}
