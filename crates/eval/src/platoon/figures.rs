//! A platoon's string stability from its cars' speeds: how far each car's speed strays from
//! where it was when the disturbance began, how hard it brakes, and each figure's ratio to the
//! car ahead of it. A string is stable when no disturbance grows on its way back: every
//! ratio at most 1 (the L-infinity speed-error criterion, as platoon tests of commercial ACCs
//! measure it).

use serde::Serialize;

/// One car's speeds over the run: (simulated seconds, speed m/s, acceleration m/s2).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CarSeries {
    pub name: String,
    pub samples: Vec<(f64, f64, f64)>,
}

/// One car's figures and their ratios to the car ahead (the leader for the first follower).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CarFigures {
    pub car: String,
    /// The largest |speed - speed when the disturbance began| from then on.
    pub peak_speed_error_mps: f64,
    /// The hardest braking from then on (positive), 0 when it never braked.
    pub peak_decel_mps2: f64,
    /// Peak speed error over the car ahead's; None for the leader.
    pub speed_ratio: Option<f64>,
    /// Peak deceleration over the car ahead's; None for the leader or when that one never
    /// braked.
    pub decel_ratio: Option<f64>,
}

/// The whole string at one time gap.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StringFigures {
    pub time_gap_s: f64,
    /// The leader first, then the followers in order.
    pub cars: Vec<CarFigures>,
    /// The largest speed ratio along the string.
    pub max_speed_ratio: f64,
    /// Every speed ratio at most 1: the disturbance did not grow from any car to the next.
    pub stable: bool,
}

/// Figures of `leader` and `followers` (in their order along the string) from `from_s`, the
/// simulated time the leader's disturbance begins; speeds before it set each car's reference.
pub(crate) fn string_figures(
    time_gap_s: f64,
    leader: &CarSeries,
    followers: &[CarSeries],
    from_s: f64,
) -> StringFigures {
    let mut cars: Vec<CarFigures> = Vec::with_capacity(followers.len() + 1);
    for series in std::iter::once(leader).chain(followers) {
        let (error, decel) = peaks(series, from_s);
        let ahead = cars.last();
        let ratio = |mine: f64, theirs: f64| (theirs > 1e-6).then(|| mine / theirs);
        cars.push(CarFigures {
            car: series.name.clone(),
            peak_speed_error_mps: error,
            peak_decel_mps2: decel,
            speed_ratio: ahead.and_then(|a| ratio(error, a.peak_speed_error_mps)),
            decel_ratio: ahead.and_then(|a| ratio(decel, a.peak_decel_mps2)),
        });
    }
    let max_speed_ratio = cars.iter().filter_map(|c| c.speed_ratio).fold(0.0, f64::max);
    StringFigures { time_gap_s, cars, max_speed_ratio, stable: max_speed_ratio <= 1.0 }
}

/// (peak speed error, peak deceleration) of one car from `from_s` on, the speed error against
/// its last speed before `from_s` (its first speed when it has none before).
fn peaks(series: &CarSeries, from_s: f64) -> (f64, f64) {
    let reference = series.samples.iter().rev().find(|s| s.0 < from_s).or(series.samples.first());
    let Some(&(_, v0, _)) = reference else { return (0.0, 0.0) };
    let after = series.samples.iter().filter(|s| s.0 >= from_s);
    after.fold((0.0_f64, 0.0_f64), |(e, d), &(_, v, a)| (e.max((v - v0).abs()), d.max(-a)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A car at 25 m/s that dips by `depth` m/s at `decel` m/s2 from t = 10 s.
    fn dipping(name: &str, depth: f64, decel: f64) -> CarSeries {
        let samples = (0..400)
            .map(|k| {
                let t = k as f64 * 0.1;
                let braking = t >= 10.0 && t < 10.0 + depth / decel;
                let v = if t < 10.0 { 25.0 } else { 25.0 - (decel * (t - 10.0)).min(depth) };
                (t, v, if braking { -decel } else { 0.0 })
            })
            .collect();
        CarSeries { name: name.into(), samples }
    }

    #[test]
    fn a_dip_that_fades_along_the_string_is_stable_and_one_that_grows_is_not() {
        let leader = dipping("leader", 5.0, 2.0);
        let fading = [dipping("car1", 4.0, 1.5), dipping("car2", 3.0, 1.0)];
        let s = string_figures(1.8, &leader, &fading, 10.0);
        assert!(s.stable, "{s:?}");
        assert_eq!(s.cars.len(), 3);
        assert_eq!(s.cars[0].speed_ratio, None);
        assert!((s.cars[1].speed_ratio.unwrap() - 0.8).abs() < 1e-9, "{s:?}");
        assert!((s.cars[2].decel_ratio.unwrap() - 1.0 / 1.5).abs() < 1e-9, "{s:?}");
        assert!((s.max_speed_ratio - 0.8).abs() < 1e-9);

        let growing = [dipping("car1", 4.0, 1.5), dipping("car2", 4.6, 2.0)];
        let s = string_figures(0.8, &leader, &growing, 10.0);
        assert!(!s.stable && (s.max_speed_ratio - 1.15).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn a_car_that_never_brakes_has_no_deceleration_ratio_behind_it() {
        let steady = CarSeries { name: "leader".into(), samples: (0..50).map(|k| (k as f64, 25.0, 0.0)).collect() };
        let s = string_figures(1.8, &steady, &[dipping("car1", 1.0, 1.0)], 10.0);
        assert_eq!((s.cars[0].peak_speed_error_mps, s.cars[0].peak_decel_mps2), (0.0, 0.0));
        assert_eq!((s.cars[1].speed_ratio, s.cars[1].decel_ratio), (None, None));
        assert!(s.stable);
    }
}
