//! The example controller drives slipstream-sim in slipstream-acc's place: started by hand as a
//! user types it, beside the simulator, in a namespace of the test's own.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use slipstream_contract::config::FaultArgs;
use slipstream_contract::{topics, Bus, ConnectArgs};

/// A child process killed and reaped when the test ends, passed or not.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// slipstream-sim of the same build (target/<profile>/, beside this package's binary).
fn sim_binary() -> std::path::PathBuf {
    let own = std::path::Path::new(env!("CARGO_BIN_EXE_own-controller"));
    let sim = own.with_file_name("slipstream-sim");
    assert!(sim.exists(), "{} is not built: build the workspace (cargo build --release --workspace)", sim.display());
    sim
}

fn start(program: &std::path::Path, args: &[&str]) -> Killed {
    let child = Command::new(program)
        .args(args)
        .env_remove("SLIPSTREAM_CONFIG")
        .env_remove("SLIPSTREAM_NAMESPACE")
        .env_remove("RUST_LOG")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("start {}: {e}", program.display()));
    Killed(child)
}

/// The ego's speed at each simulated second it reports, until `until_s` of simulated time
/// (or a generous wall-clock cap, so a broken loop fails instead of hanging).
async fn speeds(namespace: &str, until_s: f64) -> Vec<(f64, f64)> {
    let connect = ConnectArgs { namespace: Some(namespace.to_string()), ..ConnectArgs::default() };
    let bus = Bus::open_node(&connect, &FaultArgs::default(), "own-controller-test").await.unwrap();
    let speed = bus.subscriber(topics::VEHICLE_SPEED).await.unwrap();
    bus.announce().await.unwrap();
    let (mut seen, cap) = (Vec::new(), Instant::now() + Duration::from_secs(120));
    while Instant::now() < cap {
        let Some(s) = speed.recv_timeout(Duration::from_secs(1)).await else { continue };
        let t = s.header.stamp_sim_ns as f64 / 1e9;
        seen.push((t, s.msg.speed_mps));
        if t >= until_s {
            break;
        }
    }
    bus.leave().await;
    seen
}

#[test]
fn the_own_controller_brings_the_ego_to_its_set_speed() {
    let namespace = format!("own-controller-{}", std::process::id());
    // open-road: nobody ahead in the ego's lane, the ego at 20 m/s; without a controller it
    // coasts and slows down.
    let _sim = start(&sim_binary(), &["--scenario", "open-road", "-n", &namespace]);
    let controller =
        start(std::path::Path::new(env!("CARGO_BIN_EXE_own-controller")), &["--set-speed", "24", "-n", &namespace]);
    let seen = tokio::runtime::Runtime::new().unwrap().block_on(speeds(&namespace, 12.0));
    let last = seen.last().copied().unwrap_or_else(|| panic!("no vehicle/speed in {namespace}"));
    assert!(last.0 >= 12.0, "the simulation reached only {:.1} s", last.0);
    assert!((22.5..=24.8).contains(&last.1), "speed {:.2} m/s at {:.1} s, set speed 24: {seen:?}", last.1, last.0);
    drop(controller);
}
