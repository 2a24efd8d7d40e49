//! Measurement: from one dark component to a vehicle, or the reason it is none. Its contact
//! row to a fraction of a row, its distance and width, its height against the background, a
//! side seen beside its rear, its class and confidence.

use super::*;

impl Detector {
    /// Checks a dark component as a vehicle's contact band and measures the vehicle above it.
    pub(super) fn candidate(&self, rgb: &[u8], w: usize, h: usize, c: &Component) -> Result<FrameDetection, Rejection> {
        let p = &self.params;
        // The contact line is the lower edge of the component's lowest row; its horizontal
        // extent is that of the component's bottom rows.
        let contact_v = c.v1 as f64 + 1.0;
        if c.v1 as usize >= h - 1 {
            return Err(Rejection::OffTheBottom);
        }
        let (bu0, bu1) = (c.flat_u0, c.flat_u1);
        let centre_u = (bu0 + bu1 + 1) as f64 / 2.0;
        let edge_v = self.contact_edge(w, h, c).unwrap_or(contact_v);
        let contact = self.camera.ground_point(centre_u, edge_v).ok_or(Rejection::AboveTheHorizon)?;
        if contact.x < 1.0 || contact.x > p.max_distance_m {
            return Err(Rejection::ContactAt(contact.x));
        }
        let origin = self.camera.origin_in_body();
        let px_per_m = self.camera.info.fx_px / (contact.x - origin.x).max(0.5);
        let width_m = (bu1 - bu0 + 1) as f64 / px_per_m;
        let (u0, u1) = (c.u0.min(bu0) as usize, c.u1.max(bu1) as usize);
        let oblique = self.oblique_side(w, h, c, width_m)?;
        let (top, height_m, (r0, r1)) = self.height(rgb, w, c, (u0, u1), contact_v, px_per_m)?;
        // Not cut by the image's side.
        let whole = bu0 > 0 && (bu1 as usize) + 1 < w;
        let class = class_of(width_m, height_m, whole);
        let confidence = confidence_of(class, width_m, height_m);
        // A vehicle cut by the image's side (one being passed): the band's centre is the visible
        // part's, metres inside the vehicle's own, which would put a car of the next lane into
        // the ego's. Its inner side is measured: the centre lies half its class's width beyond.
        let half_width = VehicleParams::of_class(class).size_m[1] / 2.0;
        // Seen obliquely, the rear's outer edge is the band's end away from the side.
        let lateral_offset_m = match (bu0 == 0, bu1 as usize + 1 >= w, oblique) {
            (true, false, _) => self.camera.lateral_at((bu1 + 1) as f64, edge_v, contact.x) + half_width,
            (false, true, _) => self.camera.lateral_at(bu0 as f64, edge_v, contact.x) - half_width,
            (_, _, Some(Side::Left)) => self.camera.lateral_at((r1 + 1) as f64, edge_v, contact.x) + half_width,
            (_, _, Some(Side::Right)) => self.camera.lateral_at(r0 as f64, edge_v, contact.x) - half_width,
            _ => contact.y,
        };
        // Stop lamps sit at most LAMPS_MAX_HEIGHT_M above the ground, one on each side (a
        // motorcycle's single lamp in the middle): a lamp of a vehicle beside or beyond this
        // one, showing at one edge of its box, does not light it.
        let lamps_top = (contact_v - LAMPS_MAX_HEIGHT_M * px_per_m).floor().max(top as f64) as usize;
        let rows = lamps_top..=c.v1 as usize;
        // Cut by the image's side, the other lamp may be out of view.
        let brake_lights = if class == ObjectClass::Motorcycle || !whole {
            lit_pixels(rgb, w, u0..=u1, rows) >= LIT_LAMP_MIN_PX
        } else {
            // Seen from the side as well, the lamps are either side of the rear's middle.
            let rear_half_px = (half_width * px_per_m) as usize;
            let mid = match oblique {
                Some(Side::Right) => (r0 + rear_half_px).min(u1 - 1).max(u0),
                Some(Side::Left) => (r1 + 1).saturating_sub(rear_half_px).min(u1 - 1).max(u0),
                None => (u0 + u1) / 2,
            };
            lit_pixels(rgb, w, u0..=mid, rows.clone()) >= 1 && lit_pixels(rgb, w, mid + 1..=u1, rows) >= 1
        };
        Ok(FrameDetection {
            bbox: BoundingBox2d {
                u_min_px: u0 as f32,
                v_min_px: top as f32,
                u_max_px: (u1 + 1) as f32,
                v_max_px: contact_v as f32,
            },
            class,
            distance_m: contact.x + SHADOW_BEHIND_REAR_M,
            distance_sigma_m: self.distance_sigma_m(contact.x),
            lateral_offset_m,
            height_m,
            width_m,
            confidence,
            brake_lights,
        })
    }

    /// The vehicle's top row and height above the contact line at `contact_v`, over the columns
    /// `u0..=u1`, measured against the background beside them; and the columns its body may
    /// reach beyond the band (r0, r1). The background just beside the band can be the
    /// vehicle's own body where it overhangs its wheels (a truck's bumper, seen when the shadow
    /// under it is too thin to show): where dark columns of the same region adjoin the band,
    /// the height is measured beside them (as far as a body overhangs), and beside the band
    /// only if that fails; last, beside the widest overhang a body can have (a van's box over
    /// its wheels, with no dark chassis under it to show where it ends).
    pub(super) fn height(
        &self,
        rgb: &[u8],
        w: usize,
        c: &Component,
        (u0, u1): (usize, usize),
        contact_v: f64,
        px_per_m: f64,
    ) -> Result<(usize, f64, (usize, usize)), Rejection> {
        let p = &self.params;
        let max_rows = (p.max_height_m * px_per_m) as usize;
        // The background columns just outside a0..=a1, where the image has them.
        let beside = |a0: usize, a1: usize| [a0.checked_sub(FLANK_PX), (a1 + FLANK_PX < w).then_some(a1 + FLANK_PX)];
        let flanks = beside(u0, u1);
        let height_from = |flanks: [Option<usize>; 2]| -> Result<(usize, f64), Rejection> {
            let top =
                self.top_row(rgb, w, (u0, u1), (c.v1 as usize, max_rows), flanks).ok_or(Rejection::NothingAbove)?;
            let height_m = (contact_v - top as f64) / px_per_m;
            if height_m < p.min_height_m || height_m > p.max_height_m {
                return Err(Rejection::Height(height_m));
            }
            Ok((top, height_m))
        };
        let overhang_px = (MAX_OVERHANG_M * px_per_m).ceil() as u32;
        let (r0, r1) = (
            c.reach_u0.max((u0 as u32).saturating_sub(overhang_px)) as usize,
            c.reach_u1.min(u1 as u32 + overhang_px) as usize,
        );
        let outside_body = beside(r0, r1);
        let beyond_overhang = match u0.checked_sub(overhang_px as usize) {
            Some(o0) => beside(o0, u1 + overhang_px as usize),
            // The image's side is within the overhang: no background on that side.
            None => [None, beside(0, u1 + overhang_px as usize)[1]],
        };
        let (top, height_m) = if (r0, r1) != (u0, u1) {
            height_from(outside_body).or_else(|_| height_from(flanks))
        } else {
            height_from(flanks)
        }
        .or_else(|why| height_from(beyond_overhang).map_err(|_| why))?;
        Ok((top, height_m, (r0, r1)))
    }

    /// Seen from behind, the band is the rear's. A vehicle turned from the line of sight (in a
    /// bend) also shows one side, receding beside its rear: the band is wider than any rear,
    /// and the vehicle is placed by its rear's outer edge. Returns that side, None for a rear
    /// (or one whose side is too level to show: placed by the band's centre, off by at most
    /// half the side's width), or why a band of `width_m` is no vehicle.
    pub(super) fn oblique_side(
        &self,
        w: usize,
        h: usize,
        c: &Component,
        width_m: f64,
    ) -> Result<Option<Side>, Rejection> {
        let p = &self.params;
        if width_m < p.min_width_m {
            return Err(Rejection::Width(width_m));
        }
        let side = if width_m > MAX_REAR_WIDTH_M { self.receding_side(w, h, c) } else { None };
        if side.is_some() && width_m <= MAX_OBLIQUE_WIDTH_M {
            Ok(side)
        } else if width_m <= p.max_width_m.max(MAX_LEVEL_OBLIQUE_WIDTH_M) {
            Ok(None)
        } else {
            Err(Rejection::Width(width_m))
        }
    }

    /// A contact distance's expected error: the edge is located to about EDGE_SIGMA_ROWS of a
    /// row, and a row covers d^2 / (f h) metres of ground at distance d (f the focal length,
    /// h the camera's height), plus a floor for the ground model.
    pub(super) fn distance_sigma_m(&self, d: f64) -> f64 {
        let o = self.camera.origin_in_body();
        let per_row = (d - o.x).max(0.5).powi(2) / (self.camera.info.fy_px * o.z.max(0.1));
        DISTANCE_SIGMA_FLOOR_M + EDGE_SIGMA_ROWS * per_row
    }

    /// The rear edge's columns (its end columns left out: they hold background too) with the
    /// lowest dark row of each, where that row is the edge's lowest or one above: far away the
    /// shadow under a vehicle is thinner than a row and can fall between rows, and then the
    /// columns between the wheels see the road under the body and end rows higher, at the
    /// body's lower edge (at 150 m three rows are 25 m).
    pub(super) fn edge_columns(&self, w: usize, h: usize, c: &Component) -> Vec<(usize, usize)> {
        let (u0, u1) = if c.flat_u1 >= c.flat_u0 + 3 { (c.flat_u0 + 1, c.flat_u1 - 1) } else { (c.flat_u0, c.flat_u1) };
        let columns = self.lowest_dark_rows(w, h, u0..=u1, c.v1, FLAT_PX + 1);
        let lowest = columns.iter().map(|&(_, lo)| lo).max().unwrap_or(0);
        columns.into_iter().filter(|&(_, lo)| lo + 1 >= lowest).collect()
    }

    /// (column, lowest dark row) for the columns given, looking from `bottom` up to `rows`
    /// above it; columns without a dark pixel there, or too near the image's bottom for the
    /// road below to be measured, are left out.
    pub(super) fn lowest_dark_rows(
        &self,
        w: usize,
        h: usize,
        columns: std::ops::RangeInclusive<u32>,
        bottom: u32,
        rows: u32,
    ) -> Vec<(usize, usize)> {
        let (top, bottom) = (bottom.saturating_sub(rows) as usize, (bottom as usize).min(h - 1));
        columns
            .filter_map(|u| {
                let u = u as usize;
                (top..=bottom).rev().find(|&v| self.luma[v * w + u] < self.dark).map(|lo| (u, lo))
            })
            .filter(|&(_, lo)| lo + 3 < h)
            .collect()
    }

    /// The road's luminance just below a contact edge (the median of the two rows under it).
    pub(super) fn road_below(&self, w: usize, columns: &[(usize, usize)]) -> Option<f32> {
        median(columns.iter().flat_map(|&(u, lo)| [self.luma[(lo + 2) * w + u], self.luma[(lo + 3) * w + u]]).collect())
    }

    /// The band's luminance as a share of the road's, where the band is thick enough to hold
    /// whole pixels (four dark rows up from the edge): the median of the third.
    pub(super) fn band_ratio_of(&self, w: usize, h: usize, c: &Component) -> Option<f32> {
        let columns = self.edge_columns(w, h, c);
        let dark = |u: usize, v: usize| self.luma[v * w + u] < self.dark;
        // The middle half of the rear edge: the tyres, darker than any shadow, stand at its
        // sides (seen from behind or, for a vehicle in the next lane, a little from the side).
        let quarter = columns.len() / 4;
        let inside: Vec<u8> = columns[quarter..columns.len() - quarter]
            .iter()
            .filter(|&&(u, lo)| lo >= 3 && dark(u, lo - 1) && dark(u, lo - 2) && dark(u, lo - 3))
            .map(|&(u, lo)| self.luma[(lo - 2) * w + u])
            .collect();
        if inside.len() < 5 || inside.len() * 4 < columns.len() {
            return None;
        }
        Some(median(inside)? / self.road_below(w, &columns)?.max(1.0))
    }

    /// Where the contact band's lower edge lies, to a fraction of a row (None when it cannot
    /// be measured). A camera's pixel on that edge holds band and road by the share of it each
    /// covers, share = (road - luma) / (road - band) within 0..1, so in each column of the rear
    /// edge the edge lies that share into the lowest row holding band: the road's luminance
    /// measured just below, the band's from the frame's band ratio
    /// (a band a pixel or two thick at 50 m holds no whole pixel to measure it by). Averaged
    /// over the columns, pixel noise mostly cancels.
    pub(super) fn contact_edge(&self, w: usize, h: usize, c: &Component) -> Option<f64> {
        let columns = self.edge_columns(w, h, c);
        let (sum, n) = self.fractional_edges(w, &columns, true)?.fold((0.0, 0), |(s, n), e| (s + e, n + 1));
        Some(sum / n as f64)
    }

    /// The contact edge in the given columns (column, lowest row holding band), to a fraction
    /// of a row (`contact_edge`); None when it cannot be measured. With `skip_tyres`, columns
    /// whose lowest row is darker than any shadow are left out: they end on a tyre, whose
    /// lower edge says nothing of the band's within the row (it stays at the row's end, then
    /// jumps a row; a motorcycle's rear tyre stands at its rear, 0.13 m ahead of the band's
    /// edge, a car's far ones in its row from ~80 m). Only while a quarter of the columns hold
    /// band filling their lowest row's top and reaching as low as the tyres: far away the band
    /// is thinner than a row or falls between rows, and then the tyres' lower edge is the
    /// better measure. A side's rise (`receding_side`) keeps them: its quarters are the band's
    /// ends, where the tyres stand.
    pub(super) fn fractional_edges<'a>(
        &'a self,
        w: usize,
        columns: &'a [(usize, usize)],
        skip_tyres: bool,
    ) -> Option<impl Iterator<Item = f64> + 'a> {
        let road = self.road_below(w, columns)?;
        let band = road * self.band_ratio;
        if road - band < 8.0 {
            return None;
        }
        let luma = move |u: usize, v: usize| self.luma[v * w + u];
        let share = move |l: u8| ((road - l as f32) / (road - band)).clamp(0.0, 1.0) as f64;
        let darkest_band = road * MIN_BAND_RATIO;
        let not_tyre = move |l: u8| l as f32 >= darkest_band;
        let on_band = move |&&(u, lo): &&(usize, usize)| not_tyre(luma(u, lo));
        // Band filling its lowest row's top (the row above holds band too, not a tyre, a
        // quarter of it at least, well above pixel noise): the share there is the edge's
        // place, not the band's thickness.
        let thick = |u: usize, lo: usize| lo > 0 && not_tyre(luma(u, lo - 1)) && share(luma(u, lo - 1)) >= 0.25;
        let tyres_left_out = skip_tyres && {
            let (mut banded, mut band_lowest, mut tyre_lowest) = (0, 0, 0);
            for c in columns {
                if !on_band(&c) {
                    tyre_lowest = tyre_lowest.max(c.1);
                } else if thick(c.0, c.1) {
                    (banded, band_lowest) = (banded + 1, band_lowest.max(c.1));
                }
            }
            banded > 0 && banded * 4 >= columns.len() && band_lowest >= tyre_lowest
        };
        let edge = move |u: usize, lo: usize| {
            let (inner, below) = (share(luma(u, lo)), share(luma(u, lo + 1)));
            // With band in the row below, the edge is in that row, whatever the band's top does
            // in row `lo` (at 50 m the band is hardly more than a row thick); with none there,
            // in row `lo`. Blended across a quarter of a row so that noise makes no step.
            let weight = (below / 0.25).min(1.0);
            weight * (lo as f64 + 1.0 + below) + (1.0 - weight) * (lo as f64 + inner + below)
        };
        Some(columns.iter().filter(move |c| !tyres_left_out || on_band(c)).map(move |&(u, lo)| edge(u, lo)))
    }

    /// Which end of a band its contact edge rises toward, measured to a fraction of a row over
    /// its outer quarters: a vehicle's side receding beside its rear (the rear's lower edge is
    /// level across the road; the side's runs away from the camera). None when neither end
    /// rises by SIDE_RISE_PX more than the other.
    pub(super) fn receding_side(&self, w: usize, h: usize, c: &Component) -> Option<Side> {
        let columns = self.lowest_dark_rows(w, h, c.u0..=c.u1, c.v1, JUMP_PX as u32 + 1);
        if columns.len() < 8 {
            return None;
        }
        let edges: Vec<f64> = self.fractional_edges(w, &columns, false)?.collect();
        let quarter = edges.len() / 4;
        let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
        // Rows grow downward: the receding end's edge is the smaller.
        let (left, right) = (mean(&edges[..quarter]), mean(&edges[edges.len() - quarter..]));
        if left >= right + SIDE_RISE_PX {
            Some(Side::Right)
        } else if right >= left + SIDE_RISE_PX {
            Some(Side::Left)
        } else {
            None
        }
    }

    /// The highest row above `bottom` (at most `max_rows` up) where the columns `u0..=u1`
    /// still differ from the background in the `flanks` columns beside them; None when nothing
    /// rises above the contact.
    pub(super) fn top_row(
        &self,
        rgb: &[u8],
        w: usize,
        (u0, u1): (usize, usize),
        (bottom, max_rows): (usize, usize),
        flanks: [Option<usize>; 2],
    ) -> Option<usize> {
        let px = |u: usize, v: usize| {
            let i = (v * w + u) * 3;
            [rgb[i] as i32, rgb[i + 1] as i32, rgb[i + 2] as i32]
        };
        let diff = |a: [i32; 3], b: [i32; 3]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs();
        let mut top = None;
        let mut misses = 0;
        // A vehicle can show background between its parts (the road seen under it, a body
        // the colour of the road): gaps up to a sixth of the tallest vehicle are bridged.
        let max_gap = (max_rows / 6).max(3);
        let lowest = bottom.saturating_sub(max_rows);
        for v in (lowest..=bottom).rev() {
            let backgrounds: Vec<[i32; 3]> = flanks.into_iter().flatten().map(|u| px(u, v)).collect();
            if backgrounds.is_empty() {
                return None;
            }
            let step = ((u1 - u0) / 24).max(1);
            let (mut differ, mut total) = (0, 0);
            for u in (u0..=u1).step_by(step) {
                let c = px(u, v);
                total += 1;
                if backgrounds.iter().all(|b| diff(c, *b) > self.params.contrast) {
                    differ += 1;
                }
            }
            if differ * 10 >= total * 3 {
                top = Some(v);
                misses = 0;
            } else {
                misses += 1;
                if misses >= max_gap && top.is_some() {
                    break;
                }
            }
        }
        top
    }
}

/// Whether a candidate with box `c` is part of the nearer vehicle with box `nearer`: its
/// contact line lies within that box and most of its columns under it (a dark window, a
/// black car's body, a rider's dark clothes).
pub(crate) fn part_of(c: &BoundingBox2d, nearer: &BoundingBox2d) -> bool {
    let overlap = c.u_max_px.min(nearer.u_max_px) - c.u_min_px.max(nearer.u_min_px);
    let width = c.u_max_px - c.u_min_px;
    overlap > 0.5 * width && c.v_max_px <= nearer.v_max_px && c.v_max_px >= nearer.v_min_px
}

pub(super) fn median(mut xs: Vec<u8>) -> Option<f32> {
    xs.sort_unstable();
    xs.get(xs.len() / 2).map(|&x| x as f32)
}

/// The class a band's size says: by height, and a band narrower than any car's, seen whole
/// (not cut by the image's side), under something as tall as a rider is a motorcycle.
pub(super) fn class_of(width_m: f64, height_m: f64, whole: bool) -> ObjectClass {
    if height_m > 2.9 {
        ObjectClass::Truck
    } else if height_m > 1.9 {
        ObjectClass::Van
    } else if whole && width_m < MOTORCYCLE_MAX_WIDTH_M {
        ObjectClass::Motorcycle
    } else {
        ObjectClass::Car
    }
}

/// How plausible the size is for the class: 1 inside its width and height ranges, falling
/// with the ratio outside them, at least 0.05.
pub(super) fn confidence_of(class: ObjectClass, width_m: f64, height_m: f64) -> f32 {
    let plausible = |x: f64, lo: f64, hi: f64| {
        if x < lo {
            x / lo
        } else if x > hi {
            hi / x
        } else {
            1.0
        }
    };
    let widths = if class == ObjectClass::Motorcycle { (0.6, 1.2) } else { (1.4, 2.8) };
    (plausible(width_m, widths.0, widths.1) * plausible(height_m, 1.1, 3.8)).clamp(0.05, 1.0) as f32
}
