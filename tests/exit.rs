//! The end of a process: Zenoh's thread pools stop before the exit handlers run
//! (src/bus/exit.rs). A test binary of its own, so a process of its own: once the pools are
//! stopped nothing in the process may use Zenoh again, and this file's single test is the
//! only user.

#[allow(dead_code)]
#[path = "it/common.rs"]
mod common;

use common::{bus_pair, map, TIMEOUT};
use slipstream::bus::ZenohThreads;
use slipstream::msg::ImageEncoding;

/// Threads of Zenoh's pools alive in this process: they are named after their pool ("tx-0").
fn zenoh_threads() -> Vec<String> {
    std::fs::read_dir("/proc/self/task")
        .unwrap()
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("comm")).ok())
        .map(|name| name.trim().to_string())
        .filter(|name| ["app-", "acc-", "tx-", "rx-", "net-"].iter().any(|pool| name.starts_with(pool)))
        .collect()
}

#[test]
fn zenoh_threads_stop_at_the_end_of_main_once_every_bus_is_closed() {
    // As the binaries' main does: the guard first, dropped after the runtime.
    let guard = ZenohThreads::stop_at_end_of_main();
    slipstream::cli::apply_zenoh_runtime_default();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (a, b) = rt.block_on(async {
        // A frame too big for the publisher's pool (none here) goes from the heap, and Zenoh
        // makes the link's implicit shared-memory pool on one of its blocking threads: the
        // work that was still running at an exit and panicked there.
        let heap = map("{ camera: { shared_memory: false } }");
        let (a, b) = bus_pair(heap.clone(), heap).await;
        let sub = b.frame_subscriber(slipstream::topics::CAMERA_FRONT).await.unwrap();
        let publisher = a.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
        assert!(publisher.publisher().wait_for_subscriber(TIMEOUT).await);
        let (w, h) = (640u32, 480u32);
        for i in 0..3u64 {
            publisher.put_with(i, w, h, ImageEncoding::Rgb8, (w * h * 3) as usize, |px| px.fill(i as u8)).unwrap();
        }
        tokio::time::timeout(TIMEOUT, sub.recv()).await.expect("a frame arrives");
        (a, b)
    });
    assert!(!zenoh_threads().is_empty(), "the buses run on Zenoh's pools");

    // A bus still open: its threads may still call into the pools, which are left running.
    drop(ZenohThreads::stop_at_end_of_main());
    assert!(!zenoh_threads().is_empty(), "pools stopped under an open bus");

    rt.block_on(async {
        a.close().await.unwrap();
        b.close().await.unwrap();
    });
    drop(rt);
    drop(guard);
    assert_eq!(zenoh_threads(), Vec::<String>::new(), "Zenoh threads left running at the end of main");
}
