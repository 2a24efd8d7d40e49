//! JPEG and PNG frames, through the `image` crate. Behind the `images` feature: a node that
//! reads raw or LZ4 frames, or no frames at all, builds without an image codec; without the
//! feature a JPEG or PNG frame is an error that names it.

use super::image_encoding::ImageEncoding;
use super::pixel_error::PixelError;

/// RGB8 pixels as JPEG (`quality` 1..=100) or PNG.
#[cfg(feature = "images")]
pub(super) fn encode(
    rgb: &[u8],
    width: u32,
    height: u32,
    encoding: ImageEncoding,
    quality: u8,
) -> Result<Vec<u8>, PixelError> {
    use image::ImageEncoder as _;
    let mut out = Vec::with_capacity(rgb.len() / 4);
    match encoding {
        ImageEncoding::Jpeg => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100))
            .encode(rgb, width, height, image::ExtendedColorType::Rgb8)
            .map_err(codec(encoding, "encoding failed"))?,
        // Fast compression with adaptive filtering: about 3x smaller than raw on rendered
        // scenes at a fraction of the default level's time.
        ImageEncoding::Png => image::codecs::png::PngEncoder::new_with_quality(
            &mut out,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        )
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(codec(encoding, "encoding failed"))?,
        other => return Err(PixelError::NoCodec(other)),
    }
    Ok(out)
}

/// A JPEG or PNG frame's pixels as RGB8; its header must state the frame's size.
#[cfg(feature = "images")]
pub(super) fn decode(data: &[u8], width: u32, height: u32, encoding: ImageEncoding) -> Result<Vec<u8>, PixelError> {
    let format = match encoding {
        ImageEncoding::Jpeg => image::ImageFormat::Jpeg,
        ImageEncoding::Png => image::ImageFormat::Png,
        other => return Err(PixelError::NoCodec(other)),
    };
    let reader = || image::ImageReader::with_format(std::io::Cursor::new(data), format);
    let (w, h) = reader().into_dimensions().map_err(codec(encoding, "header does not decode"))?;
    if (w, h) != (width, height) {
        return Err(PixelError::HeaderSize { encoding, width, height, got_width: w, got_height: h });
    }
    let img = reader().decode().map_err(codec(encoding, "image does not decode"))?.into_rgb8();
    Ok(img.into_raw())
}

/// The codec's error on `encoding`, said with what was being done.
#[cfg(feature = "images")]
fn codec(encoding: ImageEncoding, what: &'static str) -> impl FnOnce(image::ImageError) -> PixelError {
    move |e| PixelError::Codec { encoding, what, message: e.to_string() }
}

#[cfg(not(feature = "images"))]
pub(super) fn encode(_: &[u8], _: u32, _: u32, encoding: ImageEncoding, _: u8) -> Result<Vec<u8>, PixelError> {
    Err(PixelError::NoCodec(encoding))
}

#[cfg(not(feature = "images"))]
pub(super) fn decode(_: &[u8], _: u32, _: u32, encoding: ImageEncoding) -> Result<Vec<u8>, PixelError> {
    Err(PixelError::NoCodec(encoding))
}
