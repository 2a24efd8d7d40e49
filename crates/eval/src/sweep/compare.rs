//! Two sweeps side by side (`eval sweep-compare BASE OTHER`): the same generated scenarios
//! (seed, count, families, perception) driven by two sets of nodes, yours against
//! slipstream-acc or one build against the last, compared family by family (rates per 1,000
//! km, runs passed, the time-gap error) with the runs whose verdict changed named. A
//! comparison of sweeps of different scenarios would compare the scenarios: it is refused.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::rates::{Rates, SweepRun};
use super::SweepReport;
use crate::error::{Error, Result};

/// `eval sweep-compare`'s command line.
#[derive(Debug, Clone, clap::Args)]
pub struct CompareArgs {
    /// The baseline sweep's report directory (or its sweep.json), e.g. slipstream-acc's
    #[arg(value_name = "BASE")]
    pub base: PathBuf,
    /// The sweep compared with it: the same seed, --count, --families and --perception
    #[arg(value_name = "OTHER")]
    pub other: PathBuf,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
}

/// One side of a comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Side {
    pub report: PathBuf,
    /// The nodes it judged: `slipstream-acc`, or a command of the user's own.
    pub nodes: String,
    pub wall_s: f64,
}

/// One family's rates on both sides ("all" first).
#[derive(Debug, Clone, Serialize)]
pub struct FamilyPair {
    pub family: String,
    pub base: Rates,
    pub other: Rates,
}

/// A run that passed on one side and not on the other.
#[derive(Debug, Clone, Serialize)]
pub struct Changed {
    pub name: String,
    pub family: String,
    pub base: String,
    pub other: String,
}

/// The comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    pub seed: u64,
    pub runs: usize,
    pub base: Side,
    pub other: Side,
    pub families: Vec<FamilyPair>,
    pub changed: Vec<Changed>,
}

/// Reads both reports and compares them; refuses sweeps of different scenarios or a shard.
pub fn compare(args: &CompareArgs) -> Result<Comparison> {
    let (base, other) = (super::shard::read(&args.base)?, super::shard::read(&args.other)?);
    for (path, r) in [(&args.base, &base), (&args.other, &other)] {
        if let Some(s) = r.shard {
            let rule = format!("is shard {s} of a sweep (fix: merge the shards first: slipstream eval sweep-merge)");
            return Err(Error::flag(path.display().to_string(), rule));
        }
    }
    if !super::shard::same_scenarios(&base, &other) {
        let rule = format!(
            "is a sweep of other scenarios than {} (seed {} against {}, --count {} against {}, --perception and --families the same) (fix: run both with the same --seed, --count, --families and --perception)",
            args.base.display(),
            other.seed,
            base.seed,
            other.count,
            base.count
        );
        return Err(Error::flag(args.other.display().to_string(), rule));
    }
    let mut families = vec![FamilyPair { family: "all".into(), base: base.all.clone(), other: other.all.clone() }];
    for b in &base.families {
        let o = other.families.iter().find(|o| o.family == b.family).cloned().unwrap_or_default();
        families.push(FamilyPair { family: b.family.clone(), base: b.clone(), other: o });
    }
    let side = |path: &Path, r: &SweepReport| Side {
        report: path.to_path_buf(),
        nodes: r.own.described("slipstream-acc"),
        wall_s: r.wall_s,
    };
    Ok(Comparison {
        seed: base.seed,
        runs: base.runs.len(),
        base: side(&args.base, &base),
        other: side(&args.other, &other),
        families,
        changed: changed(&base.runs, &other.runs),
    })
}

/// The runs whose verdict differs, in the sweep's order.
fn changed(base: &[SweepRun], other: &[SweepRun]) -> Vec<Changed> {
    let verdict = |r: &SweepRun| match &r.result {
        Some(x) if x.passed() => "pass".to_string(),
        Some(_) => "FAIL".to_string(),
        None => "did not finish".to_string(),
    };
    base.iter()
        .filter_map(|b| {
            let o = other.iter().find(|o| o.name == b.name)?;
            let (vb, vo) = (verdict(b), verdict(o));
            (vb != vo).then(|| Changed { name: b.name.clone(), family: b.family.name().into(), base: vb, other: vo })
        })
        .collect()
}

/// The comparison as markdown: one row per family, each figure as base -> other.
pub fn markdown(c: &Comparison) -> String {
    let mut out = format!(
        "{} runs (seed {}): BASE {} ({:.0} s) against OTHER {} ({:.0} s, {:.2}x).\n\n",
        c.runs,
        c.seed,
        c.base.nodes,
        c.base.wall_s,
        c.other.nodes,
        c.other.wall_s,
        c.other.wall_s / c.base.wall_s.max(1e-9)
    );
    out.push_str("| family | runs passed | per 1,000 km: collisions | unwarranted emergencies | phantom events | comfort violations (runs) | time-gap RMS median s |\n");
    out.push_str("|---|---|---|---|---|---|---|\n");
    for f in &c.families {
        let (b, o) = (&f.base, &f.other);
        let (pb, po) = (&b.per_1000_km, &o.per_1000_km);
        let gap = |r: &Rates| crate::fmt_opt(r.time_gap_rms_median_s, 3);
        out.push_str(&format!(
            "| {} | {} -> {} of {} | {:.1} -> {:.1} | {:.1} -> {:.1} | {:.1} -> {:.1} | {} -> {} | {} -> {} |\n",
            f.family,
            b.passed,
            o.passed,
            b.runs,
            pb.collisions,
            po.collisions,
            pb.unwarranted_emergencies,
            po.unwarranted_emergencies,
            pb.phantom_braking_events,
            po.phantom_braking_events,
            b.comfort_violations,
            o.comfort_violations,
            gap(b),
            gap(o),
        ));
    }
    match c.changed.len() {
        0 => out.push_str("\nEvery run's verdict is the same on both sides.\n"),
        n => {
            out.push_str(&format!("\n{n} runs changed verdict (base -> other):\n\n"));
            for r in &c.changed {
                out.push_str(&format!("- {} ({}): {} -> {}\n", r.name, r.family, r.base, r.other));
            }
        }
    }
    out
}
