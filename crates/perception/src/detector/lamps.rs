//! Brake lamps: lit lamps are a saturated red brighter than any sunlit paint.

use super::*;

/// Pixels of a lit lamp (LIT_RED_MIN, LIT_RED_OVER_GB) in the given columns and rows.
pub(super) fn lit_pixels(
    rgb: &[u8],
    w: usize,
    columns: std::ops::RangeInclusive<usize>,
    rows: std::ops::RangeInclusive<usize>,
) -> u32 {
    let mut n = 0;
    for v in rows {
        let row = &rgb[v * w * 3..(v + 1) * w * 3];
        for px in row[columns.start() * 3..(columns.end() + 1).min(w) * 3].chunks_exact(3) {
            let (r, g, b) = (px[0], px[1] as i32, px[2] as i32);
            n += u32::from(r >= LIT_RED_MIN && r as i32 - g.max(b) >= LIT_RED_OVER_GB);
        }
    }
    n
}
