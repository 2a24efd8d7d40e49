//! `slipstream bench sim`: the simulator's own speed, in process: physics steps/s with 1, 10
//! and 50 vehicles, software render time per frame, the vehicle detector's time per frame,
//! both default cameras rendered and detected per frame,
//! and the real-time factor of a whole run in fast mode with the camera publishing on a
//! loopback bus, and with N egos in one world ([`super::egos`]). A frame-sized memcpy runs in the
//! same process as the machine's yardstick for the render figures.

use std::time::{Duration, Instant};

use anyhow::Result;
use serde::Serialize;

use slipstream_contract::msg::ImageEncoding;
use slipstream_sim::settings::{Mode, SimSettings};
use slipstream_sim::world::{EgoInput, World};
use slipstream_sim::Scenario;
use slipstream_sim::SimRng;
use slipstream_sim::{FrameLook, Renderer};

/// One simulator figure, the median over runs.
#[derive(Debug, Clone, Serialize)]
pub struct SimFigure {
    pub what: String,
    pub value: f64,
    pub unit: String,
    pub aim: String,
    pub runs: usize,
}

fn traffic_world(vehicles: u32) -> Result<World> {
    let text = format!(
        "{{ name: 'bench-{vehicles}', duration_s: 100000, road: {{ lanes: 3, length_m: 50000 }}, ego: {{ lane: 1, speed_mps: 25 }},
           random_traffic: {{ count: {}, range_m: [-300, 3000], speed_mps: [20, 30], lane_change_every_s: 15 }} }}",
        vehicles.saturating_sub(1)
    );
    let scenario = Scenario::parse(&text, "bench").map_err(anyhow::Error::msg)?;
    let world = World::new(scenario, 1, SimSettings::default().physics_hz);
    anyhow::ensure!(
        world.vehicles().len() == vehicles as usize,
        "placed {} of {vehicles} vehicles",
        world.vehicles().len()
    );
    Ok(world)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Physics steps per second of the whole world (drivers, forces, rapier, contacts).
fn steps_per_s(vehicles: u32, steps: u64) -> Result<f64> {
    let mut world = traffic_world(vehicles)?;
    let t = Instant::now();
    for _ in 0..steps {
        world.step(EgoInput::Cruise);
    }
    Ok(steps as f64 / t.elapsed().as_secs_f64())
}

/// Median milliseconds to render one frame of the busy-traffic scenario, 5 s in.
fn render_ms(width: u32, height: u32, frames: usize) -> Result<f64> {
    let mut settings = SimSettings::default();
    settings.camera.width = width;
    settings.camera.height = height;
    let mut world = World::new(Scenario::find("busy-traffic").map_err(anyhow::Error::msg)?, 7, settings.physics_hz);
    for _ in 0..500 {
        world.step(EgoInput::Cruise);
    }
    let info = settings.camera_info(ImageEncoding::Rgb8);
    let mut renderer = Renderer::new(&info, 0.0, &mut SimRng::new(1));
    let mut rgb = vec![0u8; renderer.frame_len()];
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        world.step(EgoInput::Cruise);
        let t = Instant::now();
        let vis = renderer.render(world.road(), world.ego(), world.vehicles(), FrameLook::PLAIN, &mut rgb);
        times.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(vis);
    }
    Ok(median(times))
}

/// Median milliseconds for the vehicle detector on one 640x480 frame of busy-traffic (noisy
/// camera), frames rendered beforehand.
fn detect_ms(frames: usize) -> Result<f64> {
    let settings = SimSettings::default();
    let scenario = Scenario::find("busy-traffic").map_err(anyhow::Error::msg)?;
    let noise = scenario.noise.clone();
    let mut world = World::new(scenario, 7, settings.physics_hz);
    let info = settings.camera_info(ImageEncoding::Rgb8);
    let mut renderer = Renderer::new(&info, noise.camera_stddev, &mut SimRng::new(1));
    let mut look_rng = SimRng::new(2);
    let mut detector = slipstream_perception::Detector::new(&info, slipstream_perception::DetectorParams::default());
    let mut rgb = vec![0u8; renderer.frame_len()];
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        for _ in 0..5 {
            world.step(EgoInput::Cruise);
        }
        let look = renderer.draw_look(noise.brightness, &mut look_rng);
        renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut rgb);
        let t = Instant::now();
        std::hint::black_box(detector.detect(&rgb));
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(times))
}

/// Median milliseconds for a whole camera step of busy-traffic (noisy): both default cameras
/// rendered (front 640x480, narrow 1152x320) and their vehicles detected and fused, as
/// slipstream-sim and slipstream-detect share it per frame.
fn cameras_ms(frames: usize) -> Result<f64> {
    let settings = SimSettings::default();
    let scenario = Scenario::find("busy-traffic").map_err(anyhow::Error::msg)?;
    let mut world = World::new(scenario, 7, settings.physics_hz);
    let mut cameras = slipstream_sim::Cameras::new(&settings, &world);
    let mut rig = slipstream_perception::CameraRig::new(
        cameras.front.info(),
        cameras.narrow_info(),
        &slipstream_perception::DetectSettings::default(),
    );
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        for _ in 0..5 {
            world.step(EgoInput::Cruise);
        }
        let t = Instant::now();
        std::hint::black_box(cameras.draw(&world));
        std::hint::black_box(rig.detect(&cameras.front.rgb, cameras.narrow_rgb()));
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(times))
}

/// Median milliseconds to copy a frame of this size (cold destination each time is not
/// modelled: this is the hot-cache yardstick).
fn memcpy_ms(width: u32, height: u32, copies: usize) -> f64 {
    let src = vec![7u8; (width * height * 3) as usize];
    let mut dst = vec![0u8; src.len()];
    let mut times = Vec::with_capacity(copies);
    for _ in 0..copies {
        let t = Instant::now();
        dst.copy_from_slice(std::hint::black_box(&src));
        std::hint::black_box(&dst);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    median(times)
}

/// Real-time factor of a fast-mode run of `scenario` with 640x480 frames at 20 Hz published
/// through shared memory to a subscriber in another session on loopback.
async fn fast_rtf(scenario: &str, sim_s: f64) -> Result<f64> {
    let mut scenario = Scenario::find(scenario).map_err(anyhow::Error::msg)?;
    scenario.duration_s = sim_s;
    super::egos::fast_rtf_of(scenario, &SimSettings::default()).await
}

/// One figure of the suite: what, unit, aim, and how to take one run of it.
type Figure<'a> = dyn FnMut(&str, &str, &str, &mut dyn FnMut() -> Result<f64>) -> Result<f64> + 'a;

/// Many egos in one simulator ([`super::egos`]): the fast real-time factor at N egos with
/// their cameras and on ground truth, and what it implies at real time for the largest N.
fn egos_figures(rt: &tokio::runtime::Runtime, quick: bool, sim_s: f64, figure: &mut Figure) -> Result<()> {
    let counts: &[usize] = if quick { &[1, 2] } else { &[1, 4, 8, 16] };
    let camera = SimSettings { mode: Mode::Fast, ..SimSettings::default() };
    let ground_truth = super::egos::ground_truth_settings();
    for (what, settings) in [("cameras", &camera), ("ground truth (80x60 camera, no narrow)", &ground_truth)] {
        let mut last = 0.0;
        for &n in counts {
            let egos = if n == 1 { "1 ego".to_string() } else { format!("{n} egos") };
            let name = format!("fast mode real-time factor, {egos}, {what}, frames on the bus");
            last = figure(&name, "x", "-", &mut || {
                let run = super::egos::fast_rtf(n, settings, sim_s);
                rt.block_on(async { tokio::time::timeout(Duration::from_secs(900), run).await? })
            })?;
        }
        let n = *counts.last().unwrap_or(&1);
        let served = n as f64 * last;
        figure(&format!("egos served at real time, {what} ({n} x its factor)"), "egos", "-", &mut || Ok(served))?;
    }
    Ok(())
}

/// Runs the simulator suite; progress on stderr.
pub(crate) fn run(quick: bool, repeat: usize) -> Result<Vec<SimFigure>> {
    let repeat = if quick { 1 } else { repeat.max(1) };
    let (steps, frames, sim_s) = if quick { (300, 10, 3.0) } else { (5000, 200, 60.0) };
    let mut out = Vec::new();
    let mut figure = |what: &str, unit: &str, aim: &str, f: &mut dyn FnMut() -> Result<f64>| -> Result<f64> {
        let mut values = Vec::with_capacity(repeat);
        for i in 0..repeat {
            eprint!("[sim {}/{repeat}] {what} ... ", i + 1);
            let v = f()?;
            eprintln!("{v:.2} {unit}");
            values.push(v);
        }
        let value = median(values);
        out.push(SimFigure { what: what.into(), value, unit: unit.into(), aim: aim.into(), runs: repeat });
        Ok(value)
    };
    for n in [1, 10, 50] {
        figure(
            &format!("physics steps/s, {n} vehicles"),
            "steps/s",
            if n == 50 { ">= 10000 (20x at 500 Hz)" } else { "-" },
            &mut || steps_per_s(n, steps),
        )?;
    }
    let vga = figure("render 640x480, busy-traffic", "ms/frame", "<= 5", &mut || render_ms(640, 480, frames))?;
    figure("render 1280x720, busy-traffic", "ms/frame", "-", &mut || render_ms(1280, 720, frames))?;
    figure("detect vehicles 640x480, busy-traffic (noisy)", "ms/frame", "<= 5", &mut || detect_ms(frames))?;
    figure("render + detect, front 640x480 + narrow 1152x320, busy-traffic (noisy)", "ms/frame", "<= 5", &mut || {
        cameras_ms(frames)
    })?;
    let copy = figure("memcpy of a 640x480 RGB frame (yardstick)", "ms", "-", &mut || {
        Ok(memcpy_ms(640, 480, frames.max(50)))
    })?;
    let rt = tokio::runtime::Runtime::new()?;
    for scenario in ["steady-follow", "busy-traffic"] {
        figure(
            &format!("fast mode real-time factor, {scenario}, camera 640x480 @ 20 Hz on the bus"),
            "x",
            if scenario == "steady-follow" { ">= 20" } else { "-" },
            &mut || {
                rt.block_on(async { tokio::time::timeout(Duration::from_secs(600), fast_rtf(scenario, sim_s)).await? })
            },
        )?;
    }
    egos_figures(&rt, quick, sim_s, &mut figure)?;
    out.push(SimFigure {
        what: "render 640x480 / memcpy 640x480 (same run)".into(),
        value: vga / copy.max(1e-9),
        unit: "x".into(),
        aim: "-".into(),
        runs: repeat,
    });
    Ok(out)
}
