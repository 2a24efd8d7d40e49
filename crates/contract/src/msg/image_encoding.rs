//! How a camera frame's bytes are encoded: the one enum both the frame messages
//! ([`super::camera`]) and the pixel codecs ([`super::pixels`]) speak.

use serde::{Deserialize, Serialize};

/// How a frame's bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ImageEncoding {
    /// width x height x 3 bytes, rows top to bottom, R G B per pixel.
    Rgb8,
    /// A JPEG file.
    Jpeg,
    /// A PNG file.
    Png,
    /// Rgb8 pixels compressed as one LZ4 block (the block format: no frame header, no size
    /// prefix); it expands to exactly width x height x 3 bytes. Lossless, ~1 ms a 640x480 frame.
    Lz4,
}

impl ImageEncoding {
    /// The byte count a frame must have, when the encoding fixes it.
    pub fn expected_len(self, width: u32, height: u32) -> Option<usize> {
        match self {
            ImageEncoding::Rgb8 => Some(width as usize * height as usize * 3),
            ImageEncoding::Jpeg | ImageEncoding::Png | ImageEncoding::Lz4 => None,
        }
    }
}
