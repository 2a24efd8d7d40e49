//! Segmentation: the frame's luma prepared (noise measured, rows smoothed when noisy, the
//! road's brightness), and the dark band where each vehicle meets the road found as
//! connected components of dark runs, split where its contact row jumps and joined where one
//! band was broken in two.

use super::*;

impl Detector {
    /// Connected components of the pixels darker than `dark`, below the horizon.
    pub(super) fn dark_components(&mut self, w: usize, h: usize, first_row: usize, dark: u8) -> Vec<Component> {
        let row_start = self.dark_runs(w, h, first_row, dark);
        self.join_runs(&row_start);
        let (kept, cols) = self.contact_profiles();
        let mut out = Vec::new();
        let mut merged: Vec<(u32, u32, u32)> = Vec::new();
        for (k, &(_, first, offset)) in kept.iter().enumerate() {
            let end = kept.get(k + 1).map_or(cols.len(), |c| c.2);
            // (column, lowest row, highest row) per column.
            merged.clear();
            merged.extend(
                cols[offset..end]
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| c.1 != u32::MAX)
                    .map(|(j, &(lo, hi))| (first + j as u32, lo, hi)),
            );
            split_profile(&merged, &mut out);
        }
        out
    }

    /// The horizontal runs of dark pixels, row by row from `first_row`, into `self.runs`;
    /// returns where each row's runs start (and, last, their count).
    pub(super) fn dark_runs(&mut self, w: usize, h: usize, first_row: usize, dark: u8) -> Vec<usize> {
        self.runs.clear();
        let mut row_start = Vec::with_capacity(h - first_row + 1);
        for v in first_row..h {
            row_start.push(self.runs.len());
            let row = &self.luma[v * w..(v + 1) * w];
            let mut u = 0;
            while u < w {
                if row[u] < dark {
                    let start = u;
                    while u < w && row[u] < dark {
                        u += 1;
                    }
                    self.runs.push(Run { row: v as u32, u0: start as u32, u1: u as u32 - 1 });
                } else {
                    u += 1;
                }
            }
        }
        row_start.push(self.runs.len());
        row_start
    }

    /// Joins runs that touch runs of the row above (4-connected) in `self.parent`.
    pub(super) fn join_runs(&mut self, row_start: &[usize]) {
        self.parent.clear();
        self.parent.extend(0..self.runs.len() as u32);
        for r in 1..row_start.len() - 1 {
            let (above, here) = (row_start[r - 1]..row_start[r], row_start[r]..row_start[r + 1]);
            let mut a = above.start;
            for i in here {
                let run = self.runs[i];
                while a < above.end && self.runs[a].u1 < run.u0 {
                    a += 1;
                }
                let mut b = a;
                while b < above.end && self.runs[b].u0 <= run.u1 {
                    union(&mut self.parent, i as u32, b as u32);
                    b += 1;
                }
            }
        }
    }

    /// Per component of at least three pixels, the lowest and the highest dark row of each
    /// column it covers: the contact profile. Returns the components in root order as (root,
    /// first column, offset of its columns) and the columns of all of them in one buffer
    /// ((0, u32::MAX) where a component has no pixel): one pass over the runs, no per-pixel
    /// allocation or sort.
    #[allow(clippy::type_complexity)]
    pub(super) fn contact_profiles(&mut self) -> (Vec<(u32, u32, usize)>, Vec<(u32, u32)>) {
        let mut roots = Vec::with_capacity(self.runs.len());
        let mut extent: std::collections::HashMap<u32, (u32, u32, u32)> = std::collections::HashMap::new();
        for i in 0..self.runs.len() {
            let root = find(&mut self.parent, i as u32);
            roots.push(root);
            let r = self.runs[i];
            let e = extent.entry(root).or_insert((r.u0, r.u1, 0));
            e.0 = e.0.min(r.u0);
            e.1 = e.1.max(r.u1);
            e.2 += r.u1 - r.u0 + 1;
        }
        let mut kept: Vec<(u32, u32, u32)> =
            extent.iter().filter(|e| e.1 .2 >= 3).map(|(&r, e)| (r, e.0, e.1)).collect();
        kept.sort_unstable();
        let mut len = 0;
        let kept: Vec<(u32, u32, usize)> = kept
            .into_iter()
            .map(|(root, u0, u1)| {
                let offset = len;
                len += (u1 - u0 + 1) as usize;
                (root, u0, offset)
            })
            .collect();
        const NONE: (u32, u32) = (0, u32::MAX);
        let mut cols = vec![NONE; len];
        for (r, root) in self.runs.iter().zip(&roots) {
            let Ok(k) = kept.binary_search_by_key(root, |c| c.0) else { continue };
            let (_, first, offset) = kept[k];
            for c in &mut cols[offset + (r.u0 - first) as usize..=offset + (r.u1 - first) as usize] {
                c.0 = c.0.max(r.row);
                c.1 = c.1.min(r.row);
            }
        }
        (kept, cols)
    }

    /// Far away the band under a vehicle is thinner than a row: blended with the road, it is
    /// no longer darker than the threshold, and only the wheels at its sides are. Two
    /// components on the same contact row are one vehicle's when the pixels between them on
    /// that row are darker than the road (the thin band), or on a row above it within a
    /// vehicle's ground clearance (the band fell between rows and the road under the body
    /// shows between the wheels), and together they are no wider than a vehicle at their
    /// distance (two vehicles side by side are a lane apart: wider).
    pub(super) fn join_split_bands(&self, w: usize, road: u8, mut components: Vec<Component>) -> Vec<Component> {
        let origin_x = self.camera.origin_in_body().x;
        let bridge = road as f32 * BRIDGE_RATIO;
        components.sort_by_key(|c| c.u0);
        let mut i = 0;
        while i < components.len() {
            let a = components[i];
            let partner = components.iter().enumerate().skip(i + 1).find_map(|(j, b)| {
                if b.u0 <= a.u1 + 1 || b.v1.abs_diff(a.v1) > 1 {
                    return None;
                }
                let v1 = a.v1.max(b.v1);
                let contact = self.camera.ground_point((a.u0 + b.u1 + 1) as f64 / 2.0, v1 as f64 + 1.0)?;
                let px_per_m = self.camera.info.fx_px / (contact.x - origin_x).max(0.5);
                let width_m = (b.u1 + 1 - a.u0) as f64 / px_per_m;
                if width_m > self.params.max_width_m {
                    return None;
                }
                // Wheels end on the contact row. Two parts no farther apart than a
                // motorcycle is wide, with a dark part filling the columns between them (one
                // dark region, split where its lowest row jumps) that reaches lower, are a far
                // motorcycle's body over its rear tyre, which is where it meets the road.
                let lower_between = |c: &Component| c.u0 == a.u1 + 1 && c.u1 + 1 == b.u0 && c.v1 > v1 + 1;
                if width_m <= MOTORCYCLE_MAX_WIDTH_M && components.iter().any(lower_between) {
                    return None;
                }
                let between = |v: u32| {
                    let row = &self.luma[v as usize * w..(v as usize + 1) * w];
                    let gap = &row[a.u1 as usize + 1..b.u0 as usize];
                    gap.iter().map(|&l| l as f32).sum::<f32>() / gap.len() as f32
                };
                let clearance_rows = (GROUND_CLEARANCE_M * px_per_m).ceil() as u32 + 1;
                let darkest = (0..=clearance_rows.min(v1)).map(|up| between(v1 - up)).fold(f32::INFINITY, f32::min);
                (darkest < bridge).then_some(j)
            });
            match partner {
                Some(j) => {
                    let b = components.remove(j);
                    components[i] = Component {
                        u0: a.u0,
                        u1: b.u1,
                        v1: a.v1.max(b.v1),
                        flat_u0: a.flat_u0.min(b.flat_u0),
                        flat_u1: a.flat_u1.max(b.flat_u1),
                        reach_u0: a.reach_u0.min(b.reach_u0),
                        reach_u1: a.reach_u1.max(b.reach_u1),
                    };
                    // The joined band may join the next one too: look again from it.
                }
                None => i += 1,
            }
        }
        components
    }
}

/// Neighbouring columns (column, lowest row, highest row) where a thin band meets a tall dark
/// region a step lower: a far vehicle's contact band touching a nearer one's dark body or
/// glass in the image, not one band (a wheel at a band's side ends on the band's row).
pub(super) fn thin_meets_tall(a: (u32, u32, u32), b: (u32, u32, u32)) -> bool {
    let (ta, tb) = (a.1 - a.2 + 1, b.1 - b.2 + 1);
    a.1.abs_diff(b.1) >= 2 && ta.max(tb) >= TALL_RATIO * ta.min(tb)
}

/// The luma's noise (standard deviation, levels), from the lower ground's differences between
/// horizontal neighbours: their median absolute value is 0.954 sigma for Gaussian noise, and
/// edges (markings, vehicles) are too few to move the median.
pub(super) fn luma_noise(luma: &[u8], w: usize, h: usize, first_row: usize) -> f32 {
    let mut hist = [0u32; 256];
    let mut n = 0u32;
    let start = (first_row + (h - first_row) / 3).min(h - 1);
    for v in (start..h).step_by(3) {
        let row = &luma[v * w..(v + 1) * w];
        for u in (w / 8..w * 7 / 8).step_by(2) {
            hist[row[u].abs_diff(row[u + 1]) as usize] += 1;
            n += 1;
        }
    }
    let mut seen = 0;
    let median = hist.iter().position(|&c| {
        seen += c;
        2 * seen > n
    });
    median.map_or(0.0, |m| m as f32 / 0.954)
}

/// `rgb` with each row's channels replaced by their moving average over SMOOTH_WINDOW pixels
/// (the window shrinks at the row's ends), into `out`. One pass per row, a running sum per
/// channel; the full window divides by multiplying (x / 5 = x * 13108 >> 16 for x <= 1275).
pub(super) fn smooth_rows(rgb: &[u8], out: &mut Vec<u8>, w: usize) {
    const R: usize = SMOOTH_WINDOW / 2;
    const FULL: u32 = (1u32 << 16).div_ceil(SMOOTH_WINDOW as u32);
    out.resize(rgb.len(), 0);
    if w <= SMOOTH_WINDOW {
        out.copy_from_slice(rgb);
        return;
    }
    for (src, dst) in rgb.chunks_exact(w * 3).zip(out.chunks_exact_mut(w * 3)) {
        let mut sum = [0u32; 3];
        for u in 0..R {
            for c in 0..3 {
                sum[c] += src[u * 3 + c] as u32;
            }
        }
        for u in 0..w {
            // The window is u - R ..= u + R, cut at the row's ends.
            if u + R < w {
                for c in 0..3 {
                    sum[c] += src[(u + R) * 3 + c] as u32;
                }
            }
            if u > R {
                for c in 0..3 {
                    sum[c] -= src[(u - R - 1) * 3 + c] as u32;
                }
            }
            let n = (u + R).min(w - 1) + 1 - u.saturating_sub(R);
            for c in 0..3 {
                dst[u * 3 + c] =
                    if n == SMOOTH_WINDOW { ((sum[c] * FULL) >> 16) as u8 } else { (sum[c] / n as u32) as u8 };
            }
        }
    }
}

/// The road's luminance: the mode of the lower middle of the image.
pub(super) fn road_luma(luma: &[u8], w: usize, h: usize, first_row: usize) -> u8 {
    let mut hist = [0u32; 64];
    let start = (first_row + (h - first_row) / 3).min(h - 1);
    for v in (start..h).step_by(2) {
        for u in (w / 5..w * 4 / 5).step_by(2) {
            hist[(luma[v * w + u] >> 2) as usize] += 1;
        }
    }
    let mode = hist.iter().enumerate().max_by_key(|(_, n)| **n).map(|(i, _)| i).unwrap_or(32);
    (mode * 4 + 2) as u8
}

/// Splits one component's contact profile ((column, lowest row, highest row) per column) where
/// the contact row jumps or a column is missing: two vehicles whose dark bands touch in the
/// image stand at different distances. Stretches of two columns or more go to `out`.
pub(super) fn split_profile(merged: &[(u32, u32, u32)], out: &mut Vec<Component>) {
    let mut start = 0;
    for i in 1..=merged.len() {
        let split = i == merged.len()
            || merged[i].0 != merged[i - 1].0 + 1
            || (merged[i].1 as i64 - merged[i - 1].1 as i64).abs() > JUMP_PX
            || thin_meets_tall(merged[i - 1], merged[i]);
        if split {
            if i - start >= 2 {
                out.push(component_of(merged, start, i));
            }
            start = i;
        }
    }
}

/// The stretch `merged[start..end]` of a contact profile as a component.
pub(super) fn component_of(merged: &[(u32, u32, u32)], start: usize, end: usize) -> Component {
    let seg = &merged[start..end];
    // The flat lowest part is the rear edge (the side, if seen, rises away from it): it gives
    // the width and the centre.
    let v1 = seg.iter().map(|c| c.1).max().unwrap_or(0);
    let flat = seg.iter().filter(|c| c.1 + FLAT_PX >= v1);
    let (fu0, fu1) = flat.fold((u32::MAX, 0), |(a, b), c| (a.min(c.0), b.max(c.0)));
    // Dark columns joined to it on either side that end higher: the body over its wheels (a
    // bumper, a chassis), split off by the jump.
    let above = |c: &(u32, u32, u32)| c.1 <= v1;
    let mut reach_u0 = seg[0].0;
    for j in (0..start).rev() {
        if merged[j].0 + 1 != reach_u0 || !above(&merged[j]) {
            break;
        }
        reach_u0 = merged[j].0;
    }
    let mut reach_u1 = seg[seg.len() - 1].0;
    for c in &merged[end..] {
        if c.0 != reach_u1 + 1 || !above(c) {
            break;
        }
        reach_u1 = c.0;
    }
    Component { u0: seg[0].0, u1: seg[seg.len() - 1].0, v1, flat_u0: fu0, flat_u1: fu1, reach_u0, reach_u1 }
}

pub(super) fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

pub(super) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}
