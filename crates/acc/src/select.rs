//! Lead selection: which vehicle ahead the ACC follows. Each perception frame places every
//! track across the ego's lane (on the road's map, or on the path the yaw rate predicts),
//! picks the nearest in the lane as the lead and feeds the lead estimate; it also keeps the
//! vehicle the lead hides or reveals (beyond it in the lane, or in the lane while the lead
//! moves out), which counts for the threat at once.

use std::collections::HashMap;

use super::ego::EgoNow;
use super::in_lane;
use super::lane::LaneAhead;
use super::lead_filter::{LeadFilter, Noise};
use super::objects::{Object, PerceptionFrame};
use super::settings::{AccSettings, PerceptionSource};
use super::threat::{threat, Threat};
use super::tuning::{SelectTuning, ThreatTuning};
use slipstream_model::road::Road;

/// The lane width the settings' in-lane limits are for.
const SETTINGS_LANE_WIDTH_M: f64 = 3.5;
/// Tracks not seen for this long are forgotten.
const TRACK_MEMORY_S: f64 = 2.0;
/// A track's lateral speed counts once it has been seen in this many frames.
const RATE_AFTER_FRAMES: u32 = 4;
/// Without a map, the path ahead bends by the ego's yaw rate over its speed, that speed taken
/// as at least this (m/s): near standstill the quotient is noise (a steering wheel turned at
/// rest would bend the path into a circle).
const PATH_MIN_SPEED_MPS: f64 = 2.0;
/// A predicted path curving less than this (1/m: a 100 km radius) is a straight for the
/// offset's uncertainty.
const STRAIGHT_BELOW_PER_M: f64 = 1e-5;

/// What lead selection remembers of one track (for its lateral speed).
#[derive(Debug, Clone, Copy)]
struct Track {
    stamp_s: f64,
    /// Its offset from the ego's lane centre (or predicted path, without a map).
    lateral_m: f64,
    lateral_rate_mps: f64,
    /// Fading mean square of the raw rates about the filtered one (m2/s2).
    rate_scatter: f64,
    seen: u32,
}

impl Track {
    /// The filtered lateral rate's standard deviation: a low-pass of gain k over readings
    /// scattered by `rate_scatter` keeps k / (2 - k) of their variance.
    fn rate_sigma_mps(&self, k: f64) -> f64 {
        (self.rate_scatter * k / (2.0 - k).max(1.0)).sqrt()
    }
}

/// A vehicle in the lane beyond the lead, or one a leaving lead reveals, as last measured.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Revealed {
    id: u32,
    /// Since when it has been the vehicle revealed, frame after frame.
    since_s: f64,
    stamp_s: f64,
    gap_m: f64,
    relative_speed_mps: f64,
}

/// The lead, its estimate, and what the tracks around it say.
pub(super) struct LeadSelect {
    /// The road's map (sim/road), when one was received, and the ego's last place along it.
    pub(super) road: Option<Road>,
    road_s_m: Option<f64>,
    tracks: HashMap<u32, Track>,
    pub(super) lead: Option<LeadFilter>,
    pub(super) noise: Noise,
    /// The nearest vehicle that is in the ego's lane by the entry test while the lead stays
    /// the lead only by the stay-in-lane hysteresis (a lead moving out), else the nearest in
    /// the lane beyond the lead: it counts for the threat at once, not once the lead has left.
    next_in_lane: Option<Revealed>,
}

/// A vehicle found in the lane, with its gap.
type InLane<'a> = (&'a Object, f64);

impl LeadSelect {
    pub(super) fn new(noise: Noise) -> Self {
        LeadSelect { road: None, road_s_m: None, tracks: HashMap::new(), lead: None, noise, next_in_lane: None }
    }

    /// Takes the road's map: from now on the lane ahead comes from it.
    pub(super) fn set_road(&mut self, road: Road) {
        self.road = Some(road);
        self.road_s_m = None;
    }

    /// The threat of the vehicle the lead hides or reveals, moved on to `t_s` at its measured
    /// relative speed (it is not filtered: it counts as a vehicle holding its speed).
    pub(super) fn revealed(&self, k: &ThreatTuning, t_s: f64, v: f64) -> Option<Threat> {
        self.revealed_for(k, t_s, v, 0.0)
    }

    /// As [`Self::revealed`], only once it has been the vehicle revealed for `confirm_s`
    /// (seen in more than one frame): what may start an emergency.
    pub(super) fn revealed_for(&self, k: &ThreatTuning, t_s: f64, v: f64, confirm_s: f64) -> Option<Threat> {
        let confirmed = |r: &Revealed| r.stamp_s - r.since_s >= confirm_s - 1e-9;
        self.next_in_lane.filter(|r| self.lead.is_some() && confirmed(r)).map(|r| {
            let rel = r.relative_speed_mps;
            let gap = r.gap_m + rel * (t_s - r.stamp_s).max(0.0);
            threat(k, gap, v, (v + rel).max(0.0), 0.0)
        })
    }

    /// Takes a perception frame: updates the tracks, picks the lead and updates its estimate.
    ///
    /// A vehicle is in the ego's lane by its offset from the lane's centre: on the map's lane
    /// where there is a map (bends ahead included), else from the path the yaw rate predicts.
    pub(super) fn perceive(&mut self, s: &AccSettings, frame: &PerceptionFrame, ego: &EgoNow) {
        let (best, in_lane) = self.in_lane(s, frame, ego);
        let nearest = |beyond_m: f64| {
            in_lane.iter().filter(|(_, gap)| *gap > beyond_m).min_by(|x, y| x.1.total_cmp(&y.1)).copied()
        };
        let entering = nearest(f64::NEG_INFINITY);
        // Beyond the lead, the nearest vehicle in the lane past it: the lead cannot drive
        // through it, so it counts for the threat too. A truck standing beyond a van that
        // moves out only at the last moment is braked for from when it is seen over the van,
        // not once the van has gone. A vehicle beyond at the lead's speed or faster asks for
        // nothing.
        let beyond = best.and_then(|(_, lead_gap)| nearest(lead_gap + s.tuning.select.beyond_lead_m.get()));
        self.next_in_lane = match (best, entering) {
            (Some((b, _)), Some(e)) if e.0.id != b.id => Some(e),
            _ => beyond,
        }
        .map(|(o, gap_m)| {
            let since_s = match self.next_in_lane {
                Some(r) if r.id == o.id => r.since_s,
                _ => frame.stamp_s,
            };
            Revealed { id: o.id, since_s, stamp_s: frame.stamp_s, gap_m, relative_speed_mps: o.relative_speed_mps }
        });
        self.tracks.retain(|_, t| frame.stamp_s - t.stamp_s < TRACK_MEMORY_S);
        if self.coasting(s, frame, best) {
            return;
        }
        let current = self.lead.map(|l| l.id);
        let Some((o, gap)) = best else {
            if current.is_some() {
                tracing::debug!(from = ?current, "lead lost");
            }
            self.lead = None;
            return;
        };
        self.follow(o, gap, ego, frame.stamp_s);
    }

    /// The nearest vehicle in the lane (the current lead kept by the stay-in-lane limit), and
    /// every one in it by the entry limit, with their gaps; the tracks updated.
    fn in_lane<'f>(
        &mut self,
        s: &AccSettings,
        frame: &'f PerceptionFrame,
        ego: &EgoNow,
    ) -> (Option<InLane<'f>>, Vec<InLane<'f>>) {
        let front = s.vehicle.front_overhang_from_origin_m;
        let kappa = ego.yaw_rate_radps / ego.speed_mps.max(PATH_MIN_SPEED_MPS);
        let lane_ahead = LaneAhead::find(self.road.as_ref(), &mut self.road_s_m, ego);
        let lane = &s.lane;
        // The limits are for a 3.5 m lane: on the map's lanes they move with its width (a car
        // riding 1.8 m off the centre of a 5 m lane is in it).
        let wider_m = lane_ahead.as_ref().map_or(0.0, |l| (l.road.lane_width_m() - SETTINGS_LANE_WIDTH_M) / 2.0);
        let (in_lane_m, stay_in_lane_m) = (lane.in_lane_m + wider_m, lane.stay_in_lane_m + wider_m);
        let current = self.lead.map(|l| l.id);
        let mut best: Option<InLane> = None;
        let mut in_lane: Vec<InLane> = Vec::new();
        for o in &frame.objects {
            let off = match &lane_ahead {
                Some(l) => l.offset_m(o.distance_m, o.lateral_m),
                None => o.lateral_m - kappa * o.distance_m * o.distance_m / 2.0,
            };
            let track = track(&mut self.tracks, &s.tuning.select, o.id, off, frame.stamp_s);
            let gap = o.distance_m - front;
            if o.distance_m <= 0.0 || gap > lane.range_m {
                continue;
            }
            let limit = if current == Some(o.id) { stay_in_lane_m } else { in_lane_m };
            let sigma = match (s.perception, &lane_ahead) {
                (PerceptionSource::GroundTruth, _) => 0.0,
                (_, Some(l)) => {
                    lane.offset_sigma.at(o.distance_m, l.road.tightest_radius_between(l.s_m, l.s_m + o.distance_m))
                }
                (_, None) => {
                    lane.offset_sigma.at(o.distance_m, (kappa.abs() > STRAIGHT_BELOW_PER_M).then(|| 1.0 / kappa))
                }
            };
            // Where it is, and where its lateral speed takes it within lateral_lookahead_s,
            // with that prediction's own uncertainty (the rate's scatter: small for a car
            // cutting in near, large for one far round a bend whose offset reads noisily).
            let rate_sigma =
                if sigma > 0.0 { track.rate_sigma_mps(s.tuning.select.lateral_rate_filter.get()) } else { 0.0 };
            let predicted = (track.seen >= RATE_AFTER_FRAMES).then(|| {
                let ahead_s = lane.lateral_lookahead_s;
                (off + track.lateral_rate_mps * ahead_s, sigma.hypot(rate_sigma * ahead_s))
            });
            let within = |half_m: f64| {
                let p = lane.in_lane_probability;
                in_lane::probability(off, half_m, sigma) >= p
                    || predicted.is_some_and(|(at, sd)| in_lane::probability(at, half_m, sd) >= p)
            };
            tracing::trace!(t_s = frame.stamp_s, id = o.id, x_m = o.distance_m, offset_m = off, sigma_m = sigma, predicted = ?predicted, "placed");
            if !within(limit) {
                continue;
            }
            if best.is_none_or(|b| gap < b.1) {
                best = Some((o, gap));
            }
            if within(in_lane_m) {
                in_lane.push((o, gap));
            }
        }
        (best, in_lane)
    }

    /// Whether the lead, missing from this frame, is kept, moving on as estimated: for
    /// `lead_coast_s` unless a nearer vehicle is in the lane (far away a detector misses one
    /// now and then, and taken anew its speed would be measured again, which takes tenths of a
    /// second), for `standing_coast_s` when it is settled and standing (it cannot have driven
    /// off, only be hidden: just past a bend's exit, behind cars standing either side).
    fn coasting(&self, s: &AccSettings, frame: &PerceptionFrame, best: Option<InLane>) -> bool {
        let t = &s.tuning.select;
        self.lead.is_some_and(|f| {
            let standing = f.settled() && f.x[1] < t.standing_lead_mps.get();
            let coast_s = if standing { t.standing_coast_s.get() } else { t.lead_coast_s.get() };
            !frame.objects.iter().any(|o| o.id == f.id)
                && frame.stamp_s - f.seen_s < coast_s
                && best.is_none_or(|b| b.1 > f.x[0])
        })
    }

    /// Follows `o` at `gap` as the lead: updates its estimate, or starts a new one when the
    /// lead changed.
    fn follow(&mut self, o: &Object, gap: f64, ego: &EgoNow, stamp_s: f64) {
        let n = self.noise;
        let t = ego.t_s.max(stamp_s);
        let speed = ego.speed_mps + o.relative_speed_mps;
        // The speed's noise is the model's for this range; while a lead is new, perception's
        // own estimate when larger: a new track's speed is a guess until a few frames have
        // measured it (tens of m/s at first, far away).
        let speed_sigma =
            |settled: bool| n.speed_sigma(gap).max(if settled { 0.0 } else { o.relative_speed_sigma_mps });
        match &mut self.lead {
            Some(f) if f.id == o.id => {
                f.predict(t, ego.speed_mps, n.jerk_sigma_mps3);
                f.brake_lights(o.brake_lights);
                f.seen_s = stamp_s;
                f.update(0, gap, n.gap_sigma(gap));
                f.update_speed(speed, speed_sigma(f.settled()), n.speed_steady(gap));
            }
            current => {
                tracing::debug!(from = ?current.map(|l| l.id), to = o.id, "lead changed");
                self.lead = Some(LeadFilter::new(o.id, t, gap, speed.max(0.0), speed_sigma(false), &n));
            }
        }
    }
}

/// The track of object `id` seen at lateral offset `off` at `stamp_s`, updated and kept:
/// the rate of that same offset (in a bend a car standing in the next lane sweeps across
/// the ego's own frame as the ego turns, not across its lane), and how much that rate's
/// frame-to-frame readings scatter about it.
fn track(tracks: &mut HashMap<u32, Track>, t: &SelectTuning, id: u32, off: f64, stamp_s: f64) -> Track {
    let track = match tracks.get(&id) {
        Some(p) if stamp_s > p.stamp_s => {
            let max = t.max_lateral_rate_mps.get();
            let lat_rate = ((off - p.lateral_m) / (stamp_s - p.stamp_s)).clamp(-max, max);
            let k = t.lateral_rate_filter.get();
            Track {
                stamp_s,
                lateral_m: off,
                lateral_rate_mps: p.lateral_rate_mps + k * (lat_rate - p.lateral_rate_mps),
                rate_scatter: p.rate_scatter + k * ((lat_rate - p.lateral_rate_mps).powi(2) - p.rate_scatter),
                seen: p.seen.saturating_add(1),
            }
        }
        Some(p) => *p,
        None => Track { stamp_s, lateral_m: off, lateral_rate_mps: 0.0, rate_scatter: 0.0, seen: 1 },
    };
    tracks.insert(id, track);
    track
}
