//! Renders one camera frame of a scenario to a PNG, off the bus: for writing scenarios and
//! checking what the camera sees (`slipstream-sim --preview FILE.png --at SECONDS`).

use super::ground_truth::ground_truth;
use super::render::Renderer;
use super::settings::SimSettings;
use super::world::{EgoInput, World};
use slipstream_contract::msg::{encode_pixels, GroundTruthObjects, ImageEncoding, PixelError};

/// Steps `world` to `at_s` (the ego cruising, as before any controller) and renders the
/// front camera; ground-truth boxes are outlined in yellow when `outline_boxes`.
pub fn preview(
    mut world: World,
    settings: &SimSettings,
    at_s: f64,
    outline_boxes: bool,
) -> Result<(Vec<u8>, GroundTruthObjects), PixelError> {
    let steps = (at_s * settings.physics_hz as f64).round() as u64;
    while world.step_count() < steps && world.ended().is_none() {
        world.step(EgoInput::Cruise);
    }
    let info = settings.camera_info(ImageEncoding::Rgb8);
    let noise = world.scenario().noise.clone();
    let (mut renderer, mut look_rng) = Renderer::seeded(&info, noise.camera_stddev, world.seed());
    let look = renderer.draw_look(noise.brightness, &mut look_rng);
    let mut rgb = vec![0u8; renderer.frame_len()];
    let visibility = renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut rgb);
    let truth = ground_truth(&world, &visibility);
    let (w, h) = (info.width as usize, info.height as usize);
    if outline_boxes {
        for b in truth.objects.iter().filter_map(|o| o.bbox) {
            let (u0, v0) = (b.u_min_px as usize, b.v_min_px as usize);
            let (u1, v1) =
                ((b.u_max_px as usize).min(w).saturating_sub(1), (b.v_max_px as usize).min(h).saturating_sub(1));
            let mut put =
                |u: usize, v: usize| rgb[(v * w + u) * 3..(v * w + u) * 3 + 3].copy_from_slice(&[255, 220, 0]);
            for u in u0..=u1 {
                put(u, v0);
                put(u, v1);
            }
            for v in v0..=v1 {
                put(u0, v);
                put(u1, v);
            }
        }
    }
    Ok((encode_pixels(&rgb, info.width, info.height, ImageEncoding::Png, 0)?, truth))
}
