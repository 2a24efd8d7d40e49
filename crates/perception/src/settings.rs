//! How the detector finds and tracks vehicles: config/detect.json5 documents every key and
//! holds the defaults (compiled in); a settings file of one's own needs only the keys it
//! changes. Each number is checked here, against the rule its comment states, so a file that
//! loads is one the detector can run with.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use super::detector::DetectorParams;
use super::tracker::TrackerParams;
use slipstream_contract::config::{parse_layered, read_config, ConfigError, Invalid};

pub(crate) const DEFAULT_DETECT_CONFIG: &str = include_str!("../../../config/detect.json5");
pub(crate) const DEFAULT_DETECT_CONFIG_PATH: &str = "config/detect.json5";

const FIX: &str = "see the comments in config/detect.json5 for every key and its allowed values";

/// The longest `narrow_wait_ms` taken: a frame held longer would miss every later one.
const MAX_NARROW_WAIT_MS: u64 = 1000;

/// Everything slipstream-detect's numbers say.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetectSettings {
    pub detector: DetectorParams,
    pub tracker: TrackerParams,
    pub fusion: FusionParams,
    pub narrow_wait_ms: u64,
}

/// When a detection of the front camera and one of the narrow camera are one vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FusionParams {
    pub same_distance_share: f64,
    pub same_min_m: f64,
    pub same_lateral_m: f64,
}

impl Default for DetectSettings {
    /// The shipped file, parsed once per process (every `DetectorParams::default()` and
    /// `TrackerParams::default()` comes here).
    fn default() -> Self {
        static SHIPPED: std::sync::OnceLock<DetectSettings> = std::sync::OnceLock::new();
        SHIPPED
            .get_or_init(|| DetectSettings::parse("{}", "built-in defaults").expect("config/detect.json5 is valid"))
            .clone()
    }
}

impl DetectSettings {
    /// Settings from a file, or the built-in defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<DetectSettings, ConfigError> {
        let Some(path) = path else { return Ok(DetectSettings::default()) };
        let (text, origin) = read_config(path)?;
        DetectSettings::parse(&text, &origin)
    }

    /// `file`, else config/detect.json5 in the working directory when there is one, else the
    /// built-in defaults: what slipstream-detect runs with.
    pub fn resolve(file: Option<&Path>) -> Result<DetectSettings, ConfigError> {
        let local = PathBuf::from(DEFAULT_DETECT_CONFIG_PATH);
        let path = file.map(Path::to_path_buf).or_else(|| local.exists().then_some(local));
        DetectSettings::load_or_default(path.as_deref())
    }

    /// Parses settings text laid over the defaults.
    pub fn parse(text: &str, origin: &str) -> Result<DetectSettings, ConfigError> {
        let s: DetectSettings = parse_layered(DEFAULT_DETECT_CONFIG, DEFAULT_DETECT_CONFIG_PATH, text, origin, FIX)?;
        s.check().map_err(|i| i.at(origin))?;
        Ok(s)
    }

    pub fn narrow_wait(&self) -> Duration {
        Duration::from_millis(self.narrow_wait_ms)
    }

    /// Every rule config/detect.json5 states: the first one broken.
    pub fn check(&self) -> Result<(), Invalid> {
        self.detector.check("detector")?;
        self.tracker.check("tracker")?;
        let f = &self.fusion;
        for (key, v) in [
            ("fusion.same_distance_share", f.same_distance_share),
            ("fusion.same_min_m", f.same_min_m),
            ("fusion.same_lateral_m", f.same_lateral_m),
        ] {
            positive(key, v)?;
        }
        if self.narrow_wait_ms > MAX_NARROW_WAIT_MS {
            return Invalid::err(
                "narrow_wait_ms",
                format!("{} ms", self.narrow_wait_ms),
                format!("use 0 to {MAX_NARROW_WAIT_MS} ms"),
            );
        }
        Ok(())
    }
}

/// `v` is a finite number above 0.
pub(crate) fn positive(key: &str, v: f64) -> Result<(), Invalid> {
    match v.is_finite() && v > 0.0 {
        true => Ok(()),
        false => Invalid::err(key, format!("{v}"), "give a number > 0"),
    }
}

/// `v` is a share in (0, 1), or (0, 1] with `one_allowed`.
pub(crate) fn share(key: &str, v: f64, one_allowed: bool) -> Result<(), Invalid> {
    let ok = v > 0.0 && (v < 1.0 || (one_allowed && v == 1.0));
    match ok {
        true => Ok(()),
        false if one_allowed => Invalid::err(key, format!("{v}"), "give a share in (0, 1]"),
        false => Invalid::err(key, format!("{v}"), "give a share between 0 and 1"),
    }
}

/// `lo` below `hi`, both above 0.
pub(crate) fn range(prefix: &str, (lo_key, lo): (&str, f64), (hi_key, hi): (&str, f64)) -> Result<(), Invalid> {
    positive(&format!("{prefix}.{lo_key}"), lo)?;
    positive(&format!("{prefix}.{hi_key}"), hi)?;
    match lo < hi {
        true => Ok(()),
        false => {
            Invalid::err(format!("{prefix}.{lo_key}"), format!("{lo} is not below {hi_key} {hi}"), "keep min below max")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_is_the_default_and_a_file_needs_only_its_changes() {
        let d = DetectSettings::default();
        assert_eq!(d.detector, DetectorParams::default());
        let s = DetectSettings::parse("{ detector: { contrast: 30 }, narrow_wait_ms: 20 }", "mine.json5").unwrap();
        assert_eq!((s.detector.contrast, s.narrow_wait_ms), (30, 20));
        assert_eq!((s.tracker, s.fusion), (d.tracker, d.fusion));
        assert_eq!(s.detector.dark_ratio, d.detector.dark_ratio);
    }

    #[test]
    fn bad_values_name_the_file_key_and_fix() {
        let bad = |text: &str| DetectSettings::parse(text, "mine.json5").unwrap_err();
        let e = bad("{ detector: { dark_ratio: 1.5 } }");
        assert_eq!((e.origin.as_str(), e.key.as_str()), ("mine.json5", "detector.dark_ratio"));
        assert!(e.fix.contains("between 0 and 1"), "{e}");
        assert_eq!(bad("{ detector: { min_width_m: 4 } }").key, "detector.min_width_m");
        assert_eq!(bad("{ tracker: { confirm_hits: 0 } }").key, "tracker.confirm_hits");
        assert_eq!(bad("{ tracker: { unconfirmed_confidence: 1.2 } }").key, "tracker.unconfirmed_confidence");
        assert_eq!(bad("{ fusion: { same_min_m: -1 } }").key, "fusion.same_min_m");
        assert_eq!(bad("{ narrow_wait_ms: 5000 }").key, "narrow_wait_ms");
        let unknown = bad("{ tracker: { coast_s: 1 } }");
        assert!(unknown.key.starts_with("tracker"), "{unknown}");
        assert!(unknown.problem.contains("coast_s"), "{unknown}");
    }

    /// No key escapes a check: each one of the shipped file, set to -1 alone, is refused
    /// under its own name (a key added without a rule fails here).
    #[test]
    fn every_key_of_the_shipped_file_is_checked() {
        fn leaves(prefix: &str, v: &serde_json::Value, out: &mut Vec<String>) {
            match v.as_object() {
                Some(o) => o.iter().for_each(|(k, v)| {
                    leaves(&if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") }, v, out)
                }),
                None => out.push(prefix.to_string()),
            }
        }
        let shipped = slipstream_contract::config::parse_json5_value(DEFAULT_DETECT_CONFIG, "shipped").unwrap();
        let mut keys = Vec::new();
        leaves("", &shipped, &mut keys);
        assert!(keys.len() >= 20, "{keys:?}");
        for key in keys {
            let text = key.split('.').rev().fold("-1".to_string(), |inner, k| format!("{{ {k}: {inner} }}"));
            let e = DetectSettings::parse(&text, "mine.json5").expect_err(&text);
            assert_eq!(e.key, key, "{text}: {e}");
        }
    }
}
