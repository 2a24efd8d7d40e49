//! Each track's place in the ego's lane as a probability, not a hard threshold: far ahead,
//! and most round a bend, the camera places a vehicle across the road less well (a lane's
//! neighbour 200 m into a bend has read 2 m off its lane), so the ACC counts a vehicle as in
//! its lane only when the measured offset says so with `lane.in_lane_probability`, given the
//! offset's uncertainty at that range and bend as `eval detect` measures it
//! (`lane.offset_sigma`, docs/perception.md). With an exact offset (ground truth, sigma 0)
//! this is the plain threshold: in the lane below `lane.in_lane_m`.

use serde::Deserialize;
use slipstream_contract::config::Invalid;

/// The uncertainty (standard deviation, m) of a vehicle's measured place across the road, by
/// range band (`range_m`: each band's far end, ascending) and by the tightest bend between the
/// ego and the vehicle: `straight`, `gentle` (R >= 1,000 m), `bend` (R 500-1,000 m), `tight`
/// (R < 500 m), one figure per range band.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OffsetSigma {
    pub range_m: Vec<f64>,
    pub straight: Vec<f64>,
    pub gentle: Vec<f64>,
    pub bend: Vec<f64>,
    pub tight: Vec<f64>,
}

/// The table's bend classes by the tightest radius (m): `gentle` from GENTLE_MIN_RADIUS_M up,
/// `bend` from BEND_MIN_RADIUS_M up, `tight` below. `eval detect` measures the lateral error by
/// the same classes, so the table can be filled from its output.
pub const GENTLE_MIN_RADIUS_M: f64 = 1000.0;
pub const BEND_MIN_RADIUS_M: f64 = 500.0;

impl OffsetSigma {
    /// The sigma at `range_m` seen through a bend of `radius_m` (None: a straight): the figure
    /// of the first band reaching that far (the last band's beyond it).
    pub fn at(&self, range_m: f64, radius_m: Option<f64>) -> f64 {
        let column = match radius_m.map(f64::abs) {
            None => &self.straight,
            Some(r) if r >= GENTLE_MIN_RADIUS_M => &self.gentle,
            Some(r) if r >= BEND_MIN_RADIUS_M => &self.bend,
            Some(_) => &self.tight,
        };
        let band = self.range_m.iter().position(|&far| range_m <= far).unwrap_or(self.range_m.len() - 1);
        column[band]
    }

    /// Why the table, at `key`, is not one finite, non-negative figure per ascending band.
    pub fn check(&self, key: &str) -> Result<(), Invalid> {
        let n = self.range_m.len();
        let ascending = self.range_m.windows(2).all(|w| w[0] < w[1]);
        let columns = [&self.straight, &self.gentle, &self.bend, &self.tight];
        let figures = columns.iter().all(|c| c.len() == n && c.iter().all(|s| s.is_finite() && *s >= 0.0));
        if n == 0 || !ascending || !figures {
            return Invalid::err(
                key,
                format!("{self:?}"),
                "give range_m ascending and one sigma >= 0 per range band in each of straight, gentle, bend, tight",
            );
        }
        Ok(())
    }

    /// No uncertainty anywhere (ground truth).
    pub fn exact() -> Self {
        OffsetSigma {
            range_m: vec![f64::INFINITY],
            straight: vec![0.0],
            gentle: vec![0.0],
            bend: vec![0.0],
            tight: vec![0.0],
        }
    }
}

/// The probability that a vehicle measured `offset_m` from the lane's centre, with that
/// measurement's standard deviation `sigma_m`, is within `half_m` of it.
pub fn probability(offset_m: f64, half_m: f64, sigma_m: f64) -> f64 {
    if sigma_m <= 1e-9 {
        return if offset_m.abs() < half_m { 1.0 } else { 0.0 };
    }
    normal_cdf((half_m - offset_m) / sigma_m) - normal_cdf((-half_m - offset_m) / sigma_m)
}

/// The standard normal distribution function, through erf (Abramowitz and Stegun 7.1.26:
/// within 1.5e-7).
fn normal_cdf(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-x * x).exp();
    if z >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_distribution_function_matches_its_table() {
        for (z, p) in [(0.0, 0.5), (1.0, 0.841_344_7), (-1.0, 0.158_655_3), (1.96, 0.975_002_1), (-3.0, 0.001_349_9)] {
            assert!((normal_cdf(z) - p).abs() < 1e-6, "{z}: {}", normal_cdf(z));
        }
    }

    #[test]
    fn an_exact_offset_is_the_plain_threshold_and_an_uncertain_one_asks_for_more() {
        assert_eq!(probability(1.59, 1.6, 0.0), 1.0);
        assert_eq!(probability(-1.61, 1.6, 0.0), 0.0);
        // On a straight (0.1 m) a car 1.4 m off the centre is in the lane; 200 m into a bend
        // (0.5 m) it may as well be in the next one.
        assert!(probability(1.4, 1.6, 0.1) > 0.95);
        let far = probability(-1.4, 1.6, 0.5);
        assert!(far > 0.5 && far < 0.7, "{far}");
        // A car on the centre line is in the lane either way; symmetric about the centre.
        assert!(probability(0.0, 1.6, 0.5) > 0.99);
        assert!((probability(0.7, 1.6, 0.5) - probability(-0.7, 1.6, 0.5)).abs() < 1e-12);
    }

    #[test]
    fn the_sigma_comes_from_the_band_of_range_and_bend() {
        let t = OffsetSigma {
            range_m: vec![80.0, 200.0],
            straight: vec![0.1, 0.2],
            gentle: vec![0.3, 0.4],
            bend: vec![0.5, 0.6],
            tight: vec![0.7, 0.8],
        };
        assert_eq!(t.at(50.0, None), 0.1);
        assert_eq!(t.at(150.0, Some(1500.0)), 0.4);
        assert_eq!(t.at(80.0, Some(-700.0)), 0.5);
        assert_eq!(t.at(250.0, Some(300.0)), 0.8, "beyond the last band: its figure");
        assert!(t.check("lane.offset_sigma").is_ok());
        let short = OffsetSigma { tight: vec![0.7], ..t.clone() };
        assert!(short.check("lane.offset_sigma").is_err());
        let unordered = OffsetSigma { range_m: vec![200.0, 80.0], ..t };
        assert!(unordered.check("lane.offset_sigma").is_err());
        assert_eq!(OffsetSigma::exact().at(1e6, Some(100.0)), 0.0);
    }
}
