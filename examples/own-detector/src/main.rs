//! A vehicle detector of your own, in Rust, on slipstream's contract crate alone: one function
//! from a camera frame to detections, run by the contract's node SDK
//! (`slipstream_contract::node::detector`), which keeps the rest of the node contract (frames
//! latest-only, the camera's info, one answer per frame with its stamp, the token).
//!
//! ```sh
//! slipstream conform detector --command target/release/own-detector
//! slipstream eval detect --detector target/release/own-detector
//! ```
//!
//! A teaching detector (docs/own-node.md), the same idea as the Python example
//! (clients/python/examples/own_detect.py) without OpenCV: the dark band a vehicle makes where
//! it meets the road (its shadow and tyres, darker than the asphalt around them), found below
//! the horizon, placed on the flat road through the camera's intrinsics, matched to the last
//! frame's for a relative speed.

mod pinhole;

use clap::Parser;
use slipstream_contract::config::FaultArgs;
use slipstream_contract::msg::{BoundingBox2d, Detection, ObjectClass};
use slipstream_contract::node::detector::{self, Frame};
use slipstream_contract::node::{self, NodeArgs};

use pinhole::Pinhole;

/// A vehicle detector of your own on the slipstream bus (the contract crate alone).
#[derive(Debug, Parser)]
#[command(name = "own-detector", version)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
}

/// A pixel darker than this share of the road's brightness is shadow or tyre.
const DARK: f64 = 0.6;
/// How wide a vehicle's dark band may be, m.
const WIDTH_M: (f64, f64) = (1.2, 3.2);
/// The height given to a vehicle's rear face for its image box, m.
const REAR_HEIGHT_M: f64 = 1.5;
/// How far a band may move between frames and still be the same vehicle, m (along, across).
const SAME_VEHICLE_M: (f64, f64) = (3.0, 1.0);

/// The last frame's time and bands (distance, lateral offset): each new band's speed.
#[derive(Default)]
struct Memory {
    t_s: Option<f64>,
    seen: Vec<(f64, f64)>,
}

/// The frame's vehicles.
fn detect(frame: &Frame, memory: &mut Memory) -> Vec<Detection> {
    let cam = Pinhole::new(frame.camera);
    let (w, h) = (frame.camera.width as usize, frame.camera.height as usize);
    let top = ((cam.horizon_v() as usize) + 2).min(h);
    let grey = |u: usize, v: usize| {
        let p = &frame.rgb[(v * w + u) * 3..][..3];
        0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
    };
    let mut road: Vec<f64> =
        (h - h / 8..h).flat_map(|v| (w / 3..2 * w / 3).map(move |u| (u, v))).map(|(u, v)| grey(u, v)).collect();
    road.sort_by(f64::total_cmp);
    let road = road.get(road.len() / 2).copied().unwrap_or(0.0);
    let dark: Vec<bool> =
        (top..h).flat_map(|v| (0..w).map(move |u| (u, v))).map(|(u, v)| grey(u, v) < DARK * road).collect();
    let dt = memory.t_s.map(|t| frame.t_s - t);
    let mut found = Vec::new();
    for (u0, u1, v_bottom) in pinhole::bands(&dark, w) {
        let v = (top + v_bottom + 1) as f64;
        let (Some(left), Some(right)) = (cam.ground(u0 as f64, v), cam.ground(u1 as f64 + 1.0, v)) else { continue };
        let width = left.1 - right.1;
        if !(WIDTH_M.0..=WIDTH_M.1).contains(&width) {
            continue;
        }
        let (x, y) = (left.0, (left.1 + right.1) / 2.0);
        let Some(bbox) = cam.rear_box(x, y, width, REAR_HEIGHT_M) else { continue };
        let near =
            memory.seen.iter().find(|(sx, sy)| (sx - x).abs() < SAME_VEHICLE_M.0 && (sy - y).abs() < SAME_VEHICLE_M.1);
        let relative = match (near, dt) {
            (Some((sx, _)), Some(dt)) if dt > 0.0 => (x - sx) / dt,
            _ => 0.0,
        };
        found.push(detection(bbox, x, y, relative, near.is_some()));
    }
    memory.t_s = Some(frame.t_s);
    memory.seen = found.iter().map(|d| (d.distance_m, d.lateral_offset_m)).collect();
    found
}

/// A Detection of a vehicle's rear at (x, y) with its image box; without a match in the last
/// frame its relative speed is unknown, and says so.
fn detection(bbox: BoundingBox2d, x: f64, y: f64, relative_speed_mps: f64, matched: bool) -> Detection {
    Detection {
        track_id: 0,
        class: ObjectClass::Car,
        bbox,
        confidence: 0.5,
        distance_m: x,
        lateral_offset_m: y,
        relative_speed_mps,
        distance_sigma_m: 0.05 * x + 0.5,
        relative_speed_sigma_mps: if matched { 3.0 } else { 10.0 },
        brake_lights: false,
    }
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    let name = args.node.name_or("own-detector").to_string();
    let run = node::serve(&args.node.connect, &FaultArgs::default(), &name, async |bus, stop| {
        let mut memory = Memory::default();
        detector::run(bus, move |frame: &Frame| detect(frame, &mut memory), stop)
            .await
            .map_err(Box::<dyn std::error::Error>::from)
    });
    match run {
        Ok(stats) => {
            println!("{name}: {} frames, {} detections", stats.frames, stats.detections);
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("Error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
