//! Camera frames and the camera's calibration.
//!
//! A frame's pixels are the last field of the payload, so a publisher can write the few
//! bytes before them ([`frame_prefix`]) and render straight into the payload buffer (a shared
//! memory buffer on one host): no copy from renderer to subscriber. [`CameraFrameRef`] decodes
//! without copying the pixels.

use serde::{Deserialize, Serialize};

use super::codec::write_postcard;
use super::image_encoding::ImageEncoding;
use super::{DecodeError, Header, Message, MessageKind, Unsound, Vec3, PREAMBLE_LEN, WIRE_VERSION};

/// camera/front: one image, owned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraFrame {
    pub width: u32,
    pub height: u32,
    pub encoding: ImageEncoding,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// camera/front decoded without copying: `data` borrows the received payload.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraFrameRef<'a> {
    pub width: u32,
    pub height: u32,
    pub encoding: ImageEncoding,
    #[serde(borrow, with = "serde_bytes")]
    pub data: &'a [u8],
}

fn check_frame(width: u32, height: u32, encoding: ImageEncoding, len: usize) -> Result<(), Unsound> {
    super::pixels::check_size(width, height, encoding, len).map_err(|e| Unsound(e.to_string()))
}

impl Message for CameraFrame {
    const KIND: MessageKind = MessageKind::CameraFrame;
    fn check(&self) -> Result<(), Unsound> {
        check_frame(self.width, self.height, self.encoding, self.data.len())
    }
}

impl Message for CameraFrameRef<'_> {
    const KIND: MessageKind = MessageKind::CameraFrame;
    fn check(&self) -> Result<(), Unsound> {
        check_frame(self.width, self.height, self.encoding, self.data.len())
    }
}

impl<'a> CameraFrameRef<'a> {
    /// Copies the pixels into an owned frame (the one copy a consumer may choose to make).
    pub fn to_owned_frame(&self) -> CameraFrame {
        CameraFrame { width: self.width, height: self.height, encoding: self.encoding, data: self.data.to_vec() }
    }

    /// The image as RGB8 pixels, whatever its encoding: raw frames are borrowed as they are,
    /// the others decoded (and must have the size the frame states; crates/contract/src/msg/pixels.rs).
    pub fn to_rgb8(&self) -> Result<std::borrow::Cow<'a, [u8]>, DecodeError> {
        super::pixels::decode(self.data, self.width, self.height, self.encoding)
            .map_err(|e| DecodeError::Invalid { expected: "CameraFrame", reason: e.to_string() })
    }
}

/// The bytes of a camera/front payload that precede `data_len` bytes of image data:
/// preamble, header, width, height, encoding and the length varint. `prefix ++ data` is exactly
/// `encode(header, &CameraFrame { .., data })`.
pub fn frame_prefix(header: &Header, width: u32, height: u32, encoding: ImageEncoding, data_len: usize) -> Vec<u8> {
    let mut buf = Vec::with_capacity(48);
    buf.push(WIRE_VERSION);
    buf.push(MessageKind::CameraFrame as u8);
    write_postcard(&mut buf, header);
    write_postcard(&mut buf, &width);
    write_postcard(&mut buf, &height);
    write_postcard(&mut buf, &encoding);
    write_postcard(&mut buf, &(data_len as u64));
    debug_assert!(buf.len() > PREAMBLE_LEN);
    buf
}

/// camera/front/info: intrinsics and where the camera sits on the vehicle.
///
/// Pinhole model, pixel coordinates with u right and v down from the top-left corner:
/// u = cx + fx * (-y_cam / x_cam), v = cy + fy * (-z_cam / x_cam) for a point in the camera
/// frame (x forward, y left, z up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub width: u32,
    pub height: u32,
    pub fx_px: f64,
    pub fy_px: f64,
    pub cx_px: f64,
    pub cy_px: f64,
    pub horizontal_fov_rad: f64,
    /// Camera origin in the ego body frame.
    pub mount_position_in_ego_m: Vec3,
    /// Camera orientation relative to the body frame: roll, pitch (positive looks down), yaw.
    pub mount_roll_pitch_yaw_rad: Vec3,
    pub rate_hz: f64,
    /// Encoding of the frames on camera/front.
    pub encoding: ImageEncoding,
}

impl CameraInfo {
    /// A pinhole camera with square pixels and the principal point at the image centre, from
    /// its horizontal field of view: fx = fy = (width / 2) / tan(fov / 2).
    pub fn pinhole(
        width: u32,
        height: u32,
        horizontal_fov_rad: f64,
        mount_position_in_ego_m: Vec3,
        mount_roll_pitch_yaw_rad: Vec3,
        rate_hz: f64,
        encoding: ImageEncoding,
    ) -> CameraInfo {
        let f = (width as f64 / 2.0) / (horizontal_fov_rad / 2.0).tan();
        CameraInfo {
            width,
            height,
            fx_px: f,
            fy_px: f,
            cx_px: width as f64 / 2.0,
            cy_px: height as f64 / 2.0,
            horizontal_fov_rad,
            mount_position_in_ego_m,
            mount_roll_pitch_yaw_rad,
            rate_hz,
            encoding,
        }
    }
}

impl Message for CameraInfo {
    const KIND: MessageKind = MessageKind::CameraInfo;
    fn check(&self) -> Result<(), Unsound> {
        if self.width == 0 || self.height == 0 {
            return Err(Unsound(format!("image size {}x{} is empty", self.width, self.height)));
        }
        if !(self.fx_px > 0.0 && self.fy_px > 0.0) {
            return Err(Unsound(format!("focal lengths must be positive, got fx={} fy={}", self.fx_px, self.fy_px)));
        }
        Ok(())
    }
}

/// The CameraInfo of docs/wire-format.md's byte example.
pub fn example_info() -> CameraInfo {
    CameraInfo::pinhole(
        640,
        480,
        std::f64::consts::FRAC_PI_3,
        [1.5, 0.0, 1.4],
        [0.0, 0.05, 0.0],
        20.0,
        ImageEncoding::Rgb8,
    )
}
