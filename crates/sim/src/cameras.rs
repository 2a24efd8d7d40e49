//! The simulator's cameras drawn in process, off the bus (`eval`, tests): the front camera
//! and the narrow one when the settings turn it on, seeded as slipstream-sim seeds them, so
//! the frames are the ones the node would publish for the same run.

use super::render::{seen_by_either, ObjectVisibility, Renderer};
use super::rng::SimRng;
use super::settings::SimSettings;
use super::world::World;
use slipstream_contract::msg::{CameraInfo, ImageEncoding};

/// One camera: its renderer, the generator of its frames' looks, its last frame.
pub struct DrawnCamera {
    renderer: Renderer,
    look_rng: SimRng,
    /// The last frame drawn, RGB8.
    pub rgb: Vec<u8>,
}

impl DrawnCamera {
    fn new((renderer, look_rng): (Renderer, SimRng)) -> DrawnCamera {
        let rgb = vec![0; renderer.frame_len()];
        DrawnCamera { renderer, look_rng, rgb }
    }

    pub fn info(&self) -> &CameraInfo {
        self.renderer.info()
    }

    fn draw(&mut self, world: &World, brightness: f64) -> Vec<ObjectVisibility> {
        let look = self.renderer.draw_look(brightness, &mut self.look_rng);
        self.renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut self.rgb)
    }
}

/// The front camera and the optional narrow one of a world's run.
pub struct Cameras {
    pub front: DrawnCamera,
    pub narrow: Option<DrawnCamera>,
    brightness: f64,
}

impl Cameras {
    pub fn new(settings: &SimSettings, world: &World) -> Cameras {
        let noise = &world.scenario().noise;
        let front = settings.camera_info(ImageEncoding::Rgb8);
        let narrow = settings.narrow_camera_info(ImageEncoding::Rgb8);
        Cameras {
            front: DrawnCamera::new(Renderer::seeded(&front, noise.camera_stddev, world.seed())),
            narrow: narrow.map(|n| DrawnCamera::new(Renderer::seeded_narrow(&n, noise.camera_stddev, world.seed()))),
            brightness: noise.brightness,
        }
    }

    /// Draws every camera's frame of this instant; the vehicles' visibility over them (boxes
    /// in the front image), as the objects message gives it.
    pub fn draw(&mut self, world: &World) -> Vec<ObjectVisibility> {
        let narrow = self.narrow.as_mut().map(|n| n.draw(world, self.brightness));
        let front = self.front.draw(world, self.brightness);
        match narrow {
            Some(n) => seen_by_either(front, &n),
            None => front,
        }
    }

    pub fn narrow_rgb(&self) -> Option<&[u8]> {
        self.narrow.as_ref().map(|n| n.rgb.as_slice())
    }

    pub fn narrow_info(&self) -> Option<&CameraInfo> {
        self.narrow.as_ref().map(|n| n.info())
    }
}
