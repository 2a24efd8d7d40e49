//! A frame's pixels in each [`ImageEncoding`]: encoding RGB8 into it and decoding it back,
//! with the bounds that keep a hostile frame from costing more than a legitimate one.
//!
//! Frames cross links in whichever encoding fits the link (docs/deployment.md, "Camera frames
//! on a LAN"), so every reader decodes every encoding through this one place. A frame is
//! refused before anything is allocated for it when its size is beyond [`MAX_FRAME_PIXELS`],
//! when an LZ4 block is too short to expand to the size the frame states (LZ4 expands at
//! most [`LZ4_MAX_RATIO`] to 1), or when a JPEG or PNG header states another size than the
//! frame.

use std::borrow::Cow;

use super::image_encoding::ImageEncoding;
use super::pixel_error::PixelError;

/// The most pixels a frame may have (8192 x 8192, 192 MiB of RGB8): a frame stating more is
/// refused before it is decoded.
pub const MAX_FRAME_PIXELS: u64 = 8192 * 8192;

/// LZ4 turns n bytes into at most ~255 n: a block shorter than `expected / 255` cannot be an
/// honest frame of that size.
pub(super) const LZ4_MAX_RATIO: usize = 255;

/// Whether a frame's stated size and byte count are acceptable for its encoding, checked
/// before any decoding (what a decoder needs to trust the size it allocates).
pub fn check_size(width: u32, height: u32, encoding: ImageEncoding, len: usize) -> Result<(), PixelError> {
    if width == 0 || height == 0 {
        return Err(PixelError::Empty { width, height });
    }
    let pixels = width as u64 * height as u64;
    if pixels > MAX_FRAME_PIXELS {
        return Err(PixelError::TooLarge { width, height, max: MAX_FRAME_PIXELS });
    }
    let needed = pixels as usize * 3;
    match encoding {
        ImageEncoding::Rgb8 if len != needed => Err(PixelError::RawLength { width, height, needed, got: len }),
        ImageEncoding::Lz4 if len == 0 || len.saturating_mul(LZ4_MAX_RATIO) + 16 < needed => {
            Err(PixelError::Lz4TooShort { width, height, needed, got: len, max_ratio: LZ4_MAX_RATIO })
        }
        ImageEncoding::Jpeg | ImageEncoding::Png if len == 0 => Err(PixelError::EmptyCompressed(encoding)),
        _ => Ok(()),
    }
}

/// RGB8 pixels in `encoding`; `quality` (1..=100) applies to JPEG only.
pub fn encode(
    rgb: &[u8],
    width: u32,
    height: u32,
    encoding: ImageEncoding,
    quality: u8,
) -> Result<Vec<u8>, PixelError> {
    check_size(width, height, ImageEncoding::Rgb8, rgb.len())?;
    match encoding {
        ImageEncoding::Rgb8 => Ok(rgb.to_vec()),
        ImageEncoding::Lz4 => Ok(lz4_flex::block::compress(rgb)),
        ImageEncoding::Jpeg | ImageEncoding::Png => super::compressed::encode(rgb, width, height, encoding, quality),
    }
}

/// The frame's pixels as RGB8 (width x height x 3): raw frames borrowed as they are, the others
/// decoded. Checks [`check_size`] first; a decoded image of another size is an error.
pub fn decode<'a>(
    data: &'a [u8],
    width: u32,
    height: u32,
    encoding: ImageEncoding,
) -> Result<Cow<'a, [u8]>, PixelError> {
    check_size(width, height, encoding, data.len())?;
    let needed = width as usize * height as usize * 3;
    match encoding {
        ImageEncoding::Rgb8 => Ok(Cow::Borrowed(data)),
        ImageEncoding::Lz4 => {
            // The output is allocated at the size the frame states (bounded above), never at
            // a size the block claims.
            let rgb = lz4_flex::block::decompress(data, needed).map_err(|e| PixelError::Lz4(e.to_string()))?;
            if rgb.len() != needed {
                return Err(PixelError::Lz4Length { width, height, needed, got: rgb.len() });
            }
            Ok(Cow::Owned(rgb))
        }
        ImageEncoding::Jpeg | ImageEncoding::Png => {
            super::compressed::decode(data, width, height, encoding).map(Cow::Owned)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene-like image: sky, road and a dark box, with a little texture.
    fn scene(w: u32, h: u32) -> Vec<u8> {
        let mut px = Vec::with_capacity((w * h * 3) as usize);
        for y in 0..h {
            for x in 0..w {
                let v = if y < h / 2 { [150u8, 180, 220] } else { [90, 90, 95] };
                let dark = (w / 3..w / 2).contains(&x) && (h / 2..h / 2 + h / 8).contains(&y);
                let t = ((x * 7 + y * 13) % 5) as u8;
                px.extend(if dark { [20 + t, 20, 25] } else { [v[0] + t, v[1], v[2]] });
            }
        }
        px
    }

    /// The lossless encodings this build has (PNG with the `images` feature).
    const LOSSLESS: &[ImageEncoding] = &[
        ImageEncoding::Rgb8,
        ImageEncoding::Lz4,
        #[cfg(feature = "images")]
        ImageEncoding::Png,
    ];

    #[test]
    fn lossless_encodings_round_trip_bit_exact() {
        let rgb = scene(64, 48);
        for &enc in LOSSLESS {
            let bytes = encode(&rgb, 64, 48, enc, 85).unwrap();
            assert_eq!(decode(&bytes, 64, 48, enc).unwrap().as_ref(), &rgb[..], "{enc:?}");
        }
    }

    #[cfg(feature = "images")]
    #[test]
    fn jpeg_round_trips_within_a_small_error() {
        let rgb = scene(64, 48);
        let bytes = encode(&rgb, 64, 48, ImageEncoding::Jpeg, 85).unwrap();
        let back = decode(&bytes, 64, 48, ImageEncoding::Jpeg).unwrap();
        let mean_abs: f64 =
            rgb.iter().zip(back.iter()).map(|(a, b)| (*a as f64 - *b as f64).abs()).sum::<f64>() / rgb.len() as f64;
        assert!(mean_abs < 6.0, "mean error {mean_abs}");
    }

    #[test]
    fn an_lz4_bomb_is_refused_before_it_is_expanded() {
        // 100 bytes cannot honestly expand to 8000x8000 RGB8 (192 MB).
        let err = decode(&[0u8; 100], 8000, 8000, ImageEncoding::Lz4).unwrap_err();
        assert!(matches!(err, PixelError::Lz4TooShort { got: 100, .. }), "{err}");
        assert!(err.to_string().contains("cannot expand"), "{err}");
        let err = decode(&[0u8; 100], 9000, 9000, ImageEncoding::Lz4).unwrap_err();
        assert_eq!(err, PixelError::TooLarge { width: 9000, height: 9000, max: MAX_FRAME_PIXELS });
    }

    #[test]
    fn a_truncated_or_mislabelled_frame_is_an_error_not_a_panic() {
        let rgb = scene(64, 48);
        #[cfg(feature = "images")]
        let encodings = [ImageEncoding::Lz4, ImageEncoding::Jpeg, ImageEncoding::Png];
        #[cfg(not(feature = "images"))]
        let encodings = [ImageEncoding::Lz4];
        for enc in encodings {
            let bytes = encode(&rgb, 64, 48, enc, 85).unwrap();
            assert!(decode(&bytes[..bytes.len() / 2], 64, 48, enc).is_err(), "{enc:?} truncated");
            assert!(decode(&rgb[..bytes.len().min(rgb.len())], 64, 48, enc).is_err(), "raw bytes labelled {enc:?}");
        }
        // An LZ4 block of another frame size does not pass for this one.
        let lz4 = encode(&rgb, 64, 48, ImageEncoding::Lz4, 85).unwrap();
        assert!(decode(&lz4, 32, 48, ImageEncoding::Lz4).is_err());
    }

    #[cfg(not(feature = "images"))]
    #[test]
    fn jpeg_and_png_without_the_images_feature_are_errors_that_name_it() {
        for enc in [ImageEncoding::Jpeg, ImageEncoding::Png] {
            let err = encode(&scene(8, 8), 8, 8, enc, 85).unwrap_err();
            assert!(err.to_string().contains("`images` feature"), "{err}");
            assert_eq!(decode(&[0xff, 0xd8, 0xff], 8, 8, enc).unwrap_err(), PixelError::NoCodec(enc));
        }
    }

    #[cfg(feature = "images")]
    #[test]
    fn a_compressed_image_stating_another_size_is_refused_from_its_header() {
        let big = encode(&scene(128, 96), 128, 96, ImageEncoding::Png, 85).unwrap();
        let err = decode(&big, 64, 48, ImageEncoding::Png).unwrap_err();
        assert!(matches!(err, PixelError::HeaderSize { got_width: 128, got_height: 96, .. }), "{err}");
    }
}
