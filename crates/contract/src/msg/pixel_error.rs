//! Why a frame's pixels cannot be encoded or decoded, one type for every encoding (the size
//! checks, LZ4, the image codec and a build without it), so a reader's log and a sender's
//! error name the sizes and the encoding that did not fit.

use super::image_encoding::ImageEncoding;

/// Why a frame's pixels cannot be encoded or decoded: each says the sizes and the encoding, so
/// a reader's log names what the sender got wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PixelError {
    #[error("frame size {width}x{height} is empty")]
    Empty { width: u32, height: u32 },
    #[error("{width}x{height} is more than {max} pixels")]
    TooLarge { width: u32, height: u32, max: u64 },
    #[error("{width}x{height} Rgb8 needs {needed} bytes, got {got}")]
    RawLength { width: u32, height: u32, needed: usize, got: usize },
    /// An LZ4 block too short to expand to the frame's size (LZ4 expands at most `max_ratio`
    /// to 1).
    #[error("{got} bytes of LZ4 cannot expand to {width}x{height} Rgb8 ({needed} bytes; at most {max_ratio}x)")]
    Lz4TooShort { width: u32, height: u32, needed: usize, got: usize, max_ratio: usize },
    #[error("Lz4 block does not decode: {0}")]
    Lz4(String),
    #[error("Lz4 block expands to {got} bytes, {width}x{height} Rgb8 is {needed}")]
    Lz4Length { width: u32, height: u32, needed: usize, got: usize },
    #[error("empty {0:?} frame")]
    EmptyCompressed(ImageEncoding),
    /// A JPEG or PNG header that states another size than the frame.
    #[error("{encoding:?} image is {got_width}x{got_height}, the frame says {width}x{height}")]
    HeaderSize { encoding: ImageEncoding, width: u32, height: u32, got_width: u32, got_height: u32 },
    /// The image codec refused the pixels or the bytes (`what`: "encoding failed", "header
    /// does not decode", "image does not decode").
    #[error("{encoding:?} {what}: {message}")]
    Codec { encoding: ImageEncoding, what: &'static str, message: String },
    /// A JPEG or PNG frame in a build without an image codec.
    #[error("{0:?} frames need the contract crate's `images` feature (raw and Lz4 frames do not)")]
    NoCodec(ImageEncoding),
}
