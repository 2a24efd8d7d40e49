//! Fault profiles (`--faults NAME|FILE`): the delays, losses and outages injected where
//! samples enter a node. The model that applies them is [`crate::bus::faults`]; the format,
//! key by key, is in docs/faults.md.
//!
//! ```json5
//! {
//!   seed: 7,                                // same seed, same fates (lockstep runs repeat)
//!   topics: {
//!     "perception/objects": {
//!       delay_ms: 80,                       // fixed delay, simulated time
//!       jitter: { dist: "exponential", ms: 20 },
//!       loss: 0.2, burst_len: 4,            // 20 % lost, in bursts of 4 on average
//!     },
//!     "vehicle/control": { loss: 0.1, at: ["sim"] },
//!     "objects": { outages: [{ from_s: 10, to_s: 12 }] },
//!   },
//! }
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::{from_value, parse_json5_value, read_config, ConfigError};
use crate::topics::Topic;

const FIX: &str = "see docs/faults.md for every key of a fault profile and its allowed values";
/// The longest wait behind a bandwidth cap before a message is dropped, unless a profile says.
const DEFAULT_QUEUE_MS: f64 = 500.0;

/// The profiles that ship, by name (config/faults/<name>.json5).
pub const BUILT_IN: &[(&str, &str)] = &[
    ("wifi-busy", include_str!("../../../../config/faults/wifi-busy.json5")),
    ("lossy-camera", include_str!("../../../../config/faults/lossy-camera.json5")),
    ("congested-lan", include_str!("../../../../config/faults/congested-lan.json5")),
    ("camera-outage", include_str!("../../../../config/faults/camera-outage.json5")),
];

/// How jitter (extra delay on top of `delay_ms`) is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JitterDist {
    /// Evenly between 0 and `ms`.
    Uniform,
    /// |N(0, ms)|: mostly small, sometimes a few times `ms`.
    Normal,
    /// Exponential with mean `ms`: a long tail, as on a busy Wi-Fi channel.
    Exponential,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Jitter {
    pub dist: JitterDist,
    pub ms: f64,
}

/// Bursty loss as a two-state Gilbert-Elliott chain, stepped once per message.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct GilbertElliott {
    /// Probability of going from the good state to the bad one, per message.
    pub good_to_bad: f64,
    /// Probability of going from the bad state back to the good one, per message.
    pub bad_to_good: f64,
    /// Loss probability in the good state.
    #[serde(default)]
    pub loss_in_good: f64,
    /// Loss probability in the bad state.
    #[serde(default = "one")]
    pub loss_in_bad: f64,
}

fn one() -> f64 {
    1.0
}

impl GilbertElliott {
    /// The chain whose long-run loss is `mean` in bursts of `burst_len` messages on average
    /// (good state loses nothing, bad state loses everything).
    pub fn with_mean(mean: f64, burst_len: f64) -> GilbertElliott {
        let bad_to_good = 1.0 / burst_len;
        let good_to_bad = if mean >= 1.0 { 1.0 } else { (mean * bad_to_good / (1.0 - mean)).min(1.0) };
        GilbertElliott { good_to_bad, bad_to_good, loss_in_good: 0.0, loss_in_bad: 1.0 }
    }

    /// The long-run fraction of messages lost.
    pub fn mean_loss(&self) -> f64 {
        let (p, r) = (self.good_to_bad, self.bad_to_good);
        if p + r == 0.0 {
            return self.loss_in_good;
        }
        let bad = p / (p + r);
        bad * self.loss_in_bad + (1.0 - bad) * self.loss_in_good
    }
}

/// A stretch of simulated time in which every message is lost.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Outage {
    pub from_s: f64,
    pub to_s: f64,
}

/// Loss, as the model applies it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum Loss {
    Independent(f64),
    Bursty(GilbertElliott),
}

/// The faults on one topic, as written in a profile.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTopicFaults {
    #[serde(default)]
    at: Vec<String>,
    #[serde(default)]
    delay_ms: f64,
    jitter: Option<Jitter>,
    #[serde(default)]
    reorder: bool,
    loss: Option<f64>,
    burst_len: Option<f64>,
    gilbert_elliott: Option<GilbertElliott>,
    #[serde(default)]
    duplicate: f64,
    bandwidth_mbps: Option<f64>,
    queue_ms: Option<f64>,
    #[serde(default)]
    outages: Vec<Outage>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    description: String,
    #[serde(default)]
    topics: BTreeMap<String, RawTopicFaults>,
}

/// The faults on one topic, checked.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopicFaults {
    /// Nodes where they apply (by node name); empty: every node that subscribes.
    pub at: Vec<String>,
    pub delay_ms: f64,
    pub jitter: Option<Jitter>,
    /// Whether a jittered message may overtake an earlier one (else order is kept).
    pub reorder: bool,
    pub loss: Option<Loss>,
    /// Probability that a message is delivered twice.
    pub duplicate: f64,
    /// A link of this many Mbit/s per simulated second: messages queue behind each other.
    pub bandwidth_mbps: Option<f64>,
    /// A message that would wait longer than this in the bandwidth queue is dropped.
    pub queue_ms: f64,
    pub outages: Vec<Outage>,
}

impl Default for TopicFaults {
    /// No fault at all, at every node (what a profile's topic entry starts from).
    fn default() -> Self {
        TopicFaults {
            at: Vec::new(),
            delay_ms: 0.0,
            jitter: None,
            reorder: false,
            loss: None,
            duplicate: 0.0,
            bandwidth_mbps: None,
            queue_ms: DEFAULT_QUEUE_MS,
            outages: Vec::new(),
        }
    }
}

impl TopicFaults {
    /// Whether they apply at the node named `node`.
    pub fn applies_at(&self, node: &str) -> bool {
        self.at.is_empty() || self.at.iter().any(|n| n == node)
    }

    /// Only messages held back (delay, jitter, a bandwidth queue), no loss.
    pub fn delays(&self) -> bool {
        self.delay_ms > 0.0 || self.jitter.is_some() || self.bandwidth_mbps.is_some()
    }
}

/// A fault profile: per topic, what happens to its samples on the way into a node.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultProfile {
    /// The built-in name or the file it came from.
    pub name: String,
    pub description: String,
    pub seed: u64,
    pub topics: BTreeMap<Topic, TopicFaults>,
}

impl FaultProfile {
    /// A built-in profile by name, or a profile file.
    pub fn find(name_or_path: &str) -> Result<FaultProfile, ConfigError> {
        if let Some((name, text)) = BUILT_IN.iter().find(|(n, _)| *n == name_or_path) {
            return FaultProfile::parse(text, &format!("config/faults/{name}.json5"), name);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(ConfigError::new(
                "--faults",
                "",
                format!("no built-in fault profile named `{name_or_path}` and no such file"),
                format!(
                    "use one of: {} (or a path to a .json5 file; docs/faults.md)",
                    BUILT_IN.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        let (text, origin) = read_config(path)?;
        FaultProfile::parse(&text, &origin, &origin)
    }

    /// Parses and checks a profile; errors name `origin` and the key.
    pub fn parse(text: &str, origin: &str, name: &str) -> Result<FaultProfile, ConfigError> {
        let raw: RawProfile = from_value(parse_json5_value(text, origin)?, origin, FIX)?;
        let mut topics = BTreeMap::new();
        for (key, t) in raw.topics {
            let topic = Topic::from_name(&key).ok_or_else(|| {
                ConfigError::new(
                    origin,
                    format!("topics.{key}"),
                    format!("`{key}` is not a topic"),
                    format!(
                        "use a logical topic name: {}",
                        Topic::ALL.iter().map(|t| t.name()).collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
            topics.insert(topic, check(t, &format!("topics.{key}"), origin)?);
        }
        Ok(FaultProfile { name: name.to_string(), description: raw.description, seed: raw.seed, topics })
    }

    /// A profile of one topic's faults (the sweep of `slipstream eval faults` builds these).
    pub fn single(name: &str, seed: u64, topic: Topic, faults: TopicFaults) -> FaultProfile {
        FaultProfile {
            name: name.to_string(),
            description: String::new(),
            seed,
            topics: BTreeMap::from([(topic, faults)]),
        }
    }

    /// The faults on `topic` at node `node`, if any.
    pub fn at(&self, topic: Topic, node: &str) -> Option<&TopicFaults> {
        self.topics.get(&topic).filter(|f| f.applies_at(node))
    }

    /// The profile as JSON5 text [`FaultProfile::parse`] reads back (to hand to a node).
    pub fn to_json5(&self) -> String {
        let mut topics = serde_json::Map::new();
        for (topic, f) in &self.topics {
            let mut o = serde_json::Map::new();
            if !f.at.is_empty() {
                o.insert("at".into(), serde_json::json!(f.at));
            }
            o.insert("delay_ms".into(), serde_json::json!(f.delay_ms));
            if let Some(j) = f.jitter {
                o.insert("jitter".into(), serde_json::json!(j));
            }
            o.insert("reorder".into(), serde_json::json!(f.reorder));
            match f.loss {
                Some(Loss::Independent(p)) => {
                    o.insert("loss".into(), serde_json::json!(p));
                }
                Some(Loss::Bursty(ge)) => {
                    o.insert("gilbert_elliott".into(), serde_json::json!(ge));
                }
                None => {}
            }
            o.insert("duplicate".into(), serde_json::json!(f.duplicate));
            if let Some(b) = f.bandwidth_mbps {
                o.insert("bandwidth_mbps".into(), serde_json::json!(b));
            }
            o.insert("queue_ms".into(), serde_json::json!(f.queue_ms));
            o.insert("outages".into(), serde_json::json!(f.outages));
            topics.insert(topic.name().to_string(), serde_json::Value::Object(o));
        }
        serde_json::json!({ "seed": self.seed, "description": self.description, "topics": topics }).to_string()
    }

    /// One line per topic, for logs and reports.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        for (topic, f) in &self.topics {
            let mut s = Vec::new();
            if f.delay_ms > 0.0 {
                s.push(format!("delay {} ms", f.delay_ms));
            }
            if let Some(j) = f.jitter {
                s.push(format!("jitter {:?} {} ms", j.dist, j.ms).to_lowercase());
            }
            match f.loss {
                Some(Loss::Independent(p)) => s.push(format!("loss {:.0} %", p * 100.0)),
                Some(Loss::Bursty(ge)) => s.push(format!(
                    "bursty loss {:.0} % (bursts of {:.1})",
                    ge.mean_loss() * 100.0,
                    1.0 / ge.bad_to_good.max(1e-9)
                )),
                None => {}
            }
            if f.duplicate > 0.0 {
                s.push(format!("duplicate {} %", f.duplicate * 100.0));
            }
            if let Some(b) = f.bandwidth_mbps {
                s.push(format!("{b} Mbit/s"));
            }
            for o in &f.outages {
                s.push(format!("outage {}-{} s", o.from_s, o.to_s));
            }
            let at = if f.at.is_empty() { String::new() } else { format!(" at {}", f.at.join(",")) };
            parts.push(format!("{topic}{at}: {}", if s.is_empty() { "nothing".into() } else { s.join(", ") }));
        }
        format!("{} (seed {}): {}", self.name, self.seed, parts.join("; "))
    }
}

fn check(t: RawTopicFaults, key: &str, origin: &str) -> Result<TopicFaults, ConfigError> {
    let bad = |field: &str, problem: String| ConfigError::new(origin, format!("{key}.{field}"), problem, FIX);
    let probability = |field: &str, p: f64| {
        if (0.0..=1.0).contains(&p) {
            Ok(p)
        } else {
            Err(bad(field, format!("{p} is not a probability (0 to 1)")))
        }
    };
    let non_negative = |field: &str, v: f64| {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(bad(field, format!("{v} must be a number >= 0")))
        }
    };
    non_negative("delay_ms", t.delay_ms)?;
    if let Some(j) = t.jitter {
        non_negative("jitter.ms", j.ms)?;
    }
    probability("duplicate", t.duplicate)?;
    let loss = match (t.loss, t.burst_len, t.gilbert_elliott) {
        (Some(_), _, Some(_)) => {
            return Err(bad("gilbert_elliott", "give either `loss` (with `burst_len`) or `gilbert_elliott`".into()))
        }
        (None, Some(_), _) => return Err(bad("burst_len", "`burst_len` needs `loss` (the mean loss)".into())),
        (Some(p), None, None) => Some(Loss::Independent(probability("loss", p)?)),
        (Some(p), Some(len), None) => {
            probability("loss", p)?;
            if !(len.is_finite() && len >= 1.0) {
                return Err(bad("burst_len", format!("{len} must be a number of messages >= 1")));
            }
            Some(Loss::Bursty(GilbertElliott::with_mean(p, len)))
        }
        (None, None, Some(ge)) => {
            probability("gilbert_elliott.good_to_bad", ge.good_to_bad)?;
            probability("gilbert_elliott.bad_to_good", ge.bad_to_good)?;
            probability("gilbert_elliott.loss_in_good", ge.loss_in_good)?;
            probability("gilbert_elliott.loss_in_bad", ge.loss_in_bad)?;
            Some(Loss::Bursty(ge))
        }
        (None, None, None) => None,
    };
    if let Some(b) = t.bandwidth_mbps {
        if !(b.is_finite() && b > 0.0) {
            return Err(bad("bandwidth_mbps", format!("{b} must be a rate > 0 (Mbit/s)")));
        }
    }
    let queue_ms = non_negative("queue_ms", t.queue_ms.unwrap_or(DEFAULT_QUEUE_MS))?;
    for (i, o) in t.outages.iter().enumerate() {
        if !(o.from_s.is_finite() && o.to_s.is_finite() && 0.0 <= o.from_s && o.from_s < o.to_s) {
            return Err(bad(
                &format!("outages[{i}]"),
                format!("from_s {} to_s {}: needs 0 <= from_s < to_s (seconds of simulated time)", o.from_s, o.to_s),
            ));
        }
    }
    Ok(TopicFaults {
        at: t.at,
        delay_ms: t.delay_ms,
        jitter: t.jitter,
        reorder: t.reorder,
        loss,
        duplicate: t.duplicate,
        bandwidth_mbps: t.bandwidth_mbps,
        queue_ms,
        outages: t.outages,
    })
}

/// `--faults NAME|FILE`: the flag of the nodes and of the tools that start them.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct FaultArgs {
    /// Inject delays, losses and outages into what this node receives: a built-in profile
    /// (wifi-busy, lossy-camera, congested-lan, camera-outage) or a .json5 file (docs/faults.md).
    /// Off by default
    #[arg(long, value_name = "PROFILE", env = "SLIPSTREAM_FAULTS")]
    pub faults: Option<String>,
}

impl FaultArgs {
    pub fn profile(&self) -> Result<Option<FaultProfile>, ConfigError> {
        self.faults.as_deref().map(FaultProfile::find).transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_profile_parses() {
        for (name, _) in BUILT_IN {
            let p = FaultProfile::find(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(!p.topics.is_empty(), "{name} injects something");
            assert!(!p.description.is_empty(), "{name} says what it models");
        }
    }

    #[test]
    fn a_profile_reads_back_from_its_json5() {
        let p = FaultProfile::parse(
            r#"{ seed: 3, topics: { "perception/objects": { delay_ms: 50, jitter: { dist: "normal", ms: 5 },
                loss: 0.2, burst_len: 4, duplicate: 0.01, bandwidth_mbps: 2, outages: [{ from_s: 1, to_s: 2 }] },
                "vehicle/control": { loss: 0.1, at: ["sim"] } } }"#,
            "test",
            "test",
        )
        .unwrap();
        let back = FaultProfile::parse(&p.to_json5(), "back", "test").unwrap();
        assert_eq!(back, p);
        let Some(Loss::Bursty(ge)) = p.topics[&Topic::PerceptionObjects].loss else { panic!("bursty") };
        assert!((ge.mean_loss() - 0.2).abs() < 1e-12);
        assert!((ge.bad_to_good - 0.25).abs() < 1e-12);
        assert!(p.at(Topic::VehicleControl, "sim").is_some());
        assert!(p.at(Topic::VehicleControl, "acc").is_none());
    }

    #[test]
    fn bad_profiles_name_the_key() {
        let err = |text: &str| FaultProfile::parse(text, "f.json5", "f").unwrap_err();
        let e = err(r#"{ topics: { "vehicle/sped": { loss: 0.1 } } }"#);
        assert_eq!(e.key, "topics.vehicle/sped");
        assert!(e.fix.contains("vehicle/speed"), "{e}");
        assert_eq!(err(r#"{ topics: { "objects": { loss: 1.5 } } }"#).key, "topics.objects.loss");
        assert_eq!(err(r#"{ topics: { "objects": { burst_len: 3 } } }"#).key, "topics.objects.burst_len");
        assert_eq!(
            err(r#"{ topics: { "objects": { outages: [{ from_s: 5, to_s: 2 }] } } }"#).key,
            "topics.objects.outages[0]"
        );
        assert_eq!(err(r#"{ topics: { "objects": { lost: 0.1 } } }"#).key, "topics.objects.lost");
        assert_eq!(
            err(r#"{ topics: { "objects": { jitter: { dist: "pink", ms: 1 } } } }"#).key,
            "topics.objects.jitter.dist"
        );
        assert!(FaultProfile::find("no-such-profile").unwrap_err().fix.contains("wifi-busy"));
    }
}
