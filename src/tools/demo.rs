//! `slipstream demo`: a publisher and a subscriber in two processes, found by each other with
//! no address typed. The publisher sends what the simulator will (speed and clock at 100 Hz,
//! 640x480 camera frames at 20 Hz through shared memory, camera info); the subscriber prints
//! each topic's rate, latency and losses every second and a summary at the end.

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::bus::{Bus, StatsSnapshot};
use crate::config::ConnectArgs;
use crate::msg::{CameraInfo, ImageEncoding, SimClock, SimMode, Speed};
use crate::topics;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Role {
    /// Start a publisher and a subscriber as two child processes
    Both,
    /// Publish synthetic vehicle data
    Pub,
    /// Subscribe and report statistics
    Sub,
}

#[derive(Debug, Clone, clap::Args)]
pub struct DemoArgs {
    #[arg(long, value_enum, default_value_t = Role::Both)]
    pub role: Role,
    /// How long to run, seconds
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Print the subscriber's summary as JSON
    #[arg(long)]
    pub json: bool,
}

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;

/// Draws a sky/road gradient and a dark box that moves with time: something to look at.
fn paint(px: &mut [u8], t_s: f64) {
    let box_u = ((t_s * 40.0) as u32 % (WIDTH - 80)) as usize;
    for (i, row) in px.chunks_exact_mut(WIDTH as usize * 3).enumerate() {
        let sky = i < HEIGHT as usize / 2;
        for (u, p) in row.chunks_exact_mut(3).enumerate() {
            let in_box = (260..300).contains(&i) && (box_u..box_u + 80).contains(&u);
            let c = if in_box {
                [40, 40, 60]
            } else if sky {
                [120, 170, (200 + i / 8).min(255) as u8]
            } else {
                [90, 90, 90]
            };
            p.copy_from_slice(&c);
        }
    }
}

/// Publishes for `duration`: speed and clock at 100 Hz, frames at 20 Hz, info every second.
pub async fn publish(bus: &Bus, duration: Duration) -> Result<()> {
    let speed = bus.publisher(topics::VEHICLE_SPEED).await?;
    let clock = bus.publisher(topics::SIM_CLOCK).await?;
    let info = bus.publisher(topics::CAMERA_FRONT_INFO).await?;
    let frames = bus.frame_publisher(crate::topics::CAMERA_FRONT).await?;
    let cam_info = CameraInfo::pinhole(
        WIDTH,
        HEIGHT,
        std::f64::consts::FRAC_PI_3,
        [1.5, 0.0, 1.4],
        [0.0, 0.0, 0.0],
        20.0,
        ImageEncoding::Rgb8,
    );
    let start = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
    let mut step: u64 = 0;
    while start.elapsed() < duration {
        tick.tick().await;
        let t_ns = step * 10_000_000;
        let t_s = t_ns as f64 * 1e-9;
        speed.put(t_ns, &Speed { speed_mps: 20.0 + 5.0 * (t_s * 0.5).sin() })?;
        clock.put(t_ns, &SimClock { step, real_time_factor: 1.0, mode: SimMode::Realtime, physics_hz: 100.0 })?;
        if step.is_multiple_of(5) {
            frames.put_with(t_ns, WIDTH, HEIGHT, ImageEncoding::Rgb8, (WIDTH * HEIGHT * 3) as usize, |px| {
                paint(px, t_s)
            })?;
        }
        if step.is_multiple_of(100) {
            info.put(t_ns, &cam_info)?;
        }
        step += 1;
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct DemoSummary {
    pub topics: Vec<StatsSnapshot>,
    pub shared_memory_frames: u64,
    pub nodes_seen: Vec<String>,
}

/// Subscribes for `duration`, printing a line per second to stderr.
pub async fn subscribe(bus: &Bus, duration: Duration) -> Result<DemoSummary> {
    let speed = bus.subscriber(topics::VEHICLE_SPEED).await?;
    let clock = bus.subscriber(topics::SIM_CLOCK).await?;
    let info = bus.subscriber(topics::CAMERA_FRONT_INFO).await?;
    let frames = bus.frame_subscriber(crate::topics::CAMERA_FRONT).await?;
    let start = Instant::now();
    let mut shm = 0u64;
    let mut next_report = Duration::from_secs(1);
    let mut nodes_seen = Vec::new();
    while start.elapsed() < duration {
        tokio::select! {
            f = frames.recv() => { if f.is_shared_memory() { shm += 1; } }
            _ = speed.recv() => {}
            _ = clock.recv() => {}
            _ = info.recv() => {}
            _ = tokio::time::sleep(Duration::from_millis(50)) => {}
        }
        if start.elapsed() >= next_report {
            next_report += Duration::from_secs(1);
            let s = speed.stats().snapshot();
            let f = frames.stats().snapshot();
            eprintln!(
                "t={:>4.1}s  speed {:>5.1} Hz p50 {:>6} us lost {}  |  frames {:>4.1} Hz p50 {:>6} us lost {} (shm {})",
                start.elapsed().as_secs_f64(),
                s.rate_hz,
                s.latency_p50_us.map(|v| format!("{v:.0}")).unwrap_or("-".into()),
                s.lost,
                f.rate_hz,
                f.latency_p50_us.map(|v| format!("{v:.0}")).unwrap_or("-".into()),
                f.lost,
                shm,
            );
            if nodes_seen.len() < 2 {
                nodes_seen = bus.nodes_alive().await.unwrap_or_default();
            }
        }
    }
    Ok(DemoSummary {
        topics: vec![
            speed.stats().snapshot(),
            clock.stats().snapshot(),
            frames.stats().snapshot(),
            info.stats().snapshot(),
        ],
        shared_memory_frames: shm,
        nodes_seen,
    })
}

/// The summary as a table.
pub fn render(summary: &DemoSummary) -> String {
    let mut s = format!(
        "{:<20} {:>8} {:>9} {:>10} {:>10} {:>6} {:>8}\n",
        "TOPIC", "RECEIVED", "RATE Hz", "P50 us", "P99 us", "LOST", "BAD"
    );
    for t in &summary.topics {
        let f = |v: Option<f64>| v.map(|x| format!("{x:.0}")).unwrap_or("-".into());
        s.push_str(&format!(
            "{:<20} {:>8} {:>9.1} {:>10} {:>10} {:>6} {:>8}\n",
            t.topic,
            t.received,
            t.rate_hz,
            f(t.latency_p50_us),
            f(t.latency_p99_us),
            t.lost,
            t.decode_errors
        ));
    }
    s.push_str(&format!(
        "frames in shared memory: {}\nnodes seen: {}\n",
        summary.shared_memory_frames,
        summary.nodes_seen.join(", ")
    ));
    s
}

/// Checks a finished run: the subscriber must have received speed and frames.
pub fn verdict(summary: &DemoSummary) -> Result<()> {
    let got = |name: &str| summary.topics.iter().find(|t| t.topic == name).map_or(0, |t| t.received);
    if got("vehicle/speed") == 0 || got("camera/front") == 0 {
        bail!("the subscriber received nothing: are both processes on the same config and namespace?");
    }
    Ok(())
}

/// `slipstream demo`: with `--role both`, the publisher and the subscriber as two processes
/// (this binary again, one role each, the same flags); with one role, that side.
pub fn run(connect: &ConnectArgs, args: &DemoArgs) -> Result<()> {
    let duration = std::time::Duration::from_secs_f64(args.duration);
    if args.role == Role::Both {
        // Two real processes, started separately, as nodes will be: same flags, one role each.
        let exe = std::env::current_exe()?;
        let mut passed: Vec<String> = Vec::new();
        let mut it = std::env::args().skip(1);
        while let Some(a) = it.next() {
            if a == "--role" {
                it.next();
            } else if !a.starts_with("--role=") {
                passed.push(a);
            }
        }
        let spawn = |role: &str| std::process::Command::new(&exe).args(&passed).args(["--role", role]).spawn();
        let mut publisher = spawn("pub").context("start the publisher")?;
        let subscriber = spawn("sub").context("start the subscriber")?;
        let status = subscriber.wait_with_output()?.status;
        let _ = publisher.wait();
        anyhow::ensure!(status.success(), "the subscriber failed");
        return Ok(());
    }
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let node = if args.role == Role::Pub { "demo-pub" } else { "demo-sub" };
        let bus = Bus::open(connect.zenoh_config()?, connect.topic_map()?, node).await?;
        if args.role == Role::Pub {
            publish(&bus, duration).await?;
        } else {
            let summary = subscribe(&bus, duration).await?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("{}", render(&summary));
            }
            verdict(&summary)?;
        }
        bus.leave().await;
        Ok(())
    })
}

/// `slipstream demo`: fails when the subscriber missed what the publisher sent.
pub fn command(args: &DemoArgs, connect: &ConnectArgs) -> Result<std::process::ExitCode> {
    run(connect, args).map(|()| std::process::ExitCode::SUCCESS)
}
