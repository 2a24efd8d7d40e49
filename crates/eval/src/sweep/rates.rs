//! A sweep's runs summed into rates: per family and over all, what a driver would meet per
//! 1,000 km (collisions, unwarranted emergencies, phantom braking), and the runs most worth
//! replaying.

use serde::Serialize;

use super::families::Family;
use crate::acc::ScenarioResult;
use crate::Metrics;

/// One run of a sweep: its family, declaration, where its file is, and how it went (or why
/// it did not run).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct SweepRun {
    /// Its place in the whole sweep (what `--shard` deals by and a merge orders by).
    #[serde(default)]
    pub index: usize,
    pub name: String,
    pub family: Family,
    pub description: String,
    pub file: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<ScenarioResult>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The sums of a set of runs, and their rates per 1,000 km.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
pub struct Rates {
    /// The family's name, or "all".
    pub family: String,
    pub runs: usize,
    /// Runs that did not finish (a node died, a timeout): not in the sums.
    pub errors: usize,
    /// Runs that met every aim.
    pub passed: usize,
    pub km: f64,
    pub collisions: u64,
    pub unwarranted_emergencies: u64,
    pub phantom_braking_events: u64,
    pub phantom_braking_s: f64,
    /// Runs beyond a comfort limit (acceleration, deceleration or jerk outside emergencies).
    pub comfort_violations: usize,
    /// The median of the runs' time-gap RMS errors in steady following, seconds.
    pub time_gap_rms_median_s: Option<f64>,
    pub per_1000_km: PerDistance,
}

/// Rates per 1,000 km driven.
#[derive(Debug, Clone, Copy, Default, Serialize, serde::Deserialize)]
pub struct PerDistance {
    pub collisions: f64,
    pub unwarranted_emergencies: f64,
    pub phantom_braking_events: f64,
    pub phantom_braking_s: f64,
}

/// A run beyond a comfort limit outside emergencies.
fn comfort_violated(m: &Metrics) -> bool {
    m.checks.iter().any(|c| !c.pass && c.name.starts_with("max ") && c.name.contains("outside emergencies"))
}

impl Rates {
    /// The sums of `runs` under the label `family`.
    pub fn of<'a>(family: &str, runs: impl Iterator<Item = &'a SweepRun>) -> Rates {
        let mut r = Rates { family: family.to_string(), ..Default::default() };
        let mut gaps = Vec::new();
        for run in runs {
            r.runs += 1;
            let Some(m) = run.result.as_ref().map(|x| &x.metrics) else {
                r.errors += 1;
                continue;
            };
            r.passed += usize::from(run.result.as_ref().is_some_and(ScenarioResult::passed));
            r.km += m.distance_m / 1000.0;
            r.collisions += m.collisions;
            r.unwarranted_emergencies += m.unwarranted_emergencies;
            r.phantom_braking_events += m.phantom_braking_events;
            r.phantom_braking_s += m.phantom_braking_s;
            r.comfort_violations += usize::from(comfort_violated(m));
            gaps.extend(m.time_gap_rms_error_s);
        }
        r.time_gap_rms_median_s = median(&mut gaps);
        let per = |x: f64| if r.km > 0.0 { x * 1000.0 / r.km } else { 0.0 };
        r.per_1000_km = PerDistance {
            collisions: per(r.collisions as f64),
            unwarranted_emergencies: per(r.unwarranted_emergencies as f64),
            phantom_braking_events: per(r.phantom_braking_events as f64),
            phantom_braking_s: per(r.phantom_braking_s),
        };
        r
    }

    /// The bar: no collision, no unwarranted emergency, phantom braking at most
    /// one event per 1,000 km, and every run finished.
    pub(crate) fn meets_the_bar(&self) -> bool {
        self.errors == 0
            && self.collisions == 0
            && self.unwarranted_emergencies == 0
            && self.per_1000_km.phantom_braking_events <= 1.0
    }
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// How bad a run was, for naming the worst: a collision outweighs any number of unwarranted
/// emergencies, which outweigh phantom braking, which outweighs comfort; 0 for a clean run.
pub(crate) fn badness(run: &SweepRun) -> f64 {
    let Some(m) = run.result.as_ref().map(|r| &r.metrics) else {
        return 1e9;
    };
    m.collisions as f64 * 1e6
        + m.unwarranted_emergencies as f64 * 1e4
        + m.phantom_braking_events as f64 * 1e2
        + m.phantom_braking_s
        + f64::from(u8::from(comfort_violated(m)))
}

/// What went wrong in a run, in a few words.
pub(crate) fn faults_of(run: &SweepRun) -> String {
    let Some(r) = &run.result else {
        return format!("did not finish: {}", run.error.as_deref().unwrap_or("?"));
    };
    let failed: Vec<&str> = r.metrics.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect();
    if failed.is_empty() {
        "pass".into()
    } else {
        failed.join(", ")
    }
}

/// The `n` worst runs that missed something: the worst of each family first (worst first), then
/// each family's second worst, and so on, so that one family's many failures do not hide
/// another's few.
pub fn worst(runs: &[SweepRun], n: usize) -> Vec<&SweepRun> {
    let mut bad: Vec<&SweepRun> = runs.iter().filter(|r| badness(r) > 0.0).collect();
    bad.sort_by(|a, b| badness(b).total_cmp(&badness(a)));
    // Each run's place within its family.
    let mut seen: std::collections::HashMap<Family, usize> = Default::default();
    let mut ranked: Vec<(usize, &SweepRun)> = bad
        .into_iter()
        .map(|r| {
            let k = seen.entry(r.family).or_default();
            *k += 1;
            (*k, r)
        })
        .collect();
    ranked.sort_by(|(ka, a), (kb, b)| ka.cmp(kb).then(badness(b).total_cmp(&badness(a))));
    ranked.into_iter().take(n).map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Trace;

    /// A run of `family` whose metrics come from `metrics`.
    fn run(name: &str, metrics: Metrics) -> SweepRun {
        SweepRun {
            index: 0,
            name: name.into(),
            family: Family::CutIn,
            description: String::new(),
            file: String::new(),
            result: Some(ScenarioResult::for_tests(name, metrics)),
            error: None,
        }
    }

    fn metrics(km: f64, phantom_events: u64, unwarranted: u64) -> Metrics {
        let mut m = Metrics::of(&Trace::default());
        m.distance_m = km * 1000.0;
        m.phantom_braking_events = phantom_events;
        m.phantom_braking_s = phantom_events as f64 * 0.5;
        m.unwarranted_emergencies = unwarranted;
        m
    }

    #[test]
    fn rates_are_per_thousand_km_and_errors_are_kept_out_of_the_sums() {
        let mut runs = vec![run("a", metrics(0.4, 1, 0)), run("b", metrics(0.6, 0, 0))];
        runs.push(SweepRun { result: None, error: Some("node died".into()), ..run("c", metrics(9.0, 9, 9)) });
        let r = Rates::of("cut-in", runs.iter());
        assert_eq!((r.runs, r.errors), (3, 1));
        assert!((r.km - 1.0).abs() < 1e-9);
        assert!((r.per_1000_km.phantom_braking_events - 1000.0).abs() < 1e-6);
        assert!(!r.meets_the_bar());
        let clean = Rates::of("cut-in", runs[1..2].iter());
        assert!(clean.meets_the_bar());
    }

    #[test]
    fn the_worst_runs_are_each_familys_worst_first() {
        let mut runs = vec![
            run("clean", metrics(1.0, 0, 0)),
            run("phantom", metrics(1.0, 3, 0)),
            run("emergency", metrics(1.0, 0, 1)),
            run("two-emergencies", metrics(1.0, 0, 2)),
        ];
        runs[1].family = Family::BendNeighbours;
        let names: Vec<&str> = worst(&runs, 5).iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["two-emergencies", "phantom", "emergency"]);
        assert_eq!(worst(&runs, 1).len(), 1);
    }
}
