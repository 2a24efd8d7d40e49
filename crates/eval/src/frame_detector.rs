//! The detector under test in `eval detect`, behind one trait: what each frame the cameras
//! drew yields. slipstream-detect's detector and tracker run in process ([`Ours`]); a detector
//! of the user's own answers over the bus ([`super::detect_remote::Yours`]). The scoring does
//! not know which.

use super::link_codec::LinkCodec;
use slipstream_contract::msg::Detection;
use slipstream_perception::{CameraRig, DetectSettings};
use slipstream_sim::Cameras;

/// A detector under test: the detections of each frame the cameras drew.
pub(crate) trait FrameDetector {
    fn frame(&mut self, cameras: &Cameras, t_ns: u64) -> crate::error::Result<Vec<Detection>>;

    /// Frames it left unanswered (scored as frames without detections).
    fn unanswered(&self) -> u64 {
        0
    }
}

/// slipstream-detect's detector and tracker, in process; with `codec`, every frame goes
/// through its encoding and back first.
pub(crate) struct Ours<'a> {
    rig: CameraRig,
    codec: Option<&'a mut LinkCodec>,
}

impl<'a> Ours<'a> {
    pub(crate) fn new(cameras: &Cameras, detect: &DetectSettings, codec: Option<&'a mut LinkCodec>) -> Ours<'a> {
        Ours { rig: CameraRig::new(cameras.front.info(), cameras.narrow_info(), detect), codec }
    }
}

impl FrameDetector for Ours<'_> {
    fn frame(&mut self, cameras: &Cameras, t_ns: u64) -> crate::error::Result<Vec<Detection>> {
        let t_s = t_ns as f64 / 1e9;
        Ok(match self.codec.as_deref_mut() {
            None => self.rig.update(&cameras.front.rgb, cameras.narrow_rgb(), t_s),
            Some(c) => {
                let (f, n) = (cameras.front.info(), cameras.narrow_info());
                let front = c.pass(&cameras.front.rgb, f.width, f.height);
                let narrow = n.zip(cameras.narrow_rgb()).map(|(i, rgb)| c.pass(rgb, i.width, i.height));
                self.rig.update(&front, narrow.as_deref(), t_s)
            }
        })
    }
}
