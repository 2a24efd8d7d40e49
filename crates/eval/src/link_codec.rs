//! `eval detect --frames ENC`: every frame goes through a frame encoding and back before the
//! detector sees it, as it would through a link copy (docs/deployment.md), and what that costs
//! is measured: bytes per frame, encode and decode time. With JPEG this is what lossy
//! compression costs the detector (its scores beside a raw run).

use std::time::Instant;

use serde::Serialize;

use slipstream_contract::config::CameraEncoding;
use slipstream_contract::msg;

/// Frames through one encoding, and what they cost.
pub struct LinkCodec {
    pub encoding: CameraEncoding,
    pub jpeg_quality: u8,
    bytes: Vec<f64>,
    /// Raw size / encoded size, per frame.
    ratios: Vec<f64>,
    encode_ms: Vec<f64>,
    decode_ms: Vec<f64>,
}

/// Medians over the frames of a run (front camera and narrow camera together).
#[derive(Debug, Clone, Serialize)]
pub struct LinkCost {
    pub encoding: &'static str,
    /// Used when the encoding is JPEG.
    pub jpeg_quality: u8,
    pub frames: usize,
    pub bytes_per_frame: f64,
    /// The 90th percentile of bytes per frame (noisy or busy frames compress less).
    pub bytes_p90: f64,
    /// Raw size / encoded size (median over frames).
    pub ratio: f64,
    pub encode_ms: f64,
    pub decode_ms: f64,
}

impl LinkCodec {
    pub fn new(encoding: CameraEncoding, jpeg_quality: u8) -> LinkCodec {
        LinkCodec {
            encoding,
            jpeg_quality,
            bytes: Vec::new(),
            ratios: Vec::new(),
            encode_ms: Vec::new(),
            decode_ms: Vec::new(),
        }
    }

    /// The frame's pixels after encoding and decoding (for raw, the same bytes, measured too).
    pub fn pass(&mut self, rgb: &[u8], width: u32, height: u32) -> Vec<u8> {
        let enc = self.encoding.image_encoding();
        let t = Instant::now();
        let data = msg::encode_pixels(rgb, width, height, enc, self.jpeg_quality).expect("a rendered frame encodes");
        self.encode_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let back = msg::decode_pixels(&data, width, height, enc).expect("a frame just encoded decodes").into_owned();
        self.decode_ms.push(t.elapsed().as_secs_f64() * 1e3);
        self.bytes.push(data.len() as f64);
        self.ratios.push(rgb.len() as f64 / data.len().max(1) as f64);
        back
    }

    /// The medians.
    pub fn cost(&self) -> LinkCost {
        LinkCost {
            encoding: self.encoding.name(),
            jpeg_quality: self.jpeg_quality,
            frames: self.bytes.len(),
            bytes_per_frame: median(&self.bytes),
            bytes_p90: quantile(&self.bytes, 0.9),
            ratio: median(&self.ratios),
            encode_ms: median(&self.encode_ms),
            decode_ms: median(&self.decode_ms),
        }
    }
}

fn median(v: &[f64]) -> f64 {
    quantile(v, 0.5)
}

fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lossless_pass_gives_the_same_pixels_and_counts_its_cost() {
        let rgb: Vec<u8> = (0..64 * 48 * 3).map(|i| (i / 3 % 64) as u8).collect();
        let mut c = LinkCodec::new(CameraEncoding::Lz4, 85);
        assert_eq!(c.pass(&rgb, 64, 48), rgb);
        let cost = c.cost();
        assert_eq!((cost.encoding, cost.frames), ("lz4", 1));
        assert!(cost.ratio > 2.0, "{cost:?}");
        assert!(cost.encode_ms >= 0.0 && cost.decode_ms >= 0.0);
    }

    #[test]
    fn a_jpeg_pass_changes_pixels_a_little() {
        let rgb: Vec<u8> = (0..64 * 48 * 3).map(|i| ((i / 3 % 64) * 3) as u8).collect();
        let back = LinkCodec::new(CameraEncoding::Jpeg, 50).pass(&rgb, 64, 48);
        assert_eq!(back.len(), rgb.len());
        assert_ne!(back, rgb);
    }
}
